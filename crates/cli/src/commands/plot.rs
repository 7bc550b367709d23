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
    #[arg(long = "run", value_name = "TASK:METHOD:DIR", required_unless_present = "results")]
    runs: Vec<String>,
    /// A `results.jsonl` of `schrl experiment fig3`: every record in it that carries its
    /// run's curve is a run (task and method from the record), so the figure needs no
    /// run directory; repeatable, and may be combined with `--run`.
    #[arg(long, value_name = "FILE")]
    results: Vec<PathBuf>,
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
        x_label: "task".into(),
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
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Curve {
    /// `(environment steps, score)`, in order.
    pub points: Vec<(f64, f64)>,
    /// Whether the last score holds to the end of the x axis.
    pub holds: bool,
}

impl Curve {
    /// The curve in at most `bins` points: the mean score of the points in each of
    /// `bins` equal bins of `0..=last step`, placed at the bin's right edge (empty bins
    /// give none), so the last point stays at the run's last step. A run logs a score
    /// every iteration (thousands over a baseline's budget); drawn in a number of bins
    /// that divides `bins`, over the same steps, each drawn bin holds whole thinned
    /// bins, and its value is their mean.
    pub fn thinned(&self, bins: usize) -> Curve {
        let Some(&(end, _)) = self.points.last() else { return self.clone() };
        if self.points.len() <= bins || end <= 0.0 {
            return self.clone();
        }
        let mut sums = vec![(0.0, 0usize); bins];
        for &(x, y) in &self.points {
            // Bin k holds (end·k/bins, end·(k+1)/bins], as `binned` draws them.
            let k = ((x * bins as f64 / end).ceil() as usize).clamp(1, bins) - 1;
            sums[k] = (sums[k].0 + y, sums[k].1 + 1);
        }
        let edge = |k: usize| if k + 1 == bins { end } else { end * (k + 1) as f64 / bins as f64 };
        let points = sums
            .iter()
            .enumerate()
            .filter(|(_, s)| s.1 > 0)
            .map(|(k, &(y, n))| (edge(k), y / n as f64))
            .collect();
        Curve { points, holds: self.holds }
    }
}

/// The spec scores of the run in `dir` (none for a run logged before scores were).
pub(crate) fn scores(dir: &Path) -> Result<Curve> {
    let manifest = read_json(&dir.join(schrl::store::MANIFEST))?;
    // SCHRL and HTLTL spend their first steps on the general controller, which has no
    // spec score; their joint iterations count from its budget on.
    let offset = match manifest["kind"].as_str() {
        Some("joint") => {
            // Every general controller the run trained counts (a retried one too,
            // `schrl train --controller-tries`).
            let generals = match manifest["settings"]["controller"].as_str() {
                Some(c) => vec![PathBuf::from(c)],
                None => {
                    match schrl::store::controller::load_general_choice(dir).map_err(super::store_error)? {
                        Some(choice) => choice.tries.iter().map(|t| dir.join(&t.dir)).collect(),
                        None => vec![dir.join(schrl::store::controller::GENERAL)],
                    }
                }
            };
            let mut steps = 0.0;
            for general in generals {
                let m = read_json(&general.join(schrl::store::MANIFEST))?;
                steps += m["settings"]["total_steps"].as_f64().with_context(|| {
                    format!("{}: no settings.total_steps", general.join(schrl::store::MANIFEST).display())
                })?;
            }
            steps
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
        runs.push(CurveRun {
            task: task.into(),
            method: method.into(),
            source: CurveSource::Run(dir.into()),
        });
    }
    for path in &args.results {
        let records = crate::experiment::record::read_results(path)?;
        let before = runs.len();
        let mut without = 0;
        for r in records {
            match r.curve {
                Some(curve) => runs.push(CurveRun {
                    task: r.task,
                    method: r.method,
                    source: CurveSource::Recorded(curve),
                }),
                None => without += 1,
            }
        }
        if runs.len() == before {
            bail!(
                "{}: no record carries its run's curve (records written before curves were kept \
                 have none); draw those runs from their directories with --run TASK:METHOD:DIR",
                path.display()
            );
        }
        if without > 0 {
            eprintln!("{}: {without} records without a curve left out", path.display());
        }
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
    /// Where its scores come from.
    pub source: CurveSource,
}

/// Where a run's spec scores are read.
#[derive(Clone, Debug)]
pub enum CurveSource {
    /// Its run directory of `schrl train` or `schrl baseline train` (`metrics.jsonl`).
    Run(PathBuf),
    /// Its experiment record's copy ([`crate::experiment::record::Record::curve`]).
    Recorded(Curve),
}

/// The spec score of training runs against environment steps, in `bins` points, mean
/// ± std over each (task, method)'s runs: a panel per task, a line per method, in the
/// order given.
pub fn save_curves(runs: &[CurveRun], bins: usize, out: &Path, force: bool) -> Result<()> {
    sim::render::check_target(out, force)?;
    // (task, method) in the order given, each with its runs' points.
    let mut cells: Vec<((String, String), Vec<Curve>)> = vec![];
    for CurveRun { task, method, source } in runs {
        let points = match source {
            CurveSource::Run(dir) => {
                let points = scores(dir)?;
                if points.points.is_empty() {
                    bail!(
                        "{}: no spec scores (runs trained before the score was logged have none)",
                        dir.join("metrics.jsonl").display()
                    );
                }
                points
            }
            CurveSource::Recorded(curve) if curve.points.is_empty() => {
                bail!("the recorded curve of a {task} {method} run has no points")
            }
            CurveSource::Recorded(curve) => curve.clone(),
        };
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

#[cfg(test)]
mod tests {
    use super::*;

    /// A record keeps 200 of a run's 4000 scores; the 40 bins of a figure drawn from
    /// them are the ones drawn from every score.
    #[test]
    fn a_thinned_curve_draws_the_same_bins_as_the_whole_one() {
        let points: Vec<(f64, f64)> =
            (1..=4000).map(|i| (1000.0 * i as f64, ((i * 7919) % 101) as f64 / 10.0 - 5.0)).collect();
        let whole = Curve { points, holds: false };
        let thin = whole.thinned(200);
        assert_eq!(thin.points.len(), 200);
        assert_eq!(thin.points.last().unwrap().0, 4.0e6, "the last point stays at the run's last step");
        let (a, b) = (binned(&whole, 4.0e6, 40), binned(&thin, 4.0e6, 40));
        for (k, (a, b)) in a.iter().zip(&b).enumerate() {
            assert!((a.unwrap() - b.unwrap()).abs() < 1e-9, "bin {k}: {a:?} vs {b:?}");
        }
        let short = Curve { points: whole.points[..150].to_vec(), holds: true };
        assert_eq!(short.thinned(200), short, "a curve already short enough is kept");
    }
}
