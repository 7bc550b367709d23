//! Many environments stepped together, each seeded from one seed.

use rayon::prelude::*;

use crate::env::{Env, EnvError, Step};
use crate::map::Map;
use crate::{Robot, make_env};

/// The seed of environment `i` of a batch seeded with `seed` (SplitMix64), so that
/// batches of different sizes share their first environments' streams.
pub fn member_seed(seed: u64, i: usize) -> u64 {
    let mut z = seed.wrapping_add((i as u64 + 1).wrapping_mul(0x9E37_79B9_7F4A_7C15));
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// N environments of one robot, stepped together: in order on the calling thread, or,
/// for a robot whose step is heavy ([`Robot::steps_in_parallel`]), each on one of
/// rayon's threads. Either way every environment owns its state and random stream, so
/// the results are the same, bit for bit, whatever the thread count.
pub struct VecEnv {
    envs: Vec<Box<dyn Env>>,
    obs_dim: usize,
    act_dim: usize,
    parallel: bool,
}

impl VecEnv {
    /// `n` environments of `robot` on `map`, reset with seeds derived from `seed`.
    pub fn new(robot: Robot, map: Map, n: usize, seed: u64) -> Result<Self, EnvError> {
        let envs = (0..n).map(|_| make_env(robot, map.clone())).collect::<Result<Vec<_>, _>>()?;
        let obs_dim = envs.first().map_or(0, |e| e.observation_space().dim());
        let act_dim = envs.first().map_or(0, |e| e.action_space().dim());
        let mut v = Self { envs, obs_dim, act_dim, parallel: robot.steps_in_parallel() };
        let mut obs = vec![0.0; n * obs_dim];
        v.reset_all(seed, &mut obs)?;
        Ok(v)
    }

    /// Ends every environment's observations with its track offset, or not
    /// ([`Env::set_track_observation`]); [`VecEnv::obs_dim`] follows. Observe or reset
    /// before stepping: observations written before are of the old length.
    pub fn set_track_observation(&mut self, on: bool) {
        for e in &mut self.envs {
            e.set_track_observation(on);
        }
        self.obs_dim = self.envs.first().map_or(0, |e| e.observation_space().dim());
    }

    /// Number of environments.
    pub fn len(&self) -> usize {
        self.envs.len()
    }

    /// `true` if there are none.
    pub fn is_empty(&self) -> bool {
        self.envs.is_empty()
    }

    /// Observation length of one environment.
    pub fn obs_dim(&self) -> usize {
        self.obs_dim
    }

    /// Action length of one environment.
    pub fn act_dim(&self) -> usize {
        self.act_dim
    }

    /// The environments.
    pub fn envs(&self) -> &[Box<dyn Env>] {
        &self.envs
    }

    /// Mutable access to the environments (to set goals, reset one, ...).
    pub fn envs_mut(&mut self) -> &mut [Box<dyn Env>] {
        &mut self.envs
    }

    /// Resets every environment (`i` with [`member_seed`]`(seed, i)`), writing
    /// observations into `obs` (`n × obs_dim`).
    pub fn reset_all(&mut self, seed: u64, obs: &mut [f64]) -> Result<(), EnvError> {
        self.check(obs.len(), self.obs_dim, "observation")?;
        let reset = |(i, (env, o)): (usize, (&mut Box<dyn Env>, &mut [f64]))| {
            env.reset_into(member_seed(seed, i), None, o).map(|_| ())
        };
        if self.parallel {
            self.envs.par_iter_mut().zip(obs.par_chunks_mut(self.obs_dim)).enumerate().try_for_each(reset)
        } else {
            self.envs.iter_mut().zip(obs.chunks_mut(self.obs_dim)).enumerate().try_for_each(reset)
        }
    }

    /// Steps every environment with its action (`actions`: `n × act_dim`), writing
    /// observations (`n × obs_dim`) and step reports.
    pub fn step_all(&mut self, actions: &[f64], obs: &mut [f64], steps: &mut [Step]) -> Result<(), EnvError> {
        self.check(actions.len(), self.act_dim, "action")?;
        self.check(obs.len(), self.obs_dim, "observation")?;
        if steps.len() != self.envs.len() {
            return Err(EnvError::ObservationLength { expected: self.envs.len(), got: steps.len() });
        }
        let (ad, od) = (self.act_dim, self.obs_dim);
        let step = |env: &mut Box<dyn Env>, a: &[f64], o: &mut [f64], s: &mut Step| {
            *s = env.step_into(a, o)?;
            Ok(())
        };
        if self.parallel {
            self.envs
                .par_iter_mut()
                .zip(actions.par_chunks(ad))
                .zip(obs.par_chunks_mut(od))
                .zip(steps.par_iter_mut())
                .try_for_each(|(((env, a), o), s)| step(env, a, o, s))
        } else {
            self.envs
                .iter_mut()
                .zip(actions.chunks(ad))
                .zip(obs.chunks_mut(od))
                .zip(steps)
                .try_for_each(|(((env, a), o), s)| step(env, a, o, s))
        }
    }

    fn check(&self, len: usize, per: usize, what: &'static str) -> Result<(), EnvError> {
        let expected = per * self.envs.len();
        if len == expected {
            return Ok(());
        }
        Err(match what {
            "action" => EnvError::ActionLength {
                robot: self.envs.first().map_or("?", |e| e.robot_name()),
                expected,
                got: len,
            },
            _ => EnvError::ObservationLength { expected, got: len },
        })
    }
}
