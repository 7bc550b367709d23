//! Planner pre-training between candidates (`DIR/pretrain/` of a `schrl train` run,
//! [`PRETRAIN`]): `pretrain.json` (every candidate's score so far, and of each
//! round's best candidate and of the guided candidate their settings, validation and
//! trainer state) and their weights (`with-margin.safetensors`, `own.safetensors`,
//! `guided.safetensors`). A run cut off
//! while pre-training goes on from the last candidate instead of from the first
//! ([`crate::plan::pretrain::PretrainState`]).

use serde::{Deserialize, Serialize};

use super::{Checkpoint, SaveFiles, StoreError, check_format, invalid, planner};
use crate::plan::cpg::{CpgConfig, PlanTrainer, PlanTrainerState};
use crate::plan::pretrain::{Candidate, CandidateScore, PretrainState, candidate_task};
use crate::run::joint::JointTrainer;

/// The subdirectory of a joint run that holds its pre-training.
pub const PRETRAIN: &str = "pretrain";

const STATE: &str = "pretrain.json";

/// The layout of `pretrain.json` this build writes and reads.
const STATE_FORMAT: u32 = 1;

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct State {
    format: u32,
    scores: Vec<CandidateScore>,
    best_with_margin: Option<Kept>,
    best_own: Option<Kept>,
    /// Saves from before the guided candidate was saved have neither field.
    #[serde(default)]
    guide_tried: bool,
    #[serde(default)]
    guided: Option<Kept>,
}

/// A round's best candidate, less its weights.
#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct Kept {
    cpg: CpgConfig,
    satisfaction: f64,
    length: f64,
    trainer: PlanTrainerState,
}

/// Which kept candidate a weights file holds.
#[derive(Clone, Copy)]
enum Slot {
    WithMargin,
    Own,
    Guided,
}

impl Slot {
    fn weights(self) -> &'static str {
        match self {
            Slot::WithMargin => "with-margin.safetensors",
            Slot::Own => "own.safetensors",
            Slot::Guided => "guided.safetensors",
        }
    }

    /// Whether its candidate planned with the run's safe margin.
    fn with_safe_margin(self) -> bool {
        matches!(self, Slot::WithMargin)
    }
}

/// Writes pre-training's `state` into a save.
pub fn save_into(files: &mut SaveFiles, state: &PretrainState) -> Result<(), StoreError> {
    let mut kept = |c: &Option<Candidate>, slot: Slot| -> Result<Option<Kept>, StoreError> {
        let Some(c) = c else { return Ok(None) };
        planner::save_named(files, slot.weights(), &c.trainer)?;
        Ok(Some(Kept {
            cpg: *c.trainer.config(),
            satisfaction: c.satisfaction,
            length: c.length,
            trainer: c.trainer.state(),
        }))
    };
    let state = State {
        format: STATE_FORMAT,
        scores: state.scores.clone(),
        best_with_margin: kept(&state.best_with_margin, Slot::WithMargin)?,
        best_own: kept(&state.best_own, Slot::Own)?,
        guide_tried: state.guide_tried,
        guided: kept(&state.guided, Slot::Guided)?,
    };
    files.json(STATE, &state)
}

/// The pre-training saved in `ckpt` for the fresh trainer `t` (the run's, before
/// pre-training), its best candidates restored exactly.
pub fn load_from(ckpt: &Checkpoint, t: &JointTrainer) -> Result<PretrainState, StoreError> {
    let state: State = ckpt.json(STATE)?;
    let path = ckpt.path_of(STATE);
    check_format(&path, state.format, STATE_FORMAT, "the pre-training state")?;
    let restore = |kept: Option<Kept>, slot: Slot| -> Result<Option<Candidate>, StoreError> {
        let Some(k) = kept else { return Ok(None) };
        let task = candidate_task(t, slot.with_safe_margin()).map_err(|e| invalid(&path, e.to_string()))?;
        let mut trainer = PlanTrainer::new(task, k.cpg).map_err(|e| invalid(&path, e.to_string()))?;
        planner::restore_named(ckpt, slot.weights(), &mut trainer, k.trainer)?;
        Ok(Some(Candidate { trainer, satisfaction: k.satisfaction, length: k.length }))
    };
    Ok(PretrainState {
        scores: state.scores,
        best_with_margin: restore(state.best_with_margin, Slot::WithMargin)?,
        best_own: restore(state.best_own, Slot::Own)?,
        guide_tried: state.guide_tried,
        guided: restore(state.guided, Slot::Guided)?,
    })
}
