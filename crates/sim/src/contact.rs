//! Contact between a robot's round collision shape and a map.
//!
//! Robots are discs (ground robots) or spheres (Drone) for collision. When the shape
//! penetrates an obstacle it is moved out along the signed-distance gradient, the
//! velocity into the obstacle is removed (an inelastic contact) and the tangential
//! velocity is reduced by Coulomb friction using the normal impulse, as a
//! velocity-level contact solver would. Per physics substep robots move millimetres,
//! far less than any wall is thick, so nothing tunnels; [`ContactGuard`] skips the
//! map query while the robot is farther from every obstacle than it has moved.

use crate::map::Map;

/// MuJoCo's default sliding friction coefficient, used for robot–obstacle contact.
pub const WALL_FRICTION: f64 = 1.0;

/// Tracks how far a shape can still move before it may touch an obstacle, so that
/// the map is only queried when contact is possible.
#[derive(Clone, Copy, Debug)]
pub struct ContactGuard {
    clearance: f64,
}

impl ContactGuard {
    /// The guard for a shape of `radius` at `p`.
    pub fn new(map: &Map, p: &[f64], radius: f64) -> Self {
        Self { clearance: map.sdf(p) - radius }
    }

    /// Counts `travel` metres of motion; `true` if the shape may now touch.
    #[inline]
    pub fn may_touch(&mut self, travel: f64) -> bool {
        self.clearance -= travel;
        self.clearance <= 0.0
    }

    /// Resolves contact (after [`ContactGuard::may_touch`] said it may touch) and
    /// measures the clearance again; returns whether the shape touches.
    pub fn resolve(&mut self, map: &Map, p: &mut [f64], v: &mut [f64], radius: f64) -> bool {
        let (touched, clearance) = resolve_with_clearance(map, p, v, radius);
        self.clearance = clearance;
        touched
    }

    /// After the shape moved by at most `travel` metres, resolves contact if it may
    /// touch; returns whether it touches.
    #[inline]
    pub fn after_move(&mut self, map: &Map, p: &mut [f64], v: &mut [f64], radius: f64, travel: f64) -> bool {
        if !self.may_touch(travel) {
            return false;
        }
        self.resolve(map, p, v, radius)
    }
}

/// An upper bound of a step's length: the L1 norm of `v · dt` (no square root).
#[inline]
pub fn travel_bound(v: &[f64], dt: f64) -> f64 {
    v.iter().map(|x| x.abs()).sum::<f64>() * dt
}

/// Resolves contact for a shape of `radius` at `p` moving at `v` (both of the map's
/// dimension). Returns `true` if the shape touches an obstacle. In a concave corner
/// (two walls meeting) pushing out of one wall can push into the other, so the
/// resolution repeats until the shape is clear (a few passes at most).
pub fn resolve(map: &Map, p: &mut [f64], v: &mut [f64], radius: f64) -> bool {
    resolve_with_clearance(map, p, v, radius).0
}

/// [`resolve`], also returning the clearance left afterwards (distance to the
/// nearest obstacle minus `radius`, from the last map query).
fn resolve_with_clearance(map: &Map, p: &mut [f64], v: &mut [f64], radius: f64) -> (bool, f64) {
    let mut touched = false;
    for _ in 0..8 {
        match resolve_once(map, p, v, radius) {
            Ok(()) => touched = true,
            Err(clearance) => return (touched, clearance),
        }
    }
    (touched, map.sdf(p) - radius)
}

/// Pushes the shape out once; `Err(clearance)` if it was not touching.
fn resolve_once(map: &Map, p: &mut [f64], v: &mut [f64], radius: f64) -> Result<(), f64> {
    let mut n = [0.0; 3];
    let d = map.sdf_grad(p, &mut n);
    if d > radius {
        return Err(d - radius);
    }
    let k = p.len();
    let nn = n[..k].iter().map(|x| x * x).sum::<f64>().sqrt();
    if nn == 0.0 {
        return Ok(());
    }
    for x in &mut n[..k] {
        *x /= nn;
    }
    // Push out to the surface (a hair beyond, so that the next pass sees no contact).
    for i in 0..k {
        p[i] += (radius - d + 1e-12) * n[i];
    }
    // Remove the inward normal velocity; friction opposes the tangential velocity.
    let vn: f64 = (0..k).map(|i| v[i] * n[i]).sum();
    if vn < 0.0 {
        for i in 0..k {
            v[i] -= vn * n[i];
        }
        let vt = v[..k].iter().map(|x| x * x).sum::<f64>().sqrt();
        if vt > 0.0 {
            let scale = (1.0 - WALL_FRICTION * (-vn) / vt).max(0.0);
            for x in &mut v[..k] {
                *x *= scale;
            }
        }
    }
    Ok(())
}
