//! Joint hierarchical training (paper App. A, Algorithm 1) and task evaluation.
//!
//! Each iteration samples [`JointConfig::plan_batch`] paths from the GRU-ODE planner,
//! [`JointConfig::runs_per_start`] from each start, and rolls the controller out
//! through each path's waypoints (see [`crate::run::execute`]). Then:
//!
//! * the controller learns by PPO on the transitions of those runs;
//! * the planner takes Algorithm 1's step ([`PlanTrainer::update_joint`]): the
//!   score-function term on `r_l`, measured on each run ([`execution_reward`]: how
//!   fast the plan was executed, failures below every success), with the other runs
//!   from the same start as its baseline ([`leave_one_out`]), so the start's own
//!   difficulty cancels; and the spec's terms (`λ ∇ρ`, the dual step on `ρ ≥ ε`) on a
//!   fresh batch of sampled paths, as in pre-training, with pre-training's pathwise
//!   path-length term ([`JointConfig::length_weight`]).
//!
//! Either side can be frozen (the paper's Fig. 4 ablations). The controller is usually
//! warm-started from a general controller trained on random goals (as the authors
//! did), the planner from pre-training on the spec ([`crate::plan::pretrain`]).

use std::time::Instant;

use candle_core::{DType, Tensor};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};
use sim::{Env, Robot};

use crate::control::ControlTrainer;
use crate::control::normalize::RewardScaler;
use crate::control::policy::PolicyCache;
use crate::control::ppo::{RolloutBuffer, UpdateStats as PpoStats};
use crate::control::trainer::{RewardTerms, normalize_obs};
use crate::plan::cpg::{AnchorKind, CpgConfig, PathLengthReward, PlanTrainer, TurnReward};
use crate::run::RunError;
use crate::run::episode::{Driver, StepReports, drive};
use crate::run::evaluate::reach_steps;
use crate::run::execute::{Execution, Outcome, start_task_run, task_env};
use crate::task::along::ExecutionSpec;
use crate::task::neural_sdf::NeuralSdf;
use crate::task::{Follow, ObstacleModel, Reach, Task};

/// Joint-training settings.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct JointConfig {
    /// Paths planned and executed per iteration (reference: 8).
    pub plan_batch: usize,
    /// Weight of the measured low-level reward in the planner's score-function term,
    /// relative to the spec's advantages (which are normalised to unit scale):
    /// `A = weight · (r_l − baseline)` with `r_l` from [`execution_reward`] (0.3;
    /// on Point Seq seed 0, 0.3, 1 and 10 kept satisfaction at 0.99–1.00, and
    /// 10 disrupted the first iterations: plan satisfaction fell to 0.13 before it
    /// recovered).
    pub control_weight: f64,
    /// The controller's PPO step size in the joint phase; `None` (the default, and
    /// runs saved before it existed): the controller's own `ppo.lr`, un-annealed (the
    /// reference's 3e-4, what Point, Car and Drone use). A general controller whose
    /// step size annealed to nothing and whose actions are nearly deterministic
    /// jolts at it: Doggo Cover seed 0, KL 5.9 per update over the first 170 k steps,
    /// satisfaction 0.11 → 0.05, then up to 0.39 of 100 runs after 1.5 M; at 3e-5,
    /// KL 0.1 and a steady climb, but only to 0.21 (README, *Doggo tasks*).
    #[serde(default)]
    pub control_lr: Option<f64>,
    /// Stop each of the joint phase's PPO updates once an epoch's mean approximate KL
    /// exceeds this ([`crate::control::PpoConfig::target_kl`]); `None` (the default,
    /// and runs saved before it existed): the controller's own setting (none in every
    /// shipped preset). Doggo Cover seed 0 at 3e-4 moved 0.6–1.3 nats per update for
    /// its first 0.7 M joint steps (README, *Doggo tasks*).
    #[serde(default)]
    pub control_target_kl: Option<f64>,
    /// Weight per metre of the path-length stand-in the joint phase keeps on its
    /// fresh samples, pathwise and in their score function, as in pre-training (0.05,
    /// pre-training's; Point Seq seed 0: without it the joint phase lengthened the
    /// deployed plans, 479 steps to reach with it, 503 without). While the fresh
    /// samples' score function read ρ alone (until 2026-12-02) the plans still grew
    /// (Point Branch seed 0: 9.76 m pre-trained, 10.16 m after, 417.6 steps to reach
    /// against the frozen planner's 391.6; with it in both terms, 385.8). Runs saved
    /// before it existed used 0.
    #[serde(default)]
    pub length_weight: f64,
    /// Weight per radian of the turn term the joint phase keeps beside the length one
    /// ([`TurnReward`], pathwise and in the score function): the angles the plan turns
    /// through at its waypoints. 0 (the default for every robot, and runs saved before
    /// it existed): none; tried on the Car and not kept (README, *Seq's steps*).
    #[serde(default, skip_serializing_if = "crate::control::trainer::is_zero")]
    pub turn_weight: f64,
    /// Weight per square metre of the trust region that holds the joint phase's
    /// sampled paths near the warm-start planner's paths from the same start and
    /// noise ([`PlanTrainer::anchor_here`]; set when pre-training keeps a planner).
    /// 0 (the default, and runs saved before it existed) leaves the planner free: on
    /// Point, weight 10 held Branch and Signal at the frozen planner's steps to reach
    /// but cost Loop and Cover (README, *The trust region*). Only the GRU-ODE can be
    /// anchored.
    #[serde(default)]
    pub anchor_weight: f64,
    /// What the trust region holds: the paths (the default), or (one-sided) their
    /// length.
    #[serde(default)]
    pub anchor_on: AnchorKind,
    /// The most one planner update of the joint phase may move the sampled waypoints,
    /// mean metres over a fresh batch with the same starts and noise before and after
    /// ([`PlanTrainer::limit_joint_step`]): a trust region on each step rather than on
    /// the distance from the warm start. 0 (the default, and runs saved before it
    /// existed) leaves Adam's steps whole. Only the GRU-ODE can be bounded.
    #[serde(default)]
    pub plan_step_limit: f64,
    /// Runs from each start in an iteration (4): `plan_batch` must be a multiple.
    /// Each run's baseline is the mean `r_l` of the others from its start; with 1,
    /// the mean of the rest of the batch.
    #[serde(default = "one")]
    pub runs_per_start: usize,
    /// Keep the planner fixed.
    pub freeze_planner: bool,
    /// Keep the controller fixed (it then acts with its mean action).
    pub freeze_controller: bool,
    /// The planner plans for the task with goal discs shrunk by this much (metres;
    /// see [`Task::with_goal_margin`]), usually the controller's reach radius, so the
    /// positions where waypoints count as reached lie in the goals. Satisfaction is
    /// judged on the task's own goals. Runs saved before it existed used 0.
    #[serde(default)]
    pub goal_margin: f64,
    /// The planner plans for the task with `safe` keeping this much more clearance
    /// (metres; see [`Task::with_safe_margin`]), room for the controller's curves.
    /// Collisions are judged on the robot's trajectory. Runs saved before it existed
    /// used 0.
    #[serde(default)]
    pub safe_margin: f64,
    /// Metres more clearance the planner asks at each waypoint the robot turns at
    /// than along its segments ([`Task::with_turn_margin`]), room for a robot that
    /// swings out of its turns. The joint phase's: pre-training searches without it
    /// and the constrained updates move the kept plan's turns out. 0 (this struct's
    /// default, and runs saved before it existed): none; a run's default is its
    /// robot's ([`default_turn_margin`]).
    #[serde(default)]
    pub turn_margin: f64,
    /// The planner's `safe` measures obstacles with this network instead of the
    /// map's exact distance (`None`, the default; see [`JointConfig::planned_task`]).
    /// The paper's Drone planner saw a neural SDF of the duck (§3.1). Runs are judged
    /// on the exact geometry either way.
    #[serde(default)]
    pub neural_obstacle: Option<NeuralSdf>,
    /// The goal the controller is given while it executes a plan ([`Follow`]): the
    /// waypoints themselves (the default, the paper's, and runs saved before it
    /// existed) or a point ahead on the planned segment.
    #[serde(default)]
    pub follow: Follow,
    /// Subtracted, times the robot's distance (m) from the planned segment it drives
    /// (from the waypoint before to the current one), from the reward of every step the
    /// joint phase's controller learns from; the runs' own returns and `r_l` stay the
    /// environment's. 0 (the paper's reward, runs saved before it existed, and the
    /// default of [`JointRunSettings::for_task`] for every robot but the Doggo,
    /// [`crate::control::trainer::TrackDefaults`]): a controller that swings
    /// wide of a turn pays only when it collides.
    /// The planner checks clearance along those segments (README, *Following the
    /// planned segments*).
    #[serde(default)]
    pub off_track_weight: f64,
    /// Subtracted from the reward the joint phase's controller learns from on the
    /// step its robot falls (before reward scaling; the runs' returns and `r_l` stay
    /// the environment's), as [`crate::control::ControlConfig::fall_penalty`] in
    /// controller training. 0 (the default, the paper's reward, and runs saved before
    /// it existed): a fall costs only the return it ends. Legged robots only fall.
    #[serde(default, skip_serializing_if = "crate::control::trainer::is_zero")]
    pub fall_penalty: f64,
    /// When the executing robot counts a waypoint reached ([`Reach`]): within the
    /// reach radius (the paper's; the default but for the Drone and the Car,
    /// [`default_reach`], and runs saved before it existed) or, as well, inside the
    /// goals that hold the planned waypoint.
    #[serde(default)]
    pub reach: Reach,
}

impl JointConfig {
    /// Its fall penalty and off-track weight, as the controller's learned reward
    /// takes them.
    fn reward_terms(&self) -> RewardTerms {
        RewardTerms { fall_penalty: self.fall_penalty, off_track_weight: self.off_track_weight }
    }

    /// The stand-in for `r_l` the joint phase's planner follows beside the executed
    /// runs' rewards: the path's length and its turns.
    pub fn path_terms(&self) -> (PathLengthReward, TurnReward) {
        (PathLengthReward { weight: self.length_weight }, TurnReward { weight: self.turn_weight })
    }

    /// The task the planner plans for: `task` with the goal margin, the obstacle
    /// model, the turn margin and, if `with_safe_margin`, the safe margin. Errors when the neural
    /// obstacle learned another map.
    pub fn planned_task(&self, task: &Task, with_safe_margin: bool) -> Result<Task, RunError> {
        let margin = if with_safe_margin { self.safe_margin } else { 0.0 };
        let planned = task
            .with_goal_margin(self.goal_margin)
            .with_safe_margin(margin)
            .with_turn_margin(self.turn_margin);
        match &self.neural_obstacle {
            None => Ok(planned),
            Some(net) => planned
                .with_obstacle(ObstacleModel::Neural(std::sync::Arc::new(net.clone())))
                .map_err(|message| RunError::Setting { key: "neural_obstacle", message }),
        }
    }
}

impl Default for JointConfig {
    fn default() -> Self {
        Self {
            plan_batch: 8,
            control_weight: 0.3,
            control_lr: None,
            control_target_kl: None,
            length_weight: 0.05,
            turn_weight: 0.0,
            anchor_weight: 0.0,
            anchor_on: AnchorKind::Paths,
            plan_step_limit: 0.0,
            runs_per_start: 4,
            freeze_planner: false,
            freeze_controller: false,
            goal_margin: 0.0,
            safe_margin: 0.0,
            turn_margin: 0.0,
            neural_obstacle: None,
            follow: Follow::Waypoints,
            off_track_weight: 0.0,
            fall_penalty: 0.0,
            reach: Reach::Radius,
        }
    }
}

/// Runs saved before [`JointConfig::runs_per_start`] existed sampled one path per start.
fn one() -> usize {
    1
}

/// Every setting of a `schrl train` run: what its run directory's manifest holds,
/// and what `--resume` and `schrl eval` read back whole.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct JointRunSettings {
    /// The robot.
    pub robot: Robot,
    /// The task's TOML text.
    pub task_toml: String,
    /// The task's spec text.
    pub task_spec: String,
    /// Seed of everything.
    pub seed: u64,
    /// Environment steps of joint training (3 M).
    pub steps: usize,
    /// Stop early once this fraction of the last 20 iterations' runs satisfy the task;
    /// `None` (the default): train to the step budget. Early stopping reads the
    /// satisfaction of *sampled* plans, which joint training raises, so with it a
    /// jointly trained planner stopped its controller's training sooner than a frozen
    /// one (Point Branch: 0.28–1.47 M steps against 1.29–3.00 M) and reached more
    /// slowly (README, *Joint training*). Runs saved with a target keep it.
    pub target: Option<f64>,
    /// The controller run warm-starting the controller; `None`: a general controller
    /// trained into the run's `general/`.
    pub controller: Option<std::path::PathBuf>,
    /// General controllers the run may train before it keeps one
    /// (`schrl train`'s first stage; [`crate::train::controller::ControllerCheck`]): with more than one, each is
    /// checked on random goals and a fresh one trained while they fall short. 1 (runs
    /// saved before it existed): one, unchecked. Default: [`DEFAULT_CONTROLLER_TRIES`].
    #[serde(default = "one")]
    pub controller_tries: usize,
    /// Joint-training settings.
    pub joint: JointConfig,
    /// The planner's training hyper-parameters.
    pub cpg: CpgConfig,
    /// Planner pre-training.
    pub pretrain: crate::plan::pretrain::PretrainConfig,
    /// Evaluation groups of [`crate::run::evaluate::EVAL_PER_GROUP`] runs after training (0: none).
    pub eval_groups: usize,
    /// Iterations between checkpoints (50).
    pub save_every: usize,
    /// Joint environment steps between validations of the deployed pair; the best
    /// validated checkpoint is the run's result ([`crate::run::select`]). 0 (runs
    /// saved before it existed, and the native robots' default): the last checkpoint
    /// is. Default: [`crate::run::select::default_every`].
    #[serde(default)]
    pub select_every: usize,
    /// Which validation a selecting run deploys ([`crate::run::select::SelectRule`]):
    /// the most satisfying (runs saved before it existed) or the fastest within one
    /// standard error of it. Default: [`crate::run::select::default_rule`].
    #[serde(default)]
    pub select_rule: crate::run::select::SelectRule,
}

/// Joint-training steps of a run by default (chosen on Point).
pub const DEFAULT_STEPS: usize = 3_000_000;

/// Joint-training steps of a run by default for `robot`: [`DEFAULT_STEPS`], but the
/// Car's 4.5 M, re-derived on its own tuning seeds 0–4 with selection on: of its 25
/// runs 24 satisfy at least 0.95 against 23 at 3 M (Cover seed 1 0.830 → 0.962, its
/// best validated checkpoint at 4 M); README *Car and Drone*.
pub fn default_steps(robot: sim::Robot) -> usize {
    match robot {
        sim::Robot::Car => 4_500_000,
        sim::Robot::Point | sim::Robot::Drone | sim::Robot::Doggo => DEFAULT_STEPS,
    }
}

/// The planner's turn margin ([`JointConfig::turn_margin`]) by default for `robot`:
/// the Car's 0.2 m, about its one-wheel turning radius (0.208 m, its MuJoCo twin's
/// 0.230 m; README *Fidelity of the native Car*), the room it sweeps turning round,
/// re-derived on its own tuning seeds 0–4 with selection and 4.5 M steps (Seq seed 1,
/// which collided turning round at its first waypoint, 0.946 → 0.998; README *Car and
/// Drone*); 0 for the others, whose runs were measured without it (the Doggo's gait
/// turns wider, and a 0.5 m margin was not kept for it; README *Doggo*).
pub fn default_turn_margin(robot: sim::Robot) -> f64 {
    match robot {
        sim::Robot::Car => 0.2,
        sim::Robot::Point | sim::Robot::Drone | sim::Robot::Doggo => 0.0,
    }
}

/// When the executing robot counts a waypoint reached ([`JointConfig::reach`]) by
/// default for `robot`: in the goal ([`Reach::InGoal`]) for the Drone and the Car.
/// The planner's goal margin is at most a third of a goal's radius
/// ([`Task::with_goal_margin`]), so a waypoint may be planned up to two thirds of the
/// radius from the goal's centre and, by the radius alone, counted reached a reach
/// radius beyond that. The Drone's reach (0.6 m, the reference's, capped at 0.33 m by
/// [`Task::waypoint_reach`]) put it up to 0.16 m outside its 0.5 m goals (Drone Signal
/// seed 3: 47 of 500 runs failed the spec so, 0.906; the same checkpoint evaluated in
/// the goal 1.000); the Car's 0.3 m up to 0.13 m outside (Cover seed 1: 9 of 500 runs
/// failed the spec by 2–10 mm so, 0.948; evaluated in the goal 0.966, the other 24
/// tuning runs unchanged; README *Car and Drone*). Point and the Doggo by the radius,
/// the paper's rule: their tables were measured so (the Doggo's both ways: in the
/// goal helped its Seq and not its Loop; README *Reaching inside the goal*).
pub fn default_reach(robot: sim::Robot) -> Reach {
    match robot {
        sim::Robot::Drone | sim::Robot::Car => Reach::InGoal,
        sim::Robot::Point | sim::Robot::Doggo => Reach::Radius,
    }
}

/// Iterations between checkpoints by default.
pub const DEFAULT_SAVE_EVERY: usize = 50;
/// General controllers a run may train by default before it keeps one
/// ([`JointRunSettings::controller_tries`]): this project's, not the paper's (README,
/// *The Car accelerates as its twin does* under *Car and Drone*).
pub const DEFAULT_CONTROLLER_TRIES: usize = 3;
/// The planner's extra clearance by default: one Point radius (README, *Joint training
/// (Algorithm 1) and results*).
pub const DEFAULT_SAFE_MARGIN: f64 = 0.1;

/// A run setting out of range. `name` is the setting as a user gives it: the
/// `schrl train` flag with `_` for `-` (`plan_batch` for `--plan-batch`), which is also
/// the keyword of Python's `schrl.train`.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("{name} {message}")]
pub struct SettingError {
    /// The setting's name.
    pub name: String,
    /// What is wrong with its value.
    pub message: String,
}

impl SettingError {
    fn new(name: &str, message: String) -> Self {
        Self { name: name.into(), message }
    }

    /// A nested config's message, `"<prefix>.<key> <message>"` (as
    /// [`CpgConfig::validate`] and
    /// [`crate::plan::pretrain::PretrainConfig::validate`] word them), under the
    /// name `<name_prefix><key>`.
    fn of_nested(message: &str, prefix: &str, name_prefix: &str) -> Self {
        let rest = message.strip_prefix(prefix).unwrap_or(message);
        let (key, what) = rest.split_once(' ').unwrap_or((rest, ""));
        Self::new(&format!("{name_prefix}{}", key.trim_end_matches(':')), what.into())
    }
}

impl JointRunSettings {
    /// The default settings of a run of `task` from `seed`: the robot's step budget
    /// ([`default_steps`]), the planner's goal discs shrunk by the robot's reach radius,
    /// [`DEFAULT_SAFE_MARGIN`] more clearance, the robot's turn margin, reach rule,
    /// off-track weight, validation interval and selection rule, and each config's own
    /// defaults.
    pub fn for_task(task: &Task, seed: u64) -> Result<Self, RunError> {
        let goal_margin = sim::make_env(task.robot, task.map.clone())?.reach_radius();
        Ok(Self {
            robot: task.robot,
            task_toml: task.toml.clone(),
            task_spec: task.spec.clone(),
            seed,
            steps: default_steps(task.robot),
            target: None,
            controller: None,
            controller_tries: DEFAULT_CONTROLLER_TRIES,
            joint: JointConfig {
                goal_margin,
                safe_margin: DEFAULT_SAFE_MARGIN,
                off_track_weight: crate::control::trainer::TrackDefaults::for_robot(task.robot)
                    .joint_off_track_weight,
                turn_margin: default_turn_margin(task.robot),
                reach: default_reach(task.robot),
                ..JointConfig::default()
            },
            cpg: CpgConfig { seed, ..CpgConfig::default() },
            pretrain: crate::plan::pretrain::PretrainConfig::default(),
            eval_groups: crate::run::evaluate::EVAL_GROUPS,
            save_every: DEFAULT_SAVE_EVERY,
            select_every: crate::run::select::default_every(task.robot),
            select_rule: crate::run::select::default_rule(task.robot),
        })
    }

    /// Sets the planner network; one that cannot be anchored (all but the GRU-ODE)
    /// trains without the trust regions (anchor weight and step limit 0).
    pub fn set_planner(&mut self, kind: crate::plan::planner::PlannerKind) {
        self.cpg.planner = kind;
        if kind != crate::plan::planner::PlannerKind::GruOde {
            self.joint.anchor_weight = 0.0;
            self.joint.plan_step_limit = 0.0;
        }
    }

    /// The task these settings train on.
    pub fn task(&self) -> Result<Task, crate::task::TaskError> {
        let here = std::path::Path::new("settings");
        Task::from_texts(here, &self.task_toml, here, &self.task_spec)
    }

    /// Checks every setting, naming the first one out of range.
    pub fn validate(&self) -> Result<(), SettingError> {
        let bad = SettingError::new;
        if let Some(t) = self.target.filter(|t| !(0.0..=1.0).contains(t)) {
            return Err(bad("target", format!("must be a fraction in [0, 1], got {t}")));
        }
        if self.save_every == 0 {
            return Err(bad("save_every", "must be at least 1".into()));
        }
        if self.controller_tries == 0 {
            return Err(bad("controller_tries", "must be at least 1".into()));
        }
        let j = &self.joint;
        if j.plan_batch == 0 {
            return Err(bad("plan_batch", "must be at least 1".into()));
        }
        if j.runs_per_start == 0 || !j.plan_batch.is_multiple_of(j.runs_per_start) {
            return Err(bad(
                "runs_per_start",
                format!(
                    "must divide the plan batch ({}) into whole groups, got {}",
                    j.plan_batch, j.runs_per_start
                ),
            ));
        }
        for (name, w) in [
            ("control_weight", j.control_weight),
            ("length_weight", j.length_weight),
            ("turn_weight", j.turn_weight),
            ("anchor_weight", j.anchor_weight),
        ] {
            if !(w >= 0.0 && w.is_finite()) {
                return Err(bad(name, format!("must be a non-negative number, got {w}")));
            }
        }
        for (name, value) in [("control_lr", j.control_lr), ("control_target_kl", j.control_target_kl)] {
            if let Some(v) = value
                && !(v > 0.0 && v.is_finite())
            {
                return Err(bad(name, format!("must be a positive number, got {v}")));
            }
        }
        let gru = self.cpg.planner == crate::plan::planner::PlannerKind::GruOde;
        for (name, value) in [("anchor_weight", j.anchor_weight), ("plan_step_limit", j.plan_step_limit)] {
            if value > 0.0 && !gru {
                return Err(bad(
                    name,
                    format!(
                        "must be 0 with the {} planner (only the gru-ode's updates can be bounded)",
                        self.cpg.planner.name()
                    ),
                ));
            }
        }
        for (name, metres) in [
            ("goal_margin", j.goal_margin),
            ("safe_margin", j.safe_margin),
            ("turn_margin", j.turn_margin),
            ("plan_step_limit", j.plan_step_limit),
        ] {
            if !(metres >= 0.0 && metres.is_finite()) {
                return Err(bad(name, format!("must be a non-negative number of metres, got {metres}")));
            }
        }
        j.reward_terms().check().map_err(|(key, m)| bad(key, m))?;
        if let Some(net) = &j.neural_obstacle {
            net.check().map_err(|m| bad("neural_obstacle", m))?;
        }
        self.pretrain.validate().map_err(|e| SettingError::of_nested(&e, "pretrain.", "pretrain_"))?;
        self.cpg.validate().map_err(|e| SettingError::of_nested(&e, "cpg.", ""))
    }
}

/// What one iteration measured.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct JointMetrics {
    /// Iterations done.
    pub iteration: usize,
    /// Environment steps done.
    pub env_steps: usize,
    /// Mean hard robustness of the planned paths.
    pub plan_rho: f64,
    /// Fraction of planned paths satisfying the spec.
    pub plan_satisfaction: f64,
    /// Fraction of runs satisfying the spec on what the robot did.
    pub satisfaction: f64,
    /// Mean steps to reach the last waypoint over the satisfying runs.
    pub steps_to_reach: Option<f64>,
    /// λ after the update.
    pub lambda: f64,
    /// The planner's loss (when it trained).
    pub plan_loss: Option<f64>,
    /// Mean distance (metres) of the planner's sampled waypoints from the warm
    /// start's, when anchored ([`JointConfig::anchor_weight`]).
    #[serde(default)]
    pub plan_drift: Option<f64>,
    /// How far the planner update moved the sampled waypoints (mean metres, same
    /// starts and noise before and after), when the planner trained.
    #[serde(default)]
    pub plan_step: Option<f64>,
    /// The fraction of Adam's step the update kept under
    /// [`JointConfig::plan_step_limit`] (1 when it was within it).
    #[serde(default)]
    pub plan_step_scale: Option<f64>,
    /// Mean low-level reward `r_l` of the runs ([`execution_reward`]).
    #[serde(default)]
    pub low_level_reward: f64,
    /// Mean spec score of the runs ([`crate::task::along::ExecutionSpec::score`]: the
    /// robustness of what the robot did, finite for failed runs too; Fig. 3's y-axis).
    /// `None` in metrics written before it existed.
    #[serde(default)]
    pub score: Option<f64>,
    /// PPO statistics (when the controller updated in this iteration).
    pub control: Option<PpoStats>,
    /// Environment steps per second in this iteration.
    pub steps_per_sec: f64,
}

/// Planner and controller trained together on one task.
pub struct JointTrainer {
    /// The task.
    pub task: Task,
    /// Settings.
    pub config: JointConfig,
    /// The planner and its constrained policy gradient.
    pub plan: PlanTrainer,
    /// The controller's training state (policy, PPO, normaliser, random stream).
    pub control: ControlTrainer,
    envs: Vec<Box<dyn Env>>,
    pub(crate) scaler: RewardScaler,
    pub(crate) buffer: RolloutBuffer,
    pub(crate) rng: ChaCha8Rng,
    /// Iterations done.
    pub iterations: usize,
    /// Environment steps done.
    pub env_steps: usize,
}

/// The controller acting while it learns: actions sampled from the policy, each live
/// run's transitions recorded for PPO, rewards less the off-track penalty and scaled as
/// in controller training. With `learn` off it acts with the policy's mean and records
/// nothing.
struct Learner<'a> {
    control: &'a mut ControlTrainer,
    scaler: &'a mut RewardScaler,
    learn: bool,
    /// [`JointConfig::off_track_weight`] and [`JointConfig::fall_penalty`].
    terms: RewardTerms,
    cache: PolicyCache,
    x: Vec<f32>,
    actions: Vec<f32>,
    log_probs: Vec<f32>,
    values: Vec<f32>,
    runs: Vec<Transitions>,
}

/// One run's transitions.
#[derive(Default)]
struct Transitions {
    obs: Vec<f32>,
    actions: Vec<f32>,
    log_probs: Vec<f32>,
    values: Vec<f32>,
    rewards: Vec<f32>,
}

impl Driver for Learner<'_> {
    fn act(&mut self, raw: &[f64], live: &[bool], actions: &mut [f64]) {
        let c = &mut *self.control;
        let n = live.len();
        let norm = c.config.ppo.norm_obs;
        let od = c.policy.obs_dim();
        if self.learn && norm {
            let rows: Vec<f64> =
                raw.chunks(od).zip(live).filter(|(_, l)| **l).flat_map(|(o, _)| o.iter().copied()).collect();
            c.obs_rms.update(&rows);
        }
        self.x.resize(raw.len(), 0.0);
        normalize_obs(norm, &c.obs_rms, raw, &mut self.x);
        if self.learn {
            let ad = c.policy.act_dim();
            self.actions.resize(n * ad, 0.0);
            self.log_probs.resize(n, 0.0);
            self.values.resize(n, 0.0);
            let cache = &mut self.cache;
            c.policy.act(
                &self.x,
                n,
                &mut c.rng,
                cache,
                &mut self.actions,
                &mut self.log_probs,
                &mut self.values,
            );
        } else {
            let mean = c.policy.mean(&self.x, n, &mut self.cache);
            self.actions.clear();
            self.actions.extend_from_slice(mean);
        }
        actions.iter_mut().zip(&self.actions).for_each(|(d, s)| *d = *s as f64);
    }

    fn after_step(&mut self, live: &[bool], rewards: &mut [f64], step: &StepReports<'_>) {
        if !self.learn {
            return;
        }
        for (i, r) in rewards.iter_mut().enumerate() {
            *r = self.terms.learned(*r, step.fell[i], || step.off_track[i]);
        }
        let ended = step.ended;
        let (od, ad) = (self.control.policy.obs_dim(), self.control.policy.act_dim());
        for (i, run) in self.runs.iter_mut().enumerate().filter(|(i, _)| live[*i]) {
            run.obs.extend_from_slice(&self.x[i * od..(i + 1) * od]);
            run.actions.extend_from_slice(&self.actions[i * ad..(i + 1) * ad]);
            run.log_probs.push(self.log_probs[i]);
            run.values.push(self.values[i]);
        }
        if self.control.config.ppo.norm_reward {
            self.scaler.scale(rewards, ended);
        }
        for (i, run) in self.runs.iter_mut().enumerate().filter(|(i, _)| live[*i]) {
            run.rewards.push(rewards[i] as f32);
        }
    }
}

impl JointTrainer {
    /// Joint training of `task` with a fresh planner (`cpg`) and the given controller
    /// state (fresh or loaded from a general controller's checkpoint).
    pub fn new(
        task: Task,
        config: JointConfig,
        cpg: CpgConfig,
        control: ControlTrainer,
    ) -> Result<Self, RunError> {
        let robot = task.robot;
        if robot != control.config.robot {
            return Err(RunError::Setting {
                key: "robot",
                message: format!(
                    "the task is for the {} but the controller drives the {}",
                    task.robot, control.config.robot
                ),
            });
        }
        if config.plan_batch == 0 {
            return Err(RunError::Setting { key: "plan_batch", message: "must be at least 1".into() });
        }
        if config.runs_per_start == 0 || !config.plan_batch.is_multiple_of(config.runs_per_start) {
            return Err(RunError::Setting {
                key: "runs_per_start",
                message: format!(
                    "must divide plan_batch ({}) into whole groups, got {}",
                    config.plan_batch, config.runs_per_start
                ),
            });
        }
        for (key, w) in [
            ("control_weight", config.control_weight),
            ("length_weight", config.length_weight),
            ("turn_weight", config.turn_weight),
            ("anchor_weight", config.anchor_weight),
        ] {
            if !(w >= 0.0 && w.is_finite()) {
                return Err(RunError::Setting {
                    key,
                    message: format!("must be a non-negative number, got {w}"),
                });
            }
        }
        for (key, value) in
            [("control_lr", config.control_lr), ("control_target_kl", config.control_target_kl)]
        {
            if let Some(v) = value
                && !(v > 0.0 && v.is_finite())
            {
                return Err(RunError::Setting {
                    key,
                    message: format!("must be a positive number, got {v}"),
                });
            }
        }
        let gru = cpg.planner == crate::plan::planner::PlannerKind::GruOde;
        for (key, value) in
            [("anchor_weight", config.anchor_weight), ("plan_step_limit", config.plan_step_limit)]
        {
            if value > 0.0 && !gru {
                return Err(RunError::Setting {
                    key,
                    message: format!(
                        "only the gru-ode planner's joint updates can be bounded; with the {} planner \
                         set it to 0",
                        cpg.planner.name()
                    ),
                });
            }
        }
        for (key, metres) in [
            ("goal_margin", config.goal_margin),
            ("safe_margin", config.safe_margin),
            ("plan_step_limit", config.plan_step_limit),
        ] {
            if !(metres >= 0.0 && metres.is_finite()) {
                return Err(RunError::Setting {
                    key,
                    message: format!("must be a non-negative number of metres, got {metres}"),
                });
            }
        }
        config.reward_terms().check().map_err(|(key, message)| RunError::Setting { key, message })?;
        let task = Task { follow: config.follow, reach: config.reach, ..task };
        let mut control = control;
        if config.control_target_kl.is_some() {
            control.learner.config.target_kl = config.control_target_kl;
        }
        let planned = config.planned_task(&task, true)?;
        let mut plan = PlanTrainer::new(planned, cpg)?.with_control_reward(config.path_terms());
        plan.limit_joint_step(config.plan_step_limit)?;
        let envs = (0..config.plan_batch)
            .map(|_| task_env(robot, &task, control.config.observe_track))
            .collect::<Result<Vec<_>, _>>()?;
        if let Some(env) = envs.first() {
            config
                .follow
                .check(env.reach_radius())
                .map_err(|message| RunError::Setting { key: "follow", message })?;
        }
        let mut scaler = RewardScaler::new(config.plan_batch, control.config.ppo.gamma);
        scaler.stats = control.reward_scaler.stats.clone();
        let buffer = RolloutBuffer::new(1, control.policy.obs_dim(), control.policy.act_dim());
        Ok(Self {
            rng: ChaCha8Rng::seed_from_u64(cpg.seed ^ 0x5EED_1017),
            task,
            config,
            plan,
            control,
            envs,
            scaler,
            buffer,
            iterations: 0,
            env_steps: 0,
        })
    }

    /// One iteration: plan, execute, update.
    pub fn iterate(&mut self) -> Result<JointMetrics, RunError> {
        let start = Instant::now();
        let per_start = self.config.runs_per_start;
        let batch = self.plan.sample_grouped(self.config.plan_batch / per_start, per_start)?;
        let paths = paths_of(&batch.paths)?;
        let hard = self.plan.hard_robustness(&batch.paths)?;
        let learn = !self.config.freeze_controller;
        // Judged on the task's own goals, not the planner's shrunk ones.
        let spec = self.task.execution_spec();
        let runs = self.execute(&spec, &paths, learn)?;
        let steps: usize = runs.iter().map(|r| r.steps).sum();
        self.env_steps += steps;
        let rl: Vec<f64> = runs.iter().map(|r| execution_reward(r, &self.task)).collect();
        let (mut plan_loss, mut plan_drift, mut plan_step) = (None, None, None);
        if !self.config.freeze_planner {
            let w = self.config.control_weight;
            let adv: Vec<f64> = leave_one_out(&rl, per_start).iter().map(|a| w * a).collect();
            let stats = self.plan.update_joint(&batch, &adv)?;
            (plan_loss, plan_drift, plan_step) = (Some(stats.loss), stats.drift, stats.step);
        }
        let mut control = None;
        let ppo = &self.control.config.ppo;
        if learn && self.buffer.len() >= ppo.rollout {
            self.buffer.last_values = vec![0.0];
            let lr = self.config.control_lr.unwrap_or(ppo.lr);
            let stats = self.control.learner.update(
                &mut self.control.policy,
                &self.buffer,
                lr,
                &mut self.control.rng,
            );
            self.buffer.clear();
            control = Some(stats);
        }
        self.iterations += 1;
        let sat: Vec<&Execution> = runs.iter().filter(|r| r.satisfied()).collect();
        let n = runs.len() as f64;
        Ok(JointMetrics {
            iteration: self.iterations,
            env_steps: self.env_steps,
            plan_rho: hard.iter().sum::<f64>() / n,
            plan_satisfaction: hard.iter().filter(|r| **r > 0.0).count() as f64 / n,
            satisfaction: sat.len() as f64 / n,
            steps_to_reach: (!sat.is_empty())
                .then(|| sat.iter().map(|r| reach_steps(r, &self.task)).sum::<f64>() / sat.len() as f64),
            lambda: self.plan.lagrangian().lambda,
            plan_loss,
            plan_drift,
            plan_step: plan_step.map(|s| s.0),
            plan_step_scale: plan_step.map(|s| s.1),
            low_level_reward: rl.iter().sum::<f64>() / n,
            score: Some(
                runs.iter().map(|r| spec.score(&r.executed, &r.trajectory, &r.reached_at)).sum::<f64>() / n,
            ),
            control,
            steps_per_sec: steps as f64 / start.elapsed().as_secs_f64().max(1e-9),
        })
    }

    /// Executes `paths` in lockstep, one environment each; with `learn`, samples
    /// actions and records the transitions for PPO, otherwise uses mean actions.
    fn execute(
        &mut self,
        spec: &ExecutionSpec,
        paths: &[Vec<Vec<f64>>],
        learn: bool,
    ) -> Result<Vec<Execution>, RunError> {
        let od = self.control.policy.obs_dim();
        let n = paths.len();
        let mut raw = vec![0.0; n * od];
        let mut dispatchers = Vec::with_capacity(n);
        for (i, (env, path)) in self.envs.iter_mut().zip(paths).enumerate() {
            let seed: u64 = self.rng.random();
            let obs = &mut raw[i * od..(i + 1) * od];
            dispatchers.push(start_task_run(env.as_mut(), seed, path, &self.task, obs)?);
        }
        let mut learner = Learner {
            control: &mut self.control,
            scaler: &mut self.scaler,
            learn,
            terms: self.config.reward_terms(),
            cache: PolicyCache::default(),
            x: Vec::new(),
            actions: Vec::new(),
            log_probs: Vec::new(),
            values: Vec::new(),
            runs: (0..n).map(|_| Transitions::default()).collect(),
        };
        let episodes = drive(&mut self.envs[..n], dispatchers, self.task.follow, &mut raw, &mut learner)?;
        let Learner { runs: transitions, mut cache, .. } = learner;
        let c = &self.control;
        let gamma = c.config.ppo.gamma as f32;
        let mut out = Vec::with_capacity(n);
        for (i, (run, t)) in episodes.into_iter().zip(transitions).enumerate() {
            let outcome = run.dispatcher.outcome().unwrap_or(Outcome::TimedOut);
            if learn && !t.values.is_empty() {
                let mut rewards = t.rewards;
                if outcome == Outcome::TimedOut {
                    // Bootstrap the cut: r + γ V(s_final).
                    let mut xf = vec![0.0f32; od];
                    normalize_obs(c.config.ppo.norm_obs, &c.obs_rms, &raw[i * od..(i + 1) * od], &mut xf);
                    let v = c.policy.value(&xf, 1, &mut cache)[0];
                    *rewards.last_mut().expect("non-empty run") += gamma * v;
                }
                let len = t.values.len();
                self.buffer.obs.extend(t.obs);
                self.buffer.actions.extend(t.actions);
                self.buffer.log_probs.extend(t.log_probs);
                self.buffer.values.extend(t.values);
                self.buffer.rewards.extend(rewards);
                self.buffer.ends.extend((0..len).map(|k| k + 1 == len));
            }
            out.push(run.dispatcher.into_execution(
                spec,
                paths[i].clone(),
                run.trajectory,
                run.headings,
                run.control_return,
            ));
        }
        Ok(out)
    }
}

/// A `[n, T+1, dim]` tensor as nested vectors.
pub fn paths_of(t: &Tensor) -> candle_core::Result<Vec<Vec<Vec<f64>>>> {
    t.to_dtype(DType::F64)?.to_vec3()
}

/// The low-level reward `r_l` of one executed plan, in units of the task's step limit:
/// `−steps / limit` for a run that satisfied the task (in `[−1, 0]`: faster is
/// better), and `−2 + reached / waypoints` for one that did not (in `[−2, −1)`: below
/// every success, better the further it got). Not the controller's return, whose
/// distance-progress term restarts at every waypoint and so grows with the plan's
/// length: the planner would learn to add detours.
pub fn execution_reward(run: &Execution, task: &Task) -> f64 {
    if run.satisfied() {
        -(run.steps as f64) / task.step_limit.max(1) as f64
    } else {
        -2.0 + run.reached_at.len() as f64 / task.steps.max(1) as f64
    }
}

/// Advantages against leave-one-out baselines: `r_i` minus the mean of the other
/// rewards in its group of `group` consecutive entries (with `group` 1, of the rest of
/// the batch). Each baseline is independent of its run, so the estimate stays
/// unbiased, and runs from one start share their start's difficulty.
pub fn leave_one_out(r: &[f64], group: usize) -> Vec<f64> {
    let group = if group <= 1 { r.len() } else { group };
    r.chunks(group)
        .flat_map(|g| {
            let sum: f64 = g.iter().sum();
            let others = (g.len() - 1).max(1) as f64;
            g.iter().map(move |x| if g.len() > 1 { x - (sum - x) / others } else { 0.0 })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::control::ControlConfig;

    /// The off-track weight comes off the reward the joint phase's controller learns
    /// from in proportion to the distance, and the fall penalty on the step its robot
    /// falls and on no other.
    #[test]
    fn learner_takes_the_off_track_weight_and_the_fall_penalty_from_the_learned_reward() {
        let mut cfg = ControlConfig::for_robot(Robot::Point);
        cfg.ppo.norm_reward = false;
        let mut control = ControlTrainer::new(cfg).unwrap();
        let (od, ad) = (control.policy.obs_dim(), control.policy.act_dim());
        let mut scaler = RewardScaler::new(3, 0.99);
        let mut learner = Learner {
            control: &mut control,
            scaler: &mut scaler,
            learn: true,
            terms: RewardTerms { fall_penalty: 7.0, off_track_weight: 0.5 },
            cache: PolicyCache::default(),
            x: Vec::new(),
            actions: Vec::new(),
            log_probs: Vec::new(),
            values: Vec::new(),
            runs: (0..3).map(|_| Transitions::default()).collect(),
        };
        let live = [true; 3];
        learner.act(&vec![0.1; 3 * od], &live, &mut vec![0.0; 3 * ad]);
        let mut rewards = [1.0; 3];
        let step = StepReports {
            off_track: &[0.0, 0.2, 0.0],
            ended: &[false, false, true],
            fell: &[false, false, true],
        };
        learner.after_step(&live, &mut rewards, &step);
        let learned: Vec<f32> = learner.runs.iter().map(|r| r.rewards[0]).collect();
        assert_eq!(learned, [1.0, 0.9, -6.0]);
    }
}
