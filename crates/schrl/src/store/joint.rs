//! Joint runs (`schrl train`): the planner (`planner.safetensors`), the controller
//! (`controller.safetensors`, `controller.json`, as a controller run saves them) and
//! `joint.json`: the task's two files, the joint and planner settings as they stand
//! (pre-training may have dropped the safe margin, and picks the planner's seed), λ,
//! the planner's optimiser and random stream, the joint loop's random stream, reward
//! scaler and partial rollout, and the counters; with a trust region, the warm-start
//! planner it holds to (`anchor.safetensors`). Together they resume a run exactly.
//!
//! A run that selects its deployed checkpoint by validation ([`crate::run::select`])
//! also saves `selection.json` (every validation so far and the best) with each
//! checkpoint, and keeps the best validated checkpoint as a joint run of its own in
//! `best/` ([`BEST`]), replaced atomically when a better one is validated.

use std::collections::HashMap;
use std::path::Path;

use candle_core::{Device, Tensor};

use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use super::{Checkpoint, RunKind, SaveFiles, StoreError, check_format, controller, invalid, planner};
use crate::control::normalize::RewardScaler;
use crate::control::ppo::RolloutBuffer;
use crate::plan::cpg::{CpgConfig, PlanTrainerState};
use crate::run::joint::{JointConfig, JointTrainer};
use crate::run::select::{Selection, Validation};
use crate::task::Task;

const STATE: &str = "joint.json";
const ANCHOR: &str = "anchor.safetensors";
const SELECTION: &str = "selection.json";
/// The subdirectory of a selecting run holding its best validated checkpoint.
pub const BEST: &str = "best";

/// The layout of `joint.json` this build writes and reads (files written before the
/// field existed are this layout).
const STATE_FORMAT: u32 = 1;

fn first_format() -> u32 {
    1
}

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct State {
    #[serde(default = "first_format")]
    format: u32,
    task_toml: String,
    task_spec: String,
    joint: JointConfig,
    cpg: CpgConfig,
    iterations: usize,
    env_steps: usize,
    planner: PlanTrainerState,
    rng: ChaCha8Rng,
    scaler: RewardScaler,
    buffer: RolloutBuffer,
    /// The anchor's weight, when the planner is anchored (its parameters in
    /// [`ANCHOR`]); absent in runs saved before anchors existed.
    #[serde(default)]
    anchor_weight: Option<f64>,
}

/// Writes the joint trainer `t` into a save.
pub fn save_into(files: &mut SaveFiles, t: &JointTrainer) -> Result<(), StoreError> {
    planner::save_weights(files, &t.plan)?;
    controller::save_into(files, &t.control)?;
    let anchor = t.plan.anchor();
    if let Some((params, ..)) = anchor {
        let tensors = Tensor::from_slice(params, params.len(), &Device::Cpu)
            .map(|v| HashMap::from([("params".to_string(), v)]));
        files.write_with(ANCHOR, |p| tensors.and_then(|t| candle_core::safetensors::save(&t, p)))?;
    }
    let state = State {
        format: STATE_FORMAT,
        task_toml: t.task.toml.clone(),
        task_spec: t.task.spec.clone(),
        joint: t.config.clone(),
        cpg: *t.plan.config(),
        iterations: t.iterations,
        env_steps: t.env_steps,
        planner: t.plan.state(),
        rng: t.rng.clone(),
        scaler: t.scaler.clone(),
        buffer: t.buffer.clone(),
        anchor_weight: anchor.map(|(_, w, _)| w),
    };
    files.json(STATE, &state)
}

/// Restores the joint trainer checkpointed in `ckpt`.
pub fn load_from(ckpt: &Checkpoint) -> Result<JointTrainer, StoreError> {
    let state: State = ckpt.json(STATE)?;
    let path = ckpt.path_of(STATE);
    check_format(&path, state.format, STATE_FORMAT, "the joint-run state")?;
    let task = Task::from_texts(&path, &state.task_toml, &path, &state.task_spec)
        .map_err(|e| invalid(&path, format!("task: {}", e.message)))?;
    let control = controller::load_from(ckpt)?;
    let mut t = JointTrainer::new(task, state.joint, state.cpg, control)
        .map_err(|e| invalid(&path, e.to_string()))?;
    planner::restore_trainer(ckpt, &mut t.plan, state.planner)?;
    if let Some(weight) = state.anchor_weight {
        let file = ckpt.file(ANCHOR)?;
        let params = candle_core::safetensors::load(&file, &Device::Cpu)
            .and_then(|m| match m.get("params") {
                Some(v) => v.to_vec1::<f32>(),
                None => candle_core::bail!("no tensor 'params'"),
            })
            .map_err(|e| invalid(&file, e.to_string()))?;
        if let Some(x) = params.iter().find(|x| !x.is_finite()) {
            return Err(invalid(&file, format!("the anchor holds {x}: the weights are not usable")));
        }
        let kind = t.config.anchor_on;
        t.plan.restore_anchor(params, weight, kind).map_err(|e| invalid(&file, e.to_string()))?;
    }
    t.rng = state.rng;
    t.scaler = state.scaler;
    t.buffer = state.buffer;
    t.iterations = state.iterations;
    t.env_steps = state.env_steps;
    Ok(t)
}

/// Loads the joint run in `dir`.
pub fn load(dir: &Path) -> Result<JointTrainer, StoreError> {
    load_from(&Checkpoint::open(dir, RunKind::Joint)?)
}

/// Writes a selecting run's validations into a save.
pub fn save_selection(files: &mut SaveFiles, selection: &Selection) -> Result<(), StoreError> {
    files.json(SELECTION, selection)
}

/// The validations saved in `ckpt`; `None` for a run that does not select (or has
/// not validated yet).
pub fn load_selection(ckpt: &Checkpoint) -> Result<Option<Selection>, StoreError> {
    if !ckpt.manifest().files.contains_key(SELECTION) {
        return Ok(None);
    }
    ckpt.json(SELECTION).map(Some)
}

/// The checkpoint of the run in `dir` that is its result: for a run that selects,
/// the best validated one (in `DIR/best`) with the validation that chose it;
/// otherwise the last.
pub fn load_deployed(dir: &Path) -> Result<(JointTrainer, Option<Validation>), StoreError> {
    let ckpt = Checkpoint::open(dir, RunKind::Joint)?;
    let best = dir.join(BEST);
    if let Some(selection) = load_selection(&ckpt)?
        && best.join(super::MANIFEST).exists()
    {
        let t = load(&best)?;
        let chosen = selection.validations.iter().find(|v| v.iteration == t.iterations).copied();
        return Ok((t, chosen));
    }
    Ok((load_from(&ckpt)?, None))
}
