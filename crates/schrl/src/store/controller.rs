//! Controller checkpoints: `controller.safetensors` (the parameters and Adam's moments
//! as `f32` tensors `params`, `adam.m`, `adam.v`) and `controller.json` (configuration,
//! normaliser statistics, step counts, the random stream, every environment's state).
//! Together they restore a training run exactly: resumed training produces the same
//! numbers as training that never stopped. A controller run (`schrl control train`)
//! saves these two files; a joint run saves them beside the planner's.

use std::collections::HashMap;
use std::path::Path;

use candle_core::{Device, Tensor};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};
use sim::{Map, VecEnv};

use super::{Checkpoint, RunKind, SaveFiles, StoreError, invalid};
use crate::control::normalize::{RewardScaler, RunningMeanStd};
use crate::control::policy::ActorCritic;
use crate::control::ppo::{PpoConfig, PpoLearner};
use crate::control::trainer::{ControlConfig, ControlTrainer, Controller, RecentOutcomes};
use crate::nn::adam::Adam;

const WEIGHTS: &str = "controller.safetensors";
const STATE: &str = "controller.json";

/// What `controller.json` holds.
#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct State {
    config: ControlConfig,
    obs_dim: usize,
    act_dim: usize,
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

/// Writes `t`'s two files into a save.
pub fn save_into(files: &mut SaveFiles, t: &ControlTrainer) -> Result<(), StoreError> {
    save_weights(files, &t.policy, &t.learner)?;
    let state = State {
        config: t.config.clone(),
        obs_dim: t.policy.obs_dim(),
        act_dim: t.policy.act_dim(),
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
    files.json(STATE, &state)
}

/// Restores the controller training state saved by [`save_into`] in `ckpt`.
pub fn load_from(ckpt: &Checkpoint) -> Result<ControlTrainer, StoreError> {
    let state: State = ckpt.json(STATE)?;
    let state_path = ckpt.path_of(STATE);
    let bad = |message: String| invalid(&state_path, message);
    state.config.ppo.validate().map_err(&bad)?;
    let robot = state.config.robot;
    let map =
        Map::by_name(&state.config.map).ok_or_else(|| bad(format!("unknown map '{}'", state.config.map)))?;

    let (policy, learner) =
        load_weights(ckpt, (state.obs_dim, state.act_dim), &state.config.ppo, state.adam_t)?;

    let n = state.config.ppo.num_envs;
    let env_err = |e: sim::EnvError| bad(e.to_string());
    let mut envs = VecEnv::new(robot, map, n, 0).map_err(env_err)?;
    envs.set_track_observation(state.config.observe_track);
    if envs.obs_dim() != state.obs_dim || envs.act_dim() != state.act_dim {
        return Err(bad(format!(
            "saved for a {robot} with {} observations and {} actions, but this build's {robot} has {} and {}: \
             its model changed since this controller was trained; train it again",
            state.obs_dim,
            state.act_dim,
            envs.obs_dim(),
            envs.act_dim()
        )));
    }
    if state.env_states.len() != n
        || state.raw_obs.len() != n * state.obs_dim
        || state.episode_returns.len() != n
    {
        return Err(bad(format!("saved state is not for {n} environments")));
    }
    for (e, s) in envs.envs_mut().iter_mut().zip(&state.env_states) {
        e.restore_state(s).map_err(env_err)?;
    }
    ControlTrainer::from_parts(
        state.config,
        policy,
        learner,
        state.obs_rms,
        state.reward_scaler,
        state.rng,
        envs,
        state.raw_obs,
        state.episode_returns,
        state.recent,
        state.steps,
        state.updates,
    )
    .map_err(|e| bad(e.to_string()))
}

/// Writes an actor-critic's parameters and its Adam moments as `controller.safetensors`
/// (the controller's file; a TLTL run's flat policy is saved the same way).
pub(super) fn save_weights(
    files: &mut SaveFiles,
    policy: &ActorCritic,
    learner: &PpoLearner,
) -> Result<(), StoreError> {
    let vec = |v: &[f32]| Tensor::from_slice(v, v.len(), &Device::Cpu);
    let tensors = [("params", &policy.params), ("adam.m", &learner.adam.m), ("adam.v", &learner.adam.v)]
        .into_iter()
        .map(|(k, v)| vec(v).map(|v| (k.to_string(), v)))
        .collect::<Result<HashMap<String, Tensor>, _>>();
    files.write_with(WEIGHTS, |p| tensors.and_then(|t| candle_core::safetensors::save(&t, p)))
}

/// Reads what [`save_weights`] wrote for an `(obs_dim, act_dim)` actor-critic trained
/// with `ppo`, Adam at step `adam_t`; refuses weights of another shape or not finite.
pub(super) fn load_weights(
    ckpt: &Checkpoint,
    (obs_dim, act_dim): (usize, usize),
    ppo: &PpoConfig,
    adam_t: u64,
) -> Result<(ActorCritic, PpoLearner), StoreError> {
    let weights = ckpt.file(WEIGHTS)?;
    let tensors = candle_core::safetensors::load(&weights, &Device::Cpu)
        .map_err(|e| invalid(&weights, e.to_string()))?;
    let get = |name: &str| -> Result<Vec<f32>, StoreError> {
        let t = tensors.get(name).ok_or_else(|| invalid(&weights, format!("no tensor '{name}'")))?;
        let v = t
            .flatten_all()
            .and_then(|t| t.to_vec1::<f32>())
            .map_err(|e| invalid(&weights, format!("{name}: {e}")))?;
        match v.iter().find(|x| !x.is_finite()) {
            Some(x) => {
                Err(invalid(&weights, format!("tensor '{name}' holds {x}: the weights are not usable")))
            }
            None => Ok(v),
        }
    };
    let mut policy = ActorCritic::new(obs_dim, act_dim, &ppo.hidden, &mut rand::rng());
    let params = get("params")?;
    if params.len() != policy.params.len() {
        return Err(invalid(
            &weights,
            format!(
                "{} parameters, but a {}-{:?}-{} actor-critic has {}",
                params.len(),
                obs_dim,
                ppo.hidden,
                act_dim,
                policy.params.len()
            ),
        ));
    }
    policy.params = params;
    let mut learner = PpoLearner::new(ppo.clone(), &policy);
    let (m, v) = (get("adam.m")?, get("adam.v")?);
    if m.len() != policy.params.len() || v.len() != policy.params.len() {
        return Err(invalid(&weights, "optimizer moments have the wrong length"));
    }
    learner.adam = Adam { m, v, t: adam_t, ..Adam::new(0) };
    Ok((policy, learner))
}

/// Loads the controller training run in `dir` (a `schrl control train` run), ready to
/// continue training or to act.
pub fn load(dir: &Path) -> Result<ControlTrainer, StoreError> {
    load_from(&Checkpoint::open(dir, RunKind::Controller)?)
}

/// Loads only the deployable controller of the controller run in `dir`.
pub fn load_controller(dir: &Path) -> Result<Controller, StoreError> {
    Ok(load(dir)?.controller())
}

/// The file in a `schrl train` run directory recording which of its general
/// controllers the joint phase started from (written only by runs that check them).
pub const GENERAL_CHOICE: &str = "general.json";
/// The directory in a run of its (first) general controller.
pub const GENERAL: &str = "general";

/// One general controller a run trained: its directory (in the run), seed and check.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GeneralTry {
    /// Directory name in the run: `general`, then `general-2`, `general-3`, …
    pub dir: String,
    /// Its training seed.
    pub seed: u64,
    /// Fraction of the check's random goals it reached.
    pub success_rate: f64,
}

/// What [`GENERAL_CHOICE`] holds: every general controller a run trained, in order,
/// and which one it kept.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GeneralChoice {
    /// The controllers trained, in order.
    pub tries: Vec<GeneralTry>,
    /// Index into `tries` of the one the joint phase started from.
    pub kept: usize,
}

/// Writes `choice` into the run directory `run_dir` (atomically).
pub fn save_general_choice(run_dir: &Path, choice: &GeneralChoice) -> Result<(), StoreError> {
    let path = run_dir.join(GENERAL_CHOICE);
    let text = serde_json::to_vec_pretty(choice).map_err(|e| invalid(&path, e.to_string()))?;
    super::write_atomic(&path, &text)
}

/// The [`GeneralChoice`] of the run in `run_dir`; `None` for a run that trained one
/// general controller without checking it, or was given one.
pub fn load_general_choice(run_dir: &Path) -> Result<Option<GeneralChoice>, StoreError> {
    let path = run_dir.join(GENERAL_CHOICE);
    let text = match std::fs::read_to_string(&path) {
        Ok(t) => t,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(e) => return Err(super::io(&path, e)),
    };
    let choice: GeneralChoice = serde_json::from_str(&text).map_err(|e| invalid(&path, e.to_string()))?;
    if choice.kept >= choice.tries.len() {
        return Err(invalid(&path, format!("kept try {} of {}", choice.kept + 1, choice.tries.len())));
    }
    Ok(Some(choice))
}

/// The general controller the joint phase of the run in `run_dir` started from: the
/// one its [`GENERAL_CHOICE`] kept, else its [`GENERAL`] directory.
pub fn kept_general_dir(run_dir: &Path) -> Result<std::path::PathBuf, StoreError> {
    Ok(match load_general_choice(run_dir)? {
        Some(c) => run_dir.join(&c.tries[c.kept].dir),
        None => run_dir.join(GENERAL),
    })
}
