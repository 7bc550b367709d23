//! The gradient planner baseline (Leung et al.; paper App. J, Table 5).
//!
//! No network: the waypoints themselves are the variables. From random waypoints in
//! the map's region, Adam climbs the soft robustness of the task's spec (exact
//! gradients from [`stl::Spec::gradient`]) until the hard robustness is positive;
//! after `iterations` steps without success it restarts from new random waypoints,
//! up to `restarts` times. The start waypoint is given, not planned.
//!
//! Defaults (this project's; the paper gives none): Adam step 0.1, β (0.9, 0.999),
//! 200 steps per attempt, 50 attempts, soft STL with α = 10 (the training semantics
//! of [`crate::plan::cpg::CpgConfig`]).

use rand::Rng;
use rand_chacha::ChaCha8Rng;
use stl::{EvalError, Semantics, Spec};

use crate::plan::cpg::CpgConfig;
use crate::task::Task;

/// Settings of the gradient planner.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GradientPlannerConfig {
    /// Adam step size.
    pub lr: f64,
    /// Adam steps per attempt.
    pub iterations: usize,
    /// Attempts (random initialisations) before giving up.
    pub restarts: usize,
    /// Semantics whose gradient is followed.
    pub semantics: Semantics,
}

impl Default for GradientPlannerConfig {
    fn default() -> Self {
        Self { lr: 0.1, iterations: 200, restarts: 50, semantics: CpgConfig::default().semantics }
    }
}

/// A plan found by gradient ascent.
#[derive(Clone, Debug, PartialEq)]
pub struct GradientPlan {
    /// `(steps + 1) · dim` numbers, the start first.
    pub path: Vec<f64>,
    /// Hard robustness of the path (> 0: satisfied).
    pub robustness: f64,
    /// Attempts used (1 if the first initialisation succeeded).
    pub attempts: usize,
    /// Adam steps over all attempts.
    pub iterations: usize,
}

impl GradientPlan {
    /// `true` if the path satisfies the spec.
    pub fn satisfied(&self) -> bool {
        self.robustness > 0.0
    }
}

/// Plans for `task` from `start` by gradient ascent on robustness with restarts;
/// returns the best path found (satisfying unless every attempt failed).
pub fn plan(
    task: &Task,
    spec: &Spec,
    start: &[f64],
    cfg: &GradientPlannerConfig,
    rng: &mut ChaCha8Rng,
) -> Result<GradientPlan, EvalError> {
    let dim = task.map.dim();
    let n = (task.steps + 1) * dim;
    let (lo, hi) = task.map.region();
    let hard = Semantics::hard();
    let (b1, b2) = (0.9f64, 0.999f64);
    let mut best: Option<GradientPlan> = None;
    let mut total = 0;
    for attempt in 1..=cfg.restarts.max(1) {
        let mut path: Vec<f64> = (0..n).map(|i| rng.random_range(lo[i % dim]..hi[i % dim])).collect();
        path[..dim].copy_from_slice(start);
        let (mut m, mut v) = (vec![0.0; n], vec![0.0; n]);
        let mut ev = spec.evaluator();
        let mut grad = vec![0.0; n];
        for it in 1..=cfg.iterations {
            total += 1;
            grad.iter_mut().for_each(|g| *g = 0.0);
            ev.gradient(&path, 0, &cfg.semantics, &mut grad)?;
            let (c1, c2) = (1.0 - b1.powi(it as i32), 1.0 - b2.powi(it as i32));
            for i in dim..n {
                m[i] = b1 * m[i] + (1.0 - b1) * grad[i];
                v[i] = b2 * v[i] + (1.0 - b2) * grad[i] * grad[i];
                path[i] += cfg.lr * (m[i] / c1) / ((v[i] / c2).sqrt() + 1e-8);
            }
            // The hard check every 10 steps: it costs as much as a gradient.
            if it % 10 == 0 {
                let rho = ev.robustness(&path, &hard)?;
                if rho > 0.0 {
                    return Ok(GradientPlan { path, robustness: rho, attempts: attempt, iterations: total });
                }
            }
        }
        let rho = ev.robustness(&path, &hard)?;
        if best.as_ref().is_none_or(|b| rho > b.robustness) {
            best = Some(GradientPlan { path, robustness: rho, attempts: attempt, iterations: total });
        }
    }
    let mut best = best.expect("at least one attempt");
    best.attempts = cfg.restarts.max(1);
    best.iterations = total;
    Ok(best)
}
