//! Saving and loading trained planners.
//!
//! A checkpoint is a directory holding `planner.safetensors` (the weights) and
//! `planner.json` (task, robot, method, semantics, seed, updates, λ, the planner's
//! shape). Files are written to temporary names and renamed, so a crash never leaves
//! a half-written checkpoint, and an existing checkpoint is never replaced unless
//! asked.

use std::path::{Path, PathBuf};

use candle_core::{DType, Device};
use candle_nn::{VarBuilder, VarMap};
use serde::{Deserialize, Serialize};

use crate::cpg::PlanTrainer;
use crate::planner::{PathPlanner, PlannerConfig, PlannerKind};
use crate::tasks::{SafeAlong, Task, TaskKind};

/// What a checkpoint records besides the weights.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PlannerMeta {
    /// Robot (only "point" so far).
    pub robot: String,
    /// Task name.
    pub task: String,
    /// "cpg" or "pg".
    pub method: String,
    /// Semantics of the loss, as text (`hard`, `soft:2`, ...).
    pub semantics: String,
    /// Training seed.
    pub seed: u64,
    /// Updates made.
    pub updates: usize,
    /// λ at the end.
    pub lambda: f64,
    /// Plan dimension.
    pub dim: usize,
    /// GRU hidden size.
    pub hidden: usize,
    /// Waypoint step bound.
    pub bound: f64,
    /// Smallest standard deviation.
    pub min_std: f64,
    /// The planner network: `gru-ode` (the paper's; the default of older
    /// checkpoints), `gru` or `mlp`.
    #[serde(default = "default_planner")]
    pub planner: String,
    /// Where the task's `safe` was checked in training: `segments` (the task files'
    /// default, and that of older checkpoints) or `waypoints`.
    #[serde(default = "default_safe_along")]
    pub safe_along: String,
}

fn default_safe_along() -> String {
    SafeAlong::default().name().to_string()
}

fn default_planner() -> String {
    PlannerKind::GruOde.name().to_string()
}

/// A checkpoint problem, naming the file.
#[derive(Debug, thiserror::Error)]
pub enum CheckpointError {
    /// The directory already holds a checkpoint.
    #[error("{0} already holds a checkpoint; pass --force to replace it")]
    Exists(PathBuf),
    /// A file could not be read or written.
    #[error("{path}: {message}")]
    Io {
        /// The file.
        path: PathBuf,
        /// What went wrong.
        message: String,
    },
    /// The metadata is malformed or names something unknown.
    #[error("{path}: {message}")]
    Invalid {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
}

const WEIGHTS: &str = "planner.safetensors";
const META: &str = "planner.json";

pub(crate) fn io(path: &Path, e: impl std::fmt::Display) -> CheckpointError {
    CheckpointError::Io { path: path.to_path_buf(), message: e.to_string() }
}

/// Writes `bytes` to `path` through a temporary file and a rename.
pub(crate) fn write_atomic(
    path: &Path,
    write: impl FnOnce(&Path) -> Result<(), String>,
) -> Result<(), CheckpointError> {
    let tmp = path.with_extension(format!("tmp.{}", std::process::id()));
    if let Err(e) = write(&tmp) {
        let _ = std::fs::remove_file(&tmp);
        return Err(io(path, e));
    }
    std::fs::rename(&tmp, path).map_err(|e| {
        let _ = std::fs::remove_file(&tmp);
        io(path, e)
    })
}

/// Saves `trainer`'s planner into `dir` (created if needed); refuses to replace an
/// existing checkpoint unless `force`.
pub fn save(
    dir: &Path,
    trainer: &PlanTrainer,
    meta: &PlannerMeta,
    force: bool,
) -> Result<(), CheckpointError> {
    let weights = dir.join(WEIGHTS);
    if !force && (weights.exists() || dir.join(META).exists()) {
        return Err(CheckpointError::Exists(dir.to_path_buf()));
    }
    std::fs::create_dir_all(dir).map_err(|e| io(dir, e))?;
    // The weights file is written with a ".safetensors" name so the format is clear.
    let tmp_weights = dir.join(format!(".{WEIGHTS}.{}", std::process::id()));
    trainer.varmap().save(&tmp_weights).map_err(|e| io(&weights, e))?;
    std::fs::rename(&tmp_weights, &weights).map_err(|e| io(&weights, e))?;
    let json = serde_json::to_string_pretty(meta).map_err(|e| io(&dir.join(META), e))?;
    write_atomic(&dir.join(META), |p| std::fs::write(p, json).map_err(|e| e.to_string()))
}

/// A loaded planner with its task and metadata.
pub struct LoadedPlanner {
    /// The planner.
    pub planner: PathPlanner,
    /// Its weights.
    pub varmap: VarMap,
    /// The task it was trained on.
    pub task: Task,
    /// The metadata.
    pub meta: PlannerMeta,
}

/// Loads the checkpoint in `dir`.
pub fn load(dir: &Path) -> Result<LoadedPlanner, CheckpointError> {
    let meta_path = dir.join(META);
    let text = std::fs::read_to_string(&meta_path).map_err(|e| io(&meta_path, e))?;
    let meta: PlannerMeta = serde_json::from_str(&text)
        .map_err(|e| CheckpointError::Invalid { path: meta_path.clone(), message: e.to_string() })?;
    let invalid = |message: String| CheckpointError::Invalid { path: meta_path.clone(), message };
    if meta.robot != "point" {
        return Err(invalid(format!("robot '{}' has no planner tasks yet (only point)", meta.robot)));
    }
    let kind: TaskKind = meta.task.parse().map_err(invalid)?;
    let mut task = Task::point(kind);
    task.safe_along = meta.safe_along.parse().map_err(|e: String| invalid(format!("safe_along: {e}")))?;
    if meta.dim != task.map.dim() {
        return Err(invalid(format!(
            "plan dimension {} does not match the {} task's {}",
            meta.dim,
            meta.task,
            task.map.dim()
        )));
    }
    let mut varmap = VarMap::new();
    let vb = VarBuilder::from_varmap(&varmap, DType::F32, &Device::Cpu);
    let kind: PlannerKind = meta.planner.parse().map_err(invalid)?;
    let cfg =
        PlannerConfig { dim: meta.dim, hidden: meta.hidden, bound: meta.bound, min_std: meta.min_std, kind };
    let planner = PathPlanner::new(cfg, vb).map_err(|e| invalid(e.to_string()))?;
    let weights = dir.join(WEIGHTS);
    varmap
        .load(&weights)
        .map_err(|e| CheckpointError::Invalid { path: weights.clone(), message: e.to_string() })?;
    Ok(LoadedPlanner { planner, varmap, task, meta })
}
