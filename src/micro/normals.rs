//! Normals, normal histograms and slope statistics of a displacement map
//!.
//!
//! Slopes are central differences in micrometres:
//! `∂h/∂x ≈ (h(i+1, j) − h(i−1, j))·unit / (2·texel)` (edge handling of the
//! map at the border), the normal is `normalize(−∂h/∂x, −∂h/∂y, 1)` in the
//! tangent frame (x along u, y along v, z out of the skin). The histogram
//! bins the tangent-plane components `(n_x, n_y)` of every texel's normal
//! into `bins × bins` cells over `[−range, range]²` (values beyond fall into
//! the edge cells) and is normalised to sum 1.

use rayon::prelude::*;

use super::map::DisplacementMap;

/// Default histogram size (64 × 64 buckets, Nagano et al. 2015).
pub const HISTOGRAM_BINS: usize = 64;

/// Slope `(∂h/∂x, ∂h/∂y)` at texel `(i, j)`, dimensionless (µm per µm).
/// `stretch` scales the texel spacing along (x, y): slopes of the map as
/// it would look stretched by those ratios.
#[inline]
pub fn slope(map: &DisplacementMap, i: usize, j: usize, stretch: [f64; 2]) -> [f64; 2] {
    let (i, j) = (i as isize, j as isize);
    let k = central_difference_scale(map);
    let dx = (map.texel(i + 1, j) - map.texel(i - 1, j)) as f64 * k / stretch[0];
    let dy = (map.texel(i, j + 1) - map.texel(i, j - 1)) as f64 * k / stretch[1];
    [dx, dy]
}

/// The factor that turns a central difference of two heights (two texels
/// apart, in the map's height unit) into a slope.
fn central_difference_scale(map: &DisplacementMap) -> f64 {
    map.height_unit_um / (2.0 * map.texel_um)
}

/// Unit normal from a slope.
#[inline]
pub fn normal_of(s: [f64; 2]) -> [f64; 3] {
    let n = (s[0] * s[0] + s[1] * s[1] + 1.0).sqrt();
    [-s[0] / n, -s[1] / n, 1.0 / n]
}

/// The normal map (row-major, like the map).
///
/// Rows in parallel; within a row the texels whose four neighbours lie in
/// the grid read them directly (the same values as [`slope`] with the edge
/// rule, which the first and last column and row still take).
pub fn normal_map(map: &DisplacementMap) -> Vec<[f32; 3]> {
    let (w, h) = (map.width, map.height);
    let mut out = vec![[0.0f32; 3]; w * h];
    if w == 0 {
        return out;
    }
    let k = central_difference_scale(map);
    let normal = |s: [f64; 2]| normal_of(s).map(|c| c as f32);
    out.par_chunks_mut(w).enumerate().for_each(|(j, row)| {
        let by_rule = |i: usize| normal(slope(map, i, j, [1.0, 1.0]));
        if j == 0 || j + 1 >= h || w < 3 {
            row.iter_mut()
                .enumerate()
                .for_each(|(i, n)| *n = by_rule(i));
            return;
        }
        let line = |jj: usize| &map.data[jj * w..(jj + 1) * w];
        let (above, centre, below) = (line(j - 1), line(j), line(j + 1));
        row[0] = by_rule(0);
        row[w - 1] = by_rule(w - 1);
        for (i, n) in row.iter_mut().enumerate().take(w - 1).skip(1) {
            // `slope` with the stretch 1 (dividing by 1 is exact).
            let dx = (centre[i + 1] - centre[i - 1]) as f64 * k;
            let dy = (below[i] - above[i]) as f64 * k;
            *n = normal([dx, dy]);
        }
    });
    out
}

/// A normalised 2D histogram of normal tangent components.
#[derive(Clone, Debug, PartialEq)]
pub struct NormalHistogram {
    /// Cells per side.
    pub bins: usize,
    /// Half range of `n_x`, `n_y`.
    pub range: f64,
    /// Cell weights, row-major by `n_y` then `n_x`; they sum to 1.
    pub cells: Vec<f64>,
}

impl NormalHistogram {
    /// The histogram of `map`'s normals with the map stretched by `stretch`
    /// along (x, y) (`[1, 1]` for the map as it is).
    pub fn of(
        map: &DisplacementMap,
        bins: usize,
        range: f64,
        stretch: [f64; 2],
    ) -> NormalHistogram {
        let bins = bins.max(1);
        let width = map.width.max(1);
        // Per-row partial histograms added in row order: deterministic.
        let rows: Vec<Vec<u32>> = (0..map.height)
            .into_par_iter()
            .map(|j| {
                let mut counts = vec![0u32; bins * bins];
                for i in 0..width {
                    let n = normal_of(slope(map, i, j, stretch));
                    let cell = |c: f64| {
                        let x = ((c + range) / (2.0 * range) * bins as f64).floor();
                        x.clamp(0.0, bins as f64 - 1.0) as usize
                    };
                    counts[cell(n[1]) * bins + cell(n[0])] += 1;
                }
                counts
            })
            .collect();
        let mut cells = vec![0.0; bins * bins];
        for row in rows {
            for (c, n) in cells.iter_mut().zip(row) {
                *c += n as f64;
            }
        }
        let total: f64 = cells.iter().sum();
        if total > 0.0 {
            cells.iter_mut().for_each(|c| *c /= total);
        }
        NormalHistogram { bins, range, cells }
    }

    /// Total variation `Σ_b |H_b − Ĥ_b|` to another histogram of the same
    /// size (Nagano et al. 2015 eq. 7); in [0, 2].
    pub fn distance(&self, other: &NormalHistogram) -> f64 {
        self.cells
            .iter()
            .zip(&other.cells)
            .map(|(a, b)| (a - b).abs())
            .sum()
    }
}

/// Variance of the slope along the unit axis `axis` (texel units) over the
/// whole map (µm²/µm², dimensionless).
pub fn slope_variance(map: &DisplacementMap, axis: [f64; 2]) -> f64 {
    slope_variance_stretched(map, axis, [1.0, 1.0])
}

/// [`slope_variance`] of the map as it would look stretched by `stretch`
/// along (x, y) (see [`slope`]). Per-row sums are added in row order.
pub fn slope_variance_stretched(map: &DisplacementMap, axis: [f64; 2], stretch: [f64; 2]) -> f64 {
    let len = axis[0].hypot(axis[1]);
    let a = [axis[0] / len, axis[1] / len];
    let rows: Vec<(f64, f64)> = (0..map.height)
        .into_par_iter()
        .map(|j| {
            (0..map.width).fold((0.0, 0.0), |(s, s2), i| {
                let g = slope(map, i, j, stretch);
                let d = g[0] * a[0] + g[1] * a[1];
                (s + d, s2 + d * d)
            })
        })
        .collect();
    let (s, s2) = rows
        .iter()
        .fold((0.0, 0.0), |acc, r| (acc.0 + r.0, acc.1 + r.1));
    let n = (map.width * map.height) as f64;
    s2 / n - (s / n) * (s / n)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::micro::map::Edge;

    #[test]
    fn a_tilted_plane_has_one_normal() {
        // h = 0.2 µm per µm along x: slope 0.2 everywhere (wrapping would
        // break the plane, so clamp and look inside).
        let map = DisplacementMap::from_fn(16, 8, 2.0, Edge::Clamp, |i, _| 0.4 * i as f32);
        let s = slope(&map, 5, 3, [1.0, 1.0]);
        assert!((s[0] - 0.2).abs() < 1e-6 && s[1] == 0.0);
        let n = normal_of(s);
        assert!((n[0] + 0.2 / 1.04f64.sqrt()).abs() < 1e-6);
        // Stretching by 2 along x halves the slope.
        assert!((slope(&map, 5, 3, [2.0, 1.0])[0] - 0.1).abs() < 1e-6);
        let h = NormalHistogram::of(&map, 64, 0.5, [1.0, 1.0]);
        assert!((h.cells.iter().sum::<f64>() - 1.0).abs() < 1e-12);
        // Interior texels: n_x = −0.196 → cell ⌊(−0.196 + 0.5)/1·64⌋ = 19; n_y = 0 → 32.
        assert!(h.cells[32 * 64 + 19] > 0.7, "{}", h.cells[32 * 64 + 19]);
        assert!(slope_variance(&map, [0.0, 1.0]) < 1e-20);
    }

    #[test]
    fn the_normal_map_is_the_per_texel_definition_bit_for_bit() {
        // Rows read directly inside and by the edge rule at the border:
        // both must give `normal_of(slope(..))` exactly, for either rule
        // and for maps too small to have an inside.
        for edge in [Edge::Clamp, Edge::Wrap] {
            for (w, h) in [(1, 1), (2, 5), (3, 3), (17, 9), (64, 2)] {
                let map = DisplacementMap::from_fn(w, h, 3.0, edge, |i, j| {
                    ((i * 7 + j * 13) % 11) as f32 * 0.37 - (i as f32 * 0.05).sin()
                });
                let normals = normal_map(&map);
                for j in 0..h {
                    for i in 0..w {
                        let want = normal_of(slope(&map, i, j, [1.0, 1.0])).map(|c| c as f32);
                        assert_eq!(
                            normals[j * w + i],
                            want,
                            "{edge:?} {w}×{h} texel ({i}, {j})"
                        );
                    }
                }
            }
        }
    }
}
