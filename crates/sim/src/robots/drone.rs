//! Drone: a 6-DoF quadrotor flown by a cascaded PID controller whose gains the
//! policy adjusts (paper §4.1 "PyBullet Drone"; reference setup).
//!
//! The rigid body is the "hb" quadrotor of gym-pybullet-drones: mass 0.5 kg,
//! inertia diag(2.3e-3, 2.3e-3, 4.0e-3) kg·m², four rotors in a "+" layout at arm
//! 0.175 m, rotor force `k_f ω²` and drag torque `k_m ω²` (ω in RPM), k_f = 6.11e-8,
//! k_m = 1.5e-9, thrust-to-weight 2 (each rotor at most `2 m g / 4`), gravity 9.8.
//! No aerodynamic drag or ground effect is modelled.
//!
//! Control at 50 Hz: the position loop (PID on the error to the current goal, plus
//! gravity compensation) sets the desired force; its direction, with roll and
//! pitch limited to 30° and yaw held at its current value, sets the desired attitude and its
//! projection on the body z axis the collective thrust. The attitude loop (PID on
//! the rotation error `½ vee(R_dᵀR − RᵀR_d)` and the body rates) runs at every
//! physics step (250 Hz), as flight controllers run attitude faster than position;
//! rotor forces come from inverting the mixer and are clipped to [0, max].
//!
//! The position loop tracks a reference, not the goal itself (this project's, not
//! the reference's). Given the goal as its setpoint, the base loop flew a hop along a
//! curve: the vertical loop acts on thrust directly with the larger gains and a
//! horizontal one through the attitude loop's lag, so the Drone reached a new height
//! first and flew the rest level (0.25 m below a descending 2.9 m hop mid-way), and
//! it carried the speed it turned at into the next hop (0.28 m off it after a 135°
//! turn); the planner keeps only the straight segments clear (Drone Signal collided
//! with the duck's head so). Instead, each goal starts a [`Hop`]: a minimum-jerk move
//! along the straight line from the last goal to the new one, from rest to rest, as
//! fast as keeps the force it asks for within half of what the 30° tilt limit allows.
//! The setpoint is the hop's position offset by the feed-forward force (its
//! acceleration, led by the attitude loop's lag on a horizontal axis) and its velocity
//! under the current gains, so the loop follows the line whatever gains the policy
//! sets; the gains shape how it rejects what the model leaves out. A new goal waits
//! until the hop in flight has ended (the Drone counts a waypoint reached before it
//! stops at it).
//!
//! The 18-dimensional action scales the controller's gains: force P, I, D and
//! torque P, I, D, three axes each, `gain = base · 2^(a/8)` with `a ∈ [−1, 1]` (each
//! gain within ±9 % of its base, [`GAIN_RANGE_LOG2`]). The base loop is only just
//! damped: its attitude loop lags by P/D ≈ 1 s, so a 3 m step overshoots 0.5 m. With
//! gains over half to twice their base, the corner of high force P, low force D and
//! low torque P diverges (speeds of 12 m/s; a trained policy found it and looped
//! metres past every waypoint); at ±9 % every corner still settles. Base gains (reference setup): force P
//! (0.1, 0.1, 0.2), I 1e-4, D (0.3, 0.3, 0.4); torque P (0.3, 0.3, 0.05), D (0.3, 0.3,
//! 0.5); the reference omits the torque I gain, taken here as 1e-4 like the force I.
//!
//! The collision shape is a sphere of radius 0.2 m (arms plus rotors). Reach radius
//! 0.6 m (reference setup). Observation (18), body frame: accelerometer (specific
//! force), velocimeter, gyro, magnetometer, the world's up axis, and the goal
//! vector, 3 each.

use rand_chacha::ChaCha8Rng;

use crate::contact::{self, ContactGuard};
use crate::env::Dynamics;
use crate::map::Map;
use crate::robots::{MAGNETIC_FIELD, random_yaw};
use crate::rotation::{Quat, apply, apply_t, cross};

/// Gravity of the reference Drone (m/s²).
pub const G: f64 = 9.8;
/// Mass (kg).
pub const MASS: f64 = 0.5;
const INERTIA: [f64; 3] = [2.3e-3, 2.3e-3, 4.0e-3];
const ARM: f64 = 0.175;
const KF: f64 = 6.11e-8;
const KM: f64 = 1.5e-9;
const THRUST_TO_WEIGHT: f64 = 2.0;
/// Most force one rotor gives (N).
pub const ROTOR_MAX: f64 = THRUST_TO_WEIGHT * MASS * G / 4.0;
/// Rotor force that holds the drone in a hover (N).
pub const HOVER_FORCE: f64 = MASS * G / 4.0;
const CONTROL_DT: f64 = 0.02;
const SUBSTEPS: usize = 5;
const DT: f64 = CONTROL_DT / SUBSTEPS as f64;
const RADIUS: f64 = 0.2;
const TILT_LIMIT: f64 = std::f64::consts::PI / 6.0;
// Reciprocals for the physics loop (a division by a constant stays a division).
const INV_INERTIA: [f64; 3] = [1.0 / INERTIA[0], 1.0 / INERTIA[1], 1.0 / INERTIA[2]];
const YAW_PER_FORCE: f64 = KM / KF;
const ROLL_MIX: f64 = 1.0 / (2.0 * ARM);
const YAW_MIX: f64 = 1.0 / (4.0 * YAW_PER_FORCE);
const INTEGRAL_LIMIT: f64 = 2.0;
// The attitude loop's time constant with base gains, torque D over torque P (s).
const ATTITUDE_LAG: f64 = BASE_GAINS[15] / BASE_GAINS[9];
// The most force per kilogram a hop asks for: half of what the tilt limit allows
// (g tan 30°), the rest left to the feedback (m/s²).
const HOP_ACCEL: f64 = 0.5 * G * 0.577_350_269_189_625_8;

/// How far an action moves a gain, in octaves: `gain = base · 2^(GAIN_RANGE_LOG2 · a)`,
/// `a ∈ [−1, 1]`; the widest range whose every corner settles a 3 m step (the
/// regression test `every_corner_of_the_gain_box_settles`).
pub const GAIN_RANGE_LOG2: f64 = 0.125;

/// Base PID gains: force P, I, D, torque P, I, D (3 axes each).
pub const BASE_GAINS: [f64; 18] = [
    0.1, 0.1, 0.2, 1e-4, 1e-4, 1e-4, 0.3, 0.3, 0.4, //
    0.3, 0.3, 0.05, 1e-4, 1e-4, 1e-4, 0.3, 0.3, 0.5,
];

/// The Drone's state.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Drone {
    /// Position (m).
    pub pos: [f64; 3],
    /// Velocity (m/s, world).
    pub vel: [f64; 3],
    /// Orientation (body to world).
    pub att: Quat,
    /// Angular velocity (rad/s, body).
    pub rate: [f64; 3],
    /// Integral of the position error.
    pub pos_integral: [f64; 3],
    /// Integral of the attitude error.
    pub att_integral: [f64; 3],
    /// Acceleration over the last physics step (world).
    pub accel: [f64; 3],
    /// The last rotor forces (N).
    pub rotors: [f64; 4],
    /// The hop the position loop tracks (the module docs say why); `None` until the
    /// first control step, which starts one from the Drone's position (also in states
    /// saved before it existed).
    #[serde(default)]
    pub hop: Option<Hop>,
}

impl Default for Drone {
    fn default() -> Self {
        Self {
            pos: [0.0, 0.0, 1.0],
            vel: [0.0; 3],
            att: Quat::IDENTITY,
            rate: [0.0; 3],
            pos_integral: [0.0; 3],
            att_integral: [0.0; 3],
            accel: [0.0; 3],
            rotors: [HOVER_FORCE; 4],
            hop: None,
        }
    }
}

impl Drone {
    /// One physics step with the given rotor forces (clipped to [0, max]); `r` is
    /// the current orientation's matrix.
    fn physics(&mut self, r: &[[f64; 3]; 3], rotors: [f64; 4]) {
        let f = rotors.map(|x| x.clamp(0.0, ROTOR_MAX));
        self.rotors = f;
        let thrust = f[0] + f[1] + f[2] + f[3];
        let torque = [ARM * (f[1] - f[3]), ARM * (f[2] - f[0]), YAW_PER_FORCE * (-f[0] + f[1] - f[2] + f[3])];
        // Thrust along the body z axis (the matrix's third column), gravity down.
        let a = thrust / MASS;
        self.accel = [a * r[0][2], a * r[1][2], a * r[2][2] - G];
        for i in 0..3 {
            self.vel[i] += DT * self.accel[i];
            self.pos[i] += DT * self.vel[i];
        }
        // Euler's equations in the body frame.
        let w = self.rate;
        let iw = [INERTIA[0] * w[0], INERTIA[1] * w[1], INERTIA[2] * w[2]];
        let gyro = cross(w, iw);
        for i in 0..3 {
            self.rate[i] += DT * (torque[i] - gyro[i]) * INV_INERTIA[i];
        }
        self.att.integrate_body_unnormalized(self.rate, DT);
    }

    /// Flies one control step with fixed rotor forces, bypassing the controller (for
    /// tests: hover, free fall). Returns whether it touched an obstacle.
    pub fn fly_rotors(&mut self, rotors: [f64; 4], map: &Map) -> bool {
        let mut hit = false;
        for _ in 0..SUBSTEPS {
            let r = self.att.matrix();
            self.physics(&r, rotors);
            hit |= contact::resolve(map, &mut self.pos, &mut self.vel, RADIUS);
        }
        self.att.normalize();
        hit
    }

    /// The position loop's setpoint toward `goal` under `gains`: the current hop's
    /// position, offset so that the loop asks for the hop's feed-forward force.
    fn setpoint(&mut self, r: &[[f64; 3]; 3], gains: &[f64; 18], goal: &[f64]) -> [f64; 3] {
        let goal = [goal[0], goal[1], goal[2]];
        let hop = self.hop.get_or_insert_with(|| Hop::at(self.pos));
        if hop.elapsed >= hop.duration && hop.to != goal {
            *hop = Hop::new(hop.to, goal);
        }
        hop.elapsed = (hop.elapsed + CONTROL_DT).min(hop.duration);
        let [p, v, a, j] = hop.state();
        // Pitch (the body y torque) moves the Drone along its heading, roll across
        // it; each tilts behind its command by its torque D / P, so the force leads
        // the acceleration by that lag times the jerk.
        let n = r[0][0].hypot(r[1][0]).max(1e-9);
        let (c, s) = (r[0][0] / n, r[1][0] / n);
        let along = c * a[0] + s * a[1] + (c * j[0] + s * j[1]) * gains[16] / gains[10];
        let across = -s * a[0] + c * a[1] + (-s * j[0] + c * j[1]) * gains[15] / gains[9];
        let force = [MASS * (c * along - s * across), MASS * (s * along + c * across), MASS * a[2]];
        std::array::from_fn(|i| p[i] + (force[i] + gains[6 + i] * v[i]) / gains[i])
    }

    /// The position loop: desired attitude and collective thrust toward `goal`.
    fn position_loop(&mut self, gains: &[f64; 18], goal: &[f64]) -> ([[f64; 3]; 3], f64) {
        let r = self.att.matrix();
        let goal = self.setpoint(&r, gains, goal);
        let mut force = [0.0; 3];
        for i in 0..3 {
            let e = goal[i] - self.pos[i];
            self.pos_integral[i] =
                (self.pos_integral[i] + e * CONTROL_DT).clamp(-INTEGRAL_LIMIT, INTEGRAL_LIMIT);
            force[i] = gains[i] * e + gains[3 + i] * self.pos_integral[i] - gains[6 + i] * self.vel[i];
        }
        force[2] += MASS * G;
        // Limit roll and pitch: the horizontal force may tilt the thrust by ≤ 30°.
        force[2] = force[2].max(1e-3);
        let horizontal = (force[0] * force[0] + force[1] * force[1]).sqrt();
        let max_h = force[2] * TILT_LIMIT.tan();
        if horizontal > max_h {
            force[0] *= max_h / horizontal;
            force[1] *= max_h / horizontal;
        }
        let norm = (force[0] * force[0] + force[1] * force[1] + force[2] * force[2]).sqrt();
        let z = force.map(|x| x / norm);
        // Yaw held where it is (x_c = the body x axis flattened): the drone starts at
        // a random yaw, and a large yaw error couples into roll and pitch through
        // the attitude error and tilts the drone away from the goal.
        let (cx, cy) = (r[0][0], r[1][0]);
        let cn = (cx * cx + cy * cy).sqrt().max(1e-9);
        let y = cross(z, [cx / cn, cy / cn, 0.0]);
        let yn = (y[0] * y[0] + y[1] * y[1] + y[2] * y[2]).sqrt();
        let y = y.map(|v| v / yn);
        let x = cross(y, z);
        let desired = [[x[0], y[0], z[0]], [x[1], y[1], z[1]], [x[2], y[2], z[2]]];
        let body_z = apply(&r, [0.0, 0.0, 1.0]);
        let thrust =
            (force[0] * body_z[0] + force[1] * body_z[1] + force[2] * body_z[2]).clamp(0.0, 4.0 * ROTOR_MAX);
        (desired, thrust)
    }

    /// The attitude loop and mixer: rotor forces for the desired attitude.
    fn attitude_loop(
        &mut self,
        r: &[[f64; 3]; 3],
        gains: &[f64; 18],
        desired: &[[f64; 3]; 3],
        thrust: f64,
    ) -> [f64; 4] {
        // E = R_dᵀR − RᵀR_d is skew-symmetric; e = ½ vee(E).
        let e = |i: usize, j: usize| {
            (0..3).map(|k| desired[k][i] * r[k][j] - r[k][i] * desired[k][j]).sum::<f64>()
        };
        let err = [0.5 * e(2, 1), 0.5 * e(0, 2), 0.5 * e(1, 0)];
        let mut tau = [0.0; 3];
        for i in 0..3 {
            self.att_integral[i] =
                (self.att_integral[i] + err[i] * DT).clamp(-INTEGRAL_LIMIT, INTEGRAL_LIMIT);
            tau[i] =
                -gains[9 + i] * err[i] - gains[12 + i] * self.att_integral[i] - gains[15 + i] * self.rate[i];
        }
        let q = 0.25 * thrust;
        let (roll, pitch, yaw) = (tau[0] * ROLL_MIX, tau[1] * ROLL_MIX, tau[2] * YAW_MIX);
        [q - pitch - yaw, q + roll + yaw, q + pitch - yaw, q - roll + yaw]
    }

    /// Rotor speeds (RPM) for the last rotor forces.
    pub fn rotor_rpm(&self) -> [f64; 4] {
        self.rotors.map(|f| (f / KF).sqrt())
    }
}

impl Dynamics for Drone {
    const NAME: &'static str = "drone";
    const OBS_DIM: usize = 18;
    const ACT_DIM: usize = 18;
    const PLAN_DIM: usize = 3;
    const REACH_RADIUS: f64 = 0.6;
    const RADIUS: f64 = RADIUS;

    fn reset(&mut self, start: &[f64], rng: &mut ChaCha8Rng) {
        *self = Drone {
            pos: [start[0], start[1], start[2]],
            att: Quat::from_yaw(random_yaw(rng)),
            ..Drone::default()
        };
    }

    fn advance(&mut self, action: &[f64], map: &Map, goal: &[f64]) -> bool {
        let mut gains = BASE_GAINS;
        for (g, a) in gains.iter_mut().zip(action) {
            *g *= (GAIN_RANGE_LOG2 * a).exp2();
        }
        let (desired, thrust) = self.position_loop(&gains, goal);
        let mut guard = ContactGuard::new(map, &self.pos, RADIUS);
        let mut collided = false;
        for _ in 0..SUBSTEPS {
            let r = self.att.matrix();
            let rotors = self.attitude_loop(&r, &gains, &desired, thrust);
            self.physics(&r, rotors);
            let travel = contact::travel_bound(&self.vel, DT);
            collided |= guard.after_move(map, &mut self.pos, &mut self.vel, RADIUS, travel);
        }
        self.att.normalize();
        collided
    }

    fn plan_position(&self) -> &[f64] {
        &self.pos
    }

    fn yaw(&self) -> f64 {
        let r = self.att.matrix();
        r[1][0].atan2(r[0][0])
    }

    fn observe(&self, goal: &[f64], obs: &mut [f64]) {
        let r = self.att.matrix();
        let specific = [self.accel[0], self.accel[1], self.accel[2] + G];
        let to_goal = [goal[0] - self.pos[0], goal[1] - self.pos[1], goal[2] - self.pos[2]];
        obs[0..3].copy_from_slice(&apply_t(&r, specific));
        obs[3..6].copy_from_slice(&apply_t(&r, self.vel));
        obs[6..9].copy_from_slice(&self.rate);
        obs[9..12].copy_from_slice(&apply_t(&r, MAGNETIC_FIELD));
        obs[12..15].copy_from_slice(&apply_t(&r, [0.0, 0.0, 1.0]));
        obs[15..18].copy_from_slice(&apply_t(&r, to_goal));
    }
}

/// One move of the Drone's reference: minimum jerk from `from` to `to`, at rest at
/// both ends, over `duration` seconds (position `from + σ(τ) (to − from)`, `τ = t / T`,
/// `σ = 10τ³ − 15τ⁴ + 6τ⁵`). The duration is the shortest whose force stays within
/// half the tilt limit's, by the bound `(5.77 + 60 lag / T) L / T²` on the hop's
/// acceleration plus the base attitude lag times its jerk (`|σ″| ≤ 5.77`,
/// `|σ‴| ≤ 60`), solved by bisection.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Hop {
    /// Where the hop starts.
    pub from: [f64; 3],
    /// Where it ends.
    pub to: [f64; 3],
    /// Seconds since it started.
    pub elapsed: f64,
    /// Its length in seconds.
    pub duration: f64,
}

impl Hop {
    /// Holding still at `p`.
    pub fn at(p: [f64; 3]) -> Self {
        Self { from: p, to: p, elapsed: 0.0, duration: 0.0 }
    }

    /// The hop from `from` to `to`.
    pub fn new(from: [f64; 3], to: [f64; 3]) -> Self {
        let length = crate::segment::point_distance(&from, &to);
        if length == 0.0 {
            return Self::at(to);
        }
        let accel = |t: f64| length * (5.7735 + 60.0 * ATTITUDE_LAG / t) / (t * t);
        let (mut lo, mut hi) = (0.0, 1.0);
        while accel(hi) > HOP_ACCEL {
            hi *= 2.0;
        }
        for _ in 0..40 {
            let mid = 0.5 * (lo + hi);
            if accel(mid) > HOP_ACCEL {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        Self { from, to, elapsed: 0.0, duration: hi }
    }

    /// Position, velocity, acceleration and jerk now.
    pub fn state(&self) -> [[f64; 3]; 4] {
        if self.elapsed >= self.duration {
            return [self.to, [0.0; 3], [0.0; 3], [0.0; 3]];
        }
        let t = self.duration;
        let u = self.elapsed / t;
        let scale = [
            u * u * u * (10.0 + u * (-15.0 + 6.0 * u)),
            30.0 * u * u * (1.0 + u * (-2.0 + u)) / t,
            60.0 * u * (1.0 + u * (-3.0 + 2.0 * u)) / (t * t),
            60.0 * (1.0 + u * (-6.0 + 6.0 * u)) / (t * t * t),
        ];
        let mut out = [[0.0; 3]; 4];
        for (k, row) in out.iter_mut().enumerate() {
            for i in 0..3 {
                let base = if k == 0 { self.from[i] } else { 0.0 };
                row[i] = base + scale[k] * (self.to[i] - self.from[i]);
            }
        }
        out
    }
}
