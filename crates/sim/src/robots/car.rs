//! Car: Safety Gym's differential-drive robot (reference setup; Safety-Gymnasium
//! `car.xml`).
//!
//! A 0.2 × 0.2 × 0.1 m box chassis on two driven wheels (radius 0.05 m, 0.13 m either
//! side, 0.1 m behind the centre) and a passive ball caster 0.1 m ahead. In this
//! model's frame x points forward (the XML's −y, where the front bumper is).
//!
//! * Each wheel is driven by a motor, torque `clamp(a_i, ±0.02)` N·m (gear 1,
//!   `forcerange` ±0.02); `action = [left, right]` in [−1, 1].
//! * Wheels are massless in the plane of motion (their inertia, 2.5e-6 kg·m², is
//!   four orders below the car's): a rolling wheel passes `(τ − c_w Ω)/r` to the
//!   ground; when that exceeds Coulomb friction `μ N` the wheel spins and slips and
//!   the ground force is `μ N`. Sideways, the wheels resist slip with friction
//!   impulses bounded by the friction left over (a velocity-level contact solve), so
//!   the car skids when turned hard.
//! * The caster rolls freely; its ball-joint damping makes a rolling drag
//!   `c_c v / r²`.
//!
//! | parameter | value | source |
//! |---|---|---|
//! | physics step | 0.004 s, 10 per control step | reference setup |
//! | mass | 0.0304 kg (density 5, all geoms) | car.xml |
//! | yaw inertia | 3.44e-4 kg·m² | car.xml geometry |
//! | wheel / caster joint damping | 0.001 | car.xml default |
//! | friction μ | 1 | MuJoCo default |
//! | loads | m g / 4 per wheel, m g / 2 caster | static balance of the layout |
//! | collision shape | disc of radius 0.2 m (chassis with bumpers) | car.xml geometry |
//! | reach radius | 0.3 m | reference setup |
//!
//! Observation (26): accelerometer, velocimeter, gyro, magnetometer (3 each, robot
//! frame), the caster ball's orientation relative to the chassis (3 × 3, row-major)
//! and its angular velocity in the chassis frame (3), then the goal vector in the
//! robot frame (2).

use rand_chacha::ChaCha8Rng;

use crate::contact::ContactGuard;
use crate::env::Dynamics;
use crate::map::Map;
use crate::robots::{GRAVITY, Heading, planar_sensors, random_yaw};
use crate::rotation::{Quat, apply_t};

const DT: f64 = 0.004;
const SUBSTEPS: usize = 10;
const MASS: f64 = 0.030_445;
const INERTIA: f64 = 3.44e-4;
const WHEEL_RADIUS: f64 = 0.05;
const WHEEL_Y: f64 = 0.13;
const WHEEL_X: f64 = -0.1;
const CASTER_X: f64 = 0.1;
const CASTER_RADIUS: f64 = 0.05;
const MOTOR_LIMIT: f64 = 0.02;
const WHEEL_DAMPING: f64 = 0.001;
const CASTER_DAMPING: f64 = 0.001;
const MU: f64 = 1.0;
const WHEEL_LOAD: f64 = MASS * GRAVITY / 4.0;
const CASTER_LOAD: f64 = MASS * GRAVITY / 2.0;
const RADIUS: f64 = 0.2;
const INV_MASS: f64 = 1.0 / MASS;
const INV_WHEEL_RADIUS: f64 = 1.0 / WHEEL_RADIUS;
const INV_WHEEL_DAMPING: f64 = 1.0 / WHEEL_DAMPING;
const INV_INERTIA: f64 = 1.0 / INERTIA;
const CASTER_DRAG: f64 = CASTER_DAMPING / (CASTER_RADIUS * CASTER_RADIUS);
// Effective mass of a sideways impulse at the wheels' contact points.
const LATERAL_MASS: f64 = 1.0 / (INV_MASS + WHEEL_X * WHEEL_X * INV_INERTIA);
// Products of constants named once: the compiler keeps floating-point operations in
// the order written, so `DT * f * INV_MASS` would be two dependent multiplies.
const DT_M: f64 = DT * INV_MASS;
const DT_I: f64 = DT * INV_INERTIA;
/// A wheel's rolling damping seen at the ground: `c_w / r²` (N per m/s).
const ROLL_DAMPING: f64 = WHEEL_DAMPING * INV_WHEEL_RADIUS * INV_WHEEL_RADIUS;
/// Friction a wheel can transmit: `μ N`.
const WHEEL_GRIP: f64 = MU * WHEEL_LOAD;
/// Friction the caster can transmit: `μ N`.
const CASTER_GRIP: f64 = MU * CASTER_LOAD;

/// The Car's state.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Car {
    /// Position (m).
    pub pos: [f64; 2],
    /// Velocity (m/s, world frame).
    pub vel: [f64; 2],
    /// Heading (forward axis).
    pub heading: Heading,
    /// Yaw rate (rad/s).
    pub yaw_rate: f64,
    /// Wheel spin rates (rad/s), left and right.
    pub wheel_speed: [f64; 2],
    /// The caster ball's orientation in the world.
    pub caster: Quat,
    /// The caster ball's angular velocity (world frame, rad/s).
    pub caster_rate: [f64; 3],
    /// Acceleration over the last physics step (world frame).
    pub accel: [f64; 2],
}

impl Default for Car {
    fn default() -> Self {
        Self {
            pos: [0.0; 2],
            vel: [0.0; 2],
            heading: Heading::new(0.0),
            yaw_rate: 0.0,
            wheel_speed: [0.0; 2],
            caster: Quat::IDENTITY,
            caster_rate: [0.0; 3],
            accel: [0.0; 2],
        }
    }
}

/// The planar state a physics step updates, held in registers across the steps of a
/// control step (velocity in the body frame: forward `u`, left `l`).
#[derive(Clone, Copy)]
struct Planar {
    pos: [f64; 2],
    u: f64,
    l: f64,
    w: f64,
    heading: Heading,
}

impl Planar {
    fn world_vel(&self) -> [f64; 2] {
        self.heading.to_world([self.u, self.l])
    }
}

/// The wheels' ground forces (left, right) for motor `drive` (torque / r) at body
/// velocity (`u`, yaw rate `w`): traction `drive − c_w v / r²` of a massless wheel
/// rolling at `v = u ∓ w y`, or `±μ N` when it slips.
#[inline]
fn traction(drive: [f64; 2], u: f64, w: f64) -> [f64; 2] {
    // Summed so that the term waiting on `u` comes last.
    let turn = ROLL_DAMPING * WHEEL_Y * w;
    let roll = ROLL_DAMPING * u;
    [(drive[0] + turn) - roll, (drive[1] - turn) - roll].map(|f| f.clamp(-WHEEL_GRIP, WHEEL_GRIP))
}

/// One physics step of 0.004 s (semi-implicit Euler).
///
/// Forces act in the frame the step starts in; the chassis then moves with the new
/// velocity and its frame turns by the yaw rate the step started with (explicit
/// Euler in the heading, so the turn is computed alongside the forces instead of
/// after them). One environment is latency-bound on this step's chain of dependent
/// operations, so sums are written with the operand that is ready last added last.
#[inline]
fn substep(st: Planar, drive: [f64; 2]) -> Planar {
    let Planar { mut pos, u, l, w, mut heading } = st;
    let long = traction(drive, u, w);
    // Caster rolling drag `c_c v / r²`, bounded by its friction.
    let cl = l + CASTER_X * w;
    let speed2 = u * u + cl * cl;
    let (fcu, fcl) = if speed2 * (CASTER_DRAG * CASTER_DRAG) > CASTER_GRIP * CASTER_GRIP {
        let k = CASTER_GRIP / speed2.sqrt();
        (-k * u, -k * cl)
    } else {
        (-CASTER_DRAG * u, -CASTER_DRAG * cl)
    };
    // Explicit update with the traction and drag forces; the wheels' torque about the
    // centre is `y (f_right − f_left)`.
    let u_new = (u + DT_M * fcu) + DT_M * (long[0] + long[1]);
    let l_mid = l + DT_M * fcl;
    let w_spin = w + DT_I * CASTER_X * fcl;
    let w_mid = w_spin + DT_I * WHEEL_Y * (long[1] - long[0]);
    // Sideways friction: both wheels sit at the same x, so their contact points
    // slide sideways at one speed, `l + x w`; the impulse that stops it is bounded by
    // the friction both wheels have left after traction (the fixed point of a
    // Gauss–Seidel contact solve, in closed form).
    let want = -LATERAL_MASS * (l_mid + WHEEL_X * w_spin)
        - (LATERAL_MASS * WHEEL_X * DT_I * WHEEL_Y) * (long[1] - long[0]);
    // √(a² − f²) ≥ a − |f|: when the impulse is within that bound, no root is needed.
    let a = WHEEL_GRIP;
    let j = if want.abs() <= (2.0 * a - long[0].abs() - long[1].abs()) * DT {
        want
    } else if long[0].abs() >= a && long[1].abs() >= a {
        // Both wheels slip (the common case at full torque): no friction is left.
        0.0
    } else {
        let room = |f: f64| (a * a - f * f).max(0.0).sqrt();
        let limit = (room(long[0]) + room(long[1])) * DT;
        want.clamp(-limit, limit)
    };
    let l_new = l_mid + INV_MASS * j;
    let w_new = w_mid + WHEEL_X * INV_INERTIA * j;
    let [vx, vy] = heading.to_world([u_new, l_new]);
    pos[0] += DT * vx;
    pos[1] += DT * vy;
    // Turning the frame leaves the world velocity unchanged: its body-frame
    // components rotate back by the same angle.
    let (s, c) = heading.rotate(w * DT);
    Planar { pos, u: c * u_new + s * l_new, l: -s * u_new + c * l_new, w: w_new, heading }
}

impl Dynamics for Car {
    const NAME: &'static str = "car";
    const OBS_DIM: usize = 26;
    const ACT_DIM: usize = 2;
    const PLAN_DIM: usize = 2;
    const REACH_RADIUS: f64 = 0.3;
    const RADIUS: f64 = RADIUS;

    fn reset(&mut self, start: &[f64], rng: &mut ChaCha8Rng) {
        let yaw = random_yaw(rng);
        *self = Car {
            pos: [start[0], start[1]],
            heading: Heading::new(yaw),
            caster: Quat::from_yaw(yaw),
            ..Car::default()
        };
    }

    fn advance(&mut self, action: &[f64], map: &Map, _goal: &[f64]) -> bool {
        let torque = [action[0].clamp(-MOTOR_LIMIT, MOTOR_LIMIT), action[1].clamp(-MOTOR_LIMIT, MOTOR_LIMIT)];
        let drive = torque.map(|t| t * INV_WHEEL_RADIUS);
        let t = DT * SUBSTEPS as f64;
        let mut guard = ContactGuard::new(map, &self.pos, RADIUS);
        let mut collided = false;
        let [u, l] = self.heading.to_body(self.vel);
        let mut st = Planar { pos: self.pos, u, l, w: self.yaw_rate, heading: self.heading };
        let mut before = self.vel;
        for _ in 0..SUBSTEPS {
            before = st.world_vel();
            st = substep(st, drive);
            let travel = (st.u.abs() + st.l.abs()) * DT; // rotation-invariant L1 bound
            if guard.may_touch(travel) {
                let mut v = st.world_vel();
                collided |= guard.resolve(map, &mut st.pos, &mut v, RADIUS);
                [st.u, st.l] = st.heading.to_body(v);
            }
        }
        self.pos = st.pos;
        self.vel = st.world_vel();
        self.yaw_rate = st.w;
        self.heading = st.heading;
        let long = traction(drive, st.u, st.w);
        for i in 0..2 {
            let v_long = st.u - st.w * [WHEEL_Y, -WHEEL_Y][i];
            self.wheel_speed[i] = if long[i].abs() < WHEEL_GRIP {
                v_long * INV_WHEEL_RADIUS
            } else {
                (torque[i] - WHEEL_RADIUS * long[i]) * INV_WHEEL_DAMPING
            };
        }
        self.accel = [(self.vel[0] - before[0]) * (1.0 / DT), (self.vel[1] - before[1]) * (1.0 / DT)];
        self.heading.normalize();
        // The caster rolls without slipping under its contact point's velocity.
        let [vx, vy] = self.vel;
        let [ox, oy] = self.heading.to_world([0.0, self.yaw_rate * CASTER_X]);
        let (cx, cy) = (vx + ox, vy + oy);
        self.caster_rate = [-cy / CASTER_RADIUS, cx / CASTER_RADIUS, self.yaw_rate];
        self.caster.integrate_world(self.caster_rate, t);
        collided
    }

    fn plan_position(&self) -> &[f64] {
        &self.pos
    }

    fn yaw(&self) -> f64 {
        self.heading.angle()
    }

    fn observe(&self, goal: &[f64], obs: &mut [f64]) {
        let h = &self.heading;
        // Inertial sensors in 0..12, the caster in 12..24, the goal vector in 24..26.
        let mut imu = [0.0; 14];
        let to_goal = [goal[0] - self.pos[0], goal[1] - self.pos[1]];
        planar_sensors(h, self.accel, self.vel, self.yaw_rate, to_goal, &mut imu);
        obs[..12].copy_from_slice(&imu[..12]);
        obs[24..26].copy_from_slice(&imu[12..]);
        // Caster relative to the chassis: R_chassisᵀ R_ball, with R_chassis the yaw
        // rotation by the heading (no trigonometry needed).
        let [c, s] = h.dir();
        let ball = self.caster.matrix();
        for j in 0..3 {
            obs[12 + j] = c * ball[0][j] + s * ball[1][j];
            obs[15 + j] = -s * ball[0][j] + c * ball[1][j];
            obs[18 + j] = ball[2][j];
        }
        let r = [[h.dir()[0], -h.dir()[1], 0.0], [h.dir()[1], h.dir()[0], 0.0], [0.0, 0.0, 1.0]];
        let rate = [self.caster_rate[0], self.caster_rate[1], self.caster_rate[2] - self.yaw_rate];
        obs[21..24].copy_from_slice(&apply_t(&r, rate));
    }
}
