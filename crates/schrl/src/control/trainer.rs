//! Goal-conditioned controller training: PPO over vectorised environments where
//! every environment chases random goals.
//!
//! Each environment starts at a random free position with a random free goal
//! (uniform in the map's region, clear of obstacles). On reaching the goal it gets a
//! new one and carries on; a collision or a fall (terminal) or the step limit (truncated,
//! bootstrapped with the critic) resets it. The general controller learns in the
//! open (`empty` map for ground robots, `floor` for the Drone): it sees only the goal
//! direction, so obstacles are the planner's business (paper §3.3).
//!
//! With [`ControlConfig::goal`] set it trains an *option* instead (paper App. K, the
//! options framework the goal-conditioned controller replaces): every episode chases
//! that one goal from a random start and ends on reaching it.

use std::time::Instant;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};
use sim::{Map, Robot, Step, VecEnv};

use super::normalize::{RewardScaler, RunningMeanStd};
use super::policy::{ActorCritic, PolicyCache};
use super::ppo::{PpoConfig, PpoLearner, RolloutBuffer, UpdateStats};

/// What to train.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ControlConfig {
    /// The robot.
    pub robot: Robot,
    /// Map name; goals and starts are drawn from its free space.
    pub map: String,
    /// Seed of initial weights, environments and action noise.
    pub seed: u64,
    /// Environment steps to train for.
    pub total_steps: usize,
    /// Step limit of an episode.
    pub episode_steps: usize,
    /// PPO hyper-parameters.
    pub ppo: PpoConfig,
    /// One fixed goal (plan space): an option policy for it, whose episodes end on
    /// reaching it. `None`: a goal-conditioned controller (random goals).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub goal: Option<Vec<f64>>,
    /// Short hops: each random goal is drawn within [`NearGoals::within`] of the
    /// robot with probability [`NearGoals::fraction`], else anywhere (`None`, the
    /// default: every goal anywhere).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub near_goals: Option<NearGoals>,
    /// Subtracted from the reward PPO learns from on the step a robot falls (before
    /// reward scaling; the logged returns stay the environment's). 0, the default: the
    /// paper's reward, where a fall costs only the return it ends. Controller training
    /// only: the joint phase's controller updates learn from the environment's reward.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub fall_penalty: f64,
    /// Subtracted, times the robot's distance (m) from the straight segment between
    /// where its goal was set and the goal ([`sim::Env::goal_origin`]), from the reward
    /// PPO learns from on every step (the logged returns stay the environment's). 0 (the
    /// paper's reward, and every robot's default but the Doggo's,
    /// [`TrackDefaults`]): a robot may arc to a goal behind it as freely as
    /// turn first; a plan's segments are only clear of walls close to the straight line
    /// (README, *Following the planned segments*).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub off_track_weight: f64,
    /// The controller also observes its offset from its track
    /// ([`sim::Env::set_track_observation`]: from where its goal was set in training,
    /// the planned segment when it executes a plan), so that
    /// [`ControlConfig::off_track_weight`] and the joint phase's off-track weight price
    /// something it can see. `true` by default for the Doggo only
    /// ([`TrackDefaults`]); `false`: the robot's own observation, as in the
    /// paper.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub observe_track: bool,
}

pub(crate) fn is_zero(x: &f64) -> bool {
    *x == 0.0
}

/// What this project may take off the environment's reward before PPO learns from it,
/// in controller training ([`ControlConfig`]) and in the joint phase
/// ([`crate::run::joint::JointConfig`]) alike; both 0 is the paper's reward.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct RewardTerms {
    /// Taken on the step the robot falls.
    pub fall_penalty: f64,
    /// Taken per metre the robot is off its track, every step.
    pub off_track_weight: f64,
}

impl RewardTerms {
    /// The reward learned from a step of `reward` that ended `off_track` metres from
    /// the track (read only when the weight is above 0).
    pub fn learned(&self, reward: f64, fell: bool, off_track: impl FnOnce() -> f64) -> f64 {
        let mut r = reward - if fell { self.fall_penalty } else { 0.0 };
        if self.off_track_weight > 0.0 {
            r -= self.off_track_weight * off_track();
        }
        r
    }

    /// Errors with the key and what is wrong unless both are finite numbers ≥ 0.
    pub fn check(&self) -> Result<(), (&'static str, String)> {
        for (key, value) in [("fall_penalty", self.fall_penalty), ("off_track_weight", self.off_track_weight)]
        {
            if !(value >= 0.0 && value.is_finite()) {
                return Err((key, format!("must be a finite number ≥ 0, got {value}")));
            }
        }
        Ok(())
    }
}

/// A share of a goal-conditioned controller's random goals drawn near the robot.
///
/// Goals drawn anywhere on the map are rarely within a metre of the robot, yet a
/// plan's hops often are (a start region that overlaps a goal, two waypoints at the
/// edges of one goal), and a goal beside or behind the robot is a different skill
/// from one ahead of it.
///
/// No robot trains with near goals by default. Measured on the Car, whose general
/// controller trained on goals anywhere reached 0.48–0.93 of goals within 1 m on the
/// tuning seeds 100–104 (`schrl control eval --goals-within 1`; the rest timed out with the Car standing still, its mean action
/// exactly zero, the goal beside or behind it: an equilibrium of the closed loop that
/// the policy's noise hides in training). A quarter of its goals within 1 m and 2 M
/// steps raised that to 0.64–0.99 (median 0.96 against 0.87), but Car Loop with such
/// controllers fell on seeds 0–3 from 0.976 0.944 0.956 0.992 to 0.866 0.852 0.852
/// 0.000 (slower runs timing out, and seed 3 colliding), so it is an option
/// (`--near-goals`), not a default (README, *Controller results*).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NearGoals {
    /// Probability that a goal is drawn near (0–1).
    pub fraction: f64,
    /// Radius of the ball around the robot a near goal is drawn in (m).
    pub within: f64,
}

impl ControlConfig {
    /// Its fall penalty and off-track weight, as the reward learned from takes them.
    pub(crate) fn reward_terms(&self) -> RewardTerms {
        RewardTerms { fall_penalty: self.fall_penalty, off_track_weight: self.off_track_weight }
    }

    /// Defaults for `robot`: its open map, the reference PPO preset, and a step
    /// budget that reaches ≥ 95 % success (measured; see the README's results).
    pub fn for_robot(robot: Robot) -> Self {
        let track = TrackDefaults::for_robot(robot);
        Self {
            robot,
            map: open_map(robot).name().to_string(),
            seed: 0,
            total_steps: default_steps(robot),
            episode_steps: 1000,
            ppo: PpoConfig::reference(),
            goal: None,
            near_goals: None,
            fall_penalty: 0.0,
            off_track_weight: track.off_track_weight,
            observe_track: track.observe,
        }
    }
}

/// How a robot's controller is held to its track by default: whether it observes its
/// offset from the track ([`ControlConfig::observe_track`]) and the weight on straying
/// from it, in controller training ([`ControlConfig::off_track_weight`]) and in the joint
/// phase ([`crate::run::joint::JointConfig::off_track_weight`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TrackDefaults {
    /// The controller observes its offset from its track.
    pub observe: bool,
    /// The weight on the distance from the track, subtracted from the reward, in
    /// controller training.
    pub off_track_weight: f64,
    /// The same weight in the joint phase, where the track is the planned segment.
    pub joint_off_track_weight: f64,
}

impl TrackDefaults {
    /// The Doggo observes its track and pays 0.1 a metre off it: chosen on seed 0's Seq
    /// (0.526 → 0.940 of 5 × 100 runs) and kept on held-out seed 5 (0.754 → 0.810;
    /// README, *The track in the controller's observation*). In the joint phase it pays
    /// 0.3: chosen on seed 0's Loop (0.858 → 0.974, collisions after turns 62 → 8 of
    /// 500), then run on every task of tuning seeds 0–2 and held-out seed 5 (README,
    /// *A heavier off-track weight in the joint phase*). The other robots keep the
    /// paper's observation and reward: the track was tried on the Car and not kept
    /// (README, *The track in the Car's observation*).
    pub fn for_robot(robot: Robot) -> Self {
        match robot {
            Robot::Doggo => Self { observe: true, off_track_weight: 0.1, joint_off_track_weight: 0.3 },
            Robot::Point | Robot::Car | Robot::Drone => {
                Self { observe: false, off_track_weight: 0.0, joint_off_track_weight: 0.0 }
            }
        }
    }
}

/// Seed of the episodes of a controller evaluation (this project's fixed choice, so
/// evaluations compare).
pub const EVAL_SEED: u64 = 12345;

/// A goal within [`NearGoals::within`] of the robot, with probability
/// [`NearGoals::fraction`] (drawn from `rng`; nothing drawn without `near`); `None`:
/// the environment's own draw stands.
fn near_goal(near: Option<NearGoals>, rng: &mut ChaCha8Rng, env: &mut dyn sim::Env) -> Option<Vec<f64>> {
    let n = near?;
    (rng.random::<f64>() < n.fraction).then(|| env.sample_goal_within(n.within))
}

/// The open map a general controller trains on: `empty` for ground robots, `floor`
/// for the Drone.
pub fn open_map(robot: Robot) -> Map {
    match robot {
        Robot::Drone => Map::Floor,
        _ => Map::by_name("empty").expect("the empty map exists"),
    }
}

/// The default training budget for `robot` (environment steps; README, *Controller
/// results*).
pub fn default_steps(robot: Robot) -> usize {
    match robot {
        Robot::Point => 1_000_000,
        Robot::Car => 1_000_000,
        Robot::Drone => 400_000,
        // Seed 0 with the filtered actions (sim::mujoco::ACTION_FILTER): 0.956 of 500
        // random goals after 6 M (README's Doggo section); the paper's Doggo runs use
        // 1e8 steps in all (Fig. 3).
        Robot::Doggo => 6_000_000,
    }
}

/// A training problem, naming what is wrong.
#[derive(Debug, thiserror::Error)]
pub enum ControlError {
    /// A configuration value is invalid.
    #[error("invalid configuration: {0}")]
    Config(String),
    /// The environment refused something.
    #[error(transparent)]
    Env(#[from] sim::EnvError),
}

/// The metrics of one update (one line of `metrics.jsonl`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ControlMetrics {
    /// Updates done.
    pub update: usize,
    /// Environment steps done.
    pub steps: usize,
    /// Episodes finished in this rollout.
    pub episodes: usize,
    /// Mean undiscounted (unscaled) return of the last 100 episodes.
    pub mean_return: Option<f64>,
    /// Goals reached in this rollout.
    pub goals_reached: usize,
    /// Goals settled in this rollout (see [`ControlMetrics::success_rate`]).
    #[serde(default)]
    pub goals_settled: usize,
    /// Over the last 100 settled goals: the fraction reached. A goal is settled when
    /// reached, or lost when its episode ends by collision or fall, or by the time limit
    /// while it was the episode's first goal. A later goal cut by the time limit is not
    /// counted (censored: it had less than an episode), so an option, whose episodes
    /// hold one goal each, and a goal-conditioned controller are judged alike (App. K).
    /// Optimistic next to [`crate::run::evaluate::evaluate_controller`], which gives
    /// every goal a fresh episode.
    pub success_rate: Option<f64>,
    /// Learning rate used.
    pub lr: f64,
    /// Loss terms and diagnostics.
    pub update_stats: UpdateStats,
    /// Environment steps per second over this rollout and update.
    pub steps_per_sec: f64,
    /// Seconds spent stepping environments and acting in this rollout.
    pub rollout_s: f64,
    /// Seconds spent in the PPO update.
    pub update_s: f64,
}

/// Everything a controller training run holds; [`crate::store::controller`] saves and
/// restores all of it, so a resumed run continues exactly.
pub struct ControlTrainer {
    /// The configuration (the robot included).
    pub config: ControlConfig,
    /// Actor and critic.
    pub policy: ActorCritic,
    /// PPO's optimiser side.
    pub learner: PpoLearner,
    /// Observation statistics.
    pub obs_rms: RunningMeanStd,
    /// Reward scaling.
    pub reward_scaler: RewardScaler,
    /// Action noise, shuffling and reset seeds.
    pub rng: ChaCha8Rng,
    /// The environments.
    pub envs: VecEnv,
    /// Their current raw observations.
    pub raw_obs: Vec<f64>,
    /// Their running episode returns.
    pub episode_returns: Vec<f64>,
    /// The latest settled goals (reached or not) and finished episodes' returns.
    pub recent: RecentOutcomes,
    /// Environment steps done.
    pub steps: usize,
    /// Updates done.
    pub updates: usize,
    buffer: RolloutBuffer,
    cache: PolicyCache,
}

impl ControlTrainer {
    /// A fresh run.
    pub fn new(config: ControlConfig) -> Result<Self, ControlError> {
        config.ppo.validate().map_err(ControlError::Config)?;
        let robot = config.robot;
        let map = Map::by_name(&config.map).ok_or_else(|| sim::EnvError::UnknownMap(config.map.clone()))?;
        if config.episode_steps == 0 {
            return Err(ControlError::Config("episode_steps must be at least 1".into()));
        }
        if let Some(n) = &config.near_goals
            && !(n.fraction >= 0.0 && n.fraction <= 1.0 && n.within > 0.0 && n.within.is_finite())
        {
            return Err(ControlError::Config(format!(
                "near_goals: fraction must be in [0, 1] and within a positive number of metres, got {n:?}"
            )));
        }
        config.reward_terms().check().map_err(|(key, m)| ControlError::Config(format!("{key} {m}")))?;
        if let Some(g) = &config.goal {
            let (low, high) = map.region();
            let inside = g.len() == map.dim()
                && g.iter().zip(low.iter().zip(&high)).all(|(x, (l, h))| x >= l && x <= h);
            if !inside || map.sdf(g) <= 0.0 {
                return Err(ControlError::Config(format!(
                    "goal {g:?} is not a free point of the {} map (region {low:?} to {high:?}, clear of obstacles)",
                    map.name()
                )));
            }
        }
        let mut rng = ChaCha8Rng::seed_from_u64(config.seed);
        let env_seed: u64 = rng.random();
        let mut envs = VecEnv::new(robot, map, config.ppo.num_envs, env_seed)?;
        envs.set_track_observation(config.observe_track);
        for e in envs.envs_mut() {
            e.set_max_steps(config.episode_steps);
        }
        let (od, ad) = (envs.obs_dim(), envs.act_dim());
        let policy = ActorCritic::new(od, ad, &config.ppo.hidden, &mut rng);
        let learner = PpoLearner::new(config.ppo.clone(), &policy);
        let mut raw_obs = vec![0.0; config.ppo.num_envs * od];
        for (e, o) in envs.envs_mut().iter_mut().zip(raw_obs.chunks_mut(od)) {
            if let Some(g) = &config.goal {
                e.set_goal(g).map_err(|err| ControlError::Config(format!("goal {g:?}: {err}")))?;
            } else if let Some(g) = near_goal(config.near_goals, &mut rng, e.as_mut()) {
                e.set_goal(&g)?;
            }
            e.observe(o);
        }
        let n = config.ppo.num_envs;
        Ok(Self {
            policy,
            learner,
            obs_rms: RunningMeanStd::new(od),
            reward_scaler: RewardScaler::new(n, config.ppo.gamma),
            rng,
            envs,
            raw_obs,
            episode_returns: vec![0.0; n],
            recent: RecentOutcomes::default(),
            steps: 0,
            updates: 0,
            buffer: RolloutBuffer::new(n, od, ad),
            cache: PolicyCache::default(),
            config,
        })
    }

    /// Rebuilds a trainer from saved parts (used by checkpoint loading).
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn from_parts(
        config: ControlConfig,
        policy: ActorCritic,
        learner: PpoLearner,
        obs_rms: RunningMeanStd,
        reward_scaler: RewardScaler,
        rng: ChaCha8Rng,
        envs: VecEnv,
        raw_obs: Vec<f64>,
        episode_returns: Vec<f64>,
        recent: RecentOutcomes,
        steps: usize,
        updates: usize,
    ) -> Result<Self, ControlError> {
        let n = config.ppo.num_envs;
        let buffer = RolloutBuffer::new(n, policy.obs_dim(), policy.act_dim());
        Ok(Self {
            config,
            policy,
            learner,
            obs_rms,
            reward_scaler,
            rng,
            envs,
            raw_obs,
            episode_returns,
            recent,
            steps,
            updates,
            buffer,
            cache: PolicyCache::default(),
        })
    }

    /// Updates in the whole run.
    pub fn total_updates(&self) -> usize {
        self.config.total_steps.div_ceil(self.config.ppo.rollout).max(1)
    }

    /// `true` once the step budget is spent.
    pub fn finished(&self) -> bool {
        self.updates >= self.total_updates()
    }

    /// The deployable part: policy and observation statistics.
    pub fn controller(&self) -> Controller {
        Controller {
            robot: self.config.robot,
            policy: self.policy.clone(),
            obs_rms: self.obs_rms.clone(),
            normalize_obs: self.config.ppo.norm_obs,
            observe_track: self.config.observe_track,
        }
    }

    /// Collects one rollout and runs one PPO update.
    pub fn train_update(&mut self) -> Result<ControlMetrics, ControlError> {
        let start = Instant::now();
        let cfg = self.config.ppo.clone();
        let (n, od, ad) = (cfg.num_envs, self.policy.obs_dim(), self.policy.act_dim());
        self.buffer.clear();
        let mut obs = vec![0.0f32; n * od];
        let mut actions = vec![0.0f32; n * ad];
        let mut actions64 = vec![0.0f64; n * ad];
        let mut log_probs = vec![0.0f32; n];
        let mut values = vec![0.0f32; n];
        let mut reports = vec![Step::default(); n];
        let terms = self.config.reward_terms();
        let mut rewards = vec![0.0f64; n];
        let mut ends = vec![false; n];
        let mut truncated_obs: Vec<(usize, Vec<f64>)> = Vec::new();
        let (mut episodes, mut reached, mut settled) = (0usize, 0usize, 0usize);
        for _ in 0..cfg.steps_per_env() {
            if cfg.norm_obs {
                self.obs_rms.update(&self.raw_obs);
            }
            normalize_obs(cfg.norm_obs, &self.obs_rms, &self.raw_obs, &mut obs);
            self.policy.act(
                &obs,
                n,
                &mut self.rng,
                &mut self.cache,
                &mut actions,
                &mut log_probs,
                &mut values,
            );
            self.buffer.obs.extend_from_slice(&obs);
            self.buffer.actions.extend_from_slice(&actions);
            self.buffer.log_probs.extend_from_slice(&log_probs);
            self.buffer.values.extend_from_slice(&values);
            for (d, s) in actions64.iter_mut().zip(&actions) {
                *d = *s as f64;
            }
            self.envs.step_all(&actions64, &mut self.raw_obs, &mut reports)?;
            truncated_obs.clear();
            for (i, (env, o)) in self.envs.envs_mut().iter_mut().zip(self.raw_obs.chunks_mut(od)).enumerate()
            {
                let s = reports[i];
                rewards[i] = terms.learned(s.reward, s.fell, || {
                    sim::segment::point_segment_distance(env.position(), env.goal_origin(), env.goal())
                });
                self.episode_returns[i] += s.reward;
                if s.reached {
                    reached += 1;
                    settled += 1;
                    self.recent.push_goal(true);
                    self.recent.mark_reached(i);
                    if self.config.goal.is_none() {
                        let goal = near_goal(self.config.near_goals, &mut self.rng, env.as_mut())
                            .unwrap_or_else(|| env.sample_goal());
                        env.set_goal(&goal)?;
                        env.observe(o);
                    }
                }
                // An option's episode ends where it reaches its goal (no bootstrap).
                let option_done = s.reached && self.config.goal.is_some();
                let end = s.terminated() || s.truncated || option_done;
                ends[i] = end;
                if end {
                    let censored = s.truncated && !s.terminated() && self.recent.reached_before(i);
                    if !s.reached && !censored {
                        settled += 1;
                        self.recent.push_goal(false);
                    }
                    self.recent.new_episode(i);
                    if s.truncated && !s.terminated() && !option_done {
                        truncated_obs.push((i, o.to_vec()));
                    }
                    episodes += 1;
                    self.recent.push_return(self.episode_returns[i]);
                    self.episode_returns[i] = 0.0;
                    let seed: u64 = self.rng.random();
                    env.reset_into(seed, None, o)?;
                    if let Some(g) = &self.config.goal {
                        env.set_goal(g)?;
                        env.observe(o);
                    } else if let Some(goal) = near_goal(self.config.near_goals, &mut self.rng, env.as_mut())
                    {
                        env.set_goal(&goal)?;
                        env.observe(o);
                    }
                }
            }
            if cfg.norm_reward {
                self.reward_scaler.scale(&mut rewards, &ends);
            }
            let first = self.buffer.rewards.len();
            self.buffer.rewards.extend(rewards.iter().map(|r| *r as f32));
            self.buffer.ends.extend_from_slice(&ends);
            if !truncated_obs.is_empty() {
                // Bootstrap time-limit cuts: r + γ V(s_final).
                let raw: Vec<f64> = truncated_obs.iter().flat_map(|(_, o)| o.iter().copied()).collect();
                let mut x = vec![0.0f32; raw.len()];
                normalize_obs(cfg.norm_obs, &self.obs_rms, &raw, &mut x);
                let v = self.policy.value(&x, truncated_obs.len(), &mut self.cache).to_vec();
                for ((i, _), v) in truncated_obs.iter().zip(v) {
                    self.buffer.rewards[first + i] += cfg.gamma as f32 * v;
                }
            }
            self.steps += n;
        }
        normalize_obs(cfg.norm_obs, &self.obs_rms, &self.raw_obs, &mut obs);
        self.buffer.last_values = self.policy.value(&obs, n, &mut self.cache).to_vec();
        let rollout_s = start.elapsed().as_secs_f64();

        let lr = if cfg.anneal_lr {
            cfg.lr * (1.0 - self.updates as f64 / self.total_updates() as f64)
        } else {
            cfg.lr
        };
        let t = Instant::now();
        let stats = self.learner.update(&mut self.policy, &self.buffer, lr, &mut self.rng);
        let update_s = t.elapsed().as_secs_f64();
        self.updates += 1;
        Ok(ControlMetrics {
            update: self.updates,
            steps: self.steps,
            episodes,
            mean_return: self.recent.mean_return(),
            goals_reached: reached,
            goals_settled: settled,
            success_rate: self.recent.success_rate(),
            lr,
            update_stats: stats,
            steps_per_sec: cfg.rollout as f64 / start.elapsed().as_secs_f64(),
            rollout_s,
            update_s,
        })
    }
}

/// Standardises observations with `rms`, or only converts them when normalisation
/// is off.
/// Standardises raw observations with `rms` when `on`, else converts them to `f32`.
pub(crate) fn normalize_obs(on: bool, rms: &RunningMeanStd, raw: &[f64], out: &mut [f32]) {
    if on {
        rms.normalize_into(raw, out);
    } else {
        for (o, r) in out.iter_mut().zip(raw) {
            *o = *r as f32;
        }
    }
}

/// Sliding windows over the latest outcomes (as SB3's 100-episode info buffer).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct RecentOutcomes {
    goals: std::collections::VecDeque<bool>,
    returns: std::collections::VecDeque<f64>,
    /// Per environment: a goal has been reached in its current episode (its goal now
    /// is not the episode's first).
    #[serde(default)]
    reached_in_episode: Vec<bool>,
}

impl RecentOutcomes {
    /// Window length.
    pub const WINDOW: usize = 100;

    fn push_goal(&mut self, reached: bool) {
        if self.goals.len() == Self::WINDOW {
            self.goals.pop_front();
        }
        self.goals.push_back(reached);
    }

    fn mark_reached(&mut self, env: usize) {
        if self.reached_in_episode.len() <= env {
            self.reached_in_episode.resize(env + 1, false);
        }
        self.reached_in_episode[env] = true;
    }

    fn reached_before(&self, env: usize) -> bool {
        self.reached_in_episode.get(env).copied().unwrap_or(false)
    }

    fn new_episode(&mut self, env: usize) {
        if let Some(r) = self.reached_in_episode.get_mut(env) {
            *r = false;
        }
    }

    fn push_return(&mut self, r: f64) {
        if self.returns.len() == Self::WINDOW {
            self.returns.pop_front();
        }
        self.returns.push_back(r);
    }

    /// Fraction of the window's goals that were reached.
    pub fn success_rate(&self) -> Option<f64> {
        (!self.goals.is_empty())
            .then(|| self.goals.iter().filter(|r| **r).count() as f64 / self.goals.len() as f64)
    }

    /// Mean of the window's episode returns.
    pub fn mean_return(&self) -> Option<f64> {
        (!self.returns.is_empty()).then(|| self.returns.iter().sum::<f64>() / self.returns.len() as f64)
    }
}

/// A trained controller ready to drive a robot: the policy (its mean action is
/// used) and the frozen observation statistics.
#[derive(Clone, Debug)]
pub struct Controller {
    /// The robot it was trained for.
    pub robot: Robot,
    /// Actor and critic.
    pub policy: ActorCritic,
    /// Observation statistics.
    pub obs_rms: RunningMeanStd,
    /// Whether observations are standardised with `obs_rms` (as in training).
    pub normalize_obs: bool,
    /// Whether its observations end with the track offset
    /// ([`ControlConfig::observe_track`]).
    pub observe_track: bool,
}

impl Controller {
    /// Mean actions for `n` raw observations (`n × obs_dim`) into `actions`.
    pub fn act(&self, raw_obs: &[f64], n: usize, cache: &mut PolicyCache, actions: &mut [f64]) {
        let mut x = vec![0.0f32; raw_obs.len()];
        normalize_obs(self.normalize_obs, &self.obs_rms, raw_obs, &mut x);
        let mean = self.policy.mean(&x, n, cache);
        for (a, m) in actions.iter_mut().zip(mean) {
            *a = *m as f64;
        }
    }
}
