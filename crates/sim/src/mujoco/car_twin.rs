//! Safety Gym's Car in MuJoCo, to check the native Car against.
//!
//! [`CAR_TWIN_XML`] is the Car as the reference setup describes Safety Gym's
//! `car.xml` (chassis, bumpers, wheels, caster, densities, damping, motor limits, step),
//! on a floor without walls. Driving it and the native [`crate::Car`] with the same
//! actions compares top speed, turning and random-action paths (README, *Fidelity of
//! the native Car*; pinned by a test).

use std::f64::consts::FRAC_PI_2;
use std::sync::Arc;

use mujoco_rs::prelude::{MjData, MjModel};

use super::compile;
use crate::env::EnvError;

/// The MJCF of the MuJoCo Car.
pub const CAR_TWIN_XML: &str = include_str!("../../assets/car_twin.xml");

/// Physics steps per control step, as the native Car.
const SUBSTEPS: usize = 10;
/// The motors' torque limit (N·m; gear 1, so also the control that reaches it).
const MOTOR_LIMIT: f64 = 0.02;

/// The Car in MuJoCo (no walls: it is for comparing free motion).
#[derive(Clone)]
pub struct CarTwin {
    data: MjData<Arc<MjModel>>,
}

impl CarTwin {
    /// The twin at rest at the origin, heading along x.
    pub fn new() -> Result<Self, EnvError> {
        let model = Arc::new(compile("car", CAR_TWIN_XML)?);
        Ok(Self { data: MjData::new(model) })
    }

    /// Puts it at rest on the floor at `pos` with heading `yaw` (rad, the direction it
    /// drives forward in, as the native Car's).
    pub fn reset(&mut self, pos: [f64; 2], yaw: f64) {
        self.data.reset();
        // The model's forward axis is its −y: turning it by yaw + π/2 points it at yaw.
        let half = 0.5 * (yaw + FRAC_PI_2);
        let q = self.data.qpos_mut();
        q[0] = pos[0];
        q[1] = pos[1];
        q[3..7].copy_from_slice(&[half.cos(), 0.0, 0.0, half.sin()]);
        self.data.forward();
    }

    /// One control step (10 physics steps) under the native Car's `action = [left,
    /// right]`, clipped to [−1, 1] as the native environment clips it and scaled to
    /// the motors' torque range as the native Car scales it.
    pub fn step(&mut self, action: [f64; 2]) {
        let torque = action.map(|a| a.clamp(-1.0, 1.0) * MOTOR_LIMIT);
        let ctrl = self.data.ctrl_mut();
        // The model's first motor drives the wheel on the right of its forward axis.
        ctrl[0] = torque[1];
        ctrl[1] = torque[0];
        for _ in 0..SUBSTEPS {
            self.data.step();
        }
    }

    /// Position of the chassis's origin (m).
    pub fn position(&self) -> [f64; 2] {
        let q = self.data.qpos();
        [q[0], q[1]]
    }

    /// Heading (rad, in (−π, π]).
    pub fn yaw(&self) -> f64 {
        let q = self.data.qpos();
        let model_yaw = 2.0 * q[6].atan2(q[3]);
        let yaw = model_yaw - FRAC_PI_2;
        yaw.sin().atan2(yaw.cos())
    }

    /// Velocity (m/s, world frame) and yaw rate (rad/s).
    pub fn velocity(&self) -> [f64; 3] {
        let v = self.data.qvel();
        // A free joint's angular velocity is in the body frame, whose z stays the
        // world's while the chassis is level.
        [v[0], v[1], v[5]]
    }
}
