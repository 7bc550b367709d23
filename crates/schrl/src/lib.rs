//! Learning in schrl: tasks, planners, the controller, joint training, run directories.
//!
//! The rooms, in the order data flows through them (each depends only on those before):
//!
//! * [`task`] — tasks as data (spec, goals, map, plan length), their validation, the
//!   map-clearance and neural-SDF predicates, start and noise sampling.
//! * [`nn`] — the small-network kernels shared by planner, controller and neural SDF:
//!   a tanh MLP with its backward pass, Adam.
//! * [`plan`] — planners: the GRU-ODE network and its ablations, the constrained policy
//!   gradient (paper §3.2), the hand-written GRU-ODE update, pre-training on the spec,
//!   the deployed (autodiff-free) planner, the gradient-planner baseline.
//! * [`control`] — the goal-conditioned PPO controller (paper §3.3).
//! * [`run`] — executing plans with a controller: the waypoint dispatcher, joint
//!   training (paper App. A), evaluation over groups of runs.
//! * [`baseline`] — the paper's baselines: HTLTL (SCHRL without the Lagrange term), TLTL
//!   (a flat PPO policy rewarded by the spec's robustness), CRM (reward machines on TD3).
//! * [`store`] — run directories: manifest, atomic checkpoints, lock, metrics log.
//! * [`train`] — a task trained end to end into a run directory (controller,
//!   pre-training, joint phase, checkpoints, evaluation), watched through a progress
//!   hook: what `schrl train` and Python's `schrl.train` call.

#![warn(missing_docs)]

pub mod baseline;
pub mod control;
pub mod nn;
pub mod plan;
pub mod run;
pub mod store;
pub mod task;
pub mod train;
