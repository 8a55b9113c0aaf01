//! Fitting kernel parameters to measured deformations (seed 000 eq. 7 and
//! Fig. 11–12).
//!
//! [`fit_params`] finds the (α, σ) whose 1D convolution of the neutral map
//! along the deformation axis, seen stretched by the ratio r along that axis
//! (slopes along it divided by r, as the normals of the resampled map would
//! be), gives the normal histogram closest in total variation to the target
//! (eq. 7). The search covers α ∈ [−2, 1] in steps of 0.01 and
//! σ ∈ [1, 100] µm in steps of 0.5 µm, coarse to fine: a grid of steps
//! (0.25, 5 µm), then (0.05, 1 µm) around the best, then the final steps
//! around that. α = 0 makes every σ equal, so it is tried once.
//!
//! [`fit_model`] turns fitted (r, α, σ) points into a kernel model the way the
//! seed does: α(r) as two lines through (1, 0) exactly — one fitted by least
//! squares to the compression points, one to the stretch points — clamped
//! to [−2, 1]; σ(r) as one least-squares line over the compression points
//! and another over the stretch points (a jump at r = 1 is allowed), floored
//! at 1 µm.

use super::convolve::{convolve_pass, PassParams};
use super::kernel::{KernelModel, KernelParams, PiecewiseLinear};
use super::map::DisplacementMap;
use super::normals::NormalHistogram;
use crate::error::{Error, Result};

/// The axis of a sample's deformation (the map's u or v direction).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Axis {
    /// Along u (texel x).
    U,
    /// Along v (texel y).
    V,
}

impl Axis {
    /// Unit vector of the axis in texel units.
    pub fn unit(self) -> [f32; 2] {
        match self {
            Axis::U => [1.0, 0.0],
            Axis::V => [0.0, 1.0],
        }
    }

    /// Stretch factors along (x, y) for a ratio `r` along this axis.
    pub fn stretch(self, r: f64) -> [f64; 2] {
        match self {
            Axis::U => [r, 1.0],
            Axis::V => [1.0, r],
        }
    }
}

/// Histogram settings of the fit.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HistogramSettings {
    /// Cells per side (64 in the seed).
    pub bins: usize,
    /// Half range of the normal components.
    pub range: f64,
}

/// A fitted (α, σ) and its objective.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FitResult {
    /// Filter strength.
    pub alpha: f64,
    /// Gaussian σ (µm).
    pub sigma_um: f64,
    /// Total variation between the histograms (eq. 7), in [0, 2].
    pub distance: f64,
    /// Candidates evaluated.
    pub evaluations: usize,
}

/// The neutral map convolved along `axis` with (α, σ µm), seen stretched by
/// `r`: its normal histogram.
pub fn candidate_histogram(
    neutral: &DisplacementMap,
    axis: Axis,
    r: f64,
    params: KernelParams,
    hist: HistogramSettings,
) -> NormalHistogram {
    let pass = PassParams {
        axis: axis.unit(),
        alpha: params.alpha as f32,
        sigma: (params.sigma_um / neutral.texel_um) as f32,
    };
    let convolved = convolve_pass(neutral, &vec![pass; neutral.data.len()]);
    NormalHistogram::of(&convolved, hist.bins, hist.range, axis.stretch(r))
}

/// Finds (α, σ) for a target histogram (see the module docs).
pub fn fit_params(
    neutral: &DisplacementMap,
    target: &NormalHistogram,
    axis: Axis,
    r: f64,
    hist: HistogramSettings,
) -> FitResult {
    let evaluate = |batch: &[KernelParams]| -> Result<Vec<f64>> {
        Ok(batch
            .iter()
            .map(|&p| candidate_histogram(neutral, axis, r, p, hist).distance(target))
            .collect())
    };
    search(evaluate).expect("the CPU evaluation does not fail")
}

/// The candidate of grid indices `(a, s)`: α = −2 + 0.01·a, σ = 1 + 0.5·s µm.
fn grid_params((a, s): (i64, i64)) -> KernelParams {
    KernelParams {
        alpha: -2.0 + 0.01 * a as f64,
        sigma_um: 1.0 + 0.5 * s as f64,
    }
}

/// The coarse-to-fine search of [`fit_params`] with any evaluator of the
/// objective: `evaluate` gets each stage's new candidates as one batch and
/// returns their distances in order (the GPU evaluates a batch in one
/// submission). Ties keep the first candidate in (α, σ) order, so equal
/// objectives give the same optimum on every evaluator.
pub fn search(mut evaluate: impl FnMut(&[KernelParams]) -> Result<Vec<f64>>) -> Result<FitResult> {
    let mut cache: std::collections::HashMap<(i64, i64), f64> = std::collections::HashMap::new();
    // α = 0 makes every σ equal: one key for all.
    let key = |a: i64, s: i64| if a == 200 { (200, 0) } else { (a, s) };
    let (a_max, s_max) = (300i64, 198i64);
    let mut best = (f64::INFINITY, 200i64, 0i64);
    // (α step, σ step, half-width of the window in steps) per stage.
    for (da, ds, window) in [
        (25i64, 10i64, None),
        (5, 2, Some((25i64, 10i64))),
        (1, 1, Some((5, 2))),
    ] {
        let (a_range, s_range) = match window {
            None => ((0, a_max), (0, s_max)),
            Some((wa, ws)) => (
                ((best.1 - wa).max(0), (best.1 + wa).min(a_max)),
                ((best.2 - ws).max(0), (best.2 + ws).min(s_max)),
            ),
        };
        let grid: Vec<(i64, i64)> = (a_range.0..=a_range.1)
            .step_by(da as usize)
            .flat_map(|a| {
                (s_range.0..=s_range.1)
                    .step_by(ds as usize)
                    .map(move |s| (a, s))
            })
            .collect();
        let mut fresh: Vec<(i64, i64)> = Vec::new();
        for &(a, s) in &grid {
            let k = key(a, s);
            if !cache.contains_key(&k) && !fresh.contains(&k) {
                fresh.push(k);
            }
        }
        let params: Vec<KernelParams> = fresh.iter().map(|&k| grid_params(k)).collect();
        let distances = evaluate(&params)?;
        cache.extend(fresh.into_iter().zip(distances));
        for &(a, s) in &grid {
            let d = cache[&key(a, s)];
            if d < best.0 {
                best = (d, a, s);
            }
        }
    }
    let p = grid_params((best.1, best.2));
    Ok(FitResult {
        alpha: p.alpha,
        sigma_um: p.sigma_um,
        distance: best.0,
        evaluations: cache.len(),
    })
}

/// One fitted sample: stretch ratio and parameters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FittedPoint {
    /// Stretch ratio r.
    pub r: f64,
    /// Fitted α.
    pub alpha: f64,
    /// Fitted σ (µm).
    pub sigma_um: f64,
}

/// The lines of a fitted model, for reports: α = slope·(r − 1) on each side,
/// σ = a·r + b on each side.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ModelLines {
    /// α slope for r < 1.
    pub alpha_compression_slope: f64,
    /// α slope for r > 1.
    pub alpha_stretch_slope: f64,
    /// σ = a·r + b for r < 1 (µm).
    pub sigma_compression: (f64, f64),
    /// σ = a·r + b for r ≥ 1 (µm).
    pub sigma_stretch: (f64, f64),
}

/// Least-squares slope of y = k·(r − 1).
fn slope_through_one(points: &[(f64, f64)]) -> Option<f64> {
    let (num, den) = points.iter().fold((0.0, 0.0), |(n, d), &(r, y)| {
        (n + (r - 1.0) * y, d + (r - 1.0) * (r - 1.0))
    });
    (den > 0.0).then(|| num / den)
}

/// Least-squares line y = a·r + b (a constant for a single point).
fn line(points: &[(f64, f64)]) -> Option<(f64, f64)> {
    let n = points.len() as f64;
    if points.is_empty() {
        return None;
    }
    let (sr, sy) = points
        .iter()
        .fold((0.0, 0.0), |(a, b), &(r, y)| (a + r, b + y));
    let (mr, my) = (sr / n, sy / n);
    let (sxx, sxy) = points.iter().fold((0.0, 0.0), |(a, b), &(r, y)| {
        (a + (r - mr).powi(2), b + (r - mr) * (y - my))
    });
    if sxx <= 0.0 {
        return Some((0.0, my));
    }
    let a = sxy / sxx;
    Some((a, my - a * mr))
}

/// Fits a kernel model to points (see the module docs). Needs at least one
/// point with r < 1 and one with r > 1.
pub fn fit_model(points: &[FittedPoint]) -> Result<(KernelModel, ModelLines)> {
    let side = |compression: bool, f: fn(&FittedPoint) -> f64| -> Vec<(f64, f64)> {
        points
            .iter()
            .filter(|p| if compression { p.r < 1.0 } else { p.r > 1.0 })
            .map(|p| (p.r, f(p)))
            .collect()
    };
    let need = || Error::Parameter {
        key: "samples".into(),
        reason: "fitting a model needs samples with r < 1 and with r > 1".into(),
    };
    let kc = slope_through_one(&side(true, |p| p.alpha)).ok_or_else(need)?;
    let ks = slope_through_one(&side(false, |p| p.alpha)).ok_or_else(need)?;
    let sc = line(&side(true, |p| p.sigma_um)).ok_or_else(need)?;
    let ss = line(&side(false, |p| p.sigma_um)).ok_or_else(need)?;
    let r_min = points
        .iter()
        .map(|p| p.r)
        .fold(f64::INFINITY, f64::min)
        .min(0.5);
    let r_max = points
        .iter()
        .map(|p| p.r)
        .fold(f64::NEG_INFINITY, f64::max)
        .max(1.5);
    // α: where each line reaches its clamp (if inside the range), then ends.
    let mut alpha = vec![(1.0, 0.0)];
    let mut push_side = |k: f64, end: f64| {
        let clamp_at = |v: f64| 1.0 + v / k;
        let limit = if (k > 0.0) == (end > 1.0) { 1.0 } else { -2.0 };
        let corner = if k != 0.0 { clamp_at(limit) } else { f64::NAN };
        if corner.is_finite()
            && (corner - 1.0) * (end - 1.0) > 0.0
            && (corner - 1.0).abs() < (end - 1.0).abs()
        {
            alpha.push((corner, limit));
        } else {
            alpha.push((end, (k * (end - 1.0)).clamp(-2.0, 1.0)));
        }
    };
    push_side(kc, r_min);
    push_side(ks, r_max);
    alpha.sort_by(|a, b| a.0.total_cmp(&b.0));
    let sigma_table = |(a, b): (f64, f64), lo: f64, hi: f64| PiecewiseLinear {
        points: vec![(lo, (a * lo + b).max(1.0)), (hi, (a * hi + b).max(1.0))],
    };
    let model = KernelModel {
        alpha: PiecewiseLinear { points: alpha },
        sigma_compression_um: sigma_table(sc, r_min, 1.0),
        sigma_stretch_um: sigma_table(ss, 1.0, r_max),
    };
    model.validate("fitted model")?;
    Ok((
        model,
        ModelLines {
            alpha_compression_slope: kc,
            alpha_stretch_slope: ks,
            sigma_compression: sc,
            sigma_stretch: ss,
        },
    ))
}
