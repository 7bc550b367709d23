//! `schrl baseline train|eval` and `schrl plot curves` end to end on a small task file.

use std::path::Path;
use std::process::{Command, Output};

fn schrl(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_schrl")).env("RAYON_NUM_THREADS", "1").args(args).output().expect("runs")
}

fn text(b: &[u8]) -> String {
    String::from_utf8_lossy(b).into_owned()
}

/// A fresh scratch directory (removed when dropped) with the easy task's two files.
fn workspace() -> tempfile::TempDir {
    let scratch = tempfile::tempdir().unwrap();
    let dir = scratch.path();
    std::fs::write(
        dir.join("easy.toml"),
        "name = \"easy\"\nrobot = \"point\"\nmap = \"empty\"\nspec = \"easy.stl\"\nsteps = 2\n\
         step_limit = 100\nsafe_radius = 0.1\n[start]\nlow = [-0.2, -0.2]\nhigh = [0.2, 0.2]\n\
         [[goal]]\nname = \"g\"\ncenter = [1.0, 0.0]\nradius = 0.6\n",
    )
    .unwrap();
    std::fs::write(dir.join("easy.stl"), "F[1,2] g & G[1,2] safe\n").unwrap();
    scratch
}

fn updates(run: &Path) -> Vec<u64> {
    std::fs::read_to_string(run.join("metrics.jsonl"))
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str::<serde_json::Value>(l).unwrap()["update"].as_u64().unwrap())
        .collect()
}

#[test]
fn tltl_trains_resumes_refuses_to_clobber_evaluates_and_plots() {
    let scratch = workspace();
    let dir = scratch.path();
    let task = dir.join("easy.toml");
    let run = dir.join("run");
    let (task, out) = (task.to_str().unwrap(), run.to_str().unwrap());
    let train = |extra: &[&str]| {
        let mut a = vec!["baseline", "train", "--algo", "tltl", "--out", out];
        a.extend_from_slice(extra);
        schrl(&a)
    };
    let o = train(&["--task", task, "--steps", "8000", "--eval-groups", "1"]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    assert!(text(&o.stdout).contains("satisfaction: "), "{}", text(&o.stdout));
    for f in ["manifest.json", "metrics.jsonl", "training_curve.png", "episodes.png"] {
        assert!(run.join(f).exists(), "{f} missing");
    }
    let manifest: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(run.join("manifest.json")).unwrap()).unwrap();
    assert_eq!(manifest["kind"], "tltl");
    assert_eq!(updates(&run), [1, 2]);

    let o = train(&["--task", task, "--steps", "4000"]);
    assert!(!o.status.success() && text(&o.stderr).contains("--force"), "{}", text(&o.stderr));
    let o = train(&["--resume", "--machine", task]);
    assert!(!o.status.success() && text(&o.stderr).contains("--algo crm or dhrm"), "{}", text(&o.stderr));
    let o = train(&["--resume", "--seed", "9"]);
    assert!(!o.status.success() && text(&o.stderr).contains("--seed"), "{}", text(&o.stderr));

    // Resumed to a larger budget, the log continues where it stopped.
    let o = train(&["--resume", "--steps", "12000", "--eval-groups", "0"]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    assert_eq!(updates(&run), [1, 2, 3]);

    let o = schrl(&["baseline", "eval", "--ckpt", out, "--groups", "2", "--per-group", "10"]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    assert!(text(&o.stdout).contains("satisfaction: ") && text(&o.stdout).contains("collisions"));

    let png = dir.join("curves.png");
    let spec = format!("easy:tltl:{out}");
    let o = schrl(&["plot", "curves", "--run", &spec, "--run", &spec, "--out", png.to_str().unwrap()]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    assert!(std::fs::metadata(&png).unwrap().len() > 1000);
    let o = schrl(&["plot", "curves", "--run", out, "--out", png.to_str().unwrap(), "--force"]);
    assert!(!o.status.success() && text(&o.stderr).contains("TASK:METHOD:DIR"), "{}", text(&o.stderr));
}

#[test]
fn baseline_eval_names_a_directory_that_is_not_a_run() {
    let scratch = workspace();
    let dir = scratch.path();
    let o = schrl(&["baseline", "eval", "--ckpt", dir.join("nothing").to_str().unwrap()]);
    assert!(!o.status.success());
    assert!(text(&o.stderr).contains("nothing"), "{}", text(&o.stderr));
}

#[test]
fn crm_trains_with_a_machine_file_resumes_and_evaluates() {
    let scratch = workspace();
    let dir = scratch.path();
    let machine = dir.join("easy.rm.toml");
    std::fs::write(&machine, "initial = \"u0\"\nterminal = [\"done\"]\n[[edge]]\nfrom = \"u0\"\nto = \"done\"\non = \"g\"\nreward = 1.0\n")
        .unwrap();
    let (task, machine) = (dir.join("easy.toml"), machine.to_str().unwrap().to_string());
    let run = dir.join("run");
    let (task, out) = (task.to_str().unwrap(), run.to_str().unwrap());
    let train = |extra: &[&str]| {
        let mut a = vec!["baseline", "train", "--algo", "crm", "--out", out];
        a.extend_from_slice(extra);
        schrl(&a)
    };
    let o = train(&["--task", task, "--gamma", "0.999"]);
    assert!(
        !o.status.success() && text(&o.stderr).contains("--gamma is TLTL's discount"),
        "{}",
        text(&o.stderr)
    );
    // A user task has no shipped machine: the error says what to do.
    let o = train(&["--task", task, "--steps", "4000"]);
    assert!(
        !o.status.success() && text(&o.stderr).contains("no shipped reward machine"),
        "{}",
        text(&o.stderr)
    );
    let o = train(&["--task", task, "--machine", &machine, "--steps", "4000", "--eval-groups", "1"]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    let manifest: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(run.join("manifest.json")).unwrap()).unwrap();
    assert_eq!(manifest["kind"], "crm");
    assert!(manifest["files"]["crm.safetensors"]["sha256"].is_string());
    let other = dir.join("other.rm.toml");
    std::fs::write(&other, std::fs::read_to_string(&machine).unwrap().replace("1.0", "2.0")).unwrap();
    let o = train(&["--resume", "--machine", other.to_str().unwrap()]);
    assert!(!o.status.success() && text(&o.stderr).contains("--machine"), "{}", text(&o.stderr));
    let o = train(&["--resume", "--steps", "8000", "--eval-groups", "0"]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    assert_eq!(std::fs::read_to_string(run.join("metrics.jsonl")).unwrap().lines().count(), 2);
    let o = schrl(&["baseline", "eval", "--ckpt", out, "--groups", "1", "--per-group", "10"]);
    assert!(o.status.success() && text(&o.stdout).contains("satisfaction: "), "{}", text(&o.stderr));
    // A CRM run does not resume as DHRM.
    let o = schrl(&["baseline", "train", "--algo", "dhrm", "--out", out, "--resume"]);
    assert!(!o.status.success() && text(&o.stderr).contains("--algo"), "{}", text(&o.stderr));
    // DHRM trains on the same machine, and evaluates the same way.
    let dhrm = dir.join("dhrm");
    let dhrm = dhrm.to_str().unwrap();
    let o = schrl(&[
        "baseline",
        "train",
        "--algo",
        "dhrm",
        "--task",
        task,
        "--machine",
        &machine,
        "--steps",
        "4000",
        "--eval-groups",
        "0",
        "--out",
        dhrm,
    ]);
    assert!(o.status.success() && text(&o.stdout).contains("trained dhrm"), "{}", text(&o.stderr));
    // Regression: its log lines said "crm" (the run kind CRM and DHRM share).
    let log = text(&o.stderr);
    assert!(log.lines().any(|l| l.starts_with("dhrm ")) && !log.contains("crm "), "{log}");
    let o = schrl(&["baseline", "eval", "--ckpt", dhrm, "--groups", "1", "--per-group", "10"]);
    assert!(o.status.success() && text(&o.stdout).contains("satisfaction: "), "{}", text(&o.stderr));
}
