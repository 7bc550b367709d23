//! `schrl task`: check task files.

use std::path::PathBuf;

use anyhow::Result;
use schrl::task::Task;

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
            for w in t.warnings() {
                println!("warning: {w}");
            }
            println!("ok");
            Ok(())
        }
    }
}
