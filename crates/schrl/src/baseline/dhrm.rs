//! DHRM (Icarte et al., JAIR 2022, §5.2): hierarchical RL over a reward machine, the
//! deep variant — one option per edge of the machine that makes progress, and a
//! meta-controller that picks which option to follow.
//!
//! * *Options*: every edge `u → v` with `u ≠ v` and a positive reward (edges into a
//!   failure state are outcomes to avoid, not goals to pursue). Option `o = (u, v)`
//!   starts in machine state `u` and ends when the machine leaves `u`: reward `r_max`
//!   when it moved to `v`, the machine's own reward when that is negative (a collision)
//!   and 0 otherwise (another edge fired first); 0 on every step that stays. One TD3
//!   actor-critic ([`super::td3`]) conditioned on the option's one-hot serves them all,
//!   and every real step becomes one experience per option, as in the reference.
//! * *Meta-controller*: DQN over the flat observation ⊕ the machine state's one-hot,
//!   one Q-value per option, the options that do not start in the current state masked
//!   out. Its experience is one option run, `(s, u, o, R, s', u', k)` with
//!   `R = Σ γ^i r_i` the machine's discounted reward over the `k` steps the option ran;
//!   target `R + γ^k max_{o' from u'} Q̄(s', u', o')`. ε-greedy, ε falling linearly.
//!
//! The trainer that runs it is CRM's ([`super::crm::CrmTrainer`]) with
//! [`super::crm::CrmSettings::dhrm`] set: the same flat observation, environment loop,
//! replay of real steps, evaluation and checkpoints; this module is what differs.

use rand::Rng;
use serde::{Deserialize, Serialize};

use super::replay::{ReplayBuffer, Transition};
use super::reward_machine::{Labels, RewardMachine};
use super::td3::init_linear;
use crate::control::normalize::RunningMeanStd;
use crate::nn::adam::Adam;
use crate::nn::mlp::{MlpCache, TanhMlp};

/// The meta-controller's and the options' settings; every default names its source.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DhrmConfig {
    /// Hidden widths of the meta-controller's Q-network (64-64, the controller's;
    /// OpenAI baselines' DQN MLP used one layer of 64).
    pub hidden: Vec<usize>,
    /// Adam learning rate (5e-4, baselines' `deepq`).
    pub lr: f64,
    /// Minibatch size (32, baselines' `deepq`).
    pub batch: usize,
    /// Meta replay capacity in option runs (50 000, baselines' `deepq`).
    pub buffer: usize,
    /// Meta updates between target-network copies (500, baselines' `deepq`).
    pub target_every: usize,
    /// ε falls linearly from 1 to `final_epsilon` over this fraction of the step budget
    /// (0.1, baselines' `exploration_fraction`).
    pub exploration_fraction: f64,
    /// ε after that (0.02, baselines' `exploration_final_eps`).
    pub final_epsilon: f64,
    /// Option reward for reaching its target state (1, the reference's `r_max`).
    pub r_max: f64,
}

impl Default for DhrmConfig {
    fn default() -> Self {
        Self {
            hidden: vec![64, 64],
            lr: 5e-4,
            batch: 32,
            buffer: 50_000,
            target_every: 500,
            exploration_fraction: 0.1,
            final_epsilon: 0.02,
            r_max: 1.0,
        }
    }
}

impl DhrmConfig {
    /// Checks every number, naming the first bad one by its key (`dhrm.lr`).
    pub fn validate(&self) -> Result<(), String> {
        if self.hidden.is_empty() || self.hidden.contains(&0) {
            return Err(format!("dhrm.hidden must be positive widths, got {:?}", self.hidden));
        }
        for (key, v) in [
            ("dhrm.batch", self.batch),
            ("dhrm.buffer", self.buffer),
            ("dhrm.target_every", self.target_every),
        ] {
            if v == 0 {
                return Err(format!("{key} must be at least 1"));
            }
        }
        for (key, v, lo, hi) in [
            ("dhrm.lr", self.lr, 0.0, f64::MAX),
            ("dhrm.exploration_fraction", self.exploration_fraction, 0.0, 1.0),
            ("dhrm.final_epsilon", self.final_epsilon, 0.0, 1.0),
            ("dhrm.r_max", self.r_max, 0.0, f64::MAX),
        ] {
            if !(v >= lo && v <= hi && v.is_finite()) {
                return Err(format!("{key} must be in [{lo}, {hi}], got {v}"));
            }
        }
        Ok(())
    }
}

/// The option now followed, and what its run has collected so far.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct OptionRun {
    /// The option.
    pub option: usize,
    /// The flat observation it started from.
    pub start_obs: Vec<f64>,
    /// The machine state it started in.
    pub start_state: usize,
    /// `Σ γ^i r_i` of the machine's rewards so far.
    pub discounted_return: f64,
    /// Steps it has run.
    pub steps: usize,
}

/// Options, the meta-controller and its replay: DHRM's part of a run.
#[derive(Clone, Debug)]
pub struct Hierarchy {
    /// Settings.
    pub config: DhrmConfig,
    /// The options, `(from, to)` machine states.
    pub options: Vec<(usize, usize)>,
    q: TanhMlp,
    /// The meta Q-network's parameters.
    pub q_params: Vec<f32>,
    /// Its target copy.
    pub q_target: Vec<f32>,
    /// Its Adam.
    pub adam: Adam,
    /// Meta updates done.
    pub updates: u64,
    /// Option runs: `states` the machine state at the start, `actions` the pair
    /// `(option, steps it ran)`, `rewards` its discounted return.
    pub buffer: ReplayBuffer,
    /// The option being followed.
    pub current: OptionRun,
}

/// Standardised `raw` ⊕ the one-hot of `k` of `of`, appended to `out`: every network
/// input of the off-policy baselines.
pub(crate) fn push_input(rms: &RunningMeanStd, raw: &[f64], k: usize, of: usize, out: &mut Vec<f32>) {
    let at = out.len();
    out.resize(at + raw.len(), 0.0);
    rms.normalize_into(raw, &mut out[at..]);
    out.extend((0..of).map(|i| f32::from(u8::from(i == k))));
}

impl Hierarchy {
    /// The options of `machine` and a fresh meta-controller for flat observations of
    /// `obs_dim` numbers. Fails when a live machine state has no option (nothing for
    /// the meta-controller to pick there).
    pub fn new(
        config: DhrmConfig,
        machine: &RewardMachine,
        obs_dim: usize,
        rng: &mut impl Rng,
    ) -> Result<Self, String> {
        config.validate()?;
        let options = machine.options();
        for u in (0..machine.len()).filter(|u| !machine.terminal[*u]) {
            if !options.iter().any(|(from, _)| *from == u) {
                return Err(format!(
                    "machine state '{}' is not terminal but no edge leaves it with a positive reward: \
                     DHRM would have no option to pick there",
                    machine.states[u]
                ));
            }
        }
        let sizes = [vec![obs_dim + machine.len()], config.hidden.clone(), vec![options.len()]].concat();
        let q = TanhMlp::new(&sizes);
        let q_params = init_linear(&q, rng);
        let start = machine.initial;
        Ok(Self {
            adam: Adam::new(q_params.len()),
            q_target: q_params.clone(),
            q_params,
            q,
            updates: 0,
            buffer: ReplayBuffer::new(config.buffer, obs_dim, 2),
            current: OptionRun {
                option: 0,
                start_obs: vec![],
                start_state: start,
                discounted_return: 0.0,
                steps: 0,
            },
            options,
            config,
        })
    }

    /// The number of options.
    pub fn len(&self) -> usize {
        self.options.len()
    }

    /// `true` without options (never: [`Hierarchy::new`] refuses such a machine).
    pub fn is_empty(&self) -> bool {
        self.options.is_empty()
    }

    /// Option `o`'s reward on a step with `labels` and whether the step ends it (module
    /// docs), whatever the machine's real state.
    pub fn outcome(&self, o: usize, machine: &RewardMachine, labels: &Labels) -> (f64, bool) {
        let (from, to) = self.options[o];
        let (next, reward) = machine.step(from, labels);
        if next == to {
            (self.config.r_max, true)
        } else if next != from {
            (reward.min(0.0), true)
        } else {
            (0.0, false)
        }
    }

    /// ε after `steps` of a budget of `budget` environment steps.
    pub fn epsilon(&self, steps: usize, budget: usize) -> f64 {
        let span = self.config.exploration_fraction * budget as f64;
        let f = if span > 0.0 { (steps as f64 / span).min(1.0) } else { 1.0 };
        1.0 + f * (self.config.final_epsilon - 1.0)
    }

    /// The option with the highest Q among those starting in `state`, or with
    /// probability `epsilon` one of them uniformly.
    pub fn choose(
        &self,
        rms: &RunningMeanStd,
        obs: &[f64],
        (state, states): (usize, usize),
        epsilon: f64,
        rng: &mut impl Rng,
    ) -> usize {
        if epsilon > 0.0 && rng.random::<f64>() < epsilon {
            let valid: Vec<usize> = (0..self.len()).filter(|o| self.options[*o].0 == state).collect();
            if !valid.is_empty() {
                return valid[rng.random_range(0..valid.len())];
            }
        }
        self.greedy(rms, obs, (state, states))
    }

    /// The option with the highest Q among those starting in `state` (ties: the first
    /// in file order; a terminal state, where none starts: option 0, never run).
    pub fn greedy(&self, rms: &RunningMeanStd, obs: &[f64], (state, states): (usize, usize)) -> usize {
        let mut x = Vec::with_capacity(self.q.input_dim());
        push_input(rms, obs, state, states, &mut x);
        let q = self.q.forward(&self.q_params, &x, 1, &mut MlpCache::default()).to_vec();
        let mut best: Option<usize> = None;
        for o in (0..self.len()).filter(|o| self.options[*o].0 == state) {
            if best.is_none_or(|b| q[o] > q[b]) {
                best = Some(o);
            }
        }
        best.unwrap_or(0)
    }

    /// Starts option `option` in machine state `state` from observation `obs`.
    pub fn begin(&mut self, option: usize, obs: &[f64], state: usize) {
        self.current = OptionRun {
            option,
            start_obs: obs.to_vec(),
            start_state: state,
            discounted_return: 0.0,
            steps: 0,
        };
    }

    /// Counts one step of the current option that paid the machine's `reward`.
    pub fn record(&mut self, reward: f64, gamma: f64) {
        let c = &mut self.current;
        c.discounted_return += gamma.powi(c.steps as i32) * reward;
        c.steps += 1;
    }

    /// Ends the current option in `state` at `obs`, storing its run.
    pub fn end(&mut self, obs: &[f64], state: usize, done: bool) {
        let c = &self.current;
        self.buffer.push(&Transition {
            obs: &c.start_obs,
            state: c.start_state,
            action: &[c.option as f64, c.steps as f64],
            reward: c.discounted_return,
            next_obs: obs,
            next_state: state,
            done,
        });
    }

    /// One DQN update on a minibatch of option runs; returns its loss.
    pub fn update(
        &mut self,
        rms: &RunningMeanStd,
        machine: &RewardMachine,
        gamma: f64,
        rng: &mut impl Rng,
    ) -> f64 {
        let n = self.config.batch;
        let idx = self.buffer.sample(n, rng);
        let (b, od, m) = (&self.buffer, self.buffer.obs_dim, machine.len());
        let (mut x, mut x_next) = (Vec::with_capacity(n * (od + m)), Vec::with_capacity(n * (od + m)));
        let row =
            |v: &[f32], i: usize| v[i * od..(i + 1) * od].iter().map(|x| *x as f64).collect::<Vec<f64>>();
        for &i in &idx {
            push_input(rms, &row(&b.obs, i), b.states[i] as usize, m, &mut x);
            push_input(rms, &row(&b.next_obs, i), b.next_states[i] as usize, m, &mut x_next);
        }
        let mut cache = MlpCache::default();
        let q_next = self.q.forward(&self.q_target, &x_next, n, &mut cache).to_vec();
        let k = self.len();
        let y: Vec<f32> = idx
            .iter()
            .enumerate()
            .map(|(r, &i)| {
                let (u_next, steps) = (b.next_states[i] as usize, b.actions[i * 2 + 1]);
                let best = (0..k)
                    .filter(|o| self.options[*o].0 == u_next)
                    .map(|o| q_next[r * k + o])
                    .fold(f32::NEG_INFINITY, f32::max);
                let boot = if b.dones[i] || best == f32::NEG_INFINITY {
                    0.0
                } else {
                    (gamma as f32).powf(steps) * best
                };
                b.rewards[i] + boot
            })
            .collect();
        let chosen: Vec<usize> = idx.iter().map(|&i| b.actions[i * 2] as usize).collect();
        let (loss, mut grad) = self.gradient(&x, &chosen, &y);
        self.adam.step(&mut self.q_params, &mut grad, self.config.lr as f32, f32::INFINITY);
        self.updates += 1;
        if self.updates.is_multiple_of(self.config.target_every as u64) {
            self.q_target.copy_from_slice(&self.q_params);
        }
        loss
    }

    /// The loss `mean (Q(x, o) − y)²` over rows of inputs `x`, chosen options and
    /// targets `y`, and its gradient with respect to the Q-network's parameters.
    pub fn gradient(&self, x: &[f32], chosen: &[usize], y: &[f32]) -> (f64, Vec<f32>) {
        let (n, k) = (y.len(), self.len());
        let mut cache = MlpCache::default();
        let q = self.q.forward(&self.q_params, x, n, &mut cache).to_vec();
        let mut d_out = vec![0.0f32; n * k];
        let mut loss = 0.0;
        for r in 0..n {
            let e = q[r * k + chosen[r]] - y[r];
            loss += (e as f64).powi(2) / n as f64;
            d_out[r * k + chosen[r]] = 2.0 * e / n as f32;
        }
        let mut grad = vec![0.0f32; self.q_params.len()];
        self.q.backward(&self.q_params, x, n, &mut cache, &d_out, &mut grad);
        (loss, grad)
    }

    /// `Q(x, ·)` for `n` rows (tests and diagnostics).
    pub fn q_values(&self, x: &[f32], n: usize) -> Vec<f32> {
        self.q.forward(&self.q_params, x, n, &mut MlpCache::default()).to_vec()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::task::{Task, TaskKind};
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    fn branch() -> (RewardMachine, Hierarchy) {
        let m = RewardMachine::shipped(&Task::point(TaskKind::Branch)).unwrap();
        let h = Hierarchy::new(
            DhrmConfig { hidden: vec![5], ..DhrmConfig::default() },
            &m,
            3,
            &mut ChaCha8Rng::seed_from_u64(1),
        )
        .unwrap();
        (m, h)
    }

    /// The meta-controller's DQN gradient against central differences of its loss.
    #[test]
    fn the_meta_gradient_matches_finite_differences() {
        let (m, mut h) = branch();
        let n = 4;
        let x: Vec<f32> = (0..n * (3 + m.len())).map(|i| ((i * 37 % 11) as f32 - 5.0) / 7.0).collect();
        let chosen = [0, 2, 1, 4];
        let y = [0.3f32, -0.2, 0.9, 0.1];
        let (_, g) = h.gradient(&x, &chosen, &y);
        let eps = 1e-2f32;
        for i in (0..h.q_params.len()).step_by(3) {
            let keep = h.q_params[i];
            h.q_params[i] = keep + eps;
            let up = h.gradient(&x, &chosen, &y).0;
            h.q_params[i] = keep - eps;
            let down = h.gradient(&x, &chosen, &y).0;
            h.q_params[i] = keep;
            let fd = (up - down) / (2.0 * eps as f64);
            assert!((fd - g[i] as f64).abs() < 2e-3 * (1.0 + fd.abs()), "param {i}: {fd} vs {}", g[i]);
        }
    }

    #[test]
    fn options_are_the_progress_edges_and_pay_on_their_own_target_only() {
        let (m, h) = branch();
        let name = |u: usize| m.states[u].as_str();
        let names: Vec<(&str, &str)> = h.options.iter().map(|(a, b)| (name(*a), name(*b))).collect();
        assert!(names.contains(&("u0", "after_a1")));
        assert!(names.iter().all(|(_, to)| *to != "fail"), "{names:?}");
        let to_a1 = names.iter().position(|e| *e == ("u0", "after_a1")).unwrap();
        let to_a0 = names.iter().position(|e| *e == ("u0", "after_a0")).unwrap();
        let labels = |xs: &[&str]| Labels(xs.iter().map(|s| s.to_string()).collect());
        assert_eq!(h.outcome(to_a1, &m, &labels(&["a1"])), (1.0, true));
        assert_eq!(h.outcome(to_a0, &m, &labels(&["a1"])), (0.0, true), "another edge fired");
        assert_eq!(h.outcome(to_a0, &m, &labels(&["collision"])), (-1.0, true));
        assert_eq!(h.outcome(to_a0, &m, &labels(&[])), (0.0, false));
    }

    #[test]
    fn the_meta_controller_picks_only_options_of_the_current_state() {
        let (m, h) = branch();
        let rms = RunningMeanStd::new(3);
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        for eps in [0.0, 1.0] {
            for _ in 0..20 {
                let o = h.choose(&rms, &[0.1, 0.2, 0.3], (m.initial, m.len()), eps, &mut rng);
                assert_eq!(h.options[o].0, m.initial);
            }
        }
        assert_eq!(h.epsilon(0, 1000), 1.0);
        assert!((h.epsilon(50, 1000) - 0.51).abs() < 1e-12);
        assert!((h.epsilon(500, 1000) - 0.02).abs() < 1e-12);
    }

    /// One option run worth `r_max` from the start state, replayed: Q of that option
    /// rises towards it and above the options never rewarded.
    #[test]
    fn dqn_learns_which_option_pays() {
        let (m, mut h) = branch();
        let rms = RunningMeanStd::new(3);
        let mut rng = ChaCha8Rng::seed_from_u64(4);
        let obs = [0.5, -0.5, 0.0];
        let done = m.states.iter().position(|s| s == "done").unwrap();
        let first: Vec<usize> = (0..h.len()).filter(|o| h.options[*o].0 == m.initial).collect();
        for o in first {
            h.begin(o, &obs, m.initial);
            h.record(if o == 1 { 1.0 } else { 0.0 }, 0.99);
            h.end(&obs, done, true);
        }
        for _ in 0..400 {
            h.update(&rms, &m, 0.99, &mut rng);
        }
        let mut x = vec![];
        push_input(&rms, &obs, m.initial, m.len(), &mut x);
        let q = h.q_values(&x, 1);
        assert!(q[1] > 0.8 && q[0] < 0.2 && q[2] < 0.2, "{q:?}");
        assert_eq!(h.choose(&rms, &obs, (m.initial, m.len()), 0.0, &mut rng), 1);
    }
}
