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
    let dir = std::env::temp_dir().join(format!("schrl-sdf-cli-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
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
