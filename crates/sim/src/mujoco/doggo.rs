//! Doggo: the paper's quadruped (observation 58, action 12), on MuJoCo.
//!
//! The model is `assets/doggo.xml` ([`DOGGO_XML`]), written for this project from
//! the reference setup's facts; the walls of the map are added to it as MuJoCo boxes
//! (17 squares of 0.5 m, 0.5 m tall) when it is compiled, so legs and torso meet them
//! in MuJoCo's contact solver.
//!
//! | parameter | value | source |
//! |---|---|---|
//! | physics step | 0.005 s, 10 per control step | reference setup |
//! | joints | per leg: hip yaw −10°..30°, hip pitch −75°..0°, knee −75°..0° | reference setup |
//! | motors | 12 torque motors, ctrl ±1, gear 0.0125 | reference setup |
//! | touch sensors | 8: each leg's foot and shin | reference setup (8), placement ours |
//! | mass | 0.05 kg torso, 5 g per limb segment, 2 g per foot (0.098 kg) | this project |
//! | reach radius | 0.3 m | reference setup |
//!
//! Observation (58): accelerometer, velocimeter, gyro, magnetometer (3 each, torso
//! frame), the 8 touch sensors, the 12 joint velocities, the sines and then the
//! cosines of the 12 joint angles, and the goal vector in the robot's yaw frame (2).
//! Actions are the 12 motor controls in the order front-left, front-right, back-left,
//! back-right, each leg hip yaw, hip pitch, knee.
//!
//! A fall — the torso's centre below [`FALL_HEIGHT`], or the torso tilted past 60°
//! ([`FALL_TILT_COS`]: on its side or upside down) — is reported by [`crate::Step::fell`] and ends the episode like a collision.

use std::sync::{Arc, OnceLock};

use mujoco_rs::prelude::{MjData, MjModel, MjtObjBase};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use super::{compile, id_of};
use crate::env::{Dynamics, EnvError};
use crate::map::{Map, WALL_CENTERS, WALL_HALF};
use crate::robots::{Heading, random_yaw};

/// The MJCF model; the line `__WALLS__` is replaced by the map's wall boxes.
pub const DOGGO_XML: &str = include_str!("../../assets/doggo.xml");

/// A torso centre lower than this (m) counts as a fall: standing it is at 0.164 m,
/// lying on its belly at 0.05 m.
pub const FALL_HEIGHT: f64 = 0.08;

/// A torso tilted further than 60° from upright (on its side, or upside down) has
/// fallen: the cosine of that angle, compared with the up axis's vertical part.
pub const FALL_TILT_COS: f64 = 0.5;

const NAME: &str = "doggo";
const SUBSTEPS: usize = 10;
/// Height of the torso's centre at a reset: 1 cm above the standing height, so the
/// feet start clear of the floor and settle onto it.
const START_HEIGHT: f64 = 0.175;
/// Half the height of a wall box (m).
const WALL_HALF_HEIGHT: f64 = 0.25;
/// Sensor values the model declares: 4 inertial sensors of 3, then 8 touch sensors.
const SENSORS: usize = 20;
const JOINTS: usize = 12;
/// Free joint: 7 position numbers (x, y, z, quaternion w x y z), 6 velocity numbers.
const FREE_NQ: usize = 7;
const FREE_NV: usize = 6;

/// A compiled model with the ids the robot needs.
struct Compiled {
    model: Arc<MjModel>,
    /// Geom ids of the walls: contact with one is a collision.
    walls: std::ops::Range<usize>,
}

/// The MJCF for `map`: [`DOGGO_XML`] with one box per wall square.
fn xml_for(map: &Map) -> String {
    let walls: String = match map {
        Map::Walls(_) => WALL_CENTERS
            .iter()
            .enumerate()
            .map(|(i, c)| {
                format!(
                    "<geom name=\"wall{i}\" class=\"obstacle\" type=\"box\" pos=\"{} {} {WALL_HALF_HEIGHT}\" \
                     size=\"{WALL_HALF} {WALL_HALF} {WALL_HALF_HEIGHT}\"/>\n    ",
                    c[0], c[1]
                )
            })
            .collect(),
        _ => String::new(),
    };
    DOGGO_XML.replacen("__WALLS__", &walls, 1)
}

fn compile_for(map: &Map) -> Result<Arc<Compiled>, EnvError> {
    let model = compile(NAME, &xml_for(map))?;
    let expect = |what: &str, got: usize, want: usize| {
        if got == want {
            Ok(())
        } else {
            Err(EnvError::Mujoco {
                robot: NAME,
                reason: format!("the model has {got} {what}, expected {want}"),
            })
        }
    };
    let m = model.ffi();
    expect("position coordinates", m.nq as usize, FREE_NQ + JOINTS)?;
    expect("actuators", m.nu as usize, JOINTS)?;
    expect("sensor values", m.nsensordata as usize, SENSORS)?;
    let walls = if matches!(map, Map::Walls(_)) {
        let first = id_of(&model, NAME, MjtObjBase::mjOBJ_GEOM, "wall0")?;
        first..first + WALL_CENTERS.len()
    } else {
        0..0
    };
    Ok(Arc::new(Compiled { model: Arc::new(model), walls }))
}

/// The compiled model for `map`, compiled once per process and shared by every Doggo
/// on that map.
fn compiled(map: &Map) -> Result<Arc<Compiled>, EnvError> {
    static WALLS: OnceLock<Result<Arc<Compiled>, EnvError>> = OnceLock::new();
    static EMPTY: OnceLock<Result<Arc<Compiled>, EnvError>> = OnceLock::new();
    let cell = match map {
        Map::Walls(_) => &WALLS,
        Map::Empty(_) => &EMPTY,
        Map::Duck(_) | Map::Floor => {
            return Err(EnvError::MapMismatch { robot: NAME, map: map.name(), needs: 2, has: map.dim() });
        }
    };
    cell.get_or_init(|| compile_for(map)).clone()
}

/// The Doggo quadruped's state: MuJoCo's data for one robot.
#[derive(Clone)]
pub struct Doggo {
    compiled: Arc<Compiled>,
    map: &'static str,
    data: MjData<Arc<MjModel>>,
    pos: [f64; 2],
    fallen: bool,
}

impl Doggo {
    /// A Doggo standing at the origin of `map` (`walls` or `empty`).
    pub fn new(map: &Map) -> Result<Self, EnvError> {
        let compiled = compiled(map)?;
        let data = MjData::new(compiled.model.clone());
        let mut dog = Self { compiled, map: map.name(), data, pos: [0.0; 2], fallen: false };
        dog.place([0.0, 0.0], 0.0);
        Ok(dog)
    }

    /// MuJoCo's data (positions, velocities, contacts, sensors), read only.
    pub fn data(&self) -> &MjData<Arc<MjModel>> {
        &self.data
    }

    /// The torso's centre (x, y, z).
    pub fn torso_position(&self) -> [f64; 3] {
        let q = self.data.qpos();
        [q[0], q[1], q[2]]
    }

    /// The torso's up axis (unit vector, world frame).
    pub fn up_axis(&self) -> [f64; 3] {
        let q = self.data.qpos();
        let (w, x, y, z) = (q[3], q[4], q[5], q[6]);
        [2.0 * (x * z + w * y), 2.0 * (y * z - w * x), 1.0 - 2.0 * (x * x + y * y)]
    }

    /// The 8 touch sensors (N): feet front-left, front-right, back-left, back-right,
    /// then the shins in the same order.
    pub fn touch(&self) -> [f64; 8] {
        let mut t = [0.0; 8];
        t.copy_from_slice(&self.data.sensordata()[12..SENSORS]);
        t
    }

    /// `true` once the robot has fallen (torso too low, on its side or upside down).
    pub fn has_fallen(&self) -> bool {
        self.fallen
    }

    /// Puts the robot at rest at `xy` with heading `yaw`, joints at zero.
    fn place(&mut self, xy: [f64; 2], yaw: f64) {
        self.data.reset();
        let (s, c) = (0.5 * yaw).sin_cos();
        self.data.qpos_mut()[..FREE_NQ].copy_from_slice(&[xy[0], xy[1], START_HEIGHT, c, 0.0, 0.0, s]);
        // Sensors and contacts of the start state, for the first observation.
        self.data.forward();
        self.pos = xy;
        self.fallen = false;
    }

    fn touches_wall(&self) -> bool {
        let walls = &self.compiled.walls;
        !walls.is_empty()
            && self
                .data
                .contact()
                .iter()
                .any(|c| walls.contains(&(c.geom[0] as usize)) || walls.contains(&(c.geom[1] as usize)))
    }

    fn state(&self) -> DoggoState {
        DoggoState {
            map: self.map.to_string(),
            time: self.data.time(),
            qpos: self.data.qpos().to_vec(),
            qvel: self.data.qvel().to_vec(),
            ctrl: self.data.ctrl().to_vec(),
            qacc_warmstart: self.data.qacc_warmstart().to_vec(),
            sensordata: self.data.sensordata().to_vec(),
            fallen: self.fallen,
        }
    }

    fn set_state(&mut self, s: &DoggoState) -> Result<(), String> {
        let len = |what: &str, got: usize, want: usize| {
            if got == want { Ok(()) } else { Err(format!("{what} has {got} numbers, expected {want}")) }
        };
        len("qpos", s.qpos.len(), FREE_NQ + JOINTS)?;
        len("qvel", s.qvel.len(), FREE_NV + JOINTS)?;
        len("ctrl", s.ctrl.len(), JOINTS)?;
        len("qacc_warmstart", s.qacc_warmstart.len(), FREE_NV + JOINTS)?;
        len("sensordata", s.sensordata.len(), SENSORS)?;
        self.data.set_time(s.time);
        self.data.qpos_mut().copy_from_slice(&s.qpos);
        self.data.qvel_mut().copy_from_slice(&s.qvel);
        self.data.ctrl_mut().copy_from_slice(&s.ctrl);
        self.data.qacc_warmstart_mut().copy_from_slice(&s.qacc_warmstart);
        // Derived quantities (contacts, body frames) of the restored state; the
        // sensors keep the values read before saving, as the observation did.
        self.data.forward();
        self.data.sensordata_mut().copy_from_slice(&s.sensordata);
        self.pos = [s.qpos[0], s.qpos[1]];
        self.fallen = s.fallen;
        Ok(())
    }
}

/// What a saved Doggo holds: MuJoCo's state variables (everything the next step
/// depends on, including the solver's warm start) and the last sensor readings.
#[derive(Serialize, Deserialize)]
struct DoggoState {
    map: String,
    time: f64,
    qpos: Vec<f64>,
    qvel: Vec<f64>,
    ctrl: Vec<f64>,
    qacc_warmstart: Vec<f64>,
    sensordata: Vec<f64>,
    fallen: bool,
}

impl Serialize for Doggo {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        self.state().serialize(serializer)
    }
}

impl<'de> Deserialize<'de> for Doggo {
    fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        use serde::de::Error;
        let s = DoggoState::deserialize(deserializer)?;
        let map = Map::by_name(&s.map).ok_or_else(|| D::Error::custom(format!("unknown map '{}'", s.map)))?;
        let mut dog = Doggo::new(&map).map_err(D::Error::custom)?;
        dog.set_state(&s).map_err(D::Error::custom)?;
        Ok(dog)
    }
}

impl Dynamics for Doggo {
    const NAME: &'static str = NAME;
    const OBS_DIM: usize = 58;
    const ACT_DIM: usize = JOINTS;
    const PLAN_DIM: usize = 2;
    const REACH_RADIUS: f64 = 0.3;
    /// Feet stand about 0.25 m from the torso's centre.
    const RADIUS: f64 = 0.25;

    fn reset(&mut self, start: &[f64], rng: &mut ChaCha8Rng) {
        let yaw = random_yaw(rng);
        self.place([start[0], start[1]], yaw);
    }

    fn advance(&mut self, action: &[f64], _map: &Map, _goal: &[f64]) -> bool {
        self.data.ctrl_mut().copy_from_slice(action);
        let mut collided = false;
        for _ in 0..SUBSTEPS {
            self.data.step();
            collided |= self.touches_wall();
            // Checked every physics step, so that a fall is seen even if the robot
            // bounces back within the control step.
            self.fallen |= self.torso_position()[2] < FALL_HEIGHT || self.up_axis()[2] < FALL_TILT_COS;
        }
        let [x, y, _] = self.torso_position();
        self.pos = [x, y];
        collided
    }

    fn fallen(&self) -> bool {
        self.fallen
    }

    fn plan_position(&self) -> &[f64] {
        &self.pos
    }

    fn yaw(&self) -> f64 {
        let q = self.data.qpos();
        let (w, x, y, z) = (q[3], q[4], q[5], q[6]);
        (2.0 * (w * z + x * y)).atan2(1.0 - 2.0 * (y * y + z * z))
    }

    fn observe(&self, goal: &[f64], obs: &mut [f64]) {
        let (qpos, qvel) = (self.data.qpos(), self.data.qvel());
        obs[..SENSORS].copy_from_slice(&self.data.sensordata()[..SENSORS]);
        obs[SENSORS..SENSORS + JOINTS].copy_from_slice(&qvel[FREE_NV..]);
        for (j, q) in qpos[FREE_NQ..].iter().enumerate() {
            let (s, c) = q.sin_cos();
            obs[SENSORS + JOINTS + j] = s;
            obs[SENSORS + 2 * JOINTS + j] = c;
        }
        let to_goal = [goal[0] - self.pos[0], goal[1] - self.pos[1]];
        let g = Heading::new(self.yaw()).to_body(to_goal);
        obs[SENSORS + 3 * JOINTS..SENSORS + 3 * JOINTS + 2].copy_from_slice(&g);
    }
}
