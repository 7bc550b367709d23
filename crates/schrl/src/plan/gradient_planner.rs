//! The gradient planner baseline (Leung et al.; paper App. J, Table 5).
//!
//! No network: the waypoints themselves are the variables. From random waypoints in
//! the map's region, Adam climbs the soft robustness of the task's spec (exact
//! gradients from [`stl::Spec::gradient`]) until the hard robustness is positive;
//! after `iterations` steps without success it restarts from new random waypoints,
//! up to `restarts` times. The start waypoint is given, not planned.
//!
//! Four additions to plain gradient ascent, each switchable, each found where plain
//! ascent fails or its plans fail (README *Deployed plans and the gradient planner*);
//! the first two are on by default:
//! - *Region:* every step projects the waypoints back into the map's region; without
//!   it a clause that is met nowhere near the walls pushes waypoints metres past the
//!   map's edge, where no controller follows in time.
//! - *Repair:* every `repair_every` steps while the hard robustness is negative, one
//!   of the waypoints the hard robustness binds on (those its subgradient moves) is
//!   drawn afresh in the region, and its Adam moments reset. Loop's alternation makes
//!   the landscape multi-modal (moving a waypoint to another corner crosses robustness
//!   −1.4 halfway); ascent settles a waypoint in the wrong corner and stays there, and
//!   a redraw is a local restart of the one waypoint at fault (min-conflicts search).
//! - *Target* (off by default): once a plan satisfies the spec, ascent goes on in the
//!   same attempt until the hard robustness reaches `target` or the attempt's steps
//!   run out, and the most robust satisfying plan seen is returned; e.g. the planning
//!   network's constraint margin ε ([`CpgConfig::epsilon`]), to hold both planners to
//!   `ρ ≥ ε`. The default stops at the first `ρ > 0`, as Leung et al. On Point Loop
//!   (Fig. 4 (c), seed 3) a target of ε lifted executed satisfaction from 0.346 to
//!   0.416: the failures are not margins but 180° turns between two adjacent corners,
//!   whose swings reach the outer walls (README).
//! - *Draw* (region by default): waypoints are drawn, at the start of an attempt and
//!   on a repair, uniformly in the region or at a random goal's centre
//!   ([`WaypointDraw`]).
//!
//! Defaults (this project's; the paper gives none): Adam step 0.1, β (0.9, 0.999),
//! soft STL with α = 10 (the training semantics of [`crate::plan::cpg::CpgConfig`]);
//! region and repair on, a repair every 20 steps, attempts of 5000 steps (repairs need
//! room: Loop took 2.2 attempts of 2000 steps, 1.4 of 5000, on 40 starts not among
//! Table 5's), at most 10 attempts. Easy specs end within one attempt's first
//! hundred steps whatever these are.

use rand::Rng;
use rand_chacha::ChaCha8Rng;
use stl::{EvalError, Evaluator, Semantics, Spec};

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
    /// Project the waypoints into the map's region after every step.
    pub in_region: bool,
    /// Steps between redraws of a binding waypoint while unsatisfied (0: never).
    pub repair_every: usize,
    /// Hard robustness that ends the search once a plan satisfies (0: the first
    /// satisfying plan, the default).
    pub target: f64,
    /// Where initial and redrawn waypoints are drawn.
    pub draw: WaypointDraw,
}

/// Where the gradient planner draws a waypoint (at the start of an attempt, and on a
/// repair).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum WaypointDraw {
    /// Uniformly in the map's region (the default).
    #[default]
    Region,
    /// At the centre of a goal chosen uniformly (the region when the task has no
    /// goals): a discrete search over which goal each waypoint visits, which ascent
    /// then refines. Drone Loop's only satisfying plans with the planning margins
    /// bounce between two goals; drawn in the region, repairs found that bounce from
    /// none of 10 starts.
    GoalCentres,
}

impl std::str::FromStr for WaypointDraw {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "region" => Ok(WaypointDraw::Region),
            "goal-centres" => Ok(WaypointDraw::GoalCentres),
            other => Err(format!("unknown waypoint draw '{other}': expected region or goal-centres")),
        }
    }
}

impl Default for GradientPlannerConfig {
    fn default() -> Self {
        Self {
            lr: 0.1,
            iterations: 5000,
            restarts: 10,
            semantics: CpgConfig::default().semantics,
            in_region: true,
            repair_every: 20,
            target: 0.0,
            draw: WaypointDraw::Region,
        }
    }
}

impl GradientPlannerConfig {
    /// Plain gradient ascent with random restarts, as Leung et al. (no region, no
    /// repair, the first satisfying plan; 200 steps per attempt, 50 attempts: the same
    /// 10 000-step budget as before the repair, which needs longer attempts).
    pub fn plain() -> Self {
        Self {
            in_region: false,
            repair_every: 0,
            iterations: 200,
            restarts: 50,
            target: 0.0,
            ..Self::default()
        }
    }

    /// Checks the settings; a message starts with the bad field's name (`target: …`).
    pub fn validate(&self) -> Result<(), String> {
        if !(self.lr > 0.0 && self.lr.is_finite()) {
            return Err(format!("lr: must be a positive number, got {}", self.lr));
        }
        if self.iterations == 0 {
            return Err("iterations: must be at least 1".into());
        }
        if !(self.target >= 0.0 && self.target.is_finite()) {
            return Err(format!("target: must be a non-negative robustness, got {}", self.target));
        }
        Ok(())
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
    let hard = Semantics::hard();
    let mut best: Option<GradientPlan> = None;
    let mut total = 0;
    let mut ev = spec.evaluator();
    for attempt in 1..=cfg.restarts.max(1) {
        // Every waypoint drawn, the start too (then given): the random stream of
        // region draws is the one this planner has always used.
        let mut path = vec![0.0; n];
        for w in path.chunks_mut(dim) {
            draw_waypoint(task, cfg.draw, w, rng);
        }
        path[..dim].copy_from_slice(start);
        let (found, steps) = ascend(task, &mut ev, &mut path, cfg, rng)?;
        total += steps;
        if let Some(mut s) = found {
            (s.attempts, s.iterations) = (attempt, total);
            return Ok(s);
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

/// One attempt of [`plan`] from `path` as given (`(steps + 1) · dim` numbers, the
/// start first and kept): ascent, repairs and the target as `cfg` says. Returns the
/// most robust satisfying plan seen, else the attempt's last path (robustness
/// ≤ 0), with `attempts` 1. A plan for one start refined into a plan for a nearby
/// start keeps its shape (which goals it visits in which order) where a fresh search
/// may find another: the per-start plans a planner network can be fitted to
/// ([`crate::plan::pretrain`]'s guide).
pub fn refine(
    task: &Task,
    spec: &Spec,
    mut path: Vec<f64>,
    cfg: &GradientPlannerConfig,
    rng: &mut ChaCha8Rng,
) -> Result<GradientPlan, EvalError> {
    let mut ev = spec.evaluator();
    let (found, iterations) = ascend(task, &mut ev, &mut path, cfg, rng)?;
    if let Some(mut s) = found {
        s.iterations = iterations;
        return Ok(s);
    }
    let robustness = ev.robustness(&path, &Semantics::hard())?;
    Ok(GradientPlan { path, robustness, attempts: 1, iterations })
}

/// Adam ascent of `path`'s soft robustness for at most `cfg.iterations` steps, the
/// start fixed. Returns the most robust satisfying plan seen (`attempts` 1) and the
/// steps taken; `path` is left where ascent stopped.
fn ascend(
    task: &Task,
    ev: &mut Evaluator<'_>,
    path: &mut [f64],
    cfg: &GradientPlannerConfig,
    rng: &mut ChaCha8Rng,
) -> Result<(Option<GradientPlan>, usize), EvalError> {
    let dim = task.map.dim();
    let n = path.len();
    let (lo, hi) = task.map.region();
    let hard = Semantics::hard();
    let (b1, b2) = (0.9f64, 0.999f64);
    let mut grad = vec![0.0; n];
    let (mut m, mut v) = (vec![0.0; n], vec![0.0; n]);
    let mut satisfying: Option<GradientPlan> = None;
    let mut steps = 0;
    for it in 1..=cfg.iterations {
        steps = it;
        grad.iter_mut().for_each(|g| *g = 0.0);
        ev.gradient(path, 0, &cfg.semantics, &mut grad)?;
        let (c1, c2) = (1.0 - b1.powi(it as i32), 1.0 - b2.powi(it as i32));
        for i in dim..n {
            m[i] = b1 * m[i] + (1.0 - b1) * grad[i];
            v[i] = b2 * v[i] + (1.0 - b2) * grad[i] * grad[i];
            path[i] += cfg.lr * (m[i] / c1) / ((v[i] / c2).sqrt() + 1e-8);
            if cfg.in_region {
                path[i] = path[i].clamp(lo[i % dim], hi[i % dim]);
            }
        }
        let repair =
            cfg.repair_every > 0 && it % cfg.repair_every == 0 && it < cfg.iterations && satisfying.is_none();
        // The hard check every 10 steps (and before a repair): it costs as much as a gradient.
        if it % 10 == 0 || repair {
            let rho = ev.robustness(path, &hard)?;
            if rho > 0.0 && satisfying.as_ref().is_none_or(|s| rho > s.robustness) {
                satisfying =
                    Some(GradientPlan { path: path.to_vec(), robustness: rho, attempts: 1, iterations: it });
            }
            if rho >= cfg.target && rho > 0.0 {
                break;
            }
            if repair && rho <= 0.0 {
                redraw_a_binding_waypoint(ev, path, task, cfg.draw, rng, &mut grad)?;
                for k in (0..n).filter(|&k| grad[k] != 0.0) {
                    (m[k], v[k]) = (0.0, 0.0);
                }
            }
        }
    }
    Ok((satisfying, steps))
}

/// Draws one waypoint `w` (`dim` numbers) as `draw` says.
fn draw_waypoint(task: &Task, draw: WaypointDraw, w: &mut [f64], rng: &mut ChaCha8Rng) {
    match draw {
        WaypointDraw::GoalCentres if !task.goals.is_empty() => {
            let goal = &task.goals[rng.random_range(0..task.goals.len())];
            w.copy_from_slice(&goal.center);
        }
        _ => {
            let (lo, hi) = task.map.region();
            for (d, x) in w.iter_mut().enumerate() {
                *x = rng.random_range(lo[d]..hi[d]);
            }
        }
    }
}

/// Draws afresh (as `draw` says) one of the planned waypoints the hard robustness's
/// subgradient moves (chosen uniformly among them), leaving in `grad` nonzero entries
/// exactly at the redrawn waypoint's coordinates.
fn redraw_a_binding_waypoint(
    ev: &mut Evaluator<'_>,
    path: &mut [f64],
    task: &Task,
    draw: WaypointDraw,
    rng: &mut ChaCha8Rng,
    grad: &mut [f64],
) -> Result<(), EvalError> {
    let dim = task.map.dim();
    grad.iter_mut().for_each(|g| *g = 0.0);
    ev.gradient(path, 0, &Semantics::hard(), grad)?;
    let binding: Vec<usize> =
        (1..path.len() / dim).filter(|&w| grad[w * dim..(w + 1) * dim].iter().any(|&g| g != 0.0)).collect();
    grad.iter_mut().for_each(|g| *g = 0.0);
    if binding.is_empty() {
        return Ok(());
    }
    let w = binding[rng.random_range(0..binding.len())];
    draw_waypoint(task, draw, &mut path[w * dim..(w + 1) * dim], rng);
    grad[w * dim..(w + 1) * dim].iter_mut().for_each(|g| *g = 1.0);
    Ok(())
}
