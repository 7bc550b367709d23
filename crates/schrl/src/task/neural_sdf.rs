//! Neural signed-distance predicates (paper §3.1, App. E).
//!
//! An MLP learns a map's signed distance from samples of the exact one (the sim
//! crate's [`Map::sdf`]); bound in a spec as a named predicate, its value and its
//! gradient with respect to the waypoint flow through robustness like any other
//! predicate's (`clearance = sdf(p) − radius`). The paper uses such networks for the
//! walls and the duck; here they fit the exact distances the simulator already has,
//! so the fit can be measured: [`FitReport`] gives the error and the sign agreement
//! on held-out points, and `schrl sdf fit` draws a contour picture like Fig. 10a.
//!
//! Defaults (this project's; the paper gives no sizes): a 64-64 tanh MLP on inputs
//! scaled by the map's half extent, 20 000 Adam steps (lr 1e-2 decaying linearly to 0,
//! batch 256), half the
//! training points uniform in the map's region and half within 0.5 m of a surface.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::sync::Arc;

use serde::{Deserialize, Serialize};
use sim::Map;
use stl::Predicate;

use super::SafeAlong;

use crate::nn::adam::Adam;
use crate::nn::mlp::{MlpCache, TanhMlp};

/// How a neural SDF is fitted.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SdfFitConfig {
    /// Hidden layer sizes' width (two layers).
    pub hidden: usize,
    /// Adam steps.
    pub steps: usize,
    /// Points per step.
    pub batch: usize,
    /// Adam learning rate.
    pub lr: f32,
    /// Seed of the samples and the initial weights.
    pub seed: u64,
}

impl Default for SdfFitConfig {
    fn default() -> Self {
        Self { hidden: 64, steps: 20_000, batch: 256, lr: 1e-2, seed: 0 }
    }
}

/// A fitted network: weights, shape, the input scaling and the map it learned.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct NeuralSdf {
    /// The map's name.
    pub map: String,
    /// Layer sizes, input first.
    pub sizes: Vec<usize>,
    /// Inputs are divided by this before the network.
    pub input_scale: f64,
    /// Flat parameters ([`TanhMlp`] layout).
    pub params: Vec<f32>,
}

/// Error and sign agreement of a fit on held-out points.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct FitReport {
    /// Mean absolute error over points uniform in the region (m).
    pub mean_abs_error: f64,
    /// Largest absolute error among them (m).
    pub max_abs_error: f64,
    /// Fraction of them where the network's sign matches the exact distance's.
    pub sign_agreement: f64,
    /// The same agreement among held-out points within 0.1 m of a surface.
    pub sign_agreement_near: f64,
    /// Training loss (mean squared error) of the last step.
    pub final_loss: f64,
}

/// A point of the region: half uniform, half near a surface (|sdf| < 0.5 m).
fn sample_point(map: &Map, rng: &mut ChaCha8Rng, near: bool) -> Vec<f64> {
    let (lo, hi) = map.region();
    loop {
        let p: Vec<f64> = lo.iter().zip(&hi).map(|(l, h)| rng.random_range(*l..*h)).collect();
        if !near || map.sdf(&p).abs() < 0.5 {
            return p;
        }
    }
}

impl NeuralSdf {
    fn mlp(&self) -> TanhMlp {
        TanhMlp::new(&self.sizes)
    }

    /// Fits a network to `map`'s exact signed distance; returns it with its
    /// held-out report. Maps without obstacles have no distance to learn.
    pub fn fit(map: &Map, cfg: &SdfFitConfig) -> Result<(Self, FitReport), String> {
        if matches!(map, Map::Empty(_) | Map::Floor) {
            return Err(format!("the {} map has no obstacle whose distance could be learned", map.name()));
        }
        let dim = map.dim();
        let (lo, hi) = map.region();
        let input_scale = lo.iter().zip(&hi).map(|(l, h)| l.abs().max(h.abs())).fold(0.0, f64::max);
        let sizes = vec![dim, cfg.hidden, cfg.hidden, 1];
        let mlp = TanhMlp::new(&sizes);
        let mut rng = ChaCha8Rng::seed_from_u64(cfg.seed);
        // PyTorch's default initialisation, U(±1/√fan_in).
        let mut params = vec![0.0f32; mlp.num_params()];
        for (l, fan_in) in sizes[..mlp.num_layers()].iter().enumerate() {
            let k = 1.0 / (*fan_in as f32).sqrt();
            let (w, b) = mlp.layer_ranges(l);
            for p in &mut params[w.start..b.end] {
                *p = rng.random_range(-k..k);
            }
        }
        let mut adam = Adam::new(params.len());
        let (mut cache, mut grads) = (MlpCache::default(), vec![0.0f32; params.len()]);
        let (mut x, mut target) = (Vec::new(), Vec::new());
        let mut final_loss = 0.0;
        for step in 0..cfg.steps {
            x.clear();
            target.clear();
            for i in 0..cfg.batch {
                let p = sample_point(map, &mut rng, i % 2 == 1);
                target.push(map.sdf(&p) as f32);
                x.extend(p.iter().map(|v| (v / input_scale) as f32));
            }
            let y = mlp.forward(&params, &x, cfg.batch, &mut cache);
            let d: Vec<f32> = y.iter().zip(&target).map(|(a, b)| 2.0 * (a - b) / cfg.batch as f32).collect();
            final_loss = y.iter().zip(&target).map(|(a, b)| ((a - b) * (a - b)) as f64).sum::<f64>()
                / cfg.batch as f64;
            grads.iter_mut().for_each(|g| *g = 0.0);
            mlp.backward(&params, &x, cfg.batch, &mut cache, &d, &mut grads);
            // Linear decay to zero: the last steps refine instead of jittering.
            let lr = cfg.lr * (1.0 - step as f32 / cfg.steps as f32);
            adam.step(&mut params, &mut grads, lr, f32::INFINITY);
        }
        let net = Self { map: map.name().to_string(), sizes, input_scale, params };
        let report = net.evaluate(map, cfg.seed ^ 0x0E1D_0E1D, 4000)?;
        Ok((net, FitReport { final_loss, ..report }))
    }

    /// Error and sign agreement against `map`'s exact distance on `n` uniform and
    /// `n` near-surface points drawn with `seed` (disjoint from training draws).
    pub fn evaluate(&self, map: &Map, seed: u64, n: usize) -> Result<FitReport, String> {
        if map.name() != self.map {
            return Err(format!("this network learned the {} map, not {}", self.map, map.name()));
        }
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let (mut abs_sum, mut abs_max, mut agree) = (0.0, 0.0f64, 0);
        for _ in 0..n {
            let p = sample_point(map, &mut rng, false);
            let (exact, net) = (map.sdf(&p), self.distance(&p));
            abs_sum += (exact - net).abs();
            abs_max = abs_max.max((exact - net).abs());
            agree += ((exact > 0.0) == (net > 0.0)) as usize;
        }
        let (lo, hi) = map.region();
        let mut near_agree = 0;
        let mut near = 0;
        while near < n {
            let p: Vec<f64> = lo.iter().zip(&hi).map(|(l, h)| rng.random_range(*l..*h)).collect();
            let exact = map.sdf(&p);
            if exact.abs() < 0.1 {
                near += 1;
                near_agree += ((exact > 0.0) == (self.distance(&p) > 0.0)) as usize;
            }
        }
        Ok(FitReport {
            mean_abs_error: abs_sum / n as f64,
            max_abs_error: abs_max,
            sign_agreement: agree as f64 / n as f64,
            sign_agreement_near: near_agree as f64 / n as f64,
            final_loss: f64::NAN,
        })
    }

    /// The network's inputs for `points` (`n × dim`, flat): scaled, in `f32`.
    fn inputs(&self, points: &[f64]) -> Vec<f32> {
        points.iter().map(|v| (v / self.input_scale) as f32).collect()
    }

    /// The learned signed distance at each of `n` points (`points`: `n × dim`,
    /// flat), in one batched pass of the kernel the network was fitted with
    /// ([`TanhMlp::forward`], `f32`).
    pub fn distances(&self, points: &[f64], n: usize) -> Vec<f64> {
        let mut cache = MlpCache::default();
        self.mlp()
            .forward(&self.params, &self.inputs(points), n, &mut cache)
            .iter()
            .map(|&y| y as f64)
            .collect()
    }

    /// The learned signed distance at `p` and its gradient (written to `grad`).
    pub fn distance_and_grad(&self, p: &[f64], grad: &mut [f64]) -> f64 {
        let (mlp, x) = (self.mlp(), self.inputs(p));
        let mut cache = MlpCache::default();
        let y = mlp.forward(&self.params, &x, 1, &mut cache)[0];
        let mut dx = vec![0.0f32; p.len()];
        mlp.input_gradient(&self.params, 1, &mut cache, &[1.0], &mut dx);
        for (g, d) in grad.iter_mut().zip(&dx) {
            *g = *d as f64 / self.input_scale;
        }
        y as f64
    }

    /// The learned signed distance at `p`.
    pub fn distance(&self, p: &[f64]) -> f64 {
        self.distances(p, 1)[0]
    }

    /// Checks that the network's shape is consistent (a file may say anything).
    pub fn check(&self) -> Result<(), String> {
        if self.sizes.len() < 2 || self.sizes.last() != Some(&1) {
            return Err(format!("layer sizes {:?} do not end in one output", self.sizes));
        }
        let expected = TanhMlp::new(&self.sizes).num_params();
        if self.params.len() != expected {
            return Err(format!(
                "{} parameters for layer sizes {:?} (expected {expected})",
                self.params.len(),
                self.sizes
            ));
        }
        if !(self.input_scale.is_finite() && self.input_scale > 0.0) {
            return Err(format!("input_scale must be positive, got {}", self.input_scale));
        }
        Ok(())
    }

    /// This network as an STL predicate: `sdf(p) − radius` (clearance for a robot of
    /// `radius`), with its exact input gradient; checked at waypoints (see
    /// [`NeuralClearance::along`]).
    pub fn clearance(self: &Arc<Self>, radius: f64) -> NeuralClearance {
        NeuralClearance { net: Arc::clone(self), radius, along: SafeAlong::Waypoints }
    }
}

/// Spacing of the points at which [`NeuralClearance`] samples a segment (metres).
/// Between two samples `h` apart a distance (1-Lipschitz) can dip at most `h/2`
/// below both: 0.1 m here, the default fit's largest error on the duck (0.11 m).
/// At most [`MAX_SEGMENT_SAMPLES`] points per segment.
pub const SEGMENT_SAMPLE_SPACING: f64 = 0.2;

/// Most points sampled on one segment (longer segments are sampled more sparsely).
pub const MAX_SEGMENT_SAMPLES: usize = 64;

/// A neural SDF bound as a predicate: clearance `sdf(p) − radius`.
///
/// Along segments the clearance of `a → b` is the smallest over points evenly spaced
/// at most [`SEGMENT_SAMPLE_SPACING`] apart, ends included (a network has no closed
/// form for a segment, unlike the exact maps' [`sim::Map::segment_sdf`]); its gradient
/// is the network's at the smallest point, shared between the ends by the point's
/// position (`1 − s` to `a`, `s` to `b`). Inside an obstacle that is the deepest
/// sampled point's depth, not the exact maps' penetration depth. The sample count
/// grows with the segment's length, so where it changes the value may step by the
/// network's variation between neighbouring samples.
#[derive(Clone, Debug)]
pub struct NeuralClearance {
    net: Arc<NeuralSdf>,
    radius: f64,
    along: SafeAlong,
}

impl NeuralClearance {
    /// The same clearance, checked along segments or at waypoints.
    pub fn along(self, along: SafeAlong) -> Self {
        Self { along, ..self }
    }

    /// The segment `a → b`'s smallest sampled distance and where (`s` in [0, 1]),
    /// the samples in one batched pass.
    fn segment_min(&self, a: &[f64], b: &[f64]) -> (f64, f64) {
        let len = a.iter().zip(b).map(|(x, y)| (y - x) * (y - x)).sum::<f64>().sqrt();
        let k = ((len / SEGMENT_SAMPLE_SPACING).ceil() as usize).clamp(1, MAX_SEGMENT_SAMPLES);
        let points: Vec<f64> = (0..=k)
            .flat_map(|i| {
                let s = i as f64 / k as f64;
                a.iter().zip(b).map(move |(x, y)| x + s * (y - x))
            })
            .collect();
        let d = self.net.distances(&points, k + 1);
        // The first smallest: ties go to the sample nearer `a`.
        let (i, best) =
            d.iter().enumerate().fold((0, f64::INFINITY), |m, (i, &v)| if v < m.1 { (i, v) } else { m });
        (best, i as f64 / k as f64)
    }
}

impl Predicate for NeuralClearance {
    fn value(&self, _t: usize, state: &[f64]) -> f64 {
        self.net.distance(state) - self.radius
    }

    fn value_and_grad(&self, _t: usize, state: &[f64], scale: f64, grad: &mut [f64]) -> f64 {
        let mut g = vec![0.0; state.len()];
        let v = self.net.distance_and_grad(state, &mut g);
        for (o, gi) in grad.iter_mut().zip(&g) {
            *o += scale * gi;
        }
        v - self.radius
    }

    fn required_dim(&self) -> usize {
        self.net.sizes[0]
    }

    fn value_on_path(&self, path: &[f64], dim: usize, t: usize) -> f64 {
        if self.along == SafeAlong::Waypoints || t == 0 {
            return self.value(t, &path[t * dim..(t + 1) * dim]);
        }
        self.segment_min(&path[(t - 1) * dim..t * dim], &path[t * dim..(t + 1) * dim]).0 - self.radius
    }

    fn value_and_grad_on_path(
        &self,
        path: &[f64],
        dim: usize,
        t: usize,
        scale: f64,
        grad: &mut [f64],
    ) -> f64 {
        if self.along == SafeAlong::Waypoints || t == 0 {
            let at = t * dim..(t + 1) * dim;
            return self.value_and_grad(t, &path[at.clone()], scale, &mut grad[at]);
        }
        let (a, b) = (&path[(t - 1) * dim..t * dim], &path[t * dim..(t + 1) * dim]);
        let (_, s) = self.segment_min(a, b);
        let p: Vec<f64> = a.iter().zip(b).map(|(x, y)| x + s * (y - x)).collect();
        let mut g = vec![0.0; dim];
        let v = self.net.distance_and_grad(&p, &mut g);
        for k in 0..dim {
            grad[(t - 1) * dim + k] += scale * (1.0 - s) * g[k];
            grad[t * dim + k] += scale * s * g[k];
        }
        v - self.radius
    }
}
