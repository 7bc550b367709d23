//! Planner runs (`schrl plan train`): `planner.safetensors` (the weights) and
//! `planner.json` (what the planner is — task, shape, network — and the trainer's
//! state between updates, so a run resumes exactly). The run's settings
//! ([`PlanRunSettings`]) are in the manifest.

use std::path::Path;

use candle_core::{DType, Device};
use candle_nn::{VarBuilder, VarMap};
use serde::{Deserialize, Serialize};

use super::{Checkpoint, RunKind, SaveFiles, StoreError, invalid};
use crate::plan::cpg::{CpgConfig, PlanTrainer, PlanTrainerState};
use crate::plan::planner::{PathPlanner, PlannerConfig};
use crate::task::{SafeAlong, Task, TaskKind};

const WEIGHTS: &str = "planner.safetensors";
const STATE: &str = "planner.json";

/// Every setting of a `schrl plan train` run.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PlanRunSettings {
    /// The task (a built-in Point task).
    pub task: TaskKind,
    /// Where the task's `safe` is checked.
    pub safe_along: SafeAlong,
    /// The planner's training hyper-parameters (defaults: [`CpgConfig::default`]).
    pub cpg: CpgConfig,
    /// Most gradient updates.
    pub updates: usize,
    /// Stop once this fraction of a batch, and of 200 fresh samples, satisfies the spec.
    pub target: f64,
}

impl PlanRunSettings {
    /// The task these settings train on.
    pub fn task(&self) -> Task {
        let mut task = Task::point(self.task);
        task.safe_along = self.safe_along;
        task
    }
}

/// What a planner checkpoint records besides the weights.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PlannerMeta {
    /// Task.
    pub task: TaskKind,
    /// Where the task's `safe` was checked in training.
    pub safe_along: SafeAlong,
    /// The planner's shape and network.
    pub planner: PlannerConfig,
    /// The training hyper-parameters.
    pub cpg: CpgConfig,
    /// Updates made.
    pub updates: usize,
    /// Whether training reached its target (and stopped).
    pub reached: bool,
    /// The trainer's state between updates.
    pub trainer: PlanTrainerState,
}

/// Writes `trainer`'s planner (weights and state) into a save.
pub fn save_into(
    files: &mut SaveFiles,
    trainer: &PlanTrainer,
    updates: usize,
    reached: bool,
) -> Result<(), StoreError> {
    save_weights(files, trainer)?;
    let task = trainer.task();
    let kind: TaskKind = task.name.parse().map_err(|e: String| invalid(Path::new(STATE), e))?;
    let meta = PlannerMeta {
        task: kind,
        safe_along: task.safe_along,
        planner: *trainer.planner().config(),
        cpg: *trainer.config(),
        updates,
        reached,
        trainer: trainer.state(),
    };
    files.json(STATE, &meta)
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

/// Loads the planner of the planner run in `dir`, to plan with.
pub fn load(dir: &Path) -> Result<LoadedPlanner, StoreError> {
    let ckpt = Checkpoint::open(dir, RunKind::Planner)?;
    let meta: PlannerMeta = ckpt.json(STATE)?;
    let meta_path = ckpt.path_of(STATE);
    let mut task = Task::point(meta.task);
    task.safe_along = meta.safe_along;
    if meta.planner.dim != task.map.dim() {
        return Err(invalid(
            &meta_path,
            format!(
                "plan dimension {} does not match the {} task's {}",
                meta.planner.dim,
                meta.task.name(),
                task.map.dim()
            ),
        ));
    }
    let varmap = VarMap::new();
    let vb = VarBuilder::from_varmap(&varmap, DType::F32, &Device::Cpu);
    let planner = PathPlanner::new(meta.planner, vb).map_err(|e| invalid(&meta_path, e.to_string()))?;
    let mut varmap = varmap;
    let weights = ckpt.file(WEIGHTS)?;
    varmap.load(&weights).map_err(|e| invalid(&weights, e.to_string()))?;
    check_finite(&varmap, &weights)?;
    Ok(LoadedPlanner { planner, varmap, task, meta })
}

/// The trainer of the planner run checkpointed in `ckpt` with `settings`, restored
/// exactly; with the updates done and whether the target was reached.
pub fn load_trainer(
    ckpt: &Checkpoint,
    settings: &PlanRunSettings,
) -> Result<(PlanTrainer, usize, bool), StoreError> {
    let meta: PlannerMeta = ckpt.json(STATE)?;
    let meta_path = ckpt.path_of(STATE);
    let mut trainer =
        PlanTrainer::new(settings.task(), settings.cpg).map_err(|e| invalid(&meta_path, e.to_string()))?;
    restore_trainer(ckpt, &mut trainer, meta.trainer)?;
    Ok((trainer, meta.updates, meta.reached))
}

/// Loads the weights `ckpt` holds into `trainer` and restores its `state`.
pub(crate) fn restore_trainer(
    ckpt: &Checkpoint,
    trainer: &mut PlanTrainer,
    state: PlanTrainerState,
) -> Result<(), StoreError> {
    restore_named(ckpt, WEIGHTS, trainer, state)
}

/// Loads the weights of `ckpt`'s file `name` into `trainer` and restores its `state`.
pub(crate) fn restore_named(
    ckpt: &Checkpoint,
    name: &str,
    trainer: &mut PlanTrainer,
    state: PlanTrainerState,
) -> Result<(), StoreError> {
    let weights = ckpt.file(name)?;
    trainer.load_weights(&weights).map_err(|e| invalid(&weights, e.to_string()))?;
    check_finite(trainer.varmap(), &weights)?;
    trainer.restore_state(state).map_err(|e| invalid(&weights, e.to_string()))
}

/// Refuses weights holding NaN or ±∞: a planner of them plans nothing, and once
/// evaluated as "satisfaction 0" without a word.
fn check_finite(varmap: &VarMap, weights: &Path) -> Result<(), StoreError> {
    let data = varmap.data().lock().map_err(|_| invalid(weights, "weights are being written elsewhere"))?;
    for (name, var) in data.iter() {
        let values: Vec<f32> = var
            .flatten_all()
            .and_then(|t| t.to_vec1())
            .map_err(|e| invalid(weights, format!("{name}: {e}")))?;
        if let Some(v) = values.iter().find(|v| !v.is_finite()) {
            return Err(invalid(weights, format!("tensor '{name}' holds {v}: the weights are not usable")));
        }
    }
    Ok(())
}

/// Writes the planner weights alone (a joint run keeps the state in its own file).
pub(crate) fn save_weights(files: &mut SaveFiles, trainer: &PlanTrainer) -> Result<(), StoreError> {
    save_named(files, WEIGHTS, trainer)
}

/// Writes `trainer`'s weights into the save's file `name` (read by [`restore_named`]).
pub(crate) fn save_named(files: &mut SaveFiles, name: &str, trainer: &PlanTrainer) -> Result<(), StoreError> {
    files.write_with(name, |p| trainer.varmap().save(p))
}
