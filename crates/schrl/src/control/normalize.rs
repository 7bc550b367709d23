//! Running statistics for observation and reward normalisation.
//!
//! As in Gymnasium's `NormalizeObservation` / `NormalizeReward` wrappers, which
//! CleanRL's continuous PPO applies: observations are standardised with running
//! moments and clipped to ±10; rewards are divided by the running standard
//! deviation of the discounted return and clipped to ±10. The statistics are part
//! of the trained controller (saved in checkpoints, frozen at evaluation).

use serde::{Deserialize, Serialize};

/// Added to variances before the square root (Gymnasium's ε 1e-8).
pub const NORM_EPSILON: f64 = 1e-8;
/// Normalised values are clipped to ±this (Gymnasium's default 10).
pub const NORM_CLIP: f64 = 10.0;

/// Running mean and variance of vectors, merged batch by batch (Chan et al.'s
/// parallel algorithm, as Gymnasium's `RunningMeanStd`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RunningMeanStd {
    /// Mean per component.
    pub mean: Vec<f64>,
    /// Variance per component.
    pub var: Vec<f64>,
    /// Number of samples seen (starts at 1e-4 as in Gymnasium, so the first batch
    /// dominates without dividing by zero).
    pub count: f64,
}

impl RunningMeanStd {
    /// Statistics of `dim`-vectors, mean 0 and variance 1 before any data.
    pub fn new(dim: usize) -> Self {
        Self { mean: vec![0.0; dim], var: vec![1.0; dim], count: 1e-4 }
    }

    /// Dimension.
    pub fn dim(&self) -> usize {
        self.mean.len()
    }

    /// Merges a batch of `n` vectors (`xs`: `n × dim`).
    pub fn update(&mut self, xs: &[f64]) {
        let dim = self.dim();
        let n = xs.len() / dim;
        if n == 0 {
            return;
        }
        let total = self.count + n as f64;
        for k in 0..dim {
            let bm = xs.iter().skip(k).step_by(dim).sum::<f64>() / n as f64;
            let bv = xs.iter().skip(k).step_by(dim).map(|x| (x - bm) * (x - bm)).sum::<f64>() / n as f64;
            let delta = bm - self.mean[k];
            let m2 = self.var[k] * self.count + bv * n as f64 + delta * delta * self.count * n as f64 / total;
            self.mean[k] += delta * n as f64 / total;
            self.var[k] = m2 / total;
        }
        self.count = total;
    }

    /// Standardises and clips `xs` (`n × dim`) into `out` as `f32`.
    pub fn normalize_into(&self, xs: &[f64], out: &mut [f32]) {
        let dim = self.dim();
        let scale: Vec<f64> = self.var.iter().map(|v| 1.0 / (v + NORM_EPSILON).sqrt()).collect();
        for (row, orow) in xs.chunks_exact(dim).zip(out.chunks_exact_mut(dim)) {
            for k in 0..dim {
                orow[k] = ((row[k] - self.mean[k]) * scale[k]).clamp(-NORM_CLIP, NORM_CLIP) as f32;
            }
        }
    }
}

/// Reward scaling by the running standard deviation of each environment's
/// discounted return.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RewardScaler {
    /// Statistics of the discounted returns (dimension 1).
    pub stats: RunningMeanStd,
    /// The running discounted return of each environment.
    pub returns: Vec<f64>,
    /// Discount of the return (the PPO γ).
    pub gamma: f64,
}

impl RewardScaler {
    /// A scaler for `n` environments with discount `gamma`.
    pub fn new(n: usize, gamma: f64) -> Self {
        Self { stats: RunningMeanStd::new(1), returns: vec![0.0; n], gamma }
    }

    /// Scales one step's rewards in place; `ended[i]` restarts environment `i`'s return
    /// after this step.
    pub fn scale(&mut self, rewards: &mut [f64], ended: &[bool]) {
        for (g, r) in self.returns.iter_mut().zip(rewards.iter()) {
            *g = *g * self.gamma + r;
        }
        self.stats.update(&self.returns);
        let s = 1.0 / (self.stats.var[0] + NORM_EPSILON).sqrt();
        for r in rewards.iter_mut() {
            *r = (*r * s).clamp(-NORM_CLIP, NORM_CLIP);
        }
        for (g, e) in self.returns.iter_mut().zip(ended) {
            if *e {
                *g = 0.0;
            }
        }
    }

    /// The current scale factor (rewards are multiplied by it).
    pub fn factor(&self) -> f64 {
        1.0 / (self.stats.var[0] + NORM_EPSILON).sqrt()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn batched_moments_match_direct_moments() {
        let xs: Vec<f64> = (0..300).map(|i| ((i * 37 % 101) as f64).sin() * 3.0 + (i % 2) as f64).collect();
        let mut rms = RunningMeanStd::new(3);
        for chunk in xs.chunks(30) {
            rms.update(chunk);
        }
        for k in 0..3 {
            let col: Vec<f64> = xs.iter().skip(k).step_by(3).copied().collect();
            let m = col.iter().sum::<f64>() / col.len() as f64;
            let v = col.iter().map(|x| (x - m).powi(2)).sum::<f64>() / col.len() as f64;
            assert!((rms.mean[k] - m).abs() < 1e-5, "mean {k}");
            assert!((rms.var[k] - v).abs() < 1e-4, "var {k}");
        }
    }
}
