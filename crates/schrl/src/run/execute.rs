//! Executing plans: the controller drives the robot through a path's waypoints, and
//! the task is judged on what the robot actually did.
//!
//! A run follows the waypoints in order: the environment's goal is the current
//! waypoint; on reaching it (the robot's reach radius) the next one becomes the goal.
//! The run ends when the last waypoint is reached (completed), on a collision, or at
//! the task's step limit. It satisfies the task when it completed (so its whole
//! trajectory was collision-free) and the spec holds on the *executed* path: the start
//! followed by the robot's positions at the moments it reached each waypoint, with
//! `safe` checked at those positions and regions to avoid on every step of the
//! trajectory ([`crate::task::along::ExecutionSpec`]). Steps to reach: environment
//! steps until the last waypoint was reached.

use serde::{Deserialize, Serialize};
use sim::{Env, Step};

use crate::task::along::{Entry, ExecutionSpec};
use crate::task::{Follow, GoalRegion, Reach, Task};

/// How a run ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum Outcome {
    /// Every waypoint was reached.
    Completed,
    /// The robot touched an obstacle.
    Collided,
    /// The robot fell over.
    Fell,
    /// The step limit ran out first.
    TimedOut,
}

/// What the dispatcher wants after a step.
#[derive(Clone, Debug, PartialEq)]
pub enum Dispatch {
    /// Keep driving to the current waypoint.
    Continue,
    /// The current waypoint was reached: drive to this one next.
    NewGoal(Vec<f64>),
    /// The run is over.
    Done(Outcome),
}

/// Hands a path's waypoints to the controller one at a time.
#[derive(Clone, Debug, PartialEq)]
pub struct WaypointDispatcher {
    waypoints: Vec<Vec<f64>>,
    next: usize,
    limit: usize,
    reached: Vec<Vec<f64>>,
    reached_at: Vec<usize>,
    outcome: Option<Outcome>,
    steps: usize,
    inside: Option<InsideGoals>,
}

/// [`Reach::InGoal`]'s rule: a waypoint counts reached within `radius` of it and
/// inside every goal `goals` lists for it.
#[derive(Clone, Debug, PartialEq)]
struct InsideGoals {
    radius: f64,
    /// Per waypoint, the goals that hold it ([`Task::goals_holding`]).
    goals: Vec<Vec<GoalRegion>>,
}

impl WaypointDispatcher {
    /// A run from `start` through `waypoints` (the path without its start) with at
    /// most `limit` environment steps.
    pub fn new(start: Vec<f64>, waypoints: Vec<Vec<f64>>, limit: usize) -> Self {
        let outcome = waypoints.is_empty().then_some(Outcome::Completed);
        Self {
            waypoints,
            next: 0,
            limit,
            reached: vec![start],
            reached_at: vec![],
            outcome,
            steps: 0,
            inside: None,
        }
    }

    /// The same run with [`Reach::InGoal`]: a waypoint counts reached only within
    /// `radius` of it (the environment's reach radius) and strictly inside every goal
    /// of `task` that holds it. The dispatcher then decides reaching itself; the
    /// environment's own reach (which pays its bonus, once per goal) no longer
    /// advances the run, so a robot within the radius but outside the goal keeps
    /// driving to the same waypoint.
    pub fn reaching_in_goals(self, radius: f64, task: &Task) -> Self {
        let goals = self.waypoints.iter().map(|w| task.goals_holding(w)).collect();
        Self { inside: Some(InsideGoals { radius, goals }), ..self }
    }

    /// The waypoint being driven to.
    pub fn current(&self) -> Option<&[f64]> {
        self.waypoints.get(self.next).map(|w| w.as_slice())
    }

    /// The planned segment being driven: from the waypoint before the current one (or
    /// the start) to the current one; `None` once done.
    pub fn segment(&self) -> Option<(&[f64], &[f64])> {
        let to = self.current()?;
        let from = match self.next {
            0 => &self.reached[0],
            k => &self.waypoints[k - 1],
        };
        Some((from, to))
    }

    /// The goal `follow` gives a robot at `position` on the current
    /// [`WaypointDispatcher::segment`]; `None` once done.
    pub fn target(&self, follow: Follow, position: &[f64]) -> Option<Vec<f64>> {
        let (from, to) = self.segment()?;
        Some(follow.target(from, to, position))
    }

    /// Distance (m) from `position` to the current [`WaypointDispatcher::segment`]
    /// (0 once done). Call it before [`WaypointDispatcher::after_step`] to measure
    /// against the segment the step was driving.
    pub fn off_track(&self, position: &[f64]) -> f64 {
        self.segment().map_or(0.0, |(from, to)| sim::segment::point_segment_distance(position, from, to))
    }

    /// Accounts for one environment step that left the robot at `position`.
    pub fn after_step(&mut self, step: &Step, position: &[f64]) -> Dispatch {
        if let Some(o) = self.outcome {
            return Dispatch::Done(o);
        }
        self.steps += 1;
        let reached = match &self.inside {
            None => step.reached,
            Some(rule) => {
                sim::segment::point_distance(&self.waypoints[self.next], position) <= rule.radius
                    && rule.goals[self.next].iter().all(|g| g.holds(position))
            }
        };
        if reached {
            self.reached.push(position.to_vec());
            self.reached_at.push(self.steps);
            self.next += 1;
            if self.next == self.waypoints.len() {
                self.outcome = Some(Outcome::Completed);
                return Dispatch::Done(Outcome::Completed);
            }
        }
        if step.collided {
            self.outcome = Some(Outcome::Collided);
            return Dispatch::Done(Outcome::Collided);
        }
        if step.fell {
            self.outcome = Some(Outcome::Fell);
            return Dispatch::Done(Outcome::Fell);
        }
        if self.steps >= self.limit || step.truncated {
            self.outcome = Some(Outcome::TimedOut);
            return Dispatch::Done(Outcome::TimedOut);
        }
        if reached { Dispatch::NewGoal(self.waypoints[self.next].clone()) } else { Dispatch::Continue }
    }

    /// The start and the positions where waypoints were reached, in order.
    pub fn executed_path(&self) -> &[Vec<f64>] {
        &self.reached
    }

    /// How the run ended, once it has.
    pub fn outcome(&self) -> Option<Outcome> {
        self.outcome
    }

    /// Environment steps taken.
    pub fn steps(&self) -> usize {
        self.steps
    }

    /// Environment steps taken when each waypoint was reached, in order.
    pub fn reached_at(&self) -> &[usize] {
        &self.reached_at
    }

    /// Waypoints reached so far.
    pub fn reached_count(&self) -> usize {
        self.reached.len() - 1
    }

    /// The run as an [`Execution`] judged by `spec` (the task's
    /// [`crate::task::Task::execution_spec`]). A run not yet over counts as timed out.
    pub fn into_execution(
        self,
        spec: &ExecutionSpec,
        planned: Vec<Vec<f64>>,
        trajectory: Vec<Vec<f64>>,
        headings: Vec<f64>,
        control_return: f64,
    ) -> Execution {
        let judged = spec.judge(&self.reached, &trajectory, &self.reached_at);
        Execution {
            planned,
            robustness: judged.robustness,
            entered: judged.entered,
            outcome: self.outcome.unwrap_or(Outcome::TimedOut),
            steps: self.steps,
            executed: self.reached,
            trajectory,
            headings,
            reached_at: self.reached_at,
            control_return,
        }
    }
}

/// One executed plan.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Execution {
    /// The planned path (start first).
    pub planned: Vec<Vec<f64>>,
    /// The start and the positions where waypoints were reached.
    pub executed: Vec<Vec<f64>>,
    /// Every position the robot passed through.
    pub trajectory: Vec<Vec<f64>>,
    /// The robot's heading (yaw about the vertical, rad) at each trajectory position.
    #[serde(default)]
    pub headings: Vec<f64>,
    /// How it ended.
    pub outcome: Outcome,
    /// Environment steps taken.
    pub steps: usize,
    /// Environment steps taken when each waypoint was reached, in order.
    #[serde(default)]
    pub reached_at: Vec<usize>,
    /// Sum of the environment's rewards (distance progress plus reach bonuses).
    pub control_return: f64,
    /// Hard robustness of the executed path (−∞ when it did not complete).
    pub robustness: f64,
    /// The region to avoid whose entry failed the spec, if that is why it failed.
    #[serde(default)]
    pub entered: Option<Entry>,
}

impl Execution {
    /// Completed, and the spec holds on the executed path.
    pub fn satisfied(&self) -> bool {
        self.outcome == Outcome::Completed && self.robustness > 0.0
    }

    /// How the run ended, in words: `satisfied`, `collided`, `fell`, `timed out`,
    /// `entered hazard at step 312`, or `completed, spec violated`.
    pub fn verdict(&self) -> String {
        match (self.outcome, &self.entered) {
            (Outcome::Completed, _) if self.satisfied() => "satisfied".into(),
            (Outcome::Completed, Some(e)) => e.to_string(),
            (Outcome::Completed, None) => "completed, spec violated".into(),
            (Outcome::Collided, _) => "collided".into(),
            (Outcome::Fell, _) => "fell".into(),
            (Outcome::TimedOut, _) => "timed out".into(),
        }
    }

    /// Environment steps until `waypoints` waypoints were reached (`None`: all of
    /// them; see [`crate::task::Task::steps_to_reach_at`]), if they were.
    pub fn steps_to_reach(&self, waypoints: Option<usize>) -> Option<usize> {
        match waypoints {
            None if self.outcome == Outcome::Completed => Some(self.steps),
            None => None,
            Some(n) => n.checked_sub(1).and_then(|i| self.reached_at.get(i)).copied(),
        }
    }
}

/// An environment for `robot` executing `task`'s plans: the task's map, and
/// waypoints counted as reached within [`Task::waypoint_reach`]; with
/// `observe_track`, observations end with the offset from the planned segment being
/// driven (for a controller trained so, [`crate::control::ControlConfig::observe_track`]).
pub fn task_env(robot: sim::Robot, task: &Task, observe_track: bool) -> Result<Box<dyn Env>, sim::EnvError> {
    let mut env = sim::make_env(robot, task.map.clone())?;
    let reach = task.waypoint_reach(env.reach_radius());
    env.set_reach_radius(reach)?;
    env.set_track_observation(observe_track);
    Ok(env)
}

/// Sets `env`'s goal to what `follow` gives on `dispatcher`'s current segment (if the
/// run goes on), the segment's first waypoint as the goal's origin (the track a
/// controller that observes it sees), and writes the observation.
pub fn aim(
    env: &mut dyn Env,
    dispatcher: &WaypointDispatcher,
    follow: Follow,
    obs: &mut [f64],
) -> Result<(), sim::EnvError> {
    if let (Some(goal), Some((from, _))) = (dispatcher.target(follow, env.position()), dispatcher.segment()) {
        env.set_goal(&goal)?;
        env.set_goal_origin(from)?;
        env.observe(obs);
    }
    Ok(())
}

/// Puts `env` at a path's start with the goal `follow` gives there (the first
/// waypoint, or a point on the way to it).
pub fn start_run(
    env: &mut dyn Env,
    seed: u64,
    path: &[Vec<f64>],
    limit: usize,
    follow: Follow,
    obs: &mut [f64],
) -> Result<WaypointDispatcher, sim::EnvError> {
    env.set_max_steps(limit);
    env.reset_into(seed, Some(&path[0]), obs)?;
    let d = WaypointDispatcher::new(path[0].clone(), path[1..].to_vec(), limit);
    aim(env, &d, follow, obs)?;
    Ok(d)
}

/// [`start_run`] as `task` executes its plans: its step limit, its [`Follow`] and its
/// [`Reach`].
pub fn start_task_run(
    env: &mut dyn Env,
    seed: u64,
    path: &[Vec<f64>],
    task: &Task,
    obs: &mut [f64],
) -> Result<WaypointDispatcher, sim::EnvError> {
    let d = start_run(env, seed, path, task.step_limit, task.follow, obs)?;
    Ok(match task.reach {
        Reach::Radius => d,
        Reach::InGoal => d.reaching_in_goals(env.reach_radius(), task),
    })
}
