//! `schrl`: the command line over the schrl libraries.
//!
//! Each subcommand lives in its own module under `commands/`; this file only parses
//! arguments, dispatches, and turns errors into a message on stderr and a non-zero
//! exit code (never a panic).

use std::process::ExitCode;

use clap::{Parser, Subcommand};

mod commands;
mod experiment;
mod interrupt;
mod progress;
mod report;

/// Teach robots tasks written as Signal Temporal Logic specifications.
#[derive(Parser, Debug)]
#[command(name = "schrl", version, about, propagate_version = true)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Robustness of a spec on a trace (CSV: header names the signals, one row per step).
    Robustness(commands::robustness::Args),
    /// Simulated robots and maps.
    #[command(subcommand)]
    Sim(commands::sim::Command),
    /// Spec-constrained planners: train, sample, time.
    #[command(subcommand)]
    Plan(commands::plan::Command),
    /// Neural signed-distance predicates: fit, check.
    #[command(subcommand)]
    Sdf(commands::sdf::Command),
    /// Train planner and controller together on a task, then evaluate.
    Train(Box<commands::train::TrainArgs>),
    /// Evaluate a trained task: satisfaction and steps to reach over 5 groups of 100 runs.
    Eval(commands::train::EvalArgs),
    /// Task files: check.
    #[command(subcommand)]
    Task(commands::task::Command),
    /// Goal-conditioned PPO controllers: train, eval.
    #[command(subcommand)]
    Control(commands::control::Command),
    /// The paper's baselines (TLTL, HTLTL): train, eval.
    #[command(subcommand)]
    Baseline(commands::baseline::Command),
    /// Pictures of results: grouped bars (Fig. 4).
    #[command(subcommand)]
    Plot(commands::plot::Command),
    /// One of the paper's tables or figures, cell by cell (resumable; one cell per
    /// cluster array task with --cell or the scheduler's index).
    Experiment(commands::experiment::Args),
    /// Experiment results as markdown tables and a static HTML page.
    Report(commands::report::Args),
}

fn main() -> ExitCode {
    // A reader that closes the pipe early (`schrl ... | head`) ends the process the
    // usual way instead of making every `println!` panic.
    #[cfg(unix)]
    // SAFETY: called first thing on the main thread, before any other thread exists.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Robustness(args) => commands::robustness::run(args),
        Command::Sim(cmd) => commands::sim::run(cmd),
        Command::Plan(cmd) => commands::plan::run(cmd),
        Command::Sdf(cmd) => commands::sdf::run(cmd),
        Command::Control(cmd) => commands::control::run(cmd),
        Command::Task(cmd) => commands::task::run(cmd),
        Command::Train(args) => commands::train::train(*args),
        Command::Eval(args) => commands::train::eval(args),
        Command::Baseline(cmd) => commands::baseline::run(cmd),
        Command::Plot(cmd) => commands::plot::run(cmd),
        Command::Experiment(args) => commands::experiment::run(args),
        Command::Report(args) => commands::report::run(args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) if e.downcast_ref::<interrupt::Interrupted>().is_some() => {
            eprintln!("{e}");
            ExitCode::from(interrupt::EXIT_CODE)
        }
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::from(2)
        }
    }
}
