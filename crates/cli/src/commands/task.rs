//! `schrl task`: check task files.

use std::path::PathBuf;

use anyhow::Result;
use schrl::task::Task;
use sim::Robot;

/// The task a `--task` flag names: a task file (`.toml`), whose robot it names, or a
/// built-in task name for `robot` (default: point). A `--robot` that contradicts the
/// file is refused.
pub fn resolve(robot: Option<Robot>, task: &str) -> Result<Task> {
    Task::resolve(robot, task).map_err(|e| anyhow::anyhow!("--task {e}"))
}

/// Whether `--task` (with `--robot`) on a resumed run names a task other than the
/// saved one ([`Task::differs_from_saved`]); `None`: not given.
pub fn differs_from_saved(
    robot: Option<Robot>,
    task: Option<&str>,
    saved_robot: Robot,
    saved: (&str, &str),
) -> Result<bool> {
    let Some(t) = task else { return Ok(false) };
    Task::differs_from_saved(robot, t, saved_robot, saved).map_err(|e| anyhow::anyhow!("--task {e}"))
}

/// Subcommands of `schrl task`.
#[derive(clap::Subcommand, Debug)]
pub enum Command {
    /// Load a task (TOML plus the spec file it names) and report what it holds, or
    /// what is wrong with it.
    Check {
        /// The task's TOML file.
        file: PathBuf,
    },
}

/// Runs `schrl task ...`.
pub fn run(cmd: Command) -> Result<()> {
    match cmd {
        Command::Check { file } => {
            let t = Task::from_file(&file)?;
            println!(
                "{}: task '{}' for the {} on the {} map: {} goals, {} waypoints, step limit {}",
                file.display(),
                t.name,
                t.robot,
                t.map.name(),
                t.goals.len(),
                t.steps,
                t.step_limit
            );
            println!("spec: {}", t.formula);
            let avoid: Vec<&str> = t.avoid_regions().iter().map(|g| g.name.as_str()).collect();
            if !avoid.is_empty() {
                println!(
                    "regions to avoid, checked along the path (planned segments, every step of a run): {}",
                    avoid.join(", ")
                );
            }
            for w in t.warnings() {
                println!("warning: {w}");
            }
            println!("ok");
            Ok(())
        }
    }
}
