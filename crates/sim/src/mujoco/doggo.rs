//! Doggo: the paper's quadruped (observation 74, action 14: 12 motors and the gait's
//! amplitude and steer), on MuJoCo.
//!
//! The model is `assets/doggo.xml` ([`DOGGO_XML`]): Safety-Gym's Doggo, written for
//! this project from the facts of its public MJCF; the walls of the map are added to
//! it as MuJoCo boxes (17 squares of 0.5 m, 0.5 m tall) when it is compiled, so legs
//! and torso meet them in MuJoCo's contact solver.
//!
//! | parameter | value | source |
//! |---|---|---|
//! | body | front and rear torso cylinders (r 0.075, 0.2 m, density 0.5) on a passive waist hinge about x, ±30° | Safety-Gym's `doggo.xml` |
//! | legs | capsules r 0.032, density 5; thigh (0.098, ±0.0566, −0.05), lower leg (−0.1176, ∓0.0679, −0.1) | Safety-Gym's `doggo.xml` |
//! | joints | per leg hip z −10°..30°, hip y −75°..15° (front) / 0°..135° (rear), ankle −75°..0° | Safety-Gym's `doggo.xml` |
//! | springs | stiffness 0.01 on every joint towards its reference: front hip y −10°, ankles −20°, others 0 | Safety-Gym's `doggo.xml` |
//! | motors | 12 torque motors, ctrl ±1, gear 0.0125 | Safety-Gym's `doggo.xml` |
//! | contact | condim 6, MuJoCo's default friction, legs collide with each other | Safety-Gym's `doggo.xml` |
//! | physics step | 0.01 s, 10 per control step | Safety-Gym's `doggo.xml` and frame skip |
//! | touch sensors | 8: each lower leg's ankle and foot | Safety-Gym's `doggo.xml` |
//! | reach radius | 0.3 m | reference setup |
//!
//! Observation (74): accelerometer, velocimeter, gyro, magnetometer (3 each, front
//! torso frame), the 8 touch sensors, the velocities of the 12 motor joints, the sines
//! and then the cosines of their angles, the goal vector in the robot's yaw frame (2),
//! the 14 filtered policy actions, and the sine and cosine of the gait's phase (zeros
//! without a gait); the passive waist is not observed, as in Safety-Gym.
//! Actions are the 12 motor commands in the order front-left, front-right, back-left,
//! back-right, each leg hip z, hip y, ankle, then the gait's amplitude `a` and steer;
//! all 14 pass through a low-pass filter ([`ACTION_FILTER`]). With a [`Gait`] (the
//! default, [`GAIT`]) the motors get the filtered commands plus the gait's open-loop
//! controls at every physics step, its stride scaled by `clamp(1 + a, 0, 1)` and its
//! hip-z swing by the steer, so the policy learns a residual on a rhythm that already
//! walks at full stride with actions 0, and can stop it (`a = −1`) and turn it, as
//! PMTG's policy modulates its trajectory generator; without a gait the 13th and 14th
//! actions do nothing. Safety-Gym's 58
//! observations and 12 controls are this with β = 0, no gait, and neither the controls
//! nor the phase observed.
//!
//! A fall — the torso's centre below [`FALL_HEIGHT`], or the front torso tilted past 60°
//! ([`FALL_TILT_COS`]) for [`FALL_TILT_SECONDS`] without a break: on its side or upside
//! down — is reported by [`crate::Step::fell`] and ends the episode like a collision. So
//! is a diverged physics step (on one, MuJoCo resets the data to the model's start), which
//! leaves the robot where it was last seen.

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

/// The motors' controls follow the policy's actions through a first-order low-pass
/// filter, `ctrl ← β ctrl + (1 − β) action` once per control step, with this β; the
/// controls are observed, so the policy sees what its motors are doing. Not in
/// Safety-Gym (there the action is the control): chosen on seed 0 against the
/// unfiltered Doggo, whose trained gaits flipped it in 8 % of episodes (README's Doggo
/// section).
pub const ACTION_FILTER: f64 = 0.5;

/// A torso centre lower than this (m) counts as a fall: standing it is at
/// [`STANDING_HEIGHT`], lying on its belly at the torso's radius, 0.075 m.
pub const FALL_HEIGHT: f64 = 0.08;

/// A torso tilted further than 60° from upright for [`FALL_TILT_SECONDS`] (on its side,
/// or upside down) has fallen: the cosine of that angle, compared with the up axis's
/// vertical part.
pub const FALL_TILT_COS: f64 = 0.5;

/// Seconds of simulated time a tilt past 60° must last to be a fall: a walking Doggo
/// rears past 60° and rights itself, a fallen one stays down. Twice the longest righting
/// measured (README's Doggo section).
pub const FALL_TILT_SECONDS: f64 = 2.0;

/// An open-loop gait: each physics step, the hip-y and ankle motors of every leg get
/// `A · hip_y · s · sin φ_leg` and `A · ankle · sin(φ_leg + ankle_lag)`, and its hip-z
/// motor `S · steer_signs_leg · sin(φ_leg + steer_lag)`, on top of the policy's filtered
/// controls (the sum clipped to the control range), where `φ_leg = 2π f t + offset_leg`,
/// `t` the simulated time since the reset, `s` −1 on the rear legs when `rear_reversed`,
/// and `A` ∈ [0, 1] and `S` ∈ [−1, 1] the amplitude and steer the policy sets (its 13th
/// and 14th actions, [`gait_amplitude`]). A gait prior in the manner of PMTG (Iscen et
/// al. 2018): the rhythm is fixed, the policy modulates its stride and its turning and
/// adds a residual. The steer is a swing in step with the stride because a turn made
/// of hip-z offsets set once a control step (10 Hz, filtered) cannot follow a 4 Hz
/// stride: the pronk steered that way turned 0.009 rad a step at most.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Gait {
    /// Cycles per second.
    pub freq_hz: f64,
    /// Phase offset of each leg (rad): front-left, front-right, back-left, back-right.
    pub offsets: [f64; 4],
    /// Amplitude on the hip-y motors (control units).
    pub hip_y: f64,
    /// Amplitude on the ankle motors (control units).
    pub ankle: f64,
    /// The ankle's phase relative to its hip (rad).
    pub ankle_lag: f64,
    /// Whether the rear hips swing against the front ones (their ranges face the other
    /// way: front −75°..15°, rear 0°..135°).
    pub rear_reversed: bool,
    /// The hip-z swing's phase relative to its hip-y swing (rad).
    #[serde(default)]
    pub steer_lag: f64,
    /// Each leg's hip-z swing at steer +1 (front-left, front-right, back-left,
    /// back-right); zeros: the gait does not steer (gaits saved before it could).
    #[serde(default)]
    pub steer_signs: [f64; 4],
}

impl Gait {
    /// All four legs in phase at 4 Hz, full hip and ankle swings half a cycle apart,
    /// rear hips reversed. Chosen by an open-loop sweep (zero policy action; 6 leg
    /// patterns × 2–8 Hz × ankle amplitude and lag × rear sign, then the leaders on 12
    /// starts of 1000 steps, straight, with ±0.3 random residuals, and steered by hip z):
    /// the fastest with no fall in any of those conditions. Its steer, the left hips
    /// swinging against the right half a cycle from the stride, turns it 0.072 rad a
    /// control step at steer +1 (to the left) on a circle of about 0.5 m radius: the
    /// fastest turn with no fall of 4 leg patterns × 8 phases (the sweep's stage 3;
    /// README's Doggo section).
    pub const PRONK: Gait = Gait {
        freq_hz: 4.0,
        offsets: [0.0; 4],
        hip_y: 1.0,
        ankle: 1.0,
        ankle_lag: std::f64::consts::PI,
        rear_reversed: true,
        steer_lag: std::f64::consts::PI,
        steer_signs: [1.0, -1.0, 1.0, -1.0],
    };

    /// Its phase (rad) at simulated time `t`.
    pub fn phase(&self, t: f64) -> f64 {
        2.0 * std::f64::consts::PI * self.freq_hz * t
    }

    /// Its controls at simulated time `t`, in action order, at stride amplitude
    /// `amplitude` (0–1) and steer `steer` (−1–1).
    pub fn controls(&self, t: f64, amplitude: f64, steer: f64) -> [f64; JOINTS] {
        let mut u = [0.0; JOINTS];
        for (leg, offset) in self.offsets.iter().enumerate() {
            let phi = self.phase(t) + offset;
            let sign = if leg >= 2 && self.rear_reversed { -1.0 } else { 1.0 };
            u[3 * leg] = steer * self.steer_signs[leg] * (phi + self.steer_lag).sin();
            u[3 * leg + 1] = amplitude * sign * self.hip_y * phi.sin();
            u[3 * leg + 2] = amplitude * self.ankle * (phi + self.ankle_lag).sin();
        }
        u
    }
}

/// The scale of the gait's controls for the filtered amplitude action `a`:
/// `clamp(1 + a, 0, 1)`, so an untrained policy (mean action 0) walks the full stride
/// and `a = −1` stops it (the steer's hip-z swing is set apart, by the 14th action).
pub fn gait_amplitude(a: f64) -> f64 {
    (1.0 + a).clamp(0.0, 1.0)
}

/// The gait a Doggo walks with unless told otherwise ([`Doggo::with_gait`]).
pub const GAIT: Option<Gait> = Some(Gait::PRONK);

const NAME: &str = "doggo";
const SUBSTEPS: usize = 10;
/// Height (m) of the torso's centre standing still with the motors off, on its springs
/// and joint limits (test `stands_at_its_standing_height_with_the_motors_off`).
pub const STANDING_HEIGHT: f64 = 0.161;
/// Height of the torso's centre at a reset, joints at zero: Safety-Gym's 0.22 m; the
/// robot drops onto its feet and settles within a few control steps.
const START_HEIGHT: f64 = 0.22;
/// Half the height of a wall box (m).
const WALL_HALF_HEIGHT: f64 = 0.25;
/// Sensor values the model declares: 4 inertial sensors of 3, then 8 touch sensors.
const SENSORS: usize = 20;
/// Motor joints (observed and driven).
const JOINTS: usize = 12;
/// Policy actions: one per motor, then the gait's amplitude and steer.
const ACTIONS: usize = JOINTS + 2;
/// Passive joints: the waist.
const PASSIVE: usize = 1;
/// Free joint: 7 position numbers (x, y, z, quaternion w x y z), 6 velocity numbers.
const FREE_NQ: usize = 7;
const FREE_NV: usize = 6;
/// Position and velocity numbers of the whole robot: the free joint and every hinge.
const NQ: usize = FREE_NQ + JOINTS + PASSIVE;
const NV: usize = FREE_NV + JOINTS + PASSIVE;

/// A compiled model with the ids the robot needs.
struct Compiled {
    model: Arc<MjModel>,
    /// Geom ids of the walls: contact with one is a collision.
    walls: std::ops::Range<usize>,
    /// Where each motor's joint (in action order) sits in `qpos` and in `qvel`.
    motor_qpos: [usize; JOINTS],
    motor_qvel: [usize; JOINTS],
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
    expect("position coordinates", m.nq as usize, NQ)?;
    expect("actuators", m.nu as usize, JOINTS)?;
    expect("sensor values", m.nsensordata as usize, SENSORS)?;
    let walls = if matches!(map, Map::Walls(_)) {
        let first = id_of(&model, NAME, MjtObjBase::mjOBJ_GEOM, "wall0")?;
        first..first + WALL_CENTERS.len()
    } else {
        0..0
    };
    let (mut motor_qpos, mut motor_qvel) = ([0; JOINTS], [0; JOINTS]);
    for (a, [joint, _]) in model.actuator_trnid().iter().enumerate() {
        motor_qpos[a] = model.jnt_qposadr()[*joint as usize] as usize;
        motor_qvel[a] = model.jnt_dofadr()[*joint as usize] as usize;
    }
    Ok(Arc::new(Compiled { model: Arc::new(model), walls, motor_qpos, motor_qvel }))
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
    /// Simulated time at which the current tilt past 60° began (none: upright).
    tilted_since: Option<f64>,
    /// The policy's actions after the low-pass filter: the motors get the first 12 plus
    /// the gait's controls at [`gait_amplitude`] of the 13th and the 14th's steer.
    filtered: [f64; ACTIONS],
    gait: Option<Gait>,
}

impl Doggo {
    /// A Doggo standing at the origin of `map` (`walls` or `empty`), walking with the
    /// default [`GAIT`].
    pub fn new(map: &Map) -> Result<Self, EnvError> {
        Self::with_gait(map, GAIT)
    }

    /// A Doggo standing at the origin of `map` whose motors follow `gait` under the
    /// policy's controls (none: the policy's controls alone).
    pub fn with_gait(map: &Map, gait: Option<Gait>) -> Result<Self, EnvError> {
        let compiled = compiled(map)?;
        let data = MjData::new(compiled.model.clone());
        let mut dog = Self {
            compiled,
            map: map.name(),
            data,
            pos: [0.0; 2],
            fallen: false,
            tilted_since: None,
            filtered: [0.0; ACTIONS],
            gait,
        };
        dog.place([0.0, 0.0], 0.0);
        Ok(dog)
    }

    /// The gait its motors follow.
    pub fn gait(&self) -> Option<Gait> {
        self.gait
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
    /// then the ankles in the same order.
    pub fn touch(&self) -> [f64; 8] {
        let mut t = [0.0; 8];
        t.copy_from_slice(&self.data.sensordata()[12..SENSORS]);
        t
    }

    /// The angles (rad) of the 12 motor joints, in action order.
    pub fn motor_angles(&self) -> [f64; JOINTS] {
        self.compiled.motor_qpos.map(|i| self.data.qpos()[i])
    }

    /// The compiled model (masses, joint ranges, springs, gears), read only.
    pub fn model(&self) -> &MjModel {
        &self.compiled.model
    }

    /// `true` if MuJoCo found a position, velocity or acceleration out of bounds (a
    /// diverged solve) since the last reset, and so reset the data to the model's start.
    fn diverged(&self) -> bool {
        use mujoco_rs::mujoco_c::mjtWarning::{mjWARN_BADQACC, mjWARN_BADQPOS, mjWARN_BADQVEL};
        let w = self.data.warning();
        [mjWARN_BADQPOS, mjWARN_BADQVEL, mjWARN_BADQACC].iter().any(|&k| w[k as usize].number > 0)
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
        self.tilted_since = None;
        self.filtered = [0.0; ACTIONS];
    }

    /// Sets the motors' controls for a physics step at simulated time `t`: the filtered
    /// policy controls plus the gait's at the filtered amplitude, clipped to the
    /// control range.
    fn drive(&mut self, t: f64) {
        let (amplitude, steer) = (gait_amplitude(self.filtered[JOINTS]), self.filtered[JOINTS + 1]);
        let gait = self.gait.map_or([0.0; JOINTS], |g| g.controls(t, amplitude, steer));
        for ((c, f), g) in self.data.ctrl_mut().iter_mut().zip(&self.filtered).zip(gait) {
            *c = (f + g).clamp(-1.0, 1.0);
        }
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
            filtered: Some(self.filtered.to_vec()),
            gait: self.gait,
            qacc_warmstart: self.data.qacc_warmstart().to_vec(),
            sensordata: self.data.sensordata().to_vec(),
            fallen: self.fallen,
            tilted_since: self.tilted_since,
        }
    }

    fn set_state(&mut self, s: &DoggoState) -> Result<(), String> {
        let len = |what: &str, got: usize, want: usize| {
            if got == want { Ok(()) } else { Err(format!("{what} has {got} numbers, expected {want}")) }
        };
        len("qpos", s.qpos.len(), NQ)?;
        len("qvel", s.qvel.len(), NV)?;
        len("ctrl", s.ctrl.len(), JOINTS)?;
        // States saved before the gait's amplitude and steer actions hold 12 filtered
        // controls: their gait ran at full amplitude without steering, actions 0.
        let mut filtered = s.filtered.clone().unwrap_or_else(|| s.ctrl.clone());
        if filtered.len() == JOINTS {
            filtered.extend([0.0, 0.0]);
        }
        len("filtered", filtered.len(), ACTIONS)?;
        len("qacc_warmstart", s.qacc_warmstart.len(), NV)?;
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
        self.tilted_since = s.tilted_since;
        self.filtered.copy_from_slice(&filtered);
        self.gait = s.gait;
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
    /// The filtered policy actions (12 in states saved before the gait's actions);
    /// absent in states saved before the gait, whose controls were the filtered
    /// policy's.
    #[serde(default)]
    filtered: Option<Vec<f64>>,
    /// Absent in states saved before the gait: none.
    #[serde(default)]
    gait: Option<Gait>,
    qacc_warmstart: Vec<f64>,
    sensordata: Vec<f64>,
    fallen: bool,
    /// Absent in states saved before tilts were timed: upright.
    #[serde(default)]
    tilted_since: Option<f64>,
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
        let mut dog = Doggo::with_gait(&map, s.gait).map_err(D::Error::custom)?;
        dog.set_state(&s).map_err(D::Error::custom)?;
        Ok(dog)
    }
}

impl Dynamics for Doggo {
    const NAME: &'static str = NAME;
    const OBS_DIM: usize = SENSORS + 3 * JOINTS + 2 + ACTIONS + 2;
    const ACT_DIM: usize = ACTIONS;
    const PLAN_DIM: usize = 2;
    const REACH_RADIUS: f64 = 0.3;
    /// Standing, the front knees' capsules reach 0.357 m from the centre (the farthest
    /// part; the feet 0.25–0.34 m).
    const RADIUS: f64 = 0.36;

    fn reset(&mut self, start: &[f64], rng: &mut ChaCha8Rng) {
        let yaw = random_yaw(rng);
        self.place([start[0], start[1]], yaw);
    }

    fn advance(&mut self, action: &[f64], _map: &Map, _goal: &[f64]) -> bool {
        for (c, a) in self.filtered.iter_mut().zip(action) {
            *c = ACTION_FILTER * *c + (1.0 - ACTION_FILTER) * a;
        }
        let mut collided = false;
        for _ in 0..SUBSTEPS {
            let before = self.data.time();
            self.drive(before);
            self.data.step();
            if self.diverged() {
                // MuJoCo has put the robot back at the model's start: the episode ends
                // here, the robot where it was last seen.
                self.fallen = true;
                return collided;
            }
            collided |= self.touches_wall();
            // Checked every physics step: a torso on the floor is a fall even if it
            // bounces back within the control step, and a tilt is timed to the step.
            let now = self.data.time();
            self.tilted_since = match self.tilted_since {
                _ if self.up_axis()[2] >= FALL_TILT_COS => None,
                // The tilt began within this physics step: timed from its start.
                None => Some(before),
                since => since,
            };
            let held = self.tilted_since.is_some_and(|t| now - t >= FALL_TILT_SECONDS - 1e-9);
            self.fallen |= self.torso_position()[2] < FALL_HEIGHT || held;
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
        let c = &self.compiled;
        for (j, (&iq, &iv)) in c.motor_qpos.iter().zip(&c.motor_qvel).enumerate() {
            obs[SENSORS + j] = qvel[iv];
            let (s, c) = qpos[iq].sin_cos();
            obs[SENSORS + JOINTS + j] = s;
            obs[SENSORS + 2 * JOINTS + j] = c;
        }
        let to_goal = [goal[0] - self.pos[0], goal[1] - self.pos[1]];
        let g = Heading::new(self.yaw()).to_body(to_goal);
        obs[SENSORS + 3 * JOINTS..SENSORS + 3 * JOINTS + 2].copy_from_slice(&g);
        let controls = SENSORS + 3 * JOINTS + 2;
        obs[controls..controls + ACTIONS].copy_from_slice(&self.filtered);
        let (s, c) = self.gait.map_or((0.0, 0.0), |g| g.phase(self.data.time()).sin_cos());
        obs[controls + ACTIONS..].copy_from_slice(&[s, c]);
    }
}
