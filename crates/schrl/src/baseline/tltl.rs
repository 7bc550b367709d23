//! TLTL (Li, Vasile & Belta 2017): one flat PPO policy learns a task from the spec's
//! robustness alone — no planner, no waypoints, no goal-conditioned controller (the
//! paper's non-hierarchical baseline, §4.2).
//!
//! * *Observation*: the robot's own observation with its goal held at the map's
//!   origin (so the goal entries read the origin in the body frame), then the robot's
//!   position, then the clock `t / H`. The clock makes every task here Markov: the
//!   specs read waypoint indices, and Signal's counter is a function of the index.
//! * *Waypoint indices → environment steps*: an episode lasts the task's step limit
//!   `H`; the spec's waypoint `i` (of `T`) is the robot's position after step
//!   `⌊i·H/T⌋`, and regions to avoid are checked on every step in between, exactly as
//!   for executed plans ([`ExecutionSpec`]).
//! * *Reward*: terminal. Every step pays 0 but the last (step `H`, or a collision or a
//!   fall), which pays the spec score of the episode ([`ExecutionSpec::score`]: after
//!   a collision the robot is taken to stay where it stopped, where `safe` is
//!   negative). Li et al. reward a finite episode with its trajectory's robustness;
//!   robustness increments of a prefix are not defined for the future-time specs
//!   here (a prefix has no value for `F[1,8] g` before waypoint 8).
//! * *PPO*: the controller's ([`PpoConfig::reference`]): γ = 0.99, so a score paid
//!   at step 1000 reaches the first step discounted by 0.99¹⁰⁰⁰ ≈ 4·10⁻⁵, which is
//!   part of why the paper finds flat policies fail.
//!
//! A run satisfies the task when it neither collides nor falls and its score is
//! positive. Its steps to reach: the step of waypoint `steps_to_reach_at` for tasks that
//! set it (Loop), else of the first waypoint index from which the spec holds with the
//! robot staying there.

use std::time::Instant;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};
use sim::{Env, Robot};

use crate::control::normalize::{RewardScaler, RunningMeanStd};
use crate::control::policy::{ActorCritic, PolicyCache};
use crate::control::ppo::{PpoConfig, PpoLearner, RolloutBuffer, UpdateStats};
use crate::control::trainer::normalize_obs;
use crate::control::{ControlError, Controller};
use crate::run::RunError;
use crate::run::evaluate::{GroupTally, TaskEval};
use crate::run::execute::{Execution, Outcome, task_env};
use crate::task::Task;
use crate::task::along::ExecutionSpec;

/// Every setting of a TLTL run: what its run directory's manifest holds.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TltlSettings {
    /// The robot.
    pub robot: Robot,
    /// The task's TOML text.
    pub task_toml: String,
    /// The task's spec text.
    pub task_spec: String,
    /// Seed of weights, starts and action noise.
    pub seed: u64,
    /// Environment steps to train for.
    pub steps: usize,
    /// PPO hyper-parameters (the controller's reference preset).
    pub ppo: PpoConfig,
    /// Evaluation groups of [`crate::run::evaluate::EVAL_PER_GROUP`] runs after training (0: none).
    pub eval_groups: usize,
    /// PPO updates between checkpoints.
    pub save_every: usize,
}

impl TltlSettings {
    /// The task these settings train on.
    pub fn task(&self) -> Result<Task, crate::task::TaskError> {
        let here = std::path::Path::new("settings");
        Task::from_texts(here, &self.task_toml, here, &self.task_spec)
    }
}

/// What one PPO update measured (one line of `metrics.jsonl`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TltlMetrics {
    /// Updates done.
    pub update: usize,
    /// Environment steps done.
    pub env_steps: usize,
    /// Episodes that ended in this rollout.
    pub episodes: usize,
    /// Mean spec score of those episodes.
    pub score: Option<f64>,
    /// Fraction of them that satisfied the task.
    pub satisfaction: Option<f64>,
    /// Learning rate used.
    pub lr: f64,
    /// PPO's loss terms and diagnostics.
    pub update_stats: UpdateStats,
    /// Environment steps per second over this rollout and update.
    pub steps_per_sec: f64,
}

/// The flat observation's length for a robot whose own observation has `robot_obs`
/// numbers and whose position `dim`.
pub fn flat_obs_dim(robot_obs: usize, dim: usize) -> usize {
    robot_obs + dim + 1
}

/// Writes `env`'s flat observation (module docs) into `out`, with `horizon` the
/// episode length.
fn observe(env: &dyn Env, horizon: usize, out: &mut [f64]) {
    let od = env.observation_space().dim();
    env.observe(&mut out[..od]);
    let p = env.position();
    out[od..od + p.len()].copy_from_slice(p);
    out[od + p.len()] = env.steps() as f64 / horizon.max(1) as f64;
}

/// Puts `env` at a fresh start of `task`, its goal at the origin, and writes its flat
/// observation. Returns the start.
fn begin(
    env: &mut dyn Env,
    task: &Task,
    rng: &mut ChaCha8Rng,
    out: &mut [f64],
) -> Result<Vec<f64>, RunError> {
    let start = task.sample_start(rng);
    let od = env.observation_space().dim();
    env.set_max_steps(task.step_limit);
    env.reset_into(rng.random(), Some(&start), &mut out[..od])?;
    env.set_goal(&vec![0.0; start.len()])?;
    observe(env, task.step_limit, out);
    Ok(start)
}

/// The environment steps at which the spec reads waypoints `1..=T` of an episode of
/// `task` (module docs).
pub fn sample_steps(task: &Task) -> Vec<usize> {
    let (t, h) = (task.steps.max(1), task.step_limit);
    (1..=task.steps).map(|i| i * h / t).collect()
}

/// The waypoints the spec reads from `trajectory` (every position, the start first):
/// the start, then the positions at [`sample_steps`] the episode lasted to.
fn sampled(trajectory: &[Vec<f64>], at: &[usize]) -> (Vec<Vec<f64>>, Vec<usize>) {
    let at: Vec<usize> = at.iter().copied().filter(|k| *k < trajectory.len()).collect();
    let path = std::iter::once(0).chain(at.iter().copied()).map(|k| trajectory[k].clone()).collect();
    (path, at)
}

/// The spec score of a flat episode's `trajectory` (module docs).
pub fn episode_score(spec: &ExecutionSpec, at: &[usize], trajectory: &[Vec<f64>]) -> f64 {
    let (path, at) = sampled(trajectory, at);
    spec.score(&path, trajectory, &at)
}

/// Finished episodes' scores and verdicts, for the metrics.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
struct Finished {
    scores: Vec<f64>,
    satisfied: usize,
}

/// A TLTL training run; [`crate::store::tltl`] saves and restores all of it, so a
/// resumed run continues exactly.
pub struct TltlTrainer {
    /// The task.
    pub task: Task,
    /// The run's settings.
    pub settings: TltlSettings,
    /// Actor and critic on the flat observation.
    pub policy: ActorCritic,
    /// PPO's optimiser side.
    pub learner: PpoLearner,
    /// Observation statistics.
    pub obs_rms: RunningMeanStd,
    /// Reward scaling.
    pub reward_scaler: RewardScaler,
    /// Starts, reset seeds, action noise and shuffling.
    pub rng: ChaCha8Rng,
    /// The environments, one episode each at a time.
    pub envs: Vec<Box<dyn Env>>,
    /// Each environment's episode so far: every position, the start first.
    pub trajectories: Vec<Vec<Vec<f64>>>,
    /// Their current flat observations.
    pub raw_obs: Vec<f64>,
    /// Environment steps done.
    pub steps: usize,
    /// Updates done.
    pub updates: usize,
    spec: ExecutionSpec,
    at: Vec<usize>,
    buffer: RolloutBuffer,
    cache: PolicyCache,
}

impl TltlTrainer {
    /// A fresh run.
    pub fn new(settings: TltlSettings) -> Result<Self, RunError> {
        let task = settings.task().map_err(|e| RunError::Setting { key: "task", message: e.to_string() })?;
        if task.robot != settings.robot {
            return Err(RunError::Setting {
                key: "robot",
                message: format!("the task is for the {}, not the {}", task.robot, settings.robot),
            });
        }
        settings.ppo.validate().map_err(|e| RunError::Control(ControlError::Config(e)))?;
        if settings.save_every == 0 {
            return Err(RunError::Setting { key: "save_every", message: "must be at least 1".into() });
        }
        let mut rng = ChaCha8Rng::seed_from_u64(settings.seed);
        let n = settings.ppo.num_envs;
        let mut envs = (0..n).map(|_| task_env(task.robot, &task)).collect::<Result<Vec<_>, _>>()?;
        let od = flat_obs_dim(envs[0].observation_space().dim(), task.map.dim());
        let ad = envs[0].action_space().dim();
        let policy = ActorCritic::new(od, ad, &settings.ppo.hidden, &mut rng);
        let learner = PpoLearner::new(settings.ppo.clone(), &policy);
        let mut raw_obs = vec![0.0; n * od];
        let mut trajectories = Vec::with_capacity(n);
        for (env, o) in envs.iter_mut().zip(raw_obs.chunks_mut(od)) {
            trajectories.push(vec![begin(env.as_mut(), &task, &mut rng, o)?]);
        }
        Ok(Self {
            spec: task.execution_spec(),
            at: sample_steps(&task),
            obs_rms: RunningMeanStd::new(od),
            reward_scaler: RewardScaler::new(n, settings.ppo.gamma),
            buffer: RolloutBuffer::new(n, od, ad),
            cache: PolicyCache::default(),
            task,
            policy,
            learner,
            rng,
            envs,
            trajectories,
            raw_obs,
            steps: 0,
            updates: 0,
            settings,
        })
    }

    /// Updates in the whole run.
    pub fn total_updates(&self) -> usize {
        self.settings.steps.div_ceil(self.settings.ppo.rollout).max(1)
    }

    /// `true` once the step budget is spent.
    pub fn finished(&self) -> bool {
        self.updates >= self.total_updates()
    }

    /// The deployable policy (mean actions on the flat observation).
    pub fn controller(&self) -> Controller {
        Controller {
            robot: self.task.robot,
            policy: self.policy.clone(),
            obs_rms: self.obs_rms.clone(),
            normalize_obs: self.settings.ppo.norm_obs,
        }
    }

    /// Collects one rollout and runs one PPO update.
    pub fn train_update(&mut self) -> Result<TltlMetrics, RunError> {
        let start = Instant::now();
        let cfg = self.settings.ppo.clone();
        let (n, od, ad) = (cfg.num_envs, self.policy.obs_dim(), self.policy.act_dim());
        let horizon = self.task.step_limit;
        self.buffer.clear();
        let mut obs = vec![0.0f32; n * od];
        let mut actions = vec![0.0f32; n * ad];
        let mut actions64 = vec![0.0f64; ad];
        let mut log_probs = vec![0.0f32; n];
        let mut values = vec![0.0f32; n];
        let mut rewards = vec![0.0f64; n];
        let mut ends = vec![false; n];
        let mut done = Finished::default();
        for _ in 0..cfg.steps_per_env() {
            if cfg.norm_obs {
                self.obs_rms.update(&self.raw_obs);
            }
            normalize_obs(cfg.norm_obs, &self.obs_rms, &self.raw_obs, &mut obs);
            let cache = &mut self.cache;
            self.policy.act(&obs, n, &mut self.rng, cache, &mut actions, &mut log_probs, &mut values);
            self.buffer.obs.extend_from_slice(&obs);
            self.buffer.actions.extend_from_slice(&actions);
            self.buffer.log_probs.extend_from_slice(&log_probs);
            self.buffer.values.extend_from_slice(&values);
            for (i, (env, o)) in self.envs.iter_mut().zip(self.raw_obs.chunks_mut(od)).enumerate() {
                actions64.iter_mut().zip(&actions[i * ad..(i + 1) * ad]).for_each(|(d, s)| *d = *s as f64);
                let robot_od = env.observation_space().dim();
                let s = env.step_into(&actions64, &mut o[..robot_od])?;
                let trajectory = &mut self.trajectories[i];
                trajectory.push(env.position().to_vec());
                let end = s.terminated() || env.steps() >= horizon;
                ends[i] = end;
                rewards[i] = 0.0;
                if end {
                    let score = episode_score(&self.spec, &self.at, trajectory);
                    rewards[i] = score;
                    done.scores.push(score);
                    done.satisfied += usize::from(!s.terminated() && score > 0.0);
                    *trajectory = vec![begin(env.as_mut(), &self.task, &mut self.rng, o)?];
                } else {
                    observe(env.as_ref(), horizon, o);
                }
            }
            if cfg.norm_reward {
                self.reward_scaler.scale(&mut rewards, &ends);
            }
            // Every end is terminal: with the clock observed, the step limit is part of
            // the task, not a cut to bootstrap across.
            self.buffer.rewards.extend(rewards.iter().map(|r| *r as f32));
            self.buffer.ends.extend_from_slice(&ends);
            self.steps += n;
        }
        normalize_obs(cfg.norm_obs, &self.obs_rms, &self.raw_obs, &mut obs);
        self.buffer.last_values = self.policy.value(&obs, n, &mut self.cache).to_vec();
        let lr = if cfg.anneal_lr {
            cfg.lr * (1.0 - self.updates as f64 / self.total_updates() as f64)
        } else {
            cfg.lr
        };
        let stats = self.learner.update(&mut self.policy, &self.buffer, lr, &mut self.rng);
        self.updates += 1;
        let k = done.scores.len();
        Ok(TltlMetrics {
            update: self.updates,
            env_steps: self.steps,
            episodes: k,
            score: (k > 0).then(|| done.scores.iter().sum::<f64>() / k as f64),
            satisfaction: (k > 0).then(|| done.satisfied as f64 / k as f64),
            lr,
            update_stats: stats,
            steps_per_sec: cfg.rollout as f64 / start.elapsed().as_secs_f64().max(1e-9),
        })
    }

    /// Rebuilds the parts not saved ([`crate::store::tltl`]) around restored ones.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn restored(
        settings: TltlSettings,
        policy: ActorCritic,
        learner: PpoLearner,
        obs_rms: RunningMeanStd,
        reward_scaler: RewardScaler,
        rng: ChaCha8Rng,
        env_states: &[String],
        trajectories: Vec<Vec<Vec<f64>>>,
        raw_obs: Vec<f64>,
        (steps, updates): (usize, usize),
    ) -> Result<Self, RunError> {
        let mut t = Self::new(settings)?;
        let n = t.envs.len();
        if env_states.len() != n || trajectories.len() != n || raw_obs.len() != t.raw_obs.len() {
            return Err(RunError::Setting {
                key: "state",
                message: format!("the saved state is not for {n} environments"),
            });
        }
        if policy.obs_dim() != t.policy.obs_dim() || policy.act_dim() != t.policy.act_dim() {
            return Err(RunError::Setting {
                key: "state",
                message: format!("the saved policy does not take the {}'s flat observation", t.task.robot),
            });
        }
        for (e, s) in t.envs.iter_mut().zip(env_states) {
            e.restore_state(s)?;
        }
        t.policy = policy;
        t.learner = learner;
        t.obs_rms = obs_rms;
        t.reward_scaler = reward_scaler;
        t.rng = rng;
        t.trajectories = trajectories;
        t.raw_obs = raw_obs;
        t.steps = steps;
        t.updates = updates;
        Ok(t)
    }
}

/// Evaluates a flat policy on `task`: `groups × per_group` episodes from random
/// starts with the policy's mean actions, judged as in training (module docs).
/// Each episode is an [`Execution`] with no plan (`planned` empty) whose `executed`
/// path is the positions the spec read.
pub fn evaluate(
    task: &Task,
    controller: &Controller,
    (groups, per_group): (usize, usize),
    seed: u64,
) -> Result<TaskEval, RunError> {
    let spec = task.execution_spec();
    let at = sample_steps(task);
    let horizon = task.step_limit;
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut eval = TaskEval::empty();
    let mut cache = PolicyCache::default();
    for _ in 0..groups {
        let mut envs = (0..per_group).map(|_| task_env(task.robot, task)).collect::<Result<Vec<_>, _>>()?;
        let od = controller.policy.obs_dim();
        let ad = controller.policy.act_dim();
        let mut raw = vec![0.0; per_group * od];
        let mut trajectories = Vec::with_capacity(per_group);
        let mut headings = Vec::with_capacity(per_group);
        for (env, o) in envs.iter_mut().zip(raw.chunks_mut(od)) {
            trajectories.push(vec![begin(env.as_mut(), task, &mut rng, o)?]);
            headings.push(vec![env.heading()]);
        }
        let mut outcome = vec![None; per_group];
        let mut actions = vec![0.0; per_group * ad];
        while outcome.iter().any(Option::is_none) {
            controller.act(&raw, per_group, &mut cache, &mut actions);
            for (i, (env, o)) in envs.iter_mut().zip(raw.chunks_mut(od)).enumerate() {
                if outcome[i].is_some() {
                    continue;
                }
                let robot_od = env.observation_space().dim();
                let s = env.step_into(&actions[i * ad..(i + 1) * ad], &mut o[..robot_od])?;
                trajectories[i].push(env.position().to_vec());
                headings[i].push(env.heading());
                observe(env.as_ref(), horizon, o);
                if s.collided {
                    outcome[i] = Some(Outcome::Collided);
                } else if s.fell {
                    outcome[i] = Some(Outcome::Fell);
                } else if env.steps() >= horizon {
                    outcome[i] = Some(Outcome::Completed);
                }
            }
        }
        let mut tally = GroupTally::default();
        for ((trajectory, headings), outcome) in trajectories.into_iter().zip(headings).zip(outcome) {
            let outcome = outcome.expect("every episode ended");
            let (path, reached_at) = sampled(&trajectory, &at);
            let judged = spec.judge(&path, &trajectory, &reached_at);
            let robustness = spec.score(&path, &trajectory, &reached_at);
            let run = Execution {
                planned: vec![],
                executed: path,
                steps: trajectory.len() - 1,
                trajectory,
                headings,
                outcome,
                reached_at,
                control_return: 0.0,
                robustness,
                entered: judged.entered,
            };
            eval.tally(&mut tally, run, |r| steps_to_reach(&spec, task, &at, r) as f64);
        }
        eval.end_group(tally);
    }
    Ok(eval)
}

/// Steps to reach of a satisfying flat episode (module docs).
fn steps_to_reach(spec: &ExecutionSpec, task: &Task, at: &[usize], run: &Execution) -> usize {
    if let Some(k) = task.steps_to_reach_at {
        return at[k.clamp(1, at.len()) - 1];
    }
    (1..=at.len())
        .find(|&i| {
            let held = &run.trajectory[..=at[i - 1]];
            spec.score(&run.executed[..=i], held, &at[..i]) > 0.0
        })
        .map_or(task.step_limit, |i| at[i - 1])
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::task::TaskKind;

    #[test]
    fn waypoints_are_read_at_equal_steps_up_to_the_step_limit() {
        let task = Task::point(TaskKind::Seq);
        assert_eq!(sample_steps(&task), vec![125, 250, 375, 500, 625, 750, 875, 1000]);
    }

    #[test]
    fn a_trajectory_visiting_the_goals_in_order_scores_positive_and_stopping_short_does_not() {
        let task = Task::point(TaskKind::Seq);
        let spec = task.execution_spec();
        let at = sample_steps(&task);
        // Straight lines between the goal centres would cross walls; score only reads
        // the sampled positions and the walls' clearance there, and these positions
        // sit in open space.
        let goals: Vec<Vec<f64>> = task.goals.iter().map(|g| g.center.clone()).collect();
        let mut trajectory = vec![vec![1.5, -1.5]];
        for k in 1..=1000 {
            let i = at.iter().position(|&s| s >= k).unwrap();
            trajectory.push(goals[(i / 2).min(3)].clone());
        }
        assert!(episode_score(&spec, &at, &trajectory) > 0.0);
        // Ended (say, by a collision) at step 300: the rest is read as staying there.
        let short = &trajectory[..=300];
        assert!(episode_score(&spec, &at, short) < 0.0);
    }
}
