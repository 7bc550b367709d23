//! `schrl control`: train and evaluate goal-conditioned PPO controllers.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use schrl::control::trainer::EVAL_SEED;
use schrl::control::{ControlConfig, NearGoals, PpoConfig};
use schrl::run::evaluate::{ControllerEval, GoalDraw, GoalEpisode, evaluate_controller, goal_episodes};
use schrl::store::{self, RunKind};
use schrl::train::controller::ControllerSession;
use sim::render::{Goal, PathKind, Polyline, RobotMarker, Scene};
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
    /// Seed of weights, environments and noise [default: 0].
    #[arg(long)]
    seed: Option<u64>,
    /// PPO hyper-parameters: reference (the authors') or cleanrl [default: reference].
    #[arg(long)]
    preset: Option<String>,
    /// Environments stepped together.
    #[arg(long, value_parser = super::count::<1, 4096>)]
    num_envs: Option<usize>,
    /// Hidden layer widths of the policy and value networks, e.g. `256,256` [default:
    /// the preset's, 64,64].
    #[arg(long, value_delimiter = ',', value_parser = super::count::<1, 4096>)]
    hidden: Option<Vec<usize>>,
    /// Train an option for this one goal (`X,Y` or `X,Y,Z`) instead of a goal-conditioned
    /// controller: every episode chases it and ends on reaching it (paper App. K). The
    /// evaluation after training still draws random goals.
    #[arg(long, value_delimiter = ',', allow_negative_numbers = true)]
    goal: Option<Vec<f64>>,
    /// Share of random goals drawn near the robot (0–1) [default: 0, every goal
    /// anywhere].
    #[arg(long, value_name = "FRACTION")]
    near_goals: Option<f64>,
    /// Radius of the ball around the robot a near goal is drawn in (m) [default: 1].
    #[arg(long, value_name = "METRES")]
    near_goals_within: Option<f64>,
    /// Reward subtracted on the step the robot falls (Doggo) [default: 0, the paper's
    /// reward].
    #[arg(long, value_name = "REWARD")]
    fall_penalty: Option<f64>,
    /// Reward PPO loses per step per metre the robot strays from the straight segment
    /// between where its goal was set and the goal (0: the paper's reward) [default: 0.1
    /// for the Doggo, 0 for the others].
    #[arg(long)]
    off_track_weight: Option<f64>,
    /// The controller also observes its offset from its track (from where its goal was
    /// set; the planned segment when it executes a plan), in its heading frame; `false`:
    /// the robot's own observation, the paper's [default: true for the Doggo, false for
    /// the others; the bare flag: true].
    #[arg(long, value_name = "BOOL", num_args = 0..=1, default_missing_value = "true")]
    observe_track: Option<bool>,
    #[command(flatten)]
    run: super::RunDirArgs,
    /// Save a checkpoint every this many updates (and at the end).
    #[arg(long, default_value_t = schrl::train::controller::SAVE_EVERY)]
    save_every: usize,
    /// Episodes of the evaluation after training (0: none).
    #[arg(long, default_value_t = 200, value_parser = super::count::<0, 100_000>)]
    eval_episodes: usize,
}

/// Arguments of `schrl control eval`.
#[derive(clap::Args, Debug)]
pub struct EvalArgs {
    /// Checkpoint (run) directory.
    #[arg(long)]
    ckpt: PathBuf,
    /// Episodes (one random start and goal each).
    #[arg(long, default_value_t = 500, value_parser = super::count::<1, 100_000>)]
    episodes: usize,
    /// Seed of starts and goals.
    #[arg(long, default_value_t = EVAL_SEED)]
    seed: u64,
    /// Map (default: the one the controller trained on).
    #[arg(long)]
    map: Option<String>,
    /// Step limit of an episode.
    #[arg(long, default_value_t = 1000, value_parser = super::count::<1, 1_000_000>)]
    max_steps: usize,
    /// Draw each goal within this many metres of the start (beyond the reach radius)
    /// instead of anywhere on the map: the short hops between a plan's waypoints.
    #[arg(long, value_name = "METRES")]
    goals_within: Option<f64>,
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

impl TrainArgs {
    /// The PPO settings the flags ask for.
    fn ppo(&self) -> Result<PpoConfig> {
        let name = self.preset.as_deref().unwrap_or("reference");
        let mut ppo = PpoConfig::preset(name)
            .with_context(|| format!("unknown --preset '{name}': expected reference or cleanrl"))?;
        if let Some(n) = self.num_envs {
            ppo.num_envs = n;
            ppo.rollout = ppo.rollout.div_ceil(n) * n;
        }
        if let Some(h) = &self.hidden {
            ppo.hidden = h.clone();
        }
        Ok(ppo)
    }

    /// The settings of a new run.
    fn settings(&self) -> Result<ControlConfig> {
        let Some(robot) = self.robot else { bail!("--robot is required (point, car, drone or doggo)") };
        let mut config = ControlConfig::for_robot(robot);
        config.ppo = self.ppo()?;
        if let Some(m) = &self.map {
            config.map = parse_map(m)?.name().to_string();
        }
        config.seed = self.seed.unwrap_or(0);
        if let Some(steps) = self.steps {
            config.total_steps = steps;
        }
        config.goal = self.goal.clone();
        config.near_goals = self.near_goals(config.near_goals);
        config.fall_penalty = self.fall_penalty.unwrap_or(config.fall_penalty);
        config.off_track_weight = self.off_track_weight.unwrap_or(config.off_track_weight);
        config.observe_track = self.observe_track.unwrap_or(config.observe_track);
        Ok(config)
    }

    /// `--near-goals` and `--near-goals-within` over `base` (the config's, or a saved
    /// run's); `None` when no goal is drawn near.
    fn near_goals(&self, base: Option<NearGoals>) -> Option<NearGoals> {
        let base = base.unwrap_or(NearGoals { fraction: 0.0, within: 1.0 });
        let n = NearGoals {
            fraction: self.near_goals.unwrap_or(base.fraction),
            within: self.near_goals_within.unwrap_or(base.within),
        };
        (n.fraction != 0.0 || self.near_goals_within.is_some()).then_some(n)
    }

    /// The saved settings, with a new step budget if given; other flags that differ
    /// from the saved run are refused by name.
    fn resumed(&self, saved: &ControlConfig) -> Result<ControlConfig> {
        use super::differs;
        let preset_differs = self.preset.is_some() && self.ppo()? != saved.ppo;
        let map = self.map.as_deref().map(|m| parse_map(m).map(|m| m.name().to_string())).transpose()?;
        super::refuse_conflicts(
            RunKind::Controller,
            &[
                ("--robot", differs(&self.robot, &saved.robot)),
                ("--map", differs(&map, &saved.map)),
                ("--seed", differs(&self.seed, &saved.seed)),
                ("--preset", preset_differs),
                ("--num-envs", differs(&self.num_envs, &saved.ppo.num_envs)),
                ("--hidden", differs(&self.hidden, &saved.ppo.hidden)),
                ("--goal", self.goal.is_some() && self.goal != saved.goal),
                (
                    "--near-goals",
                    (self.near_goals.is_some() || self.near_goals_within.is_some())
                        && self.near_goals(saved.near_goals) != saved.near_goals,
                ),
                ("--fall-penalty", differs(&self.fall_penalty, &saved.fall_penalty)),
                ("--off-track-weight", differs(&self.off_track_weight, &saved.off_track_weight)),
                ("--observe-track", differs(&self.observe_track, &saved.observe_track)),
            ],
        )?;
        Ok(ControlConfig { total_steps: self.steps.unwrap_or(saved.total_steps), ..saved.clone() })
    }
}

fn train(args: TrainArgs) -> Result<()> {
    let out = args.run.out.clone();
    let session = if args.run.resume {
        let mut session = ControllerSession::resume(&out).map_err(super::train::train_error)?;
        let config = args.resumed(session.settings())?;
        session.set_total_steps(config.total_steps).map_err(super::train::train_error)?;
        session
    } else {
        ControllerSession::create(&out, args.settings()?, args.run.existing())
            .map_err(super::train::train_error)?
    };
    crate::interrupt::install();
    let mut bars = super::train::Bars::default();
    let trained = session.train(args.save_every, &mut bars);
    bars.clear();
    let trained = trained.map_err(super::train::train_error)?;
    let trainer = &trained.trainer;
    if trained.stopped {
        return Err(crate::interrupt::stopped(&out, format!("update {}", trainer.updates)));
    }
    println!(
        "trained the {} for {} environment steps in {:.1} s ({:.0} steps/s); run in {}",
        trainer.config.robot,
        trainer.steps,
        trained.seconds,
        trained.steps as f64 / trained.seconds.max(1e-9),
        out.display()
    );
    if args.eval_episodes > 0 {
        let map = parse_map(&trainer.config.map)?;
        let r = evaluate_controller(
            &trainer.controller(),
            &map,
            args.eval_episodes,
            EVAL_SEED,
            trainer.config.episode_steps,
            GoalDraw::Anywhere,
        )?;
        print_eval(&r);
    }
    Ok(())
}

fn print_eval(r: &ControllerEval) {
    println!("success rate: {}", r.success_rate);
    match r.mean_steps_to_reach {
        Some(s) => println!("mean steps to reach: {s:.1}"),
        None => println!("mean steps to reach: -"),
    }
    println!(
        "failures: {} collisions, {} falls, {} time-outs (of {} episodes)",
        r.collisions, r.falls, r.timeouts, r.episodes
    );
}

fn eval(args: EvalArgs) -> Result<()> {
    if args.episodes == 0 {
        bail!("--episodes must be at least 1");
    }
    let trainer = store::controller::load(&args.ckpt).map_err(super::store_error)?;
    let controller = trainer.controller();
    let trained_map = trainer.config.map;
    let map = parse_map(args.map.as_deref().unwrap_or(&trained_map))?;
    let draw = match args.goals_within {
        None => GoalDraw::Anywhere,
        Some(r) if r.is_finite() && r > 0.0 => GoalDraw::Within(r),
        Some(r) => bail!("--goals-within must be a positive number of metres, got {r}"),
    };
    let runs = goal_episodes(&controller, &map, args.episodes, args.seed, args.max_steps, draw)?;
    let r = ControllerEval::of(&runs);
    if let Some(out) = &args.out {
        draw_episodes(&runs, &map, out, args.force)?;
        println!("wrote {}", out.display());
    }
    print_eval(&r);
    Ok(())
}

/// Draws six evaluation episodes: goal, executed trajectory, and the robot at the end.
fn draw_episodes(runs: &[GoalEpisode], map: &Map, out: &Path, force: bool) -> Result<()> {
    let mut scene = Scene::new(map.clone());
    for r in runs.iter().take(6) {
        scene.goals.push(Goal { center: r.goal.clone(), radius: r.reach_radius, avoid: false });
        let end = r.episode.trajectory.last().cloned().unwrap_or_default();
        scene.robots.push(RobotMarker { position: end, heading: r.heading, radius: r.radius });
        scene.paths.push(Polyline { points: r.episode.trajectory.clone(), kind: PathKind::Executed });
    }
    sim::render::save(&scene, out, force)?;
    Ok(())
}
