//! One module per subcommand.

pub mod control;
pub mod plan;
pub mod robustness;
pub mod sim;
pub mod spec_text;
pub mod task;
pub mod train;

/// Reads a JSON-lines metrics log written by an earlier (resumed) run; a missing
/// file is an empty log, a malformed line an error naming the file and line.
pub fn read_jsonl<T: serde::de::DeserializeOwned>(path: &std::path::Path) -> anyhow::Result<Vec<T>> {
    use anyhow::Context;
    let Ok(text) = std::fs::read_to_string(path) else { return Ok(Vec::new()) };
    text.lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty())
        .map(|(i, l)| {
            serde_json::from_str(l)
                .with_context(|| format!("{}:{}: not a metrics line", path.display(), i + 1))
        })
        .collect()
}

/// Where a training run lives, and what to do when it already exists.
#[derive(clap::Args, Debug)]
pub struct RunDirArgs {
    /// Run directory: checkpoint, metrics.jsonl, training_curve.png.
    #[arg(long)]
    pub out: std::path::PathBuf,
    /// Replace an existing run in --out.
    #[arg(long)]
    pub force: bool,
    /// Continue the run saved in --out (up to --steps).
    #[arg(long, conflicts_with = "force")]
    pub resume: bool,
}
