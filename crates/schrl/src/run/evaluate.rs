//! Evaluation: what trained planners and controllers achieve, on fresh runs driven by
//! the controller's mean actions through the one episode loop ([`super::episode`]).
//!
//! * [`evaluate_task`] — a task: groups of runs, each executing a plan from a random
//!   start; satisfaction and steps to reach per group (the paper's protocol).
//! * [`evaluate_controller`] — a controller alone: episodes to random goals.

use candle_core::Tensor;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};
use sim::{Map, VecEnv};

use super::RunError;
use super::episode::{Episode, MeanActions, drive};
use super::execute::{Execution, Outcome, WaypointDispatcher, start_task_run, task_env};
use super::joint::paths_of;
use crate::control::Controller;
use crate::plan::gradient_planner::{self, GradientPlannerConfig};
use crate::plan::mip::{self, MipConfig};
use crate::plan::planner::PathPlanner;
use crate::task::{Follow, Task};

/// The evaluation protocol's defaults (paper §4.4: 5 groups of 100 runs); the seed of
/// starts and plans is this project's fixed choice, so evaluations compare.
pub const EVAL_GROUPS: usize = 5;
/// Runs per evaluation group.
pub const EVAL_PER_GROUP: usize = 100;
/// Seed of evaluation starts and plans.
pub const EVAL_SEED: u64 = 2024;

/// Steps to reach of a satisfying run under `task`'s count.
pub(crate) fn reach_steps(run: &Execution, task: &Task) -> f64 {
    run.steps_to_reach(task.steps_to_reach_at).unwrap_or(run.steps) as f64
}

/// Satisfaction and steps to reach over groups of runs (the paper's protocol: 5
/// groups of 100), mean ± sample std over the groups.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TaskEval {
    /// Satisfaction of each group.
    pub satisfaction: Vec<f64>,
    /// Mean steps to reach of each group (over its satisfying runs).
    pub steps_to_reach: Vec<f64>,
    /// Runs ended by a collision, over all groups.
    pub collisions: usize,
    /// Runs ended by a fall (legged robots), over all groups.
    #[serde(default)]
    pub falls: usize,
    /// Runs that timed out.
    pub timeouts: usize,
    /// Completed runs that failed by entering a region the spec says to avoid.
    #[serde(default)]
    pub entered: usize,
    /// A few runs, for pictures.
    pub examples: Vec<Execution>,
}

/// One evaluation group's count so far ([`TaskEval::tally`]).
#[derive(Default)]
pub(crate) struct GroupTally {
    satisfied: usize,
    steps: f64,
    runs: usize,
}

impl TaskEval {
    /// Draws the first four example runs (planned waypoints and executed trajectory)
    /// on the task's map, with the first run's pose at eight moments (a Car drives
    /// forwards or backwards and turns on the spot, which a trace alone does not
    /// show), to `out` (PNG or SVG).
    pub fn save_picture(&self, task: &Task, out: &std::path::Path, overwrite: bool) -> Result<(), RunError> {
        use sim::render::{PathKind, Polyline, RobotMarker, Scene};
        let mut scene = Scene::new(task.map.clone());
        scene.goals = task.picture_goals();
        let radius = sim::make_env(task.robot, task.map.clone())?.radius();
        for run in self.examples.iter().take(4) {
            // A flat policy (TLTL) plans nothing.
            if !run.planned.is_empty() {
                scene.paths.push(Polyline { points: run.planned.clone(), kind: PathKind::Planned });
            }
            scene.paths.push(Polyline { points: run.trajectory.clone(), kind: PathKind::Executed });
        }
        if let Some(run) = self.examples.first() {
            let every = (run.trajectory.len() / 8).max(1);
            let poses = run.trajectory.iter().zip(&run.headings).skip(every).step_by(every);
            scene.robots.extend(poses.map(|(p, &heading)| RobotMarker {
                position: p.clone(),
                heading,
                radius,
            }));
        }
        sim::render::save(&scene, out, overwrite).map_err(RunError::from)
    }

    /// No groups yet.
    pub(crate) fn empty() -> Self {
        Self {
            satisfaction: vec![],
            steps_to_reach: vec![],
            collisions: 0,
            falls: 0,
            timeouts: 0,
            entered: 0,
            examples: vec![],
        }
    }

    /// Counts one judged run of the current group: its failure if it failed, its
    /// steps to reach (`reach`) if it satisfied, and keeps it as an example while
    /// there are few.
    pub(crate) fn tally(
        &mut self,
        group: &mut GroupTally,
        run: Execution,
        reach: impl FnOnce(&Execution) -> f64,
    ) {
        match run.outcome {
            Outcome::Collided => self.collisions += 1,
            Outcome::Fell => self.falls += 1,
            Outcome::TimedOut => self.timeouts += 1,
            Outcome::Completed => self.entered += usize::from(run.entered.is_some()),
        }
        group.runs += 1;
        if run.satisfied() {
            group.satisfied += 1;
            group.steps += reach(&run);
        }
        if self.examples.len() < 6 {
            self.examples.push(run);
        }
    }

    /// Closes a group: its satisfaction, and its mean steps to reach if any run satisfied.
    pub(crate) fn end_group(&mut self, group: GroupTally) {
        self.satisfaction.push(group.satisfied as f64 / group.runs.max(1) as f64);
        if group.satisfied > 0 {
            self.steps_to_reach.push(group.steps / group.satisfied as f64);
        }
    }
}

/// Mean and sample standard deviation.
pub fn mean_std(xs: &[f64]) -> (f64, f64) {
    let n = xs.len() as f64;
    if xs.is_empty() {
        return (f64::NAN, f64::NAN);
    }
    let m = xs.iter().sum::<f64>() / n;
    let v = if xs.len() > 1 { xs.iter().map(|x| (x - m) * (x - m)).sum::<f64>() / (n - 1.0) } else { 0.0 };
    (m, v.sqrt())
}

/// Where the plans of an evaluation come from.
#[derive(Clone, Copy)]
pub enum Plans<'a> {
    /// The planner's mean paths: the deployed plans (default). Sampling noise (std ≥
    /// 0.1 m per waypoint) exists for exploration while training; measured on Point
    /// Seq, 62 % of sampled paths satisfied the spec and 100 % of mean paths.
    Mean(&'a PathPlanner),
    /// Paths sampled from the planner, as during training.
    Sampled(&'a PathPlanner),
    /// The gradient planner (paper Fig. 4 (c), App. J): one plan per start, optimised
    /// for `task` (give the task the network planned for, with its goal and safe
    /// margins, so both planners face the same spec).
    Gradient {
        /// The task planned for.
        task: &'a Task,
        /// Its settings.
        config: GradientPlannerConfig,
    },
    /// The MIP planner ([`crate::plan::mip`]): one most robust plan per start for
    /// `task` (as for the gradient planner, the task the network planned for).
    Mip {
        /// The task planned for.
        task: &'a Task,
        /// Its settings.
        config: MipConfig,
    },
}

impl Plans<'_> {
    /// Plans from the starts `g0` (`[n, dim]`; `noise` is used by sampled plans).
    fn plan(
        &self,
        task: &Task,
        g0: &Tensor,
        noise: &Tensor,
        rng: &mut ChaCha8Rng,
    ) -> Result<Vec<Vec<Vec<f64>>>, RunError> {
        let paths = match self {
            Plans::Mean(p) => paths_of(&p.mean_path(g0, task.steps)?)?,
            Plans::Sampled(p) => paths_of(&p.sample(g0, noise)?.paths)?,
            Plans::Gradient { task: planned, config } => {
                let spec = planned.spec();
                let starts: Vec<Vec<f64>> = g0.to_dtype(candle_core::DType::F64)?.to_vec2()?;
                let dim = planned.map.dim();
                starts
                    .iter()
                    .map(|s| {
                        let p = gradient_planner::plan(planned, &spec, s, config, rng).map_err(|e| {
                            RunError::Planner(candle_core::Error::Msg(format!("gradient planner: {e}")))
                        })?;
                        Ok(p.path.chunks(dim).map(|c| c.to_vec()).collect())
                    })
                    .collect::<Result<_, RunError>>()?
            }
            Plans::Mip { task: planned, config } => {
                let starts: Vec<Vec<f64>> = g0.to_dtype(candle_core::DType::F64)?.to_vec2()?;
                let dim = planned.map.dim();
                starts
                    .iter()
                    .map(|s| {
                        let p = mip::plan(planned, s, config).map_err(|e| {
                            RunError::Planner(candle_core::Error::Msg(format!(
                                "MIP planner from {s:.3?}: {e}"
                            )))
                        })?;
                        Ok(p.path.chunks(dim).map(|c| c.to_vec()).collect())
                    })
                    .collect::<Result<_, RunError>>()?
            }
        };
        Ok(paths)
    }
}

/// Evaluates plans and a controller on `task`: `groups × per_group` runs from random
/// starts, each executing the plan `plans` gives with the controller's mean actions.
pub fn evaluate_task(
    task: &Task,
    plans: Plans<'_>,
    controller: &Controller,
    sizes: (usize, usize),
    seed: u64,
) -> Result<TaskEval, RunError> {
    evaluate_task_with(task, plans, controller, sizes, seed, &mut |_, _, _| Ok(()))
}

/// [`evaluate_task`], handing every run to `on_run(group, index, run)` as it is judged
/// (in order: group by group), e.g. to record it ([`RunRecord::of`]).
pub fn evaluate_task_with(
    task: &Task,
    plans: Plans<'_>,
    controller: &Controller,
    (groups, per_group): (usize, usize),
    seed: u64,
    on_run: &mut dyn FnMut(usize, usize, &Execution) -> Result<(), RunError>,
) -> Result<TaskEval, RunError> {
    let spec = task.execution_spec();
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut eval = TaskEval::empty();
    for group in 0..groups {
        let g0 = task.sample_starts(&mut rng, per_group)?;
        let noise = task.sample_noise(&mut rng, per_group)?;
        let paths = plans.plan(task, &g0, &noise, &mut rng)?;
        let mut envs = (0..paths.len())
            .map(|_| task_env(controller.robot, task, controller.observe_track))
            .collect::<Result<Vec<_>, _>>()?;
        let od = envs.first().map_or(0, |e| e.observation_space().dim());
        let mut raw = vec![0.0; paths.len() * od];
        let mut dispatchers = Vec::with_capacity(paths.len());
        for (i, (env, path)) in envs.iter_mut().zip(&paths).enumerate() {
            let obs = &mut raw[i * od..(i + 1) * od];
            dispatchers.push(start_task_run(env.as_mut(), rng.random(), path, task, obs)?);
        }
        let episodes =
            drive(&mut envs, dispatchers, task.follow, &mut raw, &mut MeanActions::new(controller))?;
        let mut tally = GroupTally::default();
        for (index, (e, path)) in episodes.into_iter().zip(&paths).enumerate() {
            let run =
                e.dispatcher.into_execution(&spec, path.clone(), e.trajectory, e.headings, e.control_return);
            on_run(group, index, &run)?;
            eval.tally(&mut tally, run, |r| reach_steps(r, task));
        }
        eval.end_group(tally);
    }
    Ok(eval)
}

/// One evaluated run as `schrl eval --trajectories` writes it: one JSON object per
/// line, everything needed to re-check the run with other tools (or with `schrl
/// robustness --task … --runs …`, which judges `reached`, `reached_at` and
/// `positions` again).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RunRecord {
    /// Evaluation group (0-based).
    pub group: usize,
    /// Run within its group (0-based).
    pub index: usize,
    /// Completed, and the spec held on what the robot did.
    pub satisfied: bool,
    /// How it ended: `satisfied`, `collided`, `fell`, `timed out`, `entered R at step
    /// k`, or `completed, spec violated` ([`Execution::verdict`]).
    pub outcome: String,
    /// Hard robustness of the executed path (`null` when not every waypoint was reached).
    pub robustness: Option<f64>,
    /// Environment steps taken.
    pub steps: usize,
    /// Steps to reach under the task's count, for a satisfying run.
    pub steps_to_reach: Option<usize>,
    /// The plan: the start, then its waypoints.
    pub waypoints: Vec<Vec<f64>>,
    /// The start, then the robot's position when it reached each waypoint.
    pub reached: Vec<Vec<f64>>,
    /// The environment step at which each waypoint was reached.
    pub reached_at: Vec<usize>,
    /// The robot's position before the first step and after every environment step.
    pub positions: Vec<Vec<f64>>,
    /// The robot's heading (yaw about the vertical, rad) at each of `positions`
    /// (absent in files written before it was recorded).
    #[serde(default)]
    pub headings: Vec<f64>,
}

impl RunRecord {
    /// The record of `run`, run `index` of group `group` of an evaluation of `task`.
    pub fn of(run: &Execution, task: &Task, group: usize, index: usize) -> Self {
        Self {
            group,
            index,
            satisfied: run.satisfied(),
            outcome: run.verdict(),
            robustness: run.robustness.is_finite().then_some(run.robustness),
            steps: run.steps,
            steps_to_reach: run.satisfied().then(|| reach_steps(run, task) as usize),
            waypoints: run.planned.clone(),
            reached: run.executed.clone(),
            reached_at: run.reached_at.clone(),
            positions: run.trajectory.clone(),
            headings: run.headings.clone(),
        }
    }
}

/// What [`evaluate_controller`] measured.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ControllerEval {
    /// Episodes run.
    pub episodes: usize,
    /// Fraction of episodes whose goal was reached (within the step limit, without
    /// collision).
    pub success_rate: f64,
    /// Mean environment steps to reach the goal, over the successful episodes.
    pub mean_steps_to_reach: Option<f64>,
    /// Episodes ended by a collision.
    pub collisions: usize,
    /// Episodes ended by a fall (the Doggo; counted apart from collisions since
    /// 2026-12-02, before which they were among them).
    #[serde(default)]
    pub falls: usize,
    /// Episodes that ran out of steps.
    pub timeouts: usize,
}

/// One episode to a random goal, with what a picture of it needs.
pub struct GoalEpisode {
    /// The run.
    pub episode: Episode,
    /// Its goal.
    pub goal: Vec<f64>,
    /// The robot's heading at the end (rad).
    pub heading: f64,
    /// The robot's radius (m).
    pub radius: f64,
    /// How close counts as reaching the goal (m).
    pub reach_radius: f64,
}

/// Where [`goal_episodes`] puts each episode's goal.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum GoalDraw {
    /// Anywhere free on the map (what the controller trains on).
    Anywhere,
    /// Within this many metres of the start and beyond the reach radius
    /// ([`sim::Env::sample_goal_within`]): the short hops a plan asks for, where a
    /// goal is often beside or behind the robot.
    Within(f64),
}

/// `episodes` single-goal episodes on `map` (random free start and goal from `seed`,
/// the goal drawn as `draw` says; mean actions, at most `max_steps` steps each), 64
/// environments at a time.
pub fn goal_episodes(
    controller: &Controller,
    map: &Map,
    episodes: usize,
    seed: u64,
    max_steps: usize,
    draw: GoalDraw,
) -> Result<Vec<GoalEpisode>, RunError> {
    const BATCH: usize = 64;
    let mut out = Vec::with_capacity(episodes);
    let mut driver = MeanActions::new(controller);
    while out.len() < episodes {
        let n = BATCH.min(episodes - out.len());
        let mut envs =
            VecEnv::new(controller.robot, map.clone(), n, sim::vec_env::member_seed(seed, out.len()))?;
        envs.set_track_observation(controller.observe_track);
        let od = envs.obs_dim();
        let mut raw = vec![0.0; n * od];
        let mut goals = Vec::with_capacity(n);
        let mut dispatchers = Vec::with_capacity(n);
        for (e, o) in envs.envs_mut().iter_mut().zip(raw.chunks_mut(od)) {
            e.set_max_steps(max_steps);
            if let GoalDraw::Within(r) = draw {
                let g = e.sample_goal_within(r);
                e.set_goal(&g)?;
            }
            e.observe(o);
            goals.push(e.goal().to_vec());
            dispatchers.push(WaypointDispatcher::new(
                e.position().to_vec(),
                vec![e.goal().to_vec()],
                max_steps,
            ));
        }
        let runs = drive(envs.envs_mut(), dispatchers, Follow::Waypoints, &mut raw, &mut driver)?;
        for ((episode, goal), env) in runs.into_iter().zip(goals).zip(envs.envs()) {
            out.push(GoalEpisode {
                episode,
                goal,
                heading: env.heading(),
                radius: env.radius(),
                reach_radius: env.reach_radius(),
            });
        }
    }
    Ok(out)
}

/// Runs [`goal_episodes`] and reports how many reach their goal.
pub fn evaluate_controller(
    controller: &Controller,
    map: &Map,
    episodes: usize,
    seed: u64,
    max_steps: usize,
    draw: GoalDraw,
) -> Result<ControllerEval, RunError> {
    Ok(ControllerEval::of(&goal_episodes(controller, map, episodes, seed, max_steps, draw)?))
}

impl ControllerEval {
    /// What `runs` achieved.
    pub fn of(runs: &[GoalEpisode]) -> Self {
        let episodes = runs.len();
        let (mut successes, mut steps) = (0usize, 0usize);
        let (mut collisions, mut falls, mut timeouts) = (0usize, 0usize, 0usize);
        for r in runs {
            match r.episode.dispatcher.outcome() {
                Some(Outcome::Completed) => {
                    successes += 1;
                    steps += r.episode.dispatcher.steps();
                }
                Some(Outcome::Collided) => collisions += 1,
                Some(Outcome::Fell) => falls += 1,
                Some(Outcome::TimedOut) | None => timeouts += 1,
            }
        }
        ControllerEval {
            episodes,
            success_rate: successes as f64 / episodes.max(1) as f64,
            mean_steps_to_reach: (successes > 0).then(|| steps as f64 / successes as f64),
            collisions,
            falls,
            timeouts,
        }
    }
}
