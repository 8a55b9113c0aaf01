//! Fitting kernel parameters to measured deformations (Nagano et al. 2015 eq. 7 and
//! Fig. 11–12).
//!
//! **The objective.** A candidate (α, σ) convolves the neutral map `D` once
//! along the sample's axis (`(1 − α)·D + α·G_σ∗D`, [`convolve_pass`]),
//! resamples the result to the deformed shape — stretched by the ratio r
//! along the axis, [`resample`] — and takes the 64 × 64 histogram of its
//! normals; its score is the total variation to the target's histogram
//! (eq. 7). [`candidate_histogram`] is that definition, texel for texel.
//!
//! **The search** ([`search`]) covers the paper's grid, α ∈ [−2, 1] in steps
//! of 0.01 and σ ∈ [1, 100] µm in steps of 0.5 µm, using that the convolved
//! map, its resampling and so its slopes are linear in α: per σ, one blur
//! gives the slope field `s₀` of the resampled neutral map and the change
//! `d_σ` per unit α, and every α of that σ is the field `s₀ + α·d_σ` (one
//! blur per σ, [`Objective`]). First every σ of the grid is scored at every
//! tenth α (α step 0.1: 5,971 candidates with α = 0 once, where every σ is
//! the same); then, from each of the best [`STARTS`] local minima of that
//! grid, a window of ±0.1 in α and ±2.5 µm in σ at the full resolution is
//! moved to its best candidate until that is its centre. The optimum is the
//! best candidate scored, ties to the first in (α, σ) order, and the
//! valley — the range of α and σ over the scored candidates within
//! [`valley_margin`] of it — says how well the sample constrains the kernel.
//!
//! **The histogram window** is chosen from the data by [`auto_range`] unless
//! given: the same ±range for the target and every candidate.
//!
//! [`fit_model`] turns fitted (r, α, σ) points into a kernel model the way the
//! seed does: α(r) as connected line segments through (1, 0) exactly —
//! by default one per side, more where the samples file breaks the range of
//! r (the seed partitions it by inspecting the data; its eq. 8 has a break
//! at r ≈ 0.87) — fitted by least squares and clamped to [−2, 1]; σ(r) as
//! one least-squares line over the compression points
//! and another over the stretch points (a jump at r = 1 is allowed), floored
//! at 1 µm.

use std::collections::HashMap;

use rayon::prelude::*;

mod count;

pub use count::{count_histograms, Slopes};

use super::convolve::{blur_along_axis, convolve_pass, PassParams};
use super::kernel::{KernelModel, KernelParams, PiecewiseLinear};
use super::map::DisplacementMap;
use super::normals::{normal_of, slope, NormalHistogram};
use crate::error::{Error, Result};

/// The axis of a sample's deformation (the map's u or v direction).
#[derive(
    Clone, Copy, Debug, PartialEq, Eq, serde::Deserialize, serde::Serialize, schemars::JsonSchema,
)]
#[serde(rename_all = "lowercase")]
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
}

/// Histogram settings of the fit.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HistogramSettings {
    /// Cells per side (64 in the seed).
    pub bins: usize,
    /// Half range of the normal components.
    pub range: f64,
}

/// A fitted (α, σ), its objective and its valley.
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
    /// Smallest and largest α of the scored candidates within
    /// [`valley_margin`] of the optimum.
    pub alpha_range: (f64, f64),
    /// Smallest and largest σ (µm) of those candidates.
    pub sigma_range_um: (f64, f64),
}

/// Grid steps of α (0.01 from −2) and σ (0.5 µm from 1 µm).
pub const ALPHA_STEPS: usize = 300;
/// Grid steps of σ.
pub const SIGMA_STEPS: usize = 198;
/// Grid index of α = 0.
const ALPHA_ZERO: usize = 200;
/// Every this many α steps are scored at every σ in the first stage.
const COARSE_ALPHA: usize = 10;
/// Local minima of the first stage refined at full resolution.
pub const STARTS: usize = 6;
/// Half widths (α steps, σ steps) of a refinement window.
const WINDOW: (usize, usize) = (10, 5);

/// The candidate of grid indices `(a, s)`: α = −2 + 0.01·a, σ = 1 + 0.5·s µm.
pub fn grid_params(a: usize, s: usize) -> KernelParams {
    KernelParams {
        alpha: -2.0 + 0.01 * a as f64,
        sigma_um: 1.0 + 0.5 * s as f64,
    }
}

/// The margin of the valley reported with a fit: total variation within
/// 10% of the optimum's, and at least 0.002, of it.
pub fn valley_margin(best: f64) -> f64 {
    (0.1 * best).max(0.002)
}

/// `map` as it looks stretched by `r` along `axis`, at the same texel size:
/// `round(n·r)` texels along the axis (n the map's), output texel `o` read
/// at `(o + ½)/r − ½` by Catmull–Rom cubic interpolation along the axis
/// (exact at texel centres, the map's edge handling beyond its border), the
/// other axis unchanged. `r = 1` returns the map itself.
pub fn resample(map: &DisplacementMap, axis: Axis, r: f64) -> DisplacementMap {
    if r == 1.0 {
        return map.clone();
    }
    let along = match axis {
        Axis::U => map.width,
        Axis::V => map.height,
    };
    let n_out = ((along as f64 * r).round() as usize).max(1);
    let taps: Vec<(isize, [f64; 4])> = (0..n_out)
        .map(|o| {
            let x = (o as f64 + 0.5) / r - 0.5;
            let x0 = x.floor();
            let t = x - x0;
            let (t2, t3) = (t * t, t * t * t);
            let w = [
                0.5 * (-t3 + 2.0 * t2 - t),
                0.5 * (3.0 * t3 - 5.0 * t2 + 2.0),
                0.5 * (-3.0 * t3 + 4.0 * t2 + t),
                0.5 * (t3 - t2),
            ];
            (x0 as isize - 1, w)
        })
        .collect();
    let (width, height) = match axis {
        Axis::U => (n_out, map.height),
        Axis::V => (map.width, n_out),
    };
    let mut data = vec![0.0f32; width * height];
    data.par_chunks_mut(width.max(1))
        .enumerate()
        .for_each(|(j, row)| {
            for (i, out) in row.iter_mut().enumerate() {
                let (first, w) = match axis {
                    Axis::U => taps[i],
                    Axis::V => taps[j],
                };
                let mut sum = 0.0f64;
                if first >= 0 && first as usize + 3 < along {
                    // All four taps inside: no edge handling.
                    let (at, stride) = match axis {
                        Axis::U => (j * map.width + first as usize, 1),
                        Axis::V => (first as usize * map.width + i, map.width),
                    };
                    for (k, wk) in w.iter().enumerate() {
                        sum += wk * map.data[at + k * stride] as f64;
                    }
                } else {
                    for (k, wk) in w.iter().enumerate() {
                        let at = first + k as isize;
                        let h = match axis {
                            Axis::U => map.texel(at, j as isize),
                            Axis::V => map.texel(i as isize, at),
                        };
                        sum += wk * h as f64;
                    }
                }
                *out = sum as f32;
            }
        });
    DisplacementMap {
        width,
        height,
        texel_um: map.texel_um,
        height_unit_um: map.height_unit_um,
        edge: map.edge,
        data,
    }
}

/// The neutral map convolved along `axis` with (α, σ µm) and resampled to
/// the shape stretched by `r`: its normal histogram (the objective's
/// definition; [`Objective`] computes the same faster).
pub fn candidate_histogram(
    neutral: &DisplacementMap,
    axis: Axis,
    r: f64,
    params: KernelParams,
    hist: HistogramSettings,
) -> NormalHistogram {
    let convolved = convolve_pass(
        neutral,
        &vec![pass(neutral, axis, params); neutral.data.len()],
    );
    NormalHistogram::of(
        &resample(&convolved, axis, r),
        hist.bins,
        hist.range,
        [1.0, 1.0],
    )
}

fn pass(map: &DisplacementMap, axis: Axis, p: KernelParams) -> PassParams {
    PassParams {
        axis: axis.unit(),
        alpha: p.alpha as f32,
        sigma: (p.sigma_um / map.texel_um) as f32,
    }
}

/// Fraction of texels whose normal may fall outside the data-driven window.
pub const RANGE_QUANTILE: f64 = 0.995;

/// The histogram half range from the data: the [`RANGE_QUANTILE`] quantile
/// of `max(|n_x|, |n_y|)` over each map's normals, the largest over the
/// maps, rounded up to 0.01 (and at least 0.01).
pub fn auto_range(maps: &[&DisplacementMap]) -> f64 {
    let mut range: f64 = 0.01;
    for map in maps {
        let mut extent: Vec<f32> = (0..map.width * map.height)
            .into_par_iter()
            .map(|idx| {
                let n = normal_of(slope(map, idx % map.width, idx / map.width, [1.0, 1.0]));
                n[0].abs().max(n[1].abs()) as f32
            })
            .collect();
        if extent.is_empty() {
            continue;
        }
        let k = ((extent.len() as f64 * RANGE_QUANTILE).ceil() as usize).clamp(1, extent.len());
        let (_, q, _) = extent.select_nth_unstable_by(k - 1, f32::total_cmp);
        range = range.max((*q as f64 * 100.0).ceil() / 100.0);
    }
    range
}

/// One sample's fitting problem, prepared for [`search`]: the slopes of
/// the resampled neutral map and, per σ, their change per unit α.
pub struct Objective<'a> {
    neutral: &'a DisplacementMap,
    axis: Axis,
    r: f64,
    /// Histogram window of target and candidates.
    pub hist: HistogramSettings,
    target: &'a NormalHistogram,
    /// Slopes of the resampled neutral map (α = 0).
    pub base: Slopes,
}

impl<'a> Objective<'a> {
    /// The problem of fitting `target` (a histogram with `hist`'s window)
    /// from `neutral` deformed along `axis` by `r`.
    pub fn new(
        neutral: &'a DisplacementMap,
        target: &'a NormalHistogram,
        axis: Axis,
        r: f64,
        hist: HistogramSettings,
    ) -> Objective<'a> {
        Objective {
            neutral,
            axis,
            r,
            hist,
            target,
            base: Slopes::of(&resample(neutral, axis, r)),
        }
    }

    /// The change of the candidate slopes per unit α at σ grid index `s`:
    /// the slopes of the resampled `G_σ∗D` minus [`Objective::base`].
    pub fn direction(&self, s: usize) -> Slopes {
        let sigma = pass(self.neutral, self.axis, grid_params(0, s)).sigma;
        let blurred = blur_along_axis(self.neutral, self.axis == Axis::U, sigma);
        let mut d = Slopes::of(&resample(&blurred, self.axis, self.r));
        d.x.iter_mut().zip(&self.base.x).for_each(|(d, b)| *d -= b);
        d.y.iter_mut().zip(&self.base.y).for_each(|(d, b)| *d -= b);
        d
    }

    /// Total variation between counts (normalised) and the target.
    pub fn distance(&self, counts: &[u32]) -> f64 {
        let total: f64 = counts.iter().map(|&c| c as f64).sum::<f64>().max(1.0);
        counts
            .iter()
            .zip(&self.target.cells)
            .map(|(&c, t)| (c as f64 / total - t).abs())
            .sum()
    }
}

/// Finds (α, σ) for a target histogram on the CPU (see the module docs).
pub fn fit_params(
    neutral: &DisplacementMap,
    target: &NormalHistogram,
    axis: Axis,
    r: f64,
    hist: HistogramSettings,
) -> FitResult {
    let objective = Objective::new(neutral, target, axis, r, hist);
    search(
        &objective,
        |base, dir, alphas| Ok(count_histograms(base, dir, alphas, hist.bins, hist.range)),
        |_| {},
    )
    .expect("the CPU evaluation does not fail")
}

/// The search of the module docs with any counter of candidate histograms:
/// `count(base, dir, alphas)` returns the counts of `base + α·dir` for each
/// α in order (the GPU counts a batch in one submission). `progress` gets
/// the fraction of the first stage done (the second takes about a third
/// as long). Ties keep the first candidate in (α, σ) order, so equal
/// objectives give the same optimum with every counter.
pub fn search(
    objective: &Objective,
    mut count: impl FnMut(&Slopes, &Slopes, &[f32]) -> Result<Vec<Vec<u32>>>,
    mut progress: impl FnMut(f64),
) -> Result<FitResult> {
    use std::collections::BTreeMap;
    let key = grid_key;
    let mut scores: Scores = HashMap::new();
    let mut directions: BTreeMap<usize, Slopes> = BTreeMap::new();
    let mut evaluate =
        |s: usize, alphas: &mut dyn Iterator<Item = usize>, scores: &mut Scores| -> Result<()> {
            let mut fresh: Vec<usize> = Vec::new();
            for a in alphas {
                if !scores.contains_key(&key(a, s)) && !fresh.contains(&a) {
                    fresh.push(a);
                }
            }
            if fresh.is_empty() {
                return Ok(());
            }
            if !directions.contains_key(&s) {
                if directions.len() >= 4 * WINDOW.1 {
                    directions.clear();
                }
                directions.insert(s, objective.direction(s));
            }
            let alphas: Vec<f32> = fresh
                .iter()
                .map(|&a| grid_params(a, s).alpha as f32)
                .collect();
            let counts = count(&objective.base, &directions[&s], &alphas)?;
            for (a, c) in fresh.into_iter().zip(counts) {
                scores.insert(key(a, s), objective.distance(&c));
            }
            Ok(())
        };
    // Stage 1: every σ, every tenth α.
    for s in 0..=SIGMA_STEPS {
        evaluate(s, &mut (0..=ALPHA_STEPS).step_by(COARSE_ALPHA), &mut scores)?;
        progress((s + 1) as f64 / (SIGMA_STEPS + 1) as f64);
    }
    let score = |scores: &Scores, a: usize, s: usize| scores[&grid_key(a, s)];
    let minima = coarse_minima(&scores);
    // Stage 2: a full-resolution window from each of the best minima, moved
    // to its best candidate until that is its centre.
    let mut starts: Vec<(usize, usize)> = Vec::new();
    for &(_, a, s) in &minima {
        if starts.len() == STARTS {
            break;
        }
        // Minima along the α = 0 line are one candidate.
        if !starts.iter().any(|&(sa, ss)| key(sa, ss) == key(a, s)) {
            starts.push((a, s));
        }
    }
    for (mut a, mut s) in starts {
        for _ in 0..=ALPHA_STEPS + SIGMA_STEPS {
            let a_win = a.saturating_sub(WINDOW.0)..=(a + WINDOW.0).min(ALPHA_STEPS);
            let s_win = s.saturating_sub(WINDOW.1)..=(s + WINDOW.1).min(SIGMA_STEPS);
            for ws in s_win.clone() {
                evaluate(ws, &mut a_win.clone(), &mut scores)?;
            }
            let mut best = (score(&scores, a, s), a, s);
            for wa in a_win.clone() {
                for ws in s_win.clone() {
                    let v = score(&scores, wa, ws);
                    if v < best.0 || (v == best.0 && (wa, ws) < (best.1, best.2)) {
                        best = (v, wa, ws);
                    }
                }
            }
            if (best.1, best.2) == (a, s) {
                break;
            }
            (a, s) = (best.1, best.2);
        }
    }
    Ok(optimum(&scores))
}

/// The objective of every candidate scored so far, by grid key.
type Scores = std::collections::HashMap<(usize, usize), f64>;

/// The key of candidate `(a, s)`: α = 0 makes every σ equal, so one key
/// stands for all of them.
fn grid_key(a: usize, s: usize) -> (usize, usize) {
    if a == ALPHA_ZERO {
        (a, 0)
    } else {
        (a, s)
    }
}

/// The local minima of the first stage's grid (no neighbour strictly
/// better), best first: (objective, α index, σ index).
fn coarse_minima(scores: &Scores) -> Vec<(f64, usize, usize)> {
    let score = |a: usize, s: usize| scores[&grid_key(a, s)];
    // Its local minima (no neighbour strictly better), best first.
    let (na, ns) = (ALPHA_STEPS / COARSE_ALPHA, SIGMA_STEPS);
    let mut minima: Vec<(f64, usize, usize)> = Vec::new();
    for ca in 0..=na {
        for s in 0..=ns {
            let v = score(ca * COARSE_ALPHA, s);
            let mut lowest = true;
            for (da, ds) in [
                (-1, -1),
                (-1, 0),
                (-1, 1),
                (0, -1),
                (0, 1),
                (1, -1),
                (1, 0),
                (1, 1),
            ] {
                let (qa, qs) = (ca as i64 + da, s as i64 + ds);
                if qa < 0 || qs < 0 || qa > na as i64 || qs > ns as i64 {
                    continue;
                }
                if score(qa as usize * COARSE_ALPHA, qs as usize) < v {
                    lowest = false;
                    break;
                }
            }
            if lowest {
                minima.push((v, ca * COARSE_ALPHA, s));
            }
        }
    }
    minima.sort_by(|x, y| x.0.total_cmp(&y.0).then((x.1, x.2).cmp(&(y.1, y.2))));
    minima
}

/// The optimum over everything scored (ties to the first in (α, σ) order)
/// with its valley.
fn optimum(scores: &Scores) -> FitResult {
    // The optimum over everything scored, ties to the first in (α, σ) order.
    let mut all: Vec<((usize, usize), f64)> = scores.iter().map(|(&k, &v)| (k, v)).collect();
    all.sort_by(|x, y| x.1.total_cmp(&y.1).then(x.0.cmp(&y.0)));
    let ((ba, bs), distance) = all[0];
    let p = grid_params(ba, bs);
    let margin = valley_margin(distance);
    let (mut alpha_range, mut sigma_range) = ((p.alpha, p.alpha), (p.sigma_um, p.sigma_um));
    for &((a, s), v) in &all {
        if v > distance + margin {
            break;
        }
        let q = grid_params(a, s);
        alpha_range = (alpha_range.0.min(q.alpha), alpha_range.1.max(q.alpha));
        let (lo, hi) = if a == ALPHA_ZERO {
            (
                grid_params(0, 0).sigma_um,
                grid_params(0, SIGMA_STEPS).sigma_um,
            )
        } else {
            (q.sigma_um, q.sigma_um)
        };
        sigma_range = (sigma_range.0.min(lo), sigma_range.1.max(hi));
    }
    FitResult {
        alpha: p.alpha,
        sigma_um: p.sigma_um,
        distance,
        evaluations: scores.len(),
        alpha_range,
        sigma_range_um: sigma_range,
    }
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

/// The lines of a fitted model, for reports: α's slope on each side of
/// r = 1 (its segments adjacent to (1, 0)), σ = a·r + b on each side, and
/// the samples the α fit left to the clamp.
#[derive(Clone, Debug, PartialEq)]
pub struct ModelLines {
    /// Samples (r, α) at α's clamp (−2 or 1) where the line through the
    /// others runs past the clamp: the clamped model meets them exactly, so
    /// they do not enter its least squares.
    pub alpha_at_clamp: Vec<(f64, f64)>,
    /// α slope just below r = 1.
    pub alpha_compression_slope: f64,
    /// α slope just above r = 1.
    pub alpha_stretch_slope: f64,
    /// σ = a·r + b for r < 1 (µm).
    pub sigma_compression: (f64, f64),
    /// σ = a·r + b for r ≥ 1 (µm).
    pub sigma_stretch: (f64, f64),
}

/// The smallest σ of a fitted model (µm).
const SIGMA_FLOOR_UM: f64 = 1.0;

/// α at the clamps of the model.
const ALPHA_LIMITS: (f64, f64) = (-2.0, 1.0);

/// The continuous piecewise-linear α(r) through (1, 0) with knots at `ends`,
/// at 1 and at `breaks`, fitted by least squares to `points` and clamped to
/// [−2, 1]. A point at a clamp value (a saturated sample) counts only while
/// the unclamped model is inside the clamp there: beyond it the clamped
/// model meets it exactly. The knot values are the unknowns (hat
/// functions); the value at 1 is 0.
/// Returns the model and the points left to the clamp.
fn fit_alpha(
    points: &[(f64, f64)],
    ends: (f64, f64),
    breaks: &[f64],
) -> Result<(PiecewiseLinear, Vec<(f64, f64)>)> {
    let mut knots: Vec<f64> = vec![ends.0, 1.0, ends.1];
    knots.extend_from_slice(breaks);
    knots.sort_by(f64::total_cmp);
    knots.dedup();
    let free: Vec<usize> = (0..knots.len()).filter(|&k| knots[k] != 1.0).collect();
    // Hat-function weights of point r on each free knot.
    let row = |r: f64| -> Vec<f64> {
        let mut w = vec![0.0; knots.len()];
        let k = knots.partition_point(|&t| t <= r).clamp(1, knots.len() - 1);
        let (t0, t1) = (knots[k - 1], knots[k]);
        let f = (r - t0) / (t1 - t0);
        w[k - 1] = 1.0 - f;
        w[k] = f;
        free.iter().map(|&j| w[j]).collect()
    };
    for pair in knots.windows(2) {
        if !points.iter().any(|&(r, _)| r >= pair[0] && r <= pair[1]) {
            return Err(Error::parameter(
                "alpha_breaks",
                format!(
                    "the α segment from r = {} to {} has no sample; move or drop a break",
                    pair[0], pair[1]
                ),
            ));
        }
    }
    let saturated = |a: f64| a <= ALPHA_LIMITS.0 + 1e-9 || a >= ALPHA_LIMITS.1 - 1e-9;
    let mut values = vec![0.0; free.len()];
    let mut left_out: Vec<bool> = vec![false; points.len()];
    for _ in 0..10 {
        let used: Vec<&(f64, f64)> = points
            .iter()
            .zip(&left_out)
            .filter(|(_, &out)| !out)
            .map(|(p, _)| p)
            .collect();
        let a = nalgebra::DMatrix::from_fn(used.len(), free.len(), |i, j| row(used[i].0)[j]);
        let b = nalgebra::DVector::from_iterator(used.len(), used.iter().map(|p| p.1));
        let solution = a
            .svd(true, true)
            .solve(&b, 1e-12)
            .map_err(|e| Error::parameter("samples", format!("α fit failed: {e}")))?;
        values = solution.iter().copied().collect();
        let model = |r: f64| row(r).iter().zip(&values).map(|(w, v)| w * v).sum::<f64>();
        let next: Vec<bool> = points
            .iter()
            .map(|&(r, a)| {
                saturated(a)
                    && ((a < 0.0 && model(r) <= ALPHA_LIMITS.0)
                        || (a > 0.0 && model(r) >= ALPHA_LIMITS.1))
            })
            .collect();
        if next == left_out {
            break;
        }
        left_out = next;
    }
    let mut table: Vec<(f64, f64)> = Vec::new();
    let mut value_at = free.iter().zip(&values);
    let mut knot_values: Vec<(f64, f64)> = knots
        .iter()
        .map(|&t| {
            if t == 1.0 {
                (t, 0.0)
            } else {
                let (_, &v) = value_at.next().expect("one value per free knot");
                (t, v)
            }
        })
        .collect();
    // Corners where a segment crosses a clamp, then the clamped values.
    for pair in knot_values.windows(2) {
        let ((r0, v0), (r1, v1)) = (pair[0], pair[1]);
        table.push((r0, v0));
        for limit in [ALPHA_LIMITS.0, ALPHA_LIMITS.1] {
            if (v0 - limit) * (v1 - limit) < 0.0 {
                table.push((r0 + (limit - v0) / (v1 - v0) * (r1 - r0), limit));
            }
        }
    }
    table.push(knot_values.pop().expect("three knots at least"));
    table.sort_by(|x, y| x.0.total_cmp(&y.0));
    table.dedup_by(|x, y| x.0 == y.0);
    let at_clamp = points
        .iter()
        .zip(&left_out)
        .filter(|(_, &out)| out)
        .map(|(&p, _)| p)
        .collect();
    Ok((
        PiecewiseLinear {
            points: table
                .into_iter()
                .map(|(r, v)| (r, v.clamp(ALPHA_LIMITS.0, ALPHA_LIMITS.1)))
                .collect(),
        },
        at_clamp,
    ))
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

/// Fits a kernel model to points (see the module docs); `alpha_breaks` are
/// extra knots of α(r) (the seed partitions r by inspecting the data; none
/// gives one line per side). Needs at least one point with r < 1 and one
/// with r > 1.
pub fn fit_model(
    points: &[FittedPoint],
    alpha_breaks: &[f64],
) -> Result<(KernelModel, ModelLines)> {
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
    for (k, &b) in alpha_breaks.iter().enumerate() {
        if !(b.is_finite() && b > r_min && b < r_max && b != 1.0) {
            return Err(Error::parameter(
                format!("alpha_breaks[{k}]"),
                format!("must lie in ({r_min}, {r_max}) and differ from 1, got {b}"),
            ));
        }
    }
    let samples: Vec<(f64, f64)> = points.iter().map(|p| (p.r, p.alpha)).collect();
    let (alpha, alpha_at_clamp) = fit_alpha(&samples, (r_min, r_max), alpha_breaks)?;
    let slope_at_one = |below: bool| {
        let p = &alpha.points;
        let k = p.partition_point(|q| q.0 < 1.0);
        let (a, b) = if below {
            (p[k - 1], p[k])
        } else {
            (p[k], p[k + 1])
        };
        (b.1 - a.1) / (b.0 - a.0)
    };
    let (kc, ks) = (slope_at_one(true), slope_at_one(false));
    // σ = a·r + b floored at 1 µm, with a corner where the line crosses
    // the floor (flooring only the ends would bend the line).
    let sigma_table = |(a, b): (f64, f64), lo: f64, hi: f64| {
        let (at_lo, at_hi) = (a * lo + b, a * hi + b);
        let mut points = vec![(lo, at_lo.max(SIGMA_FLOOR_UM))];
        if (at_lo - SIGMA_FLOOR_UM) * (at_hi - SIGMA_FLOOR_UM) < 0.0 {
            points.push(((SIGMA_FLOOR_UM - b) / a, SIGMA_FLOOR_UM));
        }
        points.push((hi, at_hi.max(SIGMA_FLOOR_UM)));
        PiecewiseLinear { points }
    };
    let model = KernelModel {
        alpha,
        sigma_compression_um: sigma_table(sc, r_min, 1.0),
        sigma_stretch_um: sigma_table(ss, 1.0, r_max),
    };
    model.validate("fitted model")?;
    Ok((
        model,
        ModelLines {
            alpha_at_clamp,
            alpha_compression_slope: kc,
            alpha_stretch_slope: ks,
            sigma_compression: sc,
            sigma_stretch: ss,
        },
    ))
}
