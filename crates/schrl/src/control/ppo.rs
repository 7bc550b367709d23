//! Proximal policy optimisation (Schulman et al. 2017) for continuous actions,
//! written to match CleanRL's `ppo_continuous_action.py` step by step: GAE,
//! per-minibatch advantage normalisation, the clipped surrogate, the clipped value
//! loss, an entropy bonus, Adam with global gradient-norm clipping, linear
//! learning-rate annealing, and an optional KL early stop.

use rand::Rng;
use rand::seq::SliceRandom;
use serde::{Deserialize, Serialize};

use super::policy::{ActorCritic, HALF_LN_2PI, PolicyCache};
use crate::nn::adam::Adam;

/// PPO hyper-parameters. Every default names its source.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PpoConfig {
    /// Environments stepped together. 8 (this project's choice: decorrelates the
    /// rollout and amortises the network call; the reference used SB3's vectorised
    /// environments).
    pub num_envs: usize,
    /// Environment steps per update, over all environments (reference: 4000;
    /// CleanRL: 2048). Must be a multiple of `num_envs`.
    pub rollout: usize,
    /// Minibatch size (reference: 100; CleanRL: 2048 / 32 = 64).
    pub minibatch: usize,
    /// Passes over each rollout (reference and CleanRL: 10).
    pub epochs: usize,
    /// Adam learning rate (reference and CleanRL: 3e-4).
    pub lr: f64,
    /// Anneal the learning rate linearly to 0 over the run (CleanRL: true).
    pub anneal_lr: bool,
    /// Discount γ (reference and CleanRL: 0.99).
    pub gamma: f64,
    /// GAE λ (reference and CleanRL: 0.95).
    pub gae_lambda: f64,
    /// Clip range of the probability ratio (reference and CleanRL: 0.2).
    pub clip: f64,
    /// Clip the value loss around the old values with the same range (CleanRL: true).
    pub clip_value_loss: bool,
    /// Entropy coefficient (reference and CleanRL: 0).
    pub ent_coef: f64,
    /// Value-loss coefficient (reference and CleanRL: 0.5).
    pub vf_coef: f64,
    /// Global gradient-norm limit (reference and CleanRL: 0.5).
    pub max_grad_norm: f64,
    /// Standardise advantages within each minibatch (CleanRL: true).
    pub norm_adv: bool,
    /// Standardise observations with running statistics (CleanRL: true).
    pub norm_obs: bool,
    /// Scale rewards by the running std of the discounted return (CleanRL: true).
    pub norm_reward: bool,
    /// Stop an update's epochs once the approximate KL exceeds this (CleanRL: none).
    pub target_kl: Option<f64>,
    /// Hidden widths of actor and critic (reference and CleanRL: 64-64).
    pub hidden: Vec<usize>,
}

impl Default for PpoConfig {
    /// The reference implementation's hyper-parameters (see [`PpoConfig::reference`]).
    fn default() -> Self {
        Self::reference()
    }
}

impl PpoConfig {
    /// The authors' hyper-parameters (reference setup: lr 3e-4, rollout 4000,
    /// minibatch 100, 10 epochs, γ 0.99, λ 0.95, clip 0.2, value coefficient 0.5,
    /// gradient norm 0.5, 64-64 MLPs), with CleanRL's choices where they are silent.
    pub fn reference() -> Self {
        Self {
            num_envs: 8,
            rollout: 4000,
            minibatch: 100,
            epochs: 10,
            lr: 3e-4,
            anneal_lr: true,
            gamma: 0.99,
            gae_lambda: 0.95,
            clip: 0.2,
            clip_value_loss: true,
            ent_coef: 0.0,
            vf_coef: 0.5,
            max_grad_norm: 0.5,
            norm_adv: true,
            norm_obs: true,
            norm_reward: true,
            target_kl: None,
            hidden: vec![64, 64],
        }
    }

    /// CleanRL's `ppo_continuous_action.py` defaults (one environment there; 8 here
    /// with the same 2048-step rollout).
    pub fn cleanrl() -> Self {
        Self { rollout: 2048, minibatch: 64, ..Self::reference() }
    }

    /// The preset called `name` (`reference` or `cleanrl`).
    pub fn preset(name: &str) -> Option<Self> {
        match name {
            "reference" => Some(Self::reference()),
            "cleanrl" => Some(Self::cleanrl()),
            _ => None,
        }
    }

    /// Checks the numbers, naming the first bad field.
    pub fn validate(&self) -> Result<(), String> {
        let bad = |field: &str, why: &str| Err(format!("ppo.{field}: {why}"));
        if self.num_envs == 0 {
            return bad("num_envs", "must be at least 1");
        }
        if self.rollout == 0 || !self.rollout.is_multiple_of(self.num_envs) {
            return bad("rollout", &format!("must be a positive multiple of num_envs ({})", self.num_envs));
        }
        if self.minibatch == 0 || self.minibatch > self.rollout {
            return bad("minibatch", "must be between 1 and the rollout length");
        }
        if self.epochs == 0 {
            return bad("epochs", "must be at least 1");
        }
        for (name, v, lo, hi) in [
            ("lr", self.lr, 0.0, 1.0),
            ("gamma", self.gamma, 0.0, 1.0),
            ("gae_lambda", self.gae_lambda, 0.0, 1.0),
            ("clip", self.clip, 0.0, 10.0),
            ("max_grad_norm", self.max_grad_norm, 0.0, f64::MAX),
        ] {
            if !(v > lo && v <= hi) {
                return bad(name, &format!("{v} is outside ({lo}, {hi}]"));
            }
        }
        if !(self.ent_coef >= 0.0 && self.vf_coef >= 0.0) {
            return bad("ent_coef/vf_coef", "must be non-negative");
        }
        if self.hidden.is_empty() || self.hidden.contains(&0) {
            return bad("hidden", "needs at least one layer, each of positive width");
        }
        Ok(())
    }

    /// Steps per environment per rollout.
    pub fn steps_per_env(&self) -> usize {
        self.rollout / self.num_envs
    }
}

/// One rollout, time-major (`[t][env]`).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct RolloutBuffer {
    /// Environments.
    pub num_envs: usize,
    /// Observation length.
    pub obs_dim: usize,
    /// Action length.
    pub act_dim: usize,
    /// Normalised observations.
    pub obs: Vec<f32>,
    /// Sampled (unclipped) actions.
    pub actions: Vec<f32>,
    /// Their log-probabilities under the acting policy.
    pub log_probs: Vec<f32>,
    /// Value estimates of the observations.
    pub values: Vec<f32>,
    /// Rewards (scaled), with `γ·V(final observation)` added where an episode was
    /// cut by its time limit (bootstrapping truncation, as SB3 does).
    pub rewards: Vec<f32>,
    /// Whether the episode ended after this step (terminal or truncated).
    pub ends: Vec<bool>,
    /// Values of the observations after the last step.
    pub last_values: Vec<f32>,
}

impl RolloutBuffer {
    /// An empty buffer.
    pub fn new(num_envs: usize, obs_dim: usize, act_dim: usize) -> Self {
        Self {
            num_envs,
            obs_dim,
            act_dim,
            obs: Vec::new(),
            actions: Vec::new(),
            log_probs: Vec::new(),
            values: Vec::new(),
            rewards: Vec::new(),
            ends: Vec::new(),
            last_values: vec![0.0; num_envs],
        }
    }

    /// Forgets the stored steps.
    pub fn clear(&mut self) {
        self.obs.clear();
        self.actions.clear();
        self.log_probs.clear();
        self.values.clear();
        self.rewards.clear();
        self.ends.clear();
    }

    /// Stored transitions (over all environments).
    pub fn len(&self) -> usize {
        self.values.len()
    }

    /// `true` when nothing is stored.
    pub fn is_empty(&self) -> bool {
        self.values.is_empty()
    }
}

/// Generalised advantage estimation (Schulman et al. 2016) over a time-major
/// rollout: `δ_t = r_t + γ V_{t+1} (1 − end_t) − V_t`,
/// `A_t = δ_t + γ λ (1 − end_t) A_{t+1}`. Returns `(advantages, returns = A + V)`.
pub fn gae(
    rewards: &[f32],
    values: &[f32],
    ends: &[bool],
    last_values: &[f32],
    gamma: f32,
    lambda: f32,
) -> (Vec<f32>, Vec<f32>) {
    let n = last_values.len();
    let steps = rewards.len() / n;
    let mut adv = vec![0.0; rewards.len()];
    let mut next_adv = vec![0.0f32; n];
    for t in (0..steps).rev() {
        for e in 0..n {
            let i = t * n + e;
            let next_v = if t + 1 == steps { last_values[e] } else { values[i + n] };
            let keep = if ends[i] { 0.0 } else { 1.0 };
            let delta = rewards[i] + gamma * next_v * keep - values[i];
            next_adv[e] = delta + gamma * lambda * keep * next_adv[e];
            adv[i] = next_adv[e];
        }
    }
    let ret = adv.iter().zip(values).map(|(a, v)| a + v).collect();
    (adv, ret)
}

/// One minibatch, gathered from a rollout.
#[derive(Clone, Debug, Default)]
pub struct Minibatch {
    /// Samples.
    pub n: usize,
    /// Normalised observations (`n × obs_dim`).
    pub obs: Vec<f32>,
    /// Actions (`n × act_dim`).
    pub actions: Vec<f32>,
    /// Log-probabilities under the acting policy.
    pub old_log_probs: Vec<f32>,
    /// Values under the acting critic.
    pub old_values: Vec<f32>,
    /// Advantages (raw; normalised inside the loss if configured).
    pub advantages: Vec<f32>,
    /// Value targets.
    pub returns: Vec<f32>,
}

/// Loss terms and diagnostics of one minibatch.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct LossParts {
    /// Clipped surrogate loss.
    pub policy_loss: f32,
    /// (Clipped) value loss, with CleanRL's factor ½.
    pub value_loss: f32,
    /// Mean entropy of the policy.
    pub entropy: f32,
    /// Approximate KL from the acting policy, `E[(r − 1) − ln r]` (Schulman's k3).
    pub approx_kl: f32,
    /// Fraction of samples whose ratio left the clip range.
    pub clip_fraction: f32,
    /// The total loss that was differentiated.
    pub total: f32,
}

/// The PPO loss of `mb` under `policy` and its gradient with respect to all
/// parameters (written, not added, to `grads`). The backward pass is the analytic
/// one of the loss CleanRL builds with autograd (tested against candle's autograd).
pub fn loss_and_grad(
    policy: &ActorCritic,
    cfg: &PpoConfig,
    mb: &Minibatch,
    cache: &mut PolicyCache,
    grads: &mut [f32],
) -> LossParts {
    let (n, d) = (mb.n, policy.act_dim());
    let clip = cfg.clip as f32;
    let log_std: Vec<f32> = policy.log_std().to_vec();
    let inv_var: Vec<f32> = log_std.iter().map(|l| (-2.0 * l).exp()).collect();
    let norm_const = log_std.iter().sum::<f32>() + d as f32 * HALF_LN_2PI;

    let adv: Vec<f32> = if cfg.norm_adv && n > 1 {
        let m = mb.advantages.iter().sum::<f32>() / n as f32;
        // torch.std is the unbiased estimate.
        let var = mb.advantages.iter().map(|a| (a - m) * (a - m)).sum::<f32>() / (n - 1) as f32;
        let s = 1.0 / (var.sqrt() + 1e-8);
        mb.advantages.iter().map(|a| (a - m) * s).collect()
    } else {
        mb.advantages.clone()
    };

    grads.fill(0.0);
    let mut parts = LossParts::default();
    let mut d_mean = vec![0.0f32; n * d];
    let mut d_log_std = vec![0.0f32; d];
    let inv_n = 1.0 / n as f32;
    {
        let mean = policy.mean(&mb.obs, n, cache);
        for i in 0..n {
            let mut quad = 0.0;
            for j in 0..d {
                let z = mb.actions[i * d + j] - mean[i * d + j];
                quad += z * z * inv_var[j];
            }
            let log_prob = -0.5 * quad - norm_const;
            let log_ratio = log_prob - mb.old_log_probs[i];
            let ratio = log_ratio.exp();
            let a = adv[i];
            let unclipped = -a * ratio;
            let clipped = -a * ratio.clamp(1.0 - clip, 1.0 + clip);
            parts.policy_loss += unclipped.max(clipped) * inv_n;
            parts.approx_kl += ((ratio - 1.0) - log_ratio) * inv_n;
            parts.clip_fraction += if (ratio - 1.0).abs() > clip { inv_n } else { 0.0 };
            // The max picks the unclipped branch, or the clipped one whose ratio is
            // then constant (zero gradient).
            let g = if unclipped >= clipped { -a * ratio * inv_n } else { 0.0 };
            if g != 0.0 {
                for j in 0..d {
                    let z = mb.actions[i * d + j] - mean[i * d + j];
                    d_mean[i * d + j] = g * z * inv_var[j];
                    d_log_std[j] += g * (z * z * inv_var[j] - 1.0);
                }
            }
        }
    }
    parts.entropy = log_std.iter().sum::<f32>() + d as f32 * (0.5 + HALF_LN_2PI);
    for g in d_log_std.iter_mut() {
        *g -= cfg.ent_coef as f32;
    }

    let mut d_value = vec![0.0f32; n];
    {
        let values = policy.value(&mb.obs, n, cache);
        let vf = cfg.vf_coef as f32;
        for i in 0..n {
            let (v, r, old) = (values[i], mb.returns[i], mb.old_values[i]);
            let u = (v - r) * (v - r);
            if cfg.clip_value_loss {
                let vc = old + (v - old).clamp(-clip, clip);
                let c = (vc - r) * (vc - r);
                parts.value_loss += 0.5 * u.max(c) * inv_n;
                d_value[i] = if u >= c {
                    vf * (v - r) * inv_n
                } else if (v - old).abs() < clip {
                    vf * (vc - r) * inv_n
                } else {
                    0.0
                };
            } else {
                parts.value_loss += 0.5 * u * inv_n;
                d_value[i] = vf * (v - r) * inv_n;
            }
        }
    }
    parts.total =
        parts.policy_loss - cfg.ent_coef as f32 * parts.entropy + cfg.vf_coef as f32 * parts.value_loss;

    let (pa, pc, _) = policy.split(&policy.params);
    let (ga, gc, gl) = policy.split_mut(grads);
    policy.actor().backward(pa, &mb.obs, n, &mut cache.actor, &d_mean, ga);
    policy.critic().backward(pc, &mb.obs, n, &mut cache.critic, &d_value, gc);
    gl.copy_from_slice(&d_log_std);
    parts
}

/// Averages of one update's minibatch statistics.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct UpdateStats {
    /// Mean loss parts over the minibatches taken.
    pub loss: LossParts,
    /// Explained variance of the value predictions before the update.
    pub explained_variance: f32,
    /// Minibatch steps taken.
    pub minibatches: usize,
    /// Mean gradient norm before clipping.
    pub grad_norm: f32,
}

/// The optimising half of PPO: owns the optimiser and scratch space.
#[derive(Clone, Debug)]
pub struct PpoLearner {
    /// Hyper-parameters.
    pub config: PpoConfig,
    /// Optimiser state.
    pub adam: Adam,
    cache: PolicyCache,
    grads: Vec<f32>,
    mb: Minibatch,
}

impl PpoLearner {
    /// A learner for `policy`.
    pub fn new(config: PpoConfig, policy: &ActorCritic) -> Self {
        let n = policy.params.len();
        Self {
            config,
            adam: Adam::new(n),
            cache: PolicyCache::default(),
            grads: vec![0.0; n],
            mb: Minibatch::default(),
        }
    }

    /// Runs `epochs` passes of shuffled minibatches over `buf` with learning rate
    /// `lr`.
    pub fn update(
        &mut self,
        policy: &mut ActorCritic,
        buf: &RolloutBuffer,
        lr: f64,
        rng: &mut impl Rng,
    ) -> UpdateStats {
        let cfg = &self.config;
        let (adv, ret) = gae(
            &buf.rewards,
            &buf.values,
            &buf.ends,
            &buf.last_values,
            cfg.gamma as f32,
            cfg.gae_lambda as f32,
        );
        let total = buf.len();
        let mut stats =
            UpdateStats { explained_variance: explained_variance(&buf.values, &ret), ..Default::default() };
        let mut order: Vec<usize> = (0..total).collect();
        let (od, ad) = (buf.obs_dim, buf.act_dim);
        'epochs: for _ in 0..cfg.epochs {
            order.shuffle(rng);
            let mut epoch_kl = 0.0;
            let mut epoch_batches = 0;
            for chunk in order.chunks(cfg.minibatch) {
                let mb = &mut self.mb;
                mb.n = chunk.len();
                mb.obs.clear();
                mb.actions.clear();
                mb.old_log_probs.clear();
                mb.old_values.clear();
                mb.advantages.clear();
                mb.returns.clear();
                for &i in chunk {
                    mb.obs.extend_from_slice(&buf.obs[i * od..(i + 1) * od]);
                    mb.actions.extend_from_slice(&buf.actions[i * ad..(i + 1) * ad]);
                    mb.old_log_probs.push(buf.log_probs[i]);
                    mb.old_values.push(buf.values[i]);
                    mb.advantages.push(adv[i]);
                    mb.returns.push(ret[i]);
                }
                let parts = loss_and_grad(policy, cfg, mb, &mut self.cache, &mut self.grads);
                let norm =
                    self.adam.step(&mut policy.params, &mut self.grads, lr as f32, cfg.max_grad_norm as f32);
                stats.grad_norm += norm;
                add_parts(&mut stats.loss, &parts);
                stats.minibatches += 1;
                epoch_kl += parts.approx_kl;
                epoch_batches += 1;
            }
            if let Some(limit) = cfg.target_kl
                && epoch_kl / epoch_batches as f32 > limit as f32
            {
                break 'epochs;
            }
        }
        let k = stats.minibatches.max(1) as f32;
        scale_parts(&mut stats.loss, 1.0 / k);
        stats.grad_norm /= k;
        stats
    }
}

fn add_parts(a: &mut LossParts, b: &LossParts) {
    a.policy_loss += b.policy_loss;
    a.value_loss += b.value_loss;
    a.entropy += b.entropy;
    a.approx_kl += b.approx_kl;
    a.clip_fraction += b.clip_fraction;
    a.total += b.total;
}

fn scale_parts(a: &mut LossParts, s: f32) {
    a.policy_loss *= s;
    a.value_loss *= s;
    a.entropy *= s;
    a.approx_kl *= s;
    a.clip_fraction *= s;
    a.total *= s;
}

/// `1 − Var(returns − values) / Var(returns)` (NaN when the returns are constant).
pub fn explained_variance(values: &[f32], returns: &[f32]) -> f32 {
    let var = |xs: &mut dyn Iterator<Item = f32>, n: usize| {
        let v: Vec<f32> = xs.collect();
        let m = v.iter().sum::<f32>() / n as f32;
        v.iter().map(|x| (x - m) * (x - m)).sum::<f32>() / n as f32
    };
    let n = values.len().max(1);
    let vr = var(&mut returns.iter().copied(), n);
    if vr == 0.0 {
        return f32::NAN;
    }
    1.0 - var(&mut returns.iter().zip(values).map(|(r, v)| r - v), n) / vr
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gae_matches_a_hand_computed_example() {
        // Two environments, three steps; environment 1's episode ends after step 1.
        let rewards = [1.0, 0.0, 0.0, 2.0, 1.0, 1.0];
        let values = [0.5, 1.0, 0.2, 0.3, 0.4, 0.6];
        let ends = [false, false, false, true, false, false];
        let last = [1.5, 2.0];
        let (g, l) = (0.9f32, 0.8f32);
        let (adv, ret) = gae(&rewards, &values, &ends, &last, g, l);
        // env 0: δ2 = 1 + .9·1.5 − .4 = 1.95; δ1 = 0 + .9·.4 − .2 = .16; δ0 = 1 + .9·.2 − .5 = .68
        // A2 = 1.95; A1 = .16 + .72·1.95 = 1.564; A0 = .68 + .72·1.564 = 1.80608
        // env 1: δ2 = 1 + .9·2 − .6 = 2.2; δ1 = 2 − .3 = 1.7 (ends); δ0 = 0 + .9·.3 − 1 = −.73
        // A2 = 2.2; A1 = 1.7; A0 = −.73 + .72·1.7 = .494
        let expect = [1.80608, 0.494, 0.16 + 0.72 * 1.95, 1.7, 1.95, 2.2];
        for (a, e) in adv.iter().zip(expect) {
            assert!((a - e).abs() < 1e-5, "{adv:?}");
        }
        for ((r, a), v) in ret.iter().zip(&adv).zip(values) {
            assert!((r - (a + v)).abs() < 1e-6);
        }
    }
}
