//! Bad input found by trying the binary as a new user would: each is a clear message
//! and a non-zero exit, never a panic, an unbounded allocation or a half-made run.

use std::process::{Command, Output};

fn schrl(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_schrl")).env("RAYON_NUM_THREADS", "1").args(args).output().expect("runs")
}

fn fails_with(args: &[&str], needle: &str) {
    let o = schrl(args);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success(), "should fail: {args:?}");
    assert!(err.contains(needle), "stderr of {args:?} lacks '{needle}':\n{err}");
    assert!(!err.contains("panicked"), "{err}");
}

#[test]
fn counts_that_would_allocate_without_bound_are_refused_by_flag() {
    let scratch = tempfile::tempdir().unwrap();
    // Regressions: `--n 0` panicked inside candle, `--n 3000000` aborted on allocation,
    // `--rollout 18446744073709551615` grew to gigabytes.
    fails_with(&["plan", "sample", "--ckpt", "x", "--n", "0"], "--n <N>': 0 is outside 1..=100000");
    fails_with(&["plan", "sample", "--ckpt", "x", "--n", "3000000"], "outside 1..=100000");
    let out = scratch.path().join("r.png");
    let out = out.to_str().unwrap();
    fails_with(
        &["sim", "render", "--robot", "point", "--out", out, "--rollout", "18446744073709551615"],
        "--rollout",
    );
    fails_with(&["eval", "--ckpt", "x", "--per-group", "0"], "--per-group");
}

#[test]
fn an_unknown_reach_rule_names_the_rules_there_are() {
    fails_with(&["eval", "--ckpt", "x", "--reach", "inside"], "'inside' is not radius or in-goal");
    fails_with(
        &["train", "--task", "seq", "--out", "x", "--reach", "goal"],
        "'goal' is not radius or in-goal",
    );
}

#[test]
fn bad_training_numbers_are_named_before_a_run_directory_is_made() {
    let scratch = tempfile::tempdir().unwrap();
    for (flag, value, needle) in [
        ("--lambda-lr", "nan", "--lambda-lr must be a non-negative number, got NaN"),
        ("--pg-weight", "inf", "--pg-weight must be a non-negative number, got inf"),
        ("--semantics", "soft:0", "alpha"),
    ] {
        let dir = scratch.path().join(format!("run{}", flag.trim_start_matches('-')));
        fails_with(&["train", "--task", "seq", flag, value, "--out", dir.to_str().unwrap()], needle);
        assert!(!dir.exists(), "{flag} {value} left {}", dir.display());
    }
    let dir = scratch.path().join("optionrun");
    let out = dir.to_str().unwrap();
    fails_with(
        &["control", "train", "--robot", "point", "--goal", "99,0", "--out", out],
        "is not a free point",
    );
    fails_with(
        &["control", "train", "--robot", "point", "--goal", "1,1,1", "--out", out],
        "is not a free point",
    );
    assert!(!dir.exists());
    let dir = scratch.path().join("planrun");
    fails_with(
        &["plan", "train", "--task", "seq", "--semantics", "lse:-1", "--out", dir.to_str().unwrap()],
        "temperature",
    );
    assert!(!dir.exists());
}

#[test]
fn task_check_names_the_regions_to_avoid() {
    let keys = concat!(env!("CARGO_MANIFEST_DIR"), "/../../examples/tasks/keys.toml");
    let o = schrl(&["task", "check", keys]);
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(
        o.status.success()
            && out.contains("regions to avoid, checked along the path")
            && out.contains(": hazard"),
        "{out}"
    );
    let o = schrl(&["task", "check", concat!(env!("CARGO_MANIFEST_DIR"), "/../../tasks/point/seq.toml")]);
    assert!(!String::from_utf8_lossy(&o.stdout).contains("regions to avoid"));
}

#[test]
fn task_files_without_end_or_sense_are_refused_by_file_and_key() {
    let scratch = tempfile::tempdir().unwrap();
    fails_with(&["task", "check", "/dev/zero"], "/dev/zero: cannot read: larger than 1024 KiB");
    let toml = scratch.path().join("c.toml");
    let keys = concat!(env!("CARGO_MANIFEST_DIR"), "/../../examples/tasks/keys.toml");
    let text = std::fs::read_to_string(keys).unwrap().replace("keys.stl", "c.stl");
    std::fs::write(&toml, &text).unwrap();
    // Regression: a spec that is only `true` panicked in training.
    std::fs::write(scratch.path().join("c.stl"), "true\n").unwrap();
    fails_with(&["task", "check", toml.to_str().unwrap()], "c.stl: the spec names no goal");
    fails_with(
        &["train", "--task", toml.to_str().unwrap(), "--out", scratch.path().join("t").to_str().unwrap()],
        "constant",
    );
    // Regression: a million waypoints passed `task check` and asked for 16 GB.
    std::fs::write(scratch.path().join("c.stl"), "F[1,2] key_a\n").unwrap();
    std::fs::write(&toml, text.replace("steps = 6", "steps = 1000000")).unwrap();
    fails_with(&["task", "check", toml.to_str().unwrap()], "c.toml: steps: 1000000 waypoints");
}
