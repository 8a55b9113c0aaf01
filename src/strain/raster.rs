//! CPU reference raster of the surface field into a UV texture (DESIGN §5.3).
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
        StrainRaster {
            width,
            height,
            t: vec![Matrix2::zeros(); n],
            uv_frame: vec![Matrix2::zeros(); n],
            inside: vec![false; n],
        }
    }

    /// Rasterises `field` at `width × height` (both ≥ 1).
    pub fn new(field: &SurfaceField, width: usize, height: usize) -> StrainRaster {
        let (width, height) = (width.max(1), height.max(1));
        let mut raster = StrainRaster::outside(width, height);
        let (tri, uvs) = field.layout();
        let size = Vector2::new(width as f64, height as f64);
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
            for j in first(lo.y)..=j1 as usize {
                for i in first(lo.x)..=i1 as usize {
                    let p = Vector2::new((i as f64 + 0.5) / size.x, (j as f64 + 0.5) / size.y);
                    let Some(b) = barycentric(&w, p) else {
                        continue;
                    };
                    if b.iter().any(|&l| l < -1e-12) {
                        continue;
                    }
                    let s = field.interpolate(k, b);
                    let idx = j * width + i;
                    raster.t[idx] = s.t;
                    raster.uv_frame[idx] = s.uv_frame;
                    raster.inside[idx] = true;
                }
            }
        }
        raster
    }

    /// The raster with every outside texel within `radius` texels (square
    /// window) of an inside one filled from the nearest inside texel of
    /// this raster (Euclidean distance in texels; ties go to the first in
    /// row-major order of the window). Those texels count as inside. The
    /// GPU kernel-field stage applies the same rule when it reads the raster.
    pub fn dilated(mut self, radius: usize) -> StrainRaster {
        // Writes go only to outside texels and reads only to texels inside
        // before dilation, so one copy of the mask lets it work in place.
        let was_inside = self.inside.clone();
        let r = radius as isize;
        let (w, h) = (self.width as isize, self.height as isize);
        for j in 0..h {
            for i in 0..w {
                let idx = (j * w + i) as usize;
                if was_inside[idx] {
                    continue;
                }
                let mut best: Option<(isize, usize)> = None;
                for dj in -r..=r {
                    for di in -r..=r {
                        let (x, y) = (i + di, j + dj);
                        if x < 0 || y < 0 || x >= w || y >= h {
                            continue;
                        }
                        let k = (y * w + x) as usize;
                        let d2 = di * di + dj * dj;
                        if was_inside[k] && best.is_none_or(|b| d2 < b.0) {
                            best = Some((d2, k));
                        }
                    }
                }
                if let Some((_, k)) = best {
                    self.t[idx] = self.t[k];
                    self.uv_frame[idx] = self.uv_frame[k];
                    self.inside[idx] = true;
                }
            }
        }
        self
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
