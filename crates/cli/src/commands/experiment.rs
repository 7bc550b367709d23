//! `schrl experiment`: one of the paper's tables or figures, cell by cell, resumable,
//! one cell per cluster array task if asked.

use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};

use anyhow::{Context, Result};
use indicatif::{ProgressBar, ProgressStyle};

use crate::experiment::catalog::SAMPLED;
use crate::experiment::record::{self, Record};
use crate::experiment::runner::{self, Identity};
use crate::experiment::{Experiment, Selection, catalog, cluster, parse_seeds};

use super::plot::{BarRow, CurveRun, CurveSource, save_bar_chart, save_curves};

/// Arguments of `schrl experiment`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// The table or figure.
    #[arg(value_enum)]
    experiment: Experiment,
    /// The experiment's folder: `cells/<id>/` (each cell's runs, output and record),
    /// `results.jsonl`, plots.
    #[arg(long, required_unless_present = "list")]
    out: Option<PathBuf>,
    /// Seeds: a list and ranges, `0-4`, `0,2,5-9`.
    #[arg(long, default_value = "0-4")]
    seeds: String,
    /// Small budgets that finish in minutes: a first look, not the paper's numbers.
    #[arg(long)]
    quick: bool,
    /// Only these tasks (comma-separated) [default: all five].
    #[arg(long, value_delimiter = ',')]
    tasks: Option<Vec<String>>,
    /// Only these robots (comma-separated) [default: the experiment's].
    #[arg(long, value_delimiter = ',')]
    robots: Option<Vec<String>>,
    /// Only these methods or variants (comma-separated) [default: the experiment's].
    #[arg(long, value_delimiter = ',')]
    methods: Option<Vec<String>>,
    /// Run only the cell at this position of `--list` [default: `SLURM_ARRAY_TASK_ID`
    /// or `JOB_COMPLETION_INDEX` when set, else every cell]. Plots are drawn by a run
    /// of every cell (which skips the finished ones).
    #[arg(long)]
    cell: Option<usize>,
    /// Print the cells (position, id, commands) and exit.
    #[arg(long)]
    list: bool,
    /// Cells run at once (each is one process at a time; one core each with
    /// `RAYON_NUM_THREADS=1`).
    #[arg(long, default_value_t = 1, value_parser = super::count::<1, 256>)]
    jobs: usize,
}

/// Runs `schrl experiment`.
pub fn run(args: Args) -> Result<()> {
    let e = args.experiment;
    let seeds = parse_seeds(&args.seeds).map_err(|err| anyhow::anyhow!("--seeds: {err}"))?;
    let sel =
        Selection { seeds, quick: args.quick, tasks: args.tasks, robots: args.robots, methods: args.methods };
    let cells = catalog::cells(e, &sel)?;
    if args.list {
        for (i, c) in cells.iter().enumerate() {
            let steps: Vec<String> = c
                .steps
                .iter()
                .map(|s| runner::shell_words("schrl", &[s.command.clone(), s.flags.clone()].concat()))
                .collect();
            println!("{i}\t{}\t{}", c.id(), steps.join(" && "));
        }
        return Ok(());
    }
    let dir = args.out.expect("clap requires --out without --list");
    if cells.iter().any(|c| c.robot == "doggo") && !cfg!(feature = "mujoco") {
        anyhow::bail!(
            "{e} trains Doggo, which needs MuJoCo: run scripts/setup-mujoco.sh, then build with \
             `--features mujoco` (README, Doggo)"
        );
    }
    // A bad index is refused before the directory is made.
    let index = cluster::cell_index(args.cell, |v| std::env::var(v).ok(), cells.len())?;
    runner::claim(&dir, &Identity { experiment: e.name().into(), quick: sel.quick })?;
    let chosen: Vec<usize> = match index {
        Some(i) => vec![i],
        None => (0..cells.len()).collect(),
    };
    let exe = std::env::current_exe().context("finding the schrl binary to run the cells with")?;
    crate::interrupt::install();
    let bar = ProgressBar::new(chosen.len() as u64);
    bar.set_style(
        ProgressStyle::with_template("{prefix} [{elapsed_precise}] {wide_bar} {pos}/{len} cells  {msg}")
            .expect("a valid template"),
    );
    bar.set_prefix(e.name());
    // Cells not finished yet, handed out one at a time to `--jobs` workers; the first
    // failure stops handing out more (cells already running finish).
    let mut todo = vec![];
    for &i in &chosen {
        if record::read(&runner::cell_dir(&dir, &cells[i]))?.is_some() {
            bar.inc(1);
        } else {
            todo.push(i);
        }
    }
    let next = AtomicUsize::new(0);
    let failed = AtomicBool::new(false);
    let ran = AtomicUsize::new(0);
    let work = || -> Result<()> {
        while !failed.load(Ordering::SeqCst) {
            let Some(&i) = todo.get(next.fetch_add(1, Ordering::SeqCst)) else { return Ok(()) };
            let cell = &cells[i];
            bar.set_message(cell.id());
            let r = runner::run_cell(&exe, &dir, e, i, cell, sel.quick)
                .inspect_err(|_| failed.store(true, Ordering::SeqCst))?;
            // (`println` on the bar would drop the line when stderr is not a terminal.)
            bar.suspend(|| println!("cell {i} {}: {}", r.id, summary(&r)));
            bar.inc(1);
            ran.fetch_add(1, Ordering::SeqCst);
        }
        Ok(())
    };
    let results: Vec<Result<()>> = std::thread::scope(|scope| {
        let workers: Vec<_> = (0..args.jobs.min(todo.len()).max(1)).map(|_| scope.spawn(work)).collect();
        workers.into_iter().map(|w| w.join().expect("a worker does not panic")).collect()
    });
    let ran = ran.into_inner();
    if let Some(err) = results.into_iter().find_map(Result::err) {
        bar.finish_and_clear();
        // What the other workers finished is kept in results.jsonl.
        record::merge(&dir)?;
        return Err(err);
    }
    bar.finish_and_clear();
    if e == Experiment::Fig3 {
        let filled = record::fill_curves(&dir)?;
        if filled > 0 {
            println!("kept the curves of {filled} earlier records (written before records kept them)");
        }
    }
    let records = record::merge(&dir)?;
    let finished = cells.iter().filter(|c| records.iter().any(|r| r.id == c.id())).count();
    println!(
        "{e}: {finished} of {} cells finished ({ran} run now); results in {}",
        cells.len(),
        dir.join(record::RESULTS).display()
    );
    if index.is_none() {
        for picture in plots(e, &dir, &records)? {
            println!("wrote {}", picture.display());
        }
    }
    Ok(())
}

/// A record's headline numbers, for the progress log: each row's first two numbers
/// (satisfaction first where there is one).
fn summary(r: &Record) -> String {
    r.rows
        .iter()
        .map(|(row, m)| {
            let mut named: Vec<(&String, &f64)> = m.iter().filter(|(k, _)| !k.ends_with(" std")).collect();
            named.sort_by_key(|(k, _)| k.as_str() != "satisfaction");
            let numbers: Vec<String> = named.iter().take(2).map(|(k, v)| format!("{k} {v:.4}")).collect();
            format!("{row}: {}", numbers.join(", "))
        })
        .collect::<Vec<_>>()
        .join("; ")
}

/// The experiment's pictures from its records, in PNG and SVG: Fig. 3's curves, bars of
/// satisfaction and steps to reach for the rest that execute tasks.
pub fn plots(e: Experiment, dir: &std::path::Path, records: &[Record]) -> Result<Vec<PathBuf>> {
    let mine: Vec<&Record> = records.iter().filter(|r| r.experiment == e.name()).collect();
    if mine.is_empty() {
        return Ok(vec![]);
    }
    let mut written = vec![];
    match e {
        Experiment::Fig3 => {
            let runs: Vec<CurveRun> = mine
                .iter()
                .map(|r| CurveRun {
                    task: r.task.clone(),
                    method: r.method.clone(),
                    source: match &r.curve {
                        Some(c) => CurveSource::Recorded(c.clone()),
                        None => CurveSource::Run(record::fig3_run(dir, &r.id)),
                    },
                })
                .collect();
            for ext in ["png", "svg"] {
                let out = dir.join(format!("{e}.{ext}"));
                save_curves(&runs, 40, &out, true)?;
                written.push(out);
            }
        }
        Experiment::Table1 | Experiment::Table34 | Experiment::Fig4 => {
            // Mean paths only: the sampled-plan rows are in the tables.
            let rows: Vec<BarRow> = mine
                .iter()
                .flat_map(|r| {
                    r.rows.iter().filter(|(row, _)| !row.ends_with(SAMPLED)).map(|(row, m)| BarRow {
                        task: r.task.clone(),
                        // Table 3–4's bars are robots; Fig. 4's its variants.
                        variant: if e == Experiment::Fig4 { row.clone() } else { r.robot.clone() },
                        satisfaction: m.get("satisfaction").copied().unwrap_or(0.0),
                        steps_to_reach: m.get("steps to reach").copied(),
                    })
                })
                .collect();
            for ext in ["png", "svg"] {
                let out = dir.join(format!("{e}.{ext}"));
                save_bar_chart(&rows, &out, true)?;
                written.push(out);
            }
        }
        Experiment::Table2
        | Experiment::Table5
        | Experiment::Table6
        | Experiment::Table7
        | Experiment::Fig6
        | Experiment::Controllers => {}
    }
    Ok(written)
}
