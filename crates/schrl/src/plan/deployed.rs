//! A trained GRU-ODE planner run from its weights in plain Rust: the deployed plan.
//!
//! At deployment a plan is the planner's mean path from the robot's start (no
//! sampling noise, no gradients). Running it through candle costs a few dozen tensor
//! ops per waypoint, each with dispatch and allocation; here one waypoint is two
//! small matrix–vector products written as vectorisable loops, so a whole Seq plan
//! takes microseconds (`cargo bench -p schrl --bench deployed_plan`, BENCHMARKS.md).
//!
//! The arithmetic is the one of [`crate::plan::planner::PathPlanner::mean_path`] in `f32`
//! (PyTorch's GRU: gates r, z, n; `h' = (1 − z) n + z h`), with the sigmoid written as
//! `(1 + tanh(x/2))/2` through [`fast_tanh`]; waypoints agree with candle's to within
//! 1e-4 m (tested in `tests/planning.rs`).

use candle_core::{DType, Result, Tensor};
use candle_nn::VarMap;

use crate::nn::mlp::fast_tanh;
use crate::plan::planner::{PlannerConfig, PlannerKind};

/// The mean-path part of a GRU-ODE planner, as plain arrays.
#[derive(Clone, Debug, PartialEq)]
pub struct DeployedPlanner {
    dim: usize,
    hidden: usize,
    bound: f32,
    /// Input weights transposed: `[dim][3·hidden]`.
    w_ih_t: Vec<f32>,
    /// Recurrent weights transposed: `[hidden][3·hidden]`.
    w_hh_t: Vec<f32>,
    b_ih: Vec<f32>,
    b_hh: Vec<f32>,
    /// Mean head transposed: `[hidden][dim]`.
    w_mean_t: Vec<f32>,
    b_mean: Vec<f32>,
}

/// Reusable buffers of one planning call.
#[derive(Clone, Debug, Default)]
pub struct PlanScratch {
    h: Vec<f32>,
    gi: Vec<f32>,
    gh: Vec<f32>,
    /// The current waypoint and the mean head's output.
    g: Vec<f32>,
    m: Vec<f32>,
}

fn weights(varmap: &VarMap, name: &str, shape: &[usize]) -> Result<Vec<f32>> {
    let data = varmap.data().lock().expect("varmap lock");
    let t = data.get(name).ok_or_else(|| candle_core::Error::Msg(format!("no planner weight '{name}'")))?;
    if t.dims() != shape {
        candle_core::bail!("planner weight '{name}' has shape {:?}, expected {shape:?}", t.dims());
    }
    t.as_tensor().to_dtype(DType::F32)?.flatten_all()?.to_vec1()
}

/// `[rows][cols]` row-major into `[cols][rows]`.
fn transpose(m: &[f32], rows: usize, cols: usize) -> Vec<f32> {
    let mut t = vec![0.0; m.len()];
    for r in 0..rows {
        for c in 0..cols {
            t[c * rows + r] = m[r * cols + c];
        }
    }
    t
}

/// `out += Σ_c x[c] · wt[c]` (rows of `wt` have `out.len()` numbers): a sum of scaled
/// rows, which vectorises without reordering any reduction.
#[inline]
fn add_product(out: &mut [f32], wt: &[f32], x: &[f32]) {
    let n = out.len();
    for (row, &xc) in wt.chunks_exact(n).zip(x) {
        for (o, w) in out.iter_mut().zip(row) {
            *o += w * xc;
        }
    }
}

impl DeployedPlanner {
    /// The planner whose parameters are in `varmap` (names as
    /// [`crate::plan::planner::PathPlanner::new`] makes them) with shape `cfg`.
    pub fn from_varmap(varmap: &VarMap, cfg: &PlannerConfig) -> Result<Self> {
        if cfg.kind != PlannerKind::GruOde {
            candle_core::bail!("only GRU-ODE planners are deployed in plain Rust, not '{}'", cfg.kind.name());
        }
        let (d, h) = (cfg.dim, cfg.hidden);
        let w_ih = weights(varmap, "gru.weight_ih_l0", &[3 * h, d])?;
        let w_hh = weights(varmap, "gru.weight_hh_l0", &[3 * h, h])?;
        let w_mean = weights(varmap, "mean.weight", &[d, h])?;
        Ok(Self {
            dim: d,
            hidden: h,
            bound: cfg.bound as f32,
            w_ih_t: transpose(&w_ih, 3 * h, d),
            w_hh_t: transpose(&w_hh, 3 * h, h),
            b_ih: weights(varmap, "gru.bias_ih_l0", &[3 * h])?,
            b_hh: weights(varmap, "gru.bias_hh_l0", &[3 * h])?,
            w_mean_t: transpose(&w_mean, d, h),
            b_mean: weights(varmap, "mean.bias", &[d])?,
        })
    }

    /// Plan-space dimension.
    pub fn dim(&self) -> usize {
        self.dim
    }

    /// The mean path from `start` with `steps` waypoints after it, written to `out`
    /// as `(steps + 1) · dim` numbers, the start first.
    pub fn mean_path_into(&self, start: &[f64], steps: usize, scratch: &mut PlanScratch, out: &mut Vec<f64>) {
        assert_eq!(start.len(), self.dim, "start of the planner's dimension");
        let (d, h3) = (self.dim, 3 * self.hidden);
        let hid = self.hidden;
        scratch.h.clear();
        scratch.h.resize(hid, 0.0);
        out.clear();
        out.extend_from_slice(start);
        scratch.g.clear();
        scratch.g.extend(start.iter().map(|v| *v as f32));
        for _ in 0..steps {
            scratch.gi.clear();
            scratch.gi.extend_from_slice(&self.b_ih);
            add_product(&mut scratch.gi, &self.w_ih_t, &scratch.g);
            scratch.gh.clear();
            scratch.gh.extend_from_slice(&self.b_hh);
            add_product(&mut scratch.gh, &self.w_hh_t, &scratch.h);
            let (gi, gh) = (&scratch.gi[..h3], &scratch.gh[..h3]);
            for j in 0..hid {
                let r = 0.5 + 0.5 * fast_tanh(0.5 * (gi[j] + gh[j]));
                let z = 0.5 + 0.5 * fast_tanh(0.5 * (gi[hid + j] + gh[hid + j]));
                let n = fast_tanh(gi[2 * hid + j] + r * gh[2 * hid + j]);
                scratch.h[j] = (1.0 - z) * n + z * scratch.h[j];
            }
            scratch.m.clear();
            scratch.m.extend_from_slice(&self.b_mean);
            add_product(&mut scratch.m, &self.w_mean_t, &scratch.h);
            for (g, m) in scratch.g[..d].iter_mut().zip(&scratch.m) {
                *g += self.bound * fast_tanh(*m);
            }
            out.extend(scratch.g.iter().map(|v| *v as f64));
        }
    }

    /// The mean path from `start`: `steps + 1` waypoints, the start first.
    pub fn mean_path(&self, start: &[f64], steps: usize) -> Vec<Vec<f64>> {
        let mut out = Vec::new();
        self.mean_path_into(start, steps, &mut PlanScratch::default(), &mut out);
        out.chunks(self.dim).map(|c| c.to_vec()).collect()
    }

    /// Mean paths of a batch of starts `[n, dim]`, as a `[n, steps + 1, dim]` tensor
    /// (the shape [`crate::plan::planner::PathPlanner::mean_path`] returns).
    pub fn mean_paths_tensor(&self, starts: &Tensor, steps: usize) -> Result<Tensor> {
        let starts: Vec<Vec<f64>> = starts.to_dtype(DType::F64)?.to_vec2()?;
        let mut all = Vec::with_capacity(starts.len() * (steps + 1) * self.dim);
        let (mut scratch, mut out) = (PlanScratch::default(), Vec::new());
        for s in &starts {
            self.mean_path_into(s, steps, &mut scratch, &mut out);
            all.extend_from_slice(&out);
        }
        Tensor::from_vec(all, (starts.len(), steps + 1, self.dim), &candle_core::Device::Cpu)
    }
}
