//! A replay buffer for off-policy learning with a reward machine: each entry is one
//! transition of the environment's flat observation together with a machine state
//! before and after, so CRM's counterfactual experiences (one per machine state for
//! every real step) share nothing but their observations.

use rand::Rng;

/// A ring buffer of transitions `(o, u, a, r, o', u', done)`, oldest overwritten first.
#[derive(Clone, Debug, PartialEq)]
pub struct ReplayBuffer {
    /// Entries it holds at most.
    pub capacity: usize,
    /// Flat-observation length.
    pub obs_dim: usize,
    /// Action length.
    pub act_dim: usize,
    /// Observations, `capacity × obs_dim` once full.
    pub obs: Vec<f32>,
    /// Machine states before the step.
    pub states: Vec<u32>,
    /// Actions taken.
    pub actions: Vec<f32>,
    /// Rewards.
    pub rewards: Vec<f32>,
    /// Observations after the step.
    pub next_obs: Vec<f32>,
    /// Machine states after the step.
    pub next_states: Vec<u32>,
    /// Whether the step ended the episode (no bootstrap from `o'`).
    pub dones: Vec<bool>,
    /// Where the next entry goes once full.
    pub next: usize,
}

/// One transition, borrowed, to push.
pub struct Transition<'a> {
    /// The flat observation before the step.
    pub obs: &'a [f64],
    /// The machine state before.
    pub state: usize,
    /// The action.
    pub action: &'a [f64],
    /// The reward.
    pub reward: f64,
    /// The flat observation after.
    pub next_obs: &'a [f64],
    /// The machine state after.
    pub next_state: usize,
    /// The episode ended.
    pub done: bool,
}

impl ReplayBuffer {
    /// An empty buffer.
    pub fn new(capacity: usize, obs_dim: usize, act_dim: usize) -> Self {
        Self {
            capacity: capacity.max(1),
            obs_dim,
            act_dim,
            obs: vec![],
            states: vec![],
            actions: vec![],
            rewards: vec![],
            next_obs: vec![],
            next_states: vec![],
            dones: vec![],
            next: 0,
        }
    }

    /// Entries held.
    pub fn len(&self) -> usize {
        self.rewards.len()
    }

    /// `true` when it holds nothing.
    pub fn is_empty(&self) -> bool {
        self.rewards.is_empty()
    }

    /// Adds `t`, overwriting the oldest entry once full.
    pub fn push(&mut self, t: &Transition<'_>) {
        let f = |v: &[f64]| v.iter().map(|x| *x as f32).collect::<Vec<f32>>();
        let (od, ad) = (self.obs_dim, self.act_dim);
        if self.len() < self.capacity {
            self.obs.extend(f(t.obs));
            self.states.push(t.state as u32);
            self.actions.extend(f(t.action));
            self.rewards.push(t.reward as f32);
            self.next_obs.extend(f(t.next_obs));
            self.next_states.push(t.next_state as u32);
            self.dones.push(t.done);
            return;
        }
        let i = self.next;
        self.obs[i * od..(i + 1) * od].copy_from_slice(&f(t.obs));
        self.states[i] = t.state as u32;
        self.actions[i * ad..(i + 1) * ad].copy_from_slice(&f(t.action));
        self.rewards[i] = t.reward as f32;
        self.next_obs[i * od..(i + 1) * od].copy_from_slice(&f(t.next_obs));
        self.next_states[i] = t.next_state as u32;
        self.dones[i] = t.done;
        self.next = (i + 1) % self.capacity;
    }

    /// `n` entry indices drawn uniformly with replacement.
    pub fn sample(&self, n: usize, rng: &mut impl Rng) -> Vec<usize> {
        (0..n).map(|_| rng.random_range(0..self.len())).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_full_buffer_overwrites_its_oldest_entry() {
        let mut b = ReplayBuffer::new(2, 1, 1);
        for k in 0..3 {
            let x = [k as f64];
            b.push(&Transition {
                obs: &x,
                state: k,
                action: &x,
                reward: k as f64,
                next_obs: &x,
                next_state: k,
                done: false,
            });
        }
        assert_eq!(b.len(), 2);
        assert_eq!(b.rewards, [2.0, 1.0]);
        assert_eq!(b.states, [2, 1]);
        assert_eq!(b.next, 1);
    }
}
