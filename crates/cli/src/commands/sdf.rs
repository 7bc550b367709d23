//! `schrl sdf`: fit a neural signed distance to a map and check it.

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use schrl::task::neural_sdf::{NeuralSdf, SdfFitConfig};
use sim::Map;

/// Subcommands of `schrl sdf`.
#[derive(clap::Subcommand, Debug)]
pub enum Command {
    /// Fit an MLP to a map's exact signed distance, save it, report the held-out fit.
    Fit(FitArgs),
    /// Report the fit of a saved network against its map's exact distance.
    Check(CheckArgs),
}

/// Arguments of `schrl sdf fit`.
#[derive(clap::Args, Debug)]
pub struct FitArgs {
    /// Map: walls or duck.
    #[arg(long, default_value = "walls")]
    map: String,
    /// Where to save the network (JSON).
    #[arg(long)]
    out: PathBuf,
    /// Also draw the learned distance over the map to this PNG or SVG (ground maps).
    #[arg(long)]
    png: Option<PathBuf>,
    /// Adam steps.
    #[arg(long, default_value_t = SdfFitConfig::default().steps)]
    steps: usize,
    /// Seed of samples and initial weights.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Replace existing outputs.
    #[arg(long)]
    force: bool,
}

/// Arguments of `schrl sdf check`.
#[derive(clap::Args, Debug)]
pub struct CheckArgs {
    /// A network saved by `schrl sdf fit`.
    #[arg(long)]
    sdf: PathBuf,
}

/// Runs `schrl sdf ...`.
pub fn run(cmd: Command) -> Result<()> {
    match cmd {
        Command::Fit(args) => fit(args),
        Command::Check(args) => check(args),
    }
}

fn map_named(name: &str) -> Result<Map> {
    Map::by_name(name).ok_or_else(|| anyhow::anyhow!("unknown map '{name}': expected walls or duck"))
}

fn print_report(r: &schrl::task::neural_sdf::FitReport) {
    println!("mean abs error: {:.4}", r.mean_abs_error);
    println!("max abs error: {:.4}", r.max_abs_error);
    println!("sign agreement near surfaces: {:.4}", r.sign_agreement_near);
    println!("sign agreement: {:.4}", r.sign_agreement);
}

fn fit(args: FitArgs) -> Result<()> {
    let map = map_named(&args.map)?;
    if args.steps == 0 {
        bail!("--steps must be at least 1");
    }
    if args.out.exists() && !args.force {
        bail!("{} already exists; pass --force to replace it", args.out.display());
    }
    let cfg = SdfFitConfig { steps: args.steps, seed: args.seed, ..SdfFitConfig::default() };
    let start = std::time::Instant::now();
    let (net, report) = NeuralSdf::fit(&map, &cfg).map_err(anyhow::Error::msg)?;
    schrl::store::sdf::save(&net, &args.out, args.force).map_err(super::store_error)?;
    println!(
        "fitted the {} map's distance in {:.1} s ({} steps, final loss {:.5}); saved {}",
        map.name(),
        start.elapsed().as_secs_f64(),
        args.steps,
        report.final_loss,
        args.out.display()
    );
    if let Some(png) = &args.png {
        sim::render::save_field(&map, &|p| net.distance(p), png, args.force)
            .with_context(|| format!("cannot draw {}", png.display()))?;
        println!("wrote {}", png.display());
    }
    print_report(&report);
    Ok(())
}

fn check(args: CheckArgs) -> Result<()> {
    let net = schrl::store::sdf::load(&args.sdf)?;
    let map = map_named(&net.map)?;
    let report = net.evaluate(&map, 0xC4EC, 4000).map_err(anyhow::Error::msg)?;
    print_report(&report);
    Ok(())
}
