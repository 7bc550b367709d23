//! `schrl report`: the experiments' results as markdown tables and one static HTML page.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};

use crate::experiment::Experiment;
use crate::experiment::record::{self, Record};
use crate::report::{Picture, Section, html, markdown, table};

/// Arguments of `schrl report`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Experiment folders of `schrl experiment` (or their `results.jsonl`); each gives
    /// its own sections, so held-out seeds run into another folder stay apart.
    #[arg(required = true)]
    dirs: Vec<PathBuf>,
    /// The report's folder: `report.md`, `index.html`, `images/`.
    #[arg(long)]
    out: PathBuf,
    /// Replace a report already in --out.
    #[arg(long)]
    force: bool,
}

/// The records of an experiment folder (every finished cell's, whether or not a merge
/// has run since) or of a results file.
fn records(path: &Path) -> Result<(Vec<Record>, Option<PathBuf>)> {
    if path.is_file() {
        return Ok((record::read_results(path)?, path.parent().map(Path::to_path_buf)));
    }
    if path.join("cells").is_dir() {
        return Ok((record::all(path)?, Some(path.to_path_buf())));
    }
    if path.join(record::RESULTS).is_file() {
        return Ok((record::read_results(&path.join(record::RESULTS))?, Some(path.to_path_buf())));
    }
    bail!(
        "{}: neither an experiment folder (cells/, results.jsonl) nor a results file; \
         give the --out of `schrl experiment`",
        path.display()
    )
}

/// Runs `schrl report`.
pub fn run(args: Args) -> Result<()> {
    let page = args.out.join("index.html");
    if page.exists() && !args.force {
        bail!("{} already holds a report; pass --force to replace it", args.out.display());
    }
    let images = args.out.join("images");
    std::fs::create_dir_all(&images).with_context(|| format!("creating {}", images.display()))?;
    let mut sections = vec![];
    for (k, dir) in args.dirs.iter().enumerate() {
        let (records, folder) = records(dir)?;
        if records.is_empty() {
            bail!("{}: no finished cells yet", dir.display());
        }
        for e in Experiment::ALL {
            let mine: Vec<&Record> = records.iter().filter(|r| r.experiment == e.name()).collect();
            if mine.is_empty() {
                continue;
            }
            let mut pictures = vec![];
            if let Some(folder) = &folder {
                let mut copy = |from: PathBuf, name: String, caption: String| -> Result<()> {
                    if from.is_file() {
                        std::fs::copy(&from, images.join(&name))
                            .with_context(|| format!("copying {} into the report", from.display()))?;
                        pictures.push(Picture { caption, path: format!("images/{name}") });
                    }
                    Ok(())
                };
                copy(
                    folder.join(format!("{e}.png")),
                    format!("{k}-{e}.png"),
                    format!("{} ({})", e.title(), dir.display()),
                )?;
                // The first seed's executed runs of each robot, task and method.
                let mut seen = vec![];
                for r in &mine {
                    let key = (&r.robot, &r.task, &r.method);
                    if seen.contains(&key) {
                        continue;
                    }
                    seen.push(key);
                    let caption = format!(
                        "{} {} {}, seed {}: planned waypoints (blue) and executed paths (orange)",
                        r.robot, r.task, r.method, r.seed
                    );
                    let from = folder.join("cells").join(&r.id).join("run").join("episodes.png");
                    copy(from, format!("{k}-{}-episodes.png", r.id), caption)?;
                }
            }
            sections.push(Section { table: table(e, &mine), pictures, source: dir.display().to_string() });
        }
    }
    let md = args.out.join("report.md");
    schrl::store::write_atomic(&md, markdown::report(&sections).as_bytes())?;
    schrl::store::write_atomic(&page, html::page(&sections).as_bytes())?;
    println!("wrote {} and {}", md.display(), page.display());
    Ok(())
}
