//! Robots simulated by MuJoCo 3.17.0 (cargo feature `mujoco`).
//!
//! A legged robot with foot contacts needs a real contact solver, so the Doggo
//! quadruped runs on MuJoCo through the `mujoco-rs` bindings; the other robots stay
//! native (hand-written equations are 50–100× faster). Setup, once per clone:
//! `bash scripts/setup-mujoco.sh` copies the `libmujoco.so.3.17.0` of the PyPI wheel
//! `mujoco==3.17.0` into `.mujoco/lib/`, which `.cargo/config.toml` names as
//! `MUJOCO_DYNAMIC_LINK_DIR`; the build scripts record it as an rpath.
//!
//! * [`Doggo`] — the quadruped ([`crate::Dynamics`], so [`crate::GoalEnv`] adds goals,
//!   reward and episode bookkeeping as for every robot).
//! * [`PointTwin`] — the native [`crate::Point`] rebuilt in MuJoCo, for checking the
//!   native integrator against MuJoCo's.
//! * [`CarTwin`] — Safety Gym's Car in MuJoCo, for checking the native [`crate::Car`].

mod car_twin;
mod doggo;
mod point_twin;

pub use car_twin::{CAR_TWIN_XML, CarTwin};
pub use doggo::{
    ACTION_FILTER, DOGGO_XML, Doggo, FALL_HEIGHT, FALL_TILT_COS, FALL_TILT_SECONDS, GAIT, Gait,
    STANDING_HEIGHT, gait_amplitude,
};
pub use point_twin::{POINT_TWIN_XML, PointTwin};

use mujoco_rs::prelude::{MjModel, MjtObjBase};

use crate::env::EnvError;

/// Compiles MJCF text, mapping MuJoCo's error into an [`EnvError`].
fn compile(robot: &'static str, xml: &str) -> Result<MjModel, EnvError> {
    MjModel::from_xml_string(xml)
        .map_err(|e| EnvError::Mujoco { robot, reason: format!("cannot compile the model: {e}") })
}

/// The id of the object `name` of `kind`, or an error naming it.
fn id_of(model: &MjModel, robot: &'static str, kind: MjtObjBase, name: &str) -> Result<usize, EnvError> {
    model.name_to_id(kind, name).ok_or_else(|| EnvError::Mujoco {
        robot,
        reason: format!("the model has no {kind:?} named '{name}'"),
    })
}
