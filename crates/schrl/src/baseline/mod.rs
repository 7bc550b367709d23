//! The paper's baselines (§4.2; Fig. 3 and Fig. 12), trained on the same tasks, judged
//! by the same execution spec and evaluated by the same protocol as SCHRL.
//!
//! * HTLTL — SCHRL without the Lagrange term: the same hierarchy, pre-training and
//!   joint training ([`crate::run::joint`]) with the planner on the plain policy
//!   gradient of `r_h = ρ + r_l` ([`crate::plan::cpg::Method::Pg`]). It needs no code of
//!   its own: [`htltl`] turns SCHRL's settings into it.
//! * [`flat`] — what policies without a planner observe, and how their episodes are
//!   judged and evaluated.
//! * [`tltl`] — one flat PPO policy rewarded by the spec's robustness.
//! * [`reward_machine`] — reward machines (Icarte et al. 2022): events, transitions,
//!   the shipped machines of the five tasks.
//! * [`replay`] and [`td3`] — the off-policy pieces: a replay buffer of machine-state
//!   transitions and TD3.
//! * [`crm`] — counterfactual experiences for reward machines, on TD3.
//! * [`dhrm`] — options per progress edge of the machine under a DQN meta-controller,
//!   run by CRM's trainer.

pub mod crm;
pub mod dhrm;
pub mod flat;
pub mod replay;
pub mod reward_machine;
pub mod td3;
pub mod tltl;

use crate::plan::cpg::{CpgConfig, Method};

/// HTLTL's planner settings: SCHRL's `cpg` with the Lagrange term dropped. λ then never
/// enters the loss nor moves, so the constraint's dual step is gone as well.
pub fn htltl(cpg: CpgConfig) -> CpgConfig {
    CpgConfig { method: Method::Pg, ..cpg }
}
