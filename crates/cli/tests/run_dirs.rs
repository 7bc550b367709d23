//! Run directories under abuse: kills at random moments, Ctrl-C, a second writer,
//! directories of another kind, foreign files; and exact resume of every training
//! command (`control train`, `plan train`, `train`).

use std::path::Path;
use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant};

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

fn command<S: AsRef<std::ffi::OsStr>>(args: &[S]) -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_schrl"));
    c.env("RAYON_NUM_THREADS", "1").args(args);
    c
}

fn schrl<S: AsRef<std::ffi::OsStr>>(args: &[S]) -> Output {
    command(args).output().expect("runs")
}

fn spawn<S: AsRef<std::ffi::OsStr>>(args: &[S]) -> Child {
    command(args).stdout(Stdio::null()).stderr(Stdio::piped()).spawn().expect("starts")
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

fn manifest(dir: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(dir.join("manifest.json")).unwrap()).unwrap()
}

/// The checkpoint's files and their checksums: equal maps mean bit-identical runs.
fn files(dir: &Path) -> serde_json::Value {
    manifest(dir)["files"].clone()
}

/// The generation of the run's current checkpoint, if any.
fn generation(dir: &Path) -> Option<u64> {
    std::fs::read_to_string(dir.join("manifest.json"))
        .ok()
        .and_then(|t| serde_json::from_str::<serde_json::Value>(&t).ok())
        .and_then(|m| m["generation"].as_u64())
}

/// Waits until the run in `dir` has saved at least `n + 1` checkpoints.
fn wait_for_generation(child: &mut Child, dir: &Path, n: u64) {
    let start = Instant::now();
    while generation(dir).is_none_or(|g| g < n) {
        assert!(child.try_wait().unwrap().is_none(), "the run ended before checkpoint {n}");
        assert!(start.elapsed() < Duration::from_secs(120), "no checkpoint {n} within 2 minutes");
        std::thread::sleep(Duration::from_millis(20));
    }
}

fn sigint(child: &Child) {
    // SAFETY: signalling our own child process.
    unsafe {
        libc::kill(child.id() as libc::pid_t, libc::SIGINT);
    }
}

/// Kills `args`' process `kills` times at random moments, checking after each kill
/// that the directory loads with `check` (or has no checkpoint yet), resuming with
/// `resume` each time; then resumes to the end. At least two kills must land before
/// the run ends, or the test would not test anything.
fn kill_and_resume<S: AsRef<std::ffi::OsStr>>(
    dir: &Path,
    args: &[S],
    resume: &[&str],
    check: &[&str],
    kills: usize,
    seed: u64,
) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut child = spawn(args);
    let mut landed = 0;
    // The first kill waits for the run to claim its directory: before that, there
    // is nothing to resume and the command would rightly refuse.
    let start = Instant::now();
    while !dir.join("manifest.json").exists() {
        assert!(child.try_wait().unwrap().is_none() && start.elapsed() < Duration::from_secs(60));
        std::thread::sleep(Duration::from_millis(5));
    }
    for _ in 0..kills {
        std::thread::sleep(Duration::from_millis(rng.random_range(50..900)));
        if child.try_wait().unwrap().is_some() {
            break;
        }
        child.kill().unwrap();
        child.wait().unwrap();
        landed += 1;
        if generation(dir).is_some() {
            let o = schrl(check);
            assert!(o.status.success(), "a killed run does not load: {}", stderr(&o));
        }
        child = spawn(resume);
    }
    let o = child.wait_with_output().unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(landed >= 2, "only {landed} kills landed before the run ended");
}

/// A one-update controller run in `out`.
fn tiny_controller(out: &Path, seed: u64) {
    let seed = seed.to_string();
    let o = schrl(&[
        "control",
        "train",
        "--robot",
        "point",
        "--seed",
        &seed,
        "--steps",
        "4000",
        "--eval-episodes",
        "0",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
}

const CONTROL: [&str; 9] =
    ["control", "train", "--robot", "point", "--steps", "36000", "--save-every", "1", "--eval-episodes"];

fn control_args(out: &str) -> Vec<&str> {
    let mut a = CONTROL.to_vec();
    a.extend(["0", "--out", out]);
    a
}

#[test]
fn control_train_killed_at_random_moments_resumes_bit_for_bit() {
    let scratch = tempfile::tempdir().unwrap();
    let (straight, killed) = (scratch.path().join("control-straight"), scratch.path().join("control-killed"));
    let o = schrl(&control_args(straight.to_str().unwrap()));
    assert!(o.status.success(), "{}", stderr(&o));

    let out = killed.to_str().unwrap();
    let resume = ["control", "train", "--resume", "--eval-episodes", "0", "--out", out];
    let check = ["control", "eval", "--ckpt", out, "--episodes", "1"];
    kill_and_resume(&killed, &control_args(out), &resume, &check, 8, 1);
    assert_eq!(files(&killed), files(&straight), "resumed after kills, the run differs");
    let log = |d: &Path| -> Vec<u64> {
        std::fs::read_to_string(d.join("metrics.jsonl"))
            .unwrap()
            .lines()
            .map(|l| serde_json::from_str::<serde_json::Value>(l).unwrap()["update"].as_u64().unwrap())
            .collect()
    };
    assert_eq!(log(&killed), log(&straight), "the metrics log has gaps or repeats");
}

#[test]
fn ctrl_c_saves_and_the_resumed_run_is_bit_identical() {
    let scratch = tempfile::tempdir().unwrap();
    let (straight, stopped) = (scratch.path().join("sigint-straight"), scratch.path().join("sigint-stopped"));
    let o = schrl(&control_args(straight.to_str().unwrap()));
    assert!(o.status.success(), "{}", stderr(&o));
    let out = stopped.to_str().unwrap();
    let mut child = spawn(&control_args(out));
    wait_for_generation(&mut child, &stopped, 1);
    sigint(&child);
    let o = child.wait_with_output().unwrap();
    assert_eq!(o.status.code(), Some(130), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("interrupted: saved update") && stderr(&o).contains("--resume"),
        "{}",
        stderr(&o)
    );
    let o = schrl(&["control", "train", "--resume", "--eval-episodes", "0", "--out", out]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(files(&stopped), files(&straight));
}

#[test]
fn a_second_writer_is_refused_while_the_first_runs() {
    let scratch = tempfile::tempdir().unwrap();
    let dir = scratch.path().join("busy");
    let out = dir.to_str().unwrap();
    let mut args = control_args(out);
    args[5] = "400000";
    let mut first = spawn(&args);
    wait_for_generation(&mut first, &dir, 0);
    for second in [
        vec!["control", "train", "--resume", "--out", out],
        vec!["control", "train", "--robot", "point", "--force", "--out", out],
    ] {
        let o = schrl(&second);
        assert!(!o.status.success() && stderr(&o).contains("in use by another process"), "{}", stderr(&o));
    }
    first.kill().unwrap();
    first.wait().unwrap();
    // Once the writer is gone, the run resumes.
    let o = schrl(&["control", "train", "--resume", "--steps", "8000", "--eval-episodes", "0", "--out", out]);
    assert!(o.status.success(), "{}", stderr(&o));
}

#[test]
fn directories_of_another_kind_and_foreign_files_are_refused_by_name() {
    let scratch = tempfile::tempdir().unwrap();
    let dir = scratch.path().join("kinds");
    let ctrl = dir.join("controller");
    let c = ctrl.to_str().unwrap();
    tiny_controller(&ctrl, 0);
    let before = files(&ctrl);

    // Every other command refuses the controller run, naming both kinds.
    let refusals = [
        vec!["plan", "train", "--task", "seq", "--updates", "2", "--out", c],
        vec!["plan", "train", "--task", "seq", "--updates", "2", "--force", "--out", c],
        vec!["train", "--task", "seq", "--force", "--out", c],
        vec!["eval", "--ckpt", c],
        vec!["plan", "sample", "--ckpt", c],
    ];
    for args in refusals {
        let o = schrl(&args);
        let e = stderr(&o);
        assert!(
            !o.status.success() && e.contains("holds a controller run") && e.contains(c),
            "{args:?}: {e}"
        );
    }
    assert_eq!(files(&ctrl), before, "a refused command touched the run");
    assert!(schrl(&["control", "eval", "--ckpt", c, "--episodes", "1"]).status.success());

    // A directory with someone else's files is not written into.
    let foreign = dir.join("photos");
    std::fs::create_dir_all(&foreign).unwrap();
    std::fs::write(foreign.join("cat.jpg"), b"not a run").unwrap();
    let o = schrl(&[
        "plan",
        "train",
        "--task",
        "seq",
        "--updates",
        "2",
        "--force",
        "--out",
        foreign.to_str().unwrap(),
    ]);
    assert!(!o.status.success() && stderr(&o).contains("not a schrl run directory"), "{}", stderr(&o));
    assert_eq!(std::fs::read_dir(&foreign).unwrap().count(), 1);

    // A checkpoint file replaced by another run's is named with both checksums.
    let other = dir.join("other");
    tiny_controller(&other, 1);
    let name = |d: &Path| d.join(format!("gen-{}/controller.safetensors", generation(d).unwrap()));
    std::fs::copy(name(&other), name(&ctrl)).unwrap();
    let o = schrl(&["control", "eval", "--ckpt", c, "--episodes", "1"]);
    let e = stderr(&o);
    assert!(!o.status.success() && e.contains("controller.safetensors") && e.contains("checksum"), "{e}");
}

#[test]
fn plan_train_killed_or_interrupted_resumes_bit_for_bit() {
    let scratch = tempfile::tempdir().unwrap();
    let (straight, killed, stopped) = (
        scratch.path().join("plan-straight"),
        scratch.path().join("plan-killed"),
        scratch.path().join("plan-stopped"),
    );
    let args = |out: &Path| -> Vec<String> {
        ["plan", "train", "--task", "seq", "--updates", "400", "--target", "1", "--save-every", "10", "--out"]
            .iter()
            .map(|s| s.to_string())
            .chain([out.to_str().unwrap().to_string()])
            .collect()
    };
    let o = schrl(&args(&straight));
    assert!(o.status.success(), "{}", stderr(&o));

    let k = killed.to_str().unwrap();
    let a = args(&killed);
    kill_and_resume(
        &killed,
        &a,
        &["plan", "train", "--resume", "--out", k],
        &["plan", "sample", "--ckpt", k],
        5,
        2,
    );
    assert_eq!(files(&killed), files(&straight));

    let a = args(&stopped);
    let mut child = spawn(&a);
    wait_for_generation(&mut child, &stopped, 2);
    sigint(&child);
    assert_eq!(child.wait().unwrap().code(), Some(130));
    // Flags that would change the run are refused on resume, by name.
    let s = stopped.to_str().unwrap();
    let o = schrl(&["plan", "train", "--resume", "--seed", "3", "--semantics", "hard", "--out", s]);
    assert!(!o.status.success() && stderr(&o).contains("--semantics, --seed differ"), "{}", stderr(&o));
    let o = schrl(&["plan", "train", "--resume", "--out", s]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(files(&stopped), files(&straight));
}

#[test]
fn joint_train_killed_or_interrupted_resumes_bit_for_bit() {
    let scratch = tempfile::tempdir().unwrap();
    let dir = scratch.path().join("joint");
    let ctrl = dir.join("controller");
    let c = ctrl.to_str().unwrap();
    tiny_controller(&ctrl, 0);
    let args = |out: &str| -> Vec<String> {
        [
            "train",
            "--task",
            "seq",
            "--controller",
            c,
            "--pretrain-updates",
            "20",
            "--pretrain-candidates",
            "1",
            "--steps",
            "60000",
            "--target",
            "1",
            "--save-every",
            "2",
            "--select-every",
            "10000",
            "--eval-groups",
            "0",
            "--out",
            out,
        ]
        .iter()
        .map(|s| s.to_string())
        .collect()
    };
    let (straight, killed, stopped) = (dir.join("straight"), dir.join("killed"), dir.join("stopped"));
    let o = schrl(&args(straight.to_str().unwrap()));
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(manifest(&straight)["settings"]["pretrain"]["updates"] == 20);
    // Validated at the first iteration, the first past each 10 000 steps and the
    // last; the best is kept apart and is what `schrl eval` deploys.
    let generation = generation(&straight).unwrap();
    let selection: serde_json::Value = serde_json::from_slice(
        &std::fs::read(straight.join(format!("gen-{generation}")).join("selection.json")).unwrap(),
    )
    .unwrap();
    let at: Vec<u64> = selection["validations"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v["env_steps"].as_u64().unwrap())
        .collect();
    assert!(at.len() >= 3 && at[0] == 0, "{at:?}");
    assert!(at.windows(2).all(|w| w[0] < w[1]), "{at:?}");
    assert!(at[..at.len() - 1].windows(2).all(|w| w[1] / 10_000 > w[0] / 10_000), "{at:?}");
    let best = &selection["validations"][selection["best"].as_u64().unwrap() as usize];
    let deployed = best["iteration"].as_u64().unwrap();
    let o = schrl(&["eval", "--ckpt", straight.to_str().unwrap(), "--groups", "1", "--per-group", "2"]);
    let said = String::from_utf8_lossy(&o.stdout).into_owned();
    assert!(said.contains(&format!("deployed: the checkpoint of iteration {deployed} ")), "{said}");

    let k = killed.to_str().unwrap();
    let a = args(k);
    kill_and_resume(
        &killed,
        &a,
        &["train", "--resume", "--out", k],
        &["eval", "--ckpt", k, "--groups", "1", "--per-group", "2"],
        4,
        3,
    );
    assert_eq!(files(&killed), files(&straight));
    assert_eq!(files(&killed.join("best")), files(&straight.join("best")));

    let s = stopped.to_str().unwrap();
    let a = args(s);
    let mut child = spawn(&a);
    wait_for_generation(&mut child, &stopped, 2);
    sigint(&child);
    assert_eq!(child.wait().unwrap().code(), Some(130));
    let o = schrl(&["train", "--resume", "--pg-weight", "0.5", "--out", s]);
    assert!(!o.status.success() && stderr(&o).contains("--pg-weight differs"), "{}", stderr(&o));
    // The guide is on by default and saved so: turning it off would change the run.
    assert!(manifest(&stopped)["settings"]["pretrain"]["guide"] == true);
    let o = schrl(&["train", "--resume", "--no-pretrain-guide", "--out", s]);
    assert!(!o.status.success() && stderr(&o).contains("--no-pretrain-guide"), "{}", stderr(&o));
    let o = schrl(&["train", "--resume", "--out", s]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(files(&stopped), files(&straight));
    assert_eq!(files(&stopped.join("best")), files(&straight.join("best")));
}
