//! TLTL runs (`schrl baseline train --algo tltl`): the flat policy as a controller's
//! weights are saved (`controller.safetensors`) and `tltl.json`: the settings, the
//! normaliser and reward scaler, the random stream, every environment's state and
//! episode so far, and the counters. Together they resume a run exactly.

use std::path::Path;

use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use super::controller::{load_weights, save_weights};
use super::{Checkpoint, RunKind, SaveFiles, StoreError, check_format, invalid};
use crate::baseline::tltl::{TltlSettings, TltlTrainer};
use crate::control::normalize::{RewardScaler, RunningMeanStd};

const STATE: &str = "tltl.json";

/// The layout of `tltl.json` this build writes and reads.
const STATE_FORMAT: u32 = 1;

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct State {
    format: u32,
    settings: TltlSettings,
    obs_dim: usize,
    act_dim: usize,
    steps: usize,
    updates: usize,
    adam_t: u64,
    obs_rms: RunningMeanStd,
    reward_scaler: RewardScaler,
    rng: ChaCha8Rng,
    env_states: Vec<String>,
    trajectories: Vec<Vec<Vec<f64>>>,
    raw_obs: Vec<f64>,
}

/// Writes the TLTL trainer `t` into a save.
pub fn save_into(files: &mut SaveFiles, t: &TltlTrainer) -> Result<(), StoreError> {
    save_weights(files, &t.policy, &t.learner)?;
    let state = State {
        format: STATE_FORMAT,
        settings: t.settings.clone(),
        obs_dim: t.policy.obs_dim(),
        act_dim: t.policy.act_dim(),
        steps: t.steps,
        updates: t.updates,
        adam_t: t.learner.adam.t,
        obs_rms: t.obs_rms.clone(),
        reward_scaler: t.reward_scaler.clone(),
        rng: t.rng.clone(),
        env_states: t.envs.iter().map(|e| e.save_state()).collect(),
        trajectories: t.trajectories.clone(),
        raw_obs: t.raw_obs.clone(),
    };
    files.json(STATE, &state)
}

/// Restores the TLTL trainer checkpointed in `ckpt`.
pub fn load_from(ckpt: &Checkpoint) -> Result<TltlTrainer, StoreError> {
    let state: State = ckpt.json(STATE)?;
    let path = ckpt.path_of(STATE);
    check_format(&path, state.format, STATE_FORMAT, "the TLTL state")?;
    state.settings.ppo.validate().map_err(|e| invalid(&path, e))?;
    let (policy, learner) =
        load_weights(ckpt, (state.obs_dim, state.act_dim), &state.settings.ppo, state.adam_t)?;
    TltlTrainer::restored(
        state.settings,
        policy,
        learner,
        state.obs_rms,
        state.reward_scaler,
        state.rng,
        &state.env_states,
        state.trajectories,
        state.raw_obs,
        (state.steps, state.updates),
    )
    .map_err(|e| invalid(&path, e.to_string()))
}

/// Loads the TLTL run in `dir`.
pub fn load(dir: &Path) -> Result<TltlTrainer, StoreError> {
    load_from(&Checkpoint::open(dir, RunKind::Tltl)?)
}
