//! Slope moments of a microstructure map and their mip pyramid, for
//! prefiltered specular (LEAN mapping, Olano & Baker 2010; the future work
//! of Nagano et al. 2015 §8). CPU reference of `shaders/moments.wgsl`.
//!
//! A height field `h(u, v)` has, per texel, the slopes `x̃ = ∂h/∂u` and
//! `ỹ = ∂h/∂v` in tangent units, which the normal `n = (n_x, n_y, n_z)`
//! of the map carries as `x̃ = −n_x / n_z`, `ỹ = −n_y / n_z` (the microfacet
//! normal of slopes `(x̃, ỹ)` is `normalize(−x̃, −ỹ, 1)`). Level 0 holds per
//! texel the five moments `(x̃, ỹ, x̃², ỹ², x̃ỹ)`; level `k + 1` averages
//! 2 × 2 texels of level `k`, so every level holds the means of the moments
//! over its footprint. From a filtered lookup the shader takes the mean
//! slope and the covariance `Σ = [[E x̃² − x̄², E x̃ỹ − x̄ȳ], [·, E ỹ² − ȳ²]]`
//! of the slopes under the pixel, and shades with a Gaussian slope
//! distribution of that mean and covariance plus each lobe's own
//! (`render::specular::lean_brdf`).
//!
//! Level sizes follow GPU mip chains: side `n` becomes `max(1, ⌊n/2⌋)`.
//! Texel `i` of the next level averages source texels `2i` and `2i + 1`
//! along each axis, and the last one of an odd side also takes the left-over
//! `n − 1` (a 3-texel box), so every source texel counts in its level.

/// The five slope moments of one texel: `[x̃, ỹ, x̃², ỹ², x̃ỹ]`.
pub type Moments = [f32; 5];

/// One level of the pyramid.
#[derive(Clone, Debug, PartialEq)]
pub struct MomentLevel {
    /// Width in texels.
    pub width: usize,
    /// Height in texels.
    pub height: usize,
    /// Moments, row-major like the map.
    pub texels: Vec<Moments>,
}

/// The pyramid from the full-resolution level down to 1 × 1.
#[derive(Clone, Debug, PartialEq)]
pub struct MomentPyramid {
    /// Level 0 first.
    pub levels: Vec<MomentLevel>,
}

/// Levels of the pyramid of a `width × height` map, down to 1 × 1 (a full
/// GPU mip chain: `⌊log2 max(w, h)⌋ + 1`).
pub fn level_count(width: usize, height: usize) -> usize {
    let side = width.max(height).max(1);
    (usize::BITS - side.leading_zeros()) as usize
}

/// Side of level `level` of a side-`n` map.
pub fn level_side(n: usize, level: usize) -> usize {
    (n >> level).max(1)
}

/// Source texels `[first, end)` of texel `i` of the next level of a side
/// `n` (next side `m`).
fn source_span(i: usize, n: usize, m: usize) -> (usize, usize) {
    let first = (2 * i).min(n - 1);
    let end = if i + 1 == m { n } else { 2 * i + 2 };
    (first, end.max(first + 1))
}

/// The moments of one normal.
pub fn texel_moments(n: [f32; 3]) -> Moments {
    // A normal map never holds n_z ≤ 0 for a height field; the floor keeps
    // a corrupt texel finite.
    let nz = n[2].max(1e-6);
    let (x, y) = (-n[0] / nz, -n[1] / nz);
    [x, y, x * x, y * y, x * y]
}

impl MomentPyramid {
    /// The pyramid of a normal map (`width × height`, row-major).
    pub fn from_normals(normals: &[[f32; 3]], width: usize, height: usize) -> MomentPyramid {
        assert_eq!(normals.len(), width * height, "normal map size");
        let mut levels = vec![MomentLevel {
            width,
            height,
            texels: normals.iter().map(|&n| texel_moments(n)).collect(),
        }];
        for _ in 1..level_count(width, height) {
            let next = downsample(levels.last().expect("level 0 exists"));
            levels.push(next);
        }
        MomentPyramid { levels }
    }
}

/// The next level: each texel the mean of its 2 × 2 block (up to 3 × 3 at
/// the end of an odd side), summed row by row in the shader's order.
pub fn downsample(level: &MomentLevel) -> MomentLevel {
    let (w, h) = (level_side(level.width, 1), level_side(level.height, 1));
    let mut texels = Vec::with_capacity(w * h);
    for j in 0..h {
        let (y0, y1) = source_span(j, level.height, h);
        for i in 0..w {
            let (x0, x1) = source_span(i, level.width, w);
            let mut sum = [0.0f32; 5];
            for y in y0..y1 {
                for x in x0..x1 {
                    let t = level.texels[y * level.width + x];
                    for (s, v) in sum.iter_mut().zip(t) {
                        *s += v;
                    }
                }
            }
            let count = ((x1 - x0) * (y1 - y0)) as f32;
            texels.push(sum.map(|v| v / count));
        }
    }
    MomentLevel {
        width: w,
        height: h,
        texels,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn levels_reach_one_texel() {
        assert_eq!(level_count(1, 1), 1);
        assert_eq!(level_count(2, 2), 2);
        assert_eq!(level_count(1024, 1024), 11);
        assert_eq!(level_count(400, 300), 9); // 400 200 100 50 25 12 6 3 1
        let p = MomentPyramid::from_normals(&vec![[0.0, 0.0, 1.0]; 400 * 300], 400, 300);
        let last = p.levels.last().unwrap();
        assert_eq!((last.width, last.height), (1, 1));
    }

    /// A tilted plane's moments are exact at every level: mean slope, and
    /// second moments the squares (no variance).
    #[test]
    fn a_plane_has_no_slope_variance_at_any_level() {
        let (sx, sy) = (0.3f32, -0.2f32);
        let n = {
            let l = (sx * sx + sy * sy + 1.0).sqrt();
            [-sx / l, -sy / l, 1.0 / l]
        };
        let p = MomentPyramid::from_normals(&vec![n; 37 * 20], 37, 20);
        for level in &p.levels {
            for m in &level.texels {
                assert!(
                    (m[0] - sx).abs() < 1e-6 && (m[1] - sy).abs() < 1e-6,
                    "{m:?}"
                );
                assert!((m[2] - m[0] * m[0]).abs() < 1e-6 && (m[4] - m[0] * m[1]).abs() < 1e-6);
            }
        }
    }

    /// Two slopes alternating along u: the top level holds their mean and
    /// variance.
    #[test]
    fn alternating_slopes_average_to_their_variance() {
        let up = texel_moments([-0.5f32 / 1.25f32.sqrt(), 0.0, 1.0 / 1.25f32.sqrt()]);
        assert!((up[0] - 0.5).abs() < 1e-6);
        let (w, h) = (64, 64);
        let normals: Vec<[f32; 3]> = (0..w * h)
            .map(|k| {
                let s: f32 = if k % 2 == 0 { 0.5 } else { -0.5 };
                let l = (1.0 + s * s).sqrt();
                [-s / l, 0.0, 1.0 / l]
            })
            .collect();
        let p = MomentPyramid::from_normals(&normals, w, h);
        let top = p.levels.last().unwrap().texels[0];
        assert!(top[0].abs() < 1e-6, "mean {top:?}");
        assert!((top[2] - 0.25).abs() < 1e-6, "E x² {top:?}");
        assert!(top[1].abs() < 1e-6 && top[3].abs() < 1e-6 && top[4].abs() < 1e-6);
    }
}
