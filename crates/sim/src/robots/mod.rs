//! The robots: equations of motion and sensors, one module each.

pub mod car;
pub mod drone;
pub mod point;

/// Gravity (m/s²); the reference Drone uses 9.8, Safety Gym's MuJoCo 9.81.
pub const GRAVITY: f64 = 9.81;

/// MuJoCo's default global magnetic field (T), read by the magnetometers.
pub const MAGNETIC_FIELD: [f64; 3] = [0.0, -0.5, 0.0];

/// The inertial sensors of a planar robot, in its frame (x forward, y left, z up):
/// accelerometer (with +g on z, as MuJoCo's reads specific force), velocimeter, gyro,
/// magnetometer; then the goal vector. Writes 14 numbers.
pub fn planar_sensors(
    h: &Heading,
    accel: [f64; 2],
    vel: [f64; 2],
    yaw_rate: f64,
    to_goal: [f64; 2],
    out: &mut [f64],
) {
    let [ax, ay] = h.to_body(accel);
    let [vx, vy] = h.to_body(vel);
    let [mx, my] = h.to_body([MAGNETIC_FIELD[0], MAGNETIC_FIELD[1]]);
    let [gx, gy] = h.to_body(to_goal);
    out[..14].copy_from_slice(&[
        ax,
        ay,
        GRAVITY,
        vx,
        vy,
        0.0,
        0.0,
        0.0,
        yaw_rate,
        mx,
        my,
        MAGNETIC_FIELD[2],
        gx,
        gy,
    ]);
}

/// A heading drawn uniformly from (−π, π], for resets.
pub fn random_yaw(rng: &mut rand_chacha::ChaCha8Rng) -> f64 {
    use rand::Rng;
    rng.random_range(-std::f64::consts::PI..std::f64::consts::PI)
}

/// A planar heading kept as a unit vector, turned by small angles without calling
/// `sin`/`cos` in the physics loop.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Heading {
    c: f64,
    s: f64,
}

impl Heading {
    /// The heading at angle `theta` (rad).
    pub fn new(theta: f64) -> Self {
        let (s, c) = theta.sin_cos();
        Self { c, s }
    }

    /// The angle (rad), in (−π, π].
    pub fn angle(&self) -> f64 {
        self.s.atan2(self.c)
    }

    /// The unit vector.
    #[inline]
    pub fn dir(&self) -> [f64; 2] {
        [self.c, self.s]
    }

    /// Turns by `dtheta`. Physics steps turn by milliradians, where a 4th-order
    /// Taylor expansion is exact to 1e-15; larger turns use `sin_cos`.
    /// Returns the turn's `(sin, cos)`, so that body-frame vectors can follow it.
    #[inline]
    pub fn rotate(&mut self, dtheta: f64) -> (f64, f64) {
        let (s, c) = if dtheta.abs() < 0.05 {
            let d2 = dtheta * dtheta;
            (
                dtheta * (1.0 - d2 * (1.0 / 6.0) * (1.0 - d2 * (1.0 / 20.0))),
                1.0 - d2 * (1.0 / 2.0) * (1.0 - d2 * (1.0 / 12.0)),
            )
        } else {
            dtheta.sin_cos()
        };
        let (c0, s0) = (self.c, self.s);
        self.c = c0 * c - s0 * s;
        self.s = s0 * c + c0 * s;
        (s, c)
    }

    /// Removes rounding drift from the unit length.
    pub fn normalize(&mut self) {
        let k = crate::rotation::inv_norm(self.c * self.c + self.s * self.s);
        self.c *= k;
        self.s *= k;
    }

    /// A world-frame vector in the body frame (x forward, y left).
    #[inline]
    pub fn to_body(&self, v: [f64; 2]) -> [f64; 2] {
        [self.c * v[0] + self.s * v[1], -self.s * v[0] + self.c * v[1]]
    }

    /// A body-frame vector in the world frame.
    #[inline]
    pub fn to_world(&self, v: [f64; 2]) -> [f64; 2] {
        [self.c * v[0] - self.s * v[1], self.s * v[0] + self.c * v[1]]
    }
}
