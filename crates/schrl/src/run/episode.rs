//! The episode loop: robots driven through their waypoints in lockstep until each run
//! ends. Joint training, task evaluation and controller evaluation all run here; what
//! differs between them is only how actions are chosen ([`Driver`]).
//!
//! (Controller training is not episodic: PPO collects fixed-length rollouts over
//! environments that reset themselves to new random goals, in
//! [`crate::control::trainer`].)

use sim::{Env, EnvError};

use super::execute::{Dispatch, WaypointDispatcher};
use crate::control::Controller;
use crate::control::policy::PolicyCache;
use crate::task::Follow;

/// How the loop's actions are chosen, and what a learner records of each step.
pub trait Driver {
    /// Actions for all `n` environments (`raw`: their raw observations, `n × obs_dim`;
    /// `live`: which runs are still going) into `actions` (`n × act_dim`).
    fn act(&mut self, raw: &[f64], live: &[bool], actions: &mut [f64]);

    /// After every live environment stepped: each one's reward (0 for runs already
    /// over) and whether its run ended in this step.
    fn after_step(&mut self, _live: &[bool], _rewards: &mut [f64], _ended: &[bool]) {}
}

/// A trained controller's mean actions: how deployed runs and evaluations drive.
pub struct MeanActions<'a> {
    controller: &'a Controller,
    cache: PolicyCache,
}

impl<'a> MeanActions<'a> {
    /// Drives with `controller`.
    pub fn new(controller: &'a Controller) -> Self {
        Self { controller, cache: PolicyCache::default() }
    }
}

impl Driver for MeanActions<'_> {
    fn act(&mut self, raw: &[f64], live: &[bool], actions: &mut [f64]) {
        self.controller.act(raw, live.len(), &mut self.cache, actions);
    }
}

/// One run as the loop saw it.
#[derive(Clone, Debug)]
pub struct Episode {
    /// Its waypoints, progress and outcome.
    pub dispatcher: WaypointDispatcher,
    /// Every position, the start first.
    pub trajectory: Vec<Vec<f64>>,
    /// The robot's heading (yaw, rad) at each of those positions.
    pub headings: Vec<f64>,
    /// Sum of the environment's rewards.
    pub control_return: f64,
}

/// Drives `envs[i]` through `dispatchers[i]` until every run is over, each robot's goal
/// chosen by `follow` after every step. Each environment must have been started on its
/// run (see [`super::execute::start_run`]) with its observation in `raw[i × obs_dim ..]`;
/// `raw` holds the last observations afterwards.
pub fn drive(
    envs: &mut [Box<dyn Env>],
    dispatchers: Vec<WaypointDispatcher>,
    follow: Follow,
    raw: &mut [f64],
    driver: &mut dyn Driver,
) -> Result<Vec<Episode>, EnvError> {
    let n = dispatchers.len();
    let (od, ad) = match envs.first() {
        Some(e) => (e.observation_space().dim(), e.action_space().dim()),
        None => return Ok(vec![]),
    };
    let mut runs: Vec<Episode> = dispatchers
        .into_iter()
        .zip(envs.iter())
        .map(|(dispatcher, env)| Episode {
            trajectory: vec![dispatcher.executed_path()[0].clone()],
            headings: vec![env.heading()],
            dispatcher,
            control_return: 0.0,
        })
        .collect();
    let mut live: Vec<bool> = runs.iter().map(|r| r.dispatcher.outcome().is_none()).collect();
    let mut actions = vec![0.0; n * ad];
    let mut rewards = vec![0.0; n];
    let mut ended = vec![false; n];
    while live.iter().any(|l| *l) {
        driver.act(raw, &live, &mut actions);
        let before = live.clone();
        for (i, env) in envs.iter_mut().enumerate().take(n) {
            ended[i] = false;
            rewards[i] = 0.0;
            if !live[i] {
                continue;
            }
            let obs = &mut raw[i * od..(i + 1) * od];
            let step = env.step_into(&actions[i * ad..(i + 1) * ad], obs)?;
            let run = &mut runs[i];
            run.trajectory.push(env.position().to_vec());
            run.headings.push(env.heading());
            run.control_return += step.reward;
            rewards[i] = step.reward;
            match run.dispatcher.after_step(&step, env.position()) {
                Dispatch::Continue if follow == Follow::Waypoints => {}
                Dispatch::Continue | Dispatch::NewGoal(_) => {
                    let goal =
                        run.dispatcher.target(follow, env.position()).expect("a run going on has a goal");
                    env.set_goal(&goal)?;
                    env.observe(obs);
                }
                Dispatch::Done(_) => {
                    live[i] = false;
                    ended[i] = true;
                }
            }
        }
        driver.after_step(&before, &mut rewards, &ended);
    }
    Ok(runs)
}
