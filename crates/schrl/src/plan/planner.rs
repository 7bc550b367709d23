//! The GRU-ODE planning policy (paper §3.2, Eq. 3, App. F).
//!
//! From a start `g0`, a GRU cell reads the current waypoint and its hidden state;
//! the next waypoint's mean is the current one plus a bounded step,
//! `μ_{i+1} = g_i + bound · tanh(W h_{i+1})` (an Euler step of a neural ODE with
//! step 1, so gradients pass along the path as in a ResNet). The policy is Gaussian,
//! `g_{i+1} ~ N(μ_{i+1}, σ_{i+1})` with `σ = |V h_{i+1}| + σ_min`, sampled with the
//! reparameterisation `g = μ + σ ε`, so that a path is differentiable in the
//! parameters (the constraint term of Eq. 4 needs it) and has a log-probability
//! (the policy-gradient term needs that).
//!
//! Defaults from the reference setup: hidden size 64, one layer, step bound 10,
//! `σ_min` = 0.1.
//!
//! Two ablations of Fig. 6 share the Gaussian policy and differ in the mean
//! ([`PlannerKind`]): a plain GRU that predicts the next waypoint directly,
//! `μ_{i+1} = W h_{i+1}` (memory, no ODE step), and an MLP that sees only the current
//! waypoint, `μ_{i+1} = g_i + bound · tanh(W tanh(U g_i))` (the ODE step, no memory).

use candle_core::{D, Result, Tensor};
use candle_nn::rnn::{GRU, GRUConfig, GRUState, RNN, gru};
use candle_nn::{Linear, Module, VarBuilder, linear};

/// Which network maps the current waypoint to the next one's Gaussian.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum PlannerKind {
    /// The paper's GRU-ODE: memory and a bounded residual step (Eq. 3).
    #[default]
    GruOde,
    /// A GRU whose output is the next waypoint itself (no residual step).
    Gru,
    /// A one-hidden-layer tanh MLP of the current waypoint (no memory), residual step.
    Mlp,
}

impl PlannerKind {
    /// Its name on the command line and in checkpoints.
    pub fn name(self) -> &'static str {
        match self {
            PlannerKind::GruOde => "gru-ode",
            PlannerKind::Gru => "gru",
            PlannerKind::Mlp => "mlp",
        }
    }
}

impl std::str::FromStr for PlannerKind {
    type Err = String;

    fn from_str(s: &str) -> std::result::Result<Self, Self::Err> {
        match s {
            "gru-ode" => Ok(PlannerKind::GruOde),
            "gru" => Ok(PlannerKind::Gru),
            "mlp" => Ok(PlannerKind::Mlp),
            other => Err(format!("unknown planner '{other}': expected gru-ode, gru or mlp")),
        }
    }
}

/// Shape and constants of a planner.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PlannerConfig {
    /// Plan-space dimension (2 or 3).
    pub dim: usize,
    /// GRU hidden size (reference: 64).
    pub hidden: usize,
    /// Largest waypoint step, `bound · tanh(·)` (reference: 10).
    pub bound: f64,
    /// Smallest standard deviation (reference: 0.1).
    pub min_std: f64,
    /// The network (the paper's GRU-ODE, or an ablation).
    pub kind: PlannerKind,
}

impl PlannerConfig {
    /// The reference setup's planner for `dim`-dimensional plans.
    pub fn reference(dim: usize) -> Self {
        Self { dim, hidden: 64, bound: 10.0, min_std: 0.1, kind: PlannerKind::GruOde }
    }

    /// Checks the shape and scales, naming the first bad field.
    pub fn validate(&self) -> std::result::Result<(), String> {
        if !(1..=3).contains(&self.dim) {
            return Err(format!("dim: {} is not a plan dimension (1 to 3)", self.dim));
        }
        if !(1..=4096).contains(&self.hidden) {
            return Err(format!("hidden: {} is not a hidden size in 1..=4096", self.hidden));
        }
        for (key, v) in [("bound", self.bound), ("min_std", self.min_std)] {
            if !(v > 0.0 && v.is_finite()) {
                return Err(format!("{key}: {v} must be a positive number"));
            }
        }
        Ok(())
    }
}

/// Sampled paths and their log-probabilities.
#[derive(Debug, Clone)]
pub struct PlanBatch {
    /// `[batch, steps + 1, dim]`, index 0 the start; differentiable in the parameters.
    pub paths: Tensor,
    /// `[batch]`, `log π(path)`.
    pub log_prob: Tensor,
}

/// The recurrent or feed-forward part of a planner.
enum Core {
    /// A GRU cell (GRU-ODE and plain GRU).
    Gru(GRU),
    /// The MLP's hidden layer.
    Mlp(Linear),
}

/// A Gaussian path planner: the GRU-ODE, or one of its ablations.
pub struct PathPlanner {
    core: Core,
    mean_head: Linear,
    std_head: Linear,
    cfg: PlannerConfig,
}

/// The hidden state carried along a path (empty for the MLP).
type State = Option<GRUState>;

const HALF_LN_TAU: f64 = 0.918_938_533_204_672_8; // ½ ln 2π

impl PathPlanner {
    /// A planner with parameters in `vb`.
    pub fn new(cfg: PlannerConfig, vb: VarBuilder) -> Result<Self> {
        cfg.validate().map_err(candle_core::Error::msg)?;
        let core = match cfg.kind {
            PlannerKind::GruOde | PlannerKind::Gru => {
                Core::Gru(gru(cfg.dim, cfg.hidden, GRUConfig::default(), vb.pp("gru"))?)
            }
            PlannerKind::Mlp => Core::Mlp(linear(cfg.dim, cfg.hidden, vb.pp("mlp"))?),
        };
        Ok(Self {
            core,
            mean_head: linear(cfg.hidden, cfg.dim, vb.pp("mean"))?,
            std_head: linear(cfg.hidden, cfg.dim, vb.pp("std"))?,
            cfg,
        })
    }

    /// The configuration.
    pub fn config(&self) -> &PlannerConfig {
        &self.cfg
    }

    /// One step: from waypoint `g` `[batch, dim]` and the hidden state, the next
    /// waypoint's mean and standard deviation.
    fn step(&self, g: &Tensor, state: &State) -> Result<(Tensor, Tensor, State)> {
        let (h, state) = match (&self.core, state) {
            (Core::Gru(cell), Some(s)) => {
                let s = cell.step(g, s)?;
                (s.h().clone(), Some(s))
            }
            (Core::Mlp(layer), _) => (layer.forward(g)?.tanh()?, None),
            (Core::Gru(_), None) => candle_core::bail!("a GRU planner needs a hidden state"),
        };
        let mean = match self.cfg.kind {
            PlannerKind::Gru => self.mean_head.forward(&h)?,
            PlannerKind::GruOde | PlannerKind::Mlp => {
                (g + (self.mean_head.forward(&h)?.tanh()? * self.cfg.bound)?)?
            }
        };
        let std = (self.std_head.forward(&h)?.abs()? + self.cfg.min_std)?;
        Ok((mean, std, state))
    }

    fn zero_state(&self, g0: &Tensor) -> Result<State> {
        match &self.core {
            Core::Gru(cell) => Ok(Some(cell.zero_state(g0.dim(0)?)?)),
            Core::Mlp(_) => Ok(None),
        }
    }

    /// Samples one path per start in `g0` (`[batch, dim]`) with standard-normal
    /// `noise` (`[batch, steps, dim]`): `g_{i+1} = μ + σ ε_i`.
    pub fn sample(&self, g0: &Tensor, noise: &Tensor) -> Result<PlanBatch> {
        let steps = noise.dim(1)?;
        let mut state = self.zero_state(g0)?;
        let mut g = g0.clone();
        let mut points = vec![g0.clone()];
        let mut log_prob = Tensor::zeros(g0.dim(0)?, g0.dtype(), g0.device())?;
        for i in 0..steps {
            let (mean, std, next) = self.step(&g, &state)?;
            let eps = noise.narrow(1, i, 1)?.squeeze(1)?;
            g = (mean + (&std * &eps)?)?;
            // log N(g; μ, σ) = −ε²/2 − ln σ − ½ ln 2π, per dimension.
            let lp = ((eps.sqr()? * -0.5)? - std.log()?)?.affine(1.0, -HALF_LN_TAU)?;
            log_prob = (log_prob + lp.sum(D::Minus1)?)?;
            points.push(g.clone());
            state = next;
        }
        Ok(PlanBatch { paths: Tensor::stack(&points, 1)?, log_prob })
    }

    /// The mean path (no sampling): `[batch, steps + 1, dim]`.
    pub fn mean_path(&self, g0: &Tensor, steps: usize) -> Result<Tensor> {
        let mut state = self.zero_state(g0)?;
        let mut g = g0.clone();
        let mut points = vec![g0.clone()];
        for _ in 0..steps {
            let (mean, _, next) = self.step(&g, &state)?;
            g = mean;
            points.push(g.clone());
            state = next;
        }
        Tensor::stack(&points, 1)
    }

    /// The Gaussian of every step of given paths `[batch, steps + 1, dim]`, each step
    /// conditioned on the path's own previous waypoints: `(means, stds)`, both
    /// `[batch, steps, dim]`.
    pub fn distributions(&self, paths: &Tensor) -> Result<(Tensor, Tensor)> {
        let steps = paths.dim(1)? - 1;
        let g0 = paths.narrow(1, 0, 1)?.squeeze(1)?;
        let mut state = self.zero_state(&g0)?;
        let (mut means, mut stds) = (Vec::with_capacity(steps), Vec::with_capacity(steps));
        for i in 0..steps {
            let g = paths.narrow(1, i, 1)?.squeeze(1)?;
            let (mean, std, next) = self.step(&g, &state)?;
            means.push(mean);
            stds.push(std);
            state = next;
        }
        Ok((Tensor::stack(&means, 1)?, Tensor::stack(&stds, 1)?))
    }

    /// `log π(path)` of given paths `[batch, steps + 1, dim]`: `[batch]`.
    pub fn log_prob(&self, paths: &Tensor) -> Result<Tensor> {
        let steps = paths.dim(1)? - 1;
        let (means, stds) = self.distributions(paths)?;
        let z = ((paths.narrow(1, 1, steps)? - means)? / &stds)?;
        let lp = ((z.sqr()? * -0.5)? - stds.log()?)?.affine(1.0, -HALF_LN_TAU)?;
        lp.sum(D::Minus1)?.sum(D::Minus1)
    }
}
