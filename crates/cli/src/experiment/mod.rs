//! `schrl experiment`: the paper's tables and figures as sets of cells.
//!
//! An experiment ([`Experiment`]) expands into cells, one per (robot, task, method,
//! seed) it measures ([`catalog`]). A cell is a short list of `schrl` invocations
//! ([`Step`]): training commands that own a run directory inside the cell's folder and
//! resume from it when they find one, and evaluations. Every invocation is this very
//! binary run as a child process, so a cell's record names commands a person can paste,
//! and a crashed cell leaves its runs to resume.
//!
//! Finished cells are never rerun: a cell is finished when its record
//! (`cells/<id>/record.json`, written atomically after its last step) exists. Records of
//! concurrent cells (several processes, or a cluster array sharing a folder) never touch
//! one another's files; `results.jsonl` is a merge of the records, rewritten atomically,
//! ordered by cell ([`record`]). Which cell a cluster array task runs comes from
//! `--cell` or the scheduler's index ([`cluster`]).

pub mod catalog;
pub mod cluster;
pub mod record;
pub mod runner;

use std::fmt;

/// The experiments, named as the paper's tables and figures.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, clap::ValueEnum)]
pub enum Experiment {
    /// Table 1: Doggo on the five tasks (needs the `mujoco` feature).
    Table1,
    /// Table 2: the planner trained with the constrained policy gradient against the plain
    /// policy gradient.
    Table2,
    /// Tables 3 and 4: satisfaction and steps to reach, robots × tasks.
    #[value(name = "table3-4")]
    Table34,
    /// Table 5: planning time of the network, the gradient planner and the MIP planner.
    Table5,
    /// Table 7: the planner trained on soft against hard robustness.
    Table7,
    /// Fig. 3 / Fig. 12: SCHRL and the baselines' spec score against environment steps.
    Fig3,
    /// Fig. 4: the policy ablations (general controller, gradient planner, frozen planner).
    Fig4,
    /// Fig. 6: the planner ablation (GRU-ODE, GRU, MLP).
    Fig6,
    /// Table 6 (App. K): steps until one goal-conditioned controller converges against
    /// 1, 2 and 4 option policies (one per goal of Seq).
    Table6,
    /// The general goal-conditioned controllers: success on 500 random goals per robot.
    Controllers,
}

impl Experiment {
    /// Every experiment, in the paper's order.
    pub const ALL: [Experiment; 10] = [
        Experiment::Controllers,
        Experiment::Table1,
        Experiment::Table2,
        Experiment::Table34,
        Experiment::Table5,
        Experiment::Table6,
        Experiment::Table7,
        Experiment::Fig3,
        Experiment::Fig4,
        Experiment::Fig6,
    ];

    /// The name on the command line and in results.
    pub fn name(self) -> &'static str {
        match self {
            Experiment::Table1 => "table1",
            Experiment::Table2 => "table2",
            Experiment::Table34 => "table3-4",
            Experiment::Table5 => "table5",
            Experiment::Table7 => "table7",
            Experiment::Fig3 => "fig3",
            Experiment::Fig4 => "fig4",
            Experiment::Fig6 => "fig6",
            Experiment::Table6 => "table6",
            Experiment::Controllers => "controllers",
        }
    }

    /// What the experiment measures, for the report's headings.
    pub fn title(self) -> &'static str {
        match self {
            Experiment::Table1 => "Table 1: Doggo, satisfaction and steps to reach",
            Experiment::Table2 => "Table 2: constrained policy gradient (CPG) against policy gradient (PG)",
            Experiment::Table34 => "Tables 3 and 4: satisfaction and steps to reach per robot and task",
            Experiment::Table5 => "Table 5: planning time per plan",
            Experiment::Table7 => "Table 7: soft against hard robustness in the planner's loss",
            Experiment::Fig3 => "Fig. 3 / Fig. 12: SCHRL against the baselines",
            Experiment::Fig4 => "Fig. 4: policy ablations",
            Experiment::Fig6 => "Fig. 6: planner networks",
            Experiment::Table6 => {
                "Table 6: environment steps until convergence, goal-conditioned controller against options"
            }
            Experiment::Controllers => "General controllers: success on random goals",
        }
    }
}

impl fmt::Display for Experiment {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// One invocation of `schrl` inside a cell.
#[derive(Clone, Debug, PartialEq)]
pub struct Step {
    /// The row of the cell's results this step's printed numbers go to; `None`: a step
    /// whose output is not a result (a general controller trained for the others).
    pub row: Option<String>,
    /// The subcommand words (`train`, `baseline train --algo tltl`, `eval`).
    pub command: Vec<String>,
    /// The flags of a fresh invocation, `--out` excluded.
    pub flags: Vec<String>,
    /// The run directory the step trains into (relative to the cell's folder), passed as
    /// `--out`: when it already holds a run, the step is `command --resume --out DIR`
    /// instead. `None`: an evaluation, run again whenever the cell runs.
    pub run: Option<String>,
}

impl Step {
    /// A training step that owns the run directory `run`.
    pub fn train(row: Option<&str>, command: &str, flags: Vec<String>, run: &str) -> Self {
        Self { row: row.map(str::to_string), command: words(command), flags, run: Some(run.into()) }
    }

    /// An evaluation (or any step without a run directory of its own).
    pub fn once(row: &str, command: &str, flags: Vec<String>) -> Self {
        Self { row: Some(row.into()), command: words(command), flags, run: None }
    }
}

/// `"baseline train"` → `["baseline", "train"]`.
fn words(s: &str) -> Vec<String> {
    s.split_whitespace().map(str::to_string).collect()
}

/// One measurement: what it is, and the steps that produce it.
#[derive(Clone, Debug, PartialEq)]
pub struct Cell {
    /// Robot name.
    pub robot: String,
    /// Task name.
    pub task: String,
    /// Method or variant (a row of the paper's table; a cell may report several rows).
    pub method: String,
    /// Seed.
    pub seed: u64,
    /// The invocations, in order.
    pub steps: Vec<Step>,
}

impl Cell {
    /// The cell's folder name under `cells/`, unique within its experiment.
    pub fn id(&self) -> String {
        format!("{}-{}-{}-{}", self.robot, self.task, self.method, self.seed)
    }
}

/// Which cells of an experiment to expand.
#[derive(Clone, Debug, PartialEq)]
pub struct Selection {
    /// Seeds.
    pub seeds: Vec<u64>,
    /// Small budgets that finish in minutes (a first look, CI).
    pub quick: bool,
    /// Only these tasks (`None`: the experiment's own).
    pub tasks: Option<Vec<String>>,
    /// Only these robots.
    pub robots: Option<Vec<String>>,
    /// Only these methods.
    pub methods: Option<Vec<String>>,
}

/// Parses a seed list: comma-separated seeds and inclusive ranges, `0-4`, `0,2,5-9`.
pub fn parse_seeds(text: &str) -> Result<Vec<u64>, String> {
    let mut seeds = Vec::new();
    for part in text.split(',').map(str::trim) {
        let number = |s: &str| {
            s.trim()
                .parse::<u64>()
                .map_err(|_| format!("'{s}' in '{text}' is not a seed (a whole number ≥ 0)"))
        };
        match part.split_once('-') {
            Some((lo, hi)) => {
                let (lo, hi) = (number(lo)?, number(hi)?);
                if lo > hi {
                    return Err(format!("'{part}' in '{text}': the range runs backwards"));
                }
                if hi - lo >= 10_000 {
                    return Err(format!("'{part}' in '{text}': more than 10000 seeds"));
                }
                seeds.extend(lo..=hi);
            }
            None => seeds.push(number(part)?),
        }
    }
    let mut seen = std::collections::BTreeSet::new();
    if let Some(dup) = seeds.iter().find(|s| !seen.insert(**s)) {
        return Err(format!("seed {dup} appears twice in '{text}'"));
    }
    Ok(seeds)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn seed_lists_take_ranges_and_single_seeds() {
        assert_eq!(parse_seeds("0-4").unwrap(), vec![0, 1, 2, 3, 4]);
        assert_eq!(parse_seeds("0,2,5-7").unwrap(), vec![0, 2, 5, 6, 7]);
        assert_eq!(parse_seeds("3").unwrap(), vec![3]);
    }

    #[test]
    fn bad_seed_lists_say_what_is_wrong() {
        assert!(parse_seeds("4-0").unwrap_err().contains("backwards"));
        assert!(parse_seeds("0,x").unwrap_err().contains("'x'"));
        assert!(parse_seeds("1,0-2").unwrap_err().contains("seed 1 appears twice"));
        assert!(parse_seeds("-1").is_err());
    }

    #[test]
    fn experiment_names_round_trip() {
        for e in Experiment::ALL {
            let parsed = <Experiment as clap::ValueEnum>::from_str(e.name(), false).unwrap();
            assert_eq!(parsed, e);
        }
    }
}
