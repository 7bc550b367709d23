//! Executing plans with a controller, and learning from what happens.
//!
//! * [`execute`] — the waypoint dispatcher (a small pure state machine) and the
//!   satisfaction of an executed run.
//! * [`episode`] — the one episode loop, driving robots through their waypoints.
//! * [`joint`] — joint training of planner and controller.
//! * [`evaluate`] — tasks and controllers measured on fresh runs.

pub mod episode;
pub mod evaluate;
pub mod execute;
pub mod joint;
