//! Microstructure synthesis from a measured exemplar (Graham et al. 2013 §4):
//! constrained texture synthesis in the Image Analogies framework.
//!
//! Given an exemplar micro map A′ (≈ 1 cm² at ≈ 10 µm) and a mesostructure
//! map B (a scan at a coarser resolution), it makes B′: B's shape with the
//! exemplar's microstructure, pores and creases of B drawing on exemplar
//! places whose mesostructure looks alike.
//!
//! 1. Everything is brought to the output texel: A′ resampled if its texel
//!    differs, B upsampled bilinearly over the output grid. Heights in µm.
//! 2. The analogy's other half: A = A′ blurred by a Gaussian of σ_m
//!    ("matched to B's resolution"; default one B texel), the mesostructure
//!    of the exemplar.
//! 3. Frequencies split with a wider Gaussian σ_L (default 4 σ_m): each of
//!    A, A′, B loses its low pass, `X_h = X − G_L * X`, so B_h's medium
//!    frequencies guide the match and B's low pass is never replaced.
//! 4. Coarse to fine over `levels` Gaussian pyramid levels, with the
//!    neighbourhood window growing from `window_coarse` to `window_fine`
//!    (5 × 5 to 13 × 13 in the seed). The output is a map S from output
//!    texels to exemplar texels (B′_h(q) = A′_h(S(q))). The coarsest
//!    level starts from blocks of window × window texels, each a piece of
//!    the exemplar at an offset drawn from the seed; each finer level
//!    starts from the coarser S upsampled (a texel's four children take
//!    the four children of its source); then `passes` correction passes
//!    visit every texel.
//! 5. Per texel q, the feature is the Gaussian-weighted window of B_h
//!    around q, weighted √(1 − α), next to the window of the current B′_h,
//!    weighted √α; an exemplar texel p has [A_h window, A′_h window] the
//!    same way. So the squared distance is α |N_A′(p) − N_B′(q)|² +
//!    (1 − α) |N_A(p) − N_B(q)|², α the paper's weight. Features are reduced
//!    by PCA to `pca_dims` (default the window side n for an n × n window,
//!    as in the seed).
//! 6. Best approximate match: the nearest exemplar feature from a k-d tree
//!    ([`ann`]), visiting at most `ann_leaves` leaves. Best coherence match
//!    (Ashikhmin): the candidates S(r) + (q − r) of q's eight neighbours r
//!    and S(q) itself. The coherent one wins when
//!    `d_coh ≤ d_app (1 + 2^(l − L) κ)²` (l the level, L the finest), κ
//!    the coherence parameter (1 in the seed; see [`SynthParams::kappa`]).
//! 7. B′ = G_L * B + A′_h(S): the frequencies recombined, where each
//!    texel's A′_h value is the Gaussian-weighted mean of what its
//!    neighbours' sources say it should be (`blend_radius`; a seam between
//!    two patches would otherwise be a step that adds power at the highest
//!    frequencies).
//! 8. The mesostructure restored (`restore_passes`): B′ += G_m * (B − B′),
//!    so that B′ seen at B's resolution matches B seen at it to within a
//!    few per cent of B's range (the match alone leaves ≈ 12 %).
//!
//! Parallel and deterministic: a correction pass runs as four sub-passes
//! over the texels of one parity class (i mod 2, j mod 2) each, every texel
//! of a sub-pass reading S as it was before the sub-pass, so the result
//! does not depend on the thread count. Random starts come from a hash of
//! (seed, block). Exemplars with `Edge::Wrap` offer every texel (windows
//! wrap); with `Edge::Clamp` only those whose window lies inside. An
//! output with `Edge::Wrap` is a torus: windows wrap, and the map tiles
//! without a seam.

pub mod ann;
mod level;

use std::time::Instant;

use rayon::prelude::*;

use super::convolve::blur_along_axis;
use super::map::{DisplacementMap, Edge};
use crate::error::{shown, Error, Result};
use level::LevelData;

/// Parameters of the synthesis.
#[derive(Clone, Debug, PartialEq)]
pub struct SynthParams {
    /// σ (µm) of the Gaussian that takes the exemplar to the mesostructure
    /// map's level of detail (A = G * A′). Default: one mesostructure texel,
    /// or four output texels without a mesostructure map.
    pub mesostructure_sigma_um: Option<f64>,
    /// σ (µm) of the low pass kept from the mesostructure map. Default
    /// 4 × `mesostructure_sigma_um`.
    pub lowpass_sigma_um: Option<f64>,
    /// Pyramid levels (1: the output resolution only).
    pub levels: usize,
    /// Window side at the coarsest level (odd).
    pub window_coarse: usize,
    /// Window side at the finest level (odd).
    pub window_fine: usize,
    /// Weight of the A′/B′ neighbourhoods against the A/B ones, [0, 1].
    pub alpha: f64,
    /// Coherence parameter κ ≥ 0 (0: the approximate match whenever it is
    /// closer). The seed uses 1 with scan-line synthesis, where a coherent
    /// candidate's window holds only texels already made to agree with it;
    /// the parallel correction passes here compare whole windows, seams
    /// included, and need a larger κ for patches of the same size
    /// (docs/SYNTHESIS.md has the measurements behind the default, 100).
    pub kappa: f64,
    /// Correction passes per level.
    pub passes: usize,
    /// Dimensions kept by PCA; `None`: the window side, `Some(0)`: no PCA.
    pub pca_dims: Option<usize>,
    /// Leaves of the k-d tree visited per query (0: exact search).
    pub ann_leaves: usize,
    /// Random seed of the coarsest level's start.
    pub seed: u64,
    /// Seam blending: each output texel averages what the sources of its
    /// neighbours within this many texels say it should be (0: copies).
    pub blend_radius: usize,
    /// Mesostructure restoring passes: B′ += G_m * B − G_m * B′ each, so
    /// that B′ seen at B's resolution converges to B seen at it.
    pub restore_passes: usize,
}

impl Default for SynthParams {
    fn default() -> Self {
        SynthParams {
            mesostructure_sigma_um: None,
            lowpass_sigma_um: None,
            levels: 3,
            window_coarse: 5,
            window_fine: 13,
            alpha: 0.5,
            kappa: 100.0,
            passes: 3,
            pca_dims: None,
            ann_leaves: 8,
            seed: 1,
            blend_radius: 1,
            restore_passes: 2,
        }
    }
}

/// Most pyramid levels.
pub const MAX_LEVELS: usize = 8;
/// Widest window.
pub const MAX_WINDOW: usize = 31;
/// Most correction passes per level.
pub const MAX_PASSES: usize = 16;

impl SynthParams {
    /// Checks every parameter; `key` prefixes the names in errors.
    pub fn validate(&self, key: &str) -> Result<()> {
        let bad =
            |name: &str, reason: String| Err(Error::parameter(format!("{key}.{name}"), reason));
        for (name, v) in [
            ("mesostructure_sigma_um", self.mesostructure_sigma_um),
            ("lowpass_sigma_um", self.lowpass_sigma_um),
        ] {
            if let Some(v) = v {
                if !(v.is_finite() && v > 0.0) {
                    return bad(name, format!("must be finite and > 0, got {}", shown(v)));
                }
            }
        }
        if !(1..=MAX_LEVELS).contains(&self.levels) {
            return bad(
                "levels",
                format!("must be in 1 … {MAX_LEVELS}, got {}", self.levels),
            );
        }
        for (name, w) in [
            ("window_coarse", self.window_coarse),
            ("window_fine", self.window_fine),
        ] {
            if !(3..=MAX_WINDOW).contains(&w) || w % 2 == 0 {
                return bad(name, format!("must be odd, in 3 … {MAX_WINDOW}, got {w}"));
            }
        }
        if self.window_coarse > self.window_fine {
            return bad(
                "window_coarse",
                format!(
                    "must not exceed window_fine ({}), got {}",
                    self.window_fine, self.window_coarse
                ),
            );
        }
        if !(0.0..=1.0).contains(&self.alpha) {
            return bad(
                "alpha",
                format!("must be in [0, 1], got {}", shown(self.alpha)),
            );
        }
        if !(self.kappa.is_finite() && self.kappa >= 0.0) {
            return bad(
                "kappa",
                format!("must be finite and ≥ 0, got {}", shown(self.kappa)),
            );
        }
        if !(1..=MAX_PASSES).contains(&self.passes) {
            return bad(
                "passes",
                format!("must be in 1 … {MAX_PASSES}, got {}", self.passes),
            );
        }
        if let Some(d) = self.pca_dims {
            let most = 2 * self.window_coarse * self.window_coarse;
            if d > most {
                return bad(
                    "pca_dims",
                    format!("must be at most 2 × window_coarse² = {most} (0: no PCA), got {d}"),
                );
            }
        }
        Ok(())
    }

    /// Window side at `level` of `levels` (0 coarsest): from
    /// `window_coarse` to `window_fine` in equal steps, rounded to odd.
    pub fn window(&self, level: usize) -> usize {
        if self.levels <= 1 {
            return self.window_fine;
        }
        let t = level as f64 / (self.levels - 1) as f64;
        let w = self.window_coarse as f64 + t * (self.window_fine - self.window_coarse) as f64;
        // Nearest odd number.
        (((w - 1.0) / 2.0).round() as usize) * 2 + 1
    }
}

/// What to synthesize from.
#[derive(Clone, Copy, Debug)]
pub struct SynthInputs<'a> {
    /// The exemplar micro map A′.
    pub exemplar: &'a DisplacementMap,
    /// The mesostructure map B to detail (any texel size; covers the output).
    /// None: plain texture synthesis of `size` texels.
    pub mesostructure: Option<&'a DisplacementMap>,
    /// Output texel (µm). None: the exemplar's.
    pub texel_um: Option<f64>,
    /// Output size without a mesostructure map (with one, the output covers it).
    pub size: Option<(usize, usize)>,
    /// Output edge rule. None: the mesostructure map's, else wrap.
    pub edge: Option<Edge>,
}

impl SynthInputs<'_> {
    /// The output texel (µm): the one asked for, else the exemplar's.
    pub fn output_texel(&self) -> Result<f64> {
        let texel = self.texel_um.unwrap_or(self.exemplar.texel_um);
        if !(texel.is_finite() && texel > 0.0) {
            return Err(Error::parameter(
                "synthesis.texel_um",
                format!("must be finite and > 0, got {}", shown(texel)),
            ));
        }
        Ok(texel)
    }

    /// The output grid (texels): the mesostructure map's area at the output
    /// texel, else `size`.
    pub fn output_size(&self) -> Result<(usize, usize)> {
        let texel = self.output_texel()?;
        let (width, height) = match (self.mesostructure, self.size) {
            (Some(_), Some(_)) => {
                return Err(Error::parameter(
                    "synthesis.size_px",
                    "has no effect with a mesostructure map: the output covers the map",
                ))
            }
            (Some(b), None) => (
                (b.width as f64 * b.texel_um / texel).round() as usize,
                (b.height as f64 * b.texel_um / texel).round() as usize,
            ),
            (None, Some(s)) => s,
            (None, None) => {
                return Err(Error::parameter(
                    "synthesis.size_px",
                    "is needed without a mesostructure map",
                ))
            }
        };
        if !(1..=MAX_SIDE).contains(&width) || !(1..=MAX_SIDE).contains(&height) {
            let change = if self.mesostructure.is_some() {
                "the output covers the mesostructure map: use a smaller map (its extent) or a \
                 coarser synthesis.texel_um"
            } else {
                "change synthesis.size_px"
            };
            return Err(Error::parameter(
                "synthesis",
                format!(
                    "output of {width} × {height} texels at {texel} µm: each side must be in \
                     1 … {MAX_SIDE}; {change}"
                ),
            ));
        }
        Ok((width, height))
    }
}

/// One level's figures.
#[derive(Clone, Debug, PartialEq)]
pub struct LevelReport {
    /// Level (0 coarsest).
    pub level: usize,
    /// Output texels (width, height).
    pub size: (usize, usize),
    /// Exemplar texels at this level.
    pub exemplar: (usize, usize),
    /// Window side.
    pub window: usize,
    /// Feature dimensions searched (after PCA).
    pub dims: usize,
    /// Exemplar texels that can be matched.
    pub candidates: usize,
    /// Share of the last pass's texels that took the coherence match.
    pub coherent_share: f64,
    /// Seconds spent on the level (features, PCA, tree, passes).
    pub seconds: f64,
}

/// What a synthesis made.
#[derive(Clone, Debug)]
pub struct Synthesis {
    /// B′: heights in µm, the output texel and edge rule.
    pub map: DisplacementMap,
    /// B at the output texel (µm; zeros without a mesostructure map).
    pub guide: DisplacementMap,
    /// A′ at the output texel (µm).
    pub exemplar: DisplacementMap,
    /// Whether a mesostructure map guided the synthesis.
    pub guided: bool,
    /// Per output texel (row-major), the index `y · width + x` of the
    /// exemplar texel (of the exemplar as given) it copies.
    pub source: Vec<u32>,
    /// σ_m and σ_L used (µm).
    pub sigmas_um: (f64, f64),
    /// Per level, coarse to fine.
    pub levels: Vec<LevelReport>,
    /// Whole synthesis (s).
    pub seconds: f64,
}

/// Largest output or exemplar side.
pub const MAX_SIDE: usize = 32768;

/// Synthesizes B′. `on_level` hears of each level as it finishes.
pub fn synthesize(
    inputs: &SynthInputs<'_>,
    params: &SynthParams,
    on_level: &mut dyn FnMut(&LevelReport),
) -> Result<Synthesis> {
    let start = Instant::now();
    params.validate("synthesis")?;
    let exemplar = inputs.exemplar;
    check_map("synthesis.exemplar", exemplar)?;
    if let Some(b) = inputs.mesostructure {
        check_map("synthesis.mesostructure", b)?;
    }
    let texel = inputs.output_texel()?;
    let (width, height) = inputs.output_size()?;
    let edge = inputs
        .edge
        .or(inputs.mesostructure.map(|b| b.edge))
        .unwrap_or(Edge::Wrap);
    // The exemplar's grid at the output texel.
    let f = exemplar.texel_um / texel;
    let (ew, eh) = (
        (exemplar.width as f64 * f).round() as usize,
        (exemplar.height as f64 * f).round() as usize,
    );
    if ew.max(eh) > MAX_SIDE {
        return Err(Error::parameter(
            "synthesis.exemplar",
            format!("at the output texel ({texel} µm) it would be {ew} × {eh} texels, more than {MAX_SIDE} a side"),
        ));
    }
    check_memory(
        estimated_bytes(width * height, ew * eh, params),
        crate::memory::available(),
    )?;

    // 1. Heights in µm at the output texel.
    let a1 = if (ew, eh) == (exemplar.width, exemplar.height) {
        in_um(exemplar, texel)
    } else {
        in_um(&exemplar.resampled(ew, eh), texel)
    };
    let guide = match inputs.mesostructure {
        Some(b) => in_um(&b.resampled(width, height), texel),
        None => DisplacementMap::zeros(width, height, texel, edge),
    };
    let guide = DisplacementMap { edge, ..guide };

    // 2–3. The analogy and the frequency split.
    let sigma_m = params
        .mesostructure_sigma_um
        .unwrap_or(match inputs.mesostructure {
            Some(b) => b.texel_um,
            None => 4.0 * texel,
        });
    let sigma_l = params.lowpass_sigma_um.unwrap_or(4.0 * sigma_m);
    // A blur wider than every map leaves only their means (and its kernel
    // would take memory and time without bound): refused.
    let widest = (width.max(height).max(ew).max(eh) as f64) * texel;
    for (key, sigma) in [
        ("synthesis.mesostructure_sigma_um", sigma_m),
        (
            if params.lowpass_sigma_um.is_some() {
                "synthesis.lowpass_sigma_um"
            } else {
                "synthesis.lowpass_sigma_um (by default 4 × mesostructure_sigma_um)"
            },
            sigma_l,
        ),
    ] {
        if sigma > widest {
            return Err(Error::parameter(
                key,
                format!(
                    "is {} µm, wider than the largest map ({} µm = {} texels of {} µm)",
                    shown(sigma),
                    shown(widest),
                    width.max(height).max(ew).max(eh),
                    shown(texel)
                ),
            ));
        }
    }
    let a = gauss(&a1, sigma_m / texel);
    let high = |m: &DisplacementMap| -> (DisplacementMap, DisplacementMap) {
        let low = gauss(m, sigma_l / texel);
        let h = m.with_data(m.data.iter().zip(&low.data).map(|(x, l)| x - l).collect());
        (low, h)
    };
    let (_, a_h) = high(&a);
    let (_, a1_h) = high(&a1);
    let (b_low, b_h) = high(&guide);

    // 4. Pyramids, finest first.
    let pyramid = |m| pyramid(m, params.levels);
    let (pa, pa1, pb) = (pyramid(a_h), pyramid(a1_h), pyramid(b_h));
    check_levels(&pa1, exemplar.edge, params)?;

    let (s, reports) = match_levels(&pa, &pa1, &pb, exemplar.edge, params, on_level);

    // 7. Recombined.
    let a1_h = &pa1[0];
    let detail = resolve(&s, &b_low, a1_h, params.blend_radius);
    let data: Vec<f32> = detail
        .iter()
        .zip(&b_low.data)
        .map(|(&d, &l)| l + d)
        .collect();
    let mut map = DisplacementMap {
        texel_um: texel,
        height_unit_um: 1.0,
        edge,
        ..guide.with_data(data)
    };
    restore_mesostructure(&mut map, &guide, sigma_m / texel, params.restore_passes);
    let source = exemplar_sources(s, (a1_h.width, a1_h.height), exemplar);
    Ok(Synthesis {
        map,
        guide,
        exemplar: a1,
        guided: inputs.mesostructure.is_some(),
        source,
        sigmas_um: (sigma_m, sigma_l),
        levels: reports,
        seconds: start.elapsed().as_secs_f64(),
    })
}

/// Every pyramid level's exemplar must hold the level's window (inside it,
/// for an exemplar that does not wrap) and be at least 2 × 2 texels.
fn check_levels(pa1: &[DisplacementMap], exemplar_edge: Edge, params: &SynthParams) -> Result<()> {
    let top = params.levels - 1;
    for level in 0..params.levels {
        let ex = &pa1[top - level];
        let n = params.window(level);
        if exemplar_edge == Edge::Clamp && (ex.width <= n || ex.height <= n)
            || ex.width < 2
            || ex.height < 2
        {
            return Err(Error::parameter(
                "synthesis.exemplar",
                format!(
                    "is too small: at pyramid level {level} it has {} × {} texels, the window \
                     is {n} × {n}{}; use fewer levels, smaller windows or a larger exemplar",
                    ex.width,
                    ex.height,
                    if exemplar_edge == Edge::Clamp {
                        " and must fit inside it (the exemplar does not wrap)"
                    } else {
                        ""
                    }
                ),
            ));
        }
    }
    Ok(())
}

/// Steps 4–6, coarse to fine: S started (or upsampled from the coarser
/// level) and corrected `passes` times per level; `pa`, `pa1`, `pb` are the
/// pyramids of A_h, A′_h and B_h, finest first.
fn match_levels(
    pa: &[DisplacementMap],
    pa1: &[DisplacementMap],
    pb: &[DisplacementMap],
    exemplar_edge: Edge,
    params: &SynthParams,
    on_level: &mut dyn FnMut(&LevelReport),
) -> (Vec<u32>, Vec<LevelReport>) {
    let top = params.levels - 1;
    let mut s: Vec<u32> = Vec::new();
    let mut reports = Vec::new();
    for level in 0..params.levels {
        let t0 = Instant::now();
        let k = top - level;
        let lv = LevelData::new(&pa[k], &pa1[k], &pb[k], exemplar_edge, params, level);
        s = if level == 0 {
            lv.start(params.seed)
        } else {
            lv.upsample(&s, pb[k + 1].width, pa1[k + 1].width)
        };
        let mut coherent = 0usize;
        for _ in 0..params.passes {
            coherent = lv.correct(&mut s);
        }
        let report = LevelReport {
            level,
            size: (lv.guide.width, lv.guide.height),
            exemplar: (lv.ex_a1.width, lv.ex_a1.height),
            window: lv.window,
            dims: lv.projection.dims(),
            candidates: lv.candidates.len(),
            coherent_share: coherent as f64 / s.len().max(1) as f64,
            seconds: t0.elapsed().as_secs_f64(),
        };
        on_level(&report);
        reports.push(report);
    }
    (s, reports)
}

/// Step 8: B′ += G_m * (B − B′), `passes` times (σ_m in texels).
fn restore_mesostructure(
    map: &mut DisplacementMap,
    guide: &DisplacementMap,
    sigma_texels: f64,
    passes: usize,
) {
    let guide_low = (passes > 0).then(|| gauss(guide, sigma_texels));
    for guide_low in std::iter::repeat_n(guide_low.as_ref(), passes).flatten() {
        let low = gauss(map, sigma_texels);
        map.data
            .par_iter_mut()
            .zip(&guide_low.data)
            .zip(&low.data)
            .for_each(|((x, b), l)| *x += b - l);
    }
}

/// S's exemplar texels (on the grid of `size`, the exemplar at the output
/// texel) as texels of the exemplar as given.
fn exemplar_sources(s: Vec<u32>, (ew, eh): (usize, usize), exemplar: &DisplacementMap) -> Vec<u32> {
    if (ew, eh) == (exemplar.width, exemplar.height) {
        s
    } else {
        let (fx, fy) = (
            exemplar.width as f64 / ew as f64,
            exemplar.height as f64 / eh as f64,
        );
        s.iter()
            .map(|&p| {
                let (x, y) = ((p as usize % ew) as f64, (p as usize / ew) as f64);
                let xo = (((x + 0.5) * fx) as usize).min(exemplar.width - 1);
                let yo = (((y + 0.5) * fy) as usize).min(exemplar.height - 1);
                (yo * exemplar.width + xo) as u32
            })
            .collect()
    }
}

/// The synthesized detail B′_h: per output texel q, the exemplar detail at
/// S(q) when `radius` is 0, else the mean over the neighbours r within
/// `radius` (a square) of what r's source says q should be, A′_h(S(r) +
/// q − r), with Gaussian weights. Inside a coherent patch every neighbour
/// says the same; across a seam between patches the two sides are
/// averaged over a few texels instead of meeting in a step, which would
/// add power at the highest frequencies that the exemplar does not have.
fn resolve(s: &[u32], like: &DisplacementMap, detail: &DisplacementMap, radius: usize) -> Vec<f32> {
    let (w, h) = (like.width, like.height);
    if radius == 0 {
        return s.iter().map(|&p| detail.data[p as usize]).collect();
    }
    let r = radius as isize;
    let ew = detail.width as isize;
    let sigma = (radius as f32).max(0.5);
    let mut out = vec![0.0f32; w * h];
    out.par_chunks_mut(w).enumerate().for_each(|(j, row)| {
        for (i, o) in row.iter_mut().enumerate() {
            let (mut sum, mut norm) = (0.0f32, 0.0f32);
            for dy in -r..=r {
                for dx in -r..=r {
                    let (x, y) = (i as isize + dx, j as isize + dy);
                    let (x, y) = match like.edge {
                        Edge::Wrap => (x.rem_euclid(w as isize), y.rem_euclid(h as isize)),
                        Edge::Clamp => {
                            if x < 0 || y < 0 || x >= w as isize || y >= h as isize {
                                continue;
                            }
                            (x, y)
                        }
                    };
                    let p = s[y as usize * w + x as usize] as isize;
                    let g = (-((dx * dx + dy * dy) as f32) / (2.0 * sigma * sigma)).exp();
                    sum += g * detail.texel(p % ew - dx, p / ew - dy);
                    norm += g;
                }
            }
            *o = sum / norm;
        }
    });
    out
}

/// How a synthesis compares with its inputs (the figures of the tests and
/// of `synthesis.json`).
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct SynthStatistics {
    /// RMS of `G_m * B′ − G_m * B` over B's height range: the mesostructure
    /// kept (None without B).
    pub low_frequency_rms: Option<f64>,
    /// Total variation between the 64 × 64 normal histograms of B′ and A′
    /// (half range from the data, as the kernel fit does).
    pub histogram_tv: f64,
    /// Largest `|P_B′/P_A′ − 1|` over the octaves of the microstructure band,
    /// from `1/(π σ_m)` to Nyquist (None when the band holds no octave).
    pub spectrum_worst: Option<f64>,
    /// Per octave of that band: (low, high) cycles/µm, B′'s and A′'s power.
    pub spectrum: Vec<(f64, f64, f64, f64)>,
}

/// The statistics of a synthesis against its exemplar and mesostructure.
pub fn statistics(s: &Synthesis) -> SynthStatistics {
    use super::normals::NormalHistogram;
    use super::spectrum::{band_difference, octaves};
    let texel = s.map.texel_um;
    let sm = s.sigmas_um.0 / texel;
    let low_frequency_rms = s.guided.then(|| {
        let (lo, hi) = s.guide.range();
        let (a, b) = (gauss(&s.map, sm), gauss(&s.guide, sm));
        let sum: f64 = a
            .data
            .iter()
            .zip(&b.data)
            .map(|(x, y)| ((x - y) as f64).powi(2))
            .sum();
        (sum / a.data.len().max(1) as f64).sqrt() / ((hi - lo) as f64).max(f64::MIN_POSITIVE)
    });
    let range = super::fit::auto_range(&[&s.exemplar, &s.map]);
    let histogram_tv = NormalHistogram::of(&s.map, 64, range, [1.0, 1.0])
        .distance(&NormalHistogram::of(&s.exemplar, 64, range, [1.0, 1.0]));
    let from = 1.0 / (std::f64::consts::PI * s.sigmas_um.0);
    let band = band_difference(&octaves(&s.map), &octaves(&s.exemplar), from, 1.0);
    let (spectrum_worst, spectrum) = match band {
        Some((worst, pairs)) => (
            Some(worst),
            pairs
                .iter()
                .map(|(a, b)| (a.low_per_um, a.high_per_um, a.power, b.power))
                .collect(),
        ),
        None => (None, Vec::new()),
    };
    SynthStatistics {
        low_frequency_rms,
        histogram_tv,
        spectrum_worst,
        spectrum,
    }
}

/// About how many bytes a synthesis holds at its peak: per output texel
/// the guide, its low and high passes, their pyramids, the result and S
/// (≈ 48 B); per exemplar texel its maps and pyramids (≈ 48 B) and, at the
/// finest level, the candidates' features twice (the features and the
/// k-d tree's copy), 8 B per dimension. Measured peaks: 0.88 GB for 4096²
/// from a 1024² exemplar (estimate 0.96 GB), 2.91 GB without PCA at 1024²
/// (estimate 2.94 GB).
pub fn estimated_bytes(output_texels: usize, exemplar_texels: usize, params: &SynthParams) -> u64 {
    let n = params.window_fine;
    let dims = match params.pca_dims {
        Some(0) => 2 * n * n,
        Some(d) => d.min(2 * n * n),
        None => n,
    };
    output_texels as u64 * 48 + exemplar_texels as u64 * (48 + 8 * dims as u64)
}

/// An error when `needed` bytes exceed what is `available`.
pub fn check_memory(needed: u64, available: Option<u64>) -> Result<()> {
    match available {
        Some(have) if needed > have => Err(Error::parameter(
            "synthesis",
            format!(
                "needs about {:.1} GB of memory, {:.1} GB are available: synthesize a smaller \
                 output (per facial region), use a coarser texel_um, or PCA (pca_dims) with \
                 fewer dimensions",
                needed as f64 / 1e9,
                have as f64 / 1e9
            ),
        )),
        _ => Ok(()),
    }
}

/// Size and finiteness of an input map.
fn check_map(key: &str, m: &DisplacementMap) -> Result<()> {
    if m.width == 0 || m.height == 0 || m.width.max(m.height) > MAX_SIDE {
        return Err(Error::parameter(
            key,
            format!(
                "is {} × {} texels; each side must be in 1 … {MAX_SIDE}",
                m.width, m.height
            ),
        ));
    }
    if !(m.texel_um.is_finite() && m.texel_um > 0.0) {
        return Err(Error::parameter(
            key,
            format!(
                "has texel size {} µm; it must be finite and > 0",
                shown(m.texel_um)
            ),
        ));
    }
    if let Some(k) = m.data.iter().position(|h| !h.is_finite()) {
        return Err(Error::parameter(
            key,
            format!(
                "height at texel ({}, {}) is not finite",
                k % m.width,
                k / m.width
            ),
        ));
    }
    // Feature distances are squared sums in f32: heights beyond this would
    // overflow them (and no skin is a metre deep).
    let unit = m.height_unit_um;
    if !(unit.is_finite() && unit > 0.0) {
        return Err(Error::parameter(
            key,
            format!(
                "has height unit {} µm; it must be finite and > 0",
                shown(unit)
            ),
        ));
    }
    if let Some(k) = m
        .data
        .iter()
        .position(|&h| (h as f64 * unit).abs() > MAX_HEIGHT_UM)
    {
        return Err(Error::parameter(
            key,
            format!(
                "height at texel ({}, {}) is {} µm; heights must be within ±{MAX_HEIGHT_UM:e} µm",
                k % m.width,
                k / m.width,
                shown(m.data[k] as f64 * unit)
            ),
        ));
    }
    Ok(())
}

/// Largest height of an exemplar or mesostructure map (µm): one metre.
const MAX_HEIGHT_UM: f64 = 1e6;

/// The map in µm with texel `texel` (its grid as it is).
fn in_um(m: &DisplacementMap, texel: f64) -> DisplacementMap {
    let unit = m.height_unit_um as f32;
    DisplacementMap {
        texel_um: texel,
        height_unit_um: 1.0,
        ..m.with_data(m.data.iter().map(|h| h * unit).collect())
    }
}

/// A separable Gaussian blur of σ texels (the map's edge rule).
pub fn gauss(m: &DisplacementMap, sigma: f64) -> DisplacementMap {
    let s = sigma as f32;
    blur_along_axis(&blur_along_axis(m, true, s), false, s)
}

/// A Gaussian pyramid of `levels` levels, finest (`m`) first.
fn pyramid(m: DisplacementMap, levels: usize) -> Vec<DisplacementMap> {
    let mut pyramid = vec![m];
    for _ in 1..levels {
        let next = reduce(pyramid.last().expect("one level at least"));
        pyramid.push(next);
    }
    pyramid
}

/// One pyramid step: blurred by σ = 1 texel, every second texel kept.
fn reduce(m: &DisplacementMap) -> DisplacementMap {
    let b = gauss(m, 1.0);
    let (w, h) = (m.width.div_ceil(2), m.height.div_ceil(2));
    let mut out = DisplacementMap::from_fn(w, h, m.texel_um * 2.0, m.edge, |i, j| {
        b.data[(2 * j) * b.width + 2 * i]
    });
    out.height_unit_um = m.height_unit_um;
    out
}
