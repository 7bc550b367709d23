//! `schrl experiment` and `schrl report` end to end at quick size: every experiment
//! runs, finished cells are skipped, concurrent array tasks merge, the deploy files'
//! index mapping picks the right cell, and the report page renders in Chromium.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn schrl(args: &[&str]) -> Output {
    schrl_env(args, &[])
}

fn schrl_env(args: &[&str], env: &[(&str, &str)]) -> Output {
    let mut c = Command::new(env!("CARGO_BIN_EXE_schrl"));
    c.env("RAYON_NUM_THREADS", "1").env_remove("SLURM_ARRAY_TASK_ID").env_remove("JOB_COMPLETION_INDEX");
    c.envs(env.iter().copied()).args(args).output().expect("runs")
}

fn text(b: &[u8]) -> String {
    String::from_utf8_lossy(b).into_owned()
}

fn ok(o: &Output) -> String {
    assert!(o.status.success(), "stdout: {}\nstderr: {}", text(&o.stdout), text(&o.stderr));
    text(&o.stdout)
}

fn results(dir: &Path) -> Vec<serde_json::Value> {
    std::fs::read_to_string(dir.join("results.jsonl"))
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect()
}

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// `schrl experiment E --quick` on seed 0 (and Seq, where the experiment has tasks) into `out`.
fn quick(e: &str, out: &Path) -> Output {
    let tasks: &[&str] = if e == "controllers" { &[] } else { &["--tasks", "seq"] };
    schrl(
        &[&["experiment", e, "--quick", "--seeds", "0", "--out", out.to_str().unwrap()][..], tasks].concat(),
    )
}

/// The quick runs every other test here reads, made once.
fn quick_runs() -> &'static PathBuf {
    static RUNS: std::sync::OnceLock<PathBuf> = std::sync::OnceLock::new();
    RUNS.get_or_init(|| {
        // Shared by the tests of this process, so no guard can remove it when they
        // end: under cargo's scratch space for integration tests (target/tmp), afresh.
        let root = Path::new(env!("CARGO_TARGET_TMPDIR")).join("experiment-quick-runs");
        let _ = std::fs::remove_dir_all(&root);
        for e in ["controllers", "table2", "table3-4", "table5", "table6", "table7", "fig3", "fig4", "fig6"] {
            ok(&quick(e, &root.join(e)));
        }
        root
    })
}

#[test]
fn every_experiment_runs_end_to_end_at_quick_size() {
    let root = quick_runs();
    let expect = [
        ("controllers", vec!["general controller"; 3], "success rate"),
        ("table2", vec!["cpg", "pg"], "updates"),
        ("table3-4", vec!["schrl", "schrl", "schrl", "schrl-neural-sdf"], "satisfaction"),
        ("table5", vec!["planning time"], "mip plans satisfying"),
        ("table6", vec!["4 options"], "never converged"),
        ("table7", vec!["soft", "hard"], "updates"),
        ("fig3", vec!["schrl", "htltl", "tltl", "crm", "dhrm"], "final score"),
        ("fig4", vec!["(a) SCHRL"], "satisfaction"),
        ("fig6", vec!["gru-ode", "gru", "mlp"], "mean-path satisfaction"),
    ];
    for (e, rows, metric) in expect {
        let records = results(&root.join(e));
        assert_eq!(records.len(), rows.len(), "{e}: one record per cell");
        for (r, row) in records.iter().zip(rows) {
            assert_eq!(r["experiment"], e);
            assert_eq!(r["quick"], true);
            assert!(r["rows"][row][metric].is_number(), "{e}: {r}");
            let commands = r["commands"].as_array().unwrap();
            assert!(commands.iter().all(|c| c.as_str().unwrap().starts_with("schrl ")), "{e}: {r}");
            // The build's git commit, marked when uncommitted changes were built.
            let commit = r["commit"].as_str().unwrap();
            let hash = commit.strip_suffix("-dirty").unwrap_or(commit);
            assert!(hash.len() == 40 && hash.chars().all(|c| c.is_ascii_hexdigit()), "{e}: {commit}");
        }
    }
    // Table 3–4 covers the three native robots, and the Drone with a neural SDF too;
    // Fig. 4 all four variants.
    let robots: Vec<_> = results(&root.join("table3-4")).iter().map(|r| r["robot"].clone()).collect();
    assert_eq!(robots, ["point", "car", "drone", "drone"]);
    assert!(results(&root.join("table3-4"))[0]["rows"]["schrl (sampled plans)"]["satisfaction"].is_number());
    // Fig. 4: its four variants, and (a) and (d) on sampled plans.
    let fig4 = &results(&root.join("fig4"))[0]["rows"];
    assert_eq!(fig4.as_object().unwrap().len(), 6);
    // Table 5: two commands fill its one row (network and gradient, then the MIP).
    let t5 = &results(&root.join("table5"))[0]["rows"]["planning time"];
    for key in ["network seconds per plan", "gradient plans satisfying", "mip seconds per plan"] {
        assert!(t5[key].is_number(), "{key}: {t5}");
    }
    // Controllers: goals anywhere, and the short hops of a plan.
    for r in results(&root.join("controllers")) {
        assert!(r["rows"]["general controller, goals within 1 m"]["success rate"].is_number(), "{r}");
    }
    // Table 6: the conditioned controller and the sums over 1, 2 and 4 options.
    assert_eq!(results(&root.join("table6"))[0]["rows"].as_object().unwrap().len(), 4);
    for picture in ["fig3.png", "fig3.svg", "fig4.png", "table3-4.png"] {
        let dir = root.join(&picture[..picture.find('.').unwrap()]);
        assert!(std::fs::metadata(dir.join(picture)).unwrap().len() > 1000, "{picture}");
    }
    // Fig. 3's records keep their runs' curves: the figure redraws from the results
    // file alone, where no run folder is.
    for r in results(&root.join("fig3")) {
        assert!(r["curve"]["points"].as_array().is_some_and(|p| !p.is_empty()), "{r}");
    }
    let scratch = tempfile::tempdir().unwrap();
    let kept = scratch.path().join("results.jsonl");
    std::fs::copy(root.join("fig3").join("results.jsonl"), &kept).unwrap();
    let png = scratch.path().join("fig3.png");
    ok(&schrl(&["plot", "curves", "--results", kept.to_str().unwrap(), "--out", png.to_str().unwrap()]));
    assert!(std::fs::metadata(&png).unwrap().len() > 1000);
}

/// Table 1 (Doggo) needs MuJoCo: CI runs it with `--features mujoco`.
#[cfg(feature = "mujoco")]
#[test]
fn table1_runs_doggo_at_quick_size() {
    let scratch = tempfile::tempdir().unwrap();
    let out = scratch.path();
    ok(&quick("table1", out));
    let r = &results(out)[0];
    assert_eq!(r["robot"], "doggo");
    assert!(r["rows"]["schrl"]["satisfaction"].is_number(), "{r}");
    assert!(out.join("table1.png").exists());
    // The Doggo's defaults: its controller observes and pays for its track, and the
    // joint phase pays three times as much (README, *The track in the controller's
    // observation*, *A heavier off-track weight in the joint phase*); the
    // run deploys its best validated checkpoint (*Selecting the deployed checkpoint*).
    let manifests = manifests_under(out);
    let kind = |k: &str| manifests.iter().filter(move |m| m["kind"] == k).collect::<Vec<_>>();
    assert!(!kind("controller").is_empty() && !kind("joint").is_empty(), "{manifests:?}");
    for m in kind("controller") {
        assert_eq!(m["settings"]["observe_track"], true, "{m}");
        assert_eq!(m["settings"]["off_track_weight"], 0.1, "{m}");
    }
    for m in kind("joint") {
        assert_eq!(m["settings"]["joint"]["off_track_weight"], 0.3, "{m}");
        assert_eq!(m["settings"]["select_every"], 250_000, "{m}");
    }
}

/// Every run manifest in `dir`'s tree.
#[cfg(feature = "mujoco")]
fn manifests_under(dir: &Path) -> Vec<serde_json::Value> {
    let mut found = vec![];
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.is_dir() {
            found.extend(manifests_under(&path));
        } else if path.file_name().is_some_and(|n| n == "manifest.json") {
            found.push(serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap());
        }
    }
    found
}

#[test]
fn finished_cells_are_skipped_and_another_budget_is_refused() {
    let root = quick_runs();
    let out = root.join("table2");
    let before = std::fs::read_to_string(out.join("results.jsonl")).unwrap();
    let again = ok(&quick("table2", &out));
    assert!(again.contains("2 of 2 cells finished (0 run now)"), "{again}");
    assert_eq!(std::fs::read_to_string(out.join("results.jsonl")).unwrap(), before);
    let full =
        schrl(&["experiment", "table2", "--seeds", "0", "--tasks", "seq", "--out", out.to_str().unwrap()]);
    assert!(!full.status.success());
    assert!(
        text(&full.stderr).contains("holds the --quick experiment table2, not the full-size"),
        "{}",
        text(&full.stderr)
    );
    let other = schrl(&["experiment", "fig6", "--quick", "--seeds", "0", "--out", out.to_str().unwrap()]);
    assert!(text(&other.stderr).contains("choose another --out"), "{}", text(&other.stderr));
}

#[test]
fn bad_selections_say_what_is_wrong() {
    let scratch = tempfile::tempdir().unwrap();
    let out = scratch.path();
    let o = out.to_str().unwrap();
    let cases: [(&[&str], &str); 5] = [
        (
            &["experiment", "fig3", "--tasks", "maze", "--out", o],
            "--tasks: fig3 has no tasks 'maze'; it has seq, cover",
        ),
        (
            &["experiment", "fig3", "--seeds", "3-1", "--out", o],
            "--seeds: '3-1' in '3-1': the range runs backwards",
        ),
        (
            &["experiment", "table2", "--robots", "car", "--out", o],
            "--robots: table2 has no robots 'car'; it has point",
        ),
        (
            &["experiment", "fig3", "--cell", "500", "--out", o],
            "cell 500 does not exist: this selection has 125 cells",
        ),
        (&["experiment", "table9", "--out", o], "invalid value 'table9'"),
    ];
    for (args, want) in cases {
        let r = schrl(args);
        assert!(!r.status.success(), "{args:?}");
        assert!(text(&r.stderr).contains(want), "{args:?}: {}", text(&r.stderr));
    }
    if !cfg!(feature = "mujoco") {
        let r = schrl(&["experiment", "table1", "--quick", "--out", o]);
        assert!(text(&r.stderr).contains("table1 trains Doggo, which needs MuJoCo"), "{}", text(&r.stderr));
    }
    // Regression: a cell index out of range was refused after --out was claimed,
    // leaving experiment.json and cells/ behind.
    let left: Vec<_> = std::fs::read_dir(out).unwrap().map(|e| e.unwrap().file_name()).collect();
    assert!(left.is_empty(), "a refused selection left {left:?} in --out");
}

#[test]
fn array_tasks_from_the_deploy_files_run_their_own_cell_and_merge() {
    let scratch = tempfile::tempdir().unwrap();
    let out = scratch.path();
    let o = out.to_str().unwrap();
    let sel = ["--quick", "--seeds", "0-1", "--tasks", "seq"];
    let list = ok(&schrl(&[&["experiment", "fig6", "--list"][..], &sel].concat()));
    let ids: Vec<&str> = list.lines().map(|l| l.split('\t').nth(1).unwrap()).collect();
    assert_eq!(ids.len(), 6);
    // The Slurm script, as an array task runs it, and a Kubernetes index, concurrently.
    let sbatch = repo().join("deploy/slurm/experiment.sbatch");
    let bin = env!("CARGO_BIN_EXE_schrl");
    let mut slurm: Vec<_> = [1usize, 4]
        .iter()
        .map(|i| {
            Command::new("bash")
                .arg(&sbatch)
                .args([&["fig6", o][..], &sel].concat())
                .env("SLURM_ARRAY_TASK_ID", i.to_string())
                .env("SCHRL_BIN", bin)
                .env_remove("JOB_COMPLETION_INDEX")
                .spawn()
                .unwrap()
        })
        .collect();
    let k8s = schrl_env(
        &[&["experiment", "fig6", "--out", o][..], &sel].concat(),
        &[("JOB_COMPLETION_INDEX", "2")],
    );
    ok(&k8s);
    for child in &mut slurm {
        assert!(child.wait().unwrap().success());
    }
    let done: Vec<String> = std::fs::read_dir(out.join("cells"))
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| e.path().join("record.json").exists())
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .collect();
    let mut want = vec![ids[1], ids[2], ids[4]];
    let mut done_sorted = done.clone();
    done_sorted.sort();
    want.sort();
    assert_eq!(done_sorted, want, "exactly the indexed cells ran");
    // A run without an index finishes the rest (two cells at a time) and merges every
    // record in cell order.
    let last = ok(&schrl(&[&["experiment", "fig6", "--jobs", "2", "--out", o][..], &sel].concat()));
    assert!(last.contains("6 of 6 cells finished (3 run now)"), "{last}");
    let merged: Vec<_> = results(out).iter().map(|r| r["id"].as_str().unwrap().to_string()).collect();
    assert_eq!(merged, ids);
    // The Kubernetes manifest runs the same command, with the index from the Job.
    let job = std::fs::read_to_string(repo().join("deploy/kubernetes/experiment-job.yaml")).unwrap();
    assert!(job.contains("completionMode: Indexed"));
    assert!(job.contains(r#"command: ["schrl", "experiment", "fig3""#) && !job.contains("--cell"));
    let n = ok(&schrl(&["experiment", "fig3", "--seeds", "0-4", "--list"])).lines().count();
    assert!(
        job.contains(&format!("completions: {n}\n")),
        "the manifest's completions match its cell list ({n})"
    );
}

/// Chromium: `$CHROMIUM`, else `chromium` on PATH. CI must have it
/// (scripts/setup-chromium.sh); elsewhere the page check is skipped with a note.
fn chromium() -> Option<String> {
    let name = std::env::var("CHROMIUM").unwrap_or_else(|_| "chromium".into());
    let found = Command::new(&name).arg("--version").output().is_ok_and(|o| o.status.success());
    if !found && std::env::var("CI").is_ok_and(|v| v == "true") {
        panic!("CI needs Chromium for the report page test: run scripts/setup-chromium.sh");
    }
    found.then_some(name)
}

#[test]
fn the_report_has_every_table_and_its_page_renders_tables_and_pictures() {
    let root = quick_runs();
    let scratch = tempfile::tempdir().unwrap();
    let report = scratch.path();
    let dirs: Vec<String> =
        ["table2", "table3-4", "fig3", "fig4"].iter().map(|e| root.join(e).display().to_string()).collect();
    let out = report.join("site");
    let mut args = vec!["report"];
    args.extend(dirs.iter().map(String::as_str));
    args.extend(["--out", out.to_str().unwrap()]);
    ok(&schrl(&args));
    let md = std::fs::read_to_string(out.join("report.md")).unwrap();
    for heading in ["## Table 2", "## Tables 3 and 4", "## Fig. 3", "## Fig. 4"] {
        assert!(md.contains(heading), "{heading} in\n{md}");
    }
    assert!(md.contains("| point | seq | (c) gradient planner | 1 |"), "{md}");
    assert!(md.contains("](images/"), "pictures linked");
    let again = schrl(&args);
    assert!(text(&again.stderr).contains("already holds a report; pass --force"), "{}", text(&again.stderr));
    let Some(chromium) = chromium() else {
        eprintln!("note: no Chromium (scripts/setup-chromium.sh); the page was not rendered");
        return;
    };
    let profile = report.join("profile");
    let dom = Command::new(chromium)
        .args([
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--disable-quic",
            "--no-first-run",
            "--disable-background-networking",
            "--disable-component-update",
            "--disable-sync",
            "--virtual-time-budget=10000",
        ])
        .arg(format!("--user-data-dir={}", profile.display()))
        .arg("--dump-dom")
        .arg(format!("file://{}", out.join("index.html").canonicalize().unwrap().display()))
        .output()
        .unwrap();
    let dom = text(&dom.stdout);
    let body = dom.split("<body").nth(1).and_then(|b| b.split('>').next()).unwrap_or_default();
    assert!(body.contains(r#"data-tables="4""#), "four tables with rows: <body{body}>");
    let images = body.split(r#"data-images=""#).nth(1).and_then(|s| s.split('"').next()).unwrap_or_default();
    let (shown, all) = images.split_once(" of ").unwrap_or_else(|| panic!("no image count: <body{body}>"));
    assert!(all.parse::<usize>().unwrap() >= 4 && shown == all, "every picture decoded: {images}");
}
