//! CPU reference raster of the surface field into a UV texture.
//!
//! Texel `(i, j)` of a `width × height` raster covers
//! `u ∈ [i, i+1)/width`, `v ∈ [j, j+1)/height` (row 0 at v = 0) and samples
//! the field at its centre: the per-vertex `T` and `Q Rᵀ` of the triangle
//! containing the centre, interpolated barycentrically. Texels whose centre
//! lies in no triangle are marked outside. Triangles are visited in order and
//! a texel on a shared edge takes the last triangle's value — the same value
//! up to round-off, since the interpolation is continuous across edges. The
//! GPU raster (a render pass with UVs as positions) is compared with this.
//!
//! [`StrainRaster::dilated`] extends the field a few texels past the surface
//! edge (each outside texel copies its nearest inside texel), so kernels
//! and bilinear reads near a UV seam see surface values, not the identity.

use nalgebra::{Matrix2, Vector2};

use super::surface::{barycentric, SurfaceField};

/// How far (texels) the pipeline dilates the raster past the surface edge.
pub const DILATE_TEXELS: usize = 4;

/// Rows of a raster drawn by one parallel task.
const BAND_ROWS: usize = 32;

/// A UV raster of the deformation field.
#[derive(Clone, Debug, PartialEq)]
pub struct StrainRaster {
    /// Texels across (u).
    pub width: usize,
    /// Texels down (v).
    pub height: usize,
    /// Interpolated `T` per texel, row-major (zero outside).
    pub t: Vec<Matrix2<f64>>,
    /// Interpolated `Q Rᵀ` per texel (zero outside).
    pub uv_frame: Vec<Matrix2<f64>>,
    /// Whether the texel centre lies on the surface.
    pub inside: Vec<bool>,
}

impl StrainRaster {
    /// A `width × height` raster with every texel outside (zero values).
    pub fn outside(width: usize, height: usize) -> StrainRaster {
        let n = width * height;
        // Zeroed allocations: the pages of texels that are never drawn are
        // never written (a map larger than its surface is mostly outside).
        StrainRaster {
            width,
            height,
            t: bytemuck::zeroed_vec(n),
            uv_frame: bytemuck::zeroed_vec(n),
            inside: vec![false; n],
        }
    }

    /// Rasterises `field` at `width × height` (both ≥ 1).
    pub fn new(field: &SurfaceField, width: usize, height: usize) -> StrainRaster {
        let size = Vector2::new(width.max(1) as f64, height.max(1) as f64);
        StrainRaster::sampled(field, width, height, size)
    }

    /// Rasterises `field` at `width × height` texels whose centres lie at
    /// `u = (i + 0.5) / size.x`, `v = (j + 0.5) / size.y` (a raster of a
    /// `size`-texel map when `size` is the texel count; a coarser grid over
    /// the same UV square when it is smaller).
    fn sampled(
        field: &SurfaceField,
        width: usize,
        height: usize,
        size: Vector2<f64>,
    ) -> StrainRaster {
        use rayon::prelude::*;
        let (width, height) = (width.max(1), height.max(1));
        let mut raster = StrainRaster::outside(width, height);
        let (tri, uvs) = field.layout();
        // Bands of rows in parallel, each drawing every triangle in order
        // over its own rows: the same texels and values as one pass over
        // the triangles (on a shared edge the last triangle still wins).
        let rows = BAND_ROWS;
        let band = width * rows;
        raster
            .t
            .par_chunks_mut(band)
            .zip(raster.uv_frame.par_chunks_mut(band))
            .zip(raster.inside.par_chunks_mut(band))
            .enumerate()
            .for_each(|(b, ((t_band, frame_band), inside_band))| {
                let (j0, j_end) = (b * rows, (b * rows + rows).min(height));
                for (k, t) in tri.iter().enumerate() {
                    let w = t.map(|s| uvs[s]);
                    // Texel centres (i + 0.5)/width inside the triangle's UV box.
                    let lo = w[0].inf(&w[1]).inf(&w[2]).component_mul(&size);
                    let hi = w[0].sup(&w[1]).sup(&w[2]).component_mul(&size);
                    let first = |x: f64| (x - 0.5).ceil().max(0.0) as usize;
                    let last = |x: f64, n: usize| ((x - 0.5).floor().min(n as f64 - 1.0)).max(-1.0);
                    let (i1, j1) = (last(hi.x, width), last(hi.y, height));
                    if i1 < 0.0 || j1 < 0.0 {
                        continue;
                    }
                    let (ja, jb) = (first(lo.y).max(j0), (j1 as usize).min(j_end - 1));
                    for j in ja..=jb {
                        for i in first(lo.x)..=i1 as usize {
                            let p =
                                Vector2::new((i as f64 + 0.5) / size.x, (j as f64 + 0.5) / size.y);
                            let Some(b) = barycentric(&w, p) else {
                                continue;
                            };
                            if b.iter().any(|&l| l < -1e-12) {
                                continue;
                            }
                            let (t, frame) = field.interpolate_matrices(k, b);
                            let idx = (j - j0) * width + i;
                            t_band[idx] = t;
                            frame_band[idx] = frame;
                            inside_band[idx] = true;
                        }
                    }
                }
            });
        raster
    }

    /// The raster with every outside texel within `radius` texels (square
    /// window) of an inside one filled from the nearest inside texel of
    /// this raster (Euclidean distance in texels; ties go to the first in
    /// row-major order of the window). Those texels count as inside. The
    /// GPU kernel-field stage applies the same rule when it reads the raster.
    pub fn dilated(mut self, radius: usize) -> StrainRaster {
        use rayon::prelude::*;
        let r = radius;
        let (w, h) = (self.width, self.height);
        // Columns of the inside texels per row, then over each row's
        // window of rows: a texel farther than `r` from that span has no
        // inside texel in its window and stays outside.
        let spans: Vec<Option<(usize, usize)>> = (0..h)
            .map(|j| {
                let row = &self.inside[j * w..(j + 1) * w];
                let first = row.iter().position(|&i| i)?;
                let last = row.iter().rposition(|&i| i)?;
                Some((first, last))
            })
            .collect();
        let this = &self;
        // Each row's fills, from the raster before dilation (writes go only
        // to outside texels and reads only to inside ones).
        let fills: Vec<Vec<(usize, usize)>> = (0..h)
            .into_par_iter()
            .map(|j| {
                let window = spans[j.saturating_sub(r)..=(j + r).min(h - 1)]
                    .iter()
                    .flatten()
                    .fold(None, |acc: Option<(usize, usize)>, &(a, b)| {
                        Some(acc.map_or((a, b), |(x, y)| (x.min(a), y.max(b))))
                    });
                let Some((lo, hi)) = window else {
                    return Vec::new();
                };
                let (i0, i1) = (lo.saturating_sub(r), (hi + r).min(w - 1));
                (i0..=i1)
                    .filter(|&i| !this.inside[j * w + i])
                    .filter_map(|i| this.nearest_inside(i, j, r).map(|k| (j * w + i, k)))
                    .collect()
            })
            .collect();
        for (idx, k) in fills.into_iter().flatten() {
            self.t[idx] = self.t[k];
            self.uv_frame[idx] = self.uv_frame[k];
            self.inside[idx] = true;
        }
        self
    }

    /// The nearest inside texel to `(i, j)` within `radius` (square window,
    /// Euclidean distance; ties to the first in row-major window order).
    fn nearest_inside(&self, i: usize, j: usize, radius: usize) -> Option<usize> {
        let (r, w, h) = (radius as isize, self.width as isize, self.height as isize);
        let (i, j) = (i as isize, j as isize);
        let mut best: Option<(isize, usize)> = None;
        for dj in -r..=r {
            for di in -r..=r {
                let (x, y) = (i + di, j + dj);
                if x < 0 || y < 0 || x >= w || y >= h {
                    continue;
                }
                let k = (y * w + x) as usize;
                let d2 = di * di + dj * dj;
                if self.inside[k] && best.is_none_or(|b| d2 < b.0) {
                    best = Some((d2, k));
                }
            }
        }
        best.map(|(_, k)| k)
    }

    /// The raster of a `width × height` map sampled from a coarse raster
    /// with one texel per `step × step` map texels ([`CoarseRaster`]);
    /// `step = 1` is [`StrainRaster::new`] dilated by [`DILATE_TEXELS`], the
    /// exact raster.
    pub fn stepped(field: &SurfaceField, width: usize, height: usize, step: usize) -> StrainRaster {
        if step <= 1 {
            return StrainRaster::new(field, width, height).dilated(DILATE_TEXELS);
        }
        CoarseRaster::new(field, width, height, step).sample()
    }

    /// Texel index of `(i, j)`.
    pub fn index(&self, i: usize, j: usize) -> usize {
        j * self.width + i
    }

    /// UV of the centre of texel `(i, j)`.
    pub fn texel_uv(&self, i: usize, j: usize) -> Vector2<f64> {
        Vector2::new(
            (i as f64 + 0.5) / self.width as f64,
            (j as f64 + 0.5) / self.height as f64,
        )
    }
}

/// Dilation (raster texels) of a raster with one texel per `step` map
/// texels when the map's is `dilate` texels: `dilate` itself at step 1;
/// beyond, far enough that every map texel within `dilate` of the surface
/// has an inside texel among its four bilinear neighbours.
pub fn raster_dilation(dilate: usize, step: usize) -> usize {
    if step <= 1 {
        dilate
    } else {
        dilate.div_ceil(step) + 1
    }
}

/// How far (map texels) values of a raster with one texel per `step` map
/// texels, dilated as [`raster_dilation`] says, reach past the surface's
/// UV bounding boxes: the dilation and the bilinear footprint; `dilate`
/// for the exact raster.
pub fn stepped_reach(dilate: usize, step: usize) -> usize {
    if step <= 1 {
        dilate
    } else {
        step * (raster_dilation(dilate, step) + 2)
    }
}

/// The surface field rasterised at one texel per `step × step` texels of a
/// `map_width × map_height` map and read bilinearly at each map texel.
///
/// Coarse texel `(I, J)` sits at map coordinates `((I + ½) step, (J + ½)
/// step)` (map texel `i` spans `[i, i + 1)`), so the coarse grid starts at
/// the map's corner whatever its size, and a window of the map starting
/// at a multiple of `step` sees the same grid. The raster is dilated by
/// [`raster_dilation`]. Map texel `i` reads coarse coordinate
/// `x = (i + ½)/step − ½` (clamped to the raster), the four neighbours with
/// bilinear weights; outside neighbours drop out and the weights of the
/// inside ones are renormalised, and a texel with no inside neighbour of
/// non-zero weight is outside. Inside a triangle the field is linear, so
/// wherever a map texel's four neighbours lie in one triangle it reads the
/// exact value; near edges between triangles (where the field's gradient
/// jumps) the bilinear read differs from it by a fraction of the jump over
/// one coarse texel.
#[derive(Clone, Debug, PartialEq)]
pub struct CoarseRaster {
    /// The coarse raster, dilated.
    pub raster: StrainRaster,
    /// Map texels per coarse texel along each side.
    pub step: usize,
    /// The map's texels along u.
    pub map_width: usize,
    /// The map's texels along v.
    pub map_height: usize,
}

/// Bilinear neighbours of map texel `i` in a coarse raster of `n` texels:
/// the lower coarse index and the weight of the upper one.
pub fn coarse_neighbours(i: usize, step: usize, n: usize) -> (usize, f64) {
    let x = ((i as f64 + 0.5) / step as f64 - 0.5).clamp(0.0, (n - 1) as f64);
    let lower = (x.floor() as usize).min(n.saturating_sub(2));
    (lower, x - lower as f64)
}

impl CoarseRaster {
    /// Rasterises `field` for a `map_width × map_height` map at one texel
    /// per `step` (≥ 1) map texels along each side.
    pub fn new(
        field: &SurfaceField,
        map_width: usize,
        map_height: usize,
        step: usize,
    ) -> CoarseRaster {
        let step = step.max(1);
        let (w, h) = (map_width.div_ceil(step), map_height.div_ceil(step));
        let size = Vector2::new(
            map_width as f64 / step as f64,
            map_height as f64 / step as f64,
        );
        CoarseRaster {
            raster: StrainRaster::sampled(field, w, h, size)
                .dilated(raster_dilation(DILATE_TEXELS, step)),
            step,
            map_width,
            map_height,
        }
    }

    /// `T` and `Q Rᵀ` at map texel `(i, j)` (see the type's docs), or
    /// `None` where it is outside.
    pub fn at(&self, i: usize, j: usize) -> Option<(Matrix2<f64>, Matrix2<f64>)> {
        let r = &self.raster;
        let (x0, fx) = coarse_neighbours(i, self.step, r.width);
        let (y0, fy) = coarse_neighbours(j, self.step, r.height);
        let mut weight = 0.0;
        let mut t = Matrix2::zeros();
        let mut frame = Matrix2::zeros();
        for (dy, wy) in [(0, 1.0 - fy), (1, fy)] {
            for (dx, wx) in [(0, 1.0 - fx), (1, fx)] {
                let (x, y) = ((x0 + dx).min(r.width - 1), (y0 + dy).min(r.height - 1));
                let k = r.index(x, y);
                let w = wx * wy;
                if r.inside[k] && w > 0.0 {
                    weight += w;
                    t += (r.t[k] - Matrix2::identity()) * w;
                    frame += r.uv_frame[k] * w;
                }
            }
        }
        (weight > 0.0).then(|| (Matrix2::identity() + t / weight, frame / weight))
    }

    /// The map-size raster of [`CoarseRaster::at`] at every map texel.
    pub fn sample(&self) -> StrainRaster {
        use rayon::prelude::*;
        let w = self.map_width;
        let values: Vec<_> = (0..w * self.map_height)
            .into_par_iter()
            .map(|k| self.at(k % w, k / w))
            .collect();
        let mut out = StrainRaster::outside(w, self.map_height);
        for (k, v) in values.into_iter().enumerate() {
            if let Some((t, frame)) = v {
                out.t[k] = t;
                out.uv_frame[k] = frame;
                out.inside[k] = true;
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A coarse raster of `w × h` texels for a map `step` times finer,
    /// every texel inside, holding `T = I + f(centre)` and a frame of
    /// `g(centre)`, both linear in the texel centre's map coordinates.
    fn linear(w: usize, h: usize, step: usize, map: (usize, usize)) -> CoarseRaster {
        let mut raster = StrainRaster::outside(w, h);
        for j in 0..h {
            for i in 0..w {
                let (x, y) = (
                    (i as f64 + 0.5) * step as f64,
                    (j as f64 + 0.5) * step as f64,
                );
                let k = raster.index(i, j);
                raster.t[k] = Matrix2::new(1.0 + 0.01 * x, 0.002 * y, -0.003 * x, 1.0 - 0.004 * y);
                raster.uv_frame[k] = Matrix2::new(0.5 + 1e-3 * x, 0.1, -0.1, 0.5 + 2e-3 * y);
                raster.inside[k] = true;
            }
        }
        CoarseRaster {
            raster,
            step,
            map_width: map.0,
            map_height: map.1,
        }
    }

    #[test]
    fn a_linear_field_reads_exactly_between_coarse_texel_centres() {
        // 10 × 7 coarse texels of 4: a 38 × 27 map (the last coarse texels
        // are partly beyond the map).
        let c = linear(10, 7, 4, (38, 27));
        let mut checked = 0;
        for j in 0..27 {
            for i in 0..38 {
                let (x, y) = (i as f64 + 0.5, j as f64 + 0.5);
                let (t, frame) = c.at(i, j).unwrap();
                // Between the first and last coarse centres (2 … 38) the
                // read is the linear field; beyond them it is clamped.
                let (cx, cy) = (x.clamp(2.0, 38.0), y.clamp(2.0, 26.0));
                let want_t =
                    Matrix2::new(1.0 + 0.01 * cx, 0.002 * cy, -0.003 * cx, 1.0 - 0.004 * cy);
                let want_f = Matrix2::new(0.5 + 1e-3 * cx, 0.1, -0.1, 0.5 + 2e-3 * cy);
                assert!(
                    (t - want_t).abs().max() < 1e-13,
                    "({i}, {j}): {t} vs {want_t}"
                );
                assert!((frame - want_f).abs().max() < 1e-13, "({i}, {j})");
                checked += 1;
            }
        }
        assert_eq!(checked, 38 * 27);
        // Step 1 is the raster itself.
        let one = linear(5, 4, 1, (5, 4));
        assert_eq!(one.sample(), one.raster);
    }

    #[test]
    fn outside_neighbours_drop_out_and_the_rest_are_renormalised() {
        let mut c = linear(4, 4, 4, (16, 16));
        let r = &mut c.raster;
        for (i, j) in [(1, 1), (2, 1)] {
            let k = r.index(i, j);
            r.inside[k] = false;
            r.t[k] = Matrix2::zeros();
            r.uv_frame[k] = Matrix2::zeros();
        }
        let r = c.raster.clone();
        // Map texel (6, 6): coarse coordinate (1.125, 1.125), neighbours
        // (1, 1) and (2, 1) outside, (1, 2) and (2, 2) inside with weights
        // 0.875 · 0.125 and 0.125 · 0.125.
        let (t, _) = c.at(6, 6).unwrap();
        let (a, b) = (r.t[r.index(1, 2)], r.t[r.index(2, 2)]);
        let want = (a * 0.875 + b * 0.125) / (0.875 + 0.125);
        assert!((t - want).abs().max() < 1e-14, "{t} vs {want}");
        // Map texel (6, 2) sits on the centre row of coarse row 0 (y = 0.125
        // → rows 0 and 1 with weights 0.875, 0.125): its row-1 neighbours
        // are out, so only row 0 is read.
        let (t, _) = c.at(6, 2).unwrap();
        let (a, b) = (r.t[r.index(1, 0)], r.t[r.index(2, 0)]);
        let want = a * 0.875 + b * 0.125;
        assert!((t - want).abs().max() < 1e-14, "{t} vs {want}");
        // With every neighbour of non-zero weight outside, the texel is out.
        let mut lone = linear(1, 1, 4, (4, 4));
        lone.raster.inside[0] = false;
        assert!(lone.at(2, 2).is_none());
        assert!(!lone.sample().inside.iter().any(|&i| i));
    }

    #[test]
    fn coarse_reach_covers_the_dilation_and_the_bilinear_footprint() {
        assert_eq!(stepped_reach(DILATE_TEXELS, 1), DILATE_TEXELS);
        for step in 2..=16 {
            let d = raster_dilation(DILATE_TEXELS, step);
            // Every map texel within DILATE_TEXELS of the surface has an
            // inside (dilated) neighbour.
            assert!(d * step >= DILATE_TEXELS + step, "step {step}");
            assert!(
                stepped_reach(DILATE_TEXELS, step) >= (d + 1) * step,
                "step {step}"
            );
        }
        assert_eq!(coarse_neighbours(0, 4, 10), (0, 0.0));
        assert_eq!(coarse_neighbours(6, 4, 10), (1, 0.125));
        assert_eq!(coarse_neighbours(39, 4, 10), (8, 1.0));
        assert_eq!(coarse_neighbours(3, 4, 1), (0, 0.0));
    }
}
