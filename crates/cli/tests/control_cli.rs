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
    let scratch = tempfile::tempdir().unwrap();
    let dir = scratch.path().join("control-cli");
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
        "--hidden",
        "16,8",
        "--fall-penalty",
        "5",
        "--off-track-weight",
        "0.2",
        "--observe-track",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stdout(&o).contains("success rate: "), "{}", stdout(&o));
    // Regression: with stderr in a log file the progress bars are hidden, and such
    // logs of hour-long runs said nothing until the end. Now each stage writes a line
    // at every tenth of its way: here, both updates.
    let log = stderr(&o);
    let progress: Vec<&str> = log.lines().filter(|l| l.starts_with("controller ")).collect();
    assert_eq!(progress.len(), 2, "{log}");
    assert!(progress[1].starts_with("controller 2/2 (") && progress[1].contains("steps/s"), "{progress:?}");
    for f in ["manifest.json", "metrics.jsonl", "training_curve.png"] {
        assert!(dir.join(f).exists(), "{f} missing");
    }
    let manifest: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("manifest.json")).unwrap()).unwrap();
    assert_eq!(manifest["kind"], "controller");
    assert_eq!(manifest["settings"]["ppo"]["hidden"], serde_json::json!([16, 8]));
    assert_eq!(manifest["settings"]["fall_penalty"], 5.0);
    assert_eq!(manifest["settings"]["off_track_weight"], 0.2);
    assert_eq!(manifest["settings"]["observe_track"], true);
    for f in ["controller.safetensors", "controller.json"] {
        assert!(manifest["files"][f]["sha256"].is_string(), "{f} not in the manifest");
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
    assert!(!o.status.success() && stderr(&o).contains("--robot differs"), "{}", stderr(&o));
    for (flag, value) in [("--hidden", "64,64"), ("--fall-penalty", "0"), ("--observe-track", "false")] {
        let o = schrl(&["control", "train", "--resume", flag, value, "--out", out]);
        assert!(!o.status.success() && stderr(&o).contains(&format!("{flag} differs")), "{}", stderr(&o));
    }

    let png = dir.join("episodes.png");
    let o = schrl(&["control", "eval", "--ckpt", out, "--episodes", "30", "--out", png.to_str().unwrap()]);
    assert!(o.status.success(), "{}", stderr(&o));
    let line = stdout(&o).lines().find(|l| l.starts_with("success rate: ")).unwrap().to_string();
    let rate: f64 = line["success rate: ".len()..].parse().unwrap();
    assert!((0.0..=1.0).contains(&rate));
    assert!(std::fs::metadata(&png).unwrap().len() > 1000);
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
    let scratch = tempfile::tempdir().unwrap();
    let dir = scratch.path();
    let toml_text = std::fs::read_to_string(format!("{root}/point/seq.toml")).unwrap();
    std::fs::write(dir.join("seq.toml"), toml_text).unwrap();
    std::fs::write(dir.join("seq.stl"), "F[1,2] g0 & F[3,4] g9").unwrap();
    let o = schrl(&["task", "check", dir.join("seq.toml").to_str().unwrap()]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("seq.stl: line 1, column 20: 'g9' is not defined"), "{}", stderr(&o));
}

#[test]
fn joint_train_resume_and_eval_end_to_end() {
    let scratch = tempfile::tempdir().unwrap();
    let dir = scratch.path().join("joint-cli");
    let ctl = dir.join("ctl");
    let o = schrl(&[
        "control",
        "train",
        "--robot",
        "point",
        "--steps",
        "4000",
        "--out",
        ctl.to_str().unwrap(),
        "--eval-episodes",
        "0",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let run = dir.join("run");
    let run_s = run.to_str().unwrap();
    // Algorithm 1: the planner updates in the joint phase too (the default).
    let args = [
        "train",
        "--task",
        "branch",
        "--steps",
        "15000",
        "--pretrain-updates",
        "5",
        "--eval-groups",
        "1",
        "--planner",
        "mlp",
    ];
    let o = schrl(&[&args[..], &["--controller", ctl.to_str().unwrap(), "--out", run_s]].concat());
    assert!(o.status.success(), "{}", stderr(&o));
    // 5 updates satisfy nothing: pre-training retries without the safe margin.
    assert!(stderr(&o).contains("planning with the task's own"), "{}", stderr(&o));
    assert!(
        stdout(&o).contains("satisfaction: ") && stdout(&o).contains("steps to reach: "),
        "{}",
        stdout(&o)
    );
    for f in ["manifest.json", "metrics.jsonl", "training_curve.png", "episodes.png"] {
        assert!(run.join(f).exists(), "{f} missing");
    }
    // The planner network is part of the run: resume and eval rebuild the MLP.
    let meta = std::fs::read_to_string(run.join("manifest.json")).unwrap();
    for f in ["joint.json", "planner.safetensors", "controller.json", "controller.safetensors"] {
        assert!(meta.contains(&format!("\"{f}\"")), "{f} not in the manifest: {meta}");
    }
    assert!(meta.contains("\"planner\": \"mlp\""), "{meta}");
    let o = schrl(&[&args[..], &["--controller", ctl.to_str().unwrap(), "--out", run_s]].concat());
    assert!(!o.status.success() && stderr(&o).contains("--force"), "{}", stderr(&o));
    let lines = |p: &std::path::Path| std::fs::read_to_string(p).unwrap().lines().count();
    let before = lines(&run.join("metrics.jsonl"));
    let o = schrl(&[
        "train",
        "--task",
        "branch",
        "--resume",
        "--steps",
        "30000",
        "--eval-groups",
        "0",
        "--out",
        run_s,
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(lines(&run.join("metrics.jsonl")) > before);
    // The planner learns in the joint phase by default: a loss on every iteration.
    let metrics = std::fs::read_to_string(run.join("metrics.jsonl")).unwrap();
    for line in metrics.lines() {
        let m: serde_json::Value = serde_json::from_str(line).unwrap();
        assert!(m["plan_loss"].is_f64(), "no planner update in {line}");
        assert!(m["low_level_reward"].as_f64().is_some_and(|r| (-2.0..=0.0).contains(&r)), "{line}");
    }
    let o = schrl(&["eval", "--ckpt", run_s, "--groups", "2", "--per-group", "10"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let text = stdout(&o);
    let line = text.lines().find(|l| l.starts_with("satisfaction: ")).unwrap();
    let (mean, std) = line["satisfaction: ".len()..].split_once(" ± ").unwrap();
    assert!((0.0..=1.0).contains(&mean.parse::<f64>().unwrap()) && std.parse::<f64>().unwrap() >= 0.0);
    let o = schrl(&["eval", "--ckpt", run_s, "--groups", "1", "--per-group", "5", "--sampled-plans"]);
    assert!(o.status.success() && stdout(&o).contains("satisfaction: "), "{}", stderr(&o));
    // Fig. 4's variants: the gradient planner's plans, another controller.
    let o = schrl(&["eval", "--ckpt", run_s, "--groups", "1", "--per-group", "3", "--planner", "gradient"]);
    assert!(o.status.success() && stdout(&o).contains("satisfaction: "), "{}", stderr(&o));
    let o = schrl(&["eval", "--ckpt", run_s, "--groups", "1", "--per-group", "2", "--planner", "mip"]);
    assert!(o.status.success() && stdout(&o).contains("satisfaction: "), "{}", stderr(&o));
    let o = schrl(&[
        "eval",
        "--ckpt",
        run_s,
        "--groups",
        "1",
        "--per-group",
        "3",
        "--controller",
        ctl.to_str().unwrap(),
    ]);
    assert!(o.status.success() && stdout(&o).contains("satisfaction: "), "{}", stderr(&o));
    // `--general-controller` drives with the general controller the run kept: the one
    // its `general.json` names (a retry here), else DIR/general.
    let general = ["eval", "--ckpt", run_s, "--groups", "1", "--per-group", "3", "--general-controller"];
    let o = schrl(&general);
    assert!(!o.status.success() && stderr(&o).contains("general"), "{}", stderr(&o));
    let copy = |to: &str| {
        std::fs::create_dir_all(run.join(to)).unwrap();
        for f in std::fs::read_dir(&ctl).unwrap() {
            let f = f.unwrap().path();
            if f.is_dir() {
                let sub = run.join(to).join(f.file_name().unwrap());
                std::fs::create_dir_all(&sub).unwrap();
                for g in std::fs::read_dir(&f).unwrap() {
                    let g = g.unwrap().path();
                    std::fs::copy(&g, sub.join(g.file_name().unwrap())).unwrap();
                }
            } else if f.file_name().unwrap() != ".lock" {
                std::fs::copy(&f, run.join(to).join(f.file_name().unwrap())).unwrap();
            }
        }
    };
    copy("general-2");
    let choice = r#"{"tries": [{"dir": "general", "seed": 0, "success_rate": 0.5},
        {"dir": "general-2", "seed": 1, "success_rate": 1.0}], "kept": 1}"#;
    std::fs::write(run.join("general.json"), choice).unwrap();
    let o = schrl(&general);
    assert!(o.status.success(), "{}", stderr(&o));
    let with_ctl = schrl(&[&general[..7], &["--controller", ctl.to_str().unwrap()]].concat());
    assert_eq!(stdout(&o), stdout(&with_ctl), "the kept retry is the controller driven");
    let o = schrl(&[&general[..], &["--controller", ctl.to_str().unwrap()]].concat());
    assert!(!o.status.success() && stderr(&o).contains("cannot be used with"), "{}", stderr(&o));
    std::fs::remove_file(run.join("general.json")).unwrap();
    let o = schrl(&["eval", "--ckpt", run_s, "--planner", "gradient", "--sampled-plans"]);
    assert!(!o.status.success() && stderr(&o).contains("goes with --planner network only"), "{}", stderr(&o));
    // A task file decides its robot; every run can be written out and judged again.
    let keys = concat!(env!("CARGO_MANIFEST_DIR"), "/../../examples/tasks/keys.toml");
    let o = schrl(&["train", "--robot", "car", "--task", keys, "--out", dir.join("k").to_str().unwrap()]);
    assert!(!o.status.success() && stderr(&o).contains("is for the point"), "{}", stderr(&o));
    let krun = dir.join("keys");
    let o = schrl(&[
        "train",
        "--task",
        keys,
        "--steps",
        "2000",
        "--pretrain-updates",
        "2",
        "--planner",
        "mlp",
        "--eval-groups",
        "0",
        "--controller",
        ctl.to_str().unwrap(),
        "--out",
        krun.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let jsonl = dir.join("runs.jsonl");
    let eval_keys = |extra: &[&str]| {
        let base = ["eval", "--ckpt", krun.to_str().unwrap(), "--groups", "2", "--per-group", "3"];
        schrl(&[&base[..], &["--trajectories", jsonl.to_str().unwrap()], extra].concat())
    };
    // A picture that cannot be written fails before the evaluation, leaving nothing.
    let o = eval_keys(&["--out", "/nonexistent/x.png"]);
    assert!(
        !o.status.success() && stderr(&o).contains("/nonexistent") && !stdout(&o).contains("satisfaction")
    );
    assert!(!jsonl.exists());
    let o = eval_keys(&[]);
    assert!(o.status.success() && stdout(&o).contains("wrote 6 runs"), "{}", stderr(&o));
    let text = std::fs::read_to_string(&jsonl).unwrap();
    assert_eq!(text.lines().count(), 6);
    let mut turned = false;
    for line in text.lines() {
        let r: serde_json::Value = serde_json::from_str(line).unwrap();
        assert!(r["satisfied"].is_boolean() && r["outcome"].is_string(), "{line}");
        let positions = r["positions"].as_array().unwrap();
        assert_eq!(
            positions.len(),
            r["steps"].as_u64().unwrap() as usize + 1,
            "a position per step and the start"
        );
        assert!(positions.iter().all(|p| p.as_array().unwrap().len() == 2));
        let headings = r["headings"].as_array().unwrap();
        assert_eq!(headings.len(), positions.len(), "a heading per position");
        let yaw = |h: &serde_json::Value| h.as_f64().unwrap();
        turned |= headings.iter().any(|h| (yaw(h) - yaw(&headings[0])).abs() > 0.5);
        assert_eq!(r["waypoints"].as_array().unwrap().len(), 7, "the start and 6 waypoints");
        assert!(r["reached_at"].as_array().unwrap().len() <= 6);
    }
    assert!(turned, "the headings record the robot turning in some run");
    // Kept without --force.
    let o = eval_keys(&[]);
    assert!(!o.status.success() && stderr(&o).contains("--force"), "{}", stderr(&o));
    let rejudge = || schrl(&["robustness", "--task", keys, "--runs", jsonl.to_str().unwrap()]);
    let o = rejudge();
    assert!(
        o.status.success() && stdout(&o).contains("6 runs") && stdout(&o).contains("0 differ"),
        "{}",
        stderr(&o)
    );
    // A record that claims what its positions do not show is caught.
    let first = text.lines().next().unwrap();
    let mut r: serde_json::Value = serde_json::from_str(first).unwrap();
    r["satisfied"] = serde_json::Value::Bool(!r["satisfied"].as_bool().unwrap());
    std::fs::write(&jsonl, text.replacen(first, &r.to_string(), 1)).unwrap();
    let o = rejudge();
    assert!(!o.status.success() && stderr(&o).contains("1 of 6 runs judged differently"), "{}", stderr(&o));
    // A checkpoint whose state claims another layout is refused, even with its
    // checksum made to match.
    let tampered = dir.join("tampered");
    copy_dir(&krun, &tampered);
    let mut manifest: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(tampered.join("manifest.json")).unwrap()).unwrap();
    let gen_dir = tampered.join(format!("gen-{}", manifest["generation"]));
    let state = std::fs::read_to_string(gen_dir.join("joint.json")).unwrap();
    assert!(state.starts_with("{\"format\":1,"), "{}", &state[..40]);
    let state = state.replacen("{\"format\":1,", "{\"format\":7,", 1);
    std::fs::write(gen_dir.join("joint.json"), &state).unwrap();
    use sha2::Digest;
    let digest: String = sha2::Sha256::digest(state.as_bytes()).iter().map(|b| format!("{b:02x}")).collect();
    manifest["files"]["joint.json"]["sha256"] = digest.into();
    manifest["files"]["joint.json"]["bytes"] = state.len().into();
    std::fs::write(tampered.join("manifest.json"), manifest.to_string()).unwrap();
    let o = schrl(&["eval", "--ckpt", tampered.to_str().unwrap(), "--groups", "1", "--per-group", "1"]);
    assert!(!o.status.success() && stderr(&o).contains("joint.json: format 7 is not 1"), "{}", stderr(&o));
    // Fig. 5: the two planners' waypoints in one picture.
    let fig5 = dir.join("fig5.svg");
    let o = schrl(&["plan", "compare", "--ckpt", run_s, "--n", "2", "--out", fig5.to_str().unwrap()]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stdout(&o).contains("start 1: network"), "{}", stdout(&o));
    assert!(std::fs::read_to_string(&fig5).unwrap().contains("gradient planner"));
    let o = schrl(&[
        "train",
        "--robot",
        "car",
        "--task",
        "seq",
        "--controller",
        ctl.to_str().unwrap(),
        "--out",
        dir.join("x").to_str().unwrap(),
    ]);
    assert!(stderr(&o).contains("a point controller, not car"), "{}", stderr(&o));
    for (flag, message) in [
        ("--safe-margin=-0.5", "--safe-margin must be a non-negative"),
        ("--turn-margin=nan", "--turn-margin must be a non-negative number of metres"),
    ] {
        let out = dir.join("refused");
        let o = schrl(&[
            "train",
            "--task",
            "seq",
            flag,
            "--controller",
            ctl.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ]);
        assert!(!o.status.success() && stderr(&o).contains(message), "{flag}: {}", stderr(&o));
        assert!(!out.exists(), "{flag}: a refused run leaves no directory");
    }
}

/// Copies a run directory (files and one level of subdirectories).
fn copy_dir(from: &std::path::Path, to: &std::path::Path) {
    std::fs::create_dir_all(to).unwrap();
    for entry in std::fs::read_dir(from).unwrap() {
        let path = entry.unwrap().path();
        let target = to.join(path.file_name().unwrap());
        if path.is_dir() {
            copy_dir(&path, &target);
        } else {
            std::fs::copy(&path, &target).unwrap();
        }
    }
}

#[test]
fn plot_bars_draws_results_and_names_bad_rows() {
    let scratch = tempfile::tempdir().unwrap();
    let dir = scratch.path();
    let csv = dir.join("fig4.csv");
    std::fs::write(
        &csv,
        "task,variant,seed,satisfaction,steps_to_reach\n\
         seq,(a) SCHRL,0,1.0,480\nseq,(a) SCHRL,1,0.99,470\nseq,(c) gradient planner,0,0.02,-\n\
         loop,(a) SCHRL,0,1.0,1600\n",
    )
    .unwrap();
    let plot = |out: &str| schrl(&["plot", "bars", "--results", csv.to_str().unwrap(), "--out", out]);
    let out = dir.join("fig4.svg");
    let o = plot(out.to_str().unwrap());
    assert!(o.status.success(), "{}", stderr(&o));
    let svg = std::fs::read_to_string(&out).unwrap();
    assert!(svg.contains("(c) gradient planner") && svg.contains("steps to reach (normalised)"));
    // An existing picture is kept without --force.
    let o = plot(out.to_str().unwrap());
    assert!(!o.status.success() && stderr(&o).contains("--force"), "{}", stderr(&o));
    let other = dir.join("x.png");
    std::fs::write(&csv, "task,variant,seed,satisfaction,steps_to_reach\nseq,a,0,high,-\n").unwrap();
    let o = plot(other.to_str().unwrap());
    assert!(stderr(&o).contains("row 2, column satisfaction: 'high' is not a number"), "{}", stderr(&o));
    std::fs::write(&csv, "task,satisfaction\n").unwrap();
    let o = plot(other.to_str().unwrap());
    assert!(stderr(&o).contains("the header must be"), "{}", stderr(&o));
}
