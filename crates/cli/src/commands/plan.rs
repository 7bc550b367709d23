//! `schrl plan`: train the GRU-ODE planner on a task, sample from it, and time
//! its plans against the gradient planner.

use std::path::PathBuf;

use anyhow::{Result, bail};
use indicatif::{ProgressBar, ProgressStyle};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use schrl::plan::cpg::{CpgConfig, Method, PlanTrainer};
use schrl::plan::deployed::{DeployedPlanner, PlanScratch};
use schrl::plan::gradient_planner::{self, GradientPlannerConfig, WaypointDraw};
use schrl::plan::mip::{self, MipConfig, MipSolver};
use schrl::plan::planner::PlannerKind;
use schrl::run::evaluate::mean_std;
use schrl::store::planner::PlanRunSettings;
use schrl::store::{self, MetricsLog, RunKind, RunWriter};
use schrl::task::{SafeAlong, Task, TaskKind};
use sim::render::{PathKind, Polyline, Scene};
use stl::Semantics;

use crate::progress::LoggedBar;

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
    /// The waypoints a jointly trained planner places beside the gradient planner's,
    /// from the same starts, in one picture (the paper's Fig. 5).
    Compare(CompareArgs),
    /// Plan once with the mixed-integer planner: the spec as a MILP over the
    /// waypoints, maximising robustness (App. J's MIP column).
    Mip(MipArgs),
}

/// The MIP planner's settings as flags (`schrl plan mip`, `plan time`, `eval --planner mip`).
#[derive(clap::Args, Debug, Clone)]
pub struct MipFlags {
    /// Seconds the solver may take per plan; the best plan found by then is used.
    #[arg(long, default_value_t = MipConfig::default().time_limit)]
    time_limit: f64,
    /// Solver: microlp (pure Rust), or highs (a build with `--features highs`).
    #[arg(long, default_value = "microlp")]
    solver: MipSolver,
    /// Sides of the polygon inscribed in each goal disc.
    #[arg(long, default_value_t = MipConfig::default().sides)]
    sides: usize,
    /// Tangent directions (one binary each) for keeping outside a disc.
    #[arg(long, default_value_t = MipConfig::default().outside_sides)]
    outside_sides: usize,
    /// Maximise robustness only up to this many metres, then shorten the plan (faster;
    /// default: the most robust plan).
    #[arg(long)]
    robustness_cap: Option<f64>,
    /// Shorten over every discrete choice (which goals, which doors), not only those of
    /// the most robust plan: the shortest plan as robust (slower: a second
    /// mixed-integer program; on a time-out the unshortened plan is used).
    #[arg(long)]
    shortest: bool,
    /// Largest step between waypoints per coordinate, metres.
    #[arg(long, default_value_t = MipConfig::default().max_step)]
    max_step: f64,
    /// Ask first for a satisfying plan (robustness at least the cap, or 1 mm), with
    /// cuts valid for such plans, then the whole program if there is none [default:
    /// true with highs, false with microlp].
    #[arg(long)]
    satisfying_first: Option<bool>,
}

impl MipFlags {
    /// The planner's settings, checked; errors name the flag.
    pub fn config(&self) -> Result<MipConfig> {
        let c = MipConfig {
            sides: self.sides,
            outside_sides: self.outside_sides,
            max_step: self.max_step,
            time_limit: self.time_limit,
            robustness_cap: self.robustness_cap,
            shortest: self.shortest,
            solver: self.solver,
            satisfying_first: self.satisfying_first,
        };
        c.validate().map_err(|e| anyhow::anyhow!("{}", mip_flag(&e)))?;
        Ok(c)
    }
}

/// Flags of the gradient planner (`plan time`, `plan compare`, `eval --planner gradient`).
/// Leung et al.'s plain ascent: `--gradient-repair-every 0 --gradient-outside-region
/// --gradient-iterations 200 --gradient-restarts 50`.
#[derive(clap::Args, Debug)]
pub struct GradientFlags {
    /// Adam steps per attempt of the gradient planner.
    #[arg(long, default_value_t = GradientPlannerConfig::default().iterations, value_parser = super::count::<1, 10_000_000>)]
    gradient_iterations: usize,
    /// Attempts (random initialisations) of the gradient planner.
    #[arg(long, default_value_t = GradientPlannerConfig::default().restarts, value_parser = super::count::<1, 100_000>)]
    gradient_restarts: usize,
    /// Steps between redraws of a waypoint the robustness binds on (0: no repair).
    #[arg(long, default_value_t = GradientPlannerConfig::default().repair_every)]
    gradient_repair_every: usize,
    /// Let the gradient planner's waypoints leave the map's region.
    #[arg(long)]
    gradient_outside_region: bool,
    /// Robustness at which the gradient planner stops improving a satisfying plan (0:
    /// the first satisfying plan, as Leung et al.; e.g. 0.05, the planning network's ε).
    #[arg(long, default_value_t = GradientPlannerConfig::default().target)]
    gradient_target: f64,
    /// Where the gradient planner draws initial and redrawn waypoints: region
    /// (uniformly) or goal-centres (a random goal's centre).
    #[arg(long, default_value = "region")]
    gradient_draw: WaypointDraw,
}

impl GradientFlags {
    /// The gradient planner's settings, checked; errors name the flag.
    pub fn config(&self) -> Result<GradientPlannerConfig> {
        let c = GradientPlannerConfig {
            iterations: self.gradient_iterations,
            restarts: self.gradient_restarts,
            repair_every: self.gradient_repair_every,
            in_region: !self.gradient_outside_region,
            target: self.gradient_target,
            draw: self.gradient_draw,
            ..GradientPlannerConfig::default()
        };
        c.validate().map_err(|e| anyhow::anyhow!("--gradient-{e}"))?;
        Ok(c)
    }
}

/// A [`MipConfig::validate`] message with its key as the flag (`mip.max_step` → `--max-step`).
fn mip_flag(message: &str) -> String {
    match message.strip_prefix("mip.").and_then(|m| m.split_once(' ')) {
        Some((key, rest)) => format!("--{} {rest}", key.trim_end_matches(':').replace('_', "-")),
        None => message.to_string(),
    }
}

/// Arguments of `schrl plan mip`.
#[derive(clap::Args, Debug)]
pub struct MipArgs {
    /// Robot of a built-in task (default: point).
    #[arg(long)]
    robot: Option<sim::Robot>,
    /// Task: seq, cover, branch, loop, signal, or a task file (TOML).
    #[arg(long)]
    task: String,
    /// Start position `x,y`; without it, one drawn from the task's start region.
    #[arg(long, value_parser = parse_start, allow_hyphen_values = true)]
    start: Option<StartPoint>,
    /// Seed of the drawn start.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    #[command(flatten)]
    mip: MipFlags,
    /// Plan from this many starts drawn from the task's start region (the starts of
    /// `plan time --n N --seed S`) and report seconds per plan and plans satisfying.
    #[arg(long, default_value_t = 1, value_parser = super::count::<1, 100_000>)]
    n: usize,
    /// Write the plan (JSON: waypoints, robustness, solve time).
    #[arg(long)]
    out: Option<PathBuf>,
    /// Also draw the plan on the map (PNG or SVG).
    #[arg(long)]
    picture: Option<PathBuf>,
    /// Replace --out and --picture if they exist.
    #[arg(long)]
    force: bool,
}

/// A position given on the command line (`x,y`).
#[derive(Clone, Debug)]
struct StartPoint(Vec<f64>);

fn parse_start(s: &str) -> Result<StartPoint, String> {
    let v: Vec<f64> = s
        .split(',')
        .map(|x| x.trim().parse::<f64>().map_err(|_| format!("'{x}' in '{s}' is not a number")))
        .collect::<Result<_, _>>()?;
    if v.iter().any(|x| !x.is_finite()) {
        return Err(format!("'{s}' has a number that is not finite"));
    }
    Ok(StartPoint(v))
}

/// Arguments of `schrl plan compare`.
#[derive(clap::Args, Debug)]
pub struct CompareArgs {
    /// Run directory of `schrl train`.
    #[arg(long)]
    ckpt: PathBuf,
    /// Starts to plan from.
    #[arg(long, default_value_t = 3, value_parser = super::count::<1, 100>)]
    n: usize,
    /// Seed of the starts and the gradient planner's initialisations.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// The picture (PNG or SVG).
    #[arg(long)]
    out: PathBuf,
    /// Replace the picture.
    #[arg(long)]
    force: bool,
    #[command(flatten)]
    gradient: GradientFlags,
}

/// A trained planner and the starts to plan from: shared by `plan sample` and `plan time`.
#[derive(clap::Args, Debug)]
pub struct CheckpointStarts {
    /// Checkpoint directory of a trained planner (`schrl plan train --out`).
    #[arg(long)]
    ckpt: PathBuf,
    /// Starts to plan from (the paper times 100).
    #[arg(long, default_value_t = 100, value_parser = super::count::<1, 100_000>)]
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
    /// Planners to time, comma-separated: network, gradient, mip.
    #[arg(long, value_delimiter = ',', default_value = "network,gradient,mip")]
    planners: Vec<TimedPlanner>,
    #[command(flatten)]
    mip: MipFlags,
    #[command(flatten)]
    gradient: GradientFlags,
}

/// A planner `schrl plan time` can time.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
enum TimedPlanner {
    /// The trained network's deployed mean path.
    Network,
    /// The gradient planner.
    Gradient,
    /// The MIP planner.
    Mip,
}

/// Arguments of `schrl plan train`. With `--resume`, flags left out take the saved
/// run's values; a flag given with another value is refused (`--updates`, `--target`
/// and `--save-every` may change).
#[derive(clap::Args, Debug)]
pub struct TrainArgs {
    /// Robot (planner tasks exist for point).
    #[arg(long, default_value = "point")]
    robot: sim::Robot,
    /// Task: seq, cover, branch, loop or signal. Required for a new run.
    #[arg(long)]
    task: Option<TaskKind>,
    /// Planner network: gru-ode (the paper's), or the ablations gru and mlp (Fig. 6)
    /// [default: gru-ode].
    #[arg(long)]
    planner: Option<PlannerKind>,
    /// Where the task's `safe` is checked: segments (the straight segment into each
    /// waypoint, what a controller drives) or waypoints (the paper's literal `□ safe` on
    /// the plan's states) [default: the task's, segments].
    #[arg(long)]
    safe_along: Option<SafeAlong>,
    /// Restart from a fresh initialisation when an attempt has not had half its
    /// sampled paths satisfy the spec within this many updates; 0: never [default: 150].
    #[arg(long)]
    restart_after: Option<usize>,
    /// cpg (constrained policy gradient) or pg (policy gradient only) [default: cpg].
    #[arg(long, value_parser = parse_method)]
    method: Option<Method>,
    /// Semantics of the spec in the loss: hard, soft:ALPHA or lse:TEMPERATURE, a
    /// smooth one with ,until=flat|recursive [default: soft:10,until=flat].
    #[arg(long)]
    semantics: Option<Semantics>,
    /// Seed of parameters, starts and noise [default: 0].
    #[arg(long)]
    seed: Option<u64>,
    /// Most gradient updates [default: 3000].
    #[arg(long)]
    updates: Option<usize>,
    /// Stop once this fraction of a batch, and of 200 fresh samples, satisfies the spec
    /// [default: 0.95].
    #[arg(long)]
    target: Option<f64>,
    #[command(flatten)]
    run: super::RunDirArgs,
    /// Save a checkpoint every this many updates (and at the end).
    #[arg(long, default_value_t = 100)]
    save_every: usize,
}

impl TrainArgs {
    fn restart_after(&self) -> Option<Option<usize>> {
        self.restart_after.map(|n| (n > 0).then_some(n))
    }

    /// The settings of a new run.
    fn settings(&self) -> Result<PlanRunSettings> {
        let Some(task) = self.task else { bail!("--task is required for a new run") };
        let d = CpgConfig::default();
        let cpg = CpgConfig {
            method: self.method.unwrap_or(d.method),
            semantics: self.semantics.unwrap_or(d.semantics),
            seed: self.seed.unwrap_or(d.seed),
            planner: self.planner.unwrap_or(d.planner),
            restart_after: self.restart_after().unwrap_or(d.restart_after),
            ..d
        };
        let s = PlanRunSettings {
            task,
            safe_along: self.safe_along.unwrap_or(Task::point(task).safe_along),
            cpg,
            updates: self.updates.unwrap_or(3000),
            target: self.target.unwrap_or(0.95),
        };
        check(&s)?;
        Ok(s)
    }

    /// The saved settings with the flags that may change applied.
    fn resumed(&self, saved: &PlanRunSettings) -> Result<PlanRunSettings> {
        use super::differs;
        super::refuse_conflicts(
            RunKind::Planner,
            &[
                ("--task", differs(&self.task, &saved.task)),
                ("--planner", differs(&self.planner, &saved.cpg.planner)),
                ("--safe-along", differs(&self.safe_along, &saved.safe_along)),
                ("--restart-after", differs(&self.restart_after(), &saved.cpg.restart_after)),
                ("--method", differs(&self.method, &saved.cpg.method)),
                ("--semantics", differs(&self.semantics, &saved.cpg.semantics)),
                ("--seed", differs(&self.seed, &saved.cpg.seed)),
            ],
        )?;
        let s = PlanRunSettings {
            updates: self.updates.unwrap_or(saved.updates),
            target: self.target.unwrap_or(saved.target),
            ..saved.clone()
        };
        check(&s)?;
        Ok(s)
    }
}

fn check(s: &PlanRunSettings) -> Result<()> {
    if !(0.0..=1.0).contains(&s.target) {
        bail!("--target must be a fraction in [0, 1], got {}", s.target);
    }
    s.cpg.validate().map_err(|e| anyhow::anyhow!("{}", cpg_flag(&e)))?;
    Ok(())
}

/// A [`CpgConfig::validate`] message with its key as the flag that sets it
/// (`cpg.pg_weight` → `--pg-weight`).
pub fn cpg_flag(message: &str) -> String {
    match message.strip_prefix("cpg.").and_then(|m| m.split_once(' ')) {
        Some((key, rest)) => format!("--{} {rest}", key.trim_end_matches(':').replace('_', "-")),
        None => message.to_string(),
    }
}

/// One line of a planner run's `metrics.jsonl`.
#[derive(serde::Serialize, serde::Deserialize)]
struct PlanMetrics {
    update: usize,
    satisfaction: f64,
    mean_rho: f64,
    lambda: f64,
    loss: f64,
    /// Seconds since this process started training.
    seconds: f64,
    restarts: usize,
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

pub(crate) fn parse_method(s: &str) -> Result<Method, String> {
    s.parse()
}

/// Runs `schrl plan ...`.
pub fn run(cmd: Command) -> Result<()> {
    match cmd {
        Command::Train(args) => train(args),
        Command::Sample(args) => sample(args),
        Command::Time(args) => time(args),
        Command::Compare(args) => compare(args),
        Command::Mip(args) => mip(args),
    }
}

/// Fresh sampled paths that must also meet the target before `plan train` stops. With
/// 200, Seq seed 1 stopped at 95 % and `plan sample --n 100` then gave 0.91; at 1000 the
/// estimate's standard error is under 0.7 points at a 95 % rate.
const CONFIRM_SAMPLES: usize = 1000;

fn train(args: TrainArgs) -> Result<()> {
    if args.robot != sim::Robot::Point {
        bail!("planner tasks exist for the point robot only so far, not the {}", args.robot);
    }
    let out = args.run.out.clone();
    let (mut run, settings, resumed) = if args.run.resume {
        let (mut run, ckpt) = RunWriter::resume(&out, RunKind::Planner).map_err(super::store_error)?;
        let settings = args.resumed(&run.settings().map_err(super::store_error)?)?;
        run.set_settings(&settings).map_err(super::store_error)?;
        let resumed =
            if ckpt.has_files() { Some(store::planner::load_trainer(&ckpt, &settings)?) } else { None };
        (run, settings, resumed)
    } else {
        let settings = args.settings()?;
        let run = RunWriter::create(&out, RunKind::Planner, &settings, args.run.existing())
            .map_err(super::store_error)?;
        (run, settings, None)
    };
    let was_resumed = args.run.resume;
    let (mut trainer, mut done, mut reached) = match resumed {
        Some(r) => r,
        None => (PlanTrainer::new(settings.task(), settings.cpg)?, 0, false),
    };
    crate::interrupt::install();
    let (mut log, _) = MetricsLog::open(&run, was_resumed, |m: &PlanMetrics| m.update <= done)
        .map_err(super::store_error)?;
    let mut bar = LoggedBar::new(settings.updates as u64, "planner", "updates");
    bar.start_at(done as u64);
    let start = std::time::Instant::now();
    let mut interrupted = false;
    while !reached && done < settings.updates {
        let s = trainer.update()?;
        done += 1;
        log.append(&PlanMetrics {
            update: done,
            satisfaction: s.satisfaction,
            mean_rho: s.mean_rho,
            lambda: s.lambda,
            loss: s.loss,
            seconds: start.elapsed().as_secs_f64(),
            restarts: trainer.restarts(),
        })?;
        bar.set(done as u64, format!("satisfaction {:.2} λ {:.2}", s.satisfaction, s.lambda));
        // Confirm on fresh paths before stopping, so one lucky batch does not end training.
        reached =
            s.satisfaction >= settings.target && trainer.satisfaction(CONFIRM_SAMPLES)? >= settings.target;
        if done % args.save_every.max(1) == 0 {
            run.save(|f| store::planner::save_into(f, &trainer, done, reached))?;
        }
        if crate::interrupt::requested() {
            interrupted = true;
            break;
        }
    }
    bar.clear();
    run.save(|f| store::planner::save_into(f, &trainer, done, reached))?;
    if interrupted {
        return Err(crate::interrupt::stopped(&out, format!("update {done}")));
    }
    let satisfaction = trainer.satisfaction(200)?;
    println!(
        "{} after {done} updates ({:.1} s); checkpoint in {}",
        if reached { "reached the target" } else { "stopped at the update limit" },
        start.elapsed().as_secs_f64(),
        out.display()
    );
    println!("updates: {done}");
    if reached {
        println!("updates to target: {done}");
    }
    println!("restarts: {}", trainer.restarts());
    // Sampled paths are what training sees; mean paths are what `schrl train` deploys.
    println!("mean-path satisfaction: {}", trainer.mean_satisfaction(200)?);
    println!("satisfaction: {satisfaction}");
    Ok(())
}

fn sample(args: SampleArgs) -> Result<()> {
    let loaded = store::planner::load(&args.from.ckpt).map_err(super::store_error)?;
    let task = &loaded.task;
    let mut rng = ChaCha8Rng::seed_from_u64(args.from.seed);
    let g0 = task.sample_starts(&mut rng, args.from.n)?;
    let noise = task.sample_noise(&mut rng, args.from.n)?;
    let paths = if args.mean {
        loaded.planner.mean_path(&g0, task.steps)?
    } else {
        loaded.planner.sample(&g0, &noise)?.paths
    };
    let rho = schrl::task::hard_robustness(&task.spec(), &paths)?;
    let satisfied = rho.iter().filter(|r| **r > 0.0).count();
    if let Some(out) = &args.out {
        let mut scene = Scene::new(task.map.clone());
        scene.goals = task.picture_goals();
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
    let mip_cfg = args.mip.config()?;
    let loaded = store::planner::load(&args.from.ckpt).map_err(super::store_error)?;
    let task = &loaded.task;
    let spec = task.spec();
    let deployed = DeployedPlanner::from_varmap(&loaded.varmap, loaded.planner.config())?;
    let mut rng = ChaCha8Rng::seed_from_u64(args.from.seed);
    let starts: Vec<Vec<f64>> =
        task.sample_starts(&mut rng, args.from.n)?.to_dtype(candle_core::DType::F64)?.to_vec2()?;
    let hard = Semantics::hard();
    let n = args.from.n;
    println!("task: {} (T = {}), {n} starts", task.name, task.steps);
    let report = |name: &str, key: &str, seconds: &[f64], ok: usize, note: &str| {
        print_timing(name, key, seconds, ok, n, note);
    };

    if args.planners.contains(&TimedPlanner::Network) {
        // Each plan timed alone (mean of n, as Table 5), after one warm-up.
        let (mut scratch, mut path) = (PlanScratch::default(), Vec::new());
        deployed.mean_path_into(&starts[0], task.steps, &mut scratch, &mut path);
        let (mut secs, mut ok) = (Vec::with_capacity(n), 0);
        for s in &starts {
            let t0 = std::time::Instant::now();
            deployed.mean_path_into(s, task.steps, &mut scratch, &mut path);
            secs.push(t0.elapsed().as_secs_f64());
            ok += (spec.robustness(&path, &hard)? > 0.0) as usize;
        }
        report("network (deployed mean path)", "network", &secs, ok, "");
    }
    if args.planners.contains(&TimedPlanner::Gradient) {
        let bar = timing_bar(n, "gradient planner");
        let cfg = args.gradient.config()?;
        let (mut secs, mut ok) = (Vec::with_capacity(n), 0);
        for s in &starts {
            let t0 = std::time::Instant::now();
            let p = gradient_planner::plan(task, &spec, s, &cfg, &mut rng)?;
            secs.push(t0.elapsed().as_secs_f64());
            ok += p.satisfied() as usize;
            bar.inc(1);
        }
        bar.finish_and_clear();
        let note = format!(
            " (at most {} attempts of {} steps, target ρ ≥ {})",
            cfg.restarts, cfg.iterations, cfg.target
        );
        report("gradient planner", "gradient", &secs, ok, &note);
    }
    if args.planners.contains(&TimedPlanner::Mip) {
        let t = MipTimes::of(task, &starts, &mip_cfg)?;
        report("MIP planner", "mip", &t.seconds, t.satisfied, &t.note(&mip_cfg));
    }
    Ok(())
}

/// The MIP planner timed from each of some starts.
struct MipTimes {
    seconds: Vec<f64>,
    satisfied: usize,
    proved: usize,
    rounds: usize,
}

impl MipTimes {
    fn of(task: &Task, starts: &[Vec<f64>], cfg: &MipConfig) -> Result<MipTimes> {
        let bar = timing_bar(starts.len(), "MIP planner");
        let mut t = MipTimes { seconds: vec![], satisfied: 0, proved: 0, rounds: 0 };
        for s in starts {
            match mip::plan(task, s, cfg) {
                Ok(p) => {
                    t.seconds.push(p.seconds);
                    t.satisfied += p.satisfied() as usize;
                    t.proved += p.optimal as usize;
                    t.rounds += p.rounds;
                }
                // No plan in time: unsatisfied, at the limit.
                Err(mip::MipError::TimeOut(limit)) => t.seconds.push(limit),
                Err(e) => return Err(e.into()),
            }
            bar.inc(1);
        }
        bar.finish_and_clear();
        Ok(t)
    }

    fn note(&self, cfg: &MipConfig) -> String {
        let n = self.seconds.len();
        let first = cfg.satisfying_first.unwrap_or(cfg.solver.satisfying_first());
        format!(
            " ({}{}; {}/{n} proved optimal, {:.1} rounds per plan)",
            cfg.solver.name(),
            if first { ", satisfying first" } else { "" },
            self.proved,
            self.rounds as f64 / n.max(1) as f64
        )
    }
}

fn timing_bar(n: usize, what: &str) -> ProgressBar {
    let bar = ProgressBar::new(n as u64);
    bar.set_style(
        ProgressStyle::with_template(&format!("{what} {{bar:40}} {{pos}}/{{len}}")).expect("valid template"),
    );
    bar
}

fn compare(args: CompareArgs) -> Result<()> {
    if args.n == 0 {
        bail!("--n must be at least 1");
    }
    let (run, _) = store::joint::load_deployed(&args.ckpt).map_err(super::store_error)?;
    // Both planners plan for the spec the network trained on (goal and safe margins).
    let task = run.plan.task();
    let spec = task.spec();
    let mut rng = ChaCha8Rng::seed_from_u64(args.seed);
    let g0 = task.sample_starts(&mut rng, args.n)?;
    let network: Vec<Vec<Vec<f32>>> = run.plan.planner().mean_path(&g0, task.steps)?.to_vec3()?;
    let starts: Vec<Vec<f64>> = g0.to_dtype(candle_core::DType::F64)?.to_vec2()?;
    let mut scene = Scene::new(run.task.map.clone());
    scene.goals = run.task.picture_goals();
    scene.labels.planned = "SCHRL planner (jointly trained)".into();
    scene.labels.compared = "gradient planner".into();
    let dim = task.map.dim();
    let length = |p: &[Vec<f64>]| p.windows(2).map(|w| dist(&w[0], &w[1])).sum::<f64>();
    let hard = Semantics::hard();
    let gradient = args.gradient.config()?;
    for (i, (s, net)) in starts.iter().zip(&network).enumerate() {
        let net: Vec<Vec<f64>> = net.iter().map(|w| w.iter().map(|&x| x as f64).collect()).collect();
        let grad = gradient_planner::plan(task, &spec, s, &gradient, &mut rng)?;
        let grad: Vec<Vec<f64>> = grad.path.chunks(dim).map(|c| c.to_vec()).collect();
        let rho = |p: &[Vec<f64>]| spec.robustness(&p.concat(), &hard);
        println!(
            "start {i}: network {:.2} m, robustness {:.3}; gradient planner {:.2} m, robustness {:.3}",
            length(&net),
            rho(&net)?,
            length(&grad),
            rho(&grad)?
        );
        scene.paths.push(Polyline { points: net, kind: PathKind::Planned });
        scene.paths.push(Polyline { points: grad, kind: PathKind::Compared });
    }
    sim::render::save(&scene, &args.out, args.force)?;
    println!("wrote {}", args.out.display());
    Ok(())
}

fn dist(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum::<f64>().sqrt()
}

/// The start of a plan: the one given, checked against the task's map, or one drawn
/// from the task's start region.
fn start_for(task: &Task, given: Option<&[f64]>, seed: u64) -> Result<Vec<f64>> {
    let Some(s) = given else {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        return Ok(task.sample_starts(&mut rng, 1)?.to_dtype(candle_core::DType::F64)?.to_vec2()?.remove(0));
    };
    let dim = task.map.dim();
    if s.len() != dim {
        bail!("--start: the {} plans in {dim}-D, so give {dim} numbers (x,y), not {}", task.robot, s.len());
    }
    let (lo, hi) = task.map.region();
    if s.iter().zip(lo.iter().zip(&hi)).any(|(x, (l, h))| x < l || x > h) {
        bail!("--start: {s:?} lies outside the {} map's region ({lo:?} to {hi:?})", task.map.name());
    }
    if task.map.sdf(s) <= 0.0 {
        bail!("--start: {s:?} lies inside an obstacle of the {} map", task.map.name());
    }
    Ok(s.to_vec())
}

fn mip(args: MipArgs) -> Result<()> {
    let task = super::task::resolve(args.robot, &args.task)?;
    let cfg = args.mip.config()?;
    if args.n > 1 {
        return mip_many(&task, &cfg, &args);
    }
    let start = start_for(&task, args.start.as_ref().map(|s| &s.0[..]), args.seed)?;
    // Outputs are checked before the solve, which can take a while.
    if let Some(out) = &args.out
        && out.exists()
        && !args.force
    {
        return Err(super::store_error(schrl::store::StoreError::FileExists(out.clone())));
    }
    if let Some(p) = &args.picture {
        sim::render::check_target(p, args.force)?;
    }
    let spinner = ProgressBar::new_spinner();
    spinner.set_message(format!("solving {} from {start:.2?} with {}", task.name, cfg.solver.name()));
    spinner.enable_steady_tick(std::time::Duration::from_millis(200));
    let plan = mip::plan(&task, &start, &cfg);
    spinner.finish_and_clear();
    let plan = plan?;
    println!(
        "program: {} binaries, {} constraints, {} round{}; {}",
        plan.binaries,
        plan.constraints,
        plan.rounds,
        if plan.rounds == 1 { "" } else { "s" },
        if plan.optimal { "solved to optimality" } else { "time limit reached: best plan found so far" }
    );
    println!("solve seconds: {:.3}", plan.seconds);
    println!("program robustness: {:.4}", plan.program_robustness);
    println!("robustness: {:.4}", plan.robustness);
    if !plan.satisfied() {
        let why = if plan.optimal {
            format!(
                "infeasible: the most robust plan of {} waypoints from {start:.2?} has robustness {:.4} \
                 (program: {:.4}), so no plan satisfies the spec (up to the polygon approximation)",
                task.steps, plan.robustness, plan.program_robustness
            )
        } else {
            format!(
                "time-out: after {} s the best plan has robustness {:.4}; raise --time-limit",
                cfg.time_limit, plan.robustness
            )
        };
        bail!(why);
    }
    let dim = task.map.dim();
    let waypoints: Vec<Vec<f64>> = plan.path.chunks(dim).map(|c| c.to_vec()).collect();
    if let Some(p) = &args.picture {
        let mut scene = Scene::new(task.map.clone());
        scene.goals = task.picture_goals();
        scene.labels.planned = "MIP plan".into();
        scene.paths.push(Polyline { points: waypoints.clone(), kind: PathKind::Planned });
        sim::render::save(&scene, p, args.force)?;
        println!("wrote {}", p.display());
    }
    if let Some(out) = &args.out {
        let file = schrl::store::plan_file::PlanFile {
            planner: "mip".into(),
            task: task.name.clone(),
            robot: task.robot.name().into(),
            waypoints,
            robustness: plan.robustness,
            program_robustness: plan.program_robustness,
            optimal: plan.optimal,
            seconds: plan.seconds,
            solver: cfg.solver.name().into(),
        };
        schrl::store::plan_file::save(&file, out, args.force).map_err(super::store_error)?;
        println!("wrote {}", out.display());
    }
    Ok(())
}

/// `plan mip --n N`: one plan from each of N starts, timed (Table 5's MIP column).
fn mip_many(task: &Task, cfg: &MipConfig, args: &MipArgs) -> Result<()> {
    if args.start.is_some() || args.out.is_some() || args.picture.is_some() {
        bail!("--n {} plans from drawn starts and reports times; drop --start, --out and --picture", args.n);
    }
    let mut rng = ChaCha8Rng::seed_from_u64(args.seed);
    let starts: Vec<Vec<f64>> =
        task.sample_starts(&mut rng, args.n)?.to_dtype(candle_core::DType::F64)?.to_vec2()?;
    let t = MipTimes::of(task, &starts, cfg)?;
    println!("task: {} (T = {}), {} starts (seed {})", task.name, task.steps, args.n, args.seed);
    print_timing("MIP planner", "mip", &t.seconds, t.satisfied, args.n, &t.note(cfg));
    Ok(())
}

/// A planner's times from `n` starts: a line to read, and lines for scripts and
/// experiment records (`<key> seconds per plan: <mean> ± <std>`, `<key> plans
/// satisfying: <count>`).
fn print_timing(name: &str, key: &str, seconds: &[f64], ok: usize, n: usize, note: &str) {
    let (m, s) = mean_std(seconds);
    println!("{name}: {m:.3e} ± {s:.1e} s per plan, {ok}/{n} satisfy{note}");
    println!("{key} seconds per plan: {m:.3e} ± {s:.3e}");
    println!("{key} plans satisfying: {ok}");
}
