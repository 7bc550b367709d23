//! `schrl sdf fit` and `schrl sdf check` end to end.

use std::process::Command;

fn schrl(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_schrl")).args(args).output().expect("runs")
}

fn value(out: &std::process::Output, key: &str) -> f64 {
    let text = String::from_utf8_lossy(&out.stdout);
    let line = text.lines().find(|l| l.starts_with(key)).unwrap_or_else(|| panic!("no '{key}' in {text}"));
    line[key.len()..].trim().parse().unwrap()
}

#[test]
fn fits_draws_checks_and_refuses_to_clobber() {
    let scratch = tempfile::tempdir().unwrap();
    let dir = scratch.path();
    let (net, png) = (dir.join("walls.json"), dir.join("walls.png"));
    let (net_s, png_s) = (net.to_str().unwrap(), png.to_str().unwrap());
    let o = schrl(&["sdf", "fit", "--map", "walls", "--steps", "1500", "--out", net_s, "--png", png_s]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(value(&o, "sign agreement:") > 0.9);
    assert!(std::fs::metadata(&png).unwrap().len() > 1000);
    let c = schrl(&["sdf", "check", "--sdf", net_s]);
    assert!(c.status.success(), "{}", String::from_utf8_lossy(&c.stderr));
    assert!((value(&c, "mean abs error:") - value(&o, "mean abs error:")).abs() < 0.02);
    let again = schrl(&["sdf", "fit", "--map", "walls", "--steps", "10", "--out", net_s]);
    assert!(!again.status.success() && String::from_utf8_lossy(&again.stderr).contains("--force"));
    let empty = schrl(&["sdf", "fit", "--map", "empty", "--out", dir.join("e.json").to_str().unwrap()]);
    assert!(String::from_utf8_lossy(&empty.stderr).contains("no obstacle"));
}

/// `schrl train --obstacle-sdf` refuses a network of another map and a contradicting
/// `--obstacle exact`, before any training, naming what is wrong.
#[test]
fn train_refuses_a_neural_obstacle_that_does_not_fit_the_task() {
    let scratch = tempfile::tempdir().unwrap();
    let dir = scratch.path();
    let net = dir.join("walls.json");
    let net_s = net.to_str().unwrap();
    let o = schrl(&["sdf", "fit", "--map", "walls", "--steps", "10", "--out", net_s]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let run = dir.join("run");
    let run_s = run.to_str().unwrap();
    let drone =
        schrl(&["train", "--robot", "drone", "--task", "seq", "--obstacle-sdf", net_s, "--out", run_s]);
    let err = String::from_utf8_lossy(&drone.stderr);
    assert!(
        !drone.status.success()
            && err.contains("--obstacle-sdf")
            && err.contains("walls")
            && err.contains("duck"),
        "{err}"
    );
    let both =
        schrl(&["train", "--task", "seq", "--obstacle", "exact", "--obstacle-sdf", net_s, "--out", run_s]);
    let err = String::from_utf8_lossy(&both.stderr);
    assert!(!both.status.success() && err.contains("--obstacle exact"), "{err}");
    assert!(!run.join("manifest.json").exists(), "nothing was started");
}
