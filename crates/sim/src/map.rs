//! The worlds robots move in, each with an exact signed distance function.
//!
//! * [`WallsMap`] — the paper's four-room cross of 17 square walls (App. G; centres
//!   from the reference setup), for Point, Car and Doggo.
//! * [`EmptyMap`] — an open plane (the ground robots' Signal task).
//! * [`DuckWorld`] — a floor and a duck-shaped solid about 1.85 m tall at the
//!   origin, for the Drone (paper Fig. 1, 11e–h).
//!
//! `sdf(p)` is the signed distance from `p` to the nearest obstacle surface
//! (negative inside) and `sdf_grad` also returns its gradient. These are the ground
//! truth that neural SDF predicates are fitted to. Outside obstacles the distance is
//! exact (the minimum over convex pieces of their exact distances); inside, it is
//! the depth within the deepest piece.

/// Signed distance from `p` to an axis-aligned rectangle (`center`, `half` size).
/// Only a point beyond both edges needs a square root.
#[inline]
fn box_distance(p: &[f64], center: &[f64; 2], half: &[f64; 2]) -> f64 {
    let q0 = (p[0] - center[0]).abs() - half[0];
    let q1 = (p[1] - center[1]).abs() - half[1];
    if q0 > 0.0 && q1 > 0.0 { (q0 * q0 + q1 * q1).sqrt() } else { q0.max(q1) }
}

/// The gradient of [`box_distance`] (written to `g[..2]`): toward the nearest point
/// outside, along the axis of the nearest edge inside.
fn box_gradient(p: &[f64], center: &[f64; 2], half: &[f64; 2], g: &mut [f64]) {
    let sign = |i: usize| if p[i] >= center[i] { 1.0 } else { -1.0 };
    let q = [(p[0] - center[0]).abs() - half[0], (p[1] - center[1]).abs() - half[1]];
    if q[0] > 0.0 || q[1] > 0.0 {
        let out = [q[0].max(0.0), q[1].max(0.0)];
        let n = out[0].hypot(out[1]);
        g[0] = sign(0) * out[0] / n;
        g[1] = sign(1) * out[1] / n;
    } else {
        let axis = usize::from(q[1] > q[0]);
        g[axis] = sign(axis);
        g[1 - axis] = 0.0;
    }
}

/// The four-room map: 17 walls of 0.5 m × 0.5 m (reference setup), merged into six
/// bars for an exact distance: two crossing bars through the origin and four
/// outer pieces. Robots cannot pass them; doors are the gaps between |1.25| and
/// |2.75| on each axis.
#[derive(Clone, Debug, PartialEq)]
pub struct WallsMap {
    /// `(center, half size)` of each bar.
    bars: Vec<([f64; 2], [f64; 2])>,
}

/// Centres of the 17 walls (0.5 m squares), from the reference setup.
pub const WALL_CENTERS: [[f64; 2]; 17] = [
    [0.0, 0.0],
    [0.0, 0.5],
    [0.0, 1.0],
    [0.0, 3.0],
    [0.0, 3.5],
    [0.5, 0.0],
    [1.0, 0.0],
    [3.0, 0.0],
    [3.5, 0.0],
    [0.0, -0.5],
    [0.0, -1.0],
    [0.0, -3.0],
    [0.0, -3.5],
    [-0.5, 0.0],
    [-1.0, 0.0],
    [-3.0, 0.0],
    [-3.5, 0.0],
];

/// Half the side of one wall square.
pub const WALL_HALF: f64 = 0.25;

impl Default for WallsMap {
    fn default() -> Self {
        Self::new()
    }
}

impl WallsMap {
    /// The paper's map.
    pub fn new() -> Self {
        // Adjacent squares share faces; merging them gives the same solid.
        let h = WALL_HALF;
        let bars = vec![
            ([0.0, 0.0], [1.0 + h, h]), // (-1.25..1.25) × (-0.25..0.25)
            ([0.0, 0.0], [h, 1.0 + h]),
            ([3.25, 0.0], [0.5, h]), // 2.75..3.75
            ([-3.25, 0.0], [0.5, h]),
            ([0.0, 3.25], [h, 0.5]),
            ([0.0, -3.25], [h, 0.5]),
        ];
        Self { bars }
    }

    /// The merged bars, `(center, half size)`.
    pub fn bars(&self) -> &[([f64; 2], [f64; 2])] {
        &self.bars
    }

    /// The 17 wall squares, `(center, half size)`.
    pub fn squares(&self) -> impl Iterator<Item = ([f64; 2], [f64; 2])> {
        WALL_CENTERS.iter().map(|c| (*c, [WALL_HALF, WALL_HALF]))
    }
}

/// An open plane without obstacles.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct EmptyMap;

/// A sphere or capsule: the duck's convex pieces.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Capsule {
    /// One end of the core segment.
    pub a: [f64; 3],
    /// The other end (equal to `a` for a sphere).
    pub b: [f64; 3],
    /// Radius around the segment.
    pub radius: f64,
}

impl Capsule {
    /// Exact signed distance and its gradient.
    pub fn sdf(&self, p: &[f64], g: &mut [f64]) -> f64 {
        let ab = [self.b[0] - self.a[0], self.b[1] - self.a[1], self.b[2] - self.a[2]];
        let ap = [p[0] - self.a[0], p[1] - self.a[1], p[2] - self.a[2]];
        let len2 = ab[0] * ab[0] + ab[1] * ab[1] + ab[2] * ab[2];
        let t = if len2 > 0.0 {
            ((ap[0] * ab[0] + ap[1] * ab[1] + ap[2] * ab[2]) / len2).clamp(0.0, 1.0)
        } else {
            0.0
        };
        let d = [ap[0] - t * ab[0], ap[1] - t * ab[1], ap[2] - t * ab[2]];
        let n = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        if n > 0.0 {
            for i in 0..3 {
                g[i] = d[i] / n;
            }
        } else {
            g[..3].copy_from_slice(&[0.0, 0.0, 1.0]);
        }
        n - self.radius
    }
}

/// The Drone's world: the floor `z = 0` and a duck at the origin built from a body
/// capsule, a head sphere and a beak capsule (a stand-in the reference setup
/// allows: "any smooth closed shape built from a few ellipsoids").
#[derive(Clone, Debug, PartialEq)]
pub struct DuckWorld {
    pieces: [Capsule; 3],
    // A sphere holding the whole duck: its distance bounds the duck's from below.
    bound_center: [f64; 3],
    bound_radius: f64,
}

impl Default for DuckWorld {
    fn default() -> Self {
        Self::new()
    }
}

impl DuckWorld {
    /// The duck: body from x = −0.5 to 0.5 of radius 0.55 resting on the floor, head
    /// of radius 0.4 at height 1.45, beak pointing along +x. Top at 1.85 m.
    pub fn new() -> Self {
        Self::from_pieces([
            Capsule { a: [-0.5, 0.0, 0.55], b: [0.5, 0.0, 0.55], radius: 0.55 },
            Capsule { a: [0.45, 0.0, 1.45], b: [0.45, 0.0, 1.45], radius: 0.4 },
            Capsule { a: [0.8, 0.0, 1.4], b: [1.1, 0.0, 1.36], radius: 0.1 },
        ])
    }

    /// A duck made of `pieces`, with its bounding sphere.
    pub fn from_pieces(pieces: [Capsule; 3]) -> Self {
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        for c in &pieces {
            for k in 0..3 {
                lo[k] = lo[k].min(c.a[k].min(c.b[k]) - c.radius);
                hi[k] = hi[k].max(c.a[k].max(c.b[k]) + c.radius);
            }
        }
        let bound_center = [0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1]), 0.5 * (lo[2] + hi[2])];
        let half = [hi[0] - bound_center[0], hi[1] - bound_center[1], hi[2] - bound_center[2]];
        let bound_radius = (half[0] * half[0] + half[1] * half[1] + half[2] * half[2]).sqrt();
        Self { pieces, bound_center, bound_radius }
    }

    /// Signed distance to the duck alone (not the floor), with gradient.
    pub fn duck_sdf(&self, p: &[f64], g: &mut [f64]) -> f64 {
        let mut best = f64::INFINITY;
        let mut tmp = [0.0; 3];
        for c in &self.pieces {
            let d = c.sdf(p, &mut tmp);
            if d < best {
                best = d;
                g[..3].copy_from_slice(&tmp);
            }
        }
        best
    }

    /// The pieces the duck is made of.
    pub fn pieces(&self) -> &[Capsule; 3] {
        &self.pieces
    }
}

/// One of the maps, chosen at run time.
#[derive(Clone, Debug, PartialEq)]
pub enum Map {
    /// The four-room walls.
    Walls(WallsMap),
    /// An open plane.
    Empty(EmptyMap),
    /// Floor and duck (3-D).
    Duck(DuckWorld),
    /// The floor alone (3-D): open space where a general Drone controller learns.
    Floor,
}

/// The maps by name, for command lines and task files.
pub const MAP_NAMES: [&str; 4] = ["walls", "empty", "duck", "floor"];

impl Map {
    /// The map called `name` (`walls`, `empty`, `duck` or `floor`).
    pub fn by_name(name: &str) -> Option<Map> {
        match name {
            "walls" => Some(Map::Walls(WallsMap::new())),
            "empty" => Some(Map::Empty(EmptyMap)),
            "duck" => Some(Map::Duck(DuckWorld::new())),
            "floor" => Some(Map::Floor),
            _ => None,
        }
    }

    /// Its name.
    pub fn name(&self) -> &'static str {
        match self {
            Map::Walls(_) => "walls",
            Map::Empty(_) => "empty",
            Map::Duck(_) => "duck",
            Map::Floor => "floor",
        }
    }

    /// 2 for the ground maps, 3 for the duck world and the floor.
    pub fn dim(&self) -> usize {
        if matches!(self, Map::Duck(_) | Map::Floor) { 3 } else { 2 }
    }

    /// Signed distance from `p` (length [`Map::dim`]) to the nearest obstacle.
    pub fn sdf(&self, p: &[f64]) -> f64 {
        if let Map::Walls(w) = self {
            return w.bars.iter().map(|(c, h)| box_distance(p, c, h)).fold(f64::INFINITY, f64::min);
        }
        let mut g = [0.0; 3];
        self.sdf_grad(p, &mut g)
    }

    /// Signed distance and its gradient (written to `g[..dim]`). On the empty map
    /// the distance is `+∞` and the gradient zero.
    pub fn sdf_grad(&self, p: &[f64], g: &mut [f64]) -> f64 {
        match self {
            Map::Walls(w) => {
                // Distances first; the gradient only of the nearest bar.
                let (mut best, mut nearest) = (f64::INFINITY, 0);
                for (i, (c, h)) in w.bars.iter().enumerate() {
                    let d = box_distance(p, c, h);
                    if d < best {
                        best = d;
                        nearest = i;
                    }
                }
                let (c, h) = &w.bars[nearest];
                box_gradient(p, c, h, g);
                best
            }
            Map::Empty(_) => {
                g[..2].fill(0.0);
                f64::INFINITY
            }
            Map::Floor => {
                g[..3].copy_from_slice(&[0.0, 0.0, 1.0]);
                p[2]
            }
            Map::Duck(d) => {
                // The duck is no nearer than its bounding sphere: when the floor is
                // nearer than that, the floor is the answer (the common case).
                let c = d.bound_center;
                let to_c = ((p[0] - c[0]).powi(2) + (p[1] - c[1]).powi(2) + (p[2] - c[2]).powi(2)).sqrt();
                let duck = if to_c - d.bound_radius >= p[2] { f64::INFINITY } else { d.duck_sdf(p, g) };
                if p[2] < duck {
                    g[..3].copy_from_slice(&[0.0, 0.0, 1.0]);
                    p[2]
                } else {
                    duck
                }
            }
        }
    }

    /// The region goals and starts are drawn from: `(low, high)` per dimension.
    pub fn region(&self) -> (Vec<f64>, Vec<f64>) {
        match self {
            Map::Walls(_) | Map::Empty(_) => (vec![-3.5, -3.5], vec![3.5, 3.5]),
            Map::Duck(_) | Map::Floor => (vec![-2.5, -2.5, 0.3], vec![2.5, 2.5, 2.5]),
        }
    }
}
