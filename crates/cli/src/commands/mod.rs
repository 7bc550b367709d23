//! One module per subcommand.

pub mod control;
pub mod plan;
pub mod robustness;
pub mod sdf;
pub mod sim;
pub mod spec_text;
pub mod task;
pub mod train;

/// Opens `dir/metrics.jsonl` for a run. A fresh run starts an empty log; a resumed
/// run keeps the earlier lines its checkpoint covers (`covered`), so the log has no
/// duplicates, and gets them back as its history. A malformed line is an error
/// naming the file and line.
pub fn open_metrics_log<T: serde::Serialize + serde::de::DeserializeOwned>(
    dir: &std::path::Path,
    resume: bool,
    covered: impl Fn(&T) -> bool,
) -> anyhow::Result<(Vec<T>, std::fs::File)> {
    use anyhow::Context;
    use std::io::Write;
    let path = dir.join("metrics.jsonl");
    let mut history: Vec<T> = match (resume, std::fs::read_to_string(&path)) {
        (true, Ok(text)) => text
            .lines()
            .enumerate()
            .filter(|(_, l)| !l.trim().is_empty())
            .map(|(i, l)| {
                serde_json::from_str(l)
                    .with_context(|| format!("{}:{}: not a metrics line", path.display(), i + 1))
            })
            .collect::<anyhow::Result<_>>()?,
        _ => Vec::new(),
    };
    history.retain(|m| covered(m));
    let mut log = std::fs::File::create(&path).with_context(|| format!("cannot write {}", path.display()))?;
    for m in &history {
        writeln!(log, "{}", serde_json::to_string(m)?)?;
    }
    Ok((history, log))
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
