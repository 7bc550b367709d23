//! Point: Safety Gym's planar robot (reference setup; Safety-Gymnasium `point.xml`).
//!
//! A sphere of radius 0.1 m with a small box "arrow" showing its heading, on slide
//! joints x, y and a hinge z, so it slides on the plane without friction from the
//! floor (no vertical degree of freedom bears load). Two actuators:
//!
//! * `action[0]`: a motor pushing along the heading, gear 0.3, actuator force clamped
//!   to ±0.05 (`forcerange`) before the gear: force `0.3 · clamp(a0, ±0.05)` N.
//! * `action[1]`: a velocity servo on the hinge, gain kv = 1, gear 0.3: torque
//!   `0.3 · clamp(a1 − 0.3 ω, ±0.05)` N·m, so yaw rate settles near `3.16 · a1` rad/s.
//!
//! | parameter | value | source |
//! |---|---|---|
//! | physics step | 0.002 s, 10 per control step | reference setup |
//! | mass | 5.19e-3 kg: density 1 × (sphere r 0.1 + 0.1 m cube) | point.xml |
//! | yaw inertia | 2.86e-5 kg·m² (sphere + cube at 0.1 m) | point.xml geometry |
//! | slide damping | 0.01 N·s/m | point.xml, reference "~0.01" |
//! | hinge damping | 0.005 N·m·s | point.xml |
//! | action range | [−1, 1] both | point.xml ctrlrange |
//! | reach radius | 0.3 m | reference setup |
//!
//! Integration is semi-implicit Euler with damping and the servo treated implicitly,
//! as MuJoCo's implicit integrator does. Observation (14): accelerometer (3),
//! velocimeter (3), gyro (3), magnetometer (3), all in the robot frame (x forward,
//! y left, z up; accelerometer includes +9.81 on z; the magnetic field is MuJoCo's
//! default (0, −0.5, 0)), then the goal vector in the robot frame (2).

use rand_chacha::ChaCha8Rng;

use crate::contact::{self, ContactGuard};
use crate::env::Dynamics;
use crate::map::Map;
use crate::robots::{Heading, planar_sensors, random_yaw};

const DT: f64 = 0.002;
const SUBSTEPS: usize = 10;
const RADIUS: f64 = 0.1;
const MASS: f64 = (4.0 / 3.0 * std::f64::consts::PI * RADIUS * RADIUS * RADIUS) + 0.001;
// Sphere 2/5 m r² plus the 0.1 m cube about its own axis and offset 0.1 m.
const INERTIA: f64 = 0.4 * (MASS - 0.001) * RADIUS * RADIUS + 0.001 * (0.02 / 12.0 + 0.01);
const SLIDE_DAMPING: f64 = 0.01;
const HINGE_DAMPING: f64 = 0.005;
const GEAR: f64 = 0.3;
const FORCE_LIMIT: f64 = 0.05;
// Implicit damping factor of one step, and force-to-velocity-change, precomputed.
const DAMP: f64 = 1.0 / (1.0 + DT * SLIDE_DAMPING / MASS);
const DV_PER_N: f64 = DT / MASS;

/// The Point robot's state.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Point {
    /// Position (m).
    pub pos: [f64; 2],
    /// Velocity (m/s, world frame).
    pub vel: [f64; 2],
    /// Heading.
    pub heading: Heading,
    /// Yaw rate (rad/s).
    pub yaw_rate: f64,
    /// Acceleration over the last physics step (world frame), for the accelerometer.
    pub accel: [f64; 2],
}

impl Default for Point {
    fn default() -> Self {
        Self { pos: [0.0; 2], vel: [0.0; 2], heading: Heading::new(0.0), yaw_rate: 0.0, accel: [0.0; 2] }
    }
}

impl Point {
    /// One physics step of 0.002 s.
    fn substep(&mut self, push: f64, spin: f64) {
        // Translation: m dv/dt = F h − c v, damping implicit.
        let f = GEAR * push.clamp(-FORCE_LIMIT, FORCE_LIMIT) * DV_PER_N;
        let h = self.heading.dir();
        for i in 0..2 {
            self.vel[i] = (self.vel[i] + f * h[i]) * DAMP;
        }
        // Yaw: I dω/dt = 0.3·clamp(a1 − 0.3ω, ±0.05) − c ω, implicit in ω while the
        // servo is unsaturated.
        let w = (INERTIA * self.yaw_rate / DT + GEAR * spin) / (INERTIA / DT + GEAR * GEAR + HINGE_DAMPING);
        let servo = spin - GEAR * w;
        self.yaw_rate = if servo.abs() <= FORCE_LIMIT {
            w
        } else {
            (INERTIA * self.yaw_rate / DT + GEAR * FORCE_LIMIT * servo.signum())
                / (INERTIA / DT + HINGE_DAMPING)
        };
        self.heading.rotate(self.yaw_rate * DT);
        self.pos[0] += DT * self.vel[0];
        self.pos[1] += DT * self.vel[1];
    }
}

impl Dynamics for Point {
    const NAME: &'static str = "point";
    const OBS_DIM: usize = 14;
    const ACT_DIM: usize = 2;
    const PLAN_DIM: usize = 2;
    const REACH_RADIUS: f64 = 0.3;
    const RADIUS: f64 = RADIUS;

    fn reset(&mut self, start: &[f64], rng: &mut ChaCha8Rng) {
        *self =
            Point { pos: [start[0], start[1]], heading: Heading::new(random_yaw(rng)), ..Point::default() };
    }

    fn advance(&mut self, action: &[f64], map: &Map, _goal: &[f64]) -> bool {
        let mut guard = ContactGuard::new(map, &self.pos, RADIUS);
        let mut collided = false;
        let mut before = self.vel;
        for _ in 0..SUBSTEPS {
            before = self.vel;
            self.substep(action[0], action[1]);
            let travel = contact::travel_bound(&self.vel, DT);
            collided |= guard.after_move(map, &mut self.pos, &mut self.vel, RADIUS, travel);
        }
        // The accelerometer reads the last physics step's acceleration.
        self.accel = [(self.vel[0] - before[0]) / DT, (self.vel[1] - before[1]) / DT];
        self.heading.normalize();
        collided
    }

    fn plan_position(&self) -> &[f64] {
        &self.pos
    }

    fn yaw(&self) -> f64 {
        self.heading.angle()
    }

    fn observe(&self, goal: &[f64], obs: &mut [f64]) {
        let to_goal = [goal[0] - self.pos[0], goal[1] - self.pos[1]];
        planar_sensors(&self.heading, self.accel, self.vel, self.yaw_rate, to_goal, obs);
    }
}
