//! Saving and restoring a controller training run.
//!
//! A checkpoint directory holds `controller.safetensors` (the parameters and Adam's
//! moments as `f32` tensors `params`, `adam.m`, `adam.v`) and `controller.json`
//! (configuration, normaliser statistics, step counts, the random stream, every
//! environment's state). Together they restore a run exactly: training resumed from
//! a checkpoint produces the same numbers as training that never stopped. Each file
//! is written to a temporary name and renamed; the JSON names a checksum of the
//! weights, so a weights file from another save is detected.

use std::collections::HashMap;
use std::path::Path;

use candle_core::{Device, Tensor};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};
use sim::{Map, VecEnv};

use super::adam::Adam;
use super::normalize::{RewardScaler, RunningMeanStd};
use super::policy::ActorCritic;
use super::ppo::PpoLearner;
use super::trainer::{ControlConfig, ControlTrainer, Controller, RecentOutcomes};
use crate::checkpoint::{CheckpointError, io, write_atomic};

const WEIGHTS: &str = "controller.safetensors";
const META: &str = "controller.json";
const FORMAT: u32 = 1;

/// What `controller.json` holds.
#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct Meta {
    format: u32,
    config: ControlConfig,
    obs_dim: usize,
    act_dim: usize,
    params_checksum: String,
    steps: usize,
    updates: usize,
    adam_t: u64,
    obs_rms: RunningMeanStd,
    reward_scaler: RewardScaler,
    rng: ChaCha8Rng,
    env_states: Vec<String>,
    raw_obs: Vec<f64>,
    episode_returns: Vec<f64>,
    recent: RecentOutcomes,
}

/// FNV-1a over the parameters' bits: ties the JSON to its weights file.
fn checksum(params: &[f32]) -> String {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for p in params {
        for b in p.to_bits().to_le_bytes() {
            h ^= b as u64;
            h = h.wrapping_mul(0x0100_0000_01b3);
        }
    }
    format!("{h:016x}")
}

/// `true` if `dir` already holds a controller checkpoint.
pub fn exists(dir: &Path) -> bool {
    dir.join(META).exists() || dir.join(WEIGHTS).exists()
}

/// Saves the run into `dir` (created if needed). Refuses to replace an existing
/// checkpoint unless `overwrite`.
pub fn save(dir: &Path, t: &ControlTrainer, overwrite: bool) -> Result<(), CheckpointError> {
    if !overwrite && exists(dir) {
        return Err(CheckpointError::Exists(dir.to_path_buf()));
    }
    std::fs::create_dir_all(dir).map_err(|e| io(dir, e))?;
    let vec = |v: &[f32]| Tensor::from_slice(v, v.len(), &Device::Cpu);
    let weights = dir.join(WEIGHTS);
    let tensors: HashMap<String, Tensor> = [
        ("params", vec(&t.policy.params)),
        ("adam.m", vec(&t.learner.adam.m)),
        ("adam.v", vec(&t.learner.adam.v)),
    ]
    .into_iter()
    .map(|(k, v)| v.map(|v| (k.to_string(), v)))
    .collect::<Result<_, _>>()
    .map_err(|e| io(&weights, e))?;
    write_atomic(&weights, |p| candle_core::safetensors::save(&tensors, p).map_err(|e| e.to_string()))?;
    let meta = Meta {
        format: FORMAT,
        config: t.config.clone(),
        obs_dim: t.policy.obs_dim(),
        act_dim: t.policy.act_dim(),
        params_checksum: checksum(&t.policy.params),
        steps: t.steps,
        updates: t.updates,
        adam_t: t.learner.adam.t,
        obs_rms: t.obs_rms.clone(),
        reward_scaler: t.reward_scaler.clone(),
        rng: t.rng.clone(),
        env_states: t.envs.envs().iter().map(|e| e.save_state()).collect(),
        raw_obs: t.raw_obs.clone(),
        episode_returns: t.episode_returns.clone(),
        recent: t.recent.clone(),
    };
    let meta_path = dir.join(META);
    let json = serde_json::to_string(&meta).map_err(|e| io(&meta_path, e))?;
    write_atomic(&meta_path, |p| std::fs::write(p, json).map_err(|e| e.to_string()))
}

/// Loads the run saved in `dir`, ready to continue training.
pub fn load(dir: &Path) -> Result<ControlTrainer, CheckpointError> {
    let meta_path = dir.join(META);
    let invalid =
        |path: &Path, message: String| CheckpointError::Invalid { path: path.to_path_buf(), message };
    let text = std::fs::read_to_string(&meta_path).map_err(|e| io(&meta_path, e))?;
    let meta: Meta = serde_json::from_str(&text).map_err(|e| invalid(&meta_path, e.to_string()))?;
    if meta.format != FORMAT {
        return Err(invalid(&meta_path, format!("format {} is not {FORMAT}", meta.format)));
    }
    meta.config.ppo.validate().map_err(|e| invalid(&meta_path, e))?;
    let robot: sim::Robot =
        meta.config.robot.parse().map_err(|e: sim::EnvError| invalid(&meta_path, e.to_string()))?;
    let map = Map::by_name(&meta.config.map)
        .ok_or_else(|| invalid(&meta_path, format!("unknown map '{}'", meta.config.map)))?;

    let weights = dir.join(WEIGHTS);
    let tensors = candle_core::safetensors::load(&weights, &Device::Cpu)
        .map_err(|e| invalid(&weights, e.to_string()))?;
    let get = |name: &str| -> Result<Vec<f32>, CheckpointError> {
        let t = tensors.get(name).ok_or_else(|| invalid(&weights, format!("no tensor '{name}'")))?;
        t.flatten_all()
            .and_then(|t| t.to_vec1::<f32>())
            .map_err(|e| invalid(&weights, format!("{name}: {e}")))
    };
    let mut policy = ActorCritic::new(meta.obs_dim, meta.act_dim, &meta.config.ppo.hidden, &mut rand::rng());
    let params = get("params")?;
    if params.len() != policy.params.len() {
        return Err(invalid(
            &weights,
            format!(
                "{} parameters, but a {}-{:?}-{} actor-critic has {}",
                params.len(),
                meta.obs_dim,
                meta.config.ppo.hidden,
                meta.act_dim,
                policy.params.len()
            ),
        ));
    }
    if checksum(&params) != meta.params_checksum {
        return Err(invalid(&weights, format!("does not match {} (an interrupted or mixed save?)", META)));
    }
    policy.params = params;
    let mut learner = PpoLearner::new(meta.config.ppo.clone(), &policy);
    let (m, v) = (get("adam.m")?, get("adam.v")?);
    if m.len() != policy.params.len() || v.len() != policy.params.len() {
        return Err(invalid(&weights, "optimizer moments have the wrong length".into()));
    }
    learner.adam = Adam { m, v, t: meta.adam_t, ..Adam::new(0) };

    let n = meta.config.ppo.num_envs;
    let env_err = |e: sim::EnvError| invalid(&meta_path, e.to_string());
    let mut envs = VecEnv::new(robot, map, n, 0).map_err(env_err)?;
    if envs.obs_dim() != meta.obs_dim || envs.act_dim() != meta.act_dim {
        return Err(invalid(&meta_path, format!("the {robot} does not have {} observations", meta.obs_dim)));
    }
    if meta.env_states.len() != n || meta.raw_obs.len() != n * meta.obs_dim || meta.episode_returns.len() != n
    {
        return Err(invalid(&meta_path, format!("saved state is not for {n} environments")));
    }
    for (e, s) in envs.envs_mut().iter_mut().zip(&meta.env_states) {
        e.restore_state(s).map_err(env_err)?;
    }
    ControlTrainer::from_parts(
        meta.config,
        policy,
        learner,
        meta.obs_rms,
        meta.reward_scaler,
        meta.rng,
        envs,
        meta.raw_obs,
        meta.episode_returns,
        meta.recent,
        meta.steps,
        meta.updates,
    )
    .map_err(|e| invalid(&meta_path, e.to_string()))
}

/// Loads only the deployable controller from `dir`.
pub fn load_controller(dir: &Path) -> Result<Controller, CheckpointError> {
    Ok(load(dir)?.controller())
}
