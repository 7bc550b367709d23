//! What each experiment runs: its robots, tasks and methods, and each cell's
//! invocations at full size and at `--quick` size.
//!
//! Full-size cells use each command's defaults (the README's numbers come from them).
//! Quick cells cut every budget to seconds (a general controller of 20 000 steps shared
//! by the cell's training steps, 20 000 joint or baseline steps, 20 planner updates per
//! candidate, one evaluation group): enough to run every step end to end, not to learn.
//!
//! A flag value written `@name` is the path `name` inside the cell's folder
//! ([`super::runner`] expands it).

use anyhow::{Result, bail};

use super::{Cell, Experiment, Selection, Step};

/// The five tasks of the paper.
const TASKS: [&str; 5] = ["seq", "cover", "branch", "loop", "signal"];

/// Table 3/4's method with a neural SDF as the planner's obstacle (`--obstacle
/// neural`), the paper's Drone planner (§3.1); on the Drone only.
const NEURAL_SDF: &str = "schrl-neural-sdf";

/// Whether `method` runs on `robot` (the neural SDF method on the Drone only: the
/// paper fitted one to the duck, not to walls).
fn applies(method: &str, robot: &str) -> bool {
    method != NEURAL_SDF || robot == "drone"
}

/// Robots, tasks and methods of an experiment, before selection.
struct Axes {
    robots: &'static [&'static str],
    tasks: &'static [&'static str],
    methods: &'static [&'static str],
}

fn axes(e: Experiment) -> Axes {
    let tasks: &[&str] = match e {
        Experiment::Controllers => &["random-goals"],
        Experiment::Table6 => &["seq"],
        _ => &TASKS,
    };
    let (robots, methods): (&[&str], &[&str]) = match e {
        Experiment::Table1 => (&["doggo"], &["schrl"]),
        Experiment::Table2 => (&["point"], &["cpg", "pg"]),
        Experiment::Table34 => (&["point", "car", "drone"], &["schrl", NEURAL_SDF]),
        Experiment::Table5 => (&["point"], &["planners"]),
        Experiment::Table7 => (&["point"], &["soft", "hard"]),
        Experiment::Fig3 => (&["point"], &["schrl", "htltl", "tltl", "crm", "dhrm"]),
        Experiment::Fig4 => (&["point"], &["ablations"]),
        Experiment::Fig6 => (&["point"], &["gru-ode", "gru", "mlp"]),
        Experiment::Table6 => (&["point"], &["options"]),
        Experiment::Controllers => (&["point", "car", "drone"], &["general"]),
    };
    Axes { robots, tasks, methods }
}

/// Keeps the `chosen` values of an axis, in the experiment's order; refuses one the
/// experiment does not have.
fn select(
    e: Experiment,
    what: &str,
    all: &[&'static str],
    chosen: &Option<Vec<String>>,
) -> Result<Vec<&'static str>> {
    let Some(chosen) = chosen else { return Ok(all.to_vec()) };
    if let Some(bad) = chosen.iter().find(|c| !all.contains(&c.as_str())) {
        bail!("--{what}: {e} has no {what} '{bad}'; it has {}", all.join(", "));
    }
    Ok(all.iter().copied().filter(|a| chosen.iter().any(|c| c == a)).collect())
}

/// The experiment's cells for `sel`, in a fixed order (the cluster index is a position
/// in it): robot, task, seed, method.
pub fn cells(e: Experiment, sel: &Selection) -> Result<Vec<Cell>> {
    let ax = axes(e);
    let robots = select(e, "robots", ax.robots, &sel.robots)?;
    let tasks = select(e, "tasks", ax.tasks, &sel.tasks)?;
    let methods = select(e, "methods", ax.methods, &sel.methods)?;
    if sel.seeds.is_empty() {
        bail!("--seeds: no seeds");
    }
    let mut cells = Vec::new();
    for robot in &robots {
        for task in &tasks {
            for &seed in &sel.seeds {
                for method in methods.iter().filter(|m| applies(m, robot)) {
                    let base = Base { robot, task, seed, quick: sel.quick };
                    let steps = steps(e, method, &base)?;
                    cells.push(Cell {
                        robot: robot.to_string(),
                        task: task.to_string(),
                        method: method.to_string(),
                        seed,
                        steps,
                    });
                }
            }
        }
    }
    if cells.is_empty() {
        bail!("--methods: {} runs on none of the robots chosen ({})", methods.join(", "), robots.join(", "));
    }
    Ok(cells)
}

/// Where a cell of `experiment` (by name) sits in the experiment's full list, whatever
/// selection it ran in: robot, task, seed, method, as [`cells`] orders them (names the
/// experiment does not have go last). A record's `cell` is its position in the list of
/// the run that made it, which differs between `--tasks` or `--methods` selections.
pub fn rank(
    experiment: &str,
    robot: &str,
    task: &str,
    method: &str,
    seed: u64,
) -> (usize, usize, u64, usize) {
    let Some(&e) = Experiment::ALL.iter().find(|e| e.name() == experiment) else {
        return (usize::MAX, usize::MAX, seed, usize::MAX);
    };
    let ax = axes(e);
    let at = |all: &[&str], x: &str| all.iter().position(|a| *a == x).unwrap_or(usize::MAX);
    (at(ax.robots, robot), at(ax.tasks, task), seed, at(ax.methods, method))
}

/// What every step of a cell shares.
struct Base<'a> {
    robot: &'a str,
    task: &'a str,
    seed: u64,
    quick: bool,
}

impl Base<'_> {
    /// `--robot R --task T --seed S`.
    fn identity(&self) -> Vec<String> {
        strings(&["--robot", self.robot, "--task", self.task, "--seed", &self.seed.to_string()])
    }

    /// A quick cell's general controller, trained once for its `train` steps.
    fn quick_controller(&self) -> Step {
        let mut flags = self.controller_flags();
        flags.extend(strings(&["--eval-episodes", "10"]));
        Step::train(None, "control train", flags, "general")
    }

    /// `control train`'s robot, seed and (quick) budget.
    fn controller_flags(&self) -> Vec<String> {
        let mut flags = strings(&["--robot", self.robot, "--seed", &self.seed.to_string()]);
        if self.quick {
            flags.extend(strings(&["--steps", "20000"]));
        }
        flags
    }

    /// `schrl train` into `run` with `extra` flags (and the quick budget).
    fn train(&self, row: &str, extra: &[&str], run: &str) -> Step {
        let mut flags = self.identity();
        flags.extend(strings(extra));
        if self.quick {
            flags.extend(strings(&[
                "--steps",
                "20000",
                "--pretrain-updates",
                "20",
                "--pretrain-candidates",
                "1",
                "--eval-groups",
                "1",
                "--controller",
                "@general",
            ]));
        }
        Step::train(Some(row), "train", flags, run)
    }

    /// `schrl plan train` into `run` with `extra` flags.
    fn plan_train(&self, row: Option<&str>, extra: &[&str], run: &str) -> Step {
        let mut flags = strings(&["--task", self.task, "--seed", &self.seed.to_string()]);
        flags.extend(strings(extra));
        if self.quick {
            flags.extend(strings(&["--updates", "20"]));
        }
        Step { row: row.map(str::to_string), ..Step::train(None, "plan train", flags, run) }
    }

    /// Evaluation sizes: the protocol's 5 × 100, or one group of 20 when quick.
    fn eval_sizes(&self) -> Vec<String> {
        if self.quick { strings(&["--groups", "1", "--per-group", "20"]) } else { vec![] }
    }
}

fn strings(s: &[&str]) -> Vec<String> {
    s.iter().map(|s| s.to_string()).collect()
}

/// The steps of one cell.
fn steps(e: Experiment, method: &str, b: &Base) -> Result<Vec<Step>> {
    let mut steps = Vec::new();
    let trains = matches!(e, Experiment::Table1 | Experiment::Table34 | Experiment::Fig4)
        || (e == Experiment::Fig3 && matches!(method, "schrl" | "htltl"));
    if b.quick && trains {
        steps.push(b.quick_controller());
    }
    match e {
        Experiment::Table1 | Experiment::Table34 => {
            let extra: &[&str] = if method == NEURAL_SDF { &["--obstacle", "neural"] } else { &[] };
            steps.push(b.train(method, extra, "run"));
            let mut flags = strings(&["--ckpt", "@run", "--sampled-plans"]);
            flags.extend(b.eval_sizes());
            steps.push(Step::once(&format!("{method} (sampled plans)"), "eval", flags));
        }
        Experiment::Fig3 => match method {
            "schrl" => steps.push(b.train(method, &[], "run")),
            // HTLTL is `train --method pg` (what `baseline train --algo htltl` runs); the
            // quick budget needs flags only `train` takes.
            "htltl" if b.quick => steps.push(b.train(method, &["--method", "pg"], "run")),
            algo => {
                let mut flags = b.identity();
                if b.quick {
                    flags.extend(strings(&["--steps", "20000", "--eval-groups", "1"]));
                }
                steps.push(Step::train(Some(method), &format!("baseline train --algo {algo}"), flags, "run"));
            }
        },
        Experiment::Fig4 => {
            steps.push(b.train("(a) SCHRL", &[], "run"));
            steps.push(b.train("(d) frozen planner", &["--freeze-planner"], "frozen"));
            let mut flags = match b.quick {
                true => strings(&["--ckpt", "@run", "--controller", "@general"]),
                false => strings(&["--ckpt", "@run", "--general-controller"]),
            };
            flags.extend(b.eval_sizes());
            steps.push(Step::once("(b) general controller", "eval", flags));
            let mut flags = strings(&["--ckpt", "@run", "--planner", "gradient"]);
            flags.extend(b.eval_sizes());
            steps.push(Step::once("(c) gradient planner", "eval", flags));
            for (row, run) in [("(a) SCHRL", "@run"), ("(d) frozen planner", "@frozen")] {
                let mut flags = strings(&["--ckpt", run, "--sampled-plans"]);
                flags.extend(b.eval_sizes());
                steps.push(Step::once(&format!("{row}{SAMPLED}"), "eval", flags));
            }
        }
        Experiment::Table2 => steps.push(b.plan_train(Some(method), &["--method", method], "run")),
        Experiment::Table7 => {
            let extra: &[&str] = if method == "hard" { &["--semantics", "hard"] } else { &[] };
            steps.push(b.plan_train(Some(method), extra, "run"));
        }
        Experiment::Fig6 => steps.push(b.plan_train(Some(method), &["--planner", method], "run")),
        Experiment::Table5 => {
            // The planners on the same 100 starts (`--seed 1` draws them in both
            // commands). The MIP maximises min(ρ̃, 0.3) (any plan 0.3 robust ends the
            // search; uncapped, microlp needs up to 60 s a plan on Signal), and plans
            // Loop as the paper's authors gave it to theirs: a corner sequence (Loop as
            // written runs into the 60 s limit from most starts; README).
            steps.push(b.plan_train(None, &[], "planner"));
            let n = if b.quick { "2" } else { "100" };
            let flags =
                strings(&["--ckpt", "@planner", "--n", n, "--seed", "1", "--planners", "network,gradient"]);
            steps.push(Step::once(TABLE5_ROW, "plan time", flags));
            let task = if b.task == "loop" { "loop-sequence" } else { b.task };
            let mut flags =
                strings(&["--task", task, "--n", n, "--seed", "1", "--robustness-cap", TABLE5_MIP_CAP]);
            if b.quick {
                flags.extend(strings(&["--time-limit", "5"]));
            }
            steps.push(Step::once(TABLE5_ROW, "plan mip", flags));
        }
        Experiment::Controllers => {
            let mut flags = b.controller_flags();
            flags.extend(strings(&["--eval-episodes", "0"]));
            steps.push(Step::train(None, "control train", flags, "run"));
            let episodes = if b.quick { "20" } else { "500" };
            let flags = strings(&["--ckpt", "@run", "--episodes", episodes]);
            steps.push(Step::once("general controller", "control eval", flags.clone()));
            // The short hops of a plan (a start region overlapping a goal): where the
            // Car's controller stalled with a goal beside or behind it.
            let mut near = flags;
            near.extend(strings(&["--goals-within", "1"]));
            steps.push(Step::once("general controller, goals within 1 m", "control eval", near));
        }
        Experiment::Table6 => {
            // Its rows come from the runs' logs ([`super::record::options_rows`]).
            let mut flags = b.controller_flags();
            flags.extend(strings(&["--eval-episodes", "0"]));
            steps.push(Step::train(None, "control train", flags.clone(), "conditioned"));
            let task = schrl::task::Task::builtin(b.robot, schrl::task::TaskKind::Seq)?;
            for (i, goal) in task.goals.iter().enumerate() {
                let at: Vec<String> = goal.center.iter().map(f64::to_string).collect();
                let mut flags = flags.clone();
                flags.push(format!("--goal={}", at.join(",")));
                steps.push(Step::train(None, "control train", flags, &format!("option-{i}")));
            }
        }
    }
    Ok(steps)
}

/// Table 5's one row per task: every planner's seconds per plan and plans satisfying.
pub const TABLE5_ROW: &str = "planning time";

/// The robustness at which Table 5's MIP stops maximising (metres; `--robustness-cap`).
pub const TABLE5_MIP_CAP: &str = "0.3";

/// The report's heading of Table 5's MIP column, which names [`TABLE5_MIP_CAP`].
pub const TABLE5_MIP_HEADING: &str = "MIP, robustness capped at 0.3 (s per plan)";

/// The suffix of a row that executes sampled plans instead of mean paths.
pub const SAMPLED: &str = " (sampled plans)";

#[cfg(test)]
mod tests {
    use super::*;

    fn sel(quick: bool) -> Selection {
        Selection { seeds: vec![0, 1], quick, tasks: None, robots: None, methods: None }
    }

    #[test]
    fn every_cell_of_an_experiment_has_its_own_id() {
        for e in Experiment::ALL {
            for quick in [false, true] {
                let cells = cells(e, &sel(quick)).unwrap();
                let ids: std::collections::BTreeSet<_> = cells.iter().map(Cell::id).collect();
                assert_eq!(ids.len(), cells.len(), "{e}");
                // Table 6's rows come from its runs' logs, not from a step's output.
                let derived = e == Experiment::Table6;
                assert!(
                    derived || cells.iter().all(|c| c.steps.iter().any(|s| s.row.is_some())),
                    "{e}: a cell without results"
                );
            }
        }
    }

    #[test]
    fn the_order_is_robot_task_seed_method() {
        let cells = cells(Experiment::Fig3, &sel(false)).unwrap();
        assert_eq!(cells.len(), 5 * 2 * 5);
        assert_eq!(cells[0].id(), "point-seq-schrl-0");
        assert_eq!(cells[1].id(), "point-seq-htltl-0");
        assert_eq!(cells[5].id(), "point-seq-schrl-1");
        assert_eq!(cells[10].id(), "point-cover-schrl-0");
    }

    #[test]
    fn full_cells_use_the_commands_defaults_and_quick_cells_cut_the_budget() {
        let full = cells(Experiment::Table34, &sel(false)).unwrap();
        assert_eq!(full[0].steps.len(), 2);
        assert_eq!(full[0].steps[0].command, ["train"]);
        assert_eq!(full[0].steps[1].flags, ["--ckpt", "@run", "--sampled-plans"]);
        assert_eq!(full[0].steps[0].flags, ["--robot", "point", "--task", "seq", "--seed", "0"]);
        let quick = cells(Experiment::Table34, &sel(true)).unwrap();
        assert_eq!(quick[0].steps[0].command, ["control", "train"]);
        assert!(quick[0].steps[1].flags.windows(2).any(|w| w == ["--controller", "@general"]));
    }

    #[test]
    fn table5_times_every_planner_on_the_same_starts_and_the_mip_plans_loop_as_a_sequence() {
        let cells = cells(Experiment::Table5, &sel(false)).unwrap();
        let of = |task: &str| cells.iter().find(|c| c.task == task).unwrap().steps.clone();
        for task in TASKS {
            let steps = of(task);
            assert_eq!(steps.len(), 3, "{task}: train, time network and gradient, time the MIP");
            assert!(steps[1..].iter().all(|s| s.row.as_deref() == Some(TABLE5_ROW)));
            for s in &steps[1..] {
                assert!(s.flags.windows(2).any(|w| w == ["--seed", "1"]), "{task}: the same starts");
                assert!(s.flags.windows(2).any(|w| w == ["--n", "100"]), "{task}");
            }
            let mip_task = steps[2].flags.windows(2).find(|w| w[0] == "--task").unwrap()[1].clone();
            let expected = if task == "loop" { "loop-sequence" } else { task };
            assert_eq!(mip_task, expected);
        }
    }

    #[test]
    fn table5s_mip_heading_names_its_cap() {
        assert!(TABLE5_MIP_HEADING.contains(&format!("capped at {TABLE5_MIP_CAP} ")));
    }

    #[test]
    fn the_neural_sdf_method_runs_on_the_drone_only() {
        let all = cells(Experiment::Table34, &sel(false)).unwrap();
        let neural: Vec<_> = all.iter().filter(|c| c.method == NEURAL_SDF).collect();
        assert_eq!(neural.len(), 5 * 2);
        assert!(neural.iter().all(|c| c.robot == "drone"));
        assert!(neural[0].steps[0].flags.windows(2).any(|w| w == ["--obstacle", "neural"]));
        let mut s = sel(false);
        (s.robots, s.methods) = (Some(vec!["car".into()]), Some(vec![NEURAL_SDF.into()]));
        let err = super::cells(Experiment::Table34, &s).unwrap_err().to_string();
        assert!(err.contains("runs on none of the robots chosen (car)"), "{err}");
    }

    #[test]
    fn selections_keep_the_experiments_order_and_refuse_what_it_lacks() {
        let mut s = sel(false);
        s.methods = Some(vec!["tltl".into(), "schrl".into()]);
        s.tasks = Some(vec!["loop".into()]);
        let cells = cells(Experiment::Fig3, &s).unwrap();
        let ids: Vec<_> = cells.iter().map(Cell::id).collect();
        assert_eq!(
            ids,
            ["point-loop-schrl-0", "point-loop-tltl-0", "point-loop-schrl-1", "point-loop-tltl-1"]
        );
        s.methods = Some(vec!["ppo".into()]);
        let err = super::cells(Experiment::Fig3, &s).unwrap_err().to_string();
        assert!(err.contains("--methods: fig3 has no methods 'ppo'"), "{err}");
        assert!(err.contains("schrl, htltl, tltl, crm, dhrm"), "{err}");
    }
}
