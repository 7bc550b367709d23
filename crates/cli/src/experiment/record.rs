//! A finished cell's record, the numbers read off its commands' output, and the merge
//! of records into `results.jsonl`.

use std::collections::BTreeMap;
use std::path::Path;

use anyhow::{Context, Result};
use serde::{Deserialize, Serialize};

use crate::commands::plot::Curve;

/// What a finished cell measured, and how.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Record {
    /// Experiment name.
    pub experiment: String,
    /// The cell's position in the experiment's list (`--list`) when it ran.
    pub cell: usize,
    /// The cell's id (its folder under `cells/`).
    pub id: String,
    /// Robot.
    pub robot: String,
    /// Task.
    pub task: String,
    /// Method or variant.
    pub method: String,
    /// Seed.
    pub seed: u64,
    /// Quick budgets.
    pub quick: bool,
    /// The results: row name → metric → value.
    pub rows: BTreeMap<String, BTreeMap<String, f64>>,
    /// The invocations that produced them, as typed in a shell.
    pub commands: Vec<String>,
    /// The git commit this binary was built from.
    pub commit: String,
    /// Wall-clock seconds of the cell's steps in the invocation that finished it.
    pub seconds: f64,
    /// Fig. 3's cells: the run's spec score against environment steps, thinned to
    /// [`CURVE_POINTS`], so the figure can be redrawn from the records alone (`schrl
    /// plot curves --results`) once the runs' folders are gone.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub curve: Option<Curve>,
}

/// Points a record keeps of its run's curve: 200, which figures of 40, 50 or 100 bins
/// divide.
pub const CURVE_POINTS: usize = 200;

/// A run's curve as a record keeps it; `None` when the run logged no score.
pub fn recorded_curve(curve: &Curve) -> Option<Curve> {
    (!curve.points.is_empty()).then(|| curve.thinned(CURVE_POINTS))
}

/// The run folder of Fig. 3's cell `id` in the experiment folder `dir` (each of its
/// cells trains one run, `run`).
pub fn fig3_run(dir: &Path, id: &str) -> std::path::PathBuf {
    dir.join("cells").join(id).join("run")
}

/// Gives every Fig. 3 record under `dir/cells/` that has no curve its run's, where the
/// run's folder still holds one (records written before curves were kept); returns how
/// many it filled.
pub fn fill_curves(dir: &Path) -> Result<usize> {
    let mut filled = 0;
    for mut r in all(dir)? {
        let run = fig3_run(dir, &r.id);
        if r.experiment != super::Experiment::Fig3.name()
            || r.curve.is_some()
            || !run.join("metrics.jsonl").exists()
        {
            continue;
        }
        r.curve = recorded_curve(&crate::commands::plot::scores(&run)?);
        if r.curve.is_some() {
            write(&dir.join("cells").join(&r.id), &r)?;
            filled += 1;
        }
    }
    Ok(filled)
}

/// The numbers a command printed: every line `name: value` or `name: mean ± std`
/// (`satisfaction: 0.998 ± 0.004` gives `satisfaction` 0.998 and `satisfaction std`
/// 0.004). Lines whose value is not a number (`steps to reach: -`) are not numbers.
pub fn metrics_of(output: &str) -> BTreeMap<String, f64> {
    let mut out = BTreeMap::new();
    for line in output.lines() {
        let Some((name, value)) = line.split_once(": ") else { continue };
        let name = name.trim();
        let named = !name.is_empty()
            && name.chars().all(|c| c.is_ascii_alphanumeric() || matches!(c, ' ' | '-' | '_'));
        if !named {
            continue;
        }
        let mut parts = value.trim().split(" ± ");
        let Some(Ok(mean)) = parts.next().map(str::parse::<f64>) else { continue };
        match parts.next().map(str::parse::<f64>) {
            None => {
                out.insert(name.to_string(), mean);
            }
            Some(Ok(std)) if parts.next().is_none() => {
                out.insert(name.to_string(), mean);
                out.insert(format!("{name} std"), std);
            }
            Some(_) => {}
        }
    }
    out
}

/// The mean spec score of a run's training episodes logged in its last `window`
/// environment steps (its curve's, [`crate::commands::plot::scores`]): where a training
/// curve ends. `None` when the log has no scores.
pub fn final_score(curve: &Curve, window: f64) -> Option<f64> {
    let points = &curve.points;
    let &(last, _) = points.last()?;
    let tail: Vec<f64> = points.iter().filter(|(s, _)| *s > last - window).map(|(_, v)| *v).collect();
    Some(tail.iter().sum::<f64>() / tail.len() as f64)
}

/// Success over the last 100 settled goals at which a controller run counts as
/// converged (Table 6).
pub const CONVERGED_SUCCESS: f64 = 0.95;
/// Goals that must have been settled (reached, or lost with their episode) before a
/// success rate counts.
pub const CONVERGED_AFTER_GOALS: f64 = 100.0;

/// The environment steps of a `control train` run's first update whose success rate
/// over the last 100 settled goals is ≥ 0.95, once 100 goals have been settled in all
/// (`metrics.jsonl`: `steps`, `success_rate`, `goals_settled`); `None` if it never was.
pub fn steps_to_converge(run: &Path) -> Result<Option<f64>> {
    let path = run.join("metrics.jsonl");
    let text = std::fs::read_to_string(&path).with_context(|| format!("reading {}", path.display()))?;
    let mut settled = 0.0;
    for line in text.lines().filter(|l| !l.trim().is_empty()) {
        let v: serde_json::Value =
            serde_json::from_str(line).with_context(|| format!("{}: a line is not JSON", path.display()))?;
        settled += v["goals_settled"].as_f64().unwrap_or(0.0);
        if let (Some(steps), Some(success)) = (v["steps"].as_f64(), v["success_rate"].as_f64())
            && settled >= CONVERGED_AFTER_GOALS
            && success >= CONVERGED_SUCCESS
        {
            return Ok(Some(steps));
        }
    }
    Ok(None)
}

/// Table 6's rows from a cell's runs `conditioned` and `option-0`..: the steps until
/// the goal-conditioned controller converged, and for k = 1, 2, 4 options the sum over
/// the first k options (absent when one of them never converged). `never converged`
/// counts the row's runs that did not.
pub fn options_rows(cell_dir: &Path, options: usize) -> Result<BTreeMap<String, BTreeMap<String, f64>>> {
    const METRIC: &str = "steps to converge";
    let mut rows = BTreeMap::new();
    let conditioned = steps_to_converge(&cell_dir.join("conditioned"))?;
    let each: Vec<Option<f64>> = (0..options)
        .map(|i| steps_to_converge(&cell_dir.join(format!("option-{i}"))))
        .collect::<Result<_>>()?;
    let mut row = |name: String, runs: &[Option<f64>]| {
        let never = runs.iter().filter(|s| s.is_none()).count();
        let mut m = BTreeMap::from([("never converged".to_string(), never as f64)]);
        if let Some(sum) = runs.iter().copied().sum::<Option<f64>>() {
            m.insert(METRIC.into(), sum);
        }
        rows.insert(name, m);
    };
    row("goal-conditioned".into(), &[conditioned]);
    for k in [1, 2, 4].into_iter().filter(|&k| k <= options) {
        row(format!("{k} option{}", if k == 1 { "" } else { "s" }), &each[..k]);
    }
    Ok(rows)
}

/// Reads the record of a cell folder, `None` when the cell has not finished.
pub fn read(cell_dir: &Path) -> Result<Option<Record>> {
    let path = cell_dir.join(RECORD);
    match std::fs::read_to_string(&path) {
        Ok(text) => serde_json::from_str(&text)
            .map(Some)
            .with_context(|| format!("{}: not a cell record; delete it to rerun the cell", path.display())),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(None),
        Err(e) => Err(e).with_context(|| format!("reading {}", path.display())),
    }
}

/// Writes a cell's record atomically: the cell counts as finished from then on.
pub fn write(cell_dir: &Path, record: &Record) -> Result<()> {
    let text = serde_json::to_string_pretty(record)? + "\n";
    schrl::store::write_atomic(&cell_dir.join(RECORD), text.as_bytes())?;
    Ok(())
}

/// A cell's record file.
pub const RECORD: &str = "record.json";

/// Every record under `dir/cells/`, ordered by experiment, then the cell's place in the
/// experiment's full list ([`super::catalog::rank`]), then id.
pub fn all(dir: &Path) -> Result<Vec<Record>> {
    let cells = dir.join("cells");
    let mut records = Vec::new();
    let entries = match std::fs::read_dir(&cells) {
        Ok(e) => e,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(records),
        Err(e) => return Err(e).with_context(|| format!("reading {}", cells.display())),
    };
    for entry in entries {
        let entry = entry.with_context(|| format!("reading {}", cells.display()))?;
        if let Some(r) = read(&entry.path())? {
            records.push(r);
        }
    }
    let rank = |r: &Record| super::catalog::rank(&r.experiment, &r.robot, &r.task, &r.method, r.seed);
    records.sort_by(|a, b| (&a.experiment, rank(a), &a.id).cmp(&(&b.experiment, rank(b), &b.id)));
    Ok(records)
}

/// Rewrites `dir/results.jsonl` from the records of every finished cell (one line
/// each), atomically: cells finishing concurrently each write only their own record,
/// so a merge never loses one, and the last merge sees them all.
pub fn merge(dir: &Path) -> Result<Vec<Record>> {
    let records = all(dir)?;
    let mut text = String::new();
    for r in &records {
        text += &serde_json::to_string(r)?;
        text.push('\n');
    }
    schrl::store::write_atomic(&dir.join(RESULTS), text.as_bytes())?;
    Ok(records)
}

/// The merged results file of an experiment folder.
pub const RESULTS: &str = "results.jsonl";

/// Reads a results file.
pub fn read_results(path: &Path) -> Result<Vec<Record>> {
    let text = std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    text.lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty())
        .map(|(i, l)| {
            serde_json::from_str(l)
                .with_context(|| format!("{} line {}: not a cell record", path.display(), i + 1))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn merged_records_follow_the_full_list_whatever_selection_ran_them() {
        // Signal's cells ran with `--tasks signal` (positions 0, 1), Seq's with every
        // task (positions 0–2 too): ordered by position, the rows came out interleaved.
        let scratch = tempfile::tempdir().unwrap();
        let dir = scratch.path().join("merge-order");
        let record = |task: &str, method: &str, cell: usize| Record {
            cell,
            ..crate::report::tests::record("fig3", task, method, 0, &[])
        };
        for r in [record("signal", "htltl", 1), record("signal", "schrl", 0), record("seq", "tltl", 2)] {
            let cell = dir.join("cells").join(&r.id);
            std::fs::create_dir_all(&cell).unwrap();
            write(&cell, &r).unwrap();
        }
        let ids: Vec<String> = merge(&dir).unwrap().into_iter().map(|r| r.id).collect();
        assert_eq!(ids, ["point-seq-tltl-0", "point-signal-schrl-0", "point-signal-htltl-0"]);
    }

    #[test]
    fn records_written_before_curves_were_kept_get_their_runs_curves() {
        let scratch = tempfile::tempdir().unwrap();
        let dir = scratch.path();
        let old = crate::report::tests::record("fig3", "seq", "crm", 0, &[]);
        let (cell, run) = (dir.join("cells").join(&old.id), fig3_run(dir, &old.id));
        std::fs::create_dir_all(&run).unwrap();
        write(&cell, &old).unwrap();
        std::fs::write(run.join(schrl::store::MANIFEST), r#"{"kind":"crm"}"#).unwrap();
        let lines =
            "{\"env_steps\":1000,\"score\":-2.0}\n{\"env_steps\":1500}\n{\"env_steps\":2000,\"score\":1.0}\n";
        std::fs::write(run.join("metrics.jsonl"), lines).unwrap();
        assert_eq!(fill_curves(dir).unwrap(), 1);
        let curve = read(&cell).unwrap().unwrap().curve.expect("filled");
        assert_eq!(curve.points, [(1000.0, -2.0), (2000.0, 1.0)]);
        assert_eq!(fill_curves(dir).unwrap(), 0, "a record with a curve keeps it");
        // The merged results carry it once the run's folder is gone.
        merge(dir).unwrap();
        std::fs::remove_dir_all(&run).unwrap();
        assert_eq!(read_results(&dir.join(RESULTS)).unwrap()[0].curve, Some(curve));
    }

    #[test]
    fn metrics_are_read_off_the_lines_commands_print() {
        let out = "trained point on seq for 738 iterations; run in x\n\
                   satisfaction: 0.998 ± 0.004\n\
                   steps to reach: -\n\
                   failures: 0 collisions, 0 falls\n\
                   updates: 130\n\
                   network seconds per plan: 1.5e-4\n\
                   wrote runs/x/episodes.png\n";
        let m = metrics_of(out);
        assert_eq!(m["satisfaction"], 0.998);
        assert_eq!(m["satisfaction std"], 0.004);
        assert_eq!(m["updates"], 130.0);
        assert_eq!(m["network seconds per plan"], 1.5e-4);
        assert!(!m.contains_key("steps to reach"));
        assert_eq!(m.len(), 4, "{m:?}");
    }

    #[test]
    fn convergence_waits_for_100_settled_goals_and_options_add_up() {
        let scratch = tempfile::tempdir().unwrap();
        let dir = scratch.path().join("converge");
        let log = |name: &str, lines: &[(u64, f64, u64)]| {
            let run = dir.join(name);
            std::fs::create_dir_all(&run).unwrap();
            let text: Vec<String> = lines
                .iter()
                .map(|(s, r, g)| format!("{{\"steps\":{s},\"success_rate\":{r},\"goals_settled\":{g}}}"))
                .collect();
            std::fs::write(run.join("metrics.jsonl"), text.join("\n")).unwrap();
        };
        // Success 1.0 after 60 goals does not count; 0.96 after 120 does.
        log("conditioned", &[(4000, 1.0, 60), (8000, 0.9, 40), (12000, 0.96, 20), (16000, 1.0, 30)]);
        log("option-0", &[(4000, 0.97, 150)]);
        log("option-1", &[(4000, 0.5, 150), (8000, 0.95, 10)]);
        log("option-2", &[(4000, 0.97, 150)]);
        log("option-3", &[(4000, 0.2, 150)]);
        assert_eq!(steps_to_converge(&dir.join("conditioned")).unwrap(), Some(12000.0));
        let rows = options_rows(&dir, 4).unwrap();
        assert_eq!(rows["goal-conditioned"]["steps to converge"], 12000.0);
        assert_eq!(rows["1 option"]["steps to converge"], 4000.0);
        assert_eq!(rows["2 options"]["steps to converge"], 12000.0);
        assert!(!rows["4 options"].contains_key("steps to converge"), "option 3 never converged");
        assert_eq!(rows["4 options"]["never converged"], 1.0);
    }

    #[test]
    fn the_final_score_averages_the_last_window_of_steps() {
        let scratch = tempfile::tempdir().unwrap();
        let dir = scratch.path();
        std::fs::write(dir.join(schrl::store::MANIFEST), r#"{"kind":"tltl"}"#).unwrap();
        let lines = [(100_000, -3.0), (150_000, -1.0), (200_000, 1.0), (250_000, 2.0)]
            .map(|(s, v)| format!("{{\"env_steps\":{s},\"score\":{v}}}"))
            .join("\n");
        std::fs::write(dir.join("metrics.jsonl"), lines + "\n{\"env_steps\":260000}\n").unwrap();
        let score = |dir| final_score(&crate::commands::plot::scores(dir).unwrap(), 100_000.0);
        assert_eq!(score(dir), Some(1.5));
        std::fs::write(dir.join("metrics.jsonl"), "{\"env_steps\":1}\n").unwrap();
        assert_eq!(score(dir), None);
    }
}
