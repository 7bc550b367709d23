//! Learning in schrl: tasks, the GRU-ODE planning policy, and the
//! specification-constrained policy gradient (paper §3).
//!
//! * [`tasks`] — the five task types for Point with their specs and goals.
//! * [`planner`] — the GRU-ODE Gaussian planner (Eq. 3).
//! * [`cpg`] — the constrained policy gradient with a Lagrange multiplier (Eq. 4).
//! * [`deployed`] — a trained planner's mean path in plain Rust, no autodiff (deployment).
//! * [`gradient_planner`] — the gradient planner baseline (waypoints optimised directly).
//! * [`neural_sdf`] — MLP signed distances fitted to a map, as STL predicates.
//! * [`control`] — the goal-conditioned PPO controller.
//! * [`execute`] — driving the robot through a plan's waypoints; satisfaction of what it did.
//! * [`joint`] — joint training of planner and controller, task evaluation.
//! * [`store`] — run directories: manifest, atomic checkpoints, lock, metrics log.

#![warn(missing_docs)]

pub mod control;
pub mod cpg;
pub mod deployed;
pub mod execute;
pub mod gradient_planner;
pub mod gru_ode_backprop;
pub mod joint;
pub mod neural_sdf;
pub mod planner;
pub mod pretrain;
pub mod store;
pub mod tasks;
