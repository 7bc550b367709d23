//! The GRU-ODE planner's sampling pass and the gradient of the constrained
//! policy-gradient loss (Eq. 4), written by hand over flat `f32` arrays.
//!
//! Why not candle here: one update on 64 paths is a few hundred small tensor ops per
//! waypoint (two GRU passes, their backward, the heads), and candle's dispatch and
//! allocation made it 8–25 ms (Seq–Signal), against a 5 ms target. Here the
//! forward runs once: the reparameterised term and the score-function term read the
//! same activations (their inputs agree in value; only where the gradient may flow
//! differs), and the backward carries the two hidden-state gradients side by side.
//! Products go through `matrixmultiply` and `tanh`/sigmoid through
//! [`fast_tanh`]. candle keeps the weights (`VarMap`, the checkpoint format) and is
//! the autodiff oracle `tests/planning.rs` compares these gradients with.
//!
//! The loss, for a batch of `B` paths with advantages `A_k` and Lagrange multiplier
//! `λ`, is `L = −w/B Σ_k A_k log π(τ_k) − λ/B Σ_k ρ(τ_k)` evaluated at the current
//! parameters, where the PPO-style clipped ratio of [`crate::plan::cpg`] equals 1 and its
//! gradient is the plain score function. The paths are reparameterised,
//! `g_{i+1} = μ_i + σ_i ε_i`, so `ρ`'s gradient reaches the parameters through every
//! waypoint; `log π` treats the path as data.
//!
//! Parameters are PyTorch's GRU (gates r, z, n; `h' = (1 − z) n + z h`) and two
//! linear heads: `μ = g + bound · tanh(W_m h' + b_m)`, `σ = |W_s h' + b_s| + σ_min`.

use candle_core::{DType, Result, Tensor};
use candle_nn::VarMap;

use crate::nn::mlp::{fast_tanh, gemm};
use crate::plan::planner::{PlannerConfig, PlannerKind};

/// Names and shapes of the planner's parameters in its `VarMap`, in the order of the
/// flat vector.
fn layout(cfg: &PlannerConfig) -> [(&'static str, Vec<usize>); 8] {
    let (d, h) = (cfg.dim, cfg.hidden);
    [
        ("gru.weight_ih_l0", vec![3 * h, d]),
        ("gru.weight_hh_l0", vec![3 * h, h]),
        ("gru.bias_ih_l0", vec![3 * h]),
        ("gru.bias_hh_l0", vec![3 * h]),
        ("mean.weight", vec![d, h]),
        ("mean.bias", vec![d]),
        ("std.weight", vec![d, h]),
        ("std.bias", vec![d]),
    ]
}

/// Offsets of each parameter in the flat vector.
#[derive(Clone, Copy, Debug)]
struct Offsets {
    w_ih: usize,
    w_hh: usize,
    b_ih: usize,
    b_hh: usize,
    w_m: usize,
    b_m: usize,
    w_s: usize,
    b_s: usize,
    end: usize,
}

impl Offsets {
    fn new(d: usize, h: usize) -> Self {
        let w_ih = 0;
        let w_hh = w_ih + 3 * h * d;
        let b_ih = w_hh + 3 * h * h;
        let b_hh = b_ih + 3 * h;
        let w_m = b_hh + 3 * h;
        let b_m = w_m + d * h;
        let w_s = b_m + d;
        let b_s = w_s + d * h;
        Self { w_ih, w_hh, b_ih, b_hh, w_m, b_m, w_s, b_s, end: b_s + d }
    }
}

/// Activations of one forward pass over `batch` paths of `steps` waypoints.
#[derive(Clone, Debug, Default)]
pub struct Tape {
    batch: usize,
    steps: usize,
    /// Waypoints `[batch][steps + 1][dim]`, the start first.
    pub paths: Vec<f32>,
    /// Hidden states before each step: `[steps + 1][batch][hidden]` (index 0 zero).
    hs: Vec<f32>,
    /// Gates r, z, n and `W_hn h + b_hn` per step: `[steps][batch][4 · hidden]`.
    gates: Vec<f32>,
    /// `tanh` of the mean head, `W_s h' + b_s`, `σ` and `ε` per step: `[steps][batch][dim]`.
    tanh_a: Vec<f32>,
    s: Vec<f32>,
    sigma: Vec<f32>,
    eps: Vec<f32>,
    /// One step's `h W_hhᵀ + b_hh` and `x W_ihᵀ + b_ih`, `[batch][3 · hidden]` (scratch).
    hidden_gh: Vec<f32>,
    input_gi: Vec<f32>,
}

/// Buffers of the backward pass, reused across updates.
#[derive(Clone, Debug, Default)]
struct Work {
    /// Gradients of the input waypoints `[batch][steps + 1][dim]` (reparameterised term).
    gx: Vec<f32>,
    /// Hidden-state gradients of the two streams, `[2 · batch][hidden]`: rows `0..B` the
    /// reparameterised term, `B..2B` the score term.
    dh: Vec<f32>,
    dh_prev: Vec<f32>,
    /// Gate pre-activation gradients of the two streams `[2 · batch][3 · hidden]`
    /// (hidden side: the n part is scaled by r), and their sums `[batch][3 · hidden]`
    /// for the weight gradients.
    dgh: Vec<f32>,
    dgi: Vec<f32>,
    dgh_sum: Vec<f32>,
    dgi_sum: Vec<f32>,
    /// Head gradients of the two streams `[2 · batch][dim]` and their sums.
    da: Vec<f32>,
    ds: Vec<f32>,
    da_sum: Vec<f32>,
    ds_sum: Vec<f32>,
    /// Input-waypoint gradients of one step `[batch][dim]`.
    dx: Vec<f32>,
}

/// The GRU-ODE planner as a flat parameter vector with a hand-written backward.
#[derive(Clone, Debug)]
pub struct GruOdeBackprop {
    cfg: PlannerConfig,
    at: Offsets,
    /// Parameters, flat: the GRU's input and hidden weights and biases, then the mean
    /// and spread heads' (the order of the `VarMap` names it is read from).
    pub params: Vec<f32>,
    work: Work,
}

#[inline]
fn sigmoid(x: f32) -> f32 {
    0.5 + 0.5 * fast_tanh(0.5 * x)
}

impl GruOdeBackprop {
    /// The planner whose parameters are in `varmap`, of shape `cfg` (a GRU-ODE).
    pub fn from_varmap(varmap: &VarMap, cfg: &PlannerConfig) -> Result<Self> {
        if cfg.kind != PlannerKind::GruOde {
            candle_core::bail!("the hand-written update is for GRU-ODE planners, not '{}'", cfg.kind.name());
        }
        if !(1..=3).contains(&cfg.dim) {
            candle_core::bail!("plans of dimension 1 to 3, not {}", cfg.dim);
        }
        let at = Offsets::new(cfg.dim, cfg.hidden);
        let mut me = Self { cfg: *cfg, at, params: vec![0.0; at.end], work: Work::default() };
        me.load(varmap)?;
        Ok(me)
    }

    /// Number of parameters.
    pub fn num_params(&self) -> usize {
        self.at.end
    }

    /// Calls `f` with each parameter's variable in `varmap` and its range in the flat
    /// vector, after checking that it exists with the expected shape.
    fn each_var(
        &self,
        varmap: &VarMap,
        mut f: impl FnMut(&candle_core::Var, &[usize], std::ops::Range<usize>) -> Result<()>,
    ) -> Result<()> {
        let data = varmap.data().lock().expect("varmap lock");
        let mut off = 0;
        for (name, shape) in layout(&self.cfg) {
            let var = data
                .get(name)
                .ok_or_else(|| candle_core::Error::Msg(format!("no planner weight '{name}'")))?;
            if var.dims() != shape.as_slice() {
                candle_core::bail!("planner weight '{name}' has shape {:?}, expected {shape:?}", var.dims());
            }
            let n: usize = shape.iter().product();
            f(var, &shape, off..off + n)?;
            off += n;
        }
        Ok(())
    }

    /// Copies the parameters from `varmap`.
    pub fn load(&mut self, varmap: &VarMap) -> Result<()> {
        let mut params = std::mem::take(&mut self.params);
        let r = self.each_var(varmap, |var, _, range| {
            let v: Vec<f32> = var.as_tensor().to_dtype(DType::F32)?.flatten_all()?.to_vec1()?;
            params[range].copy_from_slice(&v);
            Ok(())
        });
        self.params = params;
        r
    }

    /// Writes the parameters into `varmap`.
    pub fn store(&self, varmap: &VarMap) -> Result<()> {
        self.each_var(varmap, |var, shape, range| {
            let t = Tensor::from_slice(&self.params[range], shape, var.device())?;
            var.set(&t.to_dtype(var.dtype())?)
        })
    }

    /// Runs the planner over `batch` paths of `steps` waypoints from `starts`
    /// (`[batch][dim]`). With `noise` (`[batch][steps][dim]`) the waypoints are
    /// sampled, `g_{i+1} = μ_i + σ_i ε_i`; with `paths` (`[batch][steps + 1][dim]`)
    /// they are given and `ε_i = (g_{i+1} − μ_i)/σ_i` is recovered, which is the same
    /// pass for paths this planner sampled.
    pub fn forward(&self, source: Source<'_>, batch: usize, steps: usize, tape: &mut Tape) {
        let (d, h) = (self.cfg.dim, self.cfg.hidden);
        let p = &self.params;
        let at = self.at;
        let bound = self.cfg.bound as f32;
        let min_std = self.cfg.min_std as f32;
        tape.batch = batch;
        tape.steps = steps;
        let per = (steps + 1) * d;
        tape.paths.resize(batch * per, 0.0);
        match source {
            Source::Sample { starts, .. } => {
                for b in 0..batch {
                    tape.paths[b * per..b * per + d].copy_from_slice(&starts[b * d..(b + 1) * d]);
                }
            }
            Source::Paths(paths) => tape.paths.copy_from_slice(&paths[..batch * per]),
        }
        tape.hs.clear();
        tape.hs.resize((steps + 1) * batch * h, 0.0);
        tape.gates.resize(steps * batch * 4 * h, 0.0);
        for v in [&mut tape.tanh_a, &mut tape.s, &mut tape.sigma, &mut tape.eps] {
            v.resize(steps * batch * d, 0.0);
        }
        let mut hidden_gh = std::mem::take(&mut tape.hidden_gh);
        let mut input_gi = std::mem::take(&mut tape.input_gi);
        hidden_gh.resize(batch * 3 * h, 0.0);
        input_gi.resize(batch * 3 * h, 0.0);
        for i in 0..steps {
            let (done, rest) = tape.hs.split_at_mut((i + 1) * batch * h);
            let h_in = &done[i * batch * h..];
            let h_out = &mut rest[..batch * h];
            // gh = h W_hhᵀ + b_hh and gi = x W_ihᵀ + b_ih (x: this step's waypoints).
            for (gh_row, gi_row) in hidden_gh.chunks_exact_mut(3 * h).zip(input_gi.chunks_exact_mut(3 * h)) {
                gh_row.copy_from_slice(&p[at.b_hh..at.b_hh + 3 * h]);
                gi_row.copy_from_slice(&p[at.b_ih..at.b_ih + 3 * h]);
            }
            gemm((batch, h, 3 * h), h_in, (h, 1), &p[at.w_hh..], (1, h), 1.0, &mut hidden_gh);
            gemm(
                (batch, d, 3 * h),
                &tape.paths[i * d..],
                (per, 1),
                &p[at.w_ih..],
                (1, d),
                1.0,
                &mut input_gi,
            );
            for b in 0..batch {
                let ghb = &hidden_gh[b * 3 * h..(b + 1) * 3 * h];
                let gib = &input_gi[b * 3 * h..(b + 1) * 3 * h];
                let g = &mut tape.gates[(i * batch + b) * 4 * h..(i * batch + b + 1) * 4 * h];
                let hb = &h_in[b * h..(b + 1) * h];
                let ob = &mut h_out[b * h..(b + 1) * h];
                for j in 0..h {
                    let r = sigmoid(gib[j] + ghb[j]);
                    let z = sigmoid(gib[h + j] + ghb[h + j]);
                    let n = fast_tanh(gib[2 * h + j] + r * ghb[2 * h + j]);
                    ob[j] = (1.0 - z) * n + z * hb[j];
                    g[j] = r;
                    g[h + j] = z;
                    g[2 * h + j] = n;
                    g[3 * h + j] = ghb[2 * h + j];
                }
                // Heads and the next waypoint.
                for k in 0..d {
                    let wm = &p[at.w_m + k * h..at.w_m + (k + 1) * h];
                    let ws = &p[at.w_s + k * h..at.w_s + (k + 1) * h];
                    let a = p[at.b_m + k] + wm.iter().zip(ob.iter()).map(|(w, v)| w * v).sum::<f32>();
                    let s = p[at.b_s + k] + ws.iter().zip(ob.iter()).map(|(w, v)| w * v).sum::<f32>();
                    let ta = fast_tanh(a);
                    let sigma = s.abs() + min_std;
                    let mu = tape.paths[b * per + i * d + k] + bound * ta;
                    let o = (i * batch + b) * d + k;
                    tape.tanh_a[o] = ta;
                    tape.s[o] = s;
                    tape.sigma[o] = sigma;
                    let next = b * per + (i + 1) * d + k;
                    match source {
                        Source::Sample { noise, .. } => {
                            let e = noise[(b * steps + i) * d + k];
                            tape.eps[o] = e;
                            tape.paths[next] = mu + sigma * e;
                        }
                        Source::Paths(_) => tape.eps[o] = (tape.paths[next] - mu) / sigma,
                    }
                }
            }
        }
        tape.hidden_gh = hidden_gh;
        tape.input_gi = input_gi;
    }

    /// `log π` of each path on `tape` (the paths as data).
    pub fn log_probs(&self, tape: &Tape) -> Vec<f32> {
        let d = self.cfg.dim;
        let half_ln_tau = 0.918_938_5_f32;
        (0..tape.batch)
            .map(|b| {
                (0..tape.steps)
                    .flat_map(|i| (0..d).map(move |k| (i * tape.batch + b) * d + k))
                    .map(|o| -0.5 * tape.eps[o] * tape.eps[o] - tape.sigma[o].ln() - half_ln_tau)
                    .sum()
            })
            .collect()
    }

    /// The gradient of `L = −Σ_k score_k log π(τ_k) − Σ_k dρ_k · τ_k` (with `score_k =
    /// w A_k / B` and `drho` the gradient of `λ/B Σ ρ` with respect to every waypoint,
    /// `[batch][steps + 1][dim]`) into `grad` (zeroed first).
    pub fn backward(&mut self, tape: &Tape, drho: &[f32], score: &[f32], grad: &mut Vec<f32>) {
        let (d, h) = (self.cfg.dim, self.cfg.hidden);
        let (bsz, steps) = (tape.batch, tape.steps);
        let per = (steps + 1) * d;
        assert_eq!(drho.len(), bsz * per, "one ρ gradient per waypoint number of the tape");
        assert_eq!(score.len(), bsz, "one score weight per path of the tape");
        let at = self.at;
        let p = &self.params;
        let bound = self.cfg.bound as f32;
        grad.clear();
        grad.resize(at.end, 0.0);
        let w = &mut self.work;
        // The loss is −λ/B Σ ρ: its gradient at each waypoint is −drho.
        w.gx.clear();
        w.gx.extend(drho.iter().map(|g| -g));
        w.dh.clear();
        w.dh.resize(2 * bsz * h, 0.0);
        w.dh_prev.resize(2 * bsz * h, 0.0);
        for v in [&mut w.dgh, &mut w.dgi] {
            v.resize(2 * bsz * 3 * h, 0.0);
        }
        for v in [&mut w.dgh_sum, &mut w.dgi_sum] {
            v.resize(bsz * 3 * h, 0.0);
        }
        for v in [&mut w.da, &mut w.ds] {
            v.resize(2 * bsz * d, 0.0);
        }
        for v in [&mut w.da_sum, &mut w.ds_sum] {
            v.resize(bsz * d, 0.0);
        }
        for i in (0..steps).rev() {
            let h_in = &tape.hs[i * bsz * h..(i + 1) * bsz * h];
            let h_out = &tape.hs[(i + 1) * bsz * h..(i + 2) * bsz * h];
            // Heads: dμ and dσ of both streams.
            for (b, &score_b) in score.iter().enumerate().take(bsz) {
                for k in 0..d {
                    let o = (i * bsz + b) * d + k;
                    let (ta, s, sigma, e) = (tape.tanh_a[o], tape.s[o], tape.sigma[o], tape.eps[o]);
                    let sign = if s > 0.0 {
                        1.0
                    } else if s < 0.0 {
                        -1.0
                    } else {
                        0.0
                    };
                    let g_next = w.gx[b * per + (i + 1) * d + k];
                    // Reparameterised: g' = μ + σ ε.
                    let (dmu_r, dsig_r) = (g_next, g_next * e);
                    // Score: −score_b ∂log π/∂(μ, σ) = −score_b (ε/σ, (ε² − 1)/σ).
                    let c = -score_b;
                    let (dmu_s, dsig_s) = (c * e / sigma, c * (e * e - 1.0) / sigma);
                    let dta = bound * (1.0 - ta * ta);
                    w.da[b * d + k] = dmu_r * dta;
                    w.ds[b * d + k] = dsig_r * sign;
                    w.da[(bsz + b) * d + k] = dmu_s * dta;
                    w.ds[(bsz + b) * d + k] = dsig_s * sign;
                    w.da_sum[b * d + k] = (dmu_r + dmu_s) * dta;
                    w.ds_sum[b * d + k] = (dsig_r + dsig_s) * sign;
                    // μ = g + …: the waypoint itself passes dμ on (reparameterised only).
                    w.gx[b * per + i * d + k] += dmu_r;
                }
            }
            // Head weights: dW_m += daᵀ h', db_m += Σ da (same for the std head).
            gemm((d, bsz, h), &w.da_sum, (1, d), h_out, (h, 1), 1.0, &mut grad[at.w_m..at.w_m + d * h]);
            gemm((d, bsz, h), &w.ds_sum, (1, d), h_out, (h, 1), 1.0, &mut grad[at.w_s..at.w_s + d * h]);
            for b in 0..bsz {
                for k in 0..d {
                    grad[at.b_m + k] += w.da_sum[b * d + k];
                    grad[at.b_s + k] += w.ds_sum[b * d + k];
                }
            }
            // dh' of both streams += da W_m + ds W_s.
            gemm((2 * bsz, d, h), &w.da, (d, 1), &p[at.w_m..], (h, 1), 1.0, &mut w.dh);
            gemm((2 * bsz, d, h), &w.ds, (d, 1), &p[at.w_s..], (h, 1), 1.0, &mut w.dh);
            // GRU cell, both streams.
            for row in 0..2 * bsz {
                let b = row % bsz;
                let g = &tape.gates[(i * bsz + b) * 4 * h..(i * bsz + b + 1) * 4 * h];
                let hb = &h_in[b * h..(b + 1) * h];
                let dhr = &w.dh[row * h..(row + 1) * h];
                let dgh = &mut w.dgh[row * 3 * h..(row + 1) * 3 * h];
                let dgi = &mut w.dgi[row * 3 * h..(row + 1) * 3 * h];
                let dprev = &mut w.dh_prev[row * h..(row + 1) * h];
                for j in 0..h {
                    let (r, z, n, ghn) = (g[j], g[h + j], g[2 * h + j], g[3 * h + j]);
                    let dh = dhr[j];
                    let dn = dh * (1.0 - z);
                    let dz = dh * (hb[j] - n);
                    dprev[j] = dh * z;
                    let dpre_n = dn * (1.0 - n * n);
                    let dr = dpre_n * ghn;
                    let dpre_z = dz * z * (1.0 - z);
                    let dpre_r = dr * r * (1.0 - r);
                    dgi[j] = dpre_r;
                    dgi[h + j] = dpre_z;
                    dgi[2 * h + j] = dpre_n;
                    dgh[j] = dpre_r;
                    dgh[h + j] = dpre_z;
                    dgh[2 * h + j] = dpre_n * r;
                }
            }
            // dh_prev += dgh W_hh (both streams).
            gemm((2 * bsz, 3 * h, h), &w.dgh, (3 * h, 1), &p[at.w_hh..], (h, 1), 1.0, &mut w.dh_prev);
            // Weight gradients from the two streams' sum.
            let (rep, sc) = w.dgh.split_at(bsz * 3 * h);
            for ((o, a), b) in w.dgh_sum.iter_mut().zip(rep).zip(sc) {
                *o = a + b;
            }
            let (rep, sc) = w.dgi.split_at(bsz * 3 * h);
            for ((o, a), b) in w.dgi_sum.iter_mut().zip(rep).zip(sc) {
                *o = a + b;
            }
            gemm(
                (3 * h, bsz, h),
                &w.dgh_sum,
                (1, 3 * h),
                h_in,
                (h, 1),
                1.0,
                &mut grad[at.w_hh..at.w_hh + 3 * h * h],
            );
            // dW_ih += dgi_sumᵀ X (X: this step's input waypoints), and the biases.
            gemm(
                (3 * h, bsz, d),
                &w.dgi_sum,
                (1, 3 * h),
                &tape.paths[i * d..],
                (per, 1),
                1.0,
                &mut grad[at.w_ih..at.w_ih + 3 * h * d],
            );
            for (gi, gh) in w.dgi_sum.chunks_exact(3 * h).zip(w.dgh_sum.chunks_exact(3 * h)) {
                for (o, v) in grad[at.b_ih..at.b_ih + 3 * h].iter_mut().zip(gi) {
                    *o += v;
                }
                for (o, v) in grad[at.b_hh..at.b_hh + 3 * h].iter_mut().zip(gh) {
                    *o += v;
                }
            }
            // The input waypoints' gradient: dgi W_ih (reparameterised stream only).
            if i > 0 {
                w.dx.clear();
                w.dx.resize(bsz * d, 0.0);
                gemm((bsz, 3 * h, d), &w.dgi, (3 * h, 1), &p[at.w_ih..], (d, 1), 0.0, &mut w.dx);
                for b in 0..bsz {
                    for k in 0..d {
                        w.gx[b * per + i * d + k] += w.dx[b * d + k];
                    }
                }
            }
            std::mem::swap(&mut w.dh, &mut w.dh_prev);
        }
    }
}

/// Where a forward pass gets its waypoints.
#[derive(Clone, Copy, Debug)]
pub enum Source<'a> {
    /// Sample them from `starts` (`[batch][dim]`) with standard-normal `noise`
    /// (`[batch][steps][dim]`).
    Sample {
        /// Start waypoints.
        starts: &'a [f32],
        /// Noise.
        noise: &'a [f32],
    },
    /// Take them as given (`[batch][steps + 1][dim]`, starts included).
    Paths(&'a [f32]),
}
