//! `schrl robustness`: monitor a recorded trace against a spec.

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use stl::{Semantics, Spec};

use super::spec_text::SpecText;

/// Arguments of `schrl robustness`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// The spec: formula text, or @FILE to read it from a file.
    #[arg(long)]
    spec: String,
    /// CSV trace: a header row naming the signals, then one row of numbers per step.
    #[arg(long)]
    trace: PathBuf,
    /// Semantics: hard, soft:<alpha> (the paper's softmax-weighted mean) or
    /// lse:<temperature> (log-sum-exp).
    #[arg(long, default_value = "hard")]
    semantics: Semantics,
    /// Smooth only and/or/implies; keep eventually/globally/until hard.
    #[arg(long)]
    smooth_logic_only: bool,
    /// Start step at which robustness is evaluated.
    #[arg(long, default_value_t = 0)]
    at: usize,
    /// Also write ∂ρ/∂trace to this CSV file (same header and shape as the trace).
    #[arg(long)]
    gradient: Option<PathBuf>,
}

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
    let mut rdr = csv::ReaderBuilder::new()
        .has_headers(true)
        .trim(csv::Trim::All)
        .from_path(path)
        .with_context(|| format!("cannot read trace {shown}"))?;
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
    let text = SpecText::load(&args.spec)?;
    let formula = text.parse()?;
    let trace = read_trace(&args.trace)?;
    let spec = Spec::builder(formula).signals(trace.names.clone()).build().map_err(|e| text.explain(e))?;
    let mut sem = args.semantics;
    if args.smooth_logic_only {
        sem = sem.logic_only();
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
    println!("{rho}");
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
