//! `schrl plot`: pictures of results written by the experiment scripts.

use std::collections::BTreeMap;
use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use sim::render::{BarChart, BarPanel, save_bars};

/// Subcommands of `schrl plot`.
#[derive(clap::Subcommand, Debug)]
pub enum Command {
    /// Grouped bars of satisfaction and steps to reach per task and variant, each
    /// normalised within its task by the largest variant (the paper's Fig. 4).
    Bars(BarsArgs),
}

/// Arguments of `schrl plot bars`.
#[derive(clap::Args, Debug)]
pub struct BarsArgs {
    /// Results CSV with the header `task,variant,seed,satisfaction,steps_to_reach`
    /// (one row per run; steps_to_reach may be `-` when no run satisfied), as
    /// `scripts/fig4.sh` writes it.
    #[arg(long)]
    results: PathBuf,
    /// The picture (PNG or SVG).
    #[arg(long)]
    out: PathBuf,
    /// Replace the picture.
    #[arg(long)]
    force: bool,
}

/// Runs `schrl plot`.
pub fn run(cmd: Command) -> Result<()> {
    match cmd {
        Command::Bars(args) => bars(args),
    }
}

/// One (task, variant): its values over seeds.
#[derive(Default)]
struct Cell {
    satisfaction: Vec<f64>,
    steps_to_reach: Vec<f64>,
}

/// The cells by (task, variant).
type Cells = BTreeMap<(String, String), Cell>;

fn read(path: &PathBuf) -> Result<(Vec<String>, Vec<String>, Cells)> {
    let mut reader = csv::Reader::from_path(path).with_context(|| format!("{}", path.display()))?;
    let header: Vec<String> = reader.headers()?.iter().map(str::to_string).collect();
    let want = ["task", "variant", "seed", "satisfaction", "steps_to_reach"];
    if header != want {
        bail!("{}: the header must be `{}`, got `{}`", path.display(), want.join(","), header.join(","));
    }
    let (mut tasks, mut variants, mut cells) = (Vec::new(), Vec::new(), Cells::new());
    for (i, row) in reader.records().enumerate() {
        let row = row.with_context(|| format!("{}: row {}", path.display(), i + 2))?;
        let number = |col: usize| -> Result<Option<f64>> {
            match &row[col] {
                "-" | "" => Ok(None),
                t => t.parse().map(Some).with_context(|| {
                    format!("{}: row {}, column {}: '{t}' is not a number", path.display(), i + 2, want[col])
                }),
            }
        };
        let (task, variant) = (row[0].to_string(), row[1].to_string());
        if !tasks.contains(&task) {
            tasks.push(task.clone());
        }
        if !variants.contains(&variant) {
            variants.push(variant.clone());
        }
        let cell = cells.entry((task, variant)).or_default();
        cell.satisfaction.push(number(3)?.unwrap_or(0.0));
        if let Some(s) = number(4)? {
            cell.steps_to_reach.push(s);
        }
    }
    if cells.is_empty() {
        bail!("{}: no rows", path.display());
    }
    Ok((tasks, variants, cells))
}

fn bars(args: BarsArgs) -> Result<()> {
    let (tasks, variants, cells) = read(&args.results)?;
    let stats = |xs: &[f64]| schrl::run::evaluate::mean_std(xs);
    // [variant][task] means and stds, then each task divided by its largest mean.
    let measure = |pick: fn(&Cell) -> &[f64]| {
        let mut values = vec![vec![f64::NAN; tasks.len()]; variants.len()];
        let mut errors = values.clone();
        for (t, task) in tasks.iter().enumerate() {
            let top = variants
                .iter()
                .filter_map(|v| cells.get(&(task.clone(), v.clone())))
                .map(|c| stats(pick(c)).0)
                .filter(|m| m.is_finite())
                .fold(0.0f64, f64::max);
            for (v, variant) in variants.iter().enumerate() {
                if let Some(c) = cells.get(&(task.clone(), variant.clone())) {
                    let (m, s) = stats(pick(c));
                    if top > 0.0 && m.is_finite() {
                        values[v][t] = m / top;
                        errors[v][t] = s / top;
                    }
                }
            }
        }
        (values, errors)
    };
    let (sat, sat_err) = measure(|c| &c.satisfaction);
    let (steps, steps_err) = measure(|c| &c.steps_to_reach);
    let chart = BarChart {
        groups: tasks.clone(),
        series: variants.clone(),
        panels: vec![
            BarPanel {
                y_label: "satisfaction (normalised)".into(),
                values: sat,
                errors: Some(sat_err),
                y_range: Some((0.0, 1.15)),
            },
            BarPanel {
                y_label: "steps to reach (normalised)".into(),
                values: steps,
                errors: Some(steps_err),
                y_range: Some((0.0, 1.15)),
            },
        ],
    };
    save_bars(&chart, &args.out, args.force)?;
    println!("wrote {}", args.out.display());
    Ok(())
}
