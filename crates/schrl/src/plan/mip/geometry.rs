//! A task's predicates as piecewise-linear functions of the waypoints.
//!
//! Every [`Shape`] is a *lower bound* of the predicate it stands for (sound: a plan
//! whose shape value is positive satisfies the predicate), built from affine pieces
//! with `min` and `max`:
//!
//! * inside a goal disc, `r − ‖x − c‖`: the disc's inscribed regular polygon of
//!   `sides` sides, `min_k r − u_k·(x − c)/cos(π/sides)`. Low by at most
//!   `‖x − c‖·(1/cos(π/sides) − 1)` (1.9 % of the distance to the centre at 16 sides);
//! * outside a disc, `‖x − c‖ − r`: the largest of `outside_sides` tangent half-planes,
//!   `max_k u_k·(x − c) − r`, low by at most `‖x − c‖·(1 − cos(π/outside_sides))`;
//! * a segment outside a disc (an avoid region checked along segments): both ends
//!   beyond one tangent line, `max_k min(u_k·(a − c), u_k·(b − c)) − r`;
//! * clearance from the walls, `sdf − safe_radius` (capped at the library's open
//!   clearance): for each wall box, the largest of its four side distances, which is
//!   the exact distance except beyond a corner (there at most √2 low); along a segment,
//!   both ends beyond one side of every box;
//! * the Signal task's counter: a constant at each waypoint.
//!
//! The start is not a variable: predicates at step 0 take their exact values.

use std::collections::HashMap;
use std::f64::consts::PI;
use std::sync::Arc;

use sim::Map;
use stl::Predicate;

use super::MipError;
use crate::task::{OPEN_CLEARANCE, SafeAlong, Task, along};

/// A piecewise-linear function of the plan's waypoints.
#[derive(Clone, Debug, PartialEq)]
pub(super) enum Shape {
    /// A number.
    Const(f64),
    /// `constant + Σ coefficient · x_t[k]` over `(t, k, coefficient)`, `t ≥ 1`.
    Affine {
        /// The terms.
        terms: Vec<(usize, usize, f64)>,
        /// The constant.
        constant: f64,
    },
    /// The least of its pieces.
    Min(Vec<Shape>),
    /// The greatest of its pieces.
    Max(Vec<Shape>),
}

/// What a name in a task's spec stands for, geometrically.
#[derive(Clone)]
enum Geometry {
    /// A goal disc, read at waypoints or (an avoid occurrence) along segments.
    Disc { center: [f64; 2], radius: f64, along_segments: bool },
    /// Clearance from axis-aligned wall boxes `(center, half size)` minus `radius`.
    Walls { boxes: Vec<([f64; 2], [f64; 2])>, radius: f64, along: SafeAlong },
    /// A predicate of time alone (the counter).
    OfTime(Arc<dyn Predicate>),
}

/// A task's names, as shapes; the start, for exact values at step 0.
pub(super) struct Atoms {
    geometry: HashMap<String, Geometry>,
    exact: HashMap<String, Arc<dyn Predicate>>,
    start: Vec<f64>,
    region: (Vec<f64>, Vec<f64>),
    sides: usize,
    outside_sides: usize,
}

impl Atoms {
    /// The names of `task`'s planning spec, planned from `start`.
    pub(super) fn of_task(
        task: &Task,
        start: &[f64],
        sides: usize,
        outside_sides: usize,
    ) -> Result<Atoms, MipError> {
        let boxes = match &task.map {
            Map::Walls(w) => w.bars().to_vec(),
            Map::Empty(_) => vec![],
            other => {
                return Err(MipError::Unsupported(format!(
                    "the {} map: the MIP planner encodes the 2-D maps (walls, empty), whose \
                     obstacles are boxes",
                    other.name()
                )));
            }
        };
        let mut geometry = HashMap::new();
        for g in &task.goals {
            let center = [g.center[0], g.center[1]];
            geometry
                .insert(g.name.clone(), Geometry::Disc { center, radius: g.radius, along_segments: false });
        }
        for g in task.avoid_regions() {
            let (center, radius) = ([g.center[0], g.center[1]], g.radius + task.avoid_margin);
            geometry
                .insert(along::along_name(&g.name), Geometry::Disc { center, radius, along_segments: true });
        }
        geometry.insert(
            "safe".into(),
            Geometry::Walls { boxes, radius: task.safe_radius, along: task.safe_along },
        );
        let mut exact: HashMap<String, Arc<dyn Predicate>> = HashMap::new();
        for (name, p) in task.predicates().into_iter().chain(along::planning_bindings(task)) {
            if name == "counter" {
                geometry.insert(name.clone(), Geometry::OfTime(p.clone()));
            }
            exact.insert(name, p);
        }
        Ok(Atoms { geometry, exact, start: start.to_vec(), region: task.map.region(), sides, outside_sides })
    }

    /// `sign · value(name) + offset` at waypoint `t` as a shape (`sign` is ±1).
    pub(super) fn shape(&self, name: &str, t: usize, sign: f64, offset: f64) -> Result<Shape, MipError> {
        let unknown = || MipError::Unsupported(format!("the name '{name}', which the task does not bind"));
        if t == 0 {
            let p = self.exact.get(name).ok_or_else(unknown)?;
            return Ok(Shape::Const(sign * p.value_on_path(&self.start, self.start.len(), 0) + offset));
        }
        match self.geometry.get(name).ok_or_else(unknown)? {
            Geometry::OfTime(p) => Ok(Shape::Const(sign * p.value(t, &self.start) + offset)),
            &Geometry::Disc { center, radius, along_segments: false } if sign > 0.0 => {
                let cos = (PI / self.sides as f64).cos();
                let pieces = directions(self.sides).map(|u| {
                    // r − u·(x − c)/cos
                    affine(&[(t, [-u[0] / cos, -u[1] / cos])], radius + dot(u, center) / cos + offset)
                });
                Ok(Shape::Min(pieces.collect()))
            }
            &Geometry::Disc { center, radius, along_segments } => {
                if sign > 0.0 {
                    return Err(MipError::Unsupported(format!(
                        "reaching '{}' somewhere along a segment: avoid occurrences are encoded as staying out",
                        name.trim_end_matches(":along")
                    )));
                }
                let ends: &[usize] = if along_segments { &[t - 1, t] } else { &[t] };
                let pieces = directions(self.outside_sides).map(|u| {
                    // u·(x − c) − r at every end
                    let at = |s: usize| affine(&[(s, u)], -dot(u, center) - radius + offset);
                    Shape::Min(ends.iter().map(|&s| at(s)).collect())
                });
                Ok(Shape::Max(pieces.collect()))
            }
            Geometry::Walls { boxes, radius, along } => {
                let open = Shape::Const(sign * (OPEN_CLEARANCE) + offset);
                if boxes.is_empty() {
                    return Ok(open);
                }
                if sign < 0.0 {
                    return Err(MipError::Unsupported(
                        "'!safe' (being inside an obstacle): the MIP planner encodes staying clear".into(),
                    ));
                }
                let ends: &[usize] = if *along == SafeAlong::Segments { &[t - 1, t] } else { &[t] };
                let region = (&self.region.0[..], &self.region.1[..]);
                let mut pieces = vec![open];
                for (c, h) in boxes {
                    let sides = box_sides(c, h).filter(|(u, d)| side_can_clear(region, *u, *d));
                    let clear = sides.map(|(u, d)| {
                        // u·x − d − radius at every end: beyond this side
                        Shape::Min(ends.iter().map(|&s| affine(&[(s, u)], -d - radius + offset)).collect())
                    });
                    pieces.push(Shape::Max(clear.collect()));
                }
                Ok(Shape::Min(pieces))
            }
        }
    }
}

/// `constant + Σ u · x_t` over `(t, u)`; the start's coordinates folded into the constant.
fn affine(terms: &[(usize, [f64; 2])], constant: f64) -> Shape {
    let terms = terms.iter().flat_map(|&(t, u)| [(t, 0, u[0]), (t, 1, u[1])]).collect();
    Shape::Affine { terms, constant }
}

fn dot(u: [f64; 2], v: [f64; 2]) -> f64 {
    u[0] * v[0] + u[1] * v[1]
}

/// `n` unit vectors evenly spaced around the circle, the first along +x.
fn directions(n: usize) -> impl Iterator<Item = [f64; 2]> {
    (0..n).map(move |k| {
        let a = 2.0 * PI * k as f64 / n as f64;
        [a.cos(), a.sin()]
    })
}

/// The four sides of a box as `(outward normal u, offset d)`: beyond the side by `u·x − d`.
fn box_sides(c: &[f64; 2], h: &[f64; 2]) -> impl Iterator<Item = ([f64; 2], f64)> {
    [
        ([1.0, 0.0], c[0] + h[0]),
        ([-1.0, 0.0], -(c[0] - h[0])),
        ([0.0, 1.0], c[1] + h[1]),
        ([0.0, -1.0], -(c[1] - h[1])),
    ]
    .into_iter()
}

/// Whether some point of the plan region (`lo`, `hi`) lies beyond the side `u·x > d`:
/// the others are left out of the disjunction (fewer binaries; the bound stays sound).
fn side_can_clear((lo, hi): (&[f64], &[f64]), u: [f64; 2], d: f64) -> bool {
    let reach: f64 = (0..2).map(|k| (u[k] * lo[k]).max(u[k] * hi[k])).sum();
    reach > d
}
