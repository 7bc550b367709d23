//! TD3 (Fujimoto, van Hoof & Meger 2018): a deterministic actor with twin critics,
//! target networks, target-policy smoothing and delayed actor updates — the off-policy
//! learner under CRM. It knows inputs, not environments: the caller builds each
//! network input (observation ⊕ machine state) and scales actions to the robot's.
//!
//! * Critics: `y = r + γ (1 − done) min(Q₁', Q₂')(x', clip(μ'(x') + clip(ε, ±c), ±1))`,
//!   `ε ~ N(0, σ̃²)`; loss `mean (Q₁ − y)² + mean (Q₂ − y)²`.
//! * Actor, every `policy_delay` critic updates: maximise `mean Q₁(x, μ(x))`, through
//!   `∂Q₁/∂a` ([`TanhMlp::backward_with_input`]) and `μ = tanh(net)`.
//! * Targets: `θ' ← τ θ + (1 − τ) θ'` after each actor update.

use rand::Rng;
use rand_distr::StandardNormal;
use serde::{Deserialize, Serialize};

use crate::nn::adam::Adam;
use crate::nn::mlp::{MlpCache, TanhMlp};

/// TD3's hyper-parameters; every default names its source.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Td3Config {
    /// Hidden widths of actor and critics (64-64, the controller's; the CRM reference
    /// used 256-256, four times the updates' cost per layer on this CPU).
    pub hidden: Vec<usize>,
    /// Discount γ (0.99, TD3 and the controller).
    pub gamma: f64,
    /// Target-network step τ (0.005, TD3).
    pub tau: f64,
    /// Adam learning rate of actor and critics (1e-3, TD3).
    pub lr: f64,
    /// Minibatch size (100, the TD3 paper's; its code later used 256, 2.5 times the cost
    /// per update).
    pub batch: usize,
    /// Target-policy smoothing noise σ̃ in action units (0.2, TD3).
    pub policy_noise: f64,
    /// Its clip c (0.5, TD3).
    pub noise_clip: f64,
    /// Critic updates per actor update (2, TD3).
    pub policy_delay: usize,
    /// Exploration noise std in action units while acting (0.1, TD3).
    pub exploration_noise: f64,
    /// Environment steps with uniformly random actions before learning (10 000; TD3: 25 000
    /// on MuJoCo, over budgets of 1 M).
    pub learning_starts: usize,
    /// Replay capacity, in entries (1 000 000, TD3).
    pub buffer: usize,
}

impl Default for Td3Config {
    fn default() -> Self {
        Self {
            hidden: vec![64, 64],
            gamma: 0.99,
            tau: 0.005,
            lr: 1e-3,
            batch: 100,
            policy_noise: 0.2,
            noise_clip: 0.5,
            policy_delay: 2,
            exploration_noise: 0.1,
            learning_starts: 10_000,
            buffer: 1_000_000,
        }
    }
}

impl Td3Config {
    /// Checks every number, naming the first bad one by its key (`td3.tau`).
    pub fn validate(&self) -> Result<(), String> {
        if self.hidden.is_empty() || self.hidden.contains(&0) {
            return Err(format!("td3.hidden must be positive widths, got {:?}", self.hidden));
        }
        for (key, v) in
            [("td3.batch", self.batch), ("td3.policy_delay", self.policy_delay), ("td3.buffer", self.buffer)]
        {
            if v == 0 {
                return Err(format!("{key} must be at least 1"));
            }
        }
        for (key, v, lo, hi) in [
            ("td3.gamma", self.gamma, 0.0, 1.0),
            ("td3.tau", self.tau, 0.0, 1.0),
            ("td3.lr", self.lr, 0.0, f64::MAX),
            ("td3.policy_noise", self.policy_noise, 0.0, f64::MAX),
            ("td3.noise_clip", self.noise_clip, 0.0, f64::MAX),
            ("td3.exploration_noise", self.exploration_noise, 0.0, f64::MAX),
        ] {
            if !(v >= lo && v <= hi && v.is_finite()) {
                return Err(format!("{key} must be in [{lo}, {hi}], got {v}"));
            }
        }
        Ok(())
    }
}

/// A minibatch of prepared inputs.
pub struct Batch<'a> {
    /// Rows.
    pub n: usize,
    /// Network inputs before the step, `n × input`.
    pub x: &'a [f32],
    /// Actions in `[−1, 1]`, `n × act`.
    pub a: &'a [f32],
    /// Rewards.
    pub r: &'a [f32],
    /// Network inputs after the step.
    pub x_next: &'a [f32],
    /// Whether the step ended the episode.
    pub done: &'a [bool],
}

/// What one update measured.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Td3Stats {
    /// Mean squared TD error of the two critics, summed.
    pub critic_loss: f64,
    /// `−mean Q₁(x, μ(x))`, on updates that moved the actor.
    pub actor_loss: Option<f64>,
}

/// Actor, twin critics, their targets and optimisers.
#[derive(Clone, Debug)]
pub struct Td3 {
    /// Settings.
    pub config: Td3Config,
    actor: TanhMlp,
    critic: TanhMlp,
    /// Actor parameters.
    pub actor_params: Vec<f32>,
    /// Target actor.
    pub actor_target: Vec<f32>,
    /// Both critics' parameters, `[Q₁ | Q₂]`.
    pub critic_params: Vec<f32>,
    /// Target critics.
    pub critic_target: Vec<f32>,
    /// The actor's Adam.
    pub actor_adam: Adam,
    /// The critics' Adam.
    pub critic_adam: Adam,
    /// Critic updates done.
    pub updates: u64,
}

/// PyTorch's default initialisation of a linear layer: weights and biases uniform in
/// `±1/√fan_in`.
pub(crate) fn init_linear(mlp: &TanhMlp, rng: &mut impl Rng) -> Vec<f32> {
    let mut p = vec![0.0f32; mlp.num_params()];
    for l in 0..mlp.num_layers() {
        let bound = 1.0 / (mlp.sizes()[l] as f32).sqrt();
        let (w, b) = mlp.layer_ranges(l);
        for x in &mut p[w.start..b.end] {
            *x = rng.random_range(-bound..bound);
        }
    }
    p
}

impl Td3 {
    /// Fresh networks for `input` numbers per row and `act` actions.
    pub fn new(input: usize, act: usize, config: Td3Config, rng: &mut impl Rng) -> Self {
        let sizes = |i: usize, o: usize| [vec![i], config.hidden.clone(), vec![o]].concat();
        let actor = TanhMlp::new(&sizes(input, act));
        let critic = TanhMlp::new(&sizes(input + act, 1));
        let actor_params = init_linear(&actor, rng);
        let critic_params = [init_linear(&critic, rng), init_linear(&critic, rng)].concat();
        Self {
            actor_adam: Adam::new(actor_params.len()),
            critic_adam: Adam::new(critic_params.len()),
            actor_target: actor_params.clone(),
            critic_target: critic_params.clone(),
            actor_params,
            critic_params,
            actor,
            critic,
            config,
            updates: 0,
        }
    }

    /// Network input width.
    pub fn input_dim(&self) -> usize {
        self.actor.input_dim()
    }

    /// Action width.
    pub fn act_dim(&self) -> usize {
        self.actor.output_dim()
    }

    /// The actor's actions in `[−1, 1]` for `n` inputs.
    pub fn act(&self, x: &[f32], n: usize, cache: &mut MlpCache) -> Vec<f32> {
        self.actor.forward(&self.actor_params, x, n, cache).iter().map(|z| z.tanh()).collect()
    }

    /// `[x | a]` rows.
    fn joined(&self, x: &[f32], a: &[f32], n: usize) -> Vec<f32> {
        let (i, d) = (self.input_dim(), self.act_dim());
        let mut out = Vec::with_capacity(n * (i + d));
        for k in 0..n {
            out.extend_from_slice(&x[k * i..(k + 1) * i]);
            out.extend_from_slice(&a[k * d..(k + 1) * d]);
        }
        out
    }

    /// One critic update and, every `policy_delay`, an actor update and target step.
    pub fn update(&mut self, b: &Batch<'_>, rng: &mut impl Rng) -> Td3Stats {
        let cfg = self.config.clone();
        let (n, qn) = (b.n, self.critic.num_params());
        let mut cache = MlpCache::default();
        // Target: smoothed target action, the smaller target critic.
        let mut a_next = self.actor.forward(&self.actor_target, b.x_next, n, &mut cache).to_vec();
        for a in &mut a_next {
            let eps: f64 = rng.sample::<f64, _>(StandardNormal) * cfg.policy_noise;
            *a = (a.tanh() as f64 + eps.clamp(-cfg.noise_clip, cfg.noise_clip)).clamp(-1.0, 1.0) as f32;
        }
        let xa_next = self.joined(b.x_next, &a_next, n);
        let q1n = self.critic.forward(&self.critic_target[..qn], &xa_next, n, &mut cache).to_vec();
        let q2n = self.critic.forward(&self.critic_target[qn..], &xa_next, n, &mut cache).to_vec();
        let y: Vec<f32> = (0..n)
            .map(|k| {
                let boot = if b.done[k] { 0.0 } else { cfg.gamma as f32 * q1n[k].min(q2n[k]) };
                b.r[k] + boot
            })
            .collect();
        let (critic_loss, mut grad) = self.critic_gradient(b.x, b.a, &y, n);
        self.critic_adam.step(&mut self.critic_params, &mut grad, cfg.lr as f32, f32::INFINITY);
        self.updates += 1;
        if !self.updates.is_multiple_of(cfg.policy_delay as u64) {
            return Td3Stats { critic_loss, actor_loss: None };
        }
        let (actor_loss, mut g) = self.actor_gradient(b.x, n);
        self.actor_adam.step(&mut self.actor_params, &mut g, cfg.lr as f32, f32::INFINITY);
        let tau = cfg.tau as f32;
        for (t, p) in self.actor_target.iter_mut().zip(&self.actor_params) {
            *t = tau * p + (1.0 - tau) * *t;
        }
        for (t, p) in self.critic_target.iter_mut().zip(&self.critic_params) {
            *t = tau * p + (1.0 - tau) * *t;
        }
        Td3Stats { critic_loss, actor_loss: Some(actor_loss) }
    }

    /// The critics' loss `mean (Q₁ − y)² + mean (Q₂ − y)²` on `n` rows and its gradient
    /// with respect to `[Q₁ | Q₂]`'s parameters.
    pub fn critic_gradient(&self, x: &[f32], a: &[f32], y: &[f32], n: usize) -> (f64, Vec<f32>) {
        let qn = self.critic.num_params();
        let xa = self.joined(x, a, n);
        let mut cache = MlpCache::default();
        let mut grad = vec![0.0f32; 2 * qn];
        let mut loss = 0.0;
        for (c, g) in grad.chunks_mut(qn).enumerate() {
            let params = &self.critic_params[c * qn..(c + 1) * qn];
            let q = self.critic.forward(params, &xa, n, &mut cache).to_vec();
            let d_out: Vec<f32> = q.iter().zip(y).map(|(q, y)| 2.0 * (q - y) / n as f32).collect();
            loss += q.iter().zip(y).map(|(q, y)| ((q - y) as f64).powi(2)).sum::<f64>() / n as f64;
            self.critic.backward(params, &xa, n, &mut cache, &d_out, g);
        }
        (loss, grad)
    }

    /// The actor's loss `−mean Q₁(x, tanh(net(x)))` on `n` rows and its gradient with
    /// respect to the actor's parameters (through `∂Q₁/∂a` and the squashing `tanh`).
    pub fn actor_gradient(&self, x: &[f32], n: usize) -> (f64, Vec<f32>) {
        let (d, i, qn) = (self.act_dim(), self.input_dim(), self.critic.num_params());
        let (mut actor_cache, mut cache) = (MlpCache::default(), MlpCache::default());
        let z = self.actor.forward(&self.actor_params, x, n, &mut actor_cache).to_vec();
        let a: Vec<f32> = z.iter().map(|z| z.tanh()).collect();
        let xa = self.joined(x, &a, n);
        let q = self.critic.forward(&self.critic_params[..qn], &xa, n, &mut cache).to_vec();
        let loss = -q.iter().map(|q| *q as f64).sum::<f64>() / n as f64;
        let d_q = vec![-1.0 / n as f32; n];
        let mut unused = vec![0.0f32; qn];
        let mut d_xa = vec![0.0f32; xa.len()];
        let critic = &self.critic_params[..qn];
        self.critic.backward_with_input(critic, &xa, n, &mut cache, &d_q, &mut unused, &mut d_xa);
        let d_z: Vec<f32> =
            (0..n * d).map(|k| d_xa[(k / d) * (i + d) + i + k % d] * (1.0 - a[k] * a[k])).collect();
        let mut g = vec![0.0f32; self.actor_params.len()];
        self.actor.backward(&self.actor_params, x, n, &mut actor_cache, &d_z, &mut g);
        (loss, g)
    }

    /// `Q₁(x, a)` for `n` rows (diagnostics and tests).
    pub fn q1(&self, x: &[f32], a: &[f32], n: usize) -> Vec<f32> {
        let xa = self.joined(x, a, n);
        let qn = self.critic.num_params();
        self.critic.forward(&self.critic_params[..qn], &xa, n, &mut MlpCache::default()).to_vec()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    /// Both gradients against central differences of their losses, on a small network.
    #[test]
    fn the_critic_and_actor_gradients_match_finite_differences() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let cfg = Td3Config { hidden: vec![5, 4], ..Td3Config::default() };
        let td3 = Td3::new(3, 2, cfg, &mut rng);
        let n = 4;
        let mut v = |k: usize| (0..k).map(|_| rng.random_range(-1.0f32..1.0)).collect::<Vec<f32>>();
        let (x, a, y) = (v(n * 3), v(n * 2), v(n));
        let check = |analytic: &[f32], loss: &dyn Fn(&Td3) -> f64, set: &dyn Fn(&mut Td3, usize, f32)| {
            for k in (0..analytic.len()).step_by(7) {
                let (mut up, mut down) = (td3.clone(), td3.clone());
                set(&mut up, k, 1e-2);
                set(&mut down, k, -1e-2);
                let fd = (loss(&up) - loss(&down)) / 2e-2;
                assert!(
                    (fd - analytic[k] as f64).abs() < 2e-3 * (1.0 + fd.abs()),
                    "parameter {k}: {fd} vs {}",
                    analytic[k]
                );
            }
        };
        let (_, g) = td3.critic_gradient(&x, &a, &y, n);
        check(&g, &|t| t.critic_gradient(&x, &a, &y, n).0, &|t, k, h| t.critic_params[k] += h);
        let (_, g) = td3.actor_gradient(&x, n);
        check(&g, &|t| t.actor_gradient(&x, n).0, &|t, k, h| t.actor_params[k] += h);
    }

    /// A one-step problem (every transition ends the episode) whose reward is
    /// `−(a − 0.5)²`: the critic must learn it and the actor move to 0.5.
    #[test]
    fn the_actor_climbs_the_critic_to_the_best_action() {
        let mut rng = ChaCha8Rng::seed_from_u64(0);
        let cfg = Td3Config { batch: 64, ..Td3Config::default() };
        let mut td3 = Td3::new(1, 1, cfg, &mut rng);
        let x = vec![1.0f32; 64];
        let done = vec![true; 64];
        let mut cache = MlpCache::default();
        let start = td3.act(&[1.0], 1, &mut cache)[0];
        for _ in 0..1500 {
            let a: Vec<f32> = (0..64).map(|_| rng.random_range(-1.0..1.0)).collect();
            let r: Vec<f32> = a.iter().map(|a| -(a - 0.5) * (a - 0.5)).collect();
            td3.update(&Batch { n: 64, x: &x, a: &a, r: &r, x_next: &x, done: &done }, &mut rng);
        }
        let end = td3.act(&[1.0], 1, &mut cache)[0];
        assert!((end - 0.5).abs() < 0.1, "actor went from {start} to {end}, not to 0.5");
        let q = td3.q1(&[1.0, 1.0], &[0.5, -0.5], 2);
        assert!(q[0] > q[1] + 0.5, "critic does not rank the actions: {q:?}");
    }
}
