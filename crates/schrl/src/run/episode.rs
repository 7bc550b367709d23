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
    /// over) and what else its step reported.
    fn after_step(&mut self, _live: &[bool], _rewards: &mut [f64], _step: &StepReports<'_>) {}
}

/// What every environment's step reported besides its reward, one entry per run
/// (0 or `false` for runs already over).
pub struct StepReports<'a> {
    /// Distance (m) from the planned segment it was driving in this step.
    pub off_track: &'a [f64],
    /// Its run ended in this step.
    pub ended: &'a [bool],
    /// Its robot fell in this step (legged robots only).
    pub fell: &'a [bool],
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
/// `raw` holds the last observations afterwards. A robot whose step is heavy
/// ([`sim::Robot::steps_in_parallel`]: the Doggo) steps its runs on all of rayon's
/// threads, as its `VecEnv` does in controller training; every run owns its
/// environment and the actions are chosen before the step, so the runs are the same,
/// bit for bit, whatever the thread count.
pub fn drive(
    envs: &mut [Box<dyn Env>],
    dispatchers: Vec<WaypointDispatcher>,
    follow: Follow,
    raw: &mut [f64],
    driver: &mut dyn Driver,
) -> Result<Vec<Episode>, EnvError> {
    let parallel = envs
        .first()
        .is_some_and(|e| e.robot_name().parse::<sim::Robot>().is_ok_and(|r| r.steps_in_parallel()));
    drive_threaded(envs, dispatchers, follow, raw, driver, parallel)
}

/// [`drive`] with the choice of stepping runs on rayon's threads made by the caller.
pub(crate) fn drive_threaded(
    envs: &mut [Box<dyn Env>],
    dispatchers: Vec<WaypointDispatcher>,
    follow: Follow,
    raw: &mut [f64],
    driver: &mut dyn Driver,
    parallel: bool,
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
    let mut off_track = vec![0.0; n];
    let mut ended = vec![false; n];
    let mut fell = vec![false; n];
    let mut stepped: Vec<Result<Option<StepReport>, EnvError>> = Vec::with_capacity(n);
    let envs = &mut envs[..n];
    while live.iter().any(|l| *l) {
        driver.act(raw, &live, &mut actions);
        let before = live.clone();
        let one = |((env, run), (obs, action)): Lane<'_>| step_run(env.as_mut(), run, follow, action, obs);
        if parallel {
            use rayon::prelude::*;
            envs.par_iter_mut()
                .zip(runs.par_iter_mut())
                .zip(raw.par_chunks_mut(od).zip(actions.par_chunks(ad)))
                .map(one)
                .collect_into_vec(&mut stepped);
        } else {
            stepped.clear();
            stepped.extend(
                envs.iter_mut().zip(runs.iter_mut()).zip(raw.chunks_mut(od).zip(actions.chunks(ad))).map(one),
            );
        }
        for (i, s) in stepped.drain(..).enumerate() {
            let report = s?;
            rewards[i] = report.map_or(0.0, |r| r.reward);
            off_track[i] = report.map_or(0.0, |r| r.off_track);
            ended[i] = report.is_some_and(|r| r.ended);
            fell[i] = report.is_some_and(|r| r.fell);
            live[i] &= !ended[i];
        }
        driver.after_step(
            &before,
            &mut rewards,
            &StepReports { off_track: &off_track, ended: &ended, fell: &fell },
        );
    }
    Ok(runs)
}

/// One run's share of a step: its environment and record, its observation and action.
type Lane<'a> = ((&'a mut Box<dyn Env>, &'a mut Episode), (&'a mut [f64], &'a [f64]));

/// What one run's step reported to the loop.
#[derive(Clone, Copy)]
struct StepReport {
    reward: f64,
    /// Distance from the segment driven in this step, measured after it.
    off_track: f64,
    ended: bool,
    fell: bool,
}

/// Steps one run with `action` (nothing if it is over, `None`), writing its
/// observation into `obs` and moving its goal as its dispatcher and `follow` say.
fn step_run(
    env: &mut dyn Env,
    run: &mut Episode,
    follow: Follow,
    action: &[f64],
    obs: &mut [f64],
) -> Result<Option<StepReport>, EnvError> {
    if run.dispatcher.outcome().is_some() {
        return Ok(None);
    }
    let step = env.step_into(action, obs)?;
    run.trajectory.push(env.position().to_vec());
    run.headings.push(env.heading());
    run.control_return += step.reward;
    let off_track = run.dispatcher.off_track(env.position());
    let ended = match run.dispatcher.after_step(&step, env.position()) {
        Dispatch::Continue if follow == Follow::Waypoints => false,
        Dispatch::Continue | Dispatch::NewGoal(_) => {
            super::execute::aim(env, &run.dispatcher, follow, obs)?;
            false
        }
        Dispatch::Done(_) => true,
    };
    Ok(Some(StepReport { reward: step.reward, off_track, ended, fell: step.fell }))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::run::execute::start_run;

    /// Steers by a fixed function of the observation and records the rewards and
    /// off-track distances it sees (one row of all runs per step), so two loops that
    /// stepped alike leave the same record.
    /// With `track_dims`, it also records the length of each run's observed track
    /// offset (the observation's last `track_dims` numbers) before every step.
    #[derive(Default)]
    struct Recorder {
        rewards: Vec<f64>,
        off_track: Vec<Vec<f64>>,
        track_dims: usize,
        observed_off_track: Vec<Vec<f64>>,
    }

    impl Driver for Recorder {
        fn act(&mut self, raw: &[f64], live: &[bool], actions: &mut [f64]) {
            let (od, ad) = (raw.len() / live.len(), actions.len() / live.len());
            if self.track_dims > 0 {
                let norm = |o: &[f64]| o[od - self.track_dims..].iter().map(|x| x * x).sum::<f64>().sqrt();
                self.observed_off_track.push(raw.chunks(od).map(norm).collect());
            }
            for (o, a) in raw.chunks(od).zip(actions.chunks_mut(ad)) {
                for (k, x) in a.iter_mut().enumerate() {
                    *x = (o.iter().skip(k).step_by(ad).sum::<f64>()).sin();
                }
            }
        }

        fn after_step(&mut self, _live: &[bool], rewards: &mut [f64], step: &StepReports<'_>) {
            self.rewards.extend_from_slice(rewards);
            self.off_track.push(step.off_track.to_vec());
        }
    }

    /// Six Point runs through three random goals each, with their paths (start first);
    /// with `observe_track`, the environments observe their track offsets.
    fn runs_with_paths(parallel: bool, observe_track: bool) -> (Vec<Episode>, Recorder, Vec<Vec<Vec<f64>>>) {
        let robot = sim::Robot::Point;
        let mut envs: Vec<Box<dyn Env>> =
            (0..6).map(|_| sim::make_env(robot, robot.default_map()).unwrap()).collect();
        for env in &mut envs {
            env.set_track_observation(observe_track);
        }
        let od = envs[0].observation_space().dim();
        let mut raw = vec![0.0; envs.len() * od];
        let (mut dispatchers, mut paths) = (vec![], vec![]);
        for (i, env) in envs.iter_mut().enumerate() {
            env.reset(i as u64, None).unwrap();
            let mut path = vec![env.position().to_vec()];
            path.extend((0..3).map(|_| env.sample_goal()));
            paths.push(path.clone());
            // Runs of different lengths: some end while others go on.
            let limit = 50 + 40 * i;
            dispatchers.push(
                start_run(
                    env.as_mut(),
                    7 + i as u64,
                    &path,
                    limit,
                    Follow::Waypoints,
                    &mut raw[i * od..(i + 1) * od],
                )
                .unwrap(),
            );
        }
        let mut rec = Recorder { track_dims: if observe_track { 2 } else { 0 }, ..Recorder::default() };
        let episodes =
            drive_threaded(&mut envs, dispatchers, Follow::Waypoints, &mut raw, &mut rec, parallel).unwrap();
        (episodes, rec, paths)
    }

    fn runs(parallel: bool) -> (Vec<Episode>, Vec<f64>) {
        let (episodes, rec, _) = runs_with_paths(parallel, false);
        (episodes, rec.rewards)
    }

    /// The off-track penalty is only right if each step is measured against the
    /// segment it drove, not the next one (the step that reaches a waypoint ends on
    /// its own segment) and not the robot's own chord.
    #[test]
    fn off_track_is_the_distance_from_the_planned_segment_being_driven() {
        let (episodes, rec, paths) = runs_with_paths(false, false);
        let mut largest: f64 = 0.0;
        for (i, (run, path)) in episodes.iter().zip(&paths).enumerate() {
            let reached_at = run.dispatcher.reached_at();
            for (t, row) in rec.off_track.iter().enumerate() {
                let step = t + 1;
                if step >= run.trajectory.len() {
                    assert_eq!(row[i], 0.0, "run {i} is over at step {step}");
                    continue;
                }
                let k = reached_at.iter().filter(|&&s| s < step).count();
                let want =
                    sim::segment::point_segment_distance(&run.trajectory[step], &path[k], &path[k + 1]);
                assert!((row[i] - want).abs() < 1e-12, "run {i} step {step}: {} against {want}", row[i]);
                largest = largest.max(want);
            }
        }
        assert!(largest > 0.05, "the runs should stray from their segments ({largest} m at most)");
    }

    /// A controller that observes its track must see the planned segment it is about
    /// to drive (the next one right after a waypoint), not where it happened to stand
    /// when the goal changed.
    #[test]
    fn observed_track_offset_is_from_the_planned_segment_about_to_be_driven() {
        let (episodes, rec, paths) = runs_with_paths(false, true);
        let mut largest: f64 = 0.0;
        for (i, (run, path)) in episodes.iter().zip(&paths).enumerate() {
            let reached_at = run.dispatcher.reached_at();
            for (t, row) in rec.observed_off_track.iter().enumerate() {
                if t + 1 >= run.trajectory.len() {
                    continue;
                }
                let k = reached_at.iter().filter(|&&s| s <= t).count();
                let want = sim::segment::point_segment_distance(&run.trajectory[t], &path[k], &path[k + 1]);
                assert!(
                    (row[i] - want).abs() < 1e-9,
                    "run {i} before step {}: {} against {want}",
                    t + 1,
                    row[i]
                );
                largest = largest.max(want);
            }
        }
        assert!(largest > 0.05, "the runs should stray from their segments ({largest} m at most)");
        let (plain, _, _) = runs_with_paths(false, false);
        assert!(
            episodes.iter().zip(&plain).any(|(a, b)| a.trajectory != b.trajectory),
            "the driver steers by the whole observation, so the offset should change the runs"
        );
    }

    #[test]
    fn runs_stepped_on_threads_are_the_runs_stepped_in_order() {
        let (serial, serial_rewards) = runs(false);
        let (threaded, threaded_rewards) = runs(true);
        let lengths: Vec<usize> = serial.iter().map(|e| e.trajectory.len()).collect();
        assert!(
            lengths.windows(2).any(|w| w[0] != w[1]),
            "the runs should end at different steps: {lengths:?}"
        );
        assert_eq!(serial_rewards, threaded_rewards);
        for (s, t) in serial.iter().zip(&threaded) {
            assert_eq!(s.trajectory, t.trajectory);
            assert_eq!(s.headings, t.headings);
            assert_eq!(s.dispatcher, t.dispatcher);
            assert_eq!(s.control_return.to_bits(), t.control_return.to_bits());
        }
    }
}
