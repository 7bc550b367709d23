//! Unit quaternions for 3-D orientations (Drone body, Car caster ball).

/// A unit quaternion `w + xi + yj + zk` rotating body vectors into the world.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Quat {
    /// Scalar part.
    pub w: f64,
    /// Vector part.
    pub v: [f64; 3],
}

impl Default for Quat {
    fn default() -> Self {
        Self::IDENTITY
    }
}

impl Quat {
    /// No rotation.
    pub const IDENTITY: Quat = Quat { w: 1.0, v: [0.0; 3] };

    /// Rotation by `angle` about the z axis.
    pub fn from_yaw(angle: f64) -> Self {
        let (s, c) = (0.5 * angle).sin_cos();
        Quat { w: c, v: [0.0, 0.0, s] }
    }

    /// The product `self ⊗ o` (apply `o` first).
    #[inline]
    pub fn mul(&self, o: &Quat) -> Quat {
        let (a, b) = (self.v, o.v);
        Quat {
            w: self.w * o.w - (a[0] * b[0] + a[1] * b[1] + a[2] * b[2]),
            v: [
                self.w * b[0] + o.w * a[0] + a[1] * b[2] - a[2] * b[1],
                self.w * b[1] + o.w * a[1] + a[2] * b[0] - a[0] * b[2],
                self.w * b[2] + o.w * a[2] + a[0] * b[1] - a[1] * b[0],
            ],
        }
    }

    /// Integrates a body-frame angular velocity `omega` over `dt`:
    /// `q ← q ⊗ exp(ω dt / 2)` (exact for constant ω), then renormalises.
    pub fn integrate_body(&mut self, omega: [f64; 3], dt: f64) {
        self.integrate_body_unnormalized(omega, dt);
        self.normalize();
    }

    /// [`Quat::integrate_body`] without the final renormalisation, for physics loops
    /// that renormalise once per control step.
    #[inline]
    pub fn integrate_body_unnormalized(&mut self, omega: [f64; 3], dt: f64) {
        *self = self.mul(&Self::step(omega, dt));
    }

    /// Integrates a world-frame angular velocity: `q ← exp(ω dt / 2) ⊗ q`.
    #[inline]
    pub fn integrate_world(&mut self, omega: [f64; 3], dt: f64) {
        *self = Self::step(omega, dt).mul(self);
        self.normalize();
    }

    /// `exp(ω dt / 2)`: the rotation by `|ω| dt` about `ω`. For half-angles
    /// `h = |ω| dt / 2 < 0.3` (every physics step, and a rolling caster over a
    /// control step) Taylor series in `h²` to degree 10 give `cos h` and
    /// `sin(h)/h` to 2e-12 without a square root or `sin_cos`.
    #[inline]
    fn step(omega: [f64; 3], dt: f64) -> Quat {
        let n2 = omega[0] * omega[0] + omega[1] * omega[1] + omega[2] * omega[2];
        let h2 = 0.25 * n2 * dt * dt;
        let (c, k) = if h2 < 4e-4 {
            // A physics step's turn (h < 0.02): degree 4 is exact to rounding.
            let x2 = h2 * h2;
            let cos = (1.0 - h2 * (1.0 / 2.0)) + x2 * (1.0 / 24.0);
            let sinc = (1.0 - h2 * (1.0 / 6.0)) + x2 * (1.0 / 120.0);
            (cos, 0.5 * dt * sinc)
        } else if h2 < 0.09 {
            const COS: [f64; 6] =
                [1.0, -1.0 / 2.0, 1.0 / 24.0, -1.0 / 720.0, 1.0 / 40320.0, -1.0 / 3628800.0];
            const SINC: [f64; 6] =
                [1.0, -1.0 / 6.0, 1.0 / 120.0, -1.0 / 5040.0, 1.0 / 362880.0, -1.0 / 39916800.0];
            (quintic(COS, h2), 0.5 * dt * quintic(SINC, h2))
        } else {
            let n = n2.sqrt();
            let (s, c) = (0.5 * n * dt).sin_cos();
            (c, s / n)
        };
        Quat { w: c, v: [omega[0] * k, omega[1] * k, omega[2] * k] }
    }

    /// Restores unit length.
    pub fn normalize(&mut self) {
        let [x, y, z] = self.v;
        let k = inv_norm((self.w * self.w + x * x) + (y * y + z * z));
        self.w *= k;
        for x in &mut self.v {
            *x *= k;
        }
    }

    /// The rotation matrix, row-major (`world = R · body`).
    #[inline]
    pub fn matrix(&self) -> [[f64; 3]; 3] {
        let (w, [x, y, z]) = (self.w, self.v);
        [
            [1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y - w * z), 2.0 * (x * z + w * y)],
            [2.0 * (x * y + w * z), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z - w * x)],
            [2.0 * (x * z - w * y), 2.0 * (y * z + w * x), 1.0 - 2.0 * (x * x + y * y)],
        ]
    }
}

/// `1 / √n2` for a squared norm `n2`. Integrators renormalise vectors that are unit
/// length to ~1e-12, where one Newton step from 1 (`1.5 − n2 / 2`, error
/// `3/8 (n2 − 1)²`) is exact to rounding and needs neither root nor division.
#[inline]
pub(crate) fn inv_norm(n2: f64) -> f64 {
    if (n2 - 1.0).abs() < 1e-8 { 1.5 - 0.5 * n2 } else { 1.0 / n2.sqrt() }
}

/// `Σ c_i x^i` for i in 0..6 by Estrin's scheme: the powers and the pairs are
/// computed side by side, so the chain of dependent operations is 5 long, not 10.
#[inline]
fn quintic(c: [f64; 6], x: f64) -> f64 {
    let (x2, x4) = (x * x, (x * x) * (x * x));
    ((c[0] + c[1] * x) + x2 * (c[2] + c[3] * x)) + x4 * (c[4] + c[5] * x)
}

/// `R · v`.
#[inline]
pub fn apply(r: &[[f64; 3]; 3], v: [f64; 3]) -> [f64; 3] {
    [
        r[0][0] * v[0] + r[0][1] * v[1] + r[0][2] * v[2],
        r[1][0] * v[0] + r[1][1] * v[1] + r[1][2] * v[2],
        r[2][0] * v[0] + r[2][1] * v[1] + r[2][2] * v[2],
    ]
}

/// `Rᵀ · v` (world to body).
#[inline]
pub fn apply_t(r: &[[f64; 3]; 3], v: [f64; 3]) -> [f64; 3] {
    [
        r[0][0] * v[0] + r[1][0] * v[1] + r[2][0] * v[2],
        r[0][1] * v[0] + r[1][1] * v[1] + r[2][1] * v[2],
        r[0][2] * v[0] + r[1][2] * v[1] + r[2][2] * v[2],
    ]
}

/// `a × b`.
#[inline]
pub fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}

#[cfg(test)]
mod tests {
    use super::Quat;

    #[test]
    fn series_step_matches_the_exact_rotation() {
        for &(w, dt) in &[(0.1, 0.004), (5.0, 0.004), (9.9, 0.004), (8.0, 0.04), (14.9, 0.04), (20.0, 0.04)] {
            let omega = [0.6 * w, -0.48 * w, 0.64 * w];
            let q = Quat::step(omega, dt);
            let n = (omega.iter().map(|x| x * x).sum::<f64>()).sqrt();
            let (s, c) = (0.5 * n * dt).sin_cos();
            assert!((q.w - c).abs() < 2e-12, "{w}: {} vs {c}", q.w);
            for i in 0..3 {
                assert!((q.v[i] - omega[i] / n * s).abs() < 2e-12);
            }
        }
    }
}
