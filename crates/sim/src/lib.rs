//! Native robot simulation for schrl: the robots, maps, and goal-conditioned
//! environments of the paper's experiments (§4.1, App. G), plus rendering.
//!
//! * [`env`](mod@env) — the [`Env`] trait (Gymnasium-shaped, goal-conditioned), the reward and
//!   reach logic ([`GoalEnv`]), spaces and errors.
//! * [`robots`] — [`Point`], [`Car`] and [`Drone`]: hand-written equations of motion,
//!   each parameter documented with its source.
//! * [`map`] — [`WallsMap`], [`EmptyMap`], [`DuckWorld`] with exact signed distances.
//! * [`segment`] — the clearance of straight segments (the paths between waypoints).
//! * [`contact`] — keeping robots out of obstacles.
//! * [`vec_env`] — N environments stepped together, deterministic under a seed.
//! * [`render`] — pictures of maps, robots, goals, waypoints and trajectories.
//! * `mujoco` (cargo feature `mujoco`) — the Doggo quadruped on MuJoCo 3.17.0, and
//!   MuJoCo twins of the Point and the Car for checking the native dynamics. Without the feature,
//!   [`make_env`] answers [`Robot::Doggo`] with [`EnvError::MujocoDisabled`], which
//!   says how to enable it.
//!
//! ```
//! use sim::{make_env, Env, Map, Robot};
//! let mut env = make_env(Robot::Point, Map::by_name("walls").unwrap()).unwrap();
//! let obs = env.reset(7, Some(&[1.5, -1.5])).unwrap();
//! assert_eq!(obs.len(), 14);
//! env.set_goal(&[2.0, -2.0]).unwrap();
//! let (_obs, step) = env.step(&[1.0, 0.0]).unwrap();
//! assert!(!step.collided);
//! ```

#![warn(missing_docs)]
// Index loops mirror the equations of motion they implement.
#![allow(clippy::needless_range_loop)]

pub mod contact;
pub mod env;
pub mod map;
#[cfg(feature = "mujoco")]
pub mod mujoco;
pub mod render;
pub mod robots;
pub mod rotation;
pub mod segment;
pub mod vec_env;

pub use env::{BoxSpace, Dynamics, Env, EnvError, GoalEnv, Step};
pub use map::{DuckWorld, EmptyMap, Map, WallsMap};
pub use robots::car::Car;
pub use robots::drone::Drone;
pub use robots::point::Point;
pub use vec_env::VecEnv;

/// The robots of the paper.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Robot {
    /// Safety Gym's Point.
    Point,
    /// Safety Gym's Car.
    Car,
    /// The quadrotor.
    Drone,
    /// The quadruped, on MuJoCo (cargo feature `mujoco`).
    Doggo,
}

impl Robot {
    /// The robots simulated natively, available in every build.
    pub const NATIVE: [Robot; 3] = [Robot::Point, Robot::Car, Robot::Drone];

    /// Every robot, including those this build may lack (see [`Robot::is_available`]).
    pub const ALL: [Robot; 4] = [Robot::Point, Robot::Car, Robot::Drone, Robot::Doggo];

    /// `true` if this build can simulate the robot (the Doggo needs the `mujoco` feature).
    pub fn is_available(self) -> bool {
        self != Robot::Doggo || cfg!(feature = "mujoco")
    }

    /// Its name.
    pub fn name(self) -> &'static str {
        match self {
            Robot::Point => "point",
            Robot::Car => "car",
            Robot::Drone => "drone",
            Robot::Doggo => "doggo",
        }
    }

    /// Whether a [`VecEnv`] of this robot steps its environments on all of rayon's
    /// threads: only the Doggo, whose MuJoCo step (about 250 µs) dwarfs a thread
    /// hand-off; a native robot's step takes about a microsecond, less than the
    /// hand-off itself.
    pub fn steps_in_parallel(self) -> bool {
        self == Robot::Doggo
    }

    /// The map it uses by default (walls for ground robots, the duck for the Drone).
    pub fn default_map(self) -> Map {
        match self {
            Robot::Drone => Map::Duck(DuckWorld::new()),
            _ => Map::Walls(WallsMap::new()),
        }
    }
}

impl std::str::FromStr for Robot {
    type Err = EnvError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "point" => Ok(Robot::Point),
            "car" => Ok(Robot::Car),
            "drone" => Ok(Robot::Drone),
            "doggo" => Ok(Robot::Doggo),
            other => Err(EnvError::UnknownRobot(other.to_string())),
        }
    }
}

impl std::fmt::Display for Robot {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// An environment for `robot` on `map`, reset with seed 0.
pub fn make_env(robot: Robot, map: Map) -> Result<Box<dyn Env>, EnvError> {
    Ok(match robot {
        Robot::Point => Box::new(GoalEnv::new(Point::default(), map)?),
        Robot::Car => Box::new(GoalEnv::new(Car::default(), map)?),
        Robot::Drone => Box::new(GoalEnv::new(Drone::default(), map)?),
        #[cfg(feature = "mujoco")]
        Robot::Doggo => {
            let dog = mujoco::Doggo::new(&map)?;
            Box::new(GoalEnv::new(dog, map)?)
        }
        #[cfg(not(feature = "mujoco"))]
        Robot::Doggo => return Err(EnvError::MujocoDisabled { robot: "doggo" }),
    })
}
