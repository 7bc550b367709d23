//! Adam with global gradient-norm clipping, over one flat parameter vector.

use serde::{Deserialize, Serialize};

/// Adam's state and hyper-parameters (PyTorch's algorithm, no weight decay).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Adam {
    /// β₁ (0.9, Kingma & Ba).
    pub beta1: f32,
    /// β₂ (0.999, Kingma & Ba).
    pub beta2: f32,
    /// ε (1e-5, CleanRL's PPO; PyTorch's default is 1e-8).
    pub eps: f32,
    /// First moments.
    pub m: Vec<f32>,
    /// Second moments.
    pub v: Vec<f32>,
    /// Steps taken.
    pub t: u64,
}

impl Adam {
    /// Fresh state for `n` parameters.
    pub fn new(n: usize) -> Self {
        Self { beta1: 0.9, beta2: 0.999, eps: 1e-5, m: vec![0.0; n], v: vec![0.0; n], t: 0 }
    }

    /// One step with learning rate `lr`, after scaling `grads` so their global L2
    /// norm is at most `max_norm` (PyTorch's `clip_grad_norm_`). Returns the norm
    /// before clipping.
    pub fn step(&mut self, params: &mut [f32], grads: &mut [f32], lr: f32, max_norm: f32) -> f32 {
        let norm = grads.iter().map(|g| g * g).sum::<f32>().sqrt();
        let clip = max_norm / (norm + 1e-6);
        if clip < 1.0 {
            grads.iter_mut().for_each(|g| *g *= clip);
        }
        self.t += 1;
        let (b1, b2) = (self.beta1, self.beta2);
        let c1 = 1.0 - b1.powi(self.t as i32);
        let c2 = 1.0 - b2.powi(self.t as i32);
        let step = lr / c1;
        let c2s = c2.sqrt();
        for (((p, g), m), v) in params.iter_mut().zip(grads.iter()).zip(&mut self.m).zip(&mut self.v) {
            *m = b1 * *m + (1.0 - b1) * g;
            *v = b2 * *v + (1.0 - b2) * g * g;
            *p -= step * *m / (v.sqrt() / c2s + self.eps);
        }
        norm
    }
}
