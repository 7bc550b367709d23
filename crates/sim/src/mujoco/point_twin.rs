//! The native Point rebuilt in MuJoCo, to check the native integrator.
//!
//! [`POINT_TWIN_XML`] has the masses, gears, force limits and damping of
//! [`crate::Point`] (see its table), slide joints x, y and a hinge z, and MuJoCo's
//! implicit integrator at the same 0.002 s step. Driving both with the same actions
//! and comparing positions measures how far the hand-written dynamics are from
//! MuJoCo's (README, *Fidelity of the native Point*; pinned by a test).

use std::sync::Arc;

use mujoco_rs::prelude::{MjData, MjModel};

use super::compile;
use crate::env::EnvError;

/// The MJCF of the MuJoCo Point.
pub const POINT_TWIN_XML: &str = include_str!("../../assets/point_twin.xml");

/// Physics steps per control step, as the native Point.
const SUBSTEPS: usize = 10;

/// The Point in MuJoCo (no walls: it is for comparing free motion).
#[derive(Clone)]
pub struct PointTwin {
    data: MjData<Arc<MjModel>>,
}

impl PointTwin {
    /// The twin at rest at the origin, heading along x.
    pub fn new() -> Result<Self, EnvError> {
        let model = Arc::new(compile("point", POINT_TWIN_XML)?);
        Ok(Self { data: MjData::new(model) })
    }

    /// Puts it at rest at `pos` with heading `yaw` (rad).
    pub fn reset(&mut self, pos: [f64; 2], yaw: f64) {
        self.data.reset();
        self.data.qpos_mut().copy_from_slice(&[pos[0], pos[1], yaw]);
        self.data.forward();
    }

    /// One control step (10 physics steps) under `action` (push, spin), each clipped
    /// to [−1, 1] as the native environment clips it.
    pub fn step(&mut self, action: [f64; 2]) {
        let ctrl = self.data.ctrl_mut();
        ctrl[0] = action[0].clamp(-1.0, 1.0);
        ctrl[1] = action[1].clamp(-1.0, 1.0);
        for _ in 0..SUBSTEPS {
            self.data.step();
        }
    }

    /// Position (m).
    pub fn position(&self) -> [f64; 2] {
        let q = self.data.qpos();
        [q[0], q[1]]
    }

    /// Heading (rad, not wrapped).
    pub fn yaw(&self) -> f64 {
        self.data.qpos()[2]
    }

    /// Velocity (m/s, world frame) and yaw rate (rad/s).
    pub fn velocity(&self) -> [f64; 3] {
        let v = self.data.qvel();
        [v[0], v[1], v[2]]
    }
}
