//! Joint hierarchical training (paper App. A, Algorithm 1) and task evaluation.
//!
//! Each iteration samples starts, plans a batch of paths with the GRU-ODE planner,
//! and rolls the controller out through each path's waypoints (see [`crate::run::execute`]).
//! The low-level reward of a path, `r_l`, is the controller's return on it (distance
//! progress plus reach bonuses) times [`JointConfig::control_weight`]; the planner is
//! updated with the constrained policy gradient on `r_h = ρ + r_l`, and the
//! controller with PPO on the transitions of the same runs. Either side can be
//! frozen (the paper's Fig. 4 ablations). The controller is usually warm-started
//! from a general controller trained on random goals (as the authors did).

use std::time::Instant;

use candle_core::{DType, Tensor};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};
use sim::{Env, Robot, Step};

use crate::control::normalize::RewardScaler;
use crate::control::policy::PolicyCache;
use crate::control::ppo::{RolloutBuffer, UpdateStats as PpoStats};
use crate::control::{ControlTrainer, Controller};
use crate::plan::cpg::{CpgConfig, PlanTrainer};
use crate::plan::planner::PathPlanner;
use crate::run::execute::{Dispatch, Execution, Outcome, start_run};
use crate::task::Task;

/// Joint-training settings.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct JointConfig {
    /// Paths planned and executed per iteration (reference: 8).
    pub plan_batch: usize,
    /// Weight of the controller's return in `r_h = ρ + weight · return` (0.05: a
    /// path whose waypoints are all reached earns about one unit per waypoint from
    /// the reach bonus of 20, comparable to robustness in metres).
    pub control_weight: f64,
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
}

impl Default for JointConfig {
    fn default() -> Self {
        Self {
            plan_batch: 8,
            control_weight: 0.05,
            freeze_planner: false,
            freeze_controller: false,
            goal_margin: 0.0,
            safe_margin: 0.0,
        }
    }
}

/// The evaluation protocol's defaults (paper §4.4: 5 groups of 100 runs); the seed of
/// starts and plans is this project's fixed choice, so evaluations compare.
pub const EVAL_GROUPS: usize = 5;
/// Runs per evaluation group.
pub const EVAL_PER_GROUP: usize = 100;
/// Seed of evaluation starts and plans.
pub const EVAL_SEED: u64 = 2024;

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
    /// Stop early once this fraction of the last 20 iterations' runs satisfy the task (0.97).
    pub target: f64,
    /// The controller run warm-starting the controller; `None`: a general controller
    /// trained into the run's `general/`.
    pub controller: Option<std::path::PathBuf>,
    /// Joint-training settings.
    pub joint: JointConfig,
    /// The planner's training hyper-parameters.
    pub cpg: CpgConfig,
    /// Planner pre-training.
    pub pretrain: crate::plan::pretrain::PretrainConfig,
    /// Evaluation groups of [`EVAL_PER_GROUP`] runs after training (0: none).
    pub eval_groups: usize,
    /// Iterations between checkpoints (50).
    pub save_every: usize,
}

impl JointRunSettings {
    /// The task these settings train on.
    pub fn task(&self) -> Result<Task, crate::task::TaskError> {
        let here = std::path::Path::new("settings");
        Task::from_texts(here, &self.task_toml, here, &self.task_spec)
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

/// A run in progress, with its transitions when the controller learns.
struct Run {
    dispatcher: crate::run::execute::WaypointDispatcher,
    trajectory: Vec<Vec<f64>>,
    control_return: f64,
    obs: Vec<f32>,
    actions: Vec<f32>,
    log_probs: Vec<f32>,
    values: Vec<f32>,
    rewards: Vec<f32>,
}

impl JointTrainer {
    /// Joint training of `task` with a fresh planner (`cpg`) and the given controller
    /// state (fresh or loaded from a general controller's checkpoint).
    pub fn new(
        task: Task,
        config: JointConfig,
        cpg: CpgConfig,
        control: ControlTrainer,
    ) -> Result<Self, crate::control::ControlError> {
        let robot: Robot = task.robot.parse()?;
        if robot != control.robot {
            return Err(crate::control::ControlError::Config(format!(
                "the task is for the {} but the controller drives the {}",
                task.robot, control.robot
            )));
        }
        if config.plan_batch == 0 {
            return Err(crate::control::ControlError::Config("plan_batch must be at least 1".into()));
        }
        for (key, metres) in [("goal_margin", config.goal_margin), ("safe_margin", config.safe_margin)] {
            if !(metres >= 0.0 && metres.is_finite()) {
                return Err(crate::control::ControlError::Config(format!(
                    "{key} must be a non-negative number of metres, got {metres}"
                )));
            }
        }
        let planned = task.with_goal_margin(config.goal_margin).with_safe_margin(config.safe_margin);
        let plan = PlanTrainer::new(planned, cpg)
            .map_err(|e| crate::control::ControlError::Config(format!("planner: {e}")))?;
        let envs = (0..config.plan_batch)
            .map(|_| sim::make_env(robot, task.map.clone()))
            .collect::<Result<Vec<_>, _>>()?;
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
    pub fn iterate(&mut self) -> Result<JointMetrics, crate::control::ControlError> {
        let start = Instant::now();
        let cerr = |e: candle_core::Error| crate::control::ControlError::Config(format!("planner: {e}"));
        let batch = self.plan.sample(self.config.plan_batch).map_err(cerr)?;
        let paths = paths_of(&batch.paths).map_err(cerr)?;
        let hard = self.plan.hard_robustness(&batch.paths).map_err(cerr)?;
        let learn = !self.config.freeze_controller;
        let runs = self.execute(&paths, learn)?;
        let steps: usize = runs.iter().map(|r| r.steps).sum();
        self.env_steps += steps;
        let rl: Vec<f64> = runs.iter().map(|r| self.config.control_weight * r.control_return).collect();
        let mut plan_loss = None;
        if !self.config.freeze_planner {
            plan_loss = Some(self.plan.update_on(&batch, &rl).map_err(cerr)?.loss);
        }
        let mut control = None;
        let ppo = &self.control.config.ppo;
        if learn && self.buffer.len() >= ppo.rollout {
            self.buffer.last_values = vec![0.0];
            let lr = ppo.lr;
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
            control,
            steps_per_sec: steps as f64 / start.elapsed().as_secs_f64().max(1e-9),
        })
    }

    /// Executes `paths` in lockstep, one environment each; with `learn`, samples
    /// actions and records the transitions for PPO, otherwise uses mean actions.
    fn execute(
        &mut self,
        paths: &[Vec<Vec<f64>>],
        learn: bool,
    ) -> Result<Vec<Execution>, crate::control::ControlError> {
        // Judged on the task's own goals, not the planner's shrunk ones.
        let spec = self.task.execution_spec();
        let c = &mut self.control;
        let (od, ad) = (c.policy.obs_dim(), c.policy.act_dim());
        let n = paths.len();
        let mut raw = vec![0.0; n * od];
        let mut runs = Vec::with_capacity(n);
        for (i, (env, path)) in self.envs.iter_mut().zip(paths).enumerate() {
            let seed: u64 = self.rng.random();
            let d =
                start_run(env.as_mut(), seed, path, self.task.step_limit, &mut raw[i * od..(i + 1) * od])?;
            runs.push(Run {
                dispatcher: d,
                trajectory: vec![path[0].clone()],
                control_return: 0.0,
                obs: Vec::new(),
                actions: Vec::new(),
                log_probs: Vec::new(),
                values: Vec::new(),
                rewards: Vec::new(),
            });
        }
        let mut cache = PolicyCache::default();
        let mut x = vec![0.0f32; n * od];
        let mut actions = vec![0.0f32; n * ad];
        let mut logp = vec![0.0f32; n];
        let mut values = vec![0.0f32; n];
        let mut rewards = vec![0.0f64; n];
        let mut ended = vec![false; n];
        let mut a = vec![0.0f64; ad];
        let mut active: Vec<bool> = runs.iter().map(|r| r.dispatcher.outcome().is_none()).collect();
        let norm = c.config.ppo.norm_obs;
        while active.iter().any(|a| *a) {
            if learn && norm {
                let live: Vec<f64> = raw
                    .chunks(od)
                    .zip(&active)
                    .filter(|(_, a)| **a)
                    .flat_map(|(o, _)| o.iter().copied())
                    .collect();
                c.obs_rms.update(&live);
            }
            normalize(norm, &c.obs_rms, &raw, &mut x);
            if learn {
                c.policy.act(&x, n, &mut c.rng, &mut cache, &mut actions, &mut logp, &mut values);
            } else {
                actions.copy_from_slice(c.policy.mean(&x, n, &mut cache));
            }
            for (i, env) in self.envs.iter_mut().enumerate() {
                ended[i] = false;
                rewards[i] = 0.0;
                if !active[i] {
                    continue;
                }
                a.iter_mut().zip(&actions[i * ad..(i + 1) * ad]).for_each(|(d, s)| *d = *s as f64);
                let obs = &mut raw[i * od..(i + 1) * od];
                let step: Step = env.step_into(&a, obs)?;
                let run = &mut runs[i];
                run.trajectory.push(env.position().to_vec());
                run.control_return += step.reward;
                rewards[i] = step.reward;
                if learn {
                    run.obs.extend_from_slice(&x[i * od..(i + 1) * od]);
                    run.actions.extend_from_slice(&actions[i * ad..(i + 1) * ad]);
                    run.log_probs.push(logp[i]);
                    run.values.push(values[i]);
                }
                match run.dispatcher.after_step(&step, env.position()) {
                    Dispatch::Continue => {}
                    Dispatch::NewGoal(g) => {
                        env.set_goal(&g)?;
                        env.observe(obs);
                    }
                    Dispatch::Done(_) => {
                        active[i] = false;
                        ended[i] = true;
                    }
                }
            }
            if learn {
                if c.config.ppo.norm_reward {
                    self.scaler.scale(&mut rewards, &ended);
                }
                for (i, run) in runs.iter_mut().enumerate() {
                    if run.rewards.len() < run.values.len() {
                        run.rewards.push(rewards[i] as f32);
                    }
                }
            }
        }
        let gamma = c.config.ppo.gamma as f32;
        let mut out = Vec::with_capacity(n);
        for (i, run) in runs.into_iter().enumerate() {
            let outcome = run.dispatcher.outcome().unwrap_or(Outcome::TimedOut);
            if learn && !run.values.is_empty() {
                let mut rewards = run.rewards;
                if outcome == Outcome::TimedOut {
                    // Bootstrap the cut: r + γ V(s_final).
                    let mut xf = vec![0.0f32; od];
                    normalize(norm, &c.obs_rms, &raw[i * od..(i + 1) * od], &mut xf);
                    let v = c.policy.value(&xf, 1, &mut cache)[0];
                    *rewards.last_mut().expect("non-empty run") += gamma * v;
                }
                let len = run.values.len();
                self.buffer.obs.extend(run.obs);
                self.buffer.actions.extend(run.actions);
                self.buffer.log_probs.extend(run.log_probs);
                self.buffer.values.extend(run.values);
                self.buffer.rewards.extend(rewards);
                self.buffer.ends.extend((0..len).map(|k| k + 1 == len));
            }
            out.push(run.dispatcher.into_execution(
                &spec,
                self.task.steps,
                paths[i].clone(),
                run.trajectory,
                run.control_return,
            ));
        }
        Ok(out)
    }
}

fn normalize(on: bool, rms: &crate::control::normalize::RunningMeanStd, raw: &[f64], out: &mut [f32]) {
    if on {
        rms.normalize_into(raw, out);
    } else {
        out.iter_mut().zip(raw).for_each(|(o, r)| *o = *r as f32);
    }
}

/// Steps to reach of a satisfying run under `task`'s count.
fn reach_steps(run: &Execution, task: &Task) -> f64 {
    run.steps_to_reach(task.steps_to_reach_at).unwrap_or(run.steps) as f64
}

/// A `[n, T+1, dim]` tensor as nested vectors.
pub fn paths_of(t: &Tensor) -> candle_core::Result<Vec<Vec<Vec<f64>>>> {
    t.to_dtype(DType::F64)?.to_vec3()
}

/// Satisfaction and steps to reach over groups of runs (the paper's protocol: 5
/// groups of 100), mean ± sample std over the groups.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TaskEval {
    /// Satisfaction of each group.
    pub satisfaction: Vec<f64>,
    /// Mean steps to reach of each group (over its satisfying runs).
    pub steps_to_reach: Vec<f64>,
    /// Runs ended by a collision, over all groups.
    pub collisions: usize,
    /// Runs ended by a fall (legged robots), over all groups.
    #[serde(default)]
    pub falls: usize,
    /// Runs that timed out.
    pub timeouts: usize,
    /// A few runs, for pictures.
    pub examples: Vec<Execution>,
}

/// Mean and sample standard deviation.
pub fn mean_std(xs: &[f64]) -> (f64, f64) {
    let n = xs.len() as f64;
    if xs.is_empty() {
        return (f64::NAN, f64::NAN);
    }
    let m = xs.iter().sum::<f64>() / n;
    let v = if xs.len() > 1 { xs.iter().map(|x| (x - m) * (x - m)).sum::<f64>() / (n - 1.0) } else { 0.0 };
    (m, v.sqrt())
}

/// Which plan a deployed planner hands the controller.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum PlanChoice {
    /// The Gaussian policy's mean path: the deployed plan (default). Sampling noise
    /// (std ≥ 0.1 m per waypoint) exists for exploration while training; measured on
    /// Point Seq, 62 % of sampled paths satisfied the spec and 100 % of mean paths.
    #[default]
    Mean,
    /// A path sampled from the policy, as during training.
    Sampled,
}

/// Evaluates a planner and controller on `task`: `groups × per_group` runs from
/// random starts, each executing the plan `choice` picks with the controller's mean
/// actions.
pub fn evaluate_task(
    task: &Task,
    planner: &PathPlanner,
    controller: &Controller,
    (groups, per_group): (usize, usize),
    choice: PlanChoice,
    seed: u64,
) -> Result<TaskEval, crate::control::ControlError> {
    let cerr = |e: candle_core::Error| crate::control::ControlError::Config(format!("planner: {e}"));
    let spec = task.execution_spec();
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut eval = TaskEval {
        satisfaction: vec![],
        steps_to_reach: vec![],
        collisions: 0,
        falls: 0,
        timeouts: 0,
        examples: vec![],
    };
    let mut cache = PolicyCache::default();
    for _ in 0..groups {
        let g0 = task.sample_starts(&mut rng, per_group).map_err(cerr)?;
        let noise = task.sample_noise(&mut rng, per_group).map_err(cerr)?;
        let planned = match choice {
            PlanChoice::Mean => planner.mean_path(&g0, task.steps),
            PlanChoice::Sampled => planner.sample(&g0, &noise).map(|b| b.paths),
        };
        let paths = paths_of(&planned.map_err(cerr)?).map_err(cerr)?;
        let (mut sat, mut steps) = (0usize, 0.0f64);
        for path in &paths {
            let mut env = sim::make_env(controller.robot, task.map.clone())?;
            let od = env.observation_space().dim();
            let mut obs = vec![0.0; od];
            let mut d = start_run(env.as_mut(), rng.random(), path, task.step_limit, &mut obs)?;
            let mut trajectory = vec![path[0].clone()];
            let mut action = vec![0.0; env.action_space().dim()];
            let mut ret = 0.0;
            while d.outcome().is_none() {
                controller.act(&obs, 1, &mut cache, &mut action);
                let s = env.step_into(&action, &mut obs)?;
                ret += s.reward;
                trajectory.push(env.position().to_vec());
                if let Dispatch::NewGoal(g) = d.after_step(&s, env.position()) {
                    env.set_goal(&g)?;
                    env.observe(&mut obs);
                }
            }
            let run = d.into_execution(&spec, task.steps, path.clone(), trajectory, ret);
            match run.outcome {
                Outcome::Collided => eval.collisions += 1,
                Outcome::Fell => eval.falls += 1,
                Outcome::TimedOut => eval.timeouts += 1,
                Outcome::Completed => {}
            }
            if run.satisfied() {
                sat += 1;
                steps += reach_steps(&run, task);
            }
            if eval.examples.len() < 6 {
                eval.examples.push(run);
            }
        }
        eval.satisfaction.push(sat as f64 / per_group as f64);
        if sat > 0 {
            eval.steps_to_reach.push(steps / sat as f64);
        }
    }
    Ok(eval)
}
