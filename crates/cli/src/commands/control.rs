//! `schrl control`: train and evaluate goal-conditioned PPO controllers.

use std::io::Write;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use indicatif::{ProgressBar, ProgressStyle};
use schrl::control::checkpoint;
use schrl::control::trainer::open_map;
use schrl::control::{ControlConfig, ControlMetrics, ControlTrainer, PpoConfig, evaluate};
use sim::render::{ChartPanel, Goal, PathKind, Polyline, RobotMarker, Scene};
use sim::{Map, Robot};

/// Subcommands of `schrl control`.
#[derive(clap::Subcommand, Debug)]
pub enum Command {
    /// Train a controller that drives a robot to random goals.
    Train(TrainArgs),
    /// Measure how often a trained controller reaches random goals.
    Eval(EvalArgs),
}

/// Arguments of `schrl control train`.
#[derive(clap::Args, Debug)]
pub struct TrainArgs {
    /// Robot: point, car, drone, or doggo (needs the `mujoco` feature).
    #[arg(long)]
    robot: Option<Robot>,
    /// Map whose free space goals are drawn from (default: empty for ground robots,
    /// floor for the drone).
    #[arg(long)]
    map: Option<String>,
    /// Environment steps (default: the robot's budget for ≥ 95 % success).
    #[arg(long)]
    steps: Option<usize>,
    /// Seed of weights, environments and noise.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// PPO hyper-parameters: reference (the authors') or cleanrl.
    #[arg(long, default_value = "reference")]
    preset: String,
    /// Environments stepped together.
    #[arg(long)]
    num_envs: Option<usize>,
    #[command(flatten)]
    run: super::RunDirArgs,
    /// Save a checkpoint every this many updates (and at the end).
    #[arg(long, default_value_t = 25)]
    save_every: usize,
    /// Episodes of the evaluation after training (0: none).
    #[arg(long, default_value_t = 200)]
    eval_episodes: usize,
}

/// Arguments of `schrl control eval`.
#[derive(clap::Args, Debug)]
pub struct EvalArgs {
    /// Checkpoint (run) directory.
    #[arg(long)]
    ckpt: PathBuf,
    /// Episodes (one random start and goal each).
    #[arg(long, default_value_t = 500)]
    episodes: usize,
    /// Seed of starts and goals.
    #[arg(long, default_value_t = 12345)]
    seed: u64,
    /// Map (default: the one the controller trained on).
    #[arg(long)]
    map: Option<String>,
    /// Step limit of an episode.
    #[arg(long, default_value_t = 1000)]
    max_steps: usize,
    /// Draw a few executed trajectories to this PNG or SVG.
    #[arg(long)]
    out: Option<PathBuf>,
    /// Replace the picture if it exists.
    #[arg(long)]
    force: bool,
}

/// Runs `schrl control ...`.
pub fn run(cmd: Command) -> Result<()> {
    match cmd {
        Command::Train(args) => train(args),
        Command::Eval(args) => eval(args),
    }
}

fn parse_map(name: &str) -> Result<Map> {
    Map::by_name(name)
        .with_context(|| format!("unknown map '{name}': expected one of {}", sim::map::MAP_NAMES.join(", ")))
}

fn train(args: TrainArgs) -> Result<()> {
    let mut trainer = if args.run.resume {
        if !checkpoint::exists(&args.run.out) {
            bail!("--resume: {} holds no controller checkpoint", args.run.out.display());
        }
        let mut t = checkpoint::load(&args.run.out)?;
        if let Some(robot) = args.robot
            && robot != t.robot
        {
            bail!("--resume: {} is a {} run, not {robot}", args.run.out.display(), t.robot);
        }
        if let Some(steps) = args.steps {
            t.config.total_steps = steps;
        }
        t
    } else {
        let Some(robot) = args.robot else { bail!("--robot is required (point, car or drone)") };
        if checkpoint::exists(&args.run.out) && !args.run.force {
            bail!(
                "{} already holds a controller run; pass --force to replace it or --resume",
                args.run.out.display()
            );
        }
        let mut config = ControlConfig::for_robot(robot);
        config.ppo = PpoConfig::preset(&args.preset)
            .with_context(|| format!("unknown --preset '{}': expected reference or cleanrl", args.preset))?;
        if let Some(n) = args.num_envs {
            config.ppo.num_envs = n;
            config.ppo.rollout = config.ppo.rollout.div_ceil(n) * n;
        }
        config.map = match &args.map {
            Some(m) => parse_map(m)?.name().to_string(),
            None => open_map(robot).name().to_string(),
        };
        config.seed = args.seed;
        if let Some(steps) = args.steps {
            config.total_steps = steps;
        }
        ControlTrainer::new(config)?
    };
    std::fs::create_dir_all(&args.run.out)
        .with_context(|| format!("cannot create {}", args.run.out.display()))?;
    let updates = trainer.updates;
    let (mut history, mut log) =
        super::open_metrics_log(&args.run.out, args.run.resume, |m: &ControlMetrics| m.update <= updates)?;
    let total = trainer.total_updates();
    let bar = ProgressBar::new(total as u64);
    bar.set_style(ProgressStyle::with_template("{bar:40} {pos}/{len} updates {elapsed_precise} {msg}")?);
    bar.set_position(trainer.updates as u64);
    let start = std::time::Instant::now();
    let first_step = trainer.steps;
    while !trainer.finished() {
        let m = trainer.train_update()?;
        writeln!(log, "{}", serde_json::to_string(&m)?)?;
        bar.set_position(m.update as u64);
        bar.set_message(format!(
            "success {} return {} {:.0} steps/s",
            m.success_rate.map_or("-".into(), |s| format!("{s:.2}")),
            m.mean_return.map_or("-".into(), |r| format!("{r:.1}")),
            m.steps_per_sec
        ));
        history.push(m);
        if trainer.updates % args.save_every.max(1) == 0 {
            checkpoint::save(&args.run.out, &trainer, true)?;
        }
    }
    bar.finish_and_clear();
    checkpoint::save(&args.run.out, &trainer, true)?;
    let wall = start.elapsed().as_secs_f64();
    let curve = args.run.out.join("training_curve.png");
    save_curve(&history, &curve)?;
    println!(
        "trained the {} for {} environment steps in {wall:.1} s ({:.0} steps/s); run in {}",
        trainer.robot,
        trainer.steps,
        (trainer.steps - first_step) as f64 / wall.max(1e-9),
        args.run.out.display()
    );
    if args.eval_episodes > 0 {
        let map = parse_map(&trainer.config.map)?;
        let r =
            evaluate(&trainer.controller(), &map, args.eval_episodes, 12345, trainer.config.episode_steps)?;
        print_eval(&r);
    }
    Ok(())
}

/// Success rate (top, 0–1) and mean episode return (bottom) against steps.
fn save_curve(history: &[ControlMetrics], out: &Path) -> Result<()> {
    let series = |f: &dyn Fn(&ControlMetrics) -> Option<f64>| -> Vec<(f64, f64)> {
        history.iter().filter_map(|m| f(m).map(|y| (m.steps as f64, y))).collect()
    };
    let panels = [
        ChartPanel { series: vec![series(&|m| m.success_rate)], y_range: Some((0.0, 1.0)) },
        ChartPanel { series: vec![series(&|m| m.mean_return)], y_range: None },
    ];
    sim::render::save_chart(&panels, out, true)?;
    Ok(())
}

fn print_eval(r: &schrl::control::EvalResult) {
    println!("success rate: {}", r.success_rate);
    match r.mean_steps_to_reach {
        Some(s) => println!("mean steps to reach: {s:.1}"),
        None => println!("mean steps to reach: -"),
    }
    println!("failures: {} collisions, {} time-outs (of {} episodes)", r.collisions, r.timeouts, r.episodes);
}

fn eval(args: EvalArgs) -> Result<()> {
    if args.episodes == 0 {
        bail!("--episodes must be at least 1");
    }
    let controller = checkpoint::load_controller(&args.ckpt)?;
    let trained_map = checkpoint::load(&args.ckpt)?.config.map;
    let map = parse_map(args.map.as_deref().unwrap_or(&trained_map))?;
    let r = evaluate(&controller, &map, args.episodes, args.seed, args.max_steps)?;
    if let Some(out) = &args.out {
        draw_episodes(&controller, &map, args.seed, args.max_steps, out, args.force)?;
        println!("wrote {}", out.display());
    }
    print_eval(&r);
    Ok(())
}

/// Draws six evaluation episodes: start, goal and the executed trajectory.
fn draw_episodes(
    controller: &schrl::control::Controller,
    map: &Map,
    seed: u64,
    max_steps: usize,
    out: &Path,
    force: bool,
) -> Result<()> {
    let mut scene = Scene::new(map.clone());
    let mut cache = Default::default();
    for k in 0..6 {
        let mut env = sim::make_env(controller.robot, map.clone())?;
        env.set_max_steps(max_steps);
        let mut obs = env.reset(sim::vec_env::member_seed(seed, k), None)?;
        scene.goals.push(Goal { center: env.goal().to_vec(), radius: env.reach_radius() });
        let mut points = vec![env.position().to_vec()];
        let mut action = vec![0.0; env.action_space().dim()];
        loop {
            controller.act(&obs, 1, &mut cache, &mut action);
            let (o, s) = env.step(&action)?;
            obs = o;
            points.push(env.position().to_vec());
            if s.reached || s.terminated() || s.truncated {
                break;
            }
        }
        scene.robots.push(RobotMarker {
            position: env.position().to_vec(),
            heading: env.heading(),
            radius: env.radius(),
        });
        scene.paths.push(Polyline { points, kind: PathKind::Executed });
    }
    sim::render::save(&scene, out, force)?;
    Ok(())
}
