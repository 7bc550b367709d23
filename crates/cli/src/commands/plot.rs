//! `schrl plot`: pictures of results written by the experiment scripts.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use sim::render::{BarChart, BarPanel, ChartPanel, Series, save_bars};

/// Subcommands of `schrl plot`.
#[derive(clap::Subcommand, Debug)]
pub enum Command {
    /// Grouped bars of satisfaction and steps to reach per task and variant, each
    /// normalised within its task by the largest variant (the paper's Fig. 4).
    Bars(BarsArgs),
    /// The spec score of training runs against environment steps, mean ± std over
    /// seeds: one panel per task, one line per method (the paper's Fig. 3 and Fig. 12).
    Curves(CurvesArgs),
}

/// Arguments of `schrl plot curves`.
#[derive(clap::Args, Debug)]
pub struct CurvesArgs {
    /// A run as TASK:METHOD:DIR, DIR a run directory of `schrl train` or `schrl
    /// baseline train`; repeat once per run (runs of one task and method are its seeds).
    #[arg(long = "run", required = true, value_name = "TASK:METHOD:DIR")]
    runs: Vec<String>,
    /// Points along the x axis: each is the mean score of a run's iterations in a bin
    /// of environment steps.
    #[arg(long, default_value_t = 40, value_parser = super::count::<2, 1000>)]
    bins: usize,
    /// The picture (PNG or SVG).
    #[arg(long)]
    out: PathBuf,
    /// Replace the picture.
    #[arg(long)]
    force: bool,
}

/// Arguments of `schrl plot bars`.
#[derive(clap::Args, Debug)]
pub struct BarsArgs {
    /// Results CSV with the header `task,variant,seed,satisfaction,steps_to_reach`
    /// (one row per run; steps_to_reach may be `-` when no run satisfied).
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
        Command::Curves(args) => curves(args),
    }
}

/// One run's result in a bar chart: its task, variant and evaluation.
#[derive(Clone, Debug, PartialEq)]
pub struct BarRow {
    /// Task (a group of bars).
    pub task: String,
    /// Variant (a bar in every group).
    pub variant: String,
    /// Satisfaction of the run.
    pub satisfaction: f64,
    /// Steps to reach, if any run satisfied.
    pub steps_to_reach: Option<f64>,
}

/// One (task, variant): its values over seeds.
#[derive(Default)]
struct Cell {
    satisfaction: Vec<f64>,
    steps_to_reach: Vec<f64>,
}

/// The cells by (task, variant).
type Cells = BTreeMap<(String, String), Cell>;

fn read(path: &PathBuf) -> Result<Vec<BarRow>> {
    let mut reader = csv::Reader::from_path(path).with_context(|| format!("{}", path.display()))?;
    let header: Vec<String> = reader.headers()?.iter().map(str::to_string).collect();
    let want = ["task", "variant", "seed", "satisfaction", "steps_to_reach"];
    if header != want {
        bail!("{}: the header must be `{}`, got `{}`", path.display(), want.join(","), header.join(","));
    }
    let mut rows = Vec::new();
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
        rows.push(BarRow {
            task: row[0].to_string(),
            variant: row[1].to_string(),
            satisfaction: number(3)?.unwrap_or(0.0),
            steps_to_reach: number(4)?,
        });
    }
    if rows.is_empty() {
        bail!("{}: no rows", path.display());
    }
    Ok(rows)
}

fn bars(args: BarsArgs) -> Result<()> {
    save_bar_chart(&read(&args.results)?, &args.out, args.force)?;
    println!("wrote {}", args.out.display());
    Ok(())
}

/// Grouped bars of satisfaction and steps to reach (mean ± std over a task's and
/// variant's rows), each normalised within its task by the largest variant; tasks and
/// variants in the order they first appear.
pub fn save_bar_chart(rows: &[BarRow], out: &Path, force: bool) -> Result<()> {
    let (mut tasks, mut variants, mut cells) = (Vec::new(), Vec::new(), Cells::new());
    for r in rows {
        if !tasks.contains(&r.task) {
            tasks.push(r.task.clone());
        }
        if !variants.contains(&r.variant) {
            variants.push(r.variant.clone());
        }
        let cell = cells.entry((r.task.clone(), r.variant.clone())).or_default();
        cell.satisfaction.push(r.satisfaction);
        cell.steps_to_reach.extend(r.steps_to_reach);
    }
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
    save_bars(&chart, out, force)?;
    Ok(())
}

/// One run's spec scores: `(environment steps, score)` in order, and whether the run
/// may have stopped early at its target (`schrl train`'s runs), so its last value holds
/// to the end.
pub(crate) struct Curve {
    /// `(environment steps, score)`, in order.
    pub(crate) points: Vec<(f64, f64)>,
    holds: bool,
}

/// The spec scores of the run in `dir` (none for a run logged before scores were).
pub(crate) fn scores(dir: &Path) -> Result<Curve> {
    let manifest = read_json(&dir.join(schrl::store::MANIFEST))?;
    // SCHRL and HTLTL spend their first steps on the general controller, which has no
    // spec score; their joint iterations count from its budget on.
    let offset = match manifest["kind"].as_str() {
        Some("joint") => {
            let general = match manifest["settings"]["controller"].as_str() {
                Some(c) => PathBuf::from(c),
                None => dir.join("general"),
            };
            let m = read_json(&general.join(schrl::store::MANIFEST))?;
            m["settings"]["total_steps"].as_f64().with_context(|| {
                format!("{}: no settings.total_steps", general.join(schrl::store::MANIFEST).display())
            })?
        }
        Some("tltl" | "crm") => 0.0,
        other => bail!(
            "{}: a {} run has no spec score; expected a run of `schrl train` or `schrl baseline train`",
            dir.display(),
            other.unwrap_or("unknown")
        ),
    };
    let path = dir.join("metrics.jsonl");
    let text = std::fs::read_to_string(&path).with_context(|| format!("{}", path.display()))?;
    let mut out = vec![];
    for (i, line) in text.lines().enumerate() {
        let v: serde_json::Value =
            serde_json::from_str(line).with_context(|| format!("{}: line {}", path.display(), i + 1))?;
        let steps = v["env_steps"]
            .as_f64()
            .with_context(|| format!("{}: line {}: no env_steps", path.display(), i + 1))?;
        if let Some(score) = v["score"].as_f64() {
            out.push((offset + steps, score));
        }
    }
    Ok(Curve { points: out, holds: manifest["kind"] == "joint" })
}

fn read_json(path: &Path) -> Result<serde_json::Value> {
    let text = std::fs::read_to_string(path).with_context(|| format!("{}", path.display()))?;
    serde_json::from_str(&text).with_context(|| format!("{}", path.display()))
}

/// A run's scores as bin means over `bins` equal bins of `0..=max_x`: a bin with no
/// iteration keeps the bin before it; bins before the run's first iteration have none,
/// nor do bins after its last unless the run may have stopped early at its target
/// ([`Curve::holds`]): a run still training ends where it stands.
fn binned(curve: &Curve, max_x: f64, bins: usize) -> Vec<Option<f64>> {
    let points = &curve.points;
    let end = points.last().map_or(0.0, |p| p.0);
    let mut out = Vec::with_capacity(bins);
    let mut last = None;
    let mut rest = &points[..];
    for k in 1..=bins {
        if !curve.holds && max_x * (k - 1) as f64 / bins as f64 >= end {
            out.push(None);
            continue;
        }
        let edge = max_x * k as f64 / bins as f64;
        let n = rest.iter().take_while(|(x, _)| *x <= edge).count();
        let (inside, after) = rest.split_at(n);
        if !inside.is_empty() {
            last = Some(inside.iter().map(|p| p.1).sum::<f64>() / n as f64);
        }
        rest = after;
        out.push(last);
    }
    out
}

fn curves(args: CurvesArgs) -> Result<()> {
    let mut runs = vec![];
    for spec in &args.runs {
        let mut parts = spec.splitn(3, ':');
        let (Some(task), Some(method), Some(dir)) = (parts.next(), parts.next(), parts.next()) else {
            bail!("--run {spec}: expected TASK:METHOD:DIR");
        };
        runs.push(CurveRun { task: task.into(), method: method.into(), dir: dir.into() });
    }
    save_curves(&runs, args.bins, &args.out, args.force)?;
    println!("wrote {}", args.out.display());
    Ok(())
}

/// A training run in a curves chart.
#[derive(Clone, Debug)]
pub struct CurveRun {
    /// Task (a panel).
    pub task: String,
    /// Method (a line; its runs are its seeds).
    pub method: String,
    /// Run directory of `schrl train` or `schrl baseline train`.
    pub dir: PathBuf,
}

/// The spec score of training runs against environment steps, in `bins` points, mean
/// ± std over each (task, method)'s runs: a panel per task, a line per method, in the
/// order given.
pub fn save_curves(runs: &[CurveRun], bins: usize, out: &Path, force: bool) -> Result<()> {
    sim::render::check_target(out, force)?;
    // (task, method) in the order given, each with its runs' points.
    let mut cells: Vec<((String, String), Vec<Curve>)> = vec![];
    for CurveRun { task, method, dir } in runs {
        let points = scores(dir)?;
        if points.points.is_empty() {
            bail!(
                "{}: no spec scores (runs trained before the score was logged have none)",
                dir.join("metrics.jsonl").display()
            );
        }
        let key = (task.to_string(), method.to_string());
        match cells.iter_mut().find(|(k, _)| *k == key) {
            Some((_, runs)) => runs.push(points),
            None => cells.push((key, vec![points])),
        }
    }
    let max_x = cells
        .iter()
        .flat_map(|(_, r)| r.iter().flat_map(|c| c.points.last()))
        .map(|p| p.0)
        .fold(0.0, f64::max);
    // Tasks in the order given, and each method's colour the same in every panel.
    let (mut tasks, mut methods): (Vec<String>, Vec<String>) = (vec![], vec![]);
    for ((task, method), _) in &cells {
        if !tasks.contains(task) {
            tasks.push(task.clone());
        }
        if !methods.contains(method) {
            methods.push(method.clone());
        }
    }
    let panels: Vec<ChartPanel> = tasks
        .iter()
        .map(|task| {
            let series: Vec<Series> = cells
                .iter()
                .filter(|((t, _), _)| t == task)
                .map(|((_, method), runs)| {
                    let per_run: Vec<Vec<Option<f64>>> =
                        runs.iter().map(|r| binned(r, max_x, bins)).collect();
                    let (mut points, mut band) = (vec![], vec![]);
                    for k in 0..bins {
                        let values: Vec<f64> = per_run.iter().filter_map(|r| r[k]).collect();
                        if values.is_empty() {
                            continue;
                        }
                        let (m, s) = schrl::run::evaluate::mean_std(&values);
                        let x = max_x * (k + 1) as f64 / bins as f64;
                        points.push((x, m));
                        band.push((x, m - s, m + s));
                    }
                    Series {
                        label: format!(
                            "{method} ({} seed{})",
                            runs.len(),
                            if runs.len() == 1 { "" } else { "s" }
                        ),
                        points,
                        band,
                        colour: methods.iter().position(|m| m == method),
                    }
                })
                .collect();
            ChartPanel {
                series,
                y_range: None,
                y_label: format!("{task}: spec score (> 0: satisfied)"),
                reference: Some(0.0),
            }
        })
        .collect();
    sim::render::save_chart(&panels, "environment steps", out, force)?;
    Ok(())
}
