//! CRM (Icarte et al., JAIR 2022, §5.1): counterfactual reasoning with reward
//! machines, on TD3 ([`super::td3`]).
//!
//! The policy sees the flat observation ([`super::flat`]) ⊕ the one-hot state of the
//! task's reward machine ([`super::reward_machine`]). Every real step is turned into one
//! experience per non-terminal machine state `u`: what the machine would have done from
//! `u` on the step's events, `(u', r) = δ(u, σ)`, ending the experience when `u'` is
//! terminal or the episode ended. So one step teaches the policy about every stage of
//! the task at once. The real machine state moves on the same events; reaching a
//! terminal state ends the episode.
//!
//! Episodes are judged by the spec as every flat policy's are ([`super::flat`]), which
//! reads positions at fixed steps: the machine rewards the order of events, not their
//! timing, so a run the machine accepts can still miss the spec's timing. Both are
//! logged: `score` / `satisfaction` (the spec), `machine_return` (the machine).
//!
//! With [`CrmSettings::dhrm`] set the same trainer runs DHRM ([`super::dhrm`]): the
//! actor is conditioned on the option instead of the machine state, the experiences
//! are one per option, and a meta-controller picks the options.

use std::time::Instant;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
use serde::{Deserialize, Serialize};
use sim::{Env, Robot};

use super::dhrm::{DhrmConfig, Hierarchy, push_input};
use super::flat::{
    Ended, EpisodeSummary, FlatDriver, begin, episode_score, flat_obs_dim, observe, sample_steps,
};
use super::replay::{ReplayBuffer, Transition};
use super::reward_machine::{Labels, RewardMachine};
use super::td3::{Batch, Td3, Td3Config};
use crate::control::normalize::RunningMeanStd;
use crate::nn::mlp::MlpCache;
use crate::run::RunError;
use crate::run::execute::task_env;
use crate::task::Task;
use crate::task::along::ExecutionSpec;

/// Every setting of a CRM run: what its run directory's manifest holds.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CrmSettings {
    /// The robot.
    pub robot: Robot,
    /// The task's TOML text.
    pub task_toml: String,
    /// The task's spec text.
    pub task_spec: String,
    /// The reward machine's TOML text.
    pub machine: String,
    /// Seed of weights, starts, exploration and minibatches.
    pub seed: u64,
    /// Environment steps to train for.
    pub steps: usize,
    /// TD3's hyper-parameters.
    pub td3: Td3Config,
    /// Evaluation groups of [`crate::run::evaluate::EVAL_PER_GROUP`] runs after training (0: none).
    pub eval_groups: usize,
    /// Logged chunks ([`CHUNK`] steps each) between checkpoints.
    pub save_every: usize,
    /// DHRM's options and meta-controller; `None`: CRM.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub dhrm: Option<DhrmConfig>,
}

impl CrmSettings {
    /// The task and reward machine these settings train on.
    pub fn task_and_machine(&self) -> Result<(Task, RewardMachine), RunError> {
        let here = std::path::Path::new("settings");
        let task = Task::from_texts(here, &self.task_toml, here, &self.task_spec)
            .map_err(|e| RunError::Setting { key: "task", message: e.to_string() })?;
        let machine = RewardMachine::parse(std::path::Path::new("settings.machine"), &self.machine, &task)
            .map_err(|e| RunError::Setting { key: "machine", message: e.to_string() })?;
        Ok((task, machine))
    }
}

/// Environment steps per logged chunk: PPO's rollout, so the curves' points compare.
pub const CHUNK: usize = 4000;

/// What one chunk of [`CHUNK`] steps measured (one line of `metrics.jsonl`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CrmMetrics {
    /// Chunks done.
    pub chunk: usize,
    /// The episodes that ended in this chunk.
    #[serde(flatten)]
    pub episodes: EpisodeSummary,
    /// Their mean return under the reward machine.
    pub machine_return: Option<f64>,
    /// Mean TD3 critic loss over the chunk's updates.
    pub critic_loss: Option<f64>,
    /// Mean TD3 actor loss over the chunk's actor updates.
    pub actor_loss: Option<f64>,
    /// DHRM: mean loss of the meta-controller's updates.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub meta_loss: Option<f64>,
    /// Environment steps (with their updates) per second.
    pub steps_per_sec: f64,
}

/// A CRM training run; [`crate::store::crm`] saves and restores all of it.
pub struct CrmTrainer {
    /// The task.
    pub task: Task,
    /// The run's settings.
    pub settings: CrmSettings,
    /// The task's reward machine.
    pub machine: RewardMachine,
    /// Actor and critics.
    pub td3: Td3,
    /// Real and counterfactual experiences.
    pub buffer: ReplayBuffer,
    /// Statistics of flat observations (inputs are standardised with them when used).
    pub obs_rms: RunningMeanStd,
    /// Starts, exploration and minibatches.
    pub rng: ChaCha8Rng,
    /// The environment.
    pub env: Box<dyn Env>,
    /// The episode so far: every position, the start first.
    pub trajectory: Vec<Vec<f64>>,
    /// The current flat observation.
    pub raw_obs: Vec<f64>,
    /// The reward machine's state.
    pub state: usize,
    /// The episode's machine return so far.
    pub episode_return: f64,
    /// Environment steps done.
    pub steps: usize,
    /// Chunks logged.
    pub chunks: usize,
    /// DHRM's options and meta-controller (`None`: CRM).
    pub hierarchy: Option<Hierarchy>,
    spec: ExecutionSpec,
    at: Vec<usize>,
}

/// An action in `[−1, 1]` scaled to the box `[low, high]`.
fn scaled(a: &[f64], env: &dyn Env) -> Vec<f64> {
    let s = env.action_space();
    a.iter().zip(s.low.iter().zip(&s.high)).map(|(a, (l, h))| l + (a + 1.0) / 2.0 * (h - l)).collect()
}

/// What a chunk accumulates.
#[derive(Default)]
struct Tally {
    ended: Ended,
    returns: Vec<f64>,
    critic: Vec<f64>,
    actor: Vec<f64>,
    meta: Vec<f64>,
}

fn mean(xs: &[f64]) -> Option<f64> {
    (!xs.is_empty()).then(|| xs.iter().sum::<f64>() / xs.len() as f64)
}

impl CrmTrainer {
    /// A fresh run.
    pub fn new(settings: CrmSettings) -> Result<Self, RunError> {
        let (task, machine) = settings.task_and_machine()?;
        if task.robot != settings.robot {
            return Err(RunError::Setting {
                key: "robot",
                message: format!("the task is for the {}, not the {}", task.robot, settings.robot),
            });
        }
        settings.td3.validate().map_err(|message| RunError::Setting { key: "td3", message })?;
        if settings.save_every == 0 {
            return Err(RunError::Setting { key: "save_every", message: "must be at least 1".into() });
        }
        let mut rng = ChaCha8Rng::seed_from_u64(settings.seed);
        let mut env = task_env(task.robot, &task, false)?;
        let od = flat_obs_dim(env.observation_space().dim(), task.map.dim());
        let ad = env.action_space().dim();
        let hierarchy = match &settings.dhrm {
            Some(cfg) => Some(
                Hierarchy::new(cfg.clone(), &machine, od, &mut rng)
                    .map_err(|message| RunError::Setting { key: "dhrm", message })?,
            ),
            None => None,
        };
        let contexts = hierarchy.as_ref().map_or(machine.len(), Hierarchy::len);
        let td3 = Td3::new(od + contexts, ad, settings.td3.clone(), &mut rng);
        let mut raw_obs = vec![0.0; od];
        let trajectory = vec![begin(env.as_mut(), &task, &mut rng, &mut raw_obs)?];
        let mut t = Self {
            buffer: ReplayBuffer::new(settings.td3.buffer, od, ad),
            obs_rms: RunningMeanStd::new(od),
            spec: task.execution_spec(),
            at: sample_steps(&task),
            state: machine.initial,
            task,
            machine,
            td3,
            rng,
            env,
            trajectory,
            raw_obs,
            episode_return: 0.0,
            steps: 0,
            chunks: 0,
            hierarchy,
            settings,
        };
        t.begin_option();
        Ok(t)
    }

    /// The actor's conditioning: the option followed (DHRM) or the machine state (CRM).
    fn context(&self) -> (usize, usize) {
        match &self.hierarchy {
            Some(h) => (h.current.option, h.len()),
            None => (self.state, self.machine.len()),
        }
    }

    /// DHRM: the meta-controller picks an option for the machine's state (ε-greedy).
    fn begin_option(&mut self) {
        if let Some(h) = self.hierarchy.as_mut() {
            let eps = h.epsilon(self.steps, self.settings.steps);
            let state = (self.state, self.machine.len());
            let o = h.choose(&self.obs_rms, &self.raw_obs, state, eps, &mut self.rng);
            h.begin(o, &self.raw_obs, self.state);
        }
    }

    /// `true` once the step budget is spent.
    pub fn finished(&self) -> bool {
        self.steps >= self.settings.steps
    }

    /// Runs [`CHUNK`] environment steps (fewer at the end of the budget), each followed
    /// by a TD3 update once learning has started.
    pub fn train_chunk(&mut self) -> Result<CrmMetrics, RunError> {
        let start = Instant::now();
        let n = CHUNK.min(self.settings.steps.saturating_sub(self.steps)).max(1);
        let mut tally = Tally::default();
        for _ in 0..n {
            self.step(&mut tally)?;
        }
        self.chunks += 1;
        Ok(CrmMetrics {
            chunk: self.chunks,
            episodes: tally.ended.summary(self.steps),
            machine_return: mean(&tally.returns),
            critic_loss: mean(&tally.critic),
            actor_loss: mean(&tally.actor),
            meta_loss: mean(&tally.meta),
            steps_per_sec: n as f64 / start.elapsed().as_secs_f64().max(1e-9),
        })
    }

    fn step(&mut self, tally: &mut Tally) -> Result<(), RunError> {
        let cfg = self.settings.td3.clone();
        let (ad, m) = (self.td3.act_dim(), self.machine.len());
        let action: Vec<f64> = if self.steps < cfg.learning_starts {
            (0..ad).map(|_| self.rng.random_range(-1.0..1.0)).collect()
        } else {
            let mut x = Vec::with_capacity(self.td3.input_dim());
            let (k, of) = self.context();
            push_input(&self.obs_rms, &self.raw_obs, k, of, &mut x);
            let mean = self.td3.act(&x, 1, &mut MlpCache::default());
            mean.iter()
                .map(|a| {
                    let eps: f64 = self.rng.sample(StandardNormal);
                    (*a as f64 + cfg.exploration_noise * eps).clamp(-1.0, 1.0)
                })
                .collect()
        };
        let before = self.raw_obs.clone();
        let horizon = self.task.step_limit;
        let robot_od = self.env.observation_space().dim();
        let s = self.env.step_into(&scaled(&action, self.env.as_ref()), &mut self.raw_obs[..robot_od])?;
        observe(self.env.as_ref(), horizon, &mut self.raw_obs);
        self.obs_rms.update(&self.raw_obs);
        self.trajectory.push(self.env.position().to_vec());
        self.steps += 1;
        let index = self.env.steps() as f64 * self.task.steps as f64 / horizon.max(1) as f64;
        let labels = Labels::of(&self.task, self.env.position(), s.collided, index);
        let env_end = s.terminated() || self.env.steps() >= horizon;
        if let Some(h) = &self.hierarchy {
            // DHRM: the step as experienced by every option.
            for o in 0..h.len() {
                let (reward, ends) = h.outcome(o, &self.machine, &labels);
                self.buffer.push(&Transition {
                    obs: &before,
                    state: o,
                    action: &action,
                    reward,
                    next_obs: &self.raw_obs,
                    next_state: o,
                    done: env_end || ends,
                });
            }
        } else {
            // Counterfactual experiences: the step as seen from every live machine state.
            for u in (0..m).filter(|u| !self.machine.terminal[*u]) {
                let (next, reward) = self.machine.step(u, &labels);
                self.buffer.push(&Transition {
                    obs: &before,
                    state: u,
                    action: &action,
                    reward,
                    next_obs: &self.raw_obs,
                    next_state: next,
                    done: env_end || self.machine.terminal[next],
                });
            }
        }
        let (next, reward) = self.machine.step(self.state, &labels);
        let moved = next != self.state;
        self.state = next;
        self.episode_return += reward;
        let ended = env_end || self.machine.terminal[next];
        if let Some(h) = self.hierarchy.as_mut() {
            h.record(reward, cfg.gamma);
            if moved || ended {
                h.end(&self.raw_obs, next, ended);
                if !ended {
                    self.begin_option();
                }
            }
        }
        if ended {
            let score = episode_score(&self.spec, &self.at, &self.trajectory);
            tally.ended.push(score, s.terminated());
            tally.returns.push(self.episode_return);
            self.trajectory = vec![begin(self.env.as_mut(), &self.task, &mut self.rng, &mut self.raw_obs)?];
            self.state = self.machine.initial;
            self.episode_return = 0.0;
            self.begin_option();
        }
        if self.steps >= cfg.learning_starts && self.buffer.len() >= cfg.batch {
            let stats = self.update(cfg.batch);
            tally.critic.push(stats.critic_loss);
            tally.actor.extend(stats.actor_loss);
        }
        if let Some(h) = self.hierarchy.as_mut()
            && self.steps >= cfg.learning_starts
            && h.buffer.len() >= h.config.batch
        {
            tally.meta.push(h.update(&self.obs_rms, &self.machine, cfg.gamma, &mut self.rng));
        }
        Ok(())
    }

    /// One TD3 update on a minibatch from the replay buffer.
    fn update(&mut self, n: usize) -> super::td3::Td3Stats {
        let idx = self.buffer.sample(n, &mut self.rng);
        let (b, od, ad, m) = (&self.buffer, self.buffer.obs_dim, self.buffer.act_dim, self.context().1);
        let (mut x, mut x_next) = (Vec::with_capacity(n * (od + m)), Vec::with_capacity(n * (od + m)));
        let (mut a, mut r, mut done) =
            (Vec::with_capacity(n * ad), Vec::with_capacity(n), Vec::with_capacity(n));
        let row =
            |v: &[f32], i: usize| v[i * od..(i + 1) * od].iter().map(|x| *x as f64).collect::<Vec<f64>>();
        for &i in &idx {
            push_input(&self.obs_rms, &row(&b.obs, i), b.states[i] as usize, m, &mut x);
            push_input(&self.obs_rms, &row(&b.next_obs, i), b.next_states[i] as usize, m, &mut x_next);
            a.extend_from_slice(&b.actions[i * ad..(i + 1) * ad]);
            r.push(b.rewards[i]);
            done.push(b.dones[i]);
        }
        let batch = Batch { n, x: &x, a: &a, r: &r, x_next: &x_next, done: &done };
        self.td3.update(&batch, &mut self.rng)
    }

    /// The deployable policy: the actor's mean actions, tracking the machine's state.
    pub fn policy(&self) -> CrmPolicy<'_> {
        CrmPolicy { trainer: self, states: vec![], options: vec![], cache: MlpCache::default() }
    }

    /// Rebuilds a run from saved parts ([`crate::store::crm`]).
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn restored(
        settings: CrmSettings,
        td3: Td3,
        buffer: ReplayBuffer,
        obs_rms: RunningMeanStd,
        rng: ChaCha8Rng,
        env_state: &str,
        trajectory: Vec<Vec<f64>>,
        raw_obs: Vec<f64>,
        (state, episode_return): (usize, f64),
        (steps, chunks): (usize, usize),
        hierarchy: Option<Hierarchy>,
    ) -> Result<Self, RunError> {
        let mut t = Self::new(settings)?;
        let bad = |message: String| RunError::Setting { key: "state", message };
        let fits = match (&hierarchy, &t.hierarchy) {
            (Some(h), Some(f)) => {
                h.q_params.len() == f.q_params.len()
                    && h.options == f.options
                    && h.current.option < h.len()
                    && h.current.start_state < t.machine.len()
                    && h.current.start_obs.len() == t.raw_obs.len()
            }
            (None, None) => true,
            _ => false,
        };
        if !fits {
            return Err(bad("the saved meta-controller does not fit the settings' DHRM and machine".into()));
        }
        if td3.input_dim() != t.td3.input_dim() || td3.act_dim() != t.td3.act_dim() {
            return Err(bad("the saved networks do not fit the task's observation and machine".into()));
        }
        if raw_obs.len() != t.raw_obs.len() || state >= t.machine.len() || obs_rms.dim() != t.raw_obs.len() {
            return Err(bad("the saved episode does not fit the task".into()));
        }
        if buffer.obs_dim != t.buffer.obs_dim || buffer.act_dim != t.buffer.act_dim {
            return Err(bad("the saved replay buffer does not fit the task".into()));
        }
        t.env.restore_state(env_state)?;
        t.td3 = td3;
        t.buffer = buffer;
        t.obs_rms = obs_rms;
        t.rng = rng;
        t.trajectory = trajectory;
        t.raw_obs = raw_obs;
        t.state = state;
        t.episode_return = episode_return;
        t.steps = steps;
        t.chunks = chunks;
        t.hierarchy = hierarchy;
        Ok(t)
    }
}

/// A trained CRM (or DHRM) policy acting in [`super::flat::evaluate`]: mean actions of
/// the actor on the flat observation ⊕ each episode's machine state (DHRM: the option
/// the meta-controller picks greedily on entering each machine state).
pub struct CrmPolicy<'a> {
    trainer: &'a CrmTrainer,
    states: Vec<usize>,
    /// DHRM: each episode's option; `None` until picked in its current state.
    options: Vec<Option<usize>>,
    cache: MlpCache,
}

impl FlatDriver for CrmPolicy<'_> {
    fn begin(&mut self, n: usize) {
        self.states = vec![self.trainer.machine.initial; n];
        self.options = vec![None; n];
    }

    fn act(&mut self, raw: &[f64], n: usize, actions: &mut [f64]) {
        let t = self.trainer;
        let od = raw.len() / n.max(1);
        let m = t.machine.len();
        let mut x = Vec::with_capacity(n * t.td3.input_dim());
        for (i, row) in raw.chunks(od).enumerate() {
            match &t.hierarchy {
                Some(h) => {
                    let o = *self.options[i]
                        .get_or_insert_with(|| h.greedy(&t.obs_rms, row, (self.states[i], m)));
                    push_input(&t.obs_rms, row, o, h.len(), &mut x);
                }
                None => push_input(&t.obs_rms, row, self.states[i], m, &mut x),
            }
        }
        let a: Vec<f64> = t.td3.act(&x, n, &mut self.cache).iter().map(|a| *a as f64).collect();
        let ad = t.td3.act_dim();
        for (i, chunk) in a.chunks(ad).enumerate() {
            actions[i * ad..(i + 1) * ad].copy_from_slice(&scaled(chunk, t.env.as_ref()));
        }
    }

    fn after_step(&mut self, i: usize, labels: &Labels) -> bool {
        let m = &self.trainer.machine;
        let next = m.step(self.states[i], labels).0;
        if next != self.states[i] {
            self.options[i] = None;
        }
        self.states[i] = next;
        m.terminal[next]
    }
}
