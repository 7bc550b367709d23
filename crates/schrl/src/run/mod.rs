//! Executing plans with a controller, and learning from what happens.
//!
//! * [`execute`] — the waypoint dispatcher (a small pure state machine) and the
//!   satisfaction of an executed run.
//! * [`joint`] — joint training of planner and controller, and task evaluation.

pub mod execute;
pub mod joint;
