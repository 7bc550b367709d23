//! `schrl control train` and `schrl control eval` end to end.

use std::process::Command;

fn schrl(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_schrl")).env("RAYON_NUM_THREADS", "1").args(args).output().expect("runs")
}

fn stdout(o: &std::process::Output) -> String {
    String::from_utf8_lossy(&o.stdout).into_owned()
}

fn stderr(o: &std::process::Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

#[test]
fn trains_resumes_refuses_to_clobber_and_evaluates() {
    let dir = std::env::temp_dir().join(format!("schrl-control-cli-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let out = dir.to_str().unwrap();
    let o = schrl(&[
        "control",
        "train",
        "--robot",
        "point",
        "--steps",
        "8000",
        "--out",
        out,
        "--eval-episodes",
        "20",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stdout(&o).contains("success rate: "), "{}", stdout(&o));
    for f in ["controller.safetensors", "controller.json", "metrics.jsonl", "training_curve.png"] {
        assert!(dir.join(f).exists(), "{f} missing");
    }
    assert_eq!(std::fs::read_to_string(dir.join("metrics.jsonl")).unwrap().lines().count(), 2);

    let o = schrl(&["control", "train", "--robot", "point", "--steps", "4000", "--out", out]);
    assert!(!o.status.success() && stderr(&o).contains("--force"), "{}", stderr(&o));

    // Resume to a larger budget: the log continues where it stopped.
    let o =
        schrl(&["control", "train", "--resume", "--steps", "12000", "--out", out, "--eval-episodes", "0"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let log = std::fs::read_to_string(dir.join("metrics.jsonl")).unwrap();
    let updates: Vec<u64> = log
        .lines()
        .map(|l| serde_json::from_str::<serde_json::Value>(l).unwrap()["update"].as_u64().unwrap())
        .collect();
    assert_eq!(updates, [1, 2, 3]);

    let o = schrl(&["control", "train", "--resume", "--robot", "car", "--out", out]);
    assert!(!o.status.success() && stderr(&o).contains("is a point run"), "{}", stderr(&o));

    let png = dir.join("episodes.png");
    let o = schrl(&["control", "eval", "--ckpt", out, "--episodes", "30", "--out", png.to_str().unwrap()]);
    assert!(o.status.success(), "{}", stderr(&o));
    let line = stdout(&o).lines().find(|l| l.starts_with("success rate: ")).unwrap().to_string();
    let rate: f64 = line["success rate: ".len()..].parse().unwrap();
    assert!((0.0..=1.0).contains(&rate));
    assert!(std::fs::metadata(&png).unwrap().len() > 1000);
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn bad_arguments_are_clear_errors() {
    let o = schrl(&["control", "train", "--robot", "tank", "--out", "x"]);
    assert!(stderr(&o).contains("unknown robot 'tank'"), "{}", stderr(&o));
    let o = schrl(&["control", "train", "--robot", "point", "--map", "moon", "--out", "/tmp/schrl-never"]);
    assert!(stderr(&o).contains("unknown map 'moon'"), "{}", stderr(&o));
    let o = schrl(&["control", "train", "--robot", "point", "--preset", "fast", "--out", "/tmp/schrl-never"]);
    assert!(stderr(&o).contains("unknown --preset 'fast'"), "{}", stderr(&o));
    let o = schrl(&["control", "eval", "--ckpt", "/nonexistent/run"]);
    assert!(!o.status.success() && stderr(&o).contains("/nonexistent/run"), "{}", stderr(&o));
}

#[test]
fn task_check_accepts_shipped_tasks_and_names_the_problem_in_bad_ones() {
    let root = concat!(env!("CARGO_MANIFEST_DIR"), "/../../tasks");
    let o = schrl(&["task", "check", &format!("{root}/drone/loop.toml")]);
    assert!(o.status.success() && stdout(&o).ends_with("ok\n"), "{}", stderr(&o));
    let dir = std::env::temp_dir().join(format!("schrl-task-cli-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let toml_text = std::fs::read_to_string(format!("{root}/point/seq.toml")).unwrap();
    std::fs::write(dir.join("seq.toml"), toml_text).unwrap();
    std::fs::write(dir.join("seq.stl"), "F[1,2] g0 & F[3,4] g9").unwrap();
    let o = schrl(&["task", "check", dir.join("seq.toml").to_str().unwrap()]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("seq.stl: line 1, column 20: 'g9' is not defined"), "{}", stderr(&o));
    std::fs::remove_dir_all(&dir).unwrap();
}
