//! Flat episodes: how a policy without a planner (TLTL, CRM, DHRM) sees a task, and how
//! its episodes are judged and evaluated.
//!
//! * *Observation*: the robot's own observation with its goal held at the map's
//!   origin (so the goal entries read the origin in the body frame), then the robot's
//!   position, then the clock `t / H`. The clock makes every task here Markov: the
//!   specs read waypoint indices, and Signal's counter is a function of the index.
//! * *Waypoint indices → environment steps*: an episode lasts the task's step limit
//!   `H`; the spec's waypoint `i` (of `T`) is the robot's position after step
//!   `⌊i·H/T⌋`, and regions to avoid are checked on every step in between, exactly as
//!   for executed plans ([`ExecutionSpec`]). An episode that ends early (a collision,
//!   a fall, a reward machine's terminal state) is read as the robot staying where it
//!   stopped ([`ExecutionSpec::score`]).
//! * *Verdict*: an episode satisfies the task when it neither collides nor falls and
//!   its score is positive. Its steps to reach: the step of waypoint
//!   `steps_to_reach_at` for tasks that set it (Loop), else of the first waypoint index
//!   from which the spec holds with the robot staying there.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};
use sim::Env;

use super::reward_machine::Labels;
use crate::control::Controller;
use crate::control::policy::PolicyCache;
use crate::run::RunError;
use crate::run::evaluate::{GroupTally, TaskEval};
use crate::run::execute::{Execution, Outcome, task_env};
use crate::task::Task;
use crate::task::along::ExecutionSpec;

/// The episodes that ended in one logged stretch of training (a PPO update's rollout,
/// a CRM chunk): what the training curves plot.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct EpisodeSummary {
    /// Environment steps done by the end of the stretch.
    pub env_steps: usize,
    /// Episodes that ended in it.
    pub episodes: usize,
    /// Their mean spec score.
    pub score: Option<f64>,
    /// The fraction of them that satisfied the task.
    pub satisfaction: Option<f64>,
}

/// Episodes as they end: their scores and how many satisfied the task.
#[derive(Clone, Debug, Default, PartialEq)]
pub(crate) struct Ended {
    pub scores: Vec<f64>,
    pub satisfied: usize,
}

impl Ended {
    /// Counts an episode that ended with `score`, satisfying the task when it did not
    /// end in failure (`failed`: a collision or a fall) and the score is positive.
    pub fn push(&mut self, score: f64, failed: bool) {
        self.scores.push(score);
        self.satisfied += usize::from(!failed && score > 0.0);
    }

    /// The summary after `env_steps` steps.
    pub fn summary(&self, env_steps: usize) -> EpisodeSummary {
        let k = self.scores.len();
        EpisodeSummary {
            env_steps,
            episodes: k,
            score: (k > 0).then(|| self.scores.iter().sum::<f64>() / k as f64),
            satisfaction: (k > 0).then(|| self.satisfied as f64 / k as f64),
        }
    }
}

/// How a flat policy acts in [`evaluate`].
pub trait FlatDriver {
    /// A group of `n` episodes begins.
    fn begin(&mut self, _n: usize) {}

    /// Actions for `n` flat observations (`raw`, `n × flat dim`) into `actions`.
    fn act(&mut self, raw: &[f64], n: usize, actions: &mut [f64]);

    /// After episode `i` stepped, with the events then true; `true` ends the episode
    /// (e.g. its reward machine reached a terminal state).
    fn after_step(&mut self, _i: usize, _labels: &Labels) -> bool {
        false
    }
}

/// A PPO policy's mean actions (TLTL).
pub struct MeanPolicy<'a> {
    controller: &'a Controller,
    cache: PolicyCache,
}

impl<'a> MeanPolicy<'a> {
    /// Acts with `controller`'s mean actions.
    pub fn new(controller: &'a Controller) -> Self {
        Self { controller, cache: PolicyCache::default() }
    }
}

impl FlatDriver for MeanPolicy<'_> {
    fn act(&mut self, raw: &[f64], n: usize, actions: &mut [f64]) {
        self.controller.act(raw, n, &mut self.cache, actions);
    }
}

/// The flat observation's length for a robot whose own observation has `robot_obs`
/// numbers and whose position `dim`.
pub fn flat_obs_dim(robot_obs: usize, dim: usize) -> usize {
    robot_obs + dim + 1
}

/// Writes `env`'s flat observation (module docs) into `out`, with `horizon` the
/// episode length.
pub(crate) fn observe(env: &dyn Env, horizon: usize, out: &mut [f64]) {
    let od = env.observation_space().dim();
    env.observe(&mut out[..od]);
    let p = env.position();
    out[od..od + p.len()].copy_from_slice(p);
    out[od + p.len()] = env.steps() as f64 / horizon.max(1) as f64;
}

/// Puts `env` at a fresh start of `task`, its goal at the origin, and writes its flat
/// observation. Returns the start.
pub(crate) fn begin(
    env: &mut dyn Env,
    task: &Task,
    rng: &mut ChaCha8Rng,
    out: &mut [f64],
) -> Result<Vec<f64>, RunError> {
    let start = task.sample_start(rng);
    let od = env.observation_space().dim();
    env.set_max_steps(task.step_limit);
    env.reset_into(rng.random(), Some(&start), &mut out[..od])?;
    env.set_goal(&vec![0.0; start.len()])?;
    observe(env, task.step_limit, out);
    Ok(start)
}

/// The environment steps at which the spec reads waypoints `1..=T` of an episode of
/// `task` (module docs).
pub fn sample_steps(task: &Task) -> Vec<usize> {
    let (t, h) = (task.steps.max(1), task.step_limit);
    (1..=task.steps).map(|i| i * h / t).collect()
}

/// The waypoints the spec reads from `trajectory` (every position, the start first):
/// the start, then the positions at [`sample_steps`] the episode lasted to.
pub(crate) fn sampled(trajectory: &[Vec<f64>], at: &[usize]) -> (Vec<Vec<f64>>, Vec<usize>) {
    let at: Vec<usize> = at.iter().copied().filter(|k| *k < trajectory.len()).collect();
    let path = std::iter::once(0).chain(at.iter().copied()).map(|k| trajectory[k].clone()).collect();
    (path, at)
}

/// The spec score of a flat episode's `trajectory` (module docs).
pub fn episode_score(spec: &ExecutionSpec, at: &[usize], trajectory: &[Vec<f64>]) -> f64 {
    let (path, at) = sampled(trajectory, at);
    spec.score(&path, trajectory, &at)
}

/// Evaluates a flat policy on `task`: `groups × per_group` episodes from random
/// starts, acting as `driver` says, judged as in training (module docs).
/// Each episode is an [`Execution`] with no plan (`planned` empty) whose `executed`
/// path is the positions the spec read.
pub fn evaluate(
    task: &Task,
    driver: &mut dyn FlatDriver,
    (groups, per_group): (usize, usize),
    seed: u64,
) -> Result<TaskEval, RunError> {
    let spec = task.execution_spec();
    let at = sample_steps(task);
    let horizon = task.step_limit;
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut eval = TaskEval::empty();
    for _ in 0..groups {
        let mut envs =
            (0..per_group).map(|_| task_env(task.robot, task, false)).collect::<Result<Vec<_>, _>>()?;
        let od = flat_obs_dim(envs[0].observation_space().dim(), task.map.dim());
        let ad = envs[0].action_space().dim();
        driver.begin(per_group);
        let mut raw = vec![0.0; per_group * od];
        let mut trajectories = Vec::with_capacity(per_group);
        let mut headings = Vec::with_capacity(per_group);
        for (env, o) in envs.iter_mut().zip(raw.chunks_mut(od)) {
            trajectories.push(vec![begin(env.as_mut(), task, &mut rng, o)?]);
            headings.push(vec![env.heading()]);
        }
        let mut outcome = vec![None; per_group];
        let mut actions = vec![0.0; per_group * ad];
        while outcome.iter().any(Option::is_none) {
            driver.act(&raw, per_group, &mut actions);
            for (i, (env, o)) in envs.iter_mut().zip(raw.chunks_mut(od)).enumerate() {
                if outcome[i].is_some() {
                    continue;
                }
                let robot_od = env.observation_space().dim();
                let s = env.step_into(&actions[i * ad..(i + 1) * ad], &mut o[..robot_od])?;
                trajectories[i].push(env.position().to_vec());
                headings[i].push(env.heading());
                observe(env.as_ref(), horizon, o);
                let index = env.steps() as f64 * task.steps as f64 / horizon.max(1) as f64;
                let ended = driver.after_step(i, &Labels::of(task, env.position(), s.collided, index));
                if s.collided {
                    outcome[i] = Some(Outcome::Collided);
                } else if s.fell {
                    outcome[i] = Some(Outcome::Fell);
                } else if ended || env.steps() >= horizon {
                    outcome[i] = Some(Outcome::Completed);
                }
            }
        }
        let mut tally = GroupTally::default();
        for ((trajectory, headings), outcome) in trajectories.into_iter().zip(headings).zip(outcome) {
            let outcome = outcome.expect("every episode ended");
            let (path, reached_at) = sampled(&trajectory, &at);
            let judged = spec.judge_stopped(&path, &trajectory, &reached_at);
            let run = Execution {
                planned: vec![],
                executed: path,
                steps: trajectory.len() - 1,
                trajectory,
                headings,
                outcome,
                reached_at,
                control_return: 0.0,
                robustness: judged.robustness,
                entered: judged.entered,
            };
            eval.tally(&mut tally, run, |r| steps_to_reach(&spec, task, &at, r) as f64);
        }
        eval.end_group(tally);
    }
    Ok(eval)
}

/// Steps to reach of a satisfying flat episode (module docs); an episode that ended
/// early is read as staying where it stopped.
pub(crate) fn steps_to_reach(spec: &ExecutionSpec, task: &Task, at: &[usize], run: &Execution) -> usize {
    let end = run.trajectory.len() - 1;
    if let Some(k) = task.steps_to_reach_at {
        return at[k.clamp(1, at.len()) - 1].min(end);
    }
    (1..=at.len())
        .map(|i| at[i - 1].min(end))
        .find(|&k| episode_score(spec, at, &run.trajectory[..=k]) > 0.0)
        .unwrap_or(end)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::task::TaskKind;

    #[test]
    fn waypoints_are_read_at_equal_steps_up_to_the_step_limit() {
        let task = Task::point(TaskKind::Seq);
        assert_eq!(sample_steps(&task), vec![125, 250, 375, 500, 625, 750, 875, 1000]);
    }

    #[test]
    fn a_trajectory_visiting_the_goals_in_order_scores_positive_and_stopping_short_does_not() {
        let task = Task::point(TaskKind::Seq);
        let spec = task.execution_spec();
        let at = sample_steps(&task);
        // Straight lines between the goal centres would cross walls; score only reads
        // the sampled positions and the walls' clearance there, and these positions
        // sit in open space.
        let goals: Vec<Vec<f64>> = task.goals.iter().map(|g| g.center.clone()).collect();
        let mut trajectory = vec![vec![1.5, -1.5]];
        for k in 1..=1000 {
            let i = at.iter().position(|&s| s >= k).unwrap();
            trajectory.push(goals[(i / 2).min(3)].clone());
        }
        assert!(episode_score(&spec, &at, &trajectory) > 0.0);
        // Ended (say, by a collision) at step 300: the rest is read as staying there.
        let short = &trajectory[..=300];
        assert!(episode_score(&spec, &at, short) < 0.0);
    }
}
