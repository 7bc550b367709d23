//! One module per subcommand.

pub mod baseline;
pub mod control;
pub mod experiment;
pub mod plan;
pub mod plot;
pub mod report;
pub mod robustness;
pub mod sdf;
pub mod sim;
pub mod spec_text;
pub mod task;
pub mod train;

use schrl::store::{Existing, RunKind, StoreError};

/// Where a training run lives, and what to do when it already exists.
#[derive(clap::Args, Debug, Default)]
pub struct RunDirArgs {
    /// Run directory: manifest, checkpoints, metrics.jsonl, pictures.
    #[arg(long)]
    pub out: std::path::PathBuf,
    /// Replace an existing run of the same kind in --out.
    #[arg(long)]
    pub force: bool,
    /// Continue the run saved in --out exactly where its last checkpoint left it.
    #[arg(long, conflicts_with = "force")]
    pub resume: bool,
}

impl RunDirArgs {
    /// What to do with an existing run when starting a new one.
    pub fn existing(&self) -> Existing {
        if self.force { Existing::Replace } else { Existing::Refuse }
    }
}

/// How many runs an evaluation executes, in groups (the paper's 5 × 100), and from
/// which seed: shared by `schrl eval` and `schrl baseline eval`, so both protocols
/// are the same flags with the same defaults.
#[derive(clap::Args, Debug)]
pub struct EvalRunsArgs {
    /// Groups of runs.
    #[arg(long, default_value_t = schrl::run::evaluate::EVAL_GROUPS, value_parser = count::<1, 100>)]
    pub groups: usize,
    /// Runs per group.
    #[arg(long, default_value_t = schrl::run::evaluate::EVAL_PER_GROUP, value_parser = count::<1, 10_000>)]
    pub per_group: usize,
    /// Seed of the runs' starts (and of sampled plans).
    #[arg(long, default_value_t = schrl::run::evaluate::EVAL_SEED)]
    pub seed: u64,
}

impl EvalRunsArgs {
    /// `(groups, runs per group)`.
    pub fn sizes(&self) -> (usize, usize) {
        (self.groups, self.per_group)
    }
}

/// A count flag's parser: a whole number in `LO..=HI`. The bounds keep what a flag
/// allocates finite (`plan sample --n 3000000` once aborted on allocation).
pub fn count<const LO: usize, const HI: usize>(s: &str) -> Result<usize, String> {
    let n: usize = s.trim().parse().map_err(|_| format!("'{s}' is not a whole number"))?;
    if (LO..=HI).contains(&n) { Ok(n) } else { Err(format!("{n} is outside {LO}..={HI}")) }
}

/// A store error as the command line says it: with the flag that would help.
pub fn store_error(e: StoreError) -> anyhow::Error {
    let hint = match &e {
        StoreError::Exists { .. } => "; pass --force to replace it, or --resume to continue it",
        StoreError::FileExists(_) => "; pass --force to replace it",
        StoreError::Busy(_) => "; wait for it to finish, or choose another --out",
        StoreError::OtherKind { .. } => "; choose another directory",
        _ => "",
    };
    anyhow::anyhow!("{e}{hint}")
}

/// Refuses `--resume` flags that differ from the saved run's settings, naming them.
/// Each entry: the flag, and whether it was given with a value other than the saved one.
pub fn refuse_conflicts(kind: RunKind, conflicts: &[(&str, bool)]) -> anyhow::Result<()> {
    let named: Vec<&str> = conflicts.iter().filter(|(_, c)| *c).map(|(f, _)| *f).collect();
    if named.is_empty() {
        return Ok(());
    }
    anyhow::bail!(
        "--resume: {} differ{} from the saved {kind} run's settings; a resumed run keeps its settings \
         (drop the flag, or start a new run)",
        named.join(", "),
        if named.len() == 1 { "s" } else { "" }
    )
}

/// `true` when `given` is set and differs from `saved`.
pub fn differs<T: PartialEq>(given: &Option<T>, saved: &T) -> bool {
    given.as_ref().is_some_and(|g| g != saved)
}
