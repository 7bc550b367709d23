//! Executing plans with a controller, and learning from what happens.
//!
//! * [`execute`] — the waypoint dispatcher (a small pure state machine) and the
//!   satisfaction of an executed run.
//! * [`episode`] — the one episode loop, driving robots through their waypoints.
//! * [`joint`] — joint training of planner and controller.
//! * [`evaluate`] — tasks and controllers measured on fresh runs.
//! * [`select`] — which checkpoint of a joint run is deployed, by validation.

pub mod episode;
pub mod evaluate;
pub mod execute;
pub mod joint;
pub mod select;

/// A problem running plans with a controller, naming its source.
#[derive(Debug, thiserror::Error)]
pub enum RunError {
    /// A joint-training setting is invalid (the setting's key, what is wrong).
    #[error("invalid setting {key}: {message}")]
    Setting {
        /// The setting's key, as in the run's settings.
        key: &'static str,
        /// What is wrong.
        message: String,
    },
    /// The planner failed (its tensors or its spec).
    #[error("planner: {0}")]
    Planner(#[from] candle_core::Error),
    /// The controller refused its configuration.
    #[error(transparent)]
    Control(#[from] crate::control::ControlError),
    /// An environment refused something.
    #[error(transparent)]
    Env(#[from] sim::EnvError),
    /// A picture could not be drawn or written.
    #[error(transparent)]
    Picture(#[from] sim::render::RenderError),
    /// A run could not be recorded (`schrl eval --trajectories`).
    #[error("recording a run: {0}")]
    Record(String),
}
