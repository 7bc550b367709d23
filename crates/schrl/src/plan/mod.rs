//! Planners: from a start, a path of waypoints that should satisfy the task's spec.
//!
//! * [`planner`] — the Gaussian GRU-ODE policy (paper Eq. 3) and the GRU/MLP ablations.
//! * [`cpg`] — the specification-constrained policy gradient (paper Eq. 4).
//! * [`gru_ode_backprop`] — the GRU-ODE's update written by hand.
//! * [`pretrain`] — warm-starting a joint run's planner on the spec alone.
//! * [`deployed`] — a trained planner's mean path in plain Rust (deployment).
//! * [`gradient_planner`] — the gradient planner baseline (waypoints optimised directly).
//! * [`mip`] — the mixed-integer planner (the spec as a MILP, solved to optimality).

pub mod cpg;
pub mod deployed;
pub mod gradient_planner;
pub mod gru_ode_backprop;
pub mod mip;
pub mod planner;
pub mod pretrain;
