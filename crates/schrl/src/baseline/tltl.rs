//! TLTL (Li, Vasile & Belta 2017): one flat PPO policy learns a task from the spec's
//! robustness alone — no planner, no waypoints, no goal-conditioned controller (the
//! paper's non-hierarchical baseline, §4.2).
//!
//! * *Episodes*: flat ([`super::flat`]): the robot's observation with its position and
//!   the clock, the spec read at equal steps up to the step limit.
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
//! Episodes are judged and evaluated as [`super::flat`] says.

use std::time::Instant;

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};
use sim::{Env, Robot};

use super::flat::{Ended, EpisodeSummary, begin, episode_score, flat_obs_dim, observe, sample_steps};
use crate::control::normalize::{RewardScaler, RunningMeanStd};
use crate::control::policy::{ActorCritic, PolicyCache};
use crate::control::ppo::{PpoConfig, PpoLearner, RolloutBuffer, UpdateStats};
use crate::control::trainer::normalize_obs;
use crate::control::{ControlError, Controller};
use crate::run::RunError;
use crate::run::execute::task_env;
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
    /// The episodes that ended in this update's rollout.
    #[serde(flatten)]
    pub episodes: EpisodeSummary,
    /// Learning rate used.
    pub lr: f64,
    /// PPO's loss terms and diagnostics.
    pub update_stats: UpdateStats,
    /// Environment steps per second over this rollout and update.
    pub steps_per_sec: f64,
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
        let mut envs = (0..n).map(|_| task_env(task.robot, &task, false)).collect::<Result<Vec<_>, _>>()?;
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
            observe_track: false,
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
        let mut done = Ended::default();
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
                    done.push(score, s.terminated());
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
        Ok(TltlMetrics {
            update: self.updates,
            episodes: done.summary(self.steps),
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
