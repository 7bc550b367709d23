//! Clearance of straight segments: how far the segment `a → b` stays from a map's
//! obstacles. A planner's waypoints are joined by the straight lines a controller
//! drives, so "the path is safe" means these segments are, not only their ends.
//!
//! [`Map::segment_sdf`] is the signed distance between the segment and the
//! obstacles: positive, the smallest distance between them; negative, the
//! penetration depth, the shortest translation that would move the segment clear
//! of the obstacle piece it crosses most deeply. The penetration depth (rather
//! than the deepest point's depth) matters for learning: a segment crossing a wall
//! far from its end has a constant deepest-point depth, while its penetration
//! depth falls as the crossing slides toward the wall's end (the door).
//!
//! Closed forms, per convex piece: a segment against an axis-aligned box in the
//! plane by the separating-axis theorem (exact distance when apart, exact minimal
//! translation when overlapping); against a capsule by segment–segment distance;
//! against the floor by the lower end's height.

use crate::map::{Capsule, Map};

/// Signed distance between the segment `a → b` and the box `center ± half`, in
/// the plane.
pub fn segment_box_2d(a: &[f64], b: &[f64], center: &[f64; 2], half: &[f64; 2]) -> f64 {
    let (lo, hi) = ([center[0] - half[0], center[1] - half[1]], [center[0] + half[0], center[1] + half[1]]);
    // Overlap of the projections on each separating axis: the box's two axes and
    // the segment's normal. Any negative overlap separates them.
    let mut depth = f64::INFINITY;
    for k in 0..2 {
        let (smin, smax) = (a[k].min(b[k]), a[k].max(b[k]));
        depth = depth.min((smax - lo[k]).min(hi[k] - smin));
    }
    let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
    let len = (dx * dx + dy * dy).sqrt();
    if len > 0.0 {
        let n = [-dy / len, dx / len];
        let sigma = a[0] * n[0] + a[1] * n[1];
        let c = center[0] * n[0] + center[1] * n[1];
        let r = half[0] * n[0].abs() + half[1] * n[1].abs();
        depth = depth.min(r - (sigma - c).abs());
    }
    if depth >= 0.0 {
        return -depth;
    }
    // Apart: the distance between a segment and a convex polygon is attained at an
    // end of the segment or at a corner of the polygon.
    let point_box = |p: &[f64]| {
        let qx = (p[0] - center[0]).abs() - half[0];
        let qy = (p[1] - center[1]).abs() - half[1];
        (qx.max(0.0).powi(2) + qy.max(0.0).powi(2)).sqrt()
    };
    let mut best = point_box(a).min(point_box(b));
    for corner in [[lo[0], lo[1]], [lo[0], hi[1]], [hi[0], lo[1]], [hi[0], hi[1]]] {
        best = best.min(point_segment_distance(&corner, a, b));
    }
    best
}

/// Euclidean distance between two points (any dimension).
pub fn point_distance(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum::<f64>().sqrt()
}

/// Distance from `p` to the segment `a → b` (any dimension).
pub fn point_segment_distance(p: &[f64], a: &[f64], b: &[f64]) -> f64 {
    let s = closest_fraction(p, a, b);
    (0..p.len()).map(|k| (p[k] - a[k] - s * (b[k] - a[k])).powi(2)).sum::<f64>().sqrt()
}

/// Where on the segment `a → b` the point nearest `p` lies, as the fraction `s ∈ [0, 1]`
/// of the way from `a` (0 for a segment of no length): the nearest point is
/// `a + s (b − a)`.
pub fn closest_fraction(p: &[f64], a: &[f64], b: &[f64]) -> f64 {
    let (mut ab2, mut apab) = (0.0, 0.0);
    for k in 0..p.len() {
        ab2 += (b[k] - a[k]) * (b[k] - a[k]);
        apab += (p[k] - a[k]) * (b[k] - a[k]);
    }
    if ab2 > 0.0 { (apab / ab2).clamp(0.0, 1.0) } else { 0.0 }
}

/// Distance between the segments `p1 → q1` and `p2 → q2` in 3-D.
pub fn segment_segment_distance(p1: &[f64; 3], q1: &[f64; 3], p2: &[f64; 3], q2: &[f64; 3]) -> f64 {
    let dot = |u: &[f64; 3], v: &[f64; 3]| u[0] * v[0] + u[1] * v[1] + u[2] * v[2];
    let sub = |u: &[f64; 3], v: &[f64; 3]| [u[0] - v[0], u[1] - v[1], u[2] - v[2]];
    let (d1, d2, r) = (sub(q1, p1), sub(q2, p2), sub(p1, p2));
    let (a, e, f) = (dot(&d1, &d1), dot(&d2, &d2), dot(&d2, &r));
    const EPS: f64 = 1e-12;
    // Parameters s on the first segment and t on the second of the closest points.
    let (s, t) = if a <= EPS && e <= EPS {
        (0.0, 0.0)
    } else if a <= EPS {
        (0.0, (f / e).clamp(0.0, 1.0))
    } else {
        let c = dot(&d1, &r);
        if e <= EPS {
            ((-c / a).clamp(0.0, 1.0), 0.0)
        } else {
            let b = dot(&d1, &d2);
            let denom = a * e - b * b;
            // Parallel segments: any s works; take the first end.
            let mut s = if denom > EPS { ((b * f - c * e) / denom).clamp(0.0, 1.0) } else { 0.0 };
            let mut t = (b * s + f) / e;
            if t < 0.0 {
                t = 0.0;
                s = (-c / a).clamp(0.0, 1.0);
            } else if t > 1.0 {
                t = 1.0;
                s = ((b - c) / a).clamp(0.0, 1.0);
            }
            (s, t)
        }
    };
    let c1 = [p1[0] + s * d1[0], p1[1] + s * d1[1], p1[2] + s * d1[2]];
    let c2 = [p2[0] + t * d2[0], p2[1] + t * d2[1], p2[2] + t * d2[2]];
    dot(&sub(&c1, &c2), &sub(&c1, &c2)).sqrt()
}

/// Signed distance between the segment `a → b` and a capsule (its radius minus
/// the distance between the capsule's core and the segment, negated).
pub fn segment_capsule(a: &[f64; 3], b: &[f64; 3], capsule: &Capsule) -> f64 {
    segment_segment_distance(a, b, &capsule.a, &capsule.b) - capsule.radius
}

/// The step [`Map::segment_sdf_grad`] differentiates with (metres): small against
/// every feature of the maps, large against rounding.
pub const SEGMENT_GRAD_STEP: f64 = 1e-6;

impl Map {
    /// Signed distance between the segment `a → b` (each of length [`Map::dim`]) and
    /// the map's obstacles: the smallest distance when clear, minus the penetration
    /// depth of the deepest crossing otherwise. `+∞` on the empty map. For a
    /// zero-length segment this is [`Map::sdf`] outside obstacles.
    pub fn segment_sdf(&self, a: &[f64], b: &[f64]) -> f64 {
        match self {
            Map::Walls(w) => {
                w.bars().iter().map(|(c, h)| segment_box_2d(a, b, c, h)).fold(f64::INFINITY, f64::min)
            }
            Map::Empty(_) => f64::INFINITY,
            Map::Floor => a[2].min(b[2]),
            Map::Duck(d) => {
                let (a3, b3) = ([a[0], a[1], a[2]], [b[0], b[1], b[2]]);
                d.pieces().iter().map(|c| segment_capsule(&a3, &b3, c)).fold(a[2].min(b[2]), f64::min)
            }
        }
    }

    /// [`Map::segment_sdf`] and its gradient with respect to both ends (written to
    /// `ga` and `gb`), by central differences: the value is piecewise smooth in at
    /// most six numbers, and each piece's derivative in closed form would be
    /// several times this code. Zero gradient where the value is infinite.
    pub fn segment_sdf_grad(&self, a: &[f64], b: &[f64], ga: &mut [f64], gb: &mut [f64]) -> f64 {
        let dim = self.dim();
        let value = self.segment_sdf(a, b);
        if !value.is_finite() {
            ga[..dim].fill(0.0);
            gb[..dim].fill(0.0);
            return value;
        }
        // Both ends in one array: x = [a, b].
        let mut x = [0.0; 6];
        x[..dim].copy_from_slice(&a[..dim]);
        x[dim..2 * dim].copy_from_slice(&b[..dim]);
        let f = |x: &[f64; 6]| self.segment_sdf(&x[..dim], &x[dim..2 * dim]);
        let h = SEGMENT_GRAD_STEP;
        for k in 0..2 * dim {
            let v = x[k];
            x[k] = v + h;
            let up = f(&x);
            x[k] = v - h;
            let down = f(&x);
            x[k] = v;
            let g = (up - down) / (2.0 * h);
            if k < dim { ga[k] = g } else { gb[k - dim] = g }
        }
        value
    }
}
