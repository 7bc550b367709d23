//! The goal-conditioned environment API, shaped like Gymnasium's.
//!
//! An environment holds one robot on one map and a current goal in plan space
//! (x, y for ground robots; x, y, z for the Drone). Each step applies an action and
//! reports the reward, whether the goal was reached, whether the robot collided, and
//! whether the step limit truncated the episode.
//!
//! Reward (paper §3.3, reference setup): the decrease of the distance to the goal
//! over the step, `‖g − x_{t−1}‖ − ‖g − x_t‖`, plus 20 on the step the robot first
//! comes within the robot's reach radius of the goal (0.3 m for ground robots, 0.6 m
//! for the Drone). A goal is reached once: until [`Env::set_goal`] gives a new one,
//! later steps earn only the distance term. Observations are written into a
//! caller's buffer so that stepping allocates nothing.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::map::Map;

/// Bonus for reaching the goal (reference setup: "+20 on reaching it").
pub const REACH_BONUS: f64 = 20.0;

/// Draws [`Env::sample_goal_within`] tries before it falls back to any free goal
/// (a ball that reaches free space is hit within a few dozen draws).
pub const NEAR_GOAL_TRIES: usize = 1000;

/// Euclidean distance between two points of plan space.
fn euclidean(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum::<f64>().sqrt()
}

/// Default step limit of an episode (the Seq/Cover tasks' limit for ground robots).
pub const DEFAULT_MAX_STEPS: usize = 1000;

/// A box of real vectors: per-dimension bounds.
#[derive(Clone, Debug, PartialEq)]
pub struct BoxSpace {
    /// Lower bounds.
    pub low: Vec<f64>,
    /// Upper bounds.
    pub high: Vec<f64>,
}

impl BoxSpace {
    /// The box `[low, high]`.
    pub fn new(low: Vec<f64>, high: Vec<f64>) -> Self {
        assert_eq!(low.len(), high.len(), "bounds of equal length");
        Self { low, high }
    }

    /// Number of dimensions.
    pub fn dim(&self) -> usize {
        self.low.len()
    }

    /// `true` if `x` lies in the box.
    pub fn contains(&self, x: &[f64]) -> bool {
        x.len() == self.dim() && x.iter().zip(&self.low).zip(&self.high).all(|((v, l), h)| v >= l && v <= h)
    }
}

/// What one step reports (the observation goes to the caller's buffer).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Step {
    /// Decrease of distance to the goal, plus the reach bonus.
    pub reward: f64,
    /// The robot came within the reach radius of the goal on this step.
    pub reached: bool,
    /// The robot touched an obstacle (wall, floor, duck) during this step.
    pub collided: bool,
    /// The episode hit its step limit.
    pub truncated: bool,
    /// The robot fell over (legged robots only; torso too low or upside down).
    pub fell: bool,
}

impl Step {
    /// The episode ended in failure on this step: a collision or a fall.
    pub fn terminated(&self) -> bool {
        self.collided || self.fell
    }
}

/// Invalid input to an environment. The environment's state is unchanged.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum EnvError {
    /// An action of the wrong length.
    #[error("{robot}: action has {got} numbers, expected {expected}")]
    ActionLength {
        /// Robot name.
        robot: &'static str,
        /// Expected length.
        expected: usize,
        /// Given length.
        got: usize,
    },
    /// NaN or an infinity in an action.
    #[error("{robot}: action[{index}] is {value}, actions must be finite")]
    NonFiniteAction {
        /// Robot name.
        robot: &'static str,
        /// Position in the action.
        index: usize,
        /// The value.
        value: f64,
    },
    /// A goal or start position of the wrong length or with non-finite numbers.
    #[error("{what} must be {expected} finite numbers (the plan space of {robot}), got {got:?}")]
    BadPoint {
        /// "goal" or "start".
        what: &'static str,
        /// Robot name.
        robot: &'static str,
        /// Plan-space dimension.
        expected: usize,
        /// What was given.
        got: Vec<f64>,
    },
    /// A start position inside or too close to an obstacle.
    #[error("start {start:?} is inside or within {clearance} m of an obstacle on the {map} map")]
    StartBlocked {
        /// The start.
        start: Vec<f64>,
        /// Map name.
        map: &'static str,
        /// Required clearance.
        clearance: f64,
    },
    /// An observation buffer of the wrong length.
    #[error("observation buffer has {got} numbers, expected {expected}")]
    ObservationLength {
        /// Expected length.
        expected: usize,
        /// Given length.
        got: usize,
    },
    /// An unknown robot name.
    #[error("unknown robot '{0}': expected one of point, car, drone, doggo")]
    UnknownRobot(String),
    /// The Doggo asked for in a build without MuJoCo.
    #[error(
        "the {robot} runs on MuJoCo, which this build does not include: run `bash scripts/setup-mujoco.sh`, \
         then build with `--features mujoco` (README, section Doggo)"
    )]
    MujocoDisabled {
        /// Robot name.
        robot: &'static str,
    },
    /// MuJoCo could not load or run a model.
    #[error("{robot}: MuJoCo: {reason}")]
    Mujoco {
        /// Robot name.
        robot: &'static str,
        /// What went wrong.
        reason: String,
    },
    /// An unknown map name.
    #[error("unknown map '{0}': expected one of walls, empty, duck, floor")]
    UnknownMap(String),
    /// A robot on a map of the wrong dimension.
    #[error("the {robot} needs a {needs}-D map, but '{map}' is {has}-D")]
    MapMismatch {
        /// Robot name.
        robot: &'static str,
        /// Map name.
        map: &'static str,
        /// Dimension the robot needs.
        needs: usize,
        /// The map's dimension.
        has: usize,
    },
    /// A reach radius that is not a positive finite number of metres.
    #[error("{robot}: reach radius {radius} must be a positive finite number of metres")]
    BadReachRadius {
        /// Robot name.
        robot: &'static str,
        /// What was given.
        radius: f64,
    },
    /// A saved state that is not a state of this robot (or is corrupt).
    #[error("cannot restore a {robot} environment from the saved state: {reason}")]
    BadState {
        /// Robot name.
        robot: &'static str,
        /// What is wrong.
        reason: String,
    },
}

/// A goal-conditioned environment (object safe, so robots can be chosen at run time).
pub trait Env: Send {
    /// The robot's name.
    fn robot_name(&self) -> &'static str;
    /// The map.
    fn map(&self) -> &Map;
    /// Bounds of observations (informative; sensors may exceed them in crashes).
    fn observation_space(&self) -> &BoxSpace;
    /// Bounds of actions; actions outside are clipped.
    fn action_space(&self) -> &BoxSpace;
    /// Plan-space dimension (2 or 3).
    fn plan_dim(&self) -> usize;
    /// Reach radius of a goal: the robot's own ([`Dynamics::REACH_RADIUS`]) unless
    /// [`Env::set_reach_radius`] changed it.
    fn reach_radius(&self) -> f64;
    /// Counts a goal as reached within `radius` metres from now on (a task whose
    /// goals are smaller than the robot's reach radius needs a tighter one).
    fn set_reach_radius(&mut self, radius: f64) -> Result<(), EnvError>;
    /// Starts an episode: the robot at `start` (or a random free position), random
    /// heading, a random free goal; writes the first observation.
    fn reset_into(&mut self, seed: u64, start: Option<&[f64]>, obs: &mut [f64]) -> Result<(), EnvError>;
    /// Applies `action` for one control step and writes the next observation.
    fn step_into(&mut self, action: &[f64], obs: &mut [f64]) -> Result<Step, EnvError>;
    /// Sets the goal (plan space); the next reach counts again.
    fn set_goal(&mut self, goal: &[f64]) -> Result<(), EnvError>;
    /// The current goal.
    fn goal(&self) -> &[f64];
    /// Where the robot was when the current goal was set (its start after a reset),
    /// unless [`Env::set_goal_origin`] moved it: with [`Env::goal`], the straight
    /// segment a robot that heads for its goal drives (its *track*).
    fn goal_origin(&self) -> &[f64];
    /// Sets the start of the current track (a planned segment's first waypoint, where
    /// a robot that reached it within its reach radius stands off it).
    fn set_goal_origin(&mut self, origin: &[f64]) -> Result<(), EnvError>;
    /// With `on`, every observation ends with the robot's offset from its track (the
    /// point of the segment [`Env::goal_origin`] → [`Env::goal`] nearest the robot,
    /// less the robot's position, turned into the robot's heading frame: forward,
    /// left, and up for a flying robot), so a controller can see how far off its
    /// segment it drives; the observation space grows by the plan dimension. Off by
    /// default: the robots' own observations, as the paper's.
    fn set_track_observation(&mut self, on: bool);
    /// Whether observations end with the track offset ([`Env::set_track_observation`]).
    fn track_observation(&self) -> bool;
    /// The robot's position in plan space.
    fn position(&self) -> &[f64];
    /// The robot's heading: yaw about the vertical axis (rad).
    fn heading(&self) -> f64;
    /// Radius of the robot's collision shape (m).
    fn radius(&self) -> f64;
    /// Writes the current observation.
    fn observe(&self, obs: &mut [f64]);
    /// Steps taken in this episode.
    fn steps(&self) -> usize;
    /// Sets the step limit.
    fn set_max_steps(&mut self, max_steps: usize);
    /// A random free goal from the environment's generator (used by trainers).
    fn sample_goal(&mut self) -> Vec<f64>;
    /// A random free goal beyond the reach radius and within `within` metres of the
    /// robot (uniform in that ball, clipped to the map's region), from the
    /// environment's generator; a goal from [`Env::sample_goal`] where none is found in
    /// [`NEAR_GOAL_TRIES`] draws (a ball with no free point in it).
    fn sample_goal_within(&mut self, within: f64) -> Vec<f64>;
    /// The whole mutable state (robot, goal, counters, random stream) as JSON, so a
    /// training run can be checkpointed and resumed exactly.
    fn save_state(&self) -> String;
    /// Restores a state written by [`Env::save_state`] for the same robot; on error
    /// the environment is unchanged.
    fn restore_state(&mut self, state: &str) -> Result<(), EnvError>;

    /// [`Env::reset_into`], returning the observation.
    fn reset(&mut self, seed: u64, start: Option<&[f64]>) -> Result<Vec<f64>, EnvError> {
        let mut obs = vec![0.0; self.observation_space().dim()];
        self.reset_into(seed, start, &mut obs)?;
        Ok(obs)
    }

    /// [`Env::step_into`], returning the observation.
    fn step(&mut self, action: &[f64]) -> Result<(Vec<f64>, Step), EnvError> {
        let mut obs = vec![0.0; self.observation_space().dim()];
        let s = self.step_into(action, &mut obs)?;
        Ok((obs, s))
    }
}

/// A robot's equations of motion and sensors, wrapped by [`GoalEnv`].
pub trait Dynamics: Send + Clone + serde::Serialize + serde::de::DeserializeOwned {
    /// Robot name.
    const NAME: &'static str;
    /// Observation length.
    const OBS_DIM: usize;
    /// Action length.
    const ACT_DIM: usize;
    /// Plan-space dimension.
    const PLAN_DIM: usize;
    /// Goal reach radius.
    const REACH_RADIUS: f64;
    /// Radius of the robot's collision shape.
    const RADIUS: f64;
    /// Action bounds: `[−1, 1]` in every dimension (all robots' control ranges).
    fn action_space() -> BoxSpace {
        BoxSpace::new(vec![-1.0; Self::ACT_DIM], vec![1.0; Self::ACT_DIM])
    }
    /// Observation bounds: unbounded (sensor readings are not clipped).
    fn observation_space() -> BoxSpace {
        BoxSpace::new(vec![f64::NEG_INFINITY; Self::OBS_DIM], vec![f64::INFINITY; Self::OBS_DIM])
    }
    /// Puts the robot at rest at `start` (plan space) with a heading from `rng`.
    fn reset(&mut self, start: &[f64], rng: &mut ChaCha8Rng);
    /// Advances one control step under `action` (already clipped); returns whether
    /// the robot touched an obstacle.
    fn advance(&mut self, action: &[f64], map: &Map, goal: &[f64]) -> bool;
    /// Position in plan space.
    fn plan_position(&self) -> &[f64];
    /// Yaw about the vertical axis (rad).
    fn yaw(&self) -> f64;
    /// Writes the observation for `goal`.
    fn observe(&self, goal: &[f64], obs: &mut [f64]);
    /// `true` once the robot has fallen over (robots that cannot fall: never).
    fn fallen(&self) -> bool {
        false
    }
}

/// A robot with goal, reward and episode bookkeeping: the [`Env`] for every robot.
#[derive(Clone)]
pub struct GoalEnv<D: Dynamics> {
    robot: D,
    map: Map,
    goal: Vec<f64>,
    goal_origin: Vec<f64>,
    prev_dist: f64,
    goal_reached: bool,
    reach_radius: f64,
    steps: usize,
    max_steps: usize,
    rng: ChaCha8Rng,
    track_observation: bool,
    obs_space: BoxSpace,
    act_space: BoxSpace,
}

impl<D: Dynamics> GoalEnv<D> {
    /// The robot on `map`, reset with seed 0.
    pub fn new(robot: D, map: Map) -> Result<Self, EnvError> {
        if map.dim() != D::PLAN_DIM {
            return Err(EnvError::MapMismatch {
                robot: D::NAME,
                map: map.name(),
                needs: D::PLAN_DIM,
                has: map.dim(),
            });
        }
        let mut env = Self {
            robot,
            map,
            goal: vec![0.0; D::PLAN_DIM],
            goal_origin: vec![0.0; D::PLAN_DIM],
            prev_dist: 0.0,
            goal_reached: false,
            reach_radius: D::REACH_RADIUS,
            steps: 0,
            max_steps: DEFAULT_MAX_STEPS,
            rng: ChaCha8Rng::seed_from_u64(0),
            track_observation: false,
            obs_space: D::observation_space(),
            act_space: D::action_space(),
        };
        let mut obs = vec![0.0; D::OBS_DIM];
        env.reset_into(0, None, &mut obs)?;
        Ok(env)
    }

    /// The robot's dynamics (for tests and rendering).
    pub fn dynamics(&self) -> &D {
        &self.robot
    }

    /// Mutable access to the dynamics (for tests that set a state).
    pub fn dynamics_mut(&mut self) -> &mut D {
        &mut self.robot
    }

    fn clearance() -> f64 {
        D::RADIUS + 0.1
    }

    fn free_point(&mut self) -> Vec<f64> {
        let (lo, hi) = self.map.region();
        loop {
            let p: Vec<f64> = lo.iter().zip(&hi).map(|(l, h)| self.rng.random_range(*l..*h)).collect();
            if self.map.sdf(&p) > Self::clearance() {
                return p;
            }
        }
    }

    fn check_point(what: &'static str, p: &[f64]) -> Result<(), EnvError> {
        if p.len() != D::PLAN_DIM || p.iter().any(|v| !v.is_finite()) {
            return Err(EnvError::BadPoint { what, robot: D::NAME, expected: D::PLAN_DIM, got: p.to_vec() });
        }
        Ok(())
    }

    fn distance(&self) -> f64 {
        euclidean(self.robot.plan_position(), &self.goal)
    }

    fn check_obs(&self, obs: &[f64]) -> Result<(), EnvError> {
        if obs.len() != self.obs_space.dim() {
            return Err(EnvError::ObservationLength { expected: self.obs_space.dim(), got: obs.len() });
        }
        Ok(())
    }

    /// The robot's observation, then (with [`Env::set_track_observation`]) its offset
    /// from the track.
    fn write_observation(&self, obs: &mut [f64]) {
        let (own, track) = obs.split_at_mut(D::OBS_DIM);
        self.robot.observe(&self.goal, own);
        if self.track_observation {
            let p = self.robot.plan_position();
            let (a, b) = (&self.goal_origin, &self.goal);
            let s = crate::segment::closest_fraction(p, a, b);
            // Plan spaces are 2-D or 3-D (checked when the robot's code is compiled);
            // no allocation on the step's path.
            const { assert!(D::PLAN_DIM == 2 || D::PLAN_DIM == 3, "a plan space is 2-D or 3-D") };
            let mut d = [0.0; 3];
            for (k, dk) in d.iter_mut().enumerate().take(D::PLAN_DIM) {
                *dk = a[k] + s * (b[k] - a[k]) - p[k];
            }
            let (sin, cos) = self.robot.yaw().sin_cos();
            track[0] = cos * d[0] + sin * d[1];
            track[1] = -sin * d[0] + cos * d[1];
            track[2..].copy_from_slice(&d[2..D::PLAN_DIM]);
        }
    }
}

impl<D: Dynamics> Env for GoalEnv<D> {
    fn robot_name(&self) -> &'static str {
        D::NAME
    }

    fn map(&self) -> &Map {
        &self.map
    }

    fn observation_space(&self) -> &BoxSpace {
        &self.obs_space
    }

    fn action_space(&self) -> &BoxSpace {
        &self.act_space
    }

    fn plan_dim(&self) -> usize {
        D::PLAN_DIM
    }

    fn reach_radius(&self) -> f64 {
        self.reach_radius
    }

    fn set_reach_radius(&mut self, radius: f64) -> Result<(), EnvError> {
        if !(radius.is_finite() && radius > 0.0) {
            return Err(EnvError::BadReachRadius { robot: D::NAME, radius });
        }
        self.reach_radius = radius;
        Ok(())
    }

    fn reset_into(&mut self, seed: u64, start: Option<&[f64]>, obs: &mut [f64]) -> Result<(), EnvError> {
        self.check_obs(obs)?;
        if let Some(s) = start {
            Self::check_point("start", s)?;
            if self.map.sdf(s) <= D::RADIUS {
                return Err(EnvError::StartBlocked {
                    start: s.to_vec(),
                    map: self.map.name(),
                    clearance: D::RADIUS,
                });
            }
        }
        self.rng = ChaCha8Rng::seed_from_u64(seed);
        let start = match start {
            Some(s) => s.to_vec(),
            None => self.free_point(),
        };
        self.robot.reset(&start, &mut self.rng);
        self.goal_origin.copy_from_slice(self.robot.plan_position());
        self.goal = self.free_point();
        self.goal_reached = false;
        self.prev_dist = self.distance();
        self.steps = 0;
        self.write_observation(obs);
        Ok(())
    }

    fn step_into(&mut self, action: &[f64], obs: &mut [f64]) -> Result<Step, EnvError> {
        if action.len() != D::ACT_DIM {
            return Err(EnvError::ActionLength { robot: D::NAME, expected: D::ACT_DIM, got: action.len() });
        }
        if let Some((index, &value)) = action.iter().enumerate().find(|(_, v)| !v.is_finite()) {
            return Err(EnvError::NonFiniteAction { robot: D::NAME, index, value });
        }
        self.check_obs(obs)?;
        let mut a = [0.0; 32];
        let a = &mut a[..D::ACT_DIM];
        for (i, (o, v)) in a.iter_mut().zip(action).enumerate() {
            *o = v.clamp(self.act_space.low[i], self.act_space.high[i]);
        }
        let collided = self.robot.advance(a, &self.map, &self.goal);
        self.steps += 1;
        let dist = self.distance();
        let mut reward = self.prev_dist - dist;
        self.prev_dist = dist;
        let reached = !self.goal_reached && dist <= self.reach_radius;
        if reached {
            self.goal_reached = true;
            reward += REACH_BONUS;
        }
        self.write_observation(obs);
        let fell = self.robot.fallen();
        Ok(Step { reward, reached, collided, truncated: self.steps >= self.max_steps, fell })
    }

    fn set_goal(&mut self, goal: &[f64]) -> Result<(), EnvError> {
        Self::check_point("goal", goal)?;
        self.goal.copy_from_slice(goal);
        self.goal_origin.copy_from_slice(self.robot.plan_position());
        self.goal_reached = false;
        self.prev_dist = self.distance();
        Ok(())
    }

    fn goal(&self) -> &[f64] {
        &self.goal
    }

    fn goal_origin(&self) -> &[f64] {
        &self.goal_origin
    }

    fn set_goal_origin(&mut self, origin: &[f64]) -> Result<(), EnvError> {
        Self::check_point("goal origin", origin)?;
        self.goal_origin.copy_from_slice(origin);
        Ok(())
    }

    fn set_track_observation(&mut self, on: bool) {
        self.track_observation = on;
        let mut space = D::observation_space();
        if on {
            space.low.extend(std::iter::repeat_n(f64::NEG_INFINITY, D::PLAN_DIM));
            space.high.extend(std::iter::repeat_n(f64::INFINITY, D::PLAN_DIM));
        }
        self.obs_space = space;
    }

    fn track_observation(&self) -> bool {
        self.track_observation
    }

    fn position(&self) -> &[f64] {
        self.robot.plan_position()
    }

    fn heading(&self) -> f64 {
        self.robot.yaw()
    }

    fn radius(&self) -> f64 {
        D::RADIUS
    }

    fn observe(&self, obs: &mut [f64]) {
        self.write_observation(obs);
    }

    fn steps(&self) -> usize {
        self.steps
    }

    fn set_max_steps(&mut self, max_steps: usize) {
        self.max_steps = max_steps;
    }

    fn sample_goal(&mut self) -> Vec<f64> {
        self.free_point()
    }

    fn sample_goal_within(&mut self, within: f64) -> Vec<f64> {
        let (lo, hi) = self.map.region();
        let at = self.robot.plan_position().to_vec();
        let bounds: Vec<(f64, f64)> =
            lo.iter().zip(&hi).zip(&at).map(|((l, h), c)| (l.max(c - within), h.min(c + within))).collect();
        if bounds.iter().all(|(l, h)| l < h) {
            for _ in 0..NEAR_GOAL_TRIES {
                let p: Vec<f64> = bounds.iter().map(|(l, h)| self.rng.random_range(*l..*h)).collect();
                let d = euclidean(&p, &at);
                if d <= within && d > self.reach_radius && self.map.sdf(&p) > Self::clearance() {
                    return p;
                }
            }
        }
        self.free_point()
    }

    fn save_state(&self) -> String {
        let state = SavedState {
            robot_name: D::NAME.to_string(),
            robot: self.robot.clone(),
            goal: self.goal.clone(),
            goal_origin: Some(self.goal_origin.clone()),
            prev_dist: self.prev_dist,
            goal_reached: self.goal_reached,
            steps: self.steps,
            max_steps: self.max_steps,
            rng: self.rng.clone(),
        };
        serde_json::to_string(&state).expect("environment states are plain numbers")
    }

    fn restore_state(&mut self, state: &str) -> Result<(), EnvError> {
        let bad = |reason: String| EnvError::BadState { robot: D::NAME, reason };
        let s: SavedState<D> = serde_json::from_str(state).map_err(|e| bad(e.to_string()))?;
        if s.robot_name != D::NAME {
            return Err(bad(format!("it is the state of a {}", s.robot_name)));
        }
        Self::check_point("goal", &s.goal)?;
        self.robot = s.robot;
        self.goal = s.goal;
        // States saved before it existed: the robot's position stands in for it.
        let origin = s.goal_origin.unwrap_or_else(|| self.robot.plan_position().to_vec());
        Self::check_point("goal origin", &origin)?;
        self.goal_origin = origin;
        self.prev_dist = s.prev_dist;
        self.goal_reached = s.goal_reached;
        self.steps = s.steps;
        self.max_steps = s.max_steps;
        self.rng = s.rng;
        Ok(())
    }
}

/// What [`Env::save_state`] writes.
#[derive(serde::Serialize, serde::Deserialize)]
struct SavedState<D> {
    robot_name: String,
    robot: D,
    goal: Vec<f64>,
    #[serde(default)]
    goal_origin: Option<Vec<f64>>,
    prev_dist: f64,
    goal_reached: bool,
    steps: usize,
    max_steps: usize,
    rng: ChaCha8Rng,
}
