//! CRM and DHRM runs (`schrl baseline train --algo crm|dhrm`): `crm.safetensors`
//! (actor, critics, their targets, both Adams' moments, and the replay buffer; DHRM
//! adds the meta-controller's Q-network, its target, Adam moments and replay) and
//! `crm.json`: the settings, counters, observation statistics, the random stream, the
//! environment's state, the episode so far, the machine's state (DHRM: and the option
//! being run). Together they resume a run exactly.

use std::collections::HashMap;
use std::path::Path;

use candle_core::{DType, Device, Tensor};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use super::{Checkpoint, RunKind, SaveFiles, StoreError, check_format, invalid};
use crate::baseline::crm::{CrmSettings, CrmTrainer};
use crate::baseline::dhrm::OptionRun;
use crate::baseline::replay::ReplayBuffer;
use crate::baseline::td3::Td3;
use crate::control::normalize::RunningMeanStd;

const WEIGHTS: &str = "crm.safetensors";
const STATE: &str = "crm.json";
/// The layout of `crm.json` this build writes and reads.
const STATE_FORMAT: u32 = 1;

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct State {
    format: u32,
    settings: CrmSettings,
    td3_updates: u64,
    actor_adam_t: u64,
    critic_adam_t: u64,
    buffer_next: usize,
    obs_rms: RunningMeanStd,
    rng: ChaCha8Rng,
    env_state: String,
    trajectory: Vec<Vec<f64>>,
    raw_obs: Vec<f64>,
    machine_state: usize,
    episode_return: f64,
    steps: usize,
    chunks: usize,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    meta: Option<MetaState>,
}

/// DHRM's counters and the option being run.
#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct MetaState {
    updates: u64,
    adam_t: u64,
    buffer_next: usize,
    current: OptionRun,
}

/// The replay buffer `b`'s tensors, named `<prefix>.obs` and so on.
fn buffer_tensors(
    prefix: &str,
    b: &ReplayBuffer,
    m: &mut HashMap<String, Tensor>,
) -> candle_core::Result<()> {
    let cpu = &Device::Cpu;
    for (name, v) in
        [("obs", &b.obs), ("actions", &b.actions), ("rewards", &b.rewards), ("next_obs", &b.next_obs)]
    {
        m.insert(format!("{prefix}.{name}"), Tensor::from_slice(v, v.len(), cpu)?);
    }
    m.insert(format!("{prefix}.states"), Tensor::from_slice(&b.states, b.states.len(), cpu)?);
    m.insert(format!("{prefix}.next_states"), Tensor::from_slice(&b.next_states, b.next_states.len(), cpu)?);
    let dones: Vec<u8> = b.dones.iter().map(|d| u8::from(*d)).collect();
    m.insert(format!("{prefix}.dones"), Tensor::from_slice(&dones, dones.len(), cpu)?);
    Ok(())
}

/// The networks' `f32` tensors of the weights file, by name.
fn floats(t: &CrmTrainer) -> [(&'static str, &[f32]); 8] {
    let d = &t.td3;
    [
        ("actor", &d.actor_params),
        ("actor.target", &d.actor_target),
        ("critic", &d.critic_params),
        ("critic.target", &d.critic_target),
        ("actor.adam.m", &d.actor_adam.m),
        ("actor.adam.v", &d.actor_adam.v),
        ("critic.adam.m", &d.critic_adam.m),
        ("critic.adam.v", &d.critic_adam.v),
    ]
}

/// Writes the CRM trainer `t` into a save.
pub fn save_into(files: &mut SaveFiles, t: &CrmTrainer) -> Result<(), StoreError> {
    let cpu = &Device::Cpu;
    let tensors = (|| -> candle_core::Result<HashMap<String, Tensor>> {
        let mut m = HashMap::new();
        for (name, v) in floats(t) {
            m.insert(name.to_string(), Tensor::from_slice(v, v.len(), cpu)?);
        }
        buffer_tensors("replay", &t.buffer, &mut m)?;
        if let Some(h) = &t.hierarchy {
            for (name, v) in [
                ("meta.q", &h.q_params),
                ("meta.q.target", &h.q_target),
                ("meta.adam.m", &h.adam.m),
                ("meta.adam.v", &h.adam.v),
            ] {
                m.insert(name.to_string(), Tensor::from_slice(v, v.len(), cpu)?);
            }
            buffer_tensors("meta.replay", &h.buffer, &mut m)?;
        }
        Ok(m)
    })();
    files.write_with(WEIGHTS, |p| tensors.and_then(|t| candle_core::safetensors::save(&t, p)))?;
    let state = State {
        format: STATE_FORMAT,
        settings: t.settings.clone(),
        td3_updates: t.td3.updates,
        actor_adam_t: t.td3.actor_adam.t,
        critic_adam_t: t.td3.critic_adam.t,
        buffer_next: t.buffer.next,
        obs_rms: t.obs_rms.clone(),
        rng: t.rng.clone(),
        env_state: t.env.save_state(),
        trajectory: t.trajectory.clone(),
        raw_obs: t.raw_obs.clone(),
        machine_state: t.state,
        episode_return: t.episode_return,
        steps: t.steps,
        chunks: t.chunks,
        meta: t.hierarchy.as_ref().map(|h| MetaState {
            updates: h.updates,
            adam_t: h.adam.t,
            buffer_next: h.buffer.next,
            current: h.current.clone(),
        }),
    };
    files.json(STATE, &state)
}

/// Restores the CRM trainer checkpointed in `ckpt`.
pub fn load_from(ckpt: &Checkpoint) -> Result<CrmTrainer, StoreError> {
    let state: State = ckpt.json(STATE)?;
    let path = ckpt.path_of(STATE);
    check_format(&path, state.format, STATE_FORMAT, "the CRM state")?;
    // A fresh trainer gives the shapes every saved tensor must have.
    let fresh = CrmTrainer::new(state.settings.clone()).map_err(|e| invalid(&path, e.to_string()))?;
    let weights = ckpt.file(WEIGHTS)?;
    let tensors = candle_core::safetensors::load(&weights, &Device::Cpu)
        .map_err(|e| invalid(&weights, e.to_string()))?;
    let get = |name: &str, dtype: DType| -> Result<Tensor, StoreError> {
        let t = tensors.get(name).ok_or_else(|| invalid(&weights, format!("no tensor '{name}'")))?;
        t.to_dtype(dtype).map_err(|e| invalid(&weights, format!("{name}: {e}")))
    };
    let f32s = |name: &str, len: Option<usize>| -> Result<Vec<f32>, StoreError> {
        let v: Vec<f32> =
            get(name, DType::F32)?.to_vec1().map_err(|e| invalid(&weights, format!("{name}: {e}")))?;
        if len.is_some_and(|l| l != v.len()) {
            return Err(invalid(
                &weights,
                format!("tensor '{name}' has {} numbers, expected {len:?}", v.len()),
            ));
        }
        if v.iter().any(|x| !x.is_finite()) {
            return Err(invalid(&weights, format!("tensor '{name}' holds a non-finite number")));
        }
        Ok(v)
    };
    let u32s = |name: &str| -> Result<Vec<u32>, StoreError> {
        get(name, DType::U32)?.to_vec1().map_err(|e| invalid(&weights, format!("{name}: {e}")))
    };
    let d = &fresh.td3;
    let (na, nc) = (d.actor_params.len(), d.critic_params.len());
    let mut td3: Td3 = d.clone();
    td3.actor_params = f32s("actor", Some(na))?;
    td3.actor_target = f32s("actor.target", Some(na))?;
    td3.critic_params = f32s("critic", Some(nc))?;
    td3.critic_target = f32s("critic.target", Some(nc))?;
    td3.actor_adam.m = f32s("actor.adam.m", Some(na))?;
    td3.actor_adam.v = f32s("actor.adam.v", Some(na))?;
    td3.critic_adam.m = f32s("critic.adam.m", Some(nc))?;
    td3.critic_adam.v = f32s("critic.adam.v", Some(nc))?;
    td3.actor_adam.t = state.actor_adam_t;
    td3.critic_adam.t = state.critic_adam_t;
    td3.updates = state.td3_updates;
    // Every buffer's tensors must agree with each other and index only `contexts`.
    let load_buffer = |prefix: &str, fresh: &ReplayBuffer, next: usize, contexts: usize| {
        let mut buffer = fresh.clone();
        buffer.obs = f32s(&format!("{prefix}.obs"), None)?;
        buffer.actions = f32s(&format!("{prefix}.actions"), None)?;
        buffer.rewards = f32s(&format!("{prefix}.rewards"), None)?;
        buffer.next_obs = f32s(&format!("{prefix}.next_obs"), None)?;
        buffer.states = u32s(&format!("{prefix}.states"))?;
        buffer.next_states = u32s(&format!("{prefix}.next_states"))?;
        let dones: Vec<u8> = get(&format!("{prefix}.dones"), DType::U8)?
            .to_vec1()
            .map_err(|e| invalid(&weights, format!("{prefix}.dones: {e}")))?;
        buffer.dones = dones.into_iter().map(|d| d != 0).collect();
        buffer.next = next;
        let n = buffer.rewards.len();
        let (od, ad) = (buffer.obs_dim, buffer.act_dim);
        let fits = n <= buffer.capacity
            && buffer.obs.len() == n * od
            && buffer.next_obs.len() == n * od
            && buffer.actions.len() == n * ad
            && [buffer.states.len(), buffer.next_states.len(), buffer.dones.len()].iter().all(|l| *l == n)
            && buffer.states.iter().chain(&buffer.next_states).all(|u| (*u as usize) < contexts)
            && buffer.next < buffer.capacity;
        if !fits {
            return Err(invalid(
                &weights,
                format!("the {prefix} buffer's tensors do not agree with each other or the task"),
            ));
        }
        Ok(buffer)
    };
    let m = fresh.machine.len();
    let contexts = fresh.hierarchy.as_ref().map_or(m, |h| h.len());
    let buffer = load_buffer("replay", &fresh.buffer, state.buffer_next, contexts)?;
    let hierarchy = match (fresh.hierarchy.clone(), state.meta) {
        (None, None) => None,
        (Some(mut h), Some(meta)) => {
            let nq = h.q_params.len();
            h.q_params = f32s("meta.q", Some(nq))?;
            h.q_target = f32s("meta.q.target", Some(nq))?;
            h.adam.m = f32s("meta.adam.m", Some(nq))?;
            h.adam.v = f32s("meta.adam.v", Some(nq))?;
            h.adam.t = meta.adam_t;
            h.updates = meta.updates;
            h.buffer = load_buffer("meta.replay", &h.buffer, meta.buffer_next, m)?;
            if h.buffer.actions.chunks(2).any(|a| a[0] as usize >= h.len()) {
                return Err(invalid(&weights, "the meta replay names an option the machine does not have"));
            }
            h.current = meta.current;
            Some(h)
        }
        _ => return Err(invalid(&path, "the settings and the saved state disagree on whether this is DHRM")),
    };
    CrmTrainer::restored(
        state.settings,
        td3,
        buffer,
        state.obs_rms,
        state.rng,
        &state.env_state,
        state.trajectory,
        state.raw_obs,
        (state.machine_state, state.episode_return),
        (state.steps, state.chunks),
        hierarchy,
    )
    .map_err(|e| invalid(&path, e.to_string()))
}

/// Loads the CRM run in `dir`.
pub fn load(dir: &Path) -> Result<CrmTrainer, StoreError> {
    load_from(&Checkpoint::open(dir, RunKind::Crm)?)
}
