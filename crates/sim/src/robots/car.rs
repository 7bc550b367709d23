//! Car: Safety Gym's differential-drive robot (reference setup; Safety-Gymnasium
//! `car.xml`).
//!
//! A 0.2 × 0.2 × 0.1 m box chassis on two driven wheels (radius 0.05 m, 0.13 m either
//! side, 0.1 m behind the centre) and a passive ball caster 0.1 m ahead. In this
//! model's frame x points forward (the XML's −y, where the front bumper is).
//!
//! * Each wheel is driven by a motor, torque `0.02 a_i` N·m for `action = [left,
//!   right]` in [−1, 1]: the action spans the motor's whole torque range. (Safety
//!   Gym's motor, gear 1 with `forcerange` ±0.02, saturates at 2 % of its ±1 control
//!   range, so a policy's action there acts by its sign alone; the deployed
//!   controller's mean action then dithered forward and back in place: 13 of 200
//!   goals within 2 m never reached.)
//! * Wheels are massless in the plane of motion (their inertia, 2.5e-6 kg·m², is
//!   four orders below the car's): a rolling wheel passes `(τ − c_w Ω)/r` to the
//!   ground while rolling. Sideways, the wheels hold against slip with the force that
//!   stops it within a physics step. When that pair (along, across) exceeds the
//!   wheel's Coulomb friction disc `μ N`, the wheel slips and the ground force is the
//!   same pair scaled onto the disc (a velocity-level contact solve), so the car skids
//!   when turned hard and still grips sideways when its wheels spin.
//! * The caster rolls freely; its ball-joint damping makes a rolling drag
//!   `c_c v / r²`.
//! * Accelerating moves load from the caster onto the wheels (braking, the other
//!   way): `m a h / L` with the centre of mass `h` = 0.089 m up and the contacts `L` =
//!   0.2 m apart, settling with a time constant of 0.2 s. Without it the wheels held
//!   their static grip and the sliding caster ate most of it: from rest the car took
//!   20 steps to top speed where MuJoCo's takes 8.
//!
//! | parameter | value | source |
//! |---|---|---|
//! | physics step | 0.004 s, 10 per control step | reference setup |
//! | mass | 0.0304 kg (density 5, all geoms) | car.xml |
//! | yaw inertia | 3.44e-4 kg·m² | car.xml geometry |
//! | wheel / caster joint damping | 0.001 | car.xml default |
//! | friction μ | 1 | MuJoCo default |
//! | loads | 0.268 m g per wheel, 0.463 m g caster | static balance about the centre of mass, 7.4 mm behind the centre (car.xml geometry) |
//! | load transfer | `m a` × 0.089 / 0.2 from the caster to the wheels | centre of mass height (car.xml geometry) over the wheel–caster distance |
//! | its settling time | 0.2 s | fitted to the MuJoCo twin's acceleration from rest |
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
/// Centre of mass ahead of the chassis centre (m): the bumpers, wheels and caster of
/// `car.xml` (density 5) put it 7.4 mm behind, towards the wheels.
const COM_X: f64 = {
    const D: f64 = 5.0;
    const PI: f64 = std::f64::consts::PI;
    // (mass, x) of each geom, x forward (the XML's −y).
    let parts = [
        (D * 0.2 * 0.2 * 0.1, 0.0),                          // chassis
        (D * 0.2 * 0.02 * 0.1, -0.15),                       // back bumper
        (D * 0.02 * 0.05 * 0.06, -0.125),                    // back connector
        (D * 0.1 * 0.02 * 0.1, 0.165),                       // front bumper
        (D * 0.1 * 0.06 * 0.02, 0.13),                       // front connector
        (2.0 * D * PI * 0.05 * 0.05 * 0.05, WHEEL_X),        // two wheels
        (D * 4.0 / 3.0 * PI * 0.05 * 0.05 * 0.05, CASTER_X), // caster
    ];
    let (mut m, mut mx, mut i) = (0.0, 0.0, 0);
    while i < parts.len() {
        m += parts[i].0;
        mx += parts[i].0 * parts[i].1;
        i += 1;
    }
    mx / m
};
/// Height of the centre of mass above the ground (m): the chassis, bumpers and
/// connectors at the body origin (0.1 m up), the wheels' and caster's centres at
/// 0.05 m (`car.xml` geometry, density 5), 0.089 m.
const COM_Z: f64 = {
    const D: f64 = 5.0;
    const PI: f64 = std::f64::consts::PI;
    let low = 2.0 * D * PI * 0.05 * 0.05 * 0.05 + D * 4.0 / 3.0 * PI * 0.05 * 0.05 * 0.05;
    (0.1 * (MASS - low) + 0.05 * low) / MASS
};
/// Load moved from the caster onto the wheels per newton of forward ground force:
/// the ground forces act `COM_Z` below the centre of mass, and their moment is carried
/// by the contacts `CASTER_X − WHEEL_X` apart.
const LOAD_TRANSFER: f64 = COM_Z / (CASTER_X - WHEEL_X);
/// The fraction of the way to its new load transfer the chassis moves in one physics
/// step: `DT / τ` with τ = 0.2 s, the chassis settling on its contacts, fitted to the
/// MuJoCo twin's acceleration from rest (README, *Fidelity of the native Car*).
const SETTLE: f64 = DT / 0.2;
/// Static balance about the centre of mass: the wheels (at `WHEEL_X`) and the caster
/// (at `CASTER_X`) share the weight in inverse proportion to their distances from it.
/// MuJoCo's contact forces at rest agree to 4 digits (0.537 on the wheels).
const WHEEL_LOAD: f64 = MASS * GRAVITY * (CASTER_X - COM_X) / (CASTER_X - WHEEL_X) / 2.0;
const CASTER_LOAD: f64 = MASS * GRAVITY * (COM_X - WHEEL_X) / (CASTER_X - WHEEL_X);
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
    /// Load (N) the last physics step's forward acceleration moved from the caster
    /// onto the wheels (negative when braking); see [`Car`]'s module notes.
    #[serde(default)]
    pub load_shift: f64,
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
            load_shift: 0.0,
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
    /// [`Car::load_shift`].
    shift: f64,
}

impl Planar {
    fn world_vel(&self) -> [f64; 2] {
        self.heading.to_world([self.u, self.l])
    }
}

/// The traction (left, right) each wheel would pass to the ground while rolling:
/// `drive − c_w v / r²` of a massless wheel at ground speed `v = u ∓ w y`, for motor
/// `drive` (torque / r) at body velocity (`u`, yaw rate `w`).
#[inline]
fn rolling_traction(drive: [f64; 2], u: f64, w: f64) -> [f64; 2] {
    // Summed so that the term waiting on `u` comes last.
    let turn = ROLL_DAMPING * WHEEL_Y * w;
    let roll = ROLL_DAMPING * u;
    [(drive[0] + turn) - roll, (drive[1] - turn) - roll]
}

/// The friction (wheel, caster) each contact can transmit, `μ N`, with `shift` of the
/// load moved from the caster onto the wheels.
#[inline]
fn grips(shift: f64) -> (f64, f64) {
    (MU * (WHEEL_LOAD + 0.5 * shift), MU * (CASTER_LOAD - shift))
}

/// A wheel's ground force (along, across) and whether it slips: the force that keeps
/// it rolling without sliding (`along`, `across`), or, when that exceeds the friction
/// disc `grip` (`μ N`), the same force scaled onto the disc (friction against the slip
/// the contact would otherwise have, as a velocity-level contact solver finds it).
#[inline]
fn wheel_force(along: f64, across: f64, grip: f64) -> (f64, f64, bool) {
    let n2 = along * along + across * across;
    // Branch-free: while driving at random, rolling and slipping alternate too often
    // for a branch to be predicted.
    let k = (grip / n2.sqrt()).min(1.0);
    (k * along, k * across, k < 1.0)
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
    let Planar { mut pos, u, l, w, mut heading, shift } = st;
    let (wheel_grip, caster_grip) = grips(shift);
    let roll = rolling_traction(drive, u, w);
    // Caster rolling drag `c_c v / r²`, bounded by its friction.
    let cl = l + CASTER_X * w;
    let k = CASTER_DRAG.min(caster_grip / (u * u + cl * cl).sqrt());
    let (fcu, fcl) = (-k * u, -k * cl);
    // Sideways, both wheels sit at the same x, so their contact points slide at one
    // speed, `l + x w`; the force that stops that slide within the step (after the
    // wheels' traction, bounded by its grip) is shared by the two wheels. The caster's
    // drag is left out of it (a Jacobi step rather than Gauss–Seidel, corrected on the
    // next step): it keeps the caster's and the wheels' square roots off one
    // dependency chain (BENCHMARKS.md).
    let est = roll.map(|f| f.clamp(-wheel_grip, wheel_grip));
    let stop = -(LATERAL_MASS / DT) * (l + WHEEL_X * w)
        - (LATERAL_MASS * WHEEL_X * DT_I * WHEEL_Y / DT) * (est[1] - est[0]);
    // Each wheel's friction disc bounds both together: a wheel spinning under full
    // torque still holds sideways (MuJoCo's car turns on the spot at 1.3 rad/s;
    // giving traction priority, as this model once did, left nothing sideways and
    // it spun at 6.17).
    let (left, left_across, _) = wheel_force(roll[0], 0.5 * stop, wheel_grip);
    let (right, right_across, _) = wheel_force(roll[1], 0.5 * stop, wheel_grip);
    let l_mid = l + DT_M * fcl;
    let w_spin = w + DT_I * CASTER_X * fcl;
    let across = left_across + right_across;
    let forward = fcu + (left + right);
    let u_new = u + DT_M * forward;
    let l_new = l_mid + DT_M * across;
    let w_new = (w_spin + DT_I * WHEEL_Y * (right - left)) + DT_I * WHEEL_X * across;
    let [vx, vy] = heading.to_world([u_new, l_new]);
    pos[0] += DT * vx;
    pos[1] += DT * vy;
    // Turning the frame leaves the world velocity unchanged: its body-frame
    // components rotate back by the same angle.
    let (s, c) = heading.rotate(w * DT);
    // The forward force pitches the chassis onto the wheels (braking, onto the
    // caster); the loads settle towards that within `SETTLE`'s time constant, and
    // the next step's grips carry them (no contact's load below zero).
    let target = (LOAD_TRANSFER * forward).clamp(-2.0 * WHEEL_LOAD, CASTER_LOAD);
    let shift = shift + SETTLE * (target - shift);
    Planar { pos, u: c * u_new + s * l_new, l: -s * u_new + c * l_new, w: w_new, heading, shift }
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
        let torque = [action[0] * MOTOR_LIMIT, action[1] * MOTOR_LIMIT];
        let drive = torque.map(|t| t * INV_WHEEL_RADIUS);
        let t = DT * SUBSTEPS as f64;
        let mut guard = ContactGuard::new(map, &self.pos, RADIUS);
        let mut collided = false;
        let [u, l] = self.heading.to_body(self.vel);
        let mut st =
            Planar { pos: self.pos, u, l, w: self.yaw_rate, heading: self.heading, shift: self.load_shift };
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
        self.load_shift = st.shift;
        // Wheel spin: rolling with the ground, or, slipping, where the motor's torque
        // balances the damping and the ground's force (the sideways share estimated
        // as zero: a state read-out, not fed back).
        let roll = rolling_traction(drive, st.u, st.w);
        let (wheel_grip, _) = grips(st.shift);
        for i in 0..2 {
            let v_long = st.u - st.w * [WHEEL_Y, -WHEEL_Y][i];
            let (along, _, slips) = wheel_force(roll[i], 0.0, wheel_grip);
            self.wheel_speed[i] = if slips {
                (torque[i] - WHEEL_RADIUS * along) * INV_WHEEL_DAMPING
            } else {
                v_long * INV_WHEEL_RADIUS
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
