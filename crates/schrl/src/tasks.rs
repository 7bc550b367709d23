//! The paper's five task types for the Point robot (App. G), with the coordinates of
//! the reference setup: a spec in the STL text syntax, the goal regions its names
//! refer to, the plan length and the start region.
//!
//! Every spec gets the obstacle clause `G[1,T] safe` where `safe` is the map's
//! signed distance minus the robot's radius (exact, from the sim crate; a neural
//! SDF can be bound in its place). The Signal task is on the empty plane, as in the
//! reference setup (its final goal, the origin, lies inside the walls' cross), so
//! its `safe` always holds.

use std::sync::Arc;

use candle_core::{DType, Device, Tensor};
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use sim::Map;
use stl::tensor::TensorSpec;
use stl::{AfterStep, Ball, Formula, Predicate, Spec};

/// One of the five task types.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum TaskKind {
    /// Visit goals in order.
    Seq,
    /// Visit all goals in any order.
    Cover,
    /// If one goal of a pair is visited, visit its partner.
    Branch,
    /// Keep moving among goals.
    Loop,
    /// Loop until a counter signal, then eventually reach a final goal.
    Signal,
}

impl TaskKind {
    /// All five, in the paper's order.
    pub const ALL: [TaskKind; 5] =
        [TaskKind::Seq, TaskKind::Cover, TaskKind::Branch, TaskKind::Loop, TaskKind::Signal];

    /// Lower-case name.
    pub fn name(self) -> &'static str {
        match self {
            TaskKind::Seq => "seq",
            TaskKind::Cover => "cover",
            TaskKind::Branch => "branch",
            TaskKind::Loop => "loop",
            TaskKind::Signal => "signal",
        }
    }
}

impl std::str::FromStr for TaskKind {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        TaskKind::ALL
            .into_iter()
            .find(|t| t.name() == s)
            .ok_or_else(|| format!("unknown task '{s}': expected one of seq, cover, branch, loop, signal"))
    }
}

/// A named goal region.
#[derive(Clone, Debug, PartialEq)]
pub struct GoalRegion {
    /// Name used in the spec.
    pub name: String,
    /// Centre.
    pub center: Vec<f64>,
    /// Radius.
    pub radius: f64,
}

/// A planning task: spec text, goals, plan length, start region, map.
#[derive(Clone, Debug)]
pub struct Task {
    /// Which task.
    pub kind: TaskKind,
    /// The spec in the STL text syntax, obstacle clause included.
    pub spec: String,
    /// The goals the spec names.
    pub goals: Vec<GoalRegion>,
    /// Waypoints planned after the start (the path has `steps + 1` states).
    pub steps: usize,
    /// Start region: `(low, high)` per dimension.
    pub start: (Vec<f64>, Vec<f64>),
    /// The map.
    pub map: Map,
    /// Environment step limit when a controller executes the plan.
    pub step_limit: usize,
    /// Waypoint index from which the Signal task's counter holds.
    pub counter_from: Option<usize>,
}

/// The Point robot's collision radius: the obstacle clause keeps waypoints clear of it.
pub const POINT_RADIUS: f64 = 0.1;

fn goals(prefix: &str, centers: &[[f64; 2]], radius: f64) -> Vec<GoalRegion> {
    centers
        .iter()
        .enumerate()
        .map(|(i, c)| GoalRegion { name: format!("{prefix}{i}"), center: c.to_vec(), radius })
        .collect()
}

/// The loop's clauses over goals `l0..l{n-1}`: be at one of them; never at the same
/// one twice in a row.
fn loop_clauses(n: usize) -> (String, String) {
    let any = (0..n).map(|i| format!("l{i}")).collect::<Vec<_>>().join(" | ");
    let alt = (0..n).map(|i| format!("(l{i} -> !X l{i})")).collect::<Vec<_>>().join(" & ");
    (any, alt)
}

/// The loop body of App. G, Eq. 9: `(∨ l_i) ∧ ∧ (l_i ⇒ ¬○ l_i)`.
fn loop_body(n: usize) -> String {
    let (any, alt) = loop_clauses(n);
    format!("({any}) & {alt}")
}

const DEFAULT_START: ([f64; 2], [f64; 2]) = ([1.0, -2.0], [2.0, -1.0]);

impl Task {
    /// The Point version of `kind` (reference setup coordinates).
    pub fn point(kind: TaskKind) -> Task {
        let corners = [[-2.0, -2.0], [-2.0, 2.0], [2.0, 2.0], [2.0, -2.0]];
        let start = (DEFAULT_START.0.to_vec(), DEFAULT_START.1.to_vec());
        let walls = Map::by_name("walls").expect("walls map");
        let (body, goals, steps, start, map, limit, counter) = match kind {
            TaskKind::Seq => (
                "F[1,2] g0 & F[3,4] g1 & F[5,6] g2 & F[7,8] g3".to_string(),
                goals("g", &[[2.0, 2.0], [-1.0, 2.0], [-2.0, -1.0], [1.0, -2.0]], 0.5),
                8,
                start,
                walls,
                1000,
                None,
            ),
            TaskKind::Cover => (
                "F[1,8] g0 & F[1,8] g1 & F[1,8] g2 & F[1,8] g3".to_string(),
                goals("g", &[[2.0, 2.0], [1.0, -2.0], [-2.0, -1.0], [-1.0, 2.0]], 0.5),
                8,
                start,
                walls,
                1000,
                None,
            ),
            TaskKind::Branch => {
                let mut g = goals("a", &[[0.0, 2.0], [2.0, -2.0], [2.0, 0.0]], 0.6);
                g.extend(goals("b", &[[0.0, -2.0], [-2.0, 2.0], [-2.0, 0.0]], 0.6));
                (
                    "(F[1,2] a0 & F[3,4] b0) | (F[1,2] a1 & F[3,4] b1) | (F[1,2] a2 & F[3,4] b2)".to_string(),
                    g,
                    4,
                    (vec![-2.0, -2.0], vec![-1.0, -1.0]),
                    walls,
                    800,
                    None,
                )
            }
            TaskKind::Loop => {
                // Alternation reads the next waypoint, so it stops one step before the
                // path's end; written over [1,17] it would ask the last waypoint to be
                // at a corner and not at it (X at the end reads the end itself).
                let (any, alt) = loop_clauses(4);
                (
                    format!("G[1,17] ({any}) & G[1,16] ({alt})"),
                    goals("l", &corners, 0.6),
                    17,
                    start,
                    walls,
                    2000,
                    None,
                )
            }
            TaskKind::Signal => {
                let mut g = goals("l", &corners, 0.8);
                g.push(GoalRegion { name: "final".into(), center: vec![0.0, 0.0], radius: 0.8 });
                (
                    format!("F[1,12] final & ({}) U[1,12] counter", loop_body(4)),
                    g,
                    12,
                    start,
                    Map::by_name("empty").expect("empty map"),
                    2000,
                    Some(10),
                )
            }
        };
        let spec = format!("({body}) & G[1,{steps}] safe");
        Task { kind, spec, goals, steps, start, map, step_limit: limit, counter_from: counter }
    }

    /// The parsed formula.
    pub fn formula(&self) -> Formula {
        stl::parse(&self.spec).expect("built-in task specs parse")
    }

    /// The scalar predicates by name: goals, `safe`, and the Signal counter.
    pub fn predicates(&self) -> Vec<(String, Arc<dyn Predicate>)> {
        let mut out: Vec<(String, Arc<dyn Predicate>)> = self
            .goals
            .iter()
            .map(|g| (g.name.clone(), Arc::new(Ball::new(g.center.clone(), g.radius)) as Arc<dyn Predicate>))
            .collect();
        out.push(("safe".into(), Arc::new(MapClearance::new(self.map.clone(), POINT_RADIUS))));
        if let Some(step) = self.counter_from {
            out.push(("counter".into(), Arc::new(AfterStep { step })));
        }
        out
    }

    /// `n` starts drawn uniformly from the start region: `[n, dim]`.
    pub fn sample_starts(&self, rng: &mut ChaCha8Rng, n: usize) -> candle_core::Result<Tensor> {
        let (lo, hi) = &self.start;
        let dim = lo.len();
        let v: Vec<f32> = (0..n * dim).map(|i| rng.random_range(lo[i % dim]..hi[i % dim]) as f32).collect();
        Tensor::from_vec(v, (n, dim), &Device::Cpu)
    }

    /// Standard-normal planner noise for `n` paths: `[n, steps, dim]`.
    pub fn sample_noise(&self, rng: &mut ChaCha8Rng, n: usize) -> candle_core::Result<Tensor> {
        let dim = self.map.dim();
        let v: Vec<f32> = (0..n * self.steps * dim).map(|_| StandardNormal.sample(rng)).collect();
        Tensor::from_vec(v, (n, self.steps, dim), &Device::Cpu)
    }

    /// The spec for single paths (plain Rust, exact gradients).
    pub fn spec(&self) -> Spec {
        let dim = self.map.dim();
        self.predicates()
            .into_iter()
            .fold(Spec::builder(self.formula()).state_dim(dim), |b, (n, p)| b.bind_shared(n, p))
            .build()
            .expect("built-in task specs bind")
    }

    /// The spec for batches of paths as tensors (differentiable in candle).
    pub fn tensor_spec(&self) -> TensorSpec {
        let dim = self.map.dim();
        self.predicates()
            .into_iter()
            .fold(TensorSpec::builder(self.formula(), dim), |b, (n, p)| b.bind_shared_predicate(n, p))
            .build()
            .expect("built-in task specs bind")
    }
}

/// Clearance from a map's obstacles: signed distance minus a radius, with the
/// exact gradient of the map's distance. Infinite maps (the empty plane) give a
/// large constant so that soft semantics stay finite.
#[derive(Clone, Debug)]
pub struct MapClearance {
    map: Map,
    radius: f64,
}

/// Clearance reported where a map has no obstacle at all.
pub const OPEN_CLEARANCE: f64 = 100.0;

impl MapClearance {
    /// Clearance from `map`'s obstacles for a robot of `radius`.
    pub fn new(map: Map, radius: f64) -> Self {
        Self { map, radius }
    }
}

impl Predicate for MapClearance {
    fn value(&self, _t: usize, state: &[f64]) -> f64 {
        (self.map.sdf(state) - self.radius).min(OPEN_CLEARANCE)
    }

    fn value_and_grad(&self, _t: usize, state: &[f64], scale: f64, grad: &mut [f64]) -> f64 {
        let mut g = [0.0; 3];
        let d = self.map.sdf_grad(state, &mut g) - self.radius;
        if d >= OPEN_CLEARANCE {
            return OPEN_CLEARANCE;
        }
        for (o, gi) in grad.iter_mut().zip(&g[..self.map.dim()]) {
            *o += scale * gi;
        }
        d
    }

    fn required_dim(&self) -> usize {
        self.map.dim()
    }
}

/// Hard-semantics robustness of each path of a `[n, steps+1, dim]` tensor under `spec`
/// (a path satisfies the spec when it is positive).
pub fn hard_robustness(spec: &Spec, paths: &Tensor) -> candle_core::Result<Vec<f64>> {
    let steps = paths.dim(1)?;
    let flat: Vec<f64> = paths.to_dtype(DType::F64)?.flatten_all()?.to_vec1()?;
    spec.robustness_batch(&flat, steps, &stl::Semantics::hard()).map_err(candle_core::Error::msg)
}
