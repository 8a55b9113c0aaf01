//! Lights: up to four point or directional lights and an environment given
//! by order-3 (nine-coefficient) spherical harmonics.
//!
//! A light's `intensity` is the irradiance it delivers at normal incidence:
//! directly for a directional light, at 100 mm for a point light (falling
//! off as `(100 mm / d)²`). The environment's irradiance follows Ramamoorthi
//! & Hanrahan (2001): with radiance `L(ω) = Σ L_lm Y_lm(ω)`,
//! `E(n) = c1 L22 (x²−y²) + c3 L20 z² + c4 L00 − c5 L20
//!        + 2c1 (L2−2 xy + L21 xz + L2−1 yz) + 2c2 (L11 x + L1−1 y + L10 z)`,
//! exact for radiance of order ≤ 2. A Lambertian surface reflects `ρ E / π`.

use glam::Vec3;

/// Most lights a scene may have.
pub const MAX_LIGHTS: usize = 4;

/// Where light comes from.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum LightKind {
    /// A point at this position (mm).
    Point(Vec3),
    /// Parallel light travelling along this unit direction.
    Directional(Vec3),
}

/// One light.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Light {
    /// Position or direction.
    pub kind: LightKind,
    /// Linear RGB colour.
    pub color: Vec3,
    /// Irradiance at normal incidence (at 100 mm for a point light).
    pub intensity: f32,
}

/// Irradiance convolution constants of Ramamoorthi & Hanrahan (2001).
pub const SH_C: [f32; 5] = [0.429_043, 0.511_664, 0.743_125, 0.886_227, 0.247_708];

/// Nine SH radiance coefficients per channel, in the order
/// L00, L1−1, L10, L11, L2−2, L2−1, L20, L21, L22.
pub type ShCoefficients = [[f32; 3]; 9];

/// The Grace Cathedral light probe (Ramamoorthi & Hanrahan 2001, Table 1),
/// with z up.
pub const GRACE_CATHEDRAL: ShCoefficients = [
    [0.79, 0.44, 0.54],
    [0.39, 0.35, 0.60],
    [-0.34, -0.18, -0.27],
    [-0.29, -0.06, 0.01],
    [-0.11, -0.05, -0.12],
    [-0.26, -0.22, -0.47],
    [-0.16, -0.09, -0.15],
    [0.56, 0.21, 0.14],
    [0.21, -0.05, -0.30],
];

/// Environment light: SH radiance scaled by `intensity`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Environment {
    /// Radiance coefficients.
    pub coefficients: ShCoefficients,
    /// Scale applied to them.
    pub intensity: f32,
}

impl Environment {
    /// Irradiance `E(n)` (RGB) for a unit normal.
    pub fn irradiance(&self, n: Vec3) -> Vec3 {
        let l = |k: usize| Vec3::from(self.coefficients[k]);
        let [c1, c2, c3, c4, c5] = SH_C;
        let (x, y, z) = (n.x, n.y, n.z);
        let e = c1 * l(8) * (x * x - y * y) + c3 * l(6) * z * z + c4 * l(0) - c5 * l(6)
            + 2.0 * c1 * (l(4) * x * y + l(7) * x * z + l(5) * y * z)
            + 2.0 * c2 * (l(3) * x + l(1) * y + l(2) * z);
        e * self.intensity
    }

    /// Radiance `L(ω)` (RGB) arriving from direction `w` (unit).
    pub fn radiance(&self, w: Vec3) -> Vec3 {
        let basis = sh_basis(w);
        let mut sum = Vec3::ZERO;
        for (b, c) in basis.iter().zip(self.coefficients) {
            sum += *b * Vec3::from(c);
        }
        sum * self.intensity
    }
}

/// The nine real SH basis functions at unit `w`, in coefficient order.
pub fn sh_basis(w: Vec3) -> [f32; 9] {
    let (x, y, z) = (w.x, w.y, w.z);
    [
        0.282_095,
        0.488_603 * y,
        0.488_603 * z,
        0.488_603 * x,
        1.092_548 * x * y,
        1.092_548 * y * z,
        0.315_392 * (3.0 * z * z - 1.0),
        1.092_548 * x * z,
        0.546_274 * (x * x - y * y),
    ]
}
