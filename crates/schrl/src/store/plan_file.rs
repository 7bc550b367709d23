//! A single plan as a JSON file (`schrl plan mip --out`): the task it is for, its
//! waypoints, how it was found and how robust it is; written atomically, never over
//! an existing file unless asked.

use std::path::Path;

use serde::{Deserialize, Serialize};

use super::{StoreError, invalid, write_atomic};

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
    if path.exists() && !force {
        return Err(StoreError::FileExists(path.to_path_buf()));
    }
    let json = serde_json::to_string_pretty(plan).map_err(|e| invalid(path, e.to_string()))?;
    write_atomic(path, json.as_bytes())
}

/// Reads a plan written by [`save`].
pub fn load(path: &Path) -> Result<PlanFile, StoreError> {
    let text =
        std::fs::read_to_string(path).map_err(|e| invalid(path, format!("cannot read the plan: {e}")))?;
    let plan: PlanFile = serde_json::from_str(&text).map_err(|e| invalid(path, e.to_string()))?;
    if plan.waypoints.is_empty() {
        return Err(invalid(path, "the plan has no waypoints"));
    }
    Ok(plan)
}
