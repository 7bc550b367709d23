//! The actor-critic: a Gaussian policy with a tanh MLP mean and a
//! state-independent log standard deviation, and a tanh MLP value function.

use rand::Rng;
use rand_distr::StandardNormal;

use crate::nn::mlp::{MlpCache, TanhMlp};

/// ½ ln 2π, the Gaussian log-density's constant per dimension.
pub const HALF_LN_2PI: f32 = 0.918_938_5;

/// Actor and critic networks with all parameters in one flat vector:
/// `[actor | critic | log_std]`, so one optimiser and one clip cover them (as in
/// CleanRL, where both networks belong to one `Agent` module).
#[derive(Clone, Debug)]
pub struct ActorCritic {
    actor: TanhMlp,
    critic: TanhMlp,
    /// All parameters.
    pub params: Vec<f32>,
}

/// Scratch space for batched evaluation of an [`ActorCritic`].
#[derive(Clone, Debug, Default)]
pub struct PolicyCache {
    /// Actor activations.
    pub actor: MlpCache,
    /// Critic activations.
    pub critic: MlpCache,
}

impl ActorCritic {
    /// Networks for `obs_dim` observations and `act_dim` actions with the given
    /// hidden widths, initialised as CleanRL does: orthogonal weights with gain √2
    /// on hidden layers, 0.01 on the actor's output and 1 on the critic's, zero
    /// biases, log-std 0.
    pub fn new(obs_dim: usize, act_dim: usize, hidden: &[usize], rng: &mut impl Rng) -> Self {
        let sizes = |out: usize| {
            let mut s = vec![obs_dim];
            s.extend_from_slice(hidden);
            s.push(out);
            s
        };
        let actor = TanhMlp::new(&sizes(act_dim));
        let critic = TanhMlp::new(&sizes(1));
        let mut params = vec![0.0; actor.num_params() + critic.num_params() + act_dim];
        let (a, rest) = params.split_at_mut(actor.num_params());
        let (c, _) = rest.split_at_mut(critic.num_params());
        init_orthogonal(&actor, a, 0.01, rng);
        init_orthogonal(&critic, c, 1.0, rng);
        Self { actor, critic, params }
    }

    /// Observation length.
    pub fn obs_dim(&self) -> usize {
        self.actor.input_dim()
    }

    /// Action length.
    pub fn act_dim(&self) -> usize {
        self.actor.output_dim()
    }

    /// Hidden widths.
    pub fn hidden(&self) -> Vec<usize> {
        let s = self.actor.sizes();
        s[1..s.len() - 1].to_vec()
    }

    /// The actor network's shape.
    pub fn actor(&self) -> &TanhMlp {
        &self.actor
    }

    /// The critic network's shape.
    pub fn critic(&self) -> &TanhMlp {
        &self.critic
    }

    /// Splits a parameter-shaped slice into `(actor, critic, log_std)`.
    pub fn split<'a>(&self, p: &'a [f32]) -> (&'a [f32], &'a [f32], &'a [f32]) {
        let (a, rest) = p.split_at(self.actor.num_params());
        let (c, l) = rest.split_at(self.critic.num_params());
        (a, c, l)
    }

    /// Mutable [`ActorCritic::split`].
    pub fn split_mut<'a>(&self, p: &'a mut [f32]) -> (&'a mut [f32], &'a mut [f32], &'a mut [f32]) {
        let (a, rest) = p.split_at_mut(self.actor.num_params());
        let (c, l) = rest.split_at_mut(self.critic.num_params());
        (a, c, l)
    }

    /// The log standard deviations.
    pub fn log_std(&self) -> &[f32] {
        self.split(&self.params).2
    }

    /// Action means for `n` normalised observations (`n × act_dim`).
    pub fn mean<'c>(&self, obs: &[f32], n: usize, cache: &'c mut PolicyCache) -> &'c [f32] {
        self.actor.forward(self.split(&self.params).0, obs, n, &mut cache.actor)
    }

    /// State values for `n` normalised observations.
    pub fn value<'c>(&self, obs: &[f32], n: usize, cache: &'c mut PolicyCache) -> &'c [f32] {
        self.critic.forward(self.split(&self.params).1, obs, n, &mut cache.critic)
    }

    /// Samples actions for `n` observations: writes actions (`n × act_dim`), their
    /// log-probabilities and the values (caller-owned buffers, reused every step).
    #[allow(clippy::too_many_arguments)]
    pub fn act(
        &self,
        obs: &[f32],
        n: usize,
        rng: &mut impl Rng,
        cache: &mut PolicyCache,
        actions: &mut [f32],
        log_probs: &mut [f32],
        values: &mut [f32],
    ) {
        let d = self.act_dim();
        let log_std = self.log_std();
        let std: Vec<f32> = log_std.iter().map(|l| l.exp()).collect();
        let norm_const = log_std.iter().sum::<f32>() + d as f32 * HALF_LN_2PI;
        let mean = self.mean(obs, n, cache);
        for i in 0..n {
            let mut lp = -norm_const;
            for j in 0..d {
                let eps: f32 = rng.sample(StandardNormal);
                actions[i * d + j] = mean[i * d + j] + std[j] * eps;
                lp -= 0.5 * eps * eps;
            }
            log_probs[i] = lp;
        }
        values[..n].copy_from_slice(self.value(obs, n, cache));
    }
}

/// Orthogonal weights (Saxe et al.; PyTorch's `orthogonal_`) with gain √2 on hidden
/// layers and `out_gain` on the last, zero biases.
fn init_orthogonal(mlp: &TanhMlp, params: &mut [f32], out_gain: f64, rng: &mut impl Rng) {
    for l in 0..mlp.num_layers() {
        let (rows, cols) = (mlp.sizes()[l + 1], mlp.sizes()[l]);
        let gain = if l + 1 == mlp.num_layers() { out_gain } else { std::f64::consts::SQRT_2 };
        let w = orthogonal(rows, cols, rng);
        let (wr, br) = mlp.layer_ranges(l);
        for (p, v) in params[wr].iter_mut().zip(&w) {
            *p = (gain * v) as f32;
        }
        params[br].fill(0.0);
    }
}

/// A `rows × cols` matrix (row-major) with orthonormal rows (if rows ≤ cols) or
/// columns: Gram–Schmidt on Gaussian vectors, which equals QR with the signs of R's
/// diagonal made positive.
pub fn orthogonal(rows: usize, cols: usize, rng: &mut impl Rng) -> Vec<f64> {
    let (long, short) = (rows.max(cols), rows.min(cols));
    // `short` orthonormal vectors of length `long`.
    let mut vs: Vec<Vec<f64>> = Vec::with_capacity(short);
    while vs.len() < short {
        let mut v: Vec<f64> = (0..long).map(|_| rng.sample(StandardNormal)).collect();
        for _ in 0..2 {
            // Twice, for numerical orthogonality.
            for u in &vs {
                let d: f64 = v.iter().zip(u).map(|(a, b)| a * b).sum();
                v.iter_mut().zip(u).for_each(|(a, b)| *a -= d * b);
            }
        }
        let n = v.iter().map(|a| a * a).sum::<f64>().sqrt();
        if n > 1e-8 {
            v.iter_mut().for_each(|a| *a /= n);
            vs.push(v);
        }
    }
    let mut w = vec![0.0; rows * cols];
    for (k, v) in vs.iter().enumerate() {
        for (j, x) in v.iter().enumerate() {
            if rows <= cols {
                w[k * cols + j] = *x; // row k
            } else {
                w[j * cols + k] = *x; // column k
            }
        }
    }
    w
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    #[test]
    fn orthogonal_rows_or_columns_are_orthonormal() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        for (r, c) in [(64, 14), (2, 64), (64, 64)] {
            let w = orthogonal(r, c, &mut rng);
            let (n, len) = if r <= c { (r, c) } else { (c, r) };
            let at = |k: usize, j: usize| if r <= c { w[k * c + j] } else { w[j * c + k] };
            for a in 0..n {
                for b in 0..n {
                    let d: f64 = (0..len).map(|j| at(a, j) * at(b, j)).sum();
                    assert!((d - if a == b { 1.0 } else { 0.0 }).abs() < 1e-9, "{r}x{c} ({a},{b}) {d}");
                }
            }
        }
    }
}
