//! A single plan as a JSON file (`schrl plan mip --out`): the task it is for, its
//! waypoints, how it was found and how robust it is; written atomically, never over
//! an existing file unless asked. (Read it with any JSON reader; nothing here reads it.)

use std::path::Path;

use serde::{Deserialize, Serialize};

use super::StoreError;

/// A plan and where it came from.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PlanFile {
    /// The planner (`mip`).
    pub planner: String,
    /// The task's name.
    pub task: String,
    /// The task's robot.
    pub robot: String,
    /// Waypoints, the start first.
    pub waypoints: Vec<Vec<f64>>,
    /// Exact hard robustness of the plan under the task's spec.
    pub robustness: f64,
    /// The planner's own robustness figure (the MIP's linearised `ρ̃ ≤ ρ`).
    pub program_robustness: f64,
    /// Whether the solver proved the plan optimal.
    pub optimal: bool,
    /// Seconds to plan.
    pub seconds: f64,
    /// The solver.
    pub solver: String,
}

/// Writes `plan` to `path`; refuses to replace a file unless `force`.
pub fn save(plan: &PlanFile, path: &Path, force: bool) -> Result<(), StoreError> {
    let json = serde_json::to_string_pretty(plan).map_err(|e| super::invalid(path, e.to_string()))?;
    super::save_file(path, json.as_bytes(), force)
}
