//! CPU reference of the spatially varying separable convolution (Nagano et
//! al. 2015 eq. 3–6, 13).
//!
//! Two 1D passes: along each texel's s axis into an intermediate map
//! (`D^s`, eq. 5), then along its t axis into the output (`D′`, eq. 4). A
//! pass at texel `p` with unit axis `a` (in texel units), strength α and
//! σ (texels) computes
//! `(1 − α)·D(p) + α·Σ_k g_k·D(p − k·a) / Σ_k g_k`, `k = −N … N`,
//! `N = ⌈3σ⌉`, `g_k = exp(−k²/2σ²)` with the outermost pair `k = ±N` scaled
//! by `3σ − (N − 1) ∈ (0, 1]`, reading D bilinearly with the map's edge
//! handling. The taper makes the kernel continuous in σ: a new pair of taps
//! enters with weight zero as 3σ passes an integer, so σ computed in f32
//! (GPU) and f64 (CPU) cannot differ by a whole tap pair. The Gaussian weights come from the recurrence
//! `g_{k+1} = g_k·q^{2k+1}`, `q = exp(−1/2σ²)`. Arithmetic is f32 in the
//! order the GPU shader uses, so the two compare texel by texel; texels are
//! independent, so the parallel loop gives the same bits on any thread count.
//!
//! Per-texel parameters come from the strain raster ([`KernelField`]): the
//! axes `S = Q Rᵀ V` (UV per millimetre) scaled to texels give each axis's
//! direction in the map and its texels per millimetre, which converts σ from
//! micrometres to texels (eq. 13); α and σ come from the kernel model at
//! r_s along s and r_t along t. Texels off the surface are left unchanged.

use rayon::prelude::*;

use super::kernel::{KernelModel, KernelParams};
use super::map::DisplacementMap;
use crate::strain::{StrainRaster, Svd2};

/// Kernel parameters of one pass at one texel.
#[derive(Clone, Copy, Debug, PartialEq, bytemuck::Zeroable)]
pub struct PassParams {
    /// Unit axis in texel units (x along u, y along v).
    pub axis: [f32; 2],
    /// Strength α.
    pub alpha: f32,
    /// Standard deviation in texels.
    pub sigma: f32,
}

impl PassParams {
    /// The identity pass (α = 0; no axis, no σ): all zeros, so a field
    /// allocated zeroed starts as the identity everywhere.
    pub const IDENTITY: PassParams = PassParams {
        axis: [0.0, 0.0],
        alpha: 0.0,
        sigma: 0.0,
    };
}

/// Per-texel parameters of both passes.
#[derive(Clone, Debug, PartialEq)]
pub struct KernelField {
    /// Texels along u.
    pub width: usize,
    /// Texels along v.
    pub height: usize,
    /// First pass (along s).
    pub s: Vec<PassParams>,
    /// Second pass (along t).
    pub t: Vec<PassParams>,
}

impl KernelField {
    /// Parameters from a strain raster of the map's size and a kernel model.
    ///
    /// # Panics
    /// If the raster and the map differ in size (the pipeline rasterises at
    /// the map's size).
    pub fn from_strain(
        raster: &StrainRaster,
        model: &KernelModel,
        map: &DisplacementMap,
    ) -> KernelField {
        assert_eq!((raster.width, raster.height), (map.width, map.height));
        let (w, h) = (map.width as f64, map.height as f64);
        let texel = |idx: usize| {
            let svd = Svd2::of(&raster.t[idx]);
            let s_matrix = raster.uv_frame[idx] * svd.v();
            let pass = |col: usize, r: f64| {
                // Texels per millimetre along the axis, and its direction.
                let a = nalgebra::Vector2::new(s_matrix[(0, col)] * w, s_matrix[(1, col)] * h);
                let per_mm = a.norm();
                let KernelParams { alpha, sigma_um } = model.params(r);
                if per_mm <= 0.0 || !per_mm.is_finite() {
                    return PassParams::IDENTITY;
                }
                PassParams {
                    axis: [(a.x / per_mm) as f32, (a.y / per_mm) as f32],
                    alpha: alpha as f32,
                    sigma: (sigma_um * 1e-3 * per_mm) as f32,
                }
            };
            (pass(0, svd.rs), pass(1, svd.rt))
        };
        // Zeroed (identity) allocations, written only at the texels on the
        // surface: most of a map larger than its surface is never touched.
        let n = map.width * map.height;
        let (mut s, mut t) = (
            bytemuck::zeroed_vec::<PassParams>(n),
            bytemuck::zeroed_vec::<PassParams>(n),
        );
        let width = map.width.max(1);
        s.par_chunks_mut(width)
            .zip(t.par_chunks_mut(width))
            .enumerate()
            .for_each(|(j, (s_row, t_row))| {
                let row = j * width;
                for i in (0..s_row.len()).filter(|&i| raster.inside[row + i]) {
                    (s_row[i], t_row[i]) = texel(row + i);
                }
            });
        KernelField {
            width: map.width,
            height: map.height,
            s,
            t,
        }
    }

    /// The same parameters at every texel: α and σ (µm, converted with the
    /// map's texel size) along the unit axis `s` (texel units) and along `t`
    /// perpendicular to it.
    pub fn constant(
        map: &DisplacementMap,
        s: [f64; 2],
        along_s: KernelParams,
        along_t: KernelParams,
    ) -> KernelField {
        let n = map.width * map.height;
        let len = s[0].hypot(s[1]);
        let s_axis = [(s[0] / len) as f32, (s[1] / len) as f32];
        let t_axis = [-s_axis[1], s_axis[0]];
        let pass = |axis: [f32; 2], p: KernelParams| PassParams {
            axis,
            alpha: p.alpha as f32,
            sigma: (p.sigma_um / map.texel_um) as f32,
        };
        KernelField {
            width: map.width,
            height: map.height,
            s: vec![pass(s_axis, along_s); n],
            t: vec![pass(t_axis, along_t); n],
        }
    }
}

/// One pass of the convolution (see the module docs).
pub fn convolve_pass(src: &DisplacementMap, params: &[PassParams]) -> DisplacementMap {
    assert_eq!(params.len(), src.data.len());
    let mut data = vec![0.0f32; src.data.len()];
    let width = src.width.max(1);
    data.par_chunks_mut(width).enumerate().for_each(|(j, row)| {
        for (i, out) in row.iter_mut().enumerate() {
            *out = convolve_texel(src, i, j, &params[j * width + i]);
        }
    });
    src.with_data(data)
}

/// The Gaussian half of a pass along the map's u (`along_u`) or v axis
/// with σ texels at every texel: [`convolve_pass`] with α = 1 along
/// `[1, 0]` or `[0, 1]`, bit for bit (the same weights and the same order
/// of additions; the taps fall on texel centres, where the bilinear reads
/// return texels exactly), but with the weights computed once and whole
/// rows added at a time. The kernel fit blurs the neutral map once per σ
/// of its grid with it.
pub fn blur_along_axis(src: &DisplacementMap, along_u: bool, sigma: f32) -> DisplacementMap {
    if sigma.is_nan() || sigma <= 0.0 {
        return src.clone();
    }
    let n = (3.0 * sigma).ceil() as i32;
    let taper = 3.0 * sigma - (n - 1) as f32;
    let q = (-0.5 / (sigma * sigma)).exp();
    let mut weights = Vec::with_capacity(n as usize);
    let (mut g, mut step, mut norm) = (1.0f32, q, 1.0f32);
    for k in 1..=n {
        g *= step;
        step *= q * q;
        let w = if k == n { g * taper } else { g };
        norm += 2.0 * w;
        weights.push(w);
    }
    let (w, h) = (src.width, src.height);
    let mut data = vec![0.0f32; w * h];
    if along_u {
        data.par_chunks_mut(w.max(1))
            .enumerate()
            .for_each(|(j, out)| {
                // The row padded by n texels each side with the map's edge rule.
                let pad: Vec<f32> = (-(n as isize)..(w as isize + n as isize))
                    .map(|i| src.texel(i, j as isize))
                    .collect();
                let centre = &pad[n as usize..n as usize + w];
                out.copy_from_slice(centre);
                for (k, &wk) in weights.iter().enumerate() {
                    let k = k + 1;
                    let (left, right) = (&pad[n as usize - k..], &pad[n as usize + k..]);
                    for ((o, a), b) in out.iter_mut().zip(left).zip(right) {
                        *o += wk * (a + b);
                    }
                }
                out.iter_mut().for_each(|o| *o /= norm);
            });
    } else {
        data.par_chunks_mut(w.max(1))
            .enumerate()
            .for_each(|(j, out)| {
                let row = |jj: isize| -> usize {
                    // The row index the edge rule reads for row jj.
                    let probe = match src.edge {
                        super::map::Edge::Wrap => jj.rem_euclid(h as isize),
                        super::map::Edge::Clamp => jj.clamp(0, h as isize - 1),
                    };
                    probe as usize * w
                };
                out.copy_from_slice(&src.data[j * w..j * w + w]);
                for (k, &wk) in weights.iter().enumerate() {
                    let k = k as isize + 1;
                    let (a0, b0) = (row(j as isize - k), row(j as isize + k));
                    let (above, below) = (&src.data[a0..a0 + w], &src.data[b0..b0 + w]);
                    for ((o, a), b) in out.iter_mut().zip(above).zip(below) {
                        *o += wk * (a + b);
                    }
                }
                out.iter_mut().for_each(|o| *o /= norm);
            });
    }
    src.with_data(data)
}

/// One texel of a pass.
#[inline]
pub fn convolve_texel(src: &DisplacementMap, i: usize, j: usize, p: &PassParams) -> f32 {
    let centre = src.data[j * src.width + i];
    if p.alpha == 0.0 || p.sigma.is_nan() || p.sigma <= 0.0 {
        return centre;
    }
    let n = (3.0 * p.sigma).ceil() as i32;
    let taper = 3.0 * p.sigma - (n - 1) as f32;
    let q = (-0.5 / (p.sigma * p.sigma)).exp();
    let (x, y) = (i as f32, j as f32);
    // Whether every sample's four texels lie inside the grid (then no edge
    // handling is needed; the values are the same).
    let (rx, ry) = (n as f32 * p.axis[0].abs(), n as f32 * p.axis[1].abs());
    let interior = x - rx >= 0.0
        && y - ry >= 0.0
        && x + rx < (src.width - 1) as f32
        && y + ry < (src.height - 1) as f32;
    // The normalised Gaussian sum, with a reader chosen once per texel; the
    // reader takes tap k's two points `(x − dx, y − dy, x + dx, y + dy)`.
    fn taps(
        centre: f32,
        n: i32,
        taper: f32,
        q: f32,
        at: (f32, f32),
        axis: [f32; 2],
        read: impl Fn([f32; 4]) -> [f32; 2],
    ) -> f32 {
        use wide::f32x4;
        let (x, y) = at;
        // Tap k's points as `base + k·dir`: `x + k·(−a) = x − k·a` exactly
        // (negation is exact), so this is `x ∓ dx` with `dx = k·a`.
        let base = f32x4::from([x, y, x, y]);
        let dir = f32x4::from([-axis[0], -axis[1], axis[0], axis[1]]);
        let mut sum = centre;
        let mut norm = 1.0f32;
        let mut g = 1.0f32;
        let mut step = q;
        for k in 1..=n {
            g *= step;
            step *= q * q;
            let w = if k == n { g * taper } else { g };
            let at = base + f32x4::splat(k as f32) * dir;
            let [behind, ahead] = read(at.to_array());
            sum += w * (behind + ahead);
            norm += 2.0 * w;
        }
        sum / norm
    }
    let blurred = if interior {
        taps(centre, n, taper, q, (x, y), p.axis, |at| {
            src.bilinear_interior_pair(at)
        })
    } else {
        taps(centre, n, taper, q, (x, y), p.axis, |at| {
            [src.bilinear(at[0], at[1]), src.bilinear(at[2], at[3])]
        })
    };
    (1.0 - p.alpha) * centre + p.alpha * blurred
}

/// One frame on the CPU: the strain raster at the map's size dilated by
/// [`crate::strain::raster::DILATE_TEXELS`], its kernel field, both passes.
/// The reference of the GPU chain (`gpu::micro`).
pub fn deform(
    map: &DisplacementMap,
    model: &KernelModel,
    field: &crate::strain::SurfaceField,
) -> DisplacementMap {
    deform_stepped(map, model, field, 1)
}

/// [`deform`] with the strain rasterised at one texel per `step × step` map
/// texels and read bilinearly ([`crate::strain::raster::CoarseRaster`];
/// `step = 1` is [`deform`]). The reference of the GPU chain with the same
/// raster step (`GpuMicro::set_raster_step`, a layer above).
pub fn deform_stepped(
    map: &DisplacementMap,
    model: &KernelModel,
    field: &crate::strain::SurfaceField,
    step: usize,
) -> DisplacementMap {
    let raster = StrainRaster::stepped(field, map.width, map.height, step);
    convolve(map, &KernelField::from_strain(&raster, model, map))
}

/// Both passes: along s, then along t (eq. 4–5).
pub fn convolve(map: &DisplacementMap, field: &KernelField) -> DisplacementMap {
    let first = convolve_pass(map, &field.s);
    convolve_pass(&first, &field.t)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_identity_pass_is_all_zeros_and_changes_nothing() {
        // `KernelField::from_strain` relies on it: zeroed texels are identity.
        assert_eq!(
            <PassParams as bytemuck::Zeroable>::zeroed(),
            PassParams::IDENTITY
        );
        let map = DisplacementMap::from_fn(9, 7, 5.0, super::super::map::Edge::Wrap, |i, j| {
            (i * 3 + j * 5) as f32 * 0.25
        });
        let out = convolve_pass(&map, &vec![PassParams::IDENTITY; 63]);
        assert_eq!(out, map);
    }
}
