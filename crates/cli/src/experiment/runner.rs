//! Running cells: each step as a child `schrl`, its output kept beside its run, its
//! printed numbers in the cell's record.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::Instant;

use anyhow::{Context, Result, bail};
use serde::{Deserialize, Serialize};

use super::record::{self, Record};
use super::{Cell, Experiment, Step};

/// What an experiment folder holds: written once, checked by every later invocation
/// (array tasks included) so that runs of another experiment or another budget never
/// mix into it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Identity {
    /// Experiment name.
    pub experiment: String,
    /// Quick budgets.
    pub quick: bool,
}

/// The identity file of an experiment folder.
pub const IDENTITY: &str = "experiment.json";

/// Makes `dir` an experiment folder for `id`, or checks that it is one.
pub fn claim(dir: &Path, id: &Identity) -> Result<()> {
    std::fs::create_dir_all(dir.join("cells")).with_context(|| format!("creating {}", dir.display()))?;
    let path = dir.join(IDENTITY);
    if !path.exists() {
        // Concurrent array tasks may all get here: each writes the same text.
        schrl::store::write_atomic(&path, (serde_json::to_string_pretty(id)? + "\n").as_bytes())?;
    }
    let text = std::fs::read_to_string(&path).with_context(|| format!("reading {}", path.display()))?;
    let found: Identity = serde_json::from_str(&text)
        .with_context(|| format!("{}: not an experiment folder's identity", path.display()))?;
    if found != *id {
        let size = |q: bool| if q { "--quick" } else { "full-size" };
        bail!(
            "{} holds the {} experiment {}, not the {} experiment {}; choose another --out",
            dir.display(),
            size(found.quick),
            found.experiment,
            size(id.quick),
            id.experiment
        );
    }
    Ok(())
}

/// The folder of a cell.
pub fn cell_dir(dir: &Path, cell: &Cell) -> PathBuf {
    dir.join("cells").join(cell.id())
}

/// The arguments of a step in `cell_dir`: `@name` flag values become paths there; a
/// training step whose run directory already holds a run resumes it, unless `fresh`
/// (the invocation that makes the run from nothing, which a resumed run equals bit for
/// bit: what a record names).
pub fn arguments(step: &Step, cell_dir: &Path, fresh: bool) -> Vec<String> {
    let expand = |a: &String| match a.strip_prefix('@') {
        Some(name) => cell_dir.join(name).display().to_string(),
        None => a.clone(),
    };
    let mut args = step.command.clone();
    match &step.run {
        Some(run) => {
            let run = cell_dir.join(run);
            if !fresh && run.join(schrl::store::MANIFEST).exists() {
                args.push("--resume".into());
            } else {
                args.extend(step.flags.iter().map(expand));
            }
            args.extend(["--out".into(), run.display().to_string()]);
        }
        None => args.extend(step.flags.iter().map(expand)),
    }
    args
}

/// A command as a shell would take it: words quoted where they need to be.
pub fn shell_words(program: &str, args: &[String]) -> String {
    let quote = |w: &str| {
        let plain = !w.is_empty()
            && w.chars().all(|c| {
                c.is_ascii_alphanumeric() || matches!(c, '-' | '_' | '.' | '/' | ',' | ':' | '=' | '@')
            });
        if plain { w.to_string() } else { format!("'{}'", w.replace('\'', r"'\''")) }
    };
    std::iter::once(program).chain(args.iter().map(String::as_str)).map(quote).collect::<Vec<_>>().join(" ")
}

/// The commit HEAD named when this binary was built (`unknown` outside a git
/// checkout), ending in `-dirty` when tracked files had uncommitted changes.
pub const COMMIT: &str = match option_env!("SCHRL_GIT_COMMIT") {
    Some(c) => c,
    None => "unknown",
};

/// Runs every step of `cell` (the `index`-th of experiment `e`) with the binary `exe`,
/// then writes its record. Each step's output goes to `<cell>/<k>.out` and `.err`.
pub fn run_cell(
    exe: &Path,
    dir: &Path,
    e: Experiment,
    index: usize,
    cell: &Cell,
    quick: bool,
) -> Result<Record> {
    let cdir = cell_dir(dir, cell);
    std::fs::create_dir_all(&cdir).with_context(|| format!("creating {}", cdir.display()))?;
    let start = Instant::now();
    let mut rows = std::collections::BTreeMap::new();
    let mut commands = Vec::new();
    let mut curve = None;
    for (k, step) in cell.steps.iter().enumerate() {
        let args = arguments(step, &cdir, false);
        let typed = shell_words("schrl", &arguments(step, &cdir, true));
        let (out_path, err_path) = (cdir.join(format!("{k}.out")), cdir.join(format!("{k}.err")));
        let stderr =
            std::fs::File::create(&err_path).with_context(|| format!("creating {}", err_path.display()))?;
        let output = Command::new(exe)
            .args(&args)
            .stdin(Stdio::null())
            .stderr(stderr)
            .output()
            .with_context(|| format!("starting {}", exe.display()))?;
        std::fs::write(&out_path, &output.stdout)
            .with_context(|| format!("writing {}", out_path.display()))?;
        if !output.status.success() {
            let code = output.status.code();
            if code == Some(i32::from(crate::interrupt::EXIT_CODE)) {
                return Err(crate::interrupt::Interrupted {
                    message: format!(
                        "interrupted in cell {} ({}); its run was saved: rerun the experiment to resume it",
                        cell.id(),
                        typed
                    ),
                }
                .into());
            }
            let last = std::fs::read_to_string(&err_path).unwrap_or_default();
            let last = last.lines().rev().find(|l| !l.trim().is_empty()).unwrap_or("").trim().to_string();
            bail!(
                "cell {} failed at `{typed}` (exit {}): {last}\n(its output: {} and {}; rerun to resume the cell)",
                cell.id(),
                code.map_or("by a signal".into(), |c| c.to_string()),
                out_path.display(),
                err_path.display()
            );
        }
        if let Some(row) = &step.row {
            let mut metrics = record::metrics_of(&String::from_utf8_lossy(&output.stdout));
            if e == Experiment::Fig3
                && let Some(run) = &step.run
            {
                // One read of the run's log gives the final score and the kept curve.
                let scores = crate::commands::plot::scores(&cdir.join(run))?;
                if let Some(score) = record::final_score(&scores, FINAL_SCORE_WINDOW) {
                    metrics.insert("final score".into(), score);
                }
                curve = record::recorded_curve(&scores);
            }
            // Steps may share a row (Table 5 times its planners in two commands).
            rows.entry(row.clone()).or_insert_with(std::collections::BTreeMap::new).extend(metrics);
        }
        commands.push(typed);
    }
    if e == Experiment::Table6 {
        let options =
            cell.steps.iter().filter(|s| s.run.as_deref().is_some_and(|r| r.starts_with("option-"))).count();
        rows.extend(record::options_rows(&cdir, options)?);
    }
    let record = Record {
        experiment: e.name().into(),
        cell: index,
        id: cell.id(),
        robot: cell.robot.clone(),
        task: cell.task.clone(),
        method: cell.method.clone(),
        seed: cell.seed,
        quick,
        rows,
        commands,
        commit: COMMIT.into(),
        seconds: start.elapsed().as_secs_f64(),
        curve,
    };
    record::write(&cdir, &record)?;
    Ok(record)
}

/// Environment steps at the end of a training curve that its final score averages.
pub const FINAL_SCORE_WINDOW: f64 = 100_000.0;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_step_with_a_saved_run_resumes_it_and_cell_paths_expand() {
        let scratch = tempfile::tempdir().unwrap();
        let dir = scratch.path().join("args");
        let step = Step::train(
            Some("x"),
            "train",
            vec!["--task".into(), "seq".into(), "--controller".into(), "@general".into()],
            "run",
        );
        let fresh = arguments(&step, &dir, false);
        let general = dir.join("general").display().to_string();
        let run = dir.join("run").display().to_string();
        assert_eq!(fresh, ["train", "--task", "seq", "--controller", &general, "--out", &run]);
        std::fs::create_dir_all(dir.join("run")).unwrap();
        std::fs::write(dir.join("run").join(schrl::store::MANIFEST), "{}").unwrap();
        assert_eq!(arguments(&step, &dir, false), ["train", "--resume", "--out", &run]);
        assert_eq!(arguments(&step, &dir, true), fresh, "records name the fresh invocation");
    }

    #[test]
    fn commands_are_recorded_as_a_shell_takes_them() {
        let args: Vec<String> =
            ["plot", "curves", "--run", "seq:(a) SCHRL:x y", "it's"].map(String::from).to_vec();
        assert_eq!(shell_words("schrl", &args), r#"schrl plot curves --run 'seq:(a) SCHRL:x y' 'it'\''s'"#);
    }

    #[test]
    fn an_experiment_folder_refuses_another_experiment_or_budget() {
        let scratch = tempfile::tempdir().unwrap();
        let dir = scratch.path().join("claim");
        let id = |e: &str, quick| Identity { experiment: e.into(), quick };
        claim(&dir, &id("fig3", true)).unwrap();
        claim(&dir, &id("fig3", true)).unwrap();
        let err = claim(&dir, &id("fig3", false)).unwrap_err().to_string();
        assert!(
            err.contains("holds the --quick experiment fig3, not the full-size experiment fig3"),
            "{err}"
        );
        let err = claim(&dir, &id("table2", true)).unwrap_err().to_string();
        assert!(err.contains("choose another --out"), "{err}");
    }
}
