//! The convolution kernel and the kernel model (Nagano et al. 2015
//! eq. 6, 8, 9).
//!
//! A 1D kernel mixes the identity and a normalised discrete Gaussian:
//! `k = (1 − α)·δ + α·G(·, σ)`, `−2 ≤ α ≤ 1` (α > 0 blurs, α < 0 sharpens,
//! α = 0 is the identity). `G` has taps `i = −N … N`, `N = ⌈3σ⌉` (σ in
//! texels), weights `exp(−i²/2σ²)` divided by their sum, so every kernel sums
//! to 1 exactly up to round-off.
//!
//! The kernel model maps a stretch ratio r to (α, σ) with piecewise-linear
//! tables, held constant beyond their first and last points: α(r) through
//! (1, 0) exactly, and σ(r) in two tables, one for compression (r < 1) and
//! one for stretch (r ≥ 1), which may disagree at r = 1 (Nagano et al. 2015 eq. 9 has a
//! jump there). The built-in forehead model is eq. 8–9 written as such
//! tables: α = min(1, 15.4r − 13.8, 3.09(r − 1)) clamped to [−2, 1] has
//! its corners at r = 13.8/15.4 − 2/15.4, (13.8 − 3.09)/(15.4 − 3.09) and
//! 1 + 1/3.09; σ = 70.5r − 46.9 µm (r < 1) and 38.2r − 26.5 µm (r ≥ 1),
//! floored at 1 µm (the compression line reaches 1 µm at r = 0.6794) and
//! tabulated up to r = 2.

use crate::error::{Error, Result};

/// A piecewise-linear function through `points` (r ascending), constant
/// beyond the first and last point.
#[derive(Clone, Debug, PartialEq)]
pub struct PiecewiseLinear {
    /// `(r, value)` pairs, r strictly increasing.
    pub points: Vec<(f64, f64)>,
}

impl PiecewiseLinear {
    /// Evaluates at `r`.
    pub fn at(&self, r: f64) -> f64 {
        let p = &self.points;
        if r <= p[0].0 {
            return p[0].1;
        }
        if r >= p[p.len() - 1].0 {
            return p[p.len() - 1].1;
        }
        let k = p.partition_point(|q| q.0 <= r);
        let ((r0, v0), (r1, v1)) = (p[k - 1], p[k]);
        v0 + (v1 - v0) * (r - r0) / (r1 - r0)
    }

    fn check(&self, key: &str, value_ok: impl Fn(f64) -> bool, what: &str) -> Result<()> {
        if self.points.is_empty() {
            return Err(Error::parameter(key, "needs at least one [r, value] point"));
        }
        for (k, &(r, v)) in self.points.iter().enumerate() {
            if !(r.is_finite() && r > 0.0) {
                return Err(Error::parameter(
                    format!("{key}[{k}]"),
                    format!("stretch ratio must be finite and > 0, got {r}"),
                ));
            }
            if !value_ok(v) {
                return Err(Error::parameter(
                    format!("{key}[{k}]"),
                    format!("{what}, got {v}"),
                ));
            }
            if k > 0 && r <= self.points[k - 1].0 {
                return Err(Error::parameter(
                    format!("{key}[{k}]"),
                    format!(
                        "stretch ratios must increase, got {r} after {}",
                        self.points[k - 1].0
                    ),
                ));
            }
        }
        Ok(())
    }
}

/// Kernel parameters along one axis.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct KernelParams {
    /// Filter strength α ∈ [−2, 1].
    pub alpha: f64,
    /// Gaussian standard deviation (µm).
    pub sigma_um: f64,
}

/// Stretch ratio → kernel parameters.
#[derive(Clone, Debug, PartialEq)]
pub struct KernelModel {
    /// α(r).
    pub alpha: PiecewiseLinear,
    /// σ(r) for r < 1 (µm).
    pub sigma_compression_um: PiecewiseLinear,
    /// σ(r) for r ≥ 1 (µm).
    pub sigma_stretch_um: PiecewiseLinear,
}

/// The sharpening/blur weight α a model may take: from −2 (the sharpest
/// the forehead model reaches) to 1 (a full blur).
pub const ALPHA_RANGE: (f64, f64) = (-2.0, 1.0);

impl KernelModel {
    /// The forehead model of Nagano et al. 2015 eq. 8–9 (see the module docs).
    pub fn forehead() -> KernelModel {
        let corner = (13.8 - 3.09) / (15.4 - 3.09);
        KernelModel {
            alpha: PiecewiseLinear {
                points: vec![
                    ((13.8 - 2.0) / 15.4, -2.0),
                    (corner, 3.09 * (corner - 1.0)),
                    (1.0, 0.0),
                    (1.0 + 1.0 / 3.09, 1.0),
                ],
            },
            sigma_compression_um: PiecewiseLinear {
                points: vec![((46.9 + 1.0) / 70.5, 1.0), (1.0, 70.5 - 46.9)],
            },
            sigma_stretch_um: PiecewiseLinear {
                points: vec![(1.0, 38.2 - 26.5), (2.0, 2.0 * 38.2 - 26.5)],
            },
        }
    }

    /// Checks the tables: r > 0 and strictly increasing, α ∈ [−2, 1] with
    /// α(1) = 0, σ > 0. `key` names the model in errors (e.g.
    /// `microstructure.kernel`).
    pub fn validate(&self, key: &str) -> Result<()> {
        let (lo, hi) = ALPHA_RANGE;
        self.alpha.check(
            &format!("{key}.alpha"),
            |a| (lo..=hi).contains(&a),
            "α must lie in [−2, 1]",
        )?;
        let at_one = self.alpha.at(1.0);
        if at_one.abs() > 1e-12 {
            return Err(Error::parameter(
                format!("{key}.alpha"),
                format!("must pass through (1, 0) (no change when unstretched), gives {at_one} at r = 1"),
            ));
        }
        let positive = |s: f64| s.is_finite() && s > 0.0;
        self.sigma_compression_um.check(
            &format!("{key}.sigma_compression_um"),
            positive,
            "σ must be finite and > 0 µm",
        )?;
        self.sigma_stretch_um.check(
            &format!("{key}.sigma_stretch_um"),
            positive,
            "σ must be finite and > 0 µm",
        )
    }

    /// The largest σ (µm) the model gives at any stretch ratio (the tables
    /// are constant beyond their ends, so it is their largest value).
    pub fn max_sigma_um(&self) -> f64 {
        self.sigma_compression_um
            .points
            .iter()
            .chain(&self.sigma_stretch_um.points)
            .map(|p| p.1)
            .fold(0.0, f64::max)
    }

    /// Kernel parameters for stretch ratio `r` (a folded, negative r is
    /// taken by its magnitude).
    pub fn params(&self, r: f64) -> KernelParams {
        let r = r.abs();
        KernelParams {
            alpha: self.alpha.at(r),
            sigma_um: if r < 1.0 {
                self.sigma_compression_um.at(r)
            } else {
                self.sigma_stretch_um.at(r)
            },
        }
    }
}

/// Taps of the discrete 1D kernel `(1 − α)δ + α·G(σ)` with σ in texels:
/// `weights[N + i]` for `i = −N … N`.
pub fn kernel_weights(alpha: f64, sigma_texels: f64) -> Vec<f64> {
    let gauss = gaussian(sigma_texels);
    let n = gauss.len() / 2;
    let mut w: Vec<f64> = gauss.iter().map(|g| alpha * g).collect();
    w[n] += 1.0 - alpha;
    w
}

/// The normalised discrete Gaussian of σ texels, radius `N = ⌈3σ⌉`, the
/// outermost pair scaled by `3σ − (N − 1)` so the taps are continuous in σ
/// (one tap of weight 1 for σ ≤ 0).
pub fn gaussian(sigma_texels: f64) -> Vec<f64> {
    if sigma_texels.is_nan() || sigma_texels <= 0.0 {
        return vec![1.0];
    }
    let n = (3.0 * sigma_texels).ceil() as usize;
    let mut g: Vec<f64> = (0..=2 * n)
        .map(|k| {
            let i = k as f64 - n as f64;
            let taper = if i.abs() == n as f64 {
                3.0 * sigma_texels - (n as f64 - 1.0)
            } else {
                1.0
            };
            taper * (-i * i / (2.0 * sigma_texels * sigma_texels)).exp()
        })
        .collect();
    let sum: f64 = g.iter().sum();
    g.iter_mut().for_each(|v| *v /= sum);
    g
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn forehead_model_matches_eq_8_and_9() {
        let m = KernelModel::forehead();
        m.validate("forehead").unwrap();
        for r in [0.70f64, 0.77, 0.8, 0.87, 0.95, 1.0, 1.1, 1.2, 1.3, 1.4, 1.9] {
            let alpha = (15.4 * r - 13.8)
                .min(3.09 * (r - 1.0))
                .min(1.0)
                .clamp(-2.0, 1.0);
            let sigma = if r >= 1.0 {
                38.2 * r - 26.5
            } else {
                (70.5 * r - 46.9).max(1.0)
            };
            let p = m.params(r);
            assert!(
                (p.alpha - alpha).abs() < 1e-12,
                "α({r}) {} vs {alpha}",
                p.alpha
            );
            assert!(
                (p.sigma_um - sigma).abs() < 1e-12,
                "σ({r}) {} vs {sigma}",
                p.sigma_um
            );
        }
        assert_eq!(m.params(1.0).alpha, 0.0);
    }

    #[test]
    fn kernels_sum_to_one_and_alpha_zero_is_identity() {
        for (alpha, sigma) in [(0.0, 3.0), (1.0, 0.7), (-2.0, 5.5), (0.4, 12.0)] {
            let w = kernel_weights(alpha, sigma);
            assert!(
                (w.iter().sum::<f64>() - 1.0).abs() < 1e-14,
                "α {alpha} σ {sigma}"
            );
            assert_eq!(w.len(), 2 * (3.0 * sigma).ceil() as usize + 1);
        }
        let id = kernel_weights(0.0, 4.0);
        assert!(id
            .iter()
            .enumerate()
            .all(|(k, &v)| v == if k == 12 { 1.0 } else { 0.0 }));
    }

    #[test]
    fn bad_tables_are_rejected_with_their_key() {
        let mut m = KernelModel::forehead();
        m.alpha.points[2].1 = 0.1;
        assert!(m.validate("k").unwrap_err().to_string().contains("k.alpha"));
        let mut m = KernelModel::forehead();
        m.alpha.points[0].1 = -2.5;
        assert!(m
            .validate("k")
            .unwrap_err()
            .to_string()
            .contains("k.alpha[0]"));
        let mut m = KernelModel::forehead();
        m.sigma_stretch_um.points[1].1 = 0.0;
        assert!(m
            .validate("k")
            .unwrap_err()
            .to_string()
            .contains("k.sigma_stretch_um[1]"));
        let mut m = KernelModel::forehead();
        m.sigma_compression_um.points[1].0 = 0.5;
        let err = m.validate("k").unwrap_err().to_string();
        assert!(err.contains("must increase"), "{err}");
        let mut m = KernelModel::forehead();
        m.alpha.points[1].0 = f64::NAN;
        assert!(m.validate("k").is_err());
    }
}
