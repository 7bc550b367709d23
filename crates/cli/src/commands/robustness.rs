//! `schrl robustness`: monitor a recorded trace against a spec.

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use schrl::run::evaluate::RunRecord;
use schrl::run::execute::{Execution, Outcome};
use stl::{Semantics, Spec};

use super::spec_text::SpecText;

/// Arguments of `schrl robustness`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// The spec: formula text, or @FILE to read it from a file.
    #[arg(long, required_unless_present = "task", conflicts_with = "task")]
    spec: Option<String>,
    /// CSV trace: a header row naming the signals, then one row of numbers per step.
    #[arg(long, required_unless_present = "runs", conflicts_with = "runs")]
    trace: Option<PathBuf>,
    /// Judge recorded runs against this task instead (a task file, or a built-in name
    /// with --robot): its goals, `safe` and regions to avoid, as `schrl eval` judges.
    #[arg(long, requires = "runs")]
    task: Option<String>,
    /// Robot of a built-in --task [default: point].
    #[arg(long, requires = "task")]
    robot: Option<sim::Robot>,
    /// Runs written by `schrl eval --trajectories` (JSON lines) to judge again: prints
    /// each run's robustness and verdict, and fails if any differs from the record.
    #[arg(long, requires = "task")]
    runs: Option<PathBuf>,
    /// Semantics: hard, soft:ALPHA (the paper's softmax-weighted mean) or
    /// lse:TEMPERATURE (log-sum-exp); a smooth one may add ,until=recursive (the
    /// default, O(T)) or ,until=flat (the definition smoothed as written, O(T·w)).
    #[arg(long, default_value = "hard")]
    semantics: Semantics,
    /// Smooth only and/or/implies; keep eventually/globally/until hard.
    #[arg(long)]
    smooth_logic_only: bool,
    /// Where `φ U[a,b] ψ` asks for φ: standard (from t, as rtamt and Maler–Nickovic) or
    /// paper (from t+a, the paper's App. C, which the shipped tasks use).
    #[arg(long, default_value = "standard")]
    until: stl::UntilRule,
    /// Start step at which robustness is evaluated.
    #[arg(long, default_value_t = 0)]
    at: usize,
    /// Also write ∂ρ/∂trace to this CSV file (same header and shape as the trace).
    #[arg(long)]
    gradient: Option<PathBuf>,
    /// Replace an existing --gradient file.
    #[arg(long)]
    force: bool,
}

/// The largest trace read (64 MiB: a million rows of a few signals).
const MAX_TRACE_BYTES: u64 = 64 << 20;

/// A trace read from CSV: signal names and row-major values.
pub struct Trace {
    /// Header names.
    pub names: Vec<String>,
    /// `steps × names.len()` values.
    pub values: Vec<f64>,
}

/// Reads a CSV trace, checking names, shape and numbers.
pub fn read_trace(path: &std::path::Path) -> Result<Trace> {
    let shown = path.display();
    let text = schrl::task::read_text(path, MAX_TRACE_BYTES)
        .with_context(|| format!("cannot read trace {shown}"))?;
    let mut rdr =
        csv::ReaderBuilder::new().has_headers(true).trim(csv::Trim::All).from_reader(text.as_bytes());
    let names: Vec<String> = rdr
        .headers()
        .with_context(|| format!("{shown}: cannot read the header row"))?
        .iter()
        .map(str::to_string)
        .collect();
    if names.is_empty() || names.iter().all(String::is_empty) {
        bail!("{shown}: the header row is empty; it must name the signals");
    }
    for (i, n) in names.iter().enumerate() {
        if !stl::is_valid_name(n) {
            bail!(
                "{shown}: header column {} is '{n}', not a valid signal name ([A-Za-z_][A-Za-z0-9_.]*, not a keyword)",
                i + 1
            );
        }
        if names[..i].contains(n) {
            bail!("{shown}: signal '{n}' appears twice in the header");
        }
    }
    let mut values = Vec::new();
    for rec in rdr.records() {
        let rec = rec.map_err(|e| match e.kind() {
            csv::ErrorKind::UnequalLengths { pos, expected_len, len } => anyhow::anyhow!(
                "{shown}: line {}: {len} fields, but the header has {expected_len}",
                pos.as_ref().map_or(0, |p| p.line())
            ),
            _ => anyhow::anyhow!("{shown}: {e}"),
        })?;
        let line = rec.position().map_or(0, |p| p.line());
        for (field, name) in rec.iter().zip(&names) {
            let v: f64 = field.parse().ok().filter(|v: &f64| v.is_finite()).with_context(|| {
                format!("{shown}: line {line}, column '{name}': '{field}' is not a finite number")
            })?;
            values.push(v);
        }
    }
    if values.is_empty() {
        bail!("{shown}: the trace has no rows; robustness needs at least one step");
    }
    Ok(Trace { names, values })
}

/// Runs the command.
pub fn run(args: Args) -> Result<()> {
    if let (Some(task), Some(runs)) = (&args.task, &args.runs) {
        return rejudge(&super::task::resolve(args.robot, task)?, runs);
    }
    let (Some(spec), Some(trace_path)) = (&args.spec, &args.trace) else {
        bail!("--spec and --trace are needed (or --task with --runs)");
    };
    let text = SpecText::load(spec)?;
    let formula = text.parse()?;
    let trace = read_trace(trace_path)?;
    let spec = Spec::builder(formula)
        .until(args.until)
        .signals(trace.names.clone())
        .build()
        .map_err(|e| text.explain(e))?;
    let mut sem = args.semantics;
    if args.smooth_logic_only {
        sem = sem.logic_only();
    }
    let rows = trace.values.len() / trace.names.len();
    if args.at >= rows {
        bail!("--at {}: the trace has {rows} rows (steps 0..={})", args.at, rows - 1);
    }
    if let Some(out) = &args.gradient {
        check_gradient_target(out, trace_path, args.force)?;
    }
    let mut ev = spec.evaluator();
    let rho = match &args.gradient {
        None => ev.robustness_at(&trace.values, args.at, &sem)?,
        Some(out) => {
            let mut grad = vec![0.0; trace.values.len()];
            let rho = ev.gradient(&trace.values, args.at, &sem, &mut grad)?;
            write_gradient(out, &trace.names, &grad)?;
            rho
        }
    };
    // `true` and `false` are ±∞ in STL; the library carries them as ±top so that
    // smooth semantics stay finite.
    match rho {
        r if r >= sem.top => println!("inf"),
        r if r <= -sem.top => println!("-inf"),
        r => println!("{r}"),
    }
    Ok(())
}

/// Refuses a gradient file that is the trace itself, or that exists without --force.
fn check_gradient_target(out: &std::path::Path, trace: &std::path::Path, force: bool) -> Result<()> {
    let same = match (std::fs::canonicalize(out), std::fs::canonicalize(trace)) {
        (Ok(a), Ok(b)) => a == b,
        _ => false,
    };
    if same {
        bail!("--gradient {} is the trace itself; write the gradient to another file", out.display());
    }
    if out.exists() && !force {
        bail!("--gradient {} already exists; pass --force to replace it", out.display());
    }
    Ok(())
}

fn write_gradient(path: &std::path::Path, names: &[String], grad: &[f64]) -> Result<()> {
    let mut w = csv::Writer::from_path(path).with_context(|| format!("cannot write {}", path.display()))?;
    w.write_record(names)?;
    for row in grad.chunks(names.len()) {
        w.write_record(row.iter().map(|g| g.to_string()))?;
    }
    w.flush()?;
    Ok(())
}

/// Judges every run recorded in `path` again under `task` and compares verdicts.
fn rejudge(task: &schrl::task::Task, path: &std::path::Path) -> Result<()> {
    use std::io::BufRead;
    let shown = path.display();
    let spec = task.execution_spec();
    let file = std::fs::File::open(path).with_context(|| format!("cannot read runs {shown}"))?;
    let (mut runs, mut satisfied, mut differ) = (0usize, 0usize, 0usize);
    println!("group,index,robustness,verdict");
    for (i, line) in std::io::BufReader::new(file).lines().enumerate() {
        let line = line.with_context(|| format!("{shown}: line {}", i + 1))?;
        if line.trim().is_empty() {
            continue;
        }
        let r: RunRecord = serde_json::from_str(&line).with_context(|| {
            format!("{shown}: line {}: not a run written by `schrl eval --trajectories`", i + 1)
        })?;
        if r.reached.iter().chain(&r.positions).chain(&r.waypoints).any(|p| p.len() != task.map.dim()) {
            bail!("{shown}: line {}: positions are not {}-D, as the task's map is", i + 1, task.map.dim());
        }
        let verdict = Execution {
            planned: r.waypoints.clone(),
            executed: r.reached.clone(),
            trajectory: vec![],
            headings: vec![],
            outcome: recorded_outcome(&r, task.steps),
            steps: r.steps,
            reached_at: r.reached_at.clone(),
            control_return: 0.0,
            robustness: 0.0,
            entered: None,
        };
        let judged = spec.judge(&r.reached, &r.positions, &r.reached_at);
        let run = Execution { robustness: judged.robustness, entered: judged.entered, ..verdict };
        let (rho, says) = (run.robustness, run.verdict());
        println!("{},{},{rho},{says}", r.group, r.index);
        runs += 1;
        satisfied += usize::from(run.satisfied());
        if run.satisfied() != r.satisfied || says != r.outcome {
            differ += 1;
            eprintln!("{shown}: line {}: recorded '{}', judged '{says}'", i + 1, r.outcome);
        }
    }
    println!("{runs} runs, {satisfied} satisfy the task, {differ} differ from the record");
    if differ > 0 {
        bail!("{differ} of {runs} runs judged differently from {shown}");
    }
    Ok(())
}

/// How a recorded run ended: completed when every waypoint was reached; otherwise
/// what the simulator said (collisions and falls are not visible in positions).
fn recorded_outcome(r: &RunRecord, steps: usize) -> Outcome {
    match r.outcome.as_str() {
        _ if r.reached.len() == steps + 1 => Outcome::Completed,
        "collided" => Outcome::Collided,
        "fell" => Outcome::Fell,
        _ => Outcome::TimedOut,
    }
}

#[cfg(test)]
mod tests {
    use proptest::prelude::*;

    proptest! {
        #![proptest_config(ProptestConfig { cases: 256, failure_persistence: None, ..ProptestConfig::default() })]

        /// Whatever a trace file holds, reading it gives a trace or an error naming
        /// the file, never a panic; a trace that reads is rectangular and finite.
        #[test]
        fn arbitrary_trace_files_read_or_fail_cleanly(
            text in prop_oneof![
                "\\PC{0,120}",
                proptest::collection::vec(
                    prop_oneof!["x", "y", "x,y", ",", "1", "-2.5", "nan", "inf", "1e400", "\"", " ", "\n", "\r\n"],
                    0..30,
                ).prop_map(|v| v.concat()),
            ]
        ) {
            let scratch = tempfile::tempdir().unwrap();
            let dir = scratch.path();
            let path = dir.join("t.csv");
            std::fs::write(&path, &text).unwrap();
            match super::read_trace(&path) {
                Ok(t) => {
                    prop_assert!(!t.names.is_empty() && t.values.len() % t.names.len() == 0);
                    prop_assert!(t.values.iter().all(|v| v.is_finite()));
                }
                Err(e) => prop_assert!(format!("{e:#}").contains("t.csv"), "{:#}", e),
            }
        }
    }
}
