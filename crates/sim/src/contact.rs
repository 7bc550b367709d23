//! Contact between a robot's round collision shape and a map.
//!
//! Robots are discs (ground robots) or spheres (Drone) for collision. When the shape
//! penetrates an obstacle it is moved out along the signed-distance gradient, the
//! velocity into the obstacle is removed (an inelastic contact) and the tangential
//! velocity is reduced by Coulomb friction using the normal impulse, as a
//! velocity-level contact solver would. Per physics substep robots move millimetres,
//! far less than any wall is thick, so nothing tunnels; [`needs_checks`] skips the
//! per-substep checks when the robot cannot reach an obstacle during the step.

use crate::map::Map;

/// MuJoCo's default sliding friction coefficient, used for robot–obstacle contact.
pub const WALL_FRICTION: f64 = 1.0;

/// `true` if an obstacle may be touched within `reach` metres of travel.
pub fn needs_checks(map: &Map, p: &[f64], radius: f64, reach: f64) -> bool {
    map.sdf(p) <= radius + reach
}

/// Resolves contact for a shape of `radius` at `p` moving at `v` (both of the map's
/// dimension). Returns `true` if the shape touches an obstacle. In a concave corner
/// (two walls meeting) pushing out of one wall can push into the other, so the
/// resolution repeats until the shape is clear (a few passes at most).
pub fn resolve(map: &Map, p: &mut [f64], v: &mut [f64], radius: f64) -> bool {
    let mut touched = false;
    for _ in 0..8 {
        if !resolve_once(map, p, v, radius) {
            break;
        }
        touched = true;
    }
    touched
}

fn resolve_once(map: &Map, p: &mut [f64], v: &mut [f64], radius: f64) -> bool {
    let mut n = [0.0; 3];
    let d = map.sdf_grad(p, &mut n);
    if d > radius {
        return false;
    }
    let k = p.len();
    let nn = n[..k].iter().map(|x| x * x).sum::<f64>().sqrt();
    if nn == 0.0 {
        return true;
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
    true
}
