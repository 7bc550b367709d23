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
use std::sync::{Arc, Mutex, OnceLock};

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
    /// Clearance from the map's walls minus `radius`, through the walls' free cells
    /// (none: an open map).
    Walls { cells: Vec<Cell>, radius: f64, along: SafeAlong },
    /// A predicate of time alone (the counter).
    OfTime(Arc<dyn Predicate>),
}

/// A task's names, as shapes; the start, for exact values at step 0.
pub(super) struct Atoms {
    geometry: HashMap<String, Geometry>,
    exact: HashMap<String, Arc<dyn Predicate>>,
    start: Vec<f64>,
    sides: usize,
    outside_sides: usize,
    /// The plan region.
    region: ([f64; 2], [f64; 2]),
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
        let (lo, hi) = task.map.region();
        let cells = cached_free_cells(&boxes, (&lo, &hi));
        geometry.insert(
            "safe".into(),
            Geometry::Walls { cells, radius: task.safe_radius, along: task.safe_along },
        );
        let mut exact: HashMap<String, Arc<dyn Predicate>> = HashMap::new();
        for (name, p) in task.predicates().into_iter().chain(along::planning_bindings(task)) {
            if name == "counter" {
                geometry.insert(name.clone(), Geometry::OfTime(p.clone()));
            }
            exact.insert(name, p);
        }
        let region = ([lo[0], lo[1]], [hi[0], hi[1]]);
        Ok(Atoms { geometry, exact, start: start.to_vec(), sides, outside_sides, region })
    }

    /// The goal discs read at waypoints, `(name, centre, radius)`, sorted by name: where
    /// a waypoint can be claimed to be (the encoding's claims).
    pub(super) fn goal_discs(&self) -> Vec<(String, [f64; 2], f64)> {
        let mut discs: Vec<_> = self
            .geometry
            .iter()
            .filter_map(|(name, g)| match *g {
                Geometry::Disc { center, radius, along_segments: false } => {
                    Some((name.clone(), center, radius))
                }
                _ => None,
            })
            .collect();
        discs.sort_by(|a, b| a.0.cmp(&b.0));
        discs
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
            Geometry::Walls { cells, .. } => {
                let open = Shape::Const(sign * OPEN_CLEARANCE + offset);
                if cells.is_empty() {
                    return Ok(open);
                }
                if sign < 0.0 {
                    return Err(MipError::Unsupported(
                        "'!safe' (being inside an obstacle): the MIP planner encodes staying clear".into(),
                    ));
                }
                // In some cell, every end at least the clearance beyond every side.
                let in_cells = (0..cells.len()).filter_map(|c| self.in_cell(name, t, c, offset));
                Ok(Shape::Min(vec![open, Shape::Max(in_cells.collect())]))
            }
        }
    }

    /// The number of free cells of the walls `name` stands for (0: not the walls, or an
    /// open map) and whether its clearance is read along segments.
    pub(super) fn cells(&self, name: &str) -> (usize, SafeAlong) {
        match self.geometry.get(name) {
            Some(Geometry::Walls { cells, along, .. }) => (cells.len(), *along),
            _ => (0, SafeAlong::Waypoints),
        }
    }

    /// Which of the walls' free cells meet: `meet[a][b]` unless no point is inside
    /// both (checked on the 5 cm grid of [`free_cells`], counting points up to one
    /// grid step outside, so a pair that meets anywhere is never missed).
    pub(super) fn cells_meet(&self, name: &str) -> Vec<Vec<bool>> {
        let Some(Geometry::Walls { cells, .. }) = self.geometry.get(name) else {
            return vec![];
        };
        let depths: Vec<Vec<f64>> =
            cells.iter().map(|c| region_grid(&self.region).map(|p| depth(c, p)).collect()).collect();
        let step = grid_step(&self.region);
        let meet = |a: &[f64], b: &[f64]| a.iter().zip(b).any(|(x, y)| *x > -step && *y > -step);
        depths.iter().map(|a| depths.iter().map(|b| meet(a, b)).collect()).collect()
    }

    /// `value(name) + offset` for "the segment into waypoint `t` (or the waypoint, as
    /// the task reads `safe`) lies in free cell `cell`": every end at least the
    /// clearance beyond every side of the cell. `None` if `name` is not the walls.
    pub(super) fn in_cell(&self, name: &str, t: usize, cell: usize, offset: f64) -> Option<Shape> {
        let Some(Geometry::Walls { cells, radius, along }) = self.geometry.get(name) else {
            return None;
        };
        let ends: &[usize] = if *along == SafeAlong::Segments { &[t - 1, t] } else { &[t] };
        let beyond = cells[cell].iter().flat_map(|&(u, d)| ends.iter().map(move |&s| (s, u, d)));
        Some(Shape::Min(beyond.map(|(s, u, d)| affine(&[(s, u)], -d - radius + offset)).collect()))
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

/// A convex region free of obstacles: points beyond every side `u·x ≥ d` of the list,
/// where every obstacle lies behind at least one of them. So a point `δ` beyond every
/// side is at least `δ` from every obstacle (an obstacle point `q` behind side `s` has
/// `‖p − q‖ ≥ u_s·(p − q) ≥ δ`), and so is every point of a segment whose ends are.
pub(super) type Cell = Vec<([f64; 2], f64)>;

/// [`free_cells`], computed once per map and region (a few milliseconds, on every plan
/// otherwise).
fn cached_free_cells(boxes: &[([f64; 2], [f64; 2])], (lo, hi): (&[f64], &[f64])) -> Vec<Cell> {
    type Cache = Mutex<Vec<(Vec<u64>, Vec<Cell>)>>;
    static CACHE: OnceLock<Cache> = OnceLock::new();
    let key: Vec<u64> = boxes
        .iter()
        .flat_map(|(c, h)| [c[0], c[1], h[0], h[1]])
        .chain(lo.iter().chain(hi).copied())
        .map(f64::to_bits)
        .collect();
    let cache = CACHE.get_or_init(|| Mutex::new(vec![]));
    let mut cache = cache.lock().unwrap_or_else(|poisoned| poisoned.into_inner());
    if let Some((_, cells)) = cache.iter().find(|(k, _)| *k == key) {
        return cells.clone();
    }
    let cells = free_cells(boxes, (lo, hi));
    cache.push((key, cells.clone()));
    cells
}

/// Points of the region `(lo, hi)`, 141 by 141 (a 5 cm grid on the walls map).
fn region_grid((lo, hi): &([f64; 2], [f64; 2])) -> impl Iterator<Item = [f64; 2]> + '_ {
    (0..=GRID).flat_map(move |i| {
        (0..=GRID).map(move |j| {
            let (a, b) = (i as f64 / GRID as f64, j as f64 / GRID as f64);
            [lo[0] + a * (hi[0] - lo[0]), lo[1] + b * (hi[1] - lo[1])]
        })
    })
}

/// Grid intervals per side of [`region_grid`].
const GRID: usize = 140;

/// The diagonal of one grid square: every point of the region is within half of it of
/// a grid point.
fn grid_step((lo, hi): &([f64; 2], [f64; 2])) -> f64 {
    ((hi[0] - lo[0]) / GRID as f64).hypot((hi[1] - lo[1]) / GRID as f64)
}

/// How far `p` is beyond every side of `cell` (negative: outside it).
fn depth(cell: &Cell, p: [f64; 2]) -> f64 {
    cell.iter().map(|&(u, d)| dot(u, p) - d).fold(f64::INFINITY, f64::min)
}

/// The free cells of a map of boxes within the plan region: every set of one or two
/// box sides that has every box behind one of them and room beyond them, less those
/// another cell contains (compared on a 5 cm grid). On the walls map: the four rooms
/// (beyond both central bars) and the four door strips (between a central bar's end
/// and an outer piece), 8 cells where the boxes one at a time need 20 sides.
pub(super) fn free_cells(boxes: &[([f64; 2], [f64; 2])], (lo, hi): (&[f64], &[f64])) -> Vec<Cell> {
    if boxes.is_empty() {
        return vec![];
    }
    // Sides some point of the region is beyond.
    let mut sides: Vec<([f64; 2], f64)> = vec![];
    for (c, h) in boxes {
        for (u, d) in box_sides(c, h) {
            let reach: f64 = (0..2).map(|k| (u[k] * lo[k]).max(u[k] * hi[k])).sum();
            if reach > d && !sides.contains(&(u, d)) {
                sides.push((u, d));
            }
        }
    }
    // Behind the side: the whole box on the other side.
    let behind = |(u, d): ([f64; 2], f64), (c, h): &([f64; 2], [f64; 2])| {
        let far: f64 = (0..2).map(|k| u[k] * c[k] + u[k].abs() * h[k]).sum();
        far <= d + 1e-12
    };
    let mut candidates: Vec<Cell> = vec![];
    for i in 0..sides.len() {
        for j in i..sides.len() {
            let cell: Cell = if i == j { vec![sides[i]] } else { vec![sides[i], sides[j]] };
            if boxes.iter().all(|b| cell.iter().any(|&s| behind(s, b))) {
                candidates.push(cell);
            }
        }
    }
    // Depth of each candidate on a grid; drop empty cells and those another covers.
    let region = ([lo[0], lo[1]], [hi[0], hi[1]]);
    let depths: Vec<Vec<f64>> =
        candidates.iter().map(|c| region_grid(&region).map(|p| depth(c, p)).collect()).collect();
    let mut keep = vec![];
    for (a, da) in depths.iter().enumerate() {
        if da.iter().all(|&v| v <= 0.0) {
            continue;
        }
        let covered = depths.iter().enumerate().any(|(b, db)| {
            b != a
                && da.iter().zip(db).all(|(x, y)| x <= y)
                && (da.iter().zip(db).any(|(x, y)| x < y) || b < a)
        });
        if !covered {
            keep.push(candidates[a].clone());
        }
    }
    keep
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_walls_map_has_four_rooms_and_four_door_strips() {
        let walls = sim::map::WallsMap::new();
        let (lo, hi) = Map::Walls(walls.clone()).region();
        let cells = free_cells(walls.bars(), (&lo, &hi));
        assert_eq!(cells.len(), 8, "{cells:?}");
        // Every cell's depth is a lower bound of the clearance, on a grid.
        let map = Map::Walls(walls);
        for cell in &cells {
            for i in 0..=70 {
                for j in 0..=70 {
                    let p = [-3.5 + 0.1 * i as f64, -3.5 + 0.1 * j as f64];
                    let depth = cell.iter().map(|&(u, d)| dot(u, p) - d).fold(f64::INFINITY, f64::min);
                    assert!(depth <= map.sdf(&p) + 1e-9 || depth <= 0.0, "{cell:?} at {p:?}");
                }
            }
        }
        // Which cells meet: a room (two perpendicular sides) meets the two bands through
        // its doors and no other room (the walls are between them); the bands (two
        // opposite sides) cross each other in the rooms' outer corners.
        let atoms =
            Atoms::of_task(&crate::task::Task::point(crate::task::TaskKind::Cover), &[1.5, -1.5], 16, 8)
                .expect("the Cover task encodes");
        let meet = atoms.cells_meet("safe");
        assert_eq!(meet.len(), 8);
        let room = |c: &Cell| dot(c[0].0, c[1].0) == 0.0;
        for (a, row) in meet.iter().enumerate() {
            assert!(row[a], "cell {a} meets itself");
            assert!((0..8).all(|b| meet[b][a] == row[b]), "symmetric");
            let rooms = (0..8).filter(|&b| b != a && row[b] && room(&cells[b])).count();
            let bands = (0..8).filter(|&b| b != a && row[b] && !room(&cells[b])).count();
            let expected = if room(&cells[a]) { (0, 2) } else { (2, 2) };
            assert_eq!((rooms, bands), expected, "cell {a}: {:?} meets {row:?}", cells[a]);
        }
        // Each door's middle and each room's middle lies deep in some cell.
        for p in [[2.0, 0.0], [0.0, 2.0], [-2.0, 0.0], [0.0, -2.0], [2.0, 2.0], [-2.0, -2.0]] {
            let best = cells
                .iter()
                .map(|c| c.iter().map(|&(u, d)| dot(u, p) - d).fold(f64::INFINITY, f64::min))
                .fold(f64::NEG_INFINITY, f64::max);
            assert!(best >= 0.75 - 1e-9, "{p:?}: {best}");
        }
    }
}
