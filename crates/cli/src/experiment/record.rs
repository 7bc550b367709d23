//! A finished cell's record, the numbers read off its commands' output, and the merge
//! of records into `results.jsonl`.

use std::collections::BTreeMap;
use std::path::Path;

use anyhow::{Context, Result};
use serde::{Deserialize, Serialize};

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
/// environment steps (`metrics.jsonl` lines with `env_steps` and `score`): where a
/// training curve ends. `None` when the log has no scores.
pub fn final_score(run: &Path, window: f64) -> Result<Option<f64>> {
    let path = run.join("metrics.jsonl");
    let text = std::fs::read_to_string(&path).with_context(|| format!("reading {}", path.display()))?;
    let mut points = Vec::new();
    for line in text.lines().filter(|l| !l.trim().is_empty()) {
        let v: serde_json::Value =
            serde_json::from_str(line).with_context(|| format!("{}: a line is not JSON", path.display()))?;
        if let (Some(steps), Some(score)) = (v["env_steps"].as_f64(), v["score"].as_f64()) {
            points.push((steps, score));
        }
    }
    let Some(&(last, _)) = points.last() else { return Ok(None) };
    let tail: Vec<f64> = points.iter().filter(|(s, _)| *s > last - window).map(|(_, v)| *v).collect();
    Ok(Some(tail.iter().sum::<f64>() / tail.len() as f64))
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

/// Every record under `dir/cells/`, ordered by experiment, then cell position, then id.
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
    records.sort_by(|a, b| (&a.experiment, a.cell, &a.id).cmp(&(&b.experiment, b.cell, &b.id)));
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
    fn the_final_score_averages_the_last_window_of_steps() {
        let dir = std::env::temp_dir().join(format!("schrl-final-score-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let lines = [(100_000, -3.0), (150_000, -1.0), (200_000, 1.0), (250_000, 2.0)]
            .map(|(s, v)| format!("{{\"env_steps\":{s},\"score\":{v}}}"))
            .join("\n");
        std::fs::write(dir.join("metrics.jsonl"), lines + "\n{\"other\":1}\n").unwrap();
        assert_eq!(final_score(&dir, 100_000.0).unwrap(), Some(1.5));
        std::fs::write(dir.join("metrics.jsonl"), "{\"other\":1}\n").unwrap();
        assert_eq!(final_score(&dir, 100_000.0).unwrap(), None);
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
