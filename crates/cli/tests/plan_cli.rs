//! `schrl plan train` and `schrl plan sample` end to end.

use std::process::Command;

fn schrl(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_schrl")).env("RAYON_NUM_THREADS", "1").args(args).output().expect("runs")
}

fn last_value(out: &std::process::Output, key: &str) -> f64 {
    let text = String::from_utf8_lossy(&out.stdout);
    let line =
        text.lines().rev().find(|l| l.starts_with(key)).unwrap_or_else(|| panic!("no '{key}' in {text}"));
    // The mean: the first number (`<mean> ± <std>` where a spread follows).
    line[key.len()..].split_whitespace().next().unwrap().parse().unwrap()
}

#[test]
fn trains_saves_refuses_to_clobber_and_samples() {
    let scratch = tempfile::tempdir().unwrap();
    let dir = scratch.path().join("plan-cli");
    let out = dir.to_str().unwrap();
    let o = schrl(&["plan", "train", "--task", "seq", "--seed", "0", "--updates", "400", "--out", out]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    // Learning itself is pinned in schrl's tests/planning.rs; here: well above the
    // untrained planner's < 5 %.
    assert!(last_value(&o, "satisfaction:") > 0.1);
    // The deployed (mean) paths do better than the noisy samples.
    assert!(last_value(&o, "mean-path satisfaction:") > last_value(&o, "satisfaction:"));
    assert!(dir.join("manifest.json").exists() && dir.join("metrics.jsonl").exists());
    let lines = std::fs::read_to_string(dir.join("metrics.jsonl")).unwrap();
    assert_eq!(lines.lines().count() as f64, last_value(&o, "updates:"));
    // A second run must not replace the checkpoint silently.
    let o = schrl(&["plan", "train", "--task", "seq", "--updates", "1", "--out", out]);
    assert!(!o.status.success() && String::from_utf8_lossy(&o.stderr).contains("--force"));
    let png = dir.join("paths.png");
    let o = schrl(&["plan", "sample", "--ckpt", out, "--n", "100", "--out", png.to_str().unwrap()]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(last_value(&o, "satisfaction:") > 0.1);
    assert!(std::fs::metadata(&png).unwrap().len() > 1000);
    // The deployed (mean) plans satisfy more often than noisy samples.
    let mean = schrl(&["plan", "sample", "--ckpt", out, "--n", "100", "--mean"]);
    assert!(last_value(&mean, "satisfaction:") > last_value(&o, "satisfaction:"));
}

#[test]
fn bad_arguments_are_clear_errors() {
    let o = schrl(&["plan", "train", "--task", "dance", "--out", "x"]);
    assert!(String::from_utf8_lossy(&o.stderr).contains("unknown task 'dance'"));
    let o = schrl(&["plan", "train", "--task", "seq", "--robot", "car", "--out", "x"]);
    assert!(String::from_utf8_lossy(&o.stderr).contains("point robot only"));
    let o = schrl(&["plan", "train", "--task", "seq", "--planner", "lstm", "--out", "x"]);
    assert!(String::from_utf8_lossy(&o.stderr).contains("unknown planner 'lstm'"));
    let o = schrl(&["plan", "train", "--task", "seq", "--safe-along", "edges", "--out", "x"]);
    assert!(String::from_utf8_lossy(&o.stderr).contains("'edges' is not segments or waypoints"));
    let o = schrl(&["plan", "sample", "--ckpt", "/nonexistent/ckpt"]);
    assert!(!o.status.success() && String::from_utf8_lossy(&o.stderr).contains("/nonexistent/ckpt"));
}

#[test]
fn an_ablation_planner_round_trips_through_its_checkpoint() {
    let scratch = tempfile::tempdir().unwrap();
    let dir = scratch.path().join("plan-mlp");
    let out = dir.to_str().unwrap();
    let o = schrl(&[
        "plan",
        "train",
        "--task",
        "branch",
        "--planner",
        "mlp",
        "--safe-along",
        "waypoints",
        "--updates",
        "5",
        "--out",
        out,
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let meta = std::fs::read_to_string(dir.join("manifest.json")).unwrap();
    assert!(
        meta.contains("\"planner\": \"mlp\"") && meta.contains("\"safe_along\": \"waypoints\""),
        "{meta}"
    );
    let o = schrl(&["plan", "sample", "--ckpt", out, "--n", "10"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    // Only the GRU-ODE has a plain-Rust deployment to time.
    let o = schrl(&["plan", "time", "--ckpt", out, "--n", "2"]);
    assert!(!o.status.success() && String::from_utf8_lossy(&o.stderr).contains("GRU-ODE"));
}

#[test]
fn time_compares_the_network_with_the_gradient_planner() {
    let scratch = tempfile::tempdir().unwrap();
    let dir = scratch.path().join("plan-time");
    let out = dir.to_str().unwrap();
    let o = schrl(&["plan", "train", "--task", "branch", "--updates", "20", "--out", out]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let o = schrl(&["plan", "time", "--ckpt", out, "--n", "5"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(text.contains("5/5 satisfy (at most"), "the gradient planner solves Branch: {text}");
    // A deployed plan is microseconds; the gradient planner's search is not.
    let (net, grad) =
        (last_value(&o, "network seconds per plan:"), last_value(&o, "gradient seconds per plan:"));
    assert!(net > 0.0 && net < grad, "network {net} s, gradient {grad} s");
    let o = schrl(&["plan", "time", "--ckpt", out, "--n", "0"]);
    assert!(!o.status.success() && String::from_utf8_lossy(&o.stderr).contains("--n"));
}

#[test]
fn mip_plans_write_a_file_say_their_robustness_and_refuse_bad_input() {
    let scratch = tempfile::tempdir().unwrap();
    let dir = scratch.path();
    let plan = dir.join("plan.json");
    let p = plan.to_str().unwrap();
    let o = schrl(&["plan", "mip", "--task", "branch", "--start", "1.5,-1.5", "--out", p]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    // Branch's goals have radius 0.6: the most robust plan visits both centres.
    assert!((last_value(&o, "robustness:") - 0.6).abs() < 1e-3);
    assert!(last_value(&o, "solve seconds:") > 0.0);
    let saved: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&plan).unwrap()).unwrap();
    assert_eq!(saved["waypoints"].as_array().unwrap().len(), 5, "{saved}");
    assert_eq!(saved["waypoints"][0], serde_json::json!([1.5, -1.5]));
    // Not over the file without --force.
    let o = schrl(&["plan", "mip", "--task", "branch", "--start", "1.5,-1.5", "--out", p]);
    assert!(!o.status.success() && String::from_utf8_lossy(&o.stderr).contains("--force"));
    // Timing from drawn starts, as Table 5.
    let o = schrl(&["plan", "mip", "--task", "seq", "--n", "3"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(
        String::from_utf8_lossy(&o.stdout).contains("3/3 satisfy"),
        "{}",
        String::from_utf8_lossy(&o.stdout)
    );
    assert!(last_value(&o, "mip seconds per plan:") > 0.0);
    assert_eq!(last_value(&o, "mip plans satisfying:"), 3.0);
    // A spec no plan satisfies: in two discs 4 m apart at the same waypoint.
    std::fs::write(dir.join("two.stl"), "F[1,1] a & F[1,1] b\n").unwrap();
    std::fs::write(
        dir.join("two.toml"),
        "name = \"two\"\nrobot = \"point\"\nmap = \"empty\"\nspec = \"two.stl\"\nsteps = 2\nstep_limit = 100\n\
         safe_radius = 0.1\n[start]\nlow = [0.0, 0.0]\nhigh = [0.0, 0.0]\n\
         [[goal]]\nname = \"a\"\ncenter = [2.0, 0.0]\nradius = 0.5\n\
         [[goal]]\nname = \"b\"\ncenter = [-2.0, 0.0]\nradius = 0.5\n",
    )
    .unwrap();
    let two = dir.join("two.toml");
    let o = schrl(&["plan", "mip", "--task", two.to_str().unwrap()]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && err.contains("infeasible") && err.contains("-1.5"), "{err}");
    let bad = |args: &[&str], says: &str| {
        let o = schrl(&[&["plan", "mip"], args].concat());
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success() && err.contains(says), "{args:?}: {err}");
    };
    bad(&["--task", "seq", "--start", "0,0"], "inside an obstacle");
    bad(&["--task", "seq", "--start", "1,2,3"], "give 2 numbers");
    bad(&["--task", "seq", "--start", "9,0"], "outside the walls map's region");
    bad(&["--task", "seq", "--start", "x,0"], "'x' in 'x,0' is not a number");
    bad(&["--task", "seq", "--robot", "drone"], "2-D");
    bad(&["--task", "seq", "--max-step", "0"], "--max-step");
    bad(&["--task", "seq", "--solver", "gurobi"], "unknown solver 'gurobi'");
    bad(&["--task", "seq", "--n", "2", "--out", p], "drop --start, --out and --picture");
}
