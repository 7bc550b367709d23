//! `schrl.envs`: the robots (Point, Car, Drone; Doggo with the `mujoco` feature) as
//! environments for Python: one ([`PyEnv`]) and N stepped together in Rust
//! ([`PyVecEnv`]). The Gymnasium classes (spaces, seeding, autoreset) are Python
//! wrappers over these (`schrl/envs.py`).

use numpy::{IntoPyArray, PyArray1, PyArray2, PyArray3, PyArrayMethods};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use sim::render::{Goal, PathKind, Polyline, RobotMarker, Scene};
use sim::{Env, EnvError, Map, Robot, VecEnv};

fn env_error(e: EnvError) -> PyErr {
    match e {
        EnvError::MujocoDisabled { robot } => PyValueError::new_err(format!(
            "the {robot} runs on MuJoCo, which this build of schrl does not include: build the wheel \
             with `SCHRL_PYTHON_FEATURES=mujoco bash scripts/setup-python.sh` (README, section Python)"
        )),
        e => PyValueError::new_err(e.to_string()),
    }
}

/// The robot and map of a name pair: `map` by default the open one a general
/// controller learns in (empty plane; floor for the Drone).
fn robot_and_map(robot: &str, map: Option<&str>) -> PyResult<(Robot, Map)> {
    let robot: Robot = robot.parse().map_err(env_error)?;
    let name = map.unwrap_or(if robot == Robot::Drone { "floor" } else { "empty" });
    let map = Map::by_name(name).ok_or_else(|| {
        PyValueError::new_err(format!(
            "map '{name}' does not exist: expected one of {}",
            sim::map::MAP_NAMES.join(", ")
        ))
    })?;
    Ok((robot, map))
}

/// What one step returns to Python: observation, reward, terminated, truncated, info.
type Transition<'py> = (Bound<'py, PyArray1<f64>>, f64, bool, bool, Bound<'py, PyDict>);

/// What a vector step returns: observations, rewards, terminated, truncated, reached.
type Transitions<'py> = (
    Bound<'py, PyArray2<f64>>,
    Bound<'py, PyArray1<f64>>,
    Bound<'py, PyArray1<bool>>,
    Bound<'py, PyArray1<bool>>,
    Bound<'py, PyArray1<bool>>,
);

/// One robot in a map, chasing a goal.
#[pyclass(name = "NativeEnv", module = "schrl.envs", unsendable)]
pub struct PyEnv {
    env: Box<dyn Env>,
    obs: Vec<f64>,
    /// Positions since the last reset, for `render`.
    trail: Vec<Vec<f64>>,
}

#[pymethods]
impl PyEnv {
    /// With `observe_track`, observations end with the robot's offset from its track,
    /// the segment from [`Env::goal_origin`] to the goal (`sim::Env::set_track_observation`).
    #[new]
    #[pyo3(signature = (robot, map = None, observe_track = false))]
    fn new(robot: &str, map: Option<&str>, observe_track: bool) -> PyResult<Self> {
        let (robot, map) = robot_and_map(robot, map)?;
        let mut env = sim::make_env(robot, map).map_err(env_error)?;
        env.set_track_observation(observe_track);
        let obs = vec![0.0; env.observation_space().dim()];
        Ok(Self { env, obs, trail: vec![] })
    }

    /// `(low, high)` of observations.
    #[getter]
    fn observation_bounds(&self) -> (Vec<f64>, Vec<f64>) {
        let s = self.env.observation_space();
        (s.low.clone(), s.high.clone())
    }

    /// `(low, high)` of actions.
    #[getter]
    fn action_bounds(&self) -> (Vec<f64>, Vec<f64>) {
        let s = self.env.action_space();
        (s.low.clone(), s.high.clone())
    }

    /// Starts an episode from `seed` (and `start`, a free position, if given): the
    /// first observation, with a random free goal.
    #[pyo3(signature = (seed, start = None))]
    fn reset<'py>(
        &mut self,
        py: Python<'py>,
        seed: u64,
        start: Option<Vec<f64>>,
    ) -> PyResult<Bound<'py, PyArray1<f64>>> {
        self.env.reset_into(seed, start.as_deref(), &mut self.obs).map_err(env_error)?;
        self.trail = vec![self.env.position().to_vec()];
        Ok(self.obs.clone().into_pyarray(py))
    }

    /// One step: `(observation, reward, terminated, truncated, info)`, info holding
    /// `reached`, `collided` and `fell`.
    fn step<'py>(&mut self, py: Python<'py>, action: Vec<f64>) -> PyResult<Transition<'py>> {
        let step = self.env.step_into(&action, &mut self.obs).map_err(env_error)?;
        self.trail.push(self.env.position().to_vec());
        let info = PyDict::new(py);
        info.set_item("reached", step.reached)?;
        info.set_item("collided", step.collided)?;
        info.set_item("fell", step.fell)?;
        Ok((self.obs.clone().into_pyarray(py), step.reward, step.terminated(), step.truncated, info))
    }

    /// Sets the goal (a free position) and returns the observation that sees it. The
    /// track then starts where the robot stands, or at `origin` if given (a planned
    /// segment's first waypoint).
    #[pyo3(signature = (goal, origin = None))]
    fn set_goal<'py>(
        &mut self,
        py: Python<'py>,
        goal: Vec<f64>,
        origin: Option<Vec<f64>>,
    ) -> PyResult<Bound<'py, PyArray1<f64>>> {
        self.env.set_goal(&goal).map_err(env_error)?;
        if let Some(origin) = origin {
            self.env.set_goal_origin(&origin).map_err(env_error)?;
        }
        self.env.observe(&mut self.obs);
        Ok(self.obs.clone().into_pyarray(py))
    }

    /// The goal.
    #[getter]
    fn goal(&self) -> Vec<f64> {
        self.env.goal().to_vec()
    }

    /// Where the current track starts (the robot's position when the goal was set,
    /// unless `set_goal` was given an origin).
    #[getter]
    fn goal_origin(&self) -> Vec<f64> {
        self.env.goal_origin().to_vec()
    }

    /// Whether observations end with the track offset.
    #[getter]
    fn observe_track(&self) -> bool {
        self.env.track_observation()
    }

    /// The robot's position (plan space: x, y; x, y, z for the Drone).
    #[getter]
    fn position(&self) -> Vec<f64> {
        self.env.position().to_vec()
    }

    /// The robot's heading (rad, about z).
    #[getter]
    fn heading(&self) -> f64 {
        self.env.heading()
    }

    /// Steps taken in this episode.
    #[getter]
    fn steps(&self) -> usize {
        self.env.steps()
    }

    /// Sets the episode's step limit (truncation).
    fn set_max_steps(&mut self, max_steps: usize) {
        self.env.set_max_steps(max_steps);
    }

    /// The map, the goal (its reach radius), the path since the reset and the robot,
    /// as an RGB array `[height, width, 3]` of `uint8`.
    fn render<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray3<u8>>> {
        let mut scene = Scene::new(self.env.map().clone());
        scene.goals.push(Goal {
            center: self.env.goal().to_vec(),
            radius: self.env.reach_radius(),
            avoid: false,
        });
        if self.trail.len() > 1 {
            scene.paths.push(Polyline { points: self.trail.clone(), kind: PathKind::Executed });
        }
        scene.robots.push(RobotMarker {
            position: self.env.position().to_vec(),
            heading: self.env.heading(),
            radius: self.env.radius(),
        });
        let (w, h, pixels) = sim::render::rgb(&scene).map_err(|e| PyValueError::new_err(e.to_string()))?;
        pixels.into_pyarray(py).reshape([h as usize, w as usize, 3])
    }
}

/// N environments of one robot stepped together in Rust (no Python per environment).
#[pyclass(name = "NativeVecEnv", module = "schrl.envs", unsendable)]
pub struct PyVecEnv {
    envs: VecEnv,
    obs: Vec<f64>,
    steps: Vec<sim::Step>,
}

#[pymethods]
impl PyVecEnv {
    /// `observe_track`: as [`PyEnv`]'s, for every environment.
    #[new]
    #[pyo3(signature = (robot, num_envs, map = None, observe_track = false))]
    fn new(robot: &str, num_envs: usize, map: Option<&str>, observe_track: bool) -> PyResult<Self> {
        if num_envs == 0 {
            return Err(PyValueError::new_err("num_envs must be at least 1"));
        }
        let (robot, map) = robot_and_map(robot, map)?;
        let mut envs = VecEnv::new(robot, map, num_envs, 0).map_err(env_error)?;
        envs.set_track_observation(observe_track);
        let obs = vec![0.0; num_envs * envs.obs_dim()];
        Ok(Self { steps: vec![sim::Step::default(); num_envs], envs, obs })
    }

    /// Resets every environment (`i` from a seed derived from `seed` and `i`):
    /// observations `[N, obs_dim]`.
    fn reset<'py>(&mut self, py: Python<'py>, seed: u64) -> PyResult<Bound<'py, PyArray2<f64>>> {
        self.envs.reset_all(seed, &mut self.obs).map_err(env_error)?;
        self.observations(py)
    }

    /// Resets environment `i` from `seed`; its new observation.
    fn reset_one<'py>(
        &mut self,
        py: Python<'py>,
        i: usize,
        seed: u64,
    ) -> PyResult<Bound<'py, PyArray1<f64>>> {
        let dim = self.envs.obs_dim();
        let n = self.envs.len();
        let env = self
            .envs
            .envs_mut()
            .get_mut(i)
            .ok_or_else(|| PyValueError::new_err(format!("env {i} of {n}")))?;
        env.reset_into(seed, None, &mut self.obs[i * dim..(i + 1) * dim]).map_err(env_error)?;
        Ok(self.obs[i * dim..(i + 1) * dim].to_vec().into_pyarray(py))
    }

    /// Steps every environment with its row of `actions` (`[N, act_dim]`):
    /// `(observations, rewards, terminated, truncated, reached)`, each with N rows.
    fn step<'py>(&mut self, py: Python<'py>, actions: Vec<Vec<f64>>) -> PyResult<Transitions<'py>> {
        if actions.len() != self.envs.len() {
            return Err(PyValueError::new_err(format!(
                "actions: {} rows for {} environments",
                actions.len(),
                self.envs.len()
            )));
        }
        let flat: Vec<f64> = actions.concat();
        {
            let Self { envs, obs, steps } = &mut *self;
            py.allow_threads(|| envs.step_all(&flat, obs, steps)).map_err(env_error)?;
        }
        let steps = &self.steps;
        let column = |f: fn(&sim::Step) -> bool| steps.iter().map(f).collect::<Vec<bool>>().into_pyarray(py);
        Ok((
            self.observations(py)?,
            steps.iter().map(|s| s.reward).collect::<Vec<_>>().into_pyarray(py),
            column(sim::Step::terminated),
            column(|s| s.truncated),
            column(|s| s.reached),
        ))
    }

    /// `(low, high)` of one environment's observations.
    #[getter]
    fn observation_bounds(&self) -> (Vec<f64>, Vec<f64>) {
        let s = self.envs.envs()[0].observation_space();
        (s.low.clone(), s.high.clone())
    }

    /// `(low, high)` of one environment's actions.
    #[getter]
    fn action_bounds(&self) -> (Vec<f64>, Vec<f64>) {
        let s = self.envs.envs()[0].action_space();
        (s.low.clone(), s.high.clone())
    }
}

impl PyVecEnv {
    fn observations<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let n = self.envs.len();
        self.obs.clone().into_pyarray(py).reshape([n, self.envs.obs_dim()])
    }
}

/// Adds the environment classes to `m`.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyEnv>()?;
    m.add_class::<PyVecEnv>()?;
    Ok(())
}
