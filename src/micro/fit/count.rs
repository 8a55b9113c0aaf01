//! The fit's objective counted on the CPU: the slope fields of the
//! candidates and their normal histograms, the same f32 arithmetic as
//! `shaders/fit.wgsl`.

use rayon::prelude::*;

use crate::micro::map::DisplacementMap;
use crate::micro::normals::slope;

/// Candidates whose histograms are counted in one sweep over the texels.
const GROUP: usize = 8;
/// Texels per block of that sweep (kept in cache for the group).
const CHUNK: usize = 2048;

/// A slope field, `(∂h/∂x, ∂h/∂y)` per texel.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Slopes {
    /// Along x (u).
    pub x: Vec<f32>,
    /// Along y (v).
    pub y: Vec<f32>,
}

impl Slopes {
    /// The central-difference slopes of `map` (as [`crate::micro::normals::NormalHistogram::of`],
    /// which reads the same texels: interior texels without edge handling).
    pub fn of(map: &DisplacementMap) -> Slopes {
        let (w, h) = (map.width, map.height);
        let mut x = vec![0.0f32; w * h];
        let mut y = vec![0.0f32; w * h];
        let k = map.height_unit_um / (2.0 * map.texel_um);
        x.par_chunks_mut(w.max(1))
            .zip(y.par_chunks_mut(w.max(1)))
            .enumerate()
            .for_each(|(j, (xr, yr))| {
                let inner_row = j > 0 && j + 1 < h;
                for i in 0..w {
                    let (sx, sy) = if inner_row && i > 0 && i + 1 < w {
                        let d = &map.data;
                        let c = j * w + i;
                        (
                            (d[c + 1] - d[c - 1]) as f64 * k,
                            (d[c + w] - d[c - w]) as f64 * k,
                        )
                    } else {
                        let s = slope(map, i, j, [1.0, 1.0]);
                        (s[0], s[1])
                    };
                    xr[i] = sx as f32;
                    yr[i] = sy as f32;
                }
            });
        Slopes { x, y }
    }

    /// Texels.
    pub fn len(&self) -> usize {
        self.x.len()
    }

    /// Whether there are none.
    pub fn is_empty(&self) -> bool {
        self.x.is_empty()
    }
}

/// Normal-histogram counts of the slope fields `base + α·dir` for each α
/// (f32, the same arithmetic as `shaders/fit.wgsl`): each texel's normal
/// `(−s_x, −s_y)/√(1 + |s|²)` falls into cell `⌊(c + range)·bins/(2·range)⌋`
/// per component, clamped to the edge cells (a NaN to the first). Candidates are counted
/// `GROUP` at a time in parallel; counts are integers, so the result
/// does not depend on the thread count.
pub fn count_histograms(
    base: &Slopes,
    dir: &Slopes,
    alphas: &[f32],
    bins: usize,
    range: f64,
) -> Vec<Vec<u32>> {
    let bins = bins.max(1);
    let cells = bins * bins;
    let grid = CellGrid {
        bins: bins as i32,
        scale: bins as f32 / (2.0 * range as f32),
        offset: range as f32,
        top: (bins - 1) as f32,
    };
    alphas
        .par_chunks(GROUP)
        .flat_map_iter(|group| {
            // Two interleaved copies per candidate, so that runs of texels in
            // one cell do not wait on each other's increments.
            let mut counts = vec![vec![0u32; 2 * cells]; group.len()];
            let mut index = vec![0u32; CHUNK];
            for start in (0..base.len()).step_by(CHUNK) {
                let end = (start + CHUNK).min(base.len());
                let (bx, by) = (&base.x[start..end], &base.y[start..end]);
                let (dx, dy) = (&dir.x[start..end], &dir.y[start..end]);
                for (c, &a) in counts.iter_mut().zip(group) {
                    // Cell indices first (four texels at a time), then the
                    // increments.
                    let index = &mut index[..end - start];
                    cells_of(&mut *index, [bx, by, dx, dy], a, grid);
                    let (even, odd) = c.split_at_mut(cells);
                    let mut pairs = index.chunks_exact(2);
                    for pair in &mut pairs {
                        even[pair[0] as usize] += 1;
                        odd[pair[1] as usize] += 1;
                    }
                    for &k in pairs.remainder() {
                        even[k as usize] += 1;
                    }
                }
            }
            counts.into_iter().map(move |mut c| {
                let (even, odd) = c.split_at_mut(cells);
                even.iter_mut().zip(odd.iter()).for_each(|(e, o)| *e += o);
                c.truncate(cells);
                c
            })
        })
        .collect()
}

/// The histogram grid of [`count_histograms`] in f32: a normal component
/// `c` falls into cell `⌊(c + offset)·scale⌋`, clamped to `[0, top]`.
#[derive(Clone, Copy)]
struct CellGrid {
    bins: i32,
    scale: f32,
    offset: f32,
    top: f32,
}

impl CellGrid {
    /// The cell of slope `(sx, sy)`: its normal `(−s_x, −s_y)/√(1 + |s|²)`
    /// per component into a cell, a NaN to the first.
    fn cell(self, sx: f32, sy: f32) -> u32 {
        let inv = 1.0 / (1.0 + sx * sx + sy * sy).sqrt();
        // In [0, bins − 1] (a NaN to 0), so the conversion is exact.
        let cx = ((-sx * inv + self.offset) * self.scale)
            .max(0.0)
            .min(self.top) as i32;
        let cy = ((-sy * inv + self.offset) * self.scale)
            .max(0.0)
            .min(self.top) as i32;
        (cy * self.bins + cx) as u32
    }
}

/// `out[k]`: the cell of texel k's slope `base + a·dir` (`[base_x, base_y,
/// dir_x, dir_y]`), four texels at a time with the same f32 operations as
/// [`CellGrid::cell`] (so the same cells), the rest one by one.
fn cells_of(out: &mut [u32], [bx, by, dx, dy]: [&[f32]; 4], a: f32, grid: CellGrid) {
    use wide::{f32x4, i32x4};
    let four = |s: &[f32], k: usize| f32x4::from([s[k], s[k + 1], s[k + 2], s[k + 3]]);
    let (a4, one, zero) = (f32x4::splat(a), f32x4::splat(1.0), f32x4::splat(0.0));
    let (offset, scale, top) = (
        f32x4::splat(grid.offset),
        f32x4::splat(grid.scale),
        f32x4::splat(grid.top),
    );
    let bins = i32x4::splat(grid.bins);
    let whole = out.len() / 4 * 4;
    for k in (0..whole).step_by(4) {
        let sx = four(bx, k) + a4 * four(dx, k);
        let sy = four(by, k) + a4 * four(dy, k);
        let inv = one / (one + sx * sx + sy * sy).sqrt();
        // f32x4::max(x, 0) is 0 for a NaN x, as f32::max is; after the
        // clamp every lane is in [0, bins − 1], so truncation is exact.
        let cx = ((-sx * inv + offset) * scale)
            .max(zero)
            .min(top)
            .fast_trunc_int();
        let cy = ((-sy * inv + offset) * scale)
            .max(zero)
            .min(top)
            .fast_trunc_int();
        let cell = (cy * bins + cx).to_array();
        for (o, c) in out[k..k + 4].iter_mut().zip(cell) {
            *o = c as u32;
        }
    }
    for k in whole..out.len() {
        out[k] = grid.cell(bx[k] + a * dx[k], by[k] + a * dy[k]);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The four-lane cells are the scalar cells for every lane and every
    /// remainder length, NaN, infinities and values past the window
    /// included.
    #[test]
    fn four_lanes_give_the_scalar_cells() {
        let grid = CellGrid {
            bins: 64,
            scale: 64.0 / (2.0 * 0.37),
            offset: 0.37,
            top: 63.0,
        };
        let special = [
            0.0,
            -0.0,
            f32::NAN,
            f32::INFINITY,
            f32::NEG_INFINITY,
            1e30,
            -1e30,
            0.37,
            -0.37,
            1e-30,
        ];
        let values: Vec<f32> = (0..97)
            .map(|k| match k % 3 {
                0 => special[k % special.len()],
                _ => (k as f32 * 0.618).sin() * 0.8,
            })
            .collect();
        for len in 0..values.len() {
            let (bx, by, dx, dy) = (
                &values[..len],
                &values[values.len() - len..],
                &values[..len],
                &values[..len],
            );
            for a in [0.0f32, -1.3, 0.7, f32::NAN] {
                let mut out = vec![u32::MAX; len];
                cells_of(&mut out, [bx, by, dx, dy], a, grid);
                for k in 0..len {
                    let want = grid.cell(bx[k] + a * dx[k], by[k] + a * dy[k]);
                    assert_eq!(out[k], want, "len {len}, a {a}, texel {k}");
                    assert!(out[k] < 64 * 64);
                }
            }
        }
    }
}
