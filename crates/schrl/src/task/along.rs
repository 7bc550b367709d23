//! Which clauses of a spec hold *between* waypoints, and how an executed run is judged
//! on them.
//!
//! A spec is evaluated on a plan's waypoints: step `t` of the spec is waypoint `t`
//! (step 0 the start). The robot, though, drives the straight segment from waypoint
//! `t − 1` to waypoint `t` in between. Reaching a goal is an event at a waypoint, but
//! staying out of a region is a promise about the whole way there, so:
//!
//! * `safe` is checked along the segment into each waypoint (the task's
//!   [`super::SafeAlong`], default `segments`), wherever it appears.
//! * A goal region `r` is an **avoid region** of `G[a,b] ψ`, and of the left side `ψ`
//!   of `ψ U[a,b] χ`, when `ψ`, read as a conjunction, has `!r` as a conjunct (also
//!   `!(r1 | r2)`, which keeps out of both). That occurrence of `r` is then checked on
//!   the segment into each waypoint: the planner sees the largest value of `r` along
//!   the segment ([`SegmentRegion`]), and an executed run is judged on the largest
//!   value along the robot's trajectory between reaching waypoint `t − 1` and
//!   waypoint `t` ([`ExecutionSpec`]), so a run that enters `r` while the clause holds
//!   fails, and says where ("entered hazard at step 312").
//! * Every other occurrence of a goal (`F r`, `r -> X s`, `G (r1 | r2)`) is read at
//!   the waypoints, as the paper writes it.
//!
//! So `G[1,8] !hazard` keeps the robot out of `hazard` from the start until it
//! reaches waypoint 8; `G[3,5] !hazard` from reaching waypoint 2 until waypoint 5.

use std::sync::Arc;

use stl::{Ball, Formula, Predicate, Spec};

use super::{GoalRegion, Task};

/// The name an avoid occurrence of `goal` is bound under; `:` is not allowed in spec
/// names, so it never clashes with a user's.
pub(crate) fn along_name(goal: &str) -> String {
    format!("{goal}:along")
}

/// `formula` with every avoid occurrence of a name in `goals` renamed to
/// `along_name(goal)`; `found` collects those goals, each once, in order.
pub(super) fn mark_avoided(formula: &Formula, goals: &[&str], found: &mut Vec<String>) -> Formula {
    let mut rec = |f: &Formula| mark_avoided(f, goals, found);
    match formula {
        Formula::True | Formula::False | Formula::Atom(_) | Formula::Compare { .. } => formula.clone(),
        Formula::Not(f) => Formula::Not(Box::new(rec(f))),
        Formula::Next(f) => Formula::Next(Box::new(rec(f))),
        Formula::Eventually(i, f) => Formula::Eventually(*i, Box::new(rec(f))),
        Formula::And(v) => Formula::And(v.iter().map(rec).collect()),
        Formula::Or(v) => Formula::Or(v.iter().map(rec).collect()),
        Formula::Implies(l, r) => Formula::Implies(Box::new(rec(l)), Box::new(rec(r))),
        Formula::Globally(i, f) => Formula::Globally(*i, Box::new(held(f, goals, found))),
        Formula::Until(i, l, r) => {
            let l = held(l, goals, found);
            Formula::Until(*i, Box::new(l), Box::new(mark_avoided(r, goals, found)))
        }
    }
}

/// A formula that must hold over a window (`G`'s operand, `U`'s left side), read as
/// a conjunction: conjuncts `!r` and `!(r1 | …)` over goals become avoid occurrences.
fn held(f: &Formula, goals: &[&str], found: &mut Vec<String>) -> Formula {
    match f {
        Formula::And(v) => Formula::And(v.iter().map(|c| held(c, goals, found)).collect()),
        Formula::Not(inner) => match union_of_goals(inner, goals) {
            Some(names) => {
                for n in names {
                    if !found.iter().any(|f| f == n) {
                        found.push(n.to_string());
                    }
                }
                Formula::Not(Box::new(rename_union(inner)))
            }
            None => mark_avoided(f, goals, found),
        },
        _ => mark_avoided(f, goals, found),
    }
}

/// The goals of `f` when it is a goal or a disjunction of goals.
fn union_of_goals<'a>(f: &'a Formula, goals: &[&str]) -> Option<Vec<&'a str>> {
    match f {
        Formula::Atom(n) if goals.contains(&n.as_str()) => Some(vec![n.as_str()]),
        Formula::Or(v) => v.iter().try_fold(vec![], |mut acc, c| {
            acc.extend(union_of_goals(c, goals)?);
            Some(acc)
        }),
        _ => None,
    }
}

fn rename_union(f: &Formula) -> Formula {
    match f {
        Formula::Atom(n) => Formula::Atom(along_name(n)),
        Formula::Or(v) => Formula::Or(v.iter().map(rename_union).collect()),
        other => other.clone(),
    }
}

/// A goal disc checked along the segment into each waypoint: at step `t ≥ 1`,
/// `radius − dist(center, [x_{t−1}, x_t])`, the largest value of the goal's
/// [`stl::Ball`] on the segment (at step 0, the ball at the start). Negated, it is
/// the segment's clearance from the disc. Gradient: through the closest point of the
/// segment, split between its ends by where that point lies (exact where the
/// closest point is unique).
#[derive(Clone, Debug)]
pub struct SegmentRegion {
    ball: Ball,
}

impl SegmentRegion {
    /// The disc of `goal` grown by `margin`, checked along segments.
    pub fn new(goal: &GoalRegion, margin: f64) -> Self {
        Self { ball: Ball::new(goal.center.clone(), goal.radius + margin) }
    }

    /// The closest point of the segment into waypoint `t` (`t ≥ 1`) to the centre: where
    /// along it it lies (`s`, 0 at waypoint `t − 1`) and the point (first `dim` entries;
    /// plans are at most 3-D).
    fn closest(&self, path: &[f64], dim: usize, t: usize) -> (f64, [f64; 3]) {
        let (a, b) = (&path[(t - 1) * dim..t * dim], &path[t * dim..(t + 1) * dim]);
        let (mut ab2, mut dot) = (0.0, 0.0);
        for ((ai, bi), ci) in a.iter().zip(b).zip(&self.ball.center) {
            ab2 += (bi - ai) * (bi - ai);
            dot += (ci - ai) * (bi - ai);
        }
        let s = if ab2 > 0.0 { (dot / ab2).clamp(0.0, 1.0) } else { 0.0 };
        let mut q = [0.0; 3];
        for (qi, (ai, bi)) in q.iter_mut().zip(a.iter().zip(b)) {
            *qi = ai + s * (bi - ai);
        }
        (s, q)
    }
}

impl Predicate for SegmentRegion {
    fn value(&self, t: usize, state: &[f64]) -> f64 {
        self.ball.value(t, state)
    }

    fn value_and_grad(&self, t: usize, state: &[f64], scale: f64, grad: &mut [f64]) -> f64 {
        self.ball.value_and_grad(t, state, scale, grad)
    }

    fn required_dim(&self) -> usize {
        self.ball.required_dim()
    }

    fn value_on_path(&self, path: &[f64], dim: usize, t: usize) -> f64 {
        if t == 0 {
            return self.value(0, &path[..dim]);
        }
        let (_, q) = self.closest(path, dim, t);
        self.ball.value(t, &q[..dim])
    }

    fn value_and_grad_on_path(
        &self,
        path: &[f64],
        dim: usize,
        t: usize,
        scale: f64,
        grad: &mut [f64],
    ) -> f64 {
        if t == 0 {
            return self.value_and_grad(0, &path[..dim], scale, &mut grad[..dim]);
        }
        let (s, q) = self.closest(path, dim, t);
        // The gradient at the closest point, split between the ends (s fixed: the
        // envelope theorem, as q is the minimiser).
        let mut gq = [0.0; 3];
        let v = self.ball.value_and_grad(t, &q[..dim], scale, &mut gq[..dim]);
        for (i, g) in gq[..dim].iter().enumerate() {
            grad[(t - 1) * dim + i] += (1.0 - s) * g;
            grad[t * dim + i] += s * g;
        }
        v
    }
}

/// Reads one column of an executed path's augmented state: the largest value a
/// region took along the trajectory into that waypoint ([`ExecutionSpec`]).
#[derive(Clone, Copy, Debug)]
struct Column(usize);

impl Predicate for Column {
    fn value(&self, _t: usize, state: &[f64]) -> f64 {
        state[self.0]
    }

    fn value_and_grad(&self, _t: usize, state: &[f64], _scale: f64, _grad: &mut [f64]) -> f64 {
        state[self.0]
    }

    fn required_dim(&self) -> usize {
        self.0 + 1
    }
}

/// The planner's bindings for avoid occurrences: `(name, predicate)`.
pub(crate) fn planning_bindings(task: &Task) -> Vec<(String, Arc<dyn Predicate>)> {
    task.avoid_regions()
        .into_iter()
        .map(|g| {
            (along_name(&g.name), Arc::new(SegmentRegion::new(g, task.avoid_margin)) as Arc<dyn Predicate>)
        })
        .collect()
}

/// A run entered a region it was to stay out of, and that failed the spec.
#[derive(Clone, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct Entry {
    /// The region's name.
    pub region: String,
    /// The environment step at which the robot was first inside it.
    pub step: usize,
}

impl std::fmt::Display for Entry {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "entered {} at step {}", self.region, self.step)
    }
}

/// The verdict on an executed run.
#[derive(Clone, Debug, PartialEq)]
pub struct Judged {
    /// Hard robustness (−∞ when the run did not reach every waypoint).
    pub robustness: f64,
    /// Why it failed, when entering an avoid region did it.
    pub entered: Option<Entry>,
}

/// The spec a run is judged by: the task's spec on the executed path (the start,
/// then the positions where each waypoint was reached), with `safe` at those
/// positions (the trajectory itself is checked for collisions at every step, which
/// is stronger) and every avoid region on the trajectory between them.
pub struct ExecutionSpec {
    spec: Spec,
    regions: Vec<GoalRegion>,
    /// The regions' discs, as the trajectory is checked against them.
    discs: Vec<Ball>,
    dim: usize,
    steps: usize,
}

impl ExecutionSpec {
    /// The execution spec of `task`.
    pub fn new(task: &Task) -> Self {
        let dim = task.map.dim();
        let regions: Vec<GoalRegion> = task.avoid_regions().into_iter().cloned().collect();
        let columns = regions
            .iter()
            .enumerate()
            .map(|(j, g)| (along_name(&g.name), Arc::new(Column(dim + j)) as Arc<dyn Predicate>));
        // Judged on the exact geometry whatever the planner saw.
        let waypoints_only = Task {
            safe_along: super::SafeAlong::Waypoints,
            obstacle: super::ObstacleModel::Exact,
            ..task.clone()
        };
        let spec = waypoints_only
            .predicates()
            .into_iter()
            .chain(columns)
            .fold(
                Spec::builder(task.planning_formula()).state_dim(dim + regions.len()).until(super::UNTIL),
                |b, (n, p)| b.bind_shared(n, p),
            )
            .build()
            .expect("task names are checked when the task is loaded");
        let discs = regions.iter().map(|g| Ball::new(g.center.clone(), g.radius)).collect();
        Self { spec, regions, discs, dim, steps: task.steps }
    }

    /// The regions checked along the trajectory.
    pub fn avoid_regions(&self) -> &[GoalRegion] {
        &self.regions
    }

    /// The spec score of a run, finite whether or not it finished (the y-axis of the
    /// paper's Fig. 3 and Fig. 12): the hard robustness of [`ExecutionSpec::judge`] on
    /// the run with its unreached waypoints filled by where the robot ended (the last
    /// trajectory position, at the last step), as if it stayed there. Equal to the
    /// judged robustness for a run that reached every waypoint; a collided run ends at
    /// the obstacle, where `safe` is negative. `trajectory` must not be empty.
    pub fn score(&self, executed: &[Vec<f64>], trajectory: &[Vec<f64>], reached_at: &[usize]) -> f64 {
        self.judge_stopped(executed, trajectory, reached_at).robustness
    }

    /// [`ExecutionSpec::judge`] on the run read as [`ExecutionSpec::score`] reads it: the
    /// score, and the region whose entry failed it.
    pub fn judge_stopped(
        &self,
        executed: &[Vec<f64>],
        trajectory: &[Vec<f64>],
        reached_at: &[usize],
    ) -> Judged {
        let (Some(last), Some(first)) = (trajectory.last(), executed.first()) else {
            return Judged { robustness: f64::NEG_INFINITY, entered: None };
        };
        let end = trajectory.len() - 1;
        let mut at: Vec<usize> = reached_at.iter().map(|s| (*s).min(end)).take(self.steps).collect();
        at.resize(self.steps, end);
        let mut path: Vec<Vec<f64>> =
            std::iter::once(first.clone()).chain(executed.iter().skip(1).take(self.steps).cloned()).collect();
        path.resize(self.steps + 1, last.clone());
        self.judge(&path, trajectory, &at)
    }

    /// Judges a run: `executed` (the start and the positions where waypoints were
    /// reached), `trajectory` (every position, the start first; empty: only the
    /// executed positions are known) and `reached_at` (the environment step at which
    /// each waypoint was reached).
    pub fn judge(&self, executed: &[Vec<f64>], trajectory: &[Vec<f64>], reached_at: &[usize]) -> Judged {
        let not_done = Judged { robustness: f64::NEG_INFINITY, entered: None };
        if executed.len() != self.steps + 1 || reached_at.len() < self.steps {
            return not_done;
        }
        let width = self.dim + self.regions.len();
        let mut rows = vec![0.0; (self.steps + 1) * width];
        // First step inside each region along each segment: (region, segment, step).
        let mut entries = vec![];
        for t in 0..=self.steps {
            let row = &mut rows[t * width..(t + 1) * width];
            row[..self.dim].copy_from_slice(&executed[t][..self.dim]);
            if self.regions.is_empty() {
                // Nothing to read from the trajectory: the reached positions are the path.
                continue;
            }
            let span: Vec<(usize, &[f64])> = if trajectory.is_empty() {
                let from = t.saturating_sub(1);
                (from..=t)
                    .map(|k| (k.checked_sub(1).map_or(0, |i| reached_at[i]), &executed[k][..]))
                    .collect()
            } else {
                let first = if t <= 1 { 0 } else { reached_at[t - 2] };
                let last = if t == 0 { 0 } else { reached_at[t - 1] };
                (first..=last.min(trajectory.len() - 1)).map(|s| (s, &trajectory[s][..])).collect()
            };
            for (j, ball) in self.discs.iter().enumerate() {
                let mut best = f64::NEG_INFINITY;
                let mut first_in = None;
                for (s, p) in &span {
                    let v = ball.value(0, &p[..self.dim]);
                    if v > 0.0 && first_in.is_none() {
                        first_in = Some(*s);
                    }
                    best = best.max(v);
                }
                row[self.dim + j] = best;
                if let Some(s) = first_in {
                    entries.push((j, t, s));
                }
            }
        }
        let rho =
            |rows: &[f64]| self.spec.robustness(rows, &stl::Semantics::hard()).unwrap_or(f64::NEG_INFINITY);
        let robustness = rho(&rows);
        if robustness > 0.0 || entries.is_empty() {
            return Judged { robustness, entered: None };
        }
        // Which entry failed it: with every entry kept just outside its region, reveal
        // them in the order they happened; the first that fails the spec is the one.
        entries.sort_by_key(|&(_, _, s)| s);
        let mut probe = rows.clone();
        for &(j, t, _) in &entries {
            probe[t * width + self.dim + j] = -f64::EPSILON;
        }
        if rho(&probe) <= 0.0 {
            return Judged { robustness, entered: None };
        }
        for &(j, t, s) in &entries {
            probe[t * width + self.dim + j] = rows[t * width + self.dim + j];
            if rho(&probe) <= 0.0 {
                return Judged {
                    robustness,
                    entered: Some(Entry { region: self.regions[j].name.clone(), step: s }),
                };
            }
        }
        Judged { robustness, entered: None }
    }
}
