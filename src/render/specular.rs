//! Skin specular reflection: the Kelemen/Szirmay-Kalos BRDF with Beckmann
//! microfacets and Schlick's Fresnel (Chappuis 2011 §2.3), two lobes per region
//! (Graham et al. 2013 Table 1), the energy-conservation table `ρ_dt` (Chappuis 2011 §2.6)
//! and the anisotropic Beckmann distribution of the strain-driven roughness
//! model (Nagano et al. 2014).
//!
//! With the half vector `h = normalize(l + v)`, the BRDF is
//! `f(l, v) = ρ_s D(h) F(v·h) / |l + v|²`, where `|l + v|² = 4 (l·h)²`
//! stands in for the masking term and `D` is normalised so that
//! `∫ D(h)(n·h) dω_h = 1`. The diffuse light that enters the skin is scaled
//! by `ρ_dt(μ) = 1 − ρ_s A(μ, m)` with the directional albedo
//! `A(μ, m) = ∫ f(l, ω) (n·ω) dω` for `n·l = μ`; the outgoing diffuse light
//! by the same factor at `n·v` (reciprocity).
//!
//! `A` is tabulated over `μ ∈ [0, 1]` and `m` by integrating over the half
//! vector with `x = tan²θ_h / m²`: `D (n·h) dω_h = e^{−x} dx dφ / 2π`, which
//! makes the integrand smooth for every roughness.

use std::f64::consts::PI;

/// Schlick's reflectance at normal incidence for skin (η ≈ 1.4).
pub const SKIN_F0: f64 = 0.028;

/// Beckmann distribution at `cos θ_h = n·h` for roughness `m` (RMS slope).
pub fn beckmann(cos_h: f64, m: f64) -> f64 {
    if cos_h <= 0.0 {
        return 0.0;
    }
    let c2 = cos_h * cos_h;
    let tan2 = (1.0 - c2) / c2;
    (-tan2 / (m * m)).exp() / (PI * m * m * c2 * c2)
}

/// Anisotropic Beckmann distribution with RMS slopes `ms`, `mt` along the
/// tangent axes; `h = (h_s, h_t, h_n)` in that frame.
pub fn beckmann_aniso(h: [f64; 3], ms: f64, mt: f64) -> f64 {
    let [hs, ht, hn] = h;
    if hn <= 0.0 {
        return 0.0;
    }
    let hn2 = hn * hn;
    (-((hs / ms).powi(2) + (ht / mt).powi(2)) / hn2).exp() / (PI * ms * mt * hn2 * hn2)
}

/// Schlick's Fresnel approximation at `cos = v·h`.
pub fn schlick(cos: f64, f0: f64) -> f64 {
    let e = (1.0 - cos).clamp(0.0, 1.0).powi(5);
    e + f0 * (1.0 - e)
}

/// Two Beckmann lobes: `w D(m1) + (1 − w) D(m2)`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Lobes {
    /// Roughness of the first lobe.
    pub m1: f64,
    /// Roughness of the second lobe.
    pub m2: f64,
    /// Weight of the first lobe, in [0, 1].
    pub w: f64,
}

/// Measured two-lobe fits (Graham et al. 2013): microscale (Table 1) and mesoscale
/// (Table 2) parameters per facial region, for subjects 1 and 2.
pub fn region_lobes(region: &str, subject: usize, microscale: bool) -> Option<Lobes> {
    // (region, [subject 1, subject 2]) as (m1, m2, w).
    const MICRO: [(&str, [[f64; 3]; 2]); 5] = [
        ("forehead", [[0.150, 0.050, 0.88], [0.150, 0.050, 0.60]]),
        ("temple", [[0.150, 0.075, 0.55], [0.175, 0.050, 0.80]]),
        ("cheek", [[0.150, 0.125, 0.60], [0.100, 0.075, 0.50]]),
        ("nose", [[0.100, 0.075, 0.80], [0.100, 0.050, 0.50]]),
        ("chin", [[0.125, 0.100, 0.90], [0.150, 0.050, 0.75]]),
    ];
    const MESO: [(&str, [[f64; 3]; 2]); 5] = [
        ("forehead", [[0.250, 0.125, 0.85], [0.250, 0.125, 0.80]]),
        ("temple", [[0.225, 0.125, 0.80], [0.225, 0.150, 0.70]]),
        ("cheek", [[0.275, 0.200, 0.60], [0.225, 0.150, 0.50]]),
        ("nose", [[0.175, 0.100, 0.65], [0.150, 0.075, 0.80]]),
        ("chin", [[0.250, 0.150, 0.35], [0.300, 0.225, 0.15]]),
    ];
    let table = if microscale { &MICRO } else { &MESO };
    let (_, fits) = table.iter().find(|(name, _)| *name == region)?;
    let [m1, m2, w] = *fits.get(subject.checked_sub(1)?)?;
    Some(Lobes { m1, m2, w })
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn normalize(a: [f64; 3]) -> [f64; 3] {
    let n = dot(a, a).sqrt();
    a.map(|x| x / n)
}

/// The Kelemen/Szirmay-Kalos BRDF (without `ρ_s`) for unit `l`, `v` in the
/// frame where the normal is +z, with Beckmann roughness `m` and Fresnel `f0`.
pub fn ks_brdf(l: [f64; 3], v: [f64; 3], m: f64, f0: f64) -> f64 {
    if l[2] <= 0.0 || v[2] <= 0.0 {
        return 0.0;
    }
    let sum = [l[0] + v[0], l[1] + v[1], l[2] + v[2]];
    let len2 = dot(sum, sum);
    if len2 <= 0.0 {
        return 0.0;
    }
    let h = normalize(sum);
    beckmann(h[2], m) * schlick(dot(v, h), f0) / len2
}

/// A Gaussian distribution of microfacet slopes (LEAN mapping): mean
/// `(x̄, ȳ)` and covariance `(σ_xx, σ_yy, σ_xy)` of `x̃ = ∂h/∂u`,
/// `ỹ = ∂h/∂v` (the facet normal of slopes `s` is `normalize(−s, 1)`).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SlopeGaussian {
    /// Mean slope.
    pub mean: [f64; 2],
    /// Covariance `[xx, yy, xy]`.
    pub cov: [f64; 3],
}

impl SlopeGaussian {
    /// From the five slope moments `[x̃, ỹ, x̃², ỹ², x̃ỹ]` (variances floored
    /// at 0 against round-off), as `skin.wgsl`'s `gaussian_of`.
    pub fn of_moments(m: [f64; 5]) -> SlopeGaussian {
        let mean = [m[0], m[1]];
        SlopeGaussian {
            mean,
            cov: [
                (m[2] - mean[0] * mean[0]).max(0.0),
                (m[3] - mean[1] * mean[1]).max(0.0),
                m[4] - mean[0] * mean[1],
            ],
        }
    }

    /// The distribution of half vectors `h` (unit, normal +z) with this
    /// slope distribution widened by a Beckmann lobe of roughness `m`
    /// (slope variance `m²/2` per axis): `P(s_h) / h_z⁴`, normalised so
    /// that `∫ D (n·h) dω = 1`. With zero mean and covariance it is
    /// [`beckmann`]`(h_z, m)`. Mirrors `beckmann_slopes` in lighting.wgsl.
    pub fn distribution(&self, h: [f64; 3], m: f64) -> f64 {
        if h[2] <= 0.0 {
            return 0.0;
        }
        let lobe = 0.5 * m * m;
        let (a, b, c) = (self.cov[0] + lobe, self.cov[1] + lobe, self.cov[2]);
        let det = a * b - c * c;
        let d = [-h[0] / h[2] - self.mean[0], -h[1] / h[2] - self.mean[1]];
        let e = (b * d[0] * d[0] - 2.0 * c * d[0] * d[1] + a * d[1] * d[1]) / det;
        (-0.5 * e).exp() / (2.0 * PI * det.sqrt() * h[2].powi(4))
    }
}

/// The two-lobe KS BRDF (without `ρ_s`) times `n·l` over the slope
/// distribution `slopes` (frame with the geometric normal +z): the
/// prefiltered specular of `skin.wgsl` (`ks_specular_moments`).
pub fn ks_moments(l: [f64; 3], v: [f64; 3], lobes: &Lobes, slopes: &SlopeGaussian, f0: f64) -> f64 {
    if l[2] <= 0.0 || v[2] <= 0.0 {
        return 0.0;
    }
    let sum = [l[0] + v[0], l[1] + v[1], l[2] + v[2]];
    let len2 = dot(sum, sum);
    let h = normalize(sum);
    let d = lobes.w * slopes.distribution(h, lobes.m1)
        + (1.0 - lobes.w) * slopes.distribution(h, lobes.m2);
    d * schlick(dot(v, h), f0) / len2 * l[2]
}

/// `A(μ, m)`: the KS BRDF's directional albedo for `n·l = μ`, by the
/// half-vector quadrature (see the module docs) on `nx × nphi` points.
pub fn directional_albedo(mu: f64, m: f64, f0: f64, nx: usize, nphi: usize) -> f64 {
    let mu = mu.clamp(1e-4, 1.0);
    let l = [(1.0 - mu * mu).sqrt(), 0.0, mu];
    let mut sum = 0.0;
    for i in 0..nx {
        // x = −ln(1 − s) maps s ∈ [0, 1) onto [0, ∞) with e^{−x} dx = ds.
        let s = (i as f64 + 0.5) / nx as f64;
        let x = -(1.0 - s).ln();
        let tan_h = m * x.sqrt();
        let cos_h = 1.0 / (1.0 + tan_h * tan_h).sqrt();
        let sin_h = tan_h * cos_h;
        let mut ring = 0.0;
        for k in 0..nphi {
            let phi = 2.0 * PI * (k as f64 + 0.5) / nphi as f64;
            let h = [sin_h * phi.cos(), sin_h * phi.sin(), cos_h];
            let lh = dot(l, h);
            if lh <= 0.0 {
                continue;
            }
            let o = [
                2.0 * lh * h[0] - l[0],
                2.0 * lh * h[1] - l[1],
                2.0 * lh * h[2] - l[2],
            ];
            if o[2] <= 0.0 {
                continue;
            }
            // f (n·o) dω_o = D F (n·o) / (4 (l·h)²) · 4 (o·h) dω_h, and
            // D (n·h) dω_h = ds dφ / 2π.
            ring += schlick(lh, f0) * o[2] / (lh * cos_h);
        }
        sum += ring / nphi as f64;
    }
    sum / nx as f64
}

/// `A(μ, m)` on a regular grid, looked up bilinearly: the table the
/// irradiance and skin shaders read (`ρ_dt = 1 − ρ_s A`).
#[derive(Clone, Debug, PartialEq)]
pub struct EnergyTable {
    /// Samples over `μ` (columns, `μ = i / (mu_samples − 1)`).
    pub mu_samples: usize,
    /// Samples over `m` (rows, from `m_min` to `m_max`).
    pub m_samples: usize,
    /// Smallest roughness tabulated.
    pub m_min: f64,
    /// Largest roughness tabulated.
    pub m_max: f64,
    /// `A` row-major (row = roughness).
    pub values: Vec<f32>,
}

impl EnergyTable {
    /// Roughness range of the table.
    pub const M_RANGE: (f64, f64) = (0.02, 1.0);

    /// Tabulates `A` for Fresnel `f0` on `mu_samples × m_samples` points.
    pub fn compute(f0: f64, mu_samples: usize, m_samples: usize) -> EnergyTable {
        use rayon::prelude::*;
        let (m_min, m_max) = Self::M_RANGE;
        let values = (0..mu_samples * m_samples)
            .into_par_iter()
            .map(|k| {
                let (i, j) = (k % mu_samples, k / mu_samples);
                let mu = i as f64 / (mu_samples - 1) as f64;
                let m = m_min + (m_max - m_min) * j as f64 / (m_samples - 1) as f64;
                directional_albedo(mu, m, f0, 96, 64) as f32
            })
            .collect();
        EnergyTable {
            mu_samples,
            m_samples,
            m_min,
            m_max,
            values,
        }
    }

    /// The table used by the renderer (64 × 64 points, skin Fresnel).
    pub fn skin() -> EnergyTable {
        EnergyTable::compute(SKIN_F0, 64, 64)
    }

    /// Bilinear lookup of `A(μ, m)` (clamped to the table's range).
    pub fn lookup(&self, mu: f64, m: f64) -> f64 {
        let x = mu.clamp(0.0, 1.0) * (self.mu_samples - 1) as f64;
        let y = ((m - self.m_min) / (self.m_max - self.m_min)).clamp(0.0, 1.0)
            * (self.m_samples - 1) as f64;
        let (i0, j0) = (
            (x.floor() as usize).min(self.mu_samples - 2),
            (y.floor() as usize).min(self.m_samples - 2),
        );
        let (fx, fy) = (x - i0 as f64, y - j0 as f64);
        let at = |i: usize, j: usize| self.values[j * self.mu_samples + i] as f64;
        (1.0 - fy) * ((1.0 - fx) * at(i0, j0) + fx * at(i0 + 1, j0))
            + fy * ((1.0 - fx) * at(i0, j0 + 1) + fx * at(i0 + 1, j0 + 1))
    }

    /// `A` for two lobes (the albedo is linear in `D`).
    pub fn lookup_lobes(&self, mu: f64, lobes: &Lobes) -> f64 {
        lobes.w * self.lookup(mu, lobes.m1) + (1.0 - lobes.w) * self.lookup(mu, lobes.m2)
    }

    /// The cosine-weighted hemispherical average `2 ∫ A(μ) μ dμ` for two
    /// lobes: the attenuation applied to environment light.
    pub fn hemispherical(&self, lobes: &Lobes) -> f64 {
        let n = 256;
        (0..n)
            .map(|i| {
                let mu = (i as f64 + 0.5) / n as f64;
                2.0 * self.lookup_lobes(mu, lobes) * mu / n as f64
            })
            .sum()
    }
}

/// The error function (Abramowitz & Stegun 7.1.26, |error| < 1.5e-7).
pub fn erf(x: f64) -> f64 {
    let t = 1.0 / (1.0 + 0.327_591_1 * x.abs());
    let poly = t
        * (0.254_829_592
            + t * (-0.284_496_736
                + t * (1.421_413_741 + t * (-1.453_152_027 + t * 1.061_405_429))));
    let y = 1.0 - poly * (-x * x).exp();
    if x >= 0.0 {
        y
    } else {
        -y
    }
}

/// Smith's masking for the Beckmann distribution at `cos θ` (exact form).
pub fn smith_g1(cos: f64, m: f64) -> f64 {
    if cos >= 1.0 {
        return 1.0;
    }
    let tan = (1.0 - cos * cos).sqrt() / cos;
    let a = 1.0 / (m * tan);
    let lambda = 0.5 * (erf(a) - 1.0) + (-a * a).exp() / (2.0 * a * PI.sqrt());
    1.0 / (1.0 + lambda)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn region_table_lookups() {
        let f = region_lobes("forehead", 1, true).unwrap();
        assert_eq!((f.m1, f.m2, f.w), (0.15, 0.05, 0.88));
        assert_eq!(region_lobes("chin", 2, false).unwrap().w, 0.15);
        assert!(region_lobes("elbow", 1, true).is_none());
        assert!(region_lobes("nose", 3, true).is_none());
        assert!(region_lobes("nose", 0, true).is_none());
    }

    #[test]
    fn erf_matches_known_values() {
        for (x, e) in [
            (0.0, 0.0),
            (0.5, 0.520_499_877_8),
            (1.0, 0.842_700_792_9),
            (-2.0, -0.995_322_265),
        ] {
            assert!((erf(x) - e).abs() < 2e-7, "erf({x})");
        }
    }
}
