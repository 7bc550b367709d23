//! `schrl train` and `schrl eval`: joint hierarchical training of a task, and its
//! evaluation on what the robot actually does.

use std::path::{Path, PathBuf};

use anyhow::{Result, bail};
use indicatif::{ProgressBar, ProgressStyle};
use schrl::control::{ControlConfig, ControlTrainer};
use schrl::plan::cpg::{CpgConfig, Method};
use schrl::plan::gradient_planner::GradientPlannerConfig;
use schrl::plan::planner::PlannerKind;
use schrl::plan::pretrain::{PretrainConfig, pretrain};
use schrl::run::RunError;
use schrl::run::evaluate::{
    EVAL_GROUPS, EVAL_PER_GROUP, EVAL_SEED, Plans, RunRecord, TaskEval, evaluate_task, evaluate_task_with,
    mean_std,
};
use schrl::run::joint::{JointConfig, JointMetrics, JointRunSettings, JointTrainer};
use schrl::store::{self, Existing, JsonLines, MetricsLog, RunKind, RunWriter};
use schrl::task::Task;
use sim::Robot;
use sim::render::{ChartPanel, PathKind, Polyline, RobotMarker, Scene, Series};
use stl::Semantics;

/// Arguments of `schrl train`. Flags left out take the default shown; with
/// `--resume` they take the saved run's value, and a flag given with another value is
/// refused (`--steps`, `--target`, `--eval-groups` and `--save-every` may change).
#[derive(clap::Args, Debug, Default)]
pub struct TrainArgs {
    /// Robot of a built-in task: point, car, drone, or doggo (needs the `mujoco`
    /// feature) [default: point; a task file names its own].
    #[arg(long)]
    robot: Option<Robot>,
    /// Task: seq, cover, branch, loop, signal, or a task file (TOML). Required for a new run.
    #[arg(long)]
    task: Option<String>,
    /// Seed of everything [default: 0].
    #[arg(long)]
    seed: Option<u64>,
    /// Environment steps of joint training [default: 3000000].
    #[arg(long)]
    steps: Option<usize>,
    /// Stop early once this fraction of the last 20 iterations' runs satisfy the task
    /// [default: 0.97].
    #[arg(long)]
    target: Option<f64>,
    /// Warm-start the controller from this `schrl control train` run (default: train a
    /// general controller first, into DIR/general).
    #[arg(long)]
    controller: Option<PathBuf>,
    /// Semantics of the spec in the planner's loss: hard, soft:<alpha> or
    /// lse:<temperature>, a smooth one with ,until=flat|recursive
    /// [default: soft:10,until=flat].
    #[arg(long)]
    semantics: Option<Semantics>,
    /// Planner network: gru-ode (the paper's), or the ablations gru and mlp [default: gru-ode].
    #[arg(long)]
    planner: Option<PlannerKind>,
    /// Paths planned and executed per iteration [default: 8].
    #[arg(long, value_parser = super::count::<1, 4096>)]
    plan_batch: Option<usize>,
    /// The planner's objective: cpg (the paper's: the Lagrangian keeps ρ ≥ ε) or pg
    /// (no Lagrange term: HTLTL, as `schrl baseline train --algo htltl`) [default: cpg].
    #[arg(long, value_parser = super::plan::parse_method)]
    method: Option<Method>,
    /// Weight of the planner's policy-gradient term [default: 0.1].
    #[arg(long)]
    pg_weight: Option<f64>,
    /// Dual step size of λ [default: 0.05].
    #[arg(long)]
    lambda_lr: Option<f64>,
    /// Planner-only updates per pre-training candidate (batch 64, no execution); 0: none
    /// [default: 3000].
    #[arg(long)]
    pretrain_updates: Option<usize>,
    /// Planners pre-trained from different seeds; the shortest satisfying one is kept
    /// [default: 3].
    #[arg(long, value_parser = super::count::<1, 100>)]
    pretrain_candidates: Option<usize>,
    /// Weight of the path-length stand-in for r_l while pre-training (per metre)
    /// [default: 0.05].
    #[arg(long)]
    pretrain_length_weight: Option<f64>,
    /// Keep the pre-trained planner fixed in the joint phase (ablation; by default it
    /// learns from the executed runs, Algorithm 1).
    #[arg(long)]
    freeze_planner: bool,
    /// Runs from each start per iteration; each run's baseline is the others from its
    /// start [default: 4].
    #[arg(long)]
    runs_per_start: Option<usize>,
    /// Weight of the measured low-level reward r_l in the planner's update, relative to
    /// the spec's unit-scale advantages [default: 0.3].
    #[arg(long)]
    control_weight: Option<f64>,
    /// Weight per metre of the path-length term the planner follows in the joint phase
    /// [default: 0.05].
    #[arg(long)]
    length_weight: Option<f64>,
    /// Keep the controller fixed (ablation).
    #[arg(long)]
    freeze_controller: bool,
    /// Metres by which the planner's goal discs are shrunk (at most a third of a radius)
    /// [default: the robot's reach radius].
    #[arg(long)]
    goal_margin: Option<f64>,
    /// Metres of clearance the planner keeps from obstacles (beyond the task's own
    /// `safe_radius`) and from regions to avoid [default: 0.1].
    #[arg(long)]
    safe_margin: Option<f64>,
    #[command(flatten)]
    run: super::RunDirArgs,
    /// Evaluation groups of 100 runs after training; 0: none [default: 5].
    #[arg(long, value_parser = super::count::<0, 100>)]
    eval_groups: Option<usize>,
    /// Iterations between checkpoints [default: 50].
    #[arg(long)]
    save_every: Option<usize>,
}

impl TrainArgs {
    /// `schrl train`'s arguments for an HTLTL run (`schrl baseline train --algo
    /// htltl`): SCHRL's defaults with the planner on the plain policy gradient.
    pub(crate) fn htltl(base: super::baseline::CommonArgs) -> Self {
        let super::baseline::CommonArgs { robot, task, seed, steps, run, eval_groups, save_every } = base;
        Self {
            robot,
            task,
            seed,
            steps,
            run,
            eval_groups,
            save_every,
            method: Some(Method::Pg),
            ..Self::default()
        }
    }

    /// The settings of a new run: the flags given, defaults for the rest.
    fn settings(&self) -> Result<JointRunSettings> {
        let Some(task_arg) = &self.task else { bail!("--task is required for a new run") };
        let task = super::task::resolve(self.robot, task_arg)?;
        let robot = task.robot;
        let goal_margin = match self.goal_margin {
            Some(m) => m,
            None => sim::make_env(robot, task.map.clone())?.reach_radius(),
        };
        let defaults = JointConfig::default();
        let joint = JointConfig {
            plan_batch: self.plan_batch.unwrap_or(defaults.plan_batch),
            goal_margin,
            safe_margin: self.safe_margin.unwrap_or(DEFAULT_SAFE_MARGIN),
            runs_per_start: self.runs_per_start.unwrap_or(defaults.runs_per_start),
            control_weight: self.control_weight.unwrap_or(defaults.control_weight),
            length_weight: self.length_weight.unwrap_or(defaults.length_weight),
            freeze_planner: self.freeze_planner,
            freeze_controller: self.freeze_controller,
        };
        let cpg_defaults = CpgConfig::default();
        let seed = self.seed.unwrap_or(0);
        let cpg = CpgConfig {
            seed,
            semantics: self.semantics.unwrap_or(cpg_defaults.semantics),
            method: self.method.unwrap_or(cpg_defaults.method),
            pg_weight: self.pg_weight.unwrap_or(cpg_defaults.pg_weight),
            lambda_lr: self.lambda_lr.unwrap_or(cpg_defaults.lambda_lr),
            planner: self.planner.unwrap_or(cpg_defaults.planner),
            ..cpg_defaults
        };
        let pre = PretrainConfig::default();
        let pretrain = PretrainConfig {
            updates: self.pretrain_updates.unwrap_or(pre.updates),
            candidates: self.pretrain_candidates.unwrap_or(pre.candidates),
            length_weight: self.pretrain_length_weight.unwrap_or(pre.length_weight),
        };
        let s = JointRunSettings {
            robot,
            task_toml: task.toml.clone(),
            task_spec: task.spec.clone(),
            seed,
            steps: self.steps.unwrap_or(DEFAULT_STEPS),
            target: self.target.unwrap_or(DEFAULT_TARGET),
            controller: self.controller.clone(),
            joint,
            cpg,
            pretrain,
            eval_groups: self.eval_groups.unwrap_or(EVAL_GROUPS),
            save_every: self.save_every.unwrap_or(DEFAULT_SAVE_EVERY),
        };
        check_settings(&s)?;
        Ok(s)
    }

    /// The saved settings of a resumed run, with the flags that may change applied;
    /// any other flag given with a different value is refused by name.
    fn resumed(&self, saved: &JointRunSettings) -> Result<JointRunSettings> {
        use super::differs;
        let task_differs = super::task::differs_from_saved(
            self.robot,
            self.task.as_deref(),
            saved.robot,
            (&saved.task_toml, &saved.task_spec),
        )?;
        super::refuse_conflicts(
            RunKind::Joint,
            &[
                ("--robot", differs(&self.robot, &saved.robot)),
                ("--task", task_differs),
                ("--seed", differs(&self.seed, &saved.seed)),
                ("--controller", self.controller.is_some() && self.controller != saved.controller),
                ("--semantics", differs(&self.semantics, &saved.cpg.semantics)),
                ("--planner", differs(&self.planner, &saved.cpg.planner)),
                ("--plan-batch", differs(&self.plan_batch, &saved.joint.plan_batch)),
                ("--method", differs(&self.method, &saved.cpg.method)),
                ("--pg-weight", differs(&self.pg_weight, &saved.cpg.pg_weight)),
                ("--lambda-lr", differs(&self.lambda_lr, &saved.cpg.lambda_lr)),
                ("--pretrain-updates", differs(&self.pretrain_updates, &saved.pretrain.updates)),
                ("--pretrain-candidates", differs(&self.pretrain_candidates, &saved.pretrain.candidates)),
                (
                    "--pretrain-length-weight",
                    differs(&self.pretrain_length_weight, &saved.pretrain.length_weight),
                ),
                ("--freeze-planner", self.freeze_planner && !saved.joint.freeze_planner),
                ("--runs-per-start", differs(&self.runs_per_start, &saved.joint.runs_per_start)),
                ("--control-weight", differs(&self.control_weight, &saved.joint.control_weight)),
                ("--length-weight", differs(&self.length_weight, &saved.joint.length_weight)),
                ("--freeze-controller", self.freeze_controller && !saved.joint.freeze_controller),
                ("--goal-margin", differs(&self.goal_margin, &saved.joint.goal_margin)),
                ("--safe-margin", differs(&self.safe_margin, &saved.joint.safe_margin)),
            ],
        )?;
        let s = JointRunSettings {
            steps: self.steps.unwrap_or(saved.steps),
            target: self.target.unwrap_or(saved.target),
            eval_groups: self.eval_groups.unwrap_or(saved.eval_groups),
            save_every: self.save_every.unwrap_or(saved.save_every),
            ..saved.clone()
        };
        check_settings(&s)?;
        Ok(s)
    }
}

/// Joint-training steps when `--steps` is not given.
const DEFAULT_STEPS: usize = 3_000_000;
/// Early-stop satisfaction when `--target` is not given.
const DEFAULT_TARGET: f64 = 0.97;
/// Iterations between checkpoints when `--save-every` is not given.
const DEFAULT_SAVE_EVERY: usize = 50;
/// The planner's extra clearance when `--safe-margin` is not given: one Point radius
/// (README, *Joint training (Algorithm 1) and results*).
const DEFAULT_SAFE_MARGIN: f64 = 0.1;

fn check_settings(s: &JointRunSettings) -> Result<()> {
    if !(0.0..=1.0).contains(&s.target) {
        bail!("--target must be a fraction in [0, 1], got {}", s.target);
    }
    if s.save_every == 0 {
        bail!("--save-every must be at least 1");
    }
    if s.joint.plan_batch == 0 {
        bail!("--plan-batch must be at least 1");
    }
    let per_start = s.joint.runs_per_start;
    if per_start == 0 || !s.joint.plan_batch.is_multiple_of(per_start) {
        bail!(
            "--runs-per-start must divide --plan-batch ({}) into whole groups, got {per_start}",
            s.joint.plan_batch
        );
    }
    for (flag, w) in
        [("--control-weight", s.joint.control_weight), ("--length-weight", s.joint.length_weight)]
    {
        if !(w >= 0.0 && w.is_finite()) {
            bail!("{flag} must be a non-negative number, got {w}");
        }
    }
    for (flag, metres) in [("--goal-margin", s.joint.goal_margin), ("--safe-margin", s.joint.safe_margin)] {
        if !(metres >= 0.0 && metres.is_finite()) {
            bail!("{flag} must be a non-negative number of metres, got {metres}");
        }
    }
    s.pretrain
        .validate()
        .map_err(|e| anyhow::anyhow!("--{}", e.replace("pretrain.", "pretrain-").replace('_', "-")))?;
    s.cpg.validate().map_err(|e| anyhow::anyhow!("{}", super::plan::cpg_flag(&e)))?;
    Ok(())
}

/// Arguments of `schrl eval`.
#[derive(clap::Args, Debug)]
pub struct EvalArgs {
    /// Run directory of `schrl train`.
    #[arg(long)]
    ckpt: PathBuf,
    /// Groups of runs.
    #[arg(long, default_value_t = EVAL_GROUPS, value_parser = super::count::<1, 100>)]
    groups: usize,
    /// Runs per group.
    #[arg(long, default_value_t = EVAL_PER_GROUP, value_parser = super::count::<1, 10_000>)]
    per_group: usize,
    /// Seed of starts and plans.
    #[arg(long, default_value_t = EVAL_SEED)]
    seed: u64,
    /// Picture of executed runs with their planned waypoints (PNG or SVG).
    #[arg(long)]
    out: Option<PathBuf>,
    /// Write every run to this file, one JSON object per line: `satisfied`,
    /// `outcome`, `robustness`, `steps`, `steps_to_reach`, `waypoints` (the plan),
    /// `reached`, `reached_at`, `positions` (the robot's position at every step) and
    /// `headings` (its yaw there).
    #[arg(long, value_name = "FILE.jsonl")]
    trajectories: Option<PathBuf>,
    /// Replace the picture and the trajectories file.
    #[arg(long)]
    force: bool,
    /// Execute paths sampled from the planner instead of its mean paths (the
    /// deployed plans).
    #[arg(long)]
    sampled_plans: bool,
    /// Which planner makes the plans: the run's network, or the gradient planner
    /// (waypoints optimised directly on the spec the network planned for, App. J).
    #[arg(long, value_enum, default_value_t = PlannerChoice::Network)]
    planner: PlannerChoice,
    /// The MIP planner's settings (with `--planner mip`).
    #[command(flatten)]
    mip: super::plan::MipFlags,
    /// Drive with this `schrl control train` run's controller instead of the run's
    /// (e.g. DIR/general: the general controller before joint training).
    #[arg(long)]
    controller: Option<PathBuf>,
}

/// The planner `schrl eval` executes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
enum PlannerChoice {
    /// The run's trained planner network.
    Network,
    /// The gradient planner baseline.
    Gradient,
    /// The mixed-integer planner (most robust plan per start).
    Mip,
}

fn bar(len: u64, what: &str) -> Result<ProgressBar> {
    let b = ProgressBar::new(len);
    b.set_style(ProgressStyle::with_template(&format!(
        "{what:>10} {{bar:40}} {{percent}}% {{elapsed_precise}} {{msg}}"
    ))?);
    Ok(b)
}

/// The general controller for `robot` in `dir`: reused when a finished one is there
/// (a resumed run), else trained there with a progress bar.
fn general_controller(robot: Robot, seed: u64, dir: &Path) -> Result<ControlTrainer> {
    let mut cfg = ControlConfig::for_robot(robot);
    cfg.seed = seed;
    if let Ok(t) = store::controller::load(dir)
        && t.config == cfg
        && t.finished()
    {
        return Ok(t);
    }
    let mut run =
        RunWriter::create(dir, RunKind::Controller, &cfg, Existing::Replace).map_err(super::store_error)?;
    let mut t = ControlTrainer::new(cfg)?;
    let b = bar(t.total_updates() as u64, "controller")?;
    while !t.finished() {
        let m = t.train_update()?;
        b.set_position(m.update as u64);
        b.set_message(format!("success {}", m.success_rate.map_or("-".into(), |s| format!("{s:.2}"))));
    }
    b.finish_and_clear();
    run.save(|f| store::controller::save_into(f, &t))?;
    Ok(t)
}

/// Runs `schrl train`.
pub fn train(args: TrainArgs) -> Result<()> {
    let start = std::time::Instant::now();
    let out = args.run.out.clone();
    let (mut run, settings, saved) = if args.run.resume {
        let (mut run, ckpt) = RunWriter::resume(&out, RunKind::Joint).map_err(super::store_error)?;
        let settings = args.resumed(&run.settings().map_err(super::store_error)?)?;
        run.set_settings(&settings).map_err(super::store_error)?;
        let saved = if ckpt.has_files() { Some(store::joint::load_from(&ckpt)?) } else { None };
        (run, settings, saved)
    } else {
        let settings = args.settings()?;
        for w in settings.task()?.warnings() {
            eprintln!("warning: {w}");
        }
        let run = RunWriter::create(&out, RunKind::Joint, &settings, args.run.existing())
            .map_err(super::store_error)?;
        (run, settings, None)
    };
    crate::interrupt::install();
    // Before the first checkpoint a resumed run starts again from its settings, which
    // repeats the same work exactly (a finished general controller is reused).
    let resumed_from = saved.as_ref().map(|t| t.iterations);
    let mut trainer = match saved {
        Some(t) => t,
        None => start_run(&settings, &mut run)?,
    };
    let done = trainer.iterations;
    let (mut log, mut history) =
        MetricsLog::open(&run, resumed_from.is_some(), |m: &JointMetrics| m.iteration <= done)
            .map_err(super::store_error)?;
    let b = bar(settings.steps as u64, "joint")?;
    b.set_position(trainer.env_steps as u64);
    let mut interrupted = false;
    while trainer.env_steps < settings.steps {
        let m = trainer.iterate()?;
        log.append(&m)?;
        b.set_position(m.env_steps.min(settings.steps) as u64);
        history.push(m);
        let recent = &history[history.len().saturating_sub(20)..];
        let sat = recent.iter().map(|m| m.satisfaction).sum::<f64>() / recent.len() as f64;
        let plan = recent.iter().map(|m| m.plan_satisfaction).sum::<f64>() / recent.len() as f64;
        b.set_message(format!(
            "satisfaction {sat:.2} (plans {plan:.2}) λ {:.2}",
            trainer.plan.lagrangian().lambda
        ));
        if trainer.iterations % settings.save_every == 0 {
            run.save(|f| store::joint::save_into(f, &trainer))?;
        }
        if recent.len() == 20 && sat >= settings.target {
            break;
        }
        if crate::interrupt::requested() {
            interrupted = true;
            break;
        }
    }
    b.finish_and_clear();
    run.save(|f| store::joint::save_into(f, &trainer))?;
    if interrupted {
        return Err(crate::interrupt::stopped(&out, format!("iteration {}", trainer.iterations)));
    }
    save_curve(&history, &out.join("training_curve.png"))?;
    println!(
        "trained {} on {} for {} iterations, {} environment steps, in {:.1} s; run in {}",
        trainer.task.robot,
        trainer.task.name,
        trainer.iterations,
        trainer.env_steps,
        start.elapsed().as_secs_f64(),
        out.display()
    );
    if settings.eval_groups > 0 {
        let eval = evaluate_task(
            &trainer.task,
            Plans::Mean(trainer.plan.planner()),
            &trainer.control.controller(),
            (settings.eval_groups, EVAL_PER_GROUP),
            EVAL_SEED,
        )?;
        let png = out.join("episodes.png");
        draw(&trainer.task, &eval, &png, true)?;
        println!("wrote {}", png.display());
        print_eval(&eval);
    }
    Ok(())
}

/// The trainer of a run that has no checkpoint yet: the warm-start controller, then
/// planner pre-training; saves the result as the run's first checkpoint.
fn start_run(settings: &JointRunSettings, run: &mut RunWriter) -> Result<JointTrainer> {
    let task = settings.task()?;
    let control = match &settings.controller {
        Some(dir) => {
            let c = store::controller::load(dir).map_err(super::store_error)?;
            if c.config.robot != settings.robot {
                bail!(
                    "--controller {}: a {} controller, not {}",
                    dir.display(),
                    c.config.robot,
                    settings.robot
                );
            }
            c
        }
        None => general_controller(settings.robot, settings.seed, &run.dir().join("general"))?,
    };
    let mut t = JointTrainer::new(task, settings.joint.clone(), settings.cpg, control)?;
    let b = bar((settings.pretrain.updates * settings.pretrain.candidates) as u64, "planner")?;
    let kept = pretrain(&mut t, &settings.pretrain, &mut |p| {
        b.set_length(p.total as u64);
        b.set_position(p.done as u64);
        b.set_message(format!("candidate {}: plan satisfaction {:.2}", p.candidate, p.satisfaction));
    })?;
    b.finish_and_clear();
    if let Some(k) = kept {
        if k.retried_without_safe_margin {
            eprintln!(
                "planner: no candidate met the spec with {} m more clearance; planning with the task's own",
                settings.joint.safe_margin
            );
        }
        eprintln!(
            "planner: kept mean paths satisfying from {:.3} of starts, {:.2} m long",
            k.satisfaction, k.length
        );
    }
    run.save(|f| store::joint::save_into(f, &t))?;
    Ok(t)
}

/// Satisfaction of executed runs and of planned paths (0–1) on top, the mean
/// low-level reward r_l in the middle, λ below; x: environment steps. Each a moving
/// average over 20 iterations, so the curve shows the trend.
fn save_curve(history: &[JointMetrics], out: &Path) -> Result<()> {
    let series = |label: &str, f: &dyn Fn(&JointMetrics) -> f64| Series {
        label: label.into(),
        points: (0..history.len())
            .map(|i| {
                let w = &history[i.saturating_sub(19)..=i];
                (history[i].env_steps as f64, w.iter().map(f).sum::<f64>() / w.len() as f64)
            })
            .collect(),
        band: vec![],
    };
    let panels = [
        ChartPanel {
            series: vec![
                series("executed runs", &|m| m.satisfaction),
                series("planned paths", &|m| m.plan_satisfaction),
            ],
            y_range: Some((0.0, 1.0)),
            y_label: "satisfaction".into(),
            reference: None,
        },
        ChartPanel {
            series: vec![series("r_l (−steps/limit; failures below −1)", &|m| m.low_level_reward)],
            y_range: None,
            y_label: "low-level reward".into(),
            reference: None,
        },
        ChartPanel {
            series: vec![series("λ (Lagrange multiplier of ρ ≥ ε)", &|m| m.lambda)],
            y_range: None,
            y_label: "λ".into(),
            reference: None,
        },
    ];
    sim::render::save_chart(&panels, "environment steps", out, true)?;
    Ok(())
}

pub(crate) fn print_eval(e: &TaskEval) {
    let (sm, ss) = mean_std(&e.satisfaction);
    println!("satisfaction: {sm:.3} ± {ss:.3}");
    if e.steps_to_reach.is_empty() {
        println!("steps to reach: -");
    } else {
        let (tm, ts) = mean_std(&e.steps_to_reach);
        println!("steps to reach: {tm:.1} ± {ts:.1}");
    }
    println!(
        "failures: {} collisions, {} falls, {} time-outs, {} entered a region to avoid",
        e.collisions, e.falls, e.timeouts, e.entered
    );
}

pub(crate) fn draw(task: &Task, e: &TaskEval, out: &Path, force: bool) -> Result<()> {
    let mut scene = Scene::new(task.map.clone());
    scene.goals = task.picture_goals();
    let radius = sim::make_env(task.robot, task.map.clone())?.radius();
    for run in e.examples.iter().take(4) {
        // A flat policy (TLTL) plans nothing.
        if !run.planned.is_empty() {
            scene.paths.push(Polyline { points: run.planned.clone(), kind: PathKind::Planned });
        }
        scene.paths.push(Polyline { points: run.trajectory.clone(), kind: PathKind::Executed });
    }
    // The first run's pose at eight moments: a Car drives forwards or backwards and
    // turns on the spot, which the trace alone does not show.
    if let Some(run) = e.examples.first() {
        let every = (run.trajectory.len() / 8).max(1);
        let poses = run.trajectory.iter().zip(&run.headings).skip(every).step_by(every);
        scene.robots.extend(poses.map(|(p, &heading)| RobotMarker { position: p.clone(), heading, radius }));
    }
    sim::render::save(&scene, out, force)?;
    Ok(())
}

/// Runs `schrl eval`.
pub fn eval(args: EvalArgs) -> Result<()> {
    if args.groups == 0 || args.per_group == 0 {
        bail!("--groups and --per-group must be at least 1");
    }
    let t = store::joint::load(&args.ckpt).map_err(super::store_error)?;
    if args.sampled_plans && args.planner != PlannerChoice::Network {
        bail!("--sampled-plans samples the network's plans; it goes with --planner network only");
    }
    let plans = match (args.planner, args.sampled_plans) {
        (PlannerChoice::Gradient, _) => {
            Plans::Gradient { task: t.plan.task(), config: GradientPlannerConfig::default() }
        }
        (PlannerChoice::Mip, _) => Plans::Mip { task: t.plan.task(), config: args.mip.config()? },
        (PlannerChoice::Network, true) => Plans::Sampled(t.plan.planner()),
        (PlannerChoice::Network, false) => Plans::Mean(t.plan.planner()),
    };
    let controller = match &args.controller {
        None => t.control.controller(),
        Some(dir) => {
            let c = store::controller::load(dir).map_err(super::store_error)?;
            if c.config.robot != t.task.robot {
                bail!(
                    "--controller {}: a {} controller, but the run's task is for the {}",
                    dir.display(),
                    c.config.robot,
                    t.task.robot
                );
            }
            c.controller()
        }
    };
    // Outputs are checked before the evaluation, which can take minutes.
    if let Some(out) = &args.out {
        sim::render::check_target(out, args.force)?;
    }
    let mut records = match &args.trajectories {
        Some(path) => Some(JsonLines::create(path, args.force).map_err(super::store_error)?),
        None => None,
    };
    let task = &t.task;
    let sizes = (args.groups, args.per_group);
    let e =
        evaluate_task_with(
            task,
            plans,
            &controller,
            sizes,
            args.seed,
            &mut |group, index, run| match records.as_mut() {
                Some(w) => w
                    .append(&RunRecord::of(run, task, group, index))
                    .map_err(|e| RunError::Record(e.to_string())),
                None => Ok(()),
            },
        )?;
    print_eval(&e);
    if let (Some(w), Some(path)) = (records, &args.trajectories) {
        w.finish().map_err(super::store_error)?;
        println!("wrote {} runs to {}", args.groups * args.per_group, path.display());
    }
    if let Some(out) = &args.out {
        draw(&t.task, &e, out, args.force)?;
        println!("wrote {}", out.display());
    }
    Ok(())
}
