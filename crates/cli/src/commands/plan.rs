//! `schrl plan`: train the GRU-ODE planner on a task, sample from it, and time
//! its plans against the gradient planner.

use std::io::Write;
use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use indicatif::{ProgressBar, ProgressStyle};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use schrl::checkpoint::{self, PlannerMeta};
use schrl::cpg::{CpgConfig, Method, PlanTrainer};
use schrl::deployed::{DeployedPlanner, PlanScratch};
use schrl::gradient_planner::{self, GradientPlannerConfig};
use schrl::joint::mean_std;
use schrl::planner::PlannerKind;
use schrl::tasks::{SafeAlong, Task, TaskKind};
use sim::render::{Goal, PathKind, Polyline, Scene};
use stl::Semantics;

/// Subcommands of `schrl plan`.
#[derive(clap::Subcommand, Debug)]
pub enum Command {
    /// Train a planner with the constrained (or plain) policy gradient.
    Train(TrainArgs),
    /// Sample paths from a trained planner and report how many satisfy the spec.
    Sample(SampleArgs),
    /// Time per plan: the trained network (deployed, no autodiff) against the
    /// gradient planner, from the same starts (paper Table 5).
    Time(TimeArgs),
}

/// A trained planner and the starts to plan from: shared by `plan sample` and `plan time`.
#[derive(clap::Args, Debug)]
pub struct CheckpointStarts {
    /// Checkpoint directory of a trained planner (`schrl plan train --out`).
    #[arg(long)]
    ckpt: PathBuf,
    /// Starts to plan from (the paper times 100).
    #[arg(long, default_value_t = 100)]
    n: usize,
    /// Seed of the starts, the sampling noise and the gradient planner's initialisations.
    #[arg(long, default_value_t = 1)]
    seed: u64,
}

/// Arguments of `schrl plan time`.
#[derive(clap::Args, Debug)]
pub struct TimeArgs {
    #[command(flatten)]
    from: CheckpointStarts,
}

/// Arguments of `schrl plan train`.
#[derive(clap::Args, Debug)]
pub struct TrainArgs {
    /// Robot (planner tasks exist for point).
    #[arg(long, default_value = "point")]
    robot: String,
    /// Task: seq, cover, branch, loop or signal.
    #[arg(long)]
    task: TaskKind,
    /// Planner network: gru-ode (the paper's), or the ablations gru and mlp (Fig. 6).
    #[arg(long, default_value = "gru-ode")]
    planner: PlannerKind,
    /// Where the task's `safe` is checked: segments (the task's default: the straight
    /// segment into each waypoint, what a controller drives) or waypoints (the
    /// paper's literal `□ safe` on the plan's states).
    #[arg(long)]
    safe_along: Option<SafeAlong>,
    /// Restart from a fresh initialisation when an attempt has not had half its
    /// sampled paths satisfy the spec within this many updates (0: never).
    #[arg(long, default_value_t = CpgConfig::default().restart_after.unwrap_or(0))]
    restart_after: usize,
    /// cpg (constrained policy gradient) or pg (policy gradient only).
    #[arg(long, default_value = "cpg", value_parser = parse_method)]
    method: Method,
    /// Semantics of the spec in the loss: hard, soft:<alpha> or lse:<temperature>.
    #[arg(long, default_value = "soft:10")]
    semantics: Semantics,
    /// Seed of parameters, starts and noise.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Most gradient updates.
    #[arg(long, default_value_t = 3000)]
    updates: usize,
    /// Stop once this fraction of sampled paths satisfies the spec.
    #[arg(long, default_value_t = 0.95)]
    target: f64,
    /// Checkpoint directory (metrics.jsonl is written there too).
    #[arg(long)]
    out: PathBuf,
    /// Replace an existing checkpoint.
    #[arg(long)]
    force: bool,
}

/// Arguments of `schrl plan sample`.
#[derive(clap::Args, Debug)]
pub struct SampleArgs {
    #[command(flatten)]
    from: CheckpointStarts,
    /// Draw the sampled paths (at most 20) on the map to this PNG or SVG.
    #[arg(long)]
    out: Option<PathBuf>,
    /// Replace the picture if it exists.
    #[arg(long)]
    force: bool,
    /// Take each start's mean path (the deployed plan) instead of sampling.
    #[arg(long)]
    mean: bool,
}

fn parse_method(s: &str) -> Result<Method, String> {
    match s {
        "cpg" => Ok(Method::Cpg),
        "pg" => Ok(Method::Pg),
        other => Err(format!("unknown method '{other}': expected cpg or pg")),
    }
}

/// Runs `schrl plan ...`.
pub fn run(cmd: Command) -> Result<()> {
    match cmd {
        Command::Train(args) => train(args),
        Command::Sample(args) => sample(args),
        Command::Time(args) => time(args),
    }
}

fn train(args: TrainArgs) -> Result<()> {
    if args.robot != "point" {
        bail!("planner tasks exist for the point robot only so far, not '{}'", args.robot);
    }
    if !(0.0..=1.0).contains(&args.target) {
        bail!("--target must be a fraction in [0, 1], got {}", args.target);
    }
    if !args.force && args.out.join("planner.json").exists() {
        bail!("{} already holds a checkpoint; pass --force to replace it", args.out.display());
    }
    std::fs::create_dir_all(&args.out).with_context(|| format!("cannot create {}", args.out.display()))?;
    let metrics_path = args.out.join("metrics.jsonl");
    let mut metrics = std::fs::File::create(&metrics_path)
        .with_context(|| format!("cannot write {}", metrics_path.display()))?;
    let cfg = CpgConfig {
        method: args.method,
        semantics: args.semantics,
        seed: args.seed,
        planner: args.planner,
        restart_after: (args.restart_after > 0).then_some(args.restart_after),
        ..CpgConfig::default()
    };
    let mut task = Task::point(args.task);
    if let Some(along) = args.safe_along {
        task.safe_along = along;
    }
    let mut trainer = PlanTrainer::new(task, cfg)?;
    let bar = ProgressBar::new(args.updates as u64);
    bar.set_style(
        ProgressStyle::with_template("{bar:40} {pos}/{len} updates {msg}").expect("valid template"),
    );
    let start = std::time::Instant::now();
    let mut done = 0;
    let mut reached = false;
    for update in 1..=args.updates {
        let s = trainer.update()?;
        done = update;
        writeln!(
            metrics,
            "{}",
            serde_json::json!({
                "update": update, "satisfaction": s.satisfaction, "mean_rho": s.mean_rho,
                "lambda": s.lambda, "loss": s.loss, "seconds": start.elapsed().as_secs_f64(),
                "restarts": trainer.restarts(),
            })
        )?;
        bar.set_position(update as u64);
        bar.set_message(format!("satisfaction {:.2} λ {:.2}", s.satisfaction, s.lambda));
        // Confirm on fresh paths before stopping, so one lucky batch does not end training.
        if s.satisfaction >= args.target && trainer.satisfaction(200)? >= args.target {
            reached = true;
            break;
        }
    }
    bar.finish_and_clear();
    let meta = PlannerMeta {
        robot: args.robot.clone(),
        task: args.task.name().into(),
        method: if args.method == Method::Cpg { "cpg" } else { "pg" }.into(),
        semantics: args.semantics.to_string(),
        seed: args.seed,
        updates: done,
        lambda: trainer.lagrangian().lambda,
        dim: trainer.planner().config().dim,
        hidden: trainer.planner().config().hidden,
        bound: trainer.planner().config().bound,
        min_std: trainer.planner().config().min_std,
        planner: args.planner.name().into(),
        safe_along: trainer.task().safe_along.name().into(),
    };
    checkpoint::save(&args.out, &trainer, &meta, args.force)?;
    let satisfaction = trainer.satisfaction(200)?;
    println!(
        "{} after {done} updates ({:.1} s); checkpoint in {}",
        if reached { "reached the target" } else { "stopped at the update limit" },
        start.elapsed().as_secs_f64(),
        args.out.display()
    );
    println!("updates: {done}");
    println!("restarts: {}", trainer.restarts());
    // Sampled paths are what training sees; mean paths are what `schrl train` deploys.
    println!("mean-path satisfaction: {}", trainer.mean_satisfaction(200)?);
    println!("satisfaction: {satisfaction}");
    Ok(())
}

fn sample(args: SampleArgs) -> Result<()> {
    let loaded = checkpoint::load(&args.from.ckpt)?;
    let task = &loaded.task;
    let mut rng = ChaCha8Rng::seed_from_u64(args.from.seed);
    let g0 = task.sample_starts(&mut rng, args.from.n)?;
    let noise = task.sample_noise(&mut rng, args.from.n)?;
    let paths = if args.mean {
        loaded.planner.mean_path(&g0, task.steps)?
    } else {
        loaded.planner.sample(&g0, &noise)?.paths
    };
    let rho = schrl::tasks::hard_robustness(&task.spec(), &paths)?;
    let satisfied = rho.iter().filter(|r| **r > 0.0).count();
    if let Some(out) = &args.out {
        let mut scene = Scene::new(task.map.clone());
        scene.goals =
            task.goals.iter().map(|g| Goal { center: g.center.clone(), radius: g.radius }).collect();
        let paths: Vec<Vec<Vec<f32>>> = paths.to_vec3()?;
        for p in paths.iter().take(20) {
            let points = p.iter().map(|w| w.iter().map(|&x| x as f64).collect()).collect();
            scene.paths.push(Polyline { points, kind: PathKind::Planned });
        }
        sim::render::save(&scene, out, args.force)?;
        println!("wrote {}", out.display());
    }
    println!("satisfaction: {}", satisfied as f64 / args.from.n.max(1) as f64);
    Ok(())
}

fn time(args: TimeArgs) -> Result<()> {
    if args.from.n == 0 {
        bail!("--n must be at least 1");
    }
    let loaded = checkpoint::load(&args.from.ckpt)?;
    let task = &loaded.task;
    let spec = task.spec();
    let deployed = DeployedPlanner::from_varmap(&loaded.varmap, loaded.planner.config())?;
    let mut rng = ChaCha8Rng::seed_from_u64(args.from.seed);
    let starts: Vec<Vec<f64>> =
        task.sample_starts(&mut rng, args.from.n)?.to_dtype(candle_core::DType::F64)?.to_vec2()?;
    let hard = Semantics::hard();

    // The network: each plan timed alone (mean of n, as Table 5), after one warm-up.
    let (mut scratch, mut path) = (PlanScratch::default(), Vec::new());
    deployed.mean_path_into(&starts[0], task.steps, &mut scratch, &mut path);
    let (mut net_us, mut net_ok) = (Vec::with_capacity(args.from.n), 0);
    for s in &starts {
        let t0 = std::time::Instant::now();
        deployed.mean_path_into(s, task.steps, &mut scratch, &mut path);
        net_us.push(t0.elapsed().as_secs_f64() * 1e6);
        net_ok += (spec.robustness(&path, &hard)? > 0.0) as usize;
    }

    let bar = ProgressBar::new(args.from.n as u64);
    bar.set_style(
        ProgressStyle::with_template("gradient planner {bar:40} {pos}/{len}").expect("valid template"),
    );
    let cfg = GradientPlannerConfig::default();
    let (mut grad_ms, mut grad_ok) = (Vec::with_capacity(args.from.n), 0);
    for s in &starts {
        let t0 = std::time::Instant::now();
        let p = gradient_planner::plan(task, &spec, s, &cfg, &mut rng)?;
        grad_ms.push(t0.elapsed().as_secs_f64() * 1e3);
        grad_ok += p.satisfied() as usize;
        bar.inc(1);
    }
    bar.finish_and_clear();
    let (nm, ns) = mean_std(&net_us);
    let (gm, gs) = mean_std(&grad_ms);
    println!("task: {} (T = {}), {} starts", task.name, task.steps, args.from.n);
    println!("network (deployed mean path): {nm:.2} ± {ns:.2} µs per plan, {net_ok}/{} satisfy", args.from.n);
    println!(
        "gradient planner: {gm:.2} ± {gs:.2} ms per plan, {grad_ok}/{} satisfy (at most {} attempts of {} steps)",
        args.from.n, cfg.restarts, cfg.iterations
    );
    println!("network seconds per plan: {:.3e}", nm * 1e-6);
    println!("gradient seconds per plan: {:.3e}", gm * 1e-3);
    Ok(())
}
