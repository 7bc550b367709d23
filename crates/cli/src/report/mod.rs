//! `schrl report`: experiment results as tables (markdown, for the README) and one
//! static HTML page with the tables, plots and episode pictures.
//!
//! Every number in a table is a mean ± sample std over seeds of what the cells
//! recorded ([`crate::experiment::record`]); nothing is typed in by hand.

pub mod html;
pub mod markdown;

use std::collections::BTreeMap;

use crate::experiment::Experiment;
use crate::experiment::record::Record;

/// A column: the metric it shows, its heading, and how its values are written.
struct Column {
    metric: &'static str,
    heading: &'static str,
    format: fn(f64) -> String,
    /// A count: summed over seeds, not averaged.
    total: bool,
}

fn fixed3(x: f64) -> String {
    format!("{x:.3}")
}

fn fixed1(x: f64) -> String {
    format!("{x:.1}")
}

fn whole(x: f64) -> String {
    format!("{x:.0}")
}

fn sci(x: f64) -> String {
    format!("{x:.2e}")
}

fn columns(e: Experiment) -> Vec<Column> {
    let col = |metric, heading, format| Column { metric, heading, format, total: false };
    let executed = vec![
        col("satisfaction", "satisfaction", fixed3 as fn(f64) -> String),
        col("steps to reach", "steps to reach", fixed1),
    ];
    match e {
        Experiment::Table1 | Experiment::Table34 | Experiment::Fig4 => executed,
        Experiment::Fig3 => {
            let mut c = executed;
            c.push(col("final score", "final spec score (last 100 k steps)", fixed3));
            c
        }
        Experiment::Table2 | Experiment::Table7 | Experiment::Fig6 => vec![
            col("updates to target", "updates until 95 % (seeds that got there)", whole),
            col("satisfaction", "satisfaction (sampled paths)", fixed3),
            col("mean-path satisfaction", "satisfaction (mean paths)", fixed3),
        ],
        Experiment::Table6 => vec![
            col("steps to converge", "environment steps until convergence", sci),
            Column {
                metric: "never converged",
                heading: "runs that never converged (all seeds)",
                format: whole,
                total: true,
            },
        ],
        Experiment::Controllers => vec![
            col("success rate", "success rate", fixed3),
            col("mean steps to reach", "steps to reach", fixed1),
        ],
        Experiment::Table5 => vec![
            col("network seconds per plan", "network (s per plan)", sci),
            col("network plans satisfying", "plans satisfying", whole),
            col("gradient seconds per plan", "gradient planner (s per plan)", sci),
            col("gradient plans satisfying", "plans satisfying", whole),
            col("mip seconds per plan", crate::experiment::catalog::TABLE5_MIP_HEADING, sci),
            col("mip plans satisfying", "plans satisfying", whole),
        ],
    }
}

/// One experiment's table.
#[derive(Clone, Debug, PartialEq)]
pub struct Table {
    /// The experiment.
    pub experiment: Experiment,
    /// Whether its cells ran with quick budgets.
    pub quick: bool,
    /// Column headings.
    pub headings: Vec<String>,
    /// Cells of each row, as text.
    pub rows: Vec<Vec<String>>,
    /// The seeds the rows average over.
    pub seeds: Vec<u64>,
    /// The commits the records were made at.
    pub commits: Vec<String>,
}

/// `mean ± std` of `xs` in `format` (`-` for none; the value alone for one).
fn summary(xs: &[f64], format: fn(f64) -> String) -> String {
    match xs.len() {
        0 => "-".into(),
        1 => format(xs[0]),
        _ => {
            let (m, s) = schrl::run::evaluate::mean_std(xs);
            format!("{} ± {}", format(m), format(s))
        }
    }
}

/// A table row's robot, task and method or variant.
type RowKey = (String, String, String);

/// The table of one experiment's records: a row per (robot, task, method or variant)
/// in the order the cells ran, each value over the seeds that recorded it.
pub fn table(e: Experiment, records: &[&Record]) -> Table {
    let cols = columns(e);
    // (robot, task, row) → per metric, the values over seeds, and how many seeds.
    let mut order: Vec<RowKey> = vec![];
    let mut values: BTreeMap<RowKey, (BTreeMap<&str, Vec<f64>>, usize)> = BTreeMap::new();
    for r in records {
        for (row, metrics) in &r.rows {
            let key = (r.robot.clone(), r.task.clone(), row.clone());
            if !order.contains(&key) {
                order.push(key.clone());
            }
            let entry = values.entry(key).or_default();
            entry.1 += 1;
            for c in &cols {
                if let Some(&v) = metrics.get(c.metric) {
                    entry.0.entry(c.metric).or_default().push(v);
                }
            }
        }
    }
    let mut headings: Vec<String> = ["robot", "task", "method", "seeds"].map(String::from).to_vec();
    headings.extend(cols.iter().map(|c| c.heading.to_string()));
    let rows = order
        .iter()
        .map(|key| {
            let (metrics, seeds) = &values[key];
            let mut cells = vec![key.0.clone(), key.1.clone(), key.2.clone(), seeds.to_string()];
            for c in &cols {
                let xs = metrics.get(c.metric).map_or(&[][..], Vec::as_slice);
                let mut text = if c.total { whole(xs.iter().sum()) } else { summary(xs, c.format) };
                if !xs.is_empty() && xs.len() < *seeds {
                    text += &format!(" ({} of {seeds} seeds)", xs.len());
                }
                cells.push(text);
            }
            cells
        })
        .collect();
    let mut seeds: Vec<u64> = records.iter().map(|r| r.seed).collect();
    seeds.sort_unstable();
    seeds.dedup();
    let mut commits: Vec<String> = records.iter().map(|r| r.commit.clone()).collect();
    commits.sort();
    commits.dedup();
    Table { experiment: e, quick: records.iter().any(|r| r.quick), headings, rows, seeds, commits }
}

/// A picture in the report: its caption and its path relative to the report folder.
#[derive(Clone, Debug, PartialEq)]
pub struct Picture {
    /// What it shows.
    pub caption: String,
    /// Path relative to the report's folder.
    pub path: String,
}

/// One experiment in the report: its table and pictures.
#[derive(Clone, Debug, PartialEq)]
pub struct Section {
    /// The table.
    pub table: Table,
    /// Plots and episode pictures.
    pub pictures: Vec<Picture>,
    /// The experiment folder or results file it comes from.
    pub source: String,
}

/// The note under a section's heading: source, seeds, budget, commits.
pub fn provenance(s: &Section) -> String {
    let t = &s.table;
    let seeds: Vec<String> = t.seeds.iter().map(u64::to_string).collect();
    format!(
        "From {}: seeds {}; {}; mean ± sample std over seeds; commit{} {}.",
        s.source,
        seeds.join(", "),
        if t.quick {
            "quick budgets (`--quick`: a first look, not the paper's numbers)"
        } else {
            "full budgets"
        },
        if t.commits.len() == 1 { "" } else { "s" },
        t.commits.iter().map(|c| short_commit(c)).collect::<Vec<_>>().join(", ")
    )
}

/// A commit as a report names it: the hash's first 12 digits, keeping `-dirty`.
fn short_commit(commit: &str) -> String {
    let (hash, dirty) = match commit.strip_suffix("-dirty") {
        Some(hash) => (hash, "-dirty"),
        None => (commit, ""),
    };
    format!("{}{dirty}", &hash[..hash.len().min(12)])
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// A record as a cell of `experiment` would write it.
    pub(crate) fn record(
        experiment: &str,
        task: &str,
        method: &str,
        seed: u64,
        metrics: &[(&str, f64)],
    ) -> Record {
        Record {
            experiment: experiment.into(),
            cell: seed as usize,
            id: format!("point-{task}-{method}-{seed}"),
            robot: "point".into(),
            task: task.into(),
            method: method.into(),
            seed,
            quick: false,
            rows: [(method.to_string(), metrics.iter().map(|(k, v)| (k.to_string(), *v)).collect())].into(),
            commands: vec![format!("schrl train --task {task} --seed {seed}")],
            commit: "abc".into(),
            seconds: 1.0,
            curve: None,
        }
    }

    #[test]
    fn rows_average_over_seeds_and_say_when_a_seed_has_no_value() {
        let records = [
            record("table3-4", "seq", "schrl", 0, &[("satisfaction", 1.0), ("steps to reach", 500.0)]),
            record("table3-4", "seq", "schrl", 1, &[("satisfaction", 0.0)]),
            record("table3-4", "loop", "schrl", 0, &[("satisfaction", 0.5), ("steps to reach", 900.0)]),
        ];
        let t = table(Experiment::Table34, &records.iter().collect::<Vec<_>>());
        assert_eq!(t.headings, ["robot", "task", "method", "seeds", "satisfaction", "steps to reach"]);
        assert_eq!(t.rows[0], ["point", "seq", "schrl", "2", "0.500 ± 0.707", "500.0 (1 of 2 seeds)"]);
        assert_eq!(t.rows[1], ["point", "loop", "schrl", "1", "0.500", "900.0"]);
        assert_eq!(t.seeds, [0, 1]);
    }

    #[test]
    fn a_dirty_build_stays_marked_dirty_in_the_report() {
        assert_eq!(short_commit("0123456789abcdef0123-dirty"), "0123456789ab-dirty");
        assert_eq!(short_commit("0123456789abcdef0123"), "0123456789ab");
        assert_eq!(short_commit("unknown"), "unknown");
    }
}
