//! `schrl train` and `schrl eval`: joint hierarchical training of a task, and its
//! evaluation on what the robot actually does.

use std::path::PathBuf;

use anyhow::{Result, bail};
use schrl::plan::cpg::{AnchorKind, Method};
use schrl::plan::planner::PlannerKind;
use schrl::run::RunError;
use schrl::run::evaluate::{Plans, RunRecord, TaskEval, evaluate_task_with, mean_std};
use schrl::run::joint::{JointRunSettings, SettingError};
use schrl::run::select::SelectRule;
use schrl::store::{self, JsonLines, RunKind};
use schrl::task::neural_sdf::{NeuralSdf, SdfFitConfig};
use schrl::task::{Follow, Reach};
use schrl::train::{Progress, ResumeChanges, RunSession, Stop, TrainError, Watcher};
use sim::Robot;
use stl::Semantics;

use crate::progress::LoggedBar;

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
    /// Environment steps of joint training [default: 3000000; the Car's 4500000].
    #[arg(long)]
    steps: Option<usize>,
    /// Stop early once this fraction of the last 20 iterations' runs satisfy the task
    /// (default: train to the step budget).
    #[arg(long)]
    target: Option<f64>,
    /// Warm-start the controller from this `schrl control train` run (default: train a
    /// general controller first, into DIR/general).
    #[arg(long)]
    controller: Option<PathBuf>,
    /// General controllers to train at most before keeping one: each is checked on 500
    /// random goals and, below 0.95 of them, another is trained from a fresh start; the
    /// first to pass (or the best) is kept [default: 3; 1: one, unchecked].
    #[arg(long, value_name = "N")]
    controller_tries: Option<usize>,
    /// Semantics of the spec in the planner's loss: hard, soft:ALPHA or
    /// lse:TEMPERATURE, a smooth one with ,until=flat|recursive
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
    /// Weight per radian of the turn term pre-training's candidates follow: the angles
    /// their plans turn through at the waypoints (0: none) [default: 0].
    #[arg(long)]
    pretrain_turn_weight: Option<f64>,
    /// Waypoints of the first rung of pre-training's horizon curriculum, climbed by
    /// attempts that keep failing where the task's spec has shorter forms; 0: none
    /// [default: 4].
    #[arg(long)]
    pretrain_horizon_from: Option<usize>,
    /// When pre-training's candidates never find the task, try a guided candidate (the
    /// network fitted to the gradient planner's plans from many starts) [default: on
    /// for candidates of 1000 updates or more; this flag is kept for older scripts].
    #[arg(long, conflicts_with = "no_pretrain_guide")]
    pretrain_guide: bool,
    /// No guided candidate after pre-training's candidates (the default before
    /// 2026-12-06).
    #[arg(long)]
    no_pretrain_guide: bool,
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
    /// The controller's PPO step size in the joint phase [default: the controller's
    /// own, 3e-4].
    #[arg(long)]
    control_lr: Option<f64>,
    /// Stop each of the joint phase's PPO updates once an epoch's mean approximate KL
    /// exceeds this [default: the controller's own, none].
    #[arg(long)]
    control_target_kl: Option<f64>,
    /// The goal the controller is given while it executes a plan: waypoints (each
    /// waypoint in turn, the paper's) or carrot:METRES (a point that far ahead on the
    /// planned segment, never past its waypoint) [default: waypoints].
    #[arg(long, value_name = "waypoints|carrot:METRES")]
    follow: Option<Follow>,
    /// When the executing robot counts a waypoint reached: radius (within the reach
    /// radius, the paper's) or in-goal (within it and inside every goal that holds
    /// the planned waypoint) [default: in-goal for the Drone and the Car, radius for the others].
    #[arg(long, value_name = "radius|in-goal")]
    reach: Option<Reach>,
    /// Reward the joint phase's controller loses per step per metre it strays from the
    /// planned segment it drives (0: the paper's reward) [default: 0.3 for the Doggo, 0
    /// for the others].
    #[arg(long)]
    off_track_weight: Option<f64>,
    /// Reward the joint phase's controller loses on the step its robot falls (0: the
    /// paper's reward) [default: 0].
    #[arg(long, value_name = "R")]
    fall_penalty: Option<f64>,
    /// Weight per metre of the path-length term the planner follows in the joint phase
    /// [default: 0.05].
    #[arg(long)]
    length_weight: Option<f64>,
    /// Weight per radian of the turn term the planner follows in the joint phase: the
    /// angles its plan turns through at the waypoints (0: none) [default: 0].
    #[arg(long)]
    turn_weight: Option<f64>,
    /// Weight per square metre of the trust region holding the joint phase's paths near
    /// the pre-trained planner's (0: none; gru-ode planner only) [default: 0].
    #[arg(long)]
    anchor_weight: Option<f64>,
    /// What the trust region holds: paths (the waypoints) or length (one-sided: plans
    /// may not grow longer than the pre-trained planner's) [default: paths].
    #[arg(long)]
    anchor_on: Option<AnchorKind>,
    /// The most one planner update of the joint phase may move the sampled waypoints,
    /// mean metres (0: unbounded; gru-ode planner only) [default: 0].
    #[arg(long)]
    plan_step_limit: Option<f64>,
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
    /// Metres more clearance the planner keeps at each waypoint the robot turns at
    /// than along its segments (room for a robot that swings out of its turns)
    /// [default: 0; the Car's 0.2].
    #[arg(long)]
    turn_margin: Option<f64>,
    /// What the planner's `safe` measures obstacles with: exact (the map's distance)
    /// or neural (a network fitted to it, as the paper's Drone planner saw the duck;
    /// fitted with `schrl sdf fit`'s defaults and the run's seed unless
    /// --obstacle-sdf names one). Runs are judged on the exact geometry [default: exact].
    #[arg(long, value_enum)]
    obstacle: Option<ObstacleChoice>,
    /// The neural SDF the planner sees (a `schrl sdf fit --out` file); implies
    /// `--obstacle neural`.
    #[arg(long, value_name = "FILE.json")]
    obstacle_sdf: Option<PathBuf>,
    #[command(flatten)]
    run: super::RunDirArgs,
    /// Evaluation groups of 100 runs after training; 0: none [default: 5].
    #[arg(long, value_parser = super::count::<0, 100>)]
    eval_groups: Option<usize>,
    /// Iterations between checkpoints [default: 50].
    #[arg(long)]
    save_every: Option<usize>,
    /// Validate the deployed pair (mean plans, mean actions) on 100 runs of its own
    /// after every STEPS joint environment steps, and at the first and last iteration;
    /// the best validated checkpoint, kept in DIR/best, is what the evaluation and
    /// `schrl eval` use; 0: the last checkpoint [default: 250000 for the Doggo and the
    /// Car, 0 for Point and the Drone].
    #[arg(long, value_name = "STEPS")]
    select_every: Option<usize>,
    /// Which validated checkpoint is deployed: most-satisfying (the fastest of the
    /// most satisfying) or one-se (the fastest within one standard error of the most
    /// satisfying) [default: one-se for the Car, most-satisfying for the others].
    #[arg(long, value_name = "most-satisfying|one-se")]
    select_rule: Option<SelectRule>,
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

    /// The settings of a new run: the flags given, the library's defaults for the rest.
    fn settings(&self) -> Result<JointRunSettings> {
        let Some(task_arg) = &self.task else { bail!("--task is required for a new run") };
        let task = super::task::resolve(self.robot, task_arg)?;
        let mut s = JointRunSettings::for_task(&task, self.seed.unwrap_or(0))?;
        fn set<T>(slot: &mut T, flag: Option<T>) {
            if let Some(v) = flag {
                *slot = v;
            }
        }
        set(&mut s.steps, self.steps);
        set(&mut s.target, self.target.map(Some));
        s.controller.clone_from(&self.controller);
        set(&mut s.controller_tries, self.controller_tries);
        let j = &mut s.joint;
        set(&mut j.plan_batch, self.plan_batch);
        set(&mut j.goal_margin, self.goal_margin);
        set(&mut j.safe_margin, self.safe_margin);
        set(&mut j.turn_margin, self.turn_margin);
        set(&mut j.runs_per_start, self.runs_per_start);
        set(&mut j.control_weight, self.control_weight);
        set(&mut j.control_lr, self.control_lr.map(Some));
        set(&mut j.control_target_kl, self.control_target_kl.map(Some));
        set(&mut j.follow, self.follow);
        set(&mut j.reach, self.reach);
        set(&mut j.off_track_weight, self.off_track_weight);
        set(&mut j.fall_penalty, self.fall_penalty);
        set(&mut j.length_weight, self.length_weight);
        set(&mut j.turn_weight, self.turn_weight);
        j.freeze_planner = self.freeze_planner;
        j.freeze_controller = self.freeze_controller;
        j.neural_obstacle = self.neural_obstacle(&task, s.seed)?;
        let c = &mut s.cpg;
        set(&mut c.semantics, self.semantics);
        set(&mut c.method, self.method);
        set(&mut c.pg_weight, self.pg_weight);
        set(&mut c.lambda_lr, self.lambda_lr);
        if let Some(kind) = self.planner {
            s.set_planner(kind);
        }
        set(&mut s.joint.anchor_weight, self.anchor_weight);
        set(&mut s.joint.anchor_on, self.anchor_on);
        set(&mut s.joint.plan_step_limit, self.plan_step_limit);
        let p = &mut s.pretrain;
        set(&mut p.updates, self.pretrain_updates);
        set(&mut p.candidates, self.pretrain_candidates);
        set(&mut p.length_weight, self.pretrain_length_weight);
        set(&mut p.turn_weight, self.pretrain_turn_weight);
        set(&mut p.horizon_from, self.pretrain_horizon_from);
        // On by default; `--pretrain-guide` only restates it.
        p.guide &= !self.no_pretrain_guide;
        set(&mut s.eval_groups, self.eval_groups);
        set(&mut s.save_every, self.save_every);
        set(&mut s.select_every, self.select_every);
        set(&mut s.select_rule, self.select_rule);
        s.validate().map_err(flag_error)?;
        Ok(s)
    }

    /// The network `--obstacle neural` / `--obstacle-sdf` give the planner, if any.
    fn neural_obstacle(&self, task: &schrl::task::Task, seed: u64) -> Result<Option<NeuralSdf>> {
        let net = match (self.obstacle, &self.obstacle_sdf) {
            (Some(ObstacleChoice::Exact), Some(_)) => {
                bail!("--obstacle-sdf gives the planner a neural SDF; it contradicts --obstacle exact")
            }
            (None | Some(ObstacleChoice::Exact), None) => return Ok(None),
            (_, Some(path)) => store::sdf::load(path).map_err(super::store_error)?,
            (Some(ObstacleChoice::Neural), None) => {
                let cfg = SdfFitConfig { seed, ..SdfFitConfig::default() };
                eprintln!(
                    "fitting a neural SDF of the {} map ({} steps) for the planner",
                    task.map.name(),
                    cfg.steps
                );
                let (net, report) =
                    NeuralSdf::fit(&task.map, &cfg).map_err(|e| anyhow::anyhow!("--obstacle neural: {e}"))?;
                eprintln!(
                    "mean abs error {:.4} m, sign agreement {:.4} ({:.4} near surfaces)",
                    report.mean_abs_error, report.sign_agreement, report.sign_agreement_near
                );
                net
            }
        };
        if net.map != task.map.name() {
            bail!(
                "--obstacle-sdf: the network learned the {} map; the {} task is on the {} map",
                net.map,
                task.name,
                task.map.name()
            );
        }
        Ok(Some(net))
    }

    /// Refuses flags given with a value other than the resumed run's saved one, naming
    /// them (the budget, target, evaluation and checkpoint interval may change).
    fn refuse_resume_conflicts(&self, saved: &JointRunSettings) -> Result<()> {
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
                ("--controller-tries", differs(&self.controller_tries, &saved.controller_tries)),
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
                ("--pretrain-turn-weight", differs(&self.pretrain_turn_weight, &saved.pretrain.turn_weight)),
                (
                    "--pretrain-horizon-from",
                    differs(&self.pretrain_horizon_from, &saved.pretrain.horizon_from),
                ),
                ("--pretrain-guide", self.pretrain_guide && !saved.pretrain.guide),
                ("--no-pretrain-guide", self.no_pretrain_guide && saved.pretrain.guide),
                ("--freeze-planner", self.freeze_planner && !saved.joint.freeze_planner),
                ("--runs-per-start", differs(&self.runs_per_start, &saved.joint.runs_per_start)),
                ("--control-weight", differs(&self.control_weight, &saved.joint.control_weight)),
                ("--control-lr", differs(&self.control_lr.map(Some), &saved.joint.control_lr)),
                (
                    "--control-target-kl",
                    differs(&self.control_target_kl.map(Some), &saved.joint.control_target_kl),
                ),
                ("--follow", differs(&self.follow, &saved.joint.follow)),
                ("--reach", differs(&self.reach, &saved.joint.reach)),
                ("--off-track-weight", differs(&self.off_track_weight, &saved.joint.off_track_weight)),
                ("--fall-penalty", differs(&self.fall_penalty, &saved.joint.fall_penalty)),
                ("--length-weight", differs(&self.length_weight, &saved.joint.length_weight)),
                ("--turn-weight", differs(&self.turn_weight, &saved.joint.turn_weight)),
                ("--anchor-weight", differs(&self.anchor_weight, &saved.joint.anchor_weight)),
                ("--anchor-on", differs(&self.anchor_on, &saved.joint.anchor_on)),
                ("--plan-step-limit", differs(&self.plan_step_limit, &saved.joint.plan_step_limit)),
                ("--freeze-controller", self.freeze_controller && !saved.joint.freeze_controller),
                ("--goal-margin", differs(&self.goal_margin, &saved.joint.goal_margin)),
                ("--safe-margin", differs(&self.safe_margin, &saved.joint.safe_margin)),
                ("--turn-margin", differs(&self.turn_margin, &saved.joint.turn_margin)),
                (
                    "--obstacle",
                    self.obstacle.is_some_and(|o| {
                        (o == ObstacleChoice::Neural) != saved.joint.neural_obstacle.is_some()
                    }),
                ),
                ("--obstacle-sdf", self.obstacle_sdf_differs(saved)?),
                ("--select-every", differs(&self.select_every, &saved.select_every)),
                ("--select-rule", differs(&self.select_rule, &saved.select_rule)),
            ],
        )
    }
}

impl TrainArgs {
    /// `true` when `--obstacle-sdf` names a network other than the saved run's.
    fn obstacle_sdf_differs(&self, saved: &JointRunSettings) -> Result<bool> {
        let Some(path) = &self.obstacle_sdf else { return Ok(false) };
        let net = store::sdf::load(path).map_err(super::store_error)?;
        Ok(saved.joint.neural_obstacle.as_ref() != Some(&net))
    }
}

/// What the planner's `safe` measures obstacles with (`--obstacle`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
enum ObstacleChoice {
    /// The map's exact signed distance.
    Exact,
    /// A neural SDF fitted to it.
    Neural,
}

/// A setting out of range, named by its flag.
fn flag_error(e: SettingError) -> anyhow::Error {
    anyhow::anyhow!("--{} {}", e.name.replace('_', "-"), e.message)
}

/// Arguments of `schrl eval`.
#[derive(clap::Args, Debug)]
pub struct EvalArgs {
    /// Run directory of `schrl train`.
    #[arg(long)]
    ckpt: PathBuf,
    #[command(flatten)]
    runs: super::EvalRunsArgs,
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
    /// The gradient planner's settings (with `--planner gradient`).
    #[command(flatten)]
    gradient: super::plan::GradientFlags,
    /// Drive with this `schrl control train` run's controller instead of the run's.
    #[arg(long)]
    controller: Option<PathBuf>,
    /// Drive with the run's general controller, the one its joint phase started from
    /// (DIR/general, or the retry `schrl train` kept: DIR/general.json), instead of the
    /// jointly trained one.
    #[arg(long, conflicts_with = "controller")]
    general_controller: bool,
    /// The goal the controller is given while it executes a plan: waypoints or
    /// carrot:METRES (see `schrl train --follow`) [default: the run's].
    #[arg(long, value_name = "waypoints|carrot:METRES")]
    follow: Option<Follow>,
    /// When the robot counts a waypoint reached: radius or in-goal (see `schrl train
    /// --reach`) [default: the run's].
    #[arg(long, value_name = "radius|in-goal")]
    reach: Option<Reach>,
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

/// The training commands' view of a run (`schrl train`, `schrl control train`): one
/// progress bar per stage (lines in a log), notes on stderr, and Ctrl-C as the request
/// to stop.
#[derive(Default)]
pub(crate) struct Bars {
    /// The stage shown and its bar.
    current: Option<(&'static str, LoggedBar)>,
}

impl Bars {
    /// Shows `stage` at `pos` of `len` `unit`s with `message`, replacing the previous
    /// stage's bar.
    fn show(&mut self, stage: &'static str, unit: &str, (pos, len): (u64, u64), message: String) {
        if self.current.as_ref().is_none_or(|(s, _)| *s != stage) {
            self.clear();
            let mut b = LoggedBar::new(len, stage, unit);
            // A resumed stage logs from where it resumed.
            b.start_at(pos.saturating_sub(1));
            self.current = Some((stage, b));
        }
        let b = &mut self.current.as_mut().expect("set above").1;
        b.set_length(len);
        b.set(pos, message);
    }

    pub(crate) fn clear(&mut self) {
        if let Some((_, b)) = self.current.take() {
            b.clear();
        }
    }
}

impl Watcher for Bars {
    fn progress(&mut self, p: Progress<'_>) {
        match p {
            Progress::Controller { metrics: m, total } => {
                let message = format!(
                    "success {} return {} {:.0} steps/s",
                    m.success_rate.map_or("-".into(), |s| format!("{s:.2}")),
                    m.mean_return.map_or("-".into(), |r| format!("{r:.1}")),
                    m.steps_per_sec
                );
                self.show("controller", "updates", (m.update as u64, total as u64), message);
            }
            Progress::Pretrain(p) => {
                let message = format!("candidate {}: plan satisfaction {:.2}", p.candidate, p.satisfaction);
                self.show("planner", "updates", (p.done as u64, p.total as u64), message);
            }
            Progress::Joint { metrics, total_steps, satisfaction, plan_satisfaction } => {
                let message = format!(
                    "satisfaction {satisfaction:.2} (plans {plan_satisfaction:.2}) λ {:.2}",
                    metrics.lambda
                );
                let pos = metrics.env_steps.min(total_steps) as u64;
                self.show("joint", "steps", (pos, total_steps as u64), message);
            }
        }
    }

    fn note(&mut self, note: &str) {
        match &self.current {
            Some((_, b)) => b.suspend(|| eprintln!("{note}")),
            None => eprintln!("{note}"),
        }
    }

    fn stop_requested(&mut self) -> bool {
        crate::interrupt::requested()
    }
}

/// Runs `schrl train`.
pub fn train(args: TrainArgs) -> Result<()> {
    let out = args.run.out.clone();
    let session = if args.run.resume {
        let mut session = RunSession::resume(&out).map_err(train_error)?;
        args.refuse_resume_conflicts(session.settings())?;
        session
            .change(ResumeChanges {
                steps: args.steps,
                target: args.target,
                eval_groups: args.eval_groups,
                save_every: args.save_every,
            })
            .map_err(train_error)?;
        session
    } else {
        let settings = args.settings()?;
        RunSession::create(&out, settings, args.run.existing()).map_err(train_error)?
    };
    crate::interrupt::install();
    let mut bars = Bars::default();
    let trained = session.train(&mut bars);
    bars.clear();
    let trained = trained.map_err(train_error)?;
    let t = &trained.trainer;
    if trained.stop == Stop::Requested {
        return Err(crate::interrupt::stopped(&out, format!("iteration {}", t.iterations)));
    }
    println!(
        "trained {} on {} for {} iterations, {} environment steps, in {:.1} s; run in {}",
        t.task.robot,
        t.task.name,
        t.iterations,
        t.env_steps,
        trained.seconds,
        out.display()
    );
    if let Some(v) = &trained.selected {
        println!("{}", deployed(v));
    }
    if let Some(eval) = &trained.evaluation {
        if let Some(png) = trained.pictures.last() {
            println!("wrote {}", png.display());
        }
        print_eval(eval);
    }
    Ok(())
}

/// A training error as the command line says it: settings by their flags, store
/// errors with the flag that would help, a stop as Ctrl-C's.
pub(crate) fn train_error(e: TrainError) -> anyhow::Error {
    match e {
        TrainError::StoppedInController { update, dir } => {
            let run = dir.parent().unwrap_or(&dir);
            crate::interrupt::stopped(run, format!("the general controller at update {update}"))
        }
        TrainError::StoppedInPretraining { candidates, dir } => {
            let run = dir.parent().unwrap_or(&dir);
            crate::interrupt::stopped(run, format!("planner pre-training after candidate {candidates}"))
        }
        TrainError::Setting(e) => flag_error(e),
        TrainError::Store(e) => super::store_error(e),
        TrainError::ControllerRobot { dir, found, wanted } => {
            anyhow::anyhow!("--controller {}: a {found} controller, not {wanted}", dir.display())
        }
        e => e.into(),
    }
}

/// Which checkpoint a selecting run deploys, as `schrl train` and `schrl eval` say it.
fn deployed(v: &schrl::run::select::Validation) -> String {
    format!(
        "deployed: the checkpoint of iteration {} ({} joint steps), validated at satisfaction {:.3}",
        v.iteration, v.env_steps, v.satisfaction
    )
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

/// Runs `schrl eval`.
pub fn eval(args: EvalArgs) -> Result<()> {
    let (t, selected) = store::joint::load_deployed(&args.ckpt).map_err(super::store_error)?;
    if let Some(v) = &selected {
        println!("{}", deployed(v));
    }
    if args.sampled_plans && args.planner != PlannerChoice::Network {
        bail!("--sampled-plans samples the network's plans; it goes with --planner network only");
    }
    let plans = match (args.planner, args.sampled_plans) {
        (PlannerChoice::Gradient, _) => {
            Plans::Gradient { task: t.plan.task(), config: args.gradient.config()? }
        }
        (PlannerChoice::Mip, _) => Plans::Mip { task: t.plan.task(), config: args.mip.config()? },
        (PlannerChoice::Network, true) => Plans::Sampled(t.plan.planner()),
        (PlannerChoice::Network, false) => Plans::Mean(t.plan.planner()),
    };
    let general = match args.general_controller {
        true => Some(store::controller::kept_general_dir(&args.ckpt).map_err(super::store_error)?),
        false => None,
    };
    let controller = match general.as_ref().or(args.controller.as_ref()) {
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
    let mut task = t.task.clone();
    if let Some(follow) = args.follow {
        let reach = schrl::run::execute::task_env(task.robot, &task, false)?.reach_radius();
        follow.check(reach).map_err(|e| anyhow::anyhow!("--follow {follow}: {e}"))?;
        task.follow = follow;
    }
    if let Some(reach) = args.reach {
        task.reach = reach;
    }
    let task = &task;
    let sizes = args.runs.sizes();
    let e = evaluate_task_with(task, plans, &controller, sizes, args.runs.seed, &mut |group, index, run| {
        match records.as_mut() {
            Some(w) => {
                w.append(&RunRecord::of(run, task, group, index)).map_err(|e| RunError::Record(e.to_string()))
            }
            None => Ok(()),
        }
    })?;
    print_eval(&e);
    if let (Some(w), Some(path)) = (records, &args.trajectories) {
        w.finish().map_err(super::store_error)?;
        println!("wrote {} runs to {}", args.runs.groups * args.runs.per_group, path.display());
    }
    if let Some(out) = &args.out {
        e.save_picture(&t.task, out, args.force)?;
        println!("wrote {}", out.display());
    }
    Ok(())
}
