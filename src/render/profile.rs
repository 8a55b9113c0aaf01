//! The skin diffusion profile as a sum of six Gaussians and its
//! texture-space convolution (CPU reference of `shaders/diffusion.wgsl`).
//!
//! The profile (d'Eon & Luebke's fit of a three-layer skin model, tabulated
//! in Chappuis 2011 Fig. 2.7) is `R_c(r) = Σ_i w_{i,c} G(v_i, r)` with the
//! normalised 2D Gaussian `G(v, r) = exp(−r²/2v) / (2πv)`; each colour
//! channel's weights sum to one, so white light diffuses to white.
//!
//! Texture-space diffusion blurs the irradiance texture with each Gaussian.
//! Convolving Gaussians adds their variances, so Gaussian `i` is obtained
//! from Gaussian `i − 1` by a further blur of variance `v_i − v_{i−1}`,
//! always with the same seven-tap kernel whose tap spacing is that blur's
//! standard deviation in texels. Stretch correction: the spacing is divided
//! by the local millimetres per texel along the pass, measured from the
//! deformed surface, so stretched skin diffuses over fewer texels.

/// Variances of the six Gaussians (mm²), ascending.
pub const VARIANCES_MM2: [f64; 6] = [0.0064, 0.0484, 0.187, 0.567, 1.99, 7.41];

/// Weights of the six Gaussians per channel (R, G, B).
pub const WEIGHTS: [[f64; 3]; 6] = [
    [0.233, 0.455, 0.649],
    [0.100, 0.336, 0.344],
    [0.118, 0.198, 0.0],
    [0.113, 0.007, 0.007],
    [0.358, 0.004, 0.0],
    [0.078, 0.0, 0.0],
];

/// Tap offsets of the seven-tap kernel, in units of its standard deviation.
pub const TAP_OFFSETS: [f64; 7] = [-3.0, -2.0, -1.0, 0.0, 1.0, 2.0, 3.0];

/// The normalised 2D Gaussian of variance `v` (mm²) at radius `r` (mm).
pub fn gaussian(v: f64, r: f64) -> f64 {
    (-r * r / (2.0 * v)).exp() / (2.0 * std::f64::consts::PI * v)
}

/// The summed profile `R(r)` per channel (1/mm²).
pub fn profile(r: f64) -> [f64; 3] {
    let mut sum = [0.0; 3];
    for (v, w) in VARIANCES_MM2.iter().zip(WEIGHTS) {
        let g = gaussian(*v, r);
        for c in 0..3 {
            sum[c] += w[c] * g;
        }
    }
    sum
}

/// Variance each blur step adds: `v_0`, then `v_i − v_{i−1}` (mm²).
pub fn variance_steps() -> [f64; 6] {
    let mut steps = VARIANCES_MM2;
    for i in (1..6).rev() {
        steps[i] -= VARIANCES_MM2[i - 1];
    }
    steps
}

/// The seven tap weights: samples of a Gaussian at the tap offsets whose
/// width is chosen so the discrete kernel has unit sum and unit variance
/// (the paper's rounded weights sum to 1.001 with variance 1.08, which would
/// inflate every step of the chain).
pub fn tap_weights() -> [f64; 7] {
    // Bisection on the sampled Gaussian's width s: the variance of the
    // normalised taps grows monotonically with s.
    let taps = |s: f64| {
        let raw = TAP_OFFSETS.map(|x| (-x * x / (2.0 * s * s)).exp());
        let total: f64 = raw.iter().sum();
        raw.map(|w| w / total)
    };
    let variance = |w: [f64; 7]| -> f64 { w.iter().zip(TAP_OFFSETS).map(|(w, x)| w * x * x).sum() };
    let (mut lo, mut hi) = (0.5, 2.0);
    for _ in 0..100 {
        let mid = 0.5 * (lo + hi);
        if variance(taps(mid)) < 1.0 {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    taps(0.5 * (lo + hi))
}

/// A linear RGBA image of `width × height` texels, row 0 at v = 0.
#[derive(Clone, Debug, PartialEq)]
pub struct Texture {
    /// Width in texels.
    pub width: usize,
    /// Height in texels.
    pub height: usize,
    /// Texels, row-major.
    pub texels: Vec<[f32; 4]>,
}

impl Texture {
    /// A texture of `width × height` zero texels.
    pub fn zeros(width: usize, height: usize) -> Texture {
        Texture {
            width,
            height,
            texels: vec![[0.0; 4]; width * height],
        }
    }

    /// Bilinear sample at texture coordinates `(u, v)` with clamp-to-edge
    /// addressing, as a linear sampler does.
    pub fn sample(&self, u: f64, v: f64) -> [f64; 4] {
        let x = u * self.width as f64 - 0.5;
        let y = v * self.height as f64 - 0.5;
        let (x0, y0) = (x.floor(), y.floor());
        let (fx, fy) = (x - x0, y - y0);
        let clamp = |i: f64, n: usize| (i.max(0.0) as usize).min(n - 1);
        let mut out = [0.0; 4];
        for (dy, wy) in [(0.0, 1.0 - fy), (1.0, fy)] {
            for (dx, wx) in [(0.0, 1.0 - fx), (1.0, fx)] {
                let i = clamp(x0 + dx, self.width);
                let j = clamp(y0 + dy, self.height);
                let t = self.texels[j * self.width + i];
                for c in 0..4 {
                    out[c] += wx * wy * t[c] as f64;
                }
            }
        }
        out
    }
}

/// Texels per standard deviation a Gaussian of the chain keeps at least
/// (at rest): a Gaussian this wide is stored at the coarsest halving of the
/// texture that still has them (see [`level_sizes`]).
pub const TEXELS_PER_SIGMA: f64 = 6.0;

/// Smallest side a blurred texture is reduced to.
pub const MIN_LEVEL_SIZE: usize = 8;

/// The side of each of the six blurred textures for an irradiance texture
/// of `size²` texels, `texel_mm` millimetres a texel at rest: Gaussian `i`
/// (standard deviation `σ_i = √v_i`) goes to the smallest halving of the
/// previous Gaussian's side whose texels are at most `σ_i /`
/// [`TEXELS_PER_SIGMA`] wide. A wide Gaussian's texture is smooth over
/// many texels, so storing it coarser and reading it bilinearly changes the
/// diffused light by a small fraction of a percent while the passes that
/// make it cost a quarter per halving ([`pass_sizes`] says how each pass
/// reduces).
pub fn level_sizes(size: usize, texel_mm: f64) -> [usize; 6] {
    let mut sizes = [size; 6];
    let mut side = size;
    for (out, v) in sizes.iter_mut().zip(VARIANCES_MM2) {
        let widest = v.sqrt() / TEXELS_PER_SIGMA;
        loop {
            let half = side.div_ceil(2);
            // (half ≥ MIN_LEVEL_SIZE implies half < side.)
            if half < MIN_LEVEL_SIZE || texel_mm * size as f64 / half as f64 > widest {
                break;
            }
            side = half;
        }
        *out = side;
    }
    sizes
}

/// One seven-tap pass along `axis` (0: u, 1: v) adding `variance_mm2`, read
/// from `input` and written at `width × height` texels (CPU reference of
/// `diffusion.wgsl`). `stretch` holds millimetres per texel of its own grid
/// along u and v in channels 0 and 1; it is read bilinearly at each output
/// texel's centre.
pub fn blur_pass(
    input: &Texture,
    stretch: &Texture,
    variance_mm2: f64,
    axis: usize,
    (width, height): (usize, usize),
) -> Texture {
    let weights = tap_weights();
    let sigma = variance_mm2.sqrt();
    let stretch_side = if axis == 0 {
        stretch.width
    } else {
        stretch.height
    } as f64;
    let mut out = Texture::zeros(width, height);
    for j in 0..height {
        for i in 0..width {
            let u = (i as f64 + 0.5) / width as f64;
            let v = (j as f64 + 0.5) / height as f64;
            let mm_per_texel = stretch.sample(u, v)[axis];
            // Tap spacing in texture coordinates.
            let step = sigma / mm_per_texel.max(1e-9) / stretch_side;
            let mut sum = [0.0; 4];
            for (w, x) in weights.iter().zip(TAP_OFFSETS) {
                let (du, dv) = if axis == 0 {
                    (x * step, 0.0)
                } else {
                    (0.0, x * step)
                };
                let s = input.sample(u + du, v + dv);
                for c in 0..4 {
                    sum[c] += w * s[c];
                }
            }
            out.texels[j * width + i] = sum.map(|x| x as f32);
        }
    }
    out
}

/// The six blurred irradiance textures of the chain at the sides `sizes`
/// ([`level_sizes`]): Gaussian `i` is blur `i` applied to Gaussian `i − 1`,
/// the first to the irradiance itself.
pub fn diffuse(irradiance: &Texture, stretch: &Texture, sizes: &[usize; 6]) -> Vec<Texture> {
    let mut out: Vec<Texture> = Vec::with_capacity(6);
    for (i, dv) in variance_steps().into_iter().enumerate() {
        let source = if i == 0 { irradiance } else { &out[i - 1] };
        let [along_u, done] = pass_sizes(source.height, sizes[i]);
        let along_u = blur_pass(source, stretch, dv, 0, along_u);
        out.push(blur_pass(&along_u, stretch, dv, 1, done));
    }
    out
}

/// Output sizes of the two passes of a Gaussian stored at `side²` blurred
/// from a source `rows` texels tall: the u pass reduces only u (its result
/// is still only as smooth along v as the source, so it keeps the source's
/// rows), the v pass then reduces v.
pub fn pass_sizes(rows: usize, side: usize) -> [(usize, usize); 2] {
    [(side, rows), (side, side)]
}

/// The weighted sum of the six blurred textures at texture coordinates
/// `(u, v)`, each read bilinearly as the skin pass does: the diffused
/// radiance per channel.
pub fn combine(blurred: &[Texture], u: f64, v: f64) -> [f64; 3] {
    let mut sum = [0.0; 3];
    for (tex, w) in blurred.iter().zip(WEIGHTS) {
        let t = tex.sample(u, v);
        for c in 0..3 {
            sum[c] += w[c] * t[c];
        }
    }
    sum
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn taps_have_unit_sum_and_variance() {
        let w = tap_weights();
        let sum: f64 = w.iter().sum();
        let var: f64 = w.iter().zip(TAP_OFFSETS).map(|(w, x)| w * x * x).sum();
        assert!(
            (sum - 1.0).abs() < 1e-12 && (var - 1.0).abs() < 1e-9,
            "{sum} {var}"
        );
        // Close to the paper's rounded weights (0.006, 0.061, 0.242, 0.383).
        for (a, b) in w[..4].iter().zip([0.006, 0.061, 0.242, 0.383]) {
            assert!((a - b).abs() < 0.03, "{a} vs {b}");
        }
    }

    #[test]
    fn level_sizes_halve_with_the_gaussians() {
        // 1024² over 10 mm (the examples): the narrowest Gaussian keeps
        // the full size, each wider one has at least TEXELS_PER_SIGMA
        // texels per standard deviation and would lose that at half size.
        let sizes = level_sizes(1024, 10.0 / 1024.0);
        assert_eq!(sizes, [1024, 512, 256, 128, 64, 32]);
        for (side, v) in sizes.iter().zip(VARIANCES_MM2) {
            let texels = v.sqrt() / (10.0 / *side as f64);
            assert!(texels >= TEXELS_PER_SIGMA, "{side}: {texels}");
            assert!(v.sqrt() / (20.0 / *side as f64) < TEXELS_PER_SIGMA);
        }
        // Never below MIN_LEVEL_SIZE, never above the input, non-increasing.
        let sizes = level_sizes(100, 1.0);
        assert_eq!(sizes, [100; 6]);
        let sizes = level_sizes(96, 0.001);
        assert!(sizes.windows(2).all(|w| w[1] <= w[0]), "{sizes:?}");
        assert!(
            sizes.iter().all(|&s| (MIN_LEVEL_SIZE..=96).contains(&s)),
            "{sizes:?}"
        );
        assert_eq!(sizes[5], 12);
    }

    #[test]
    fn variance_steps_add_up() {
        let mut acc = 0.0;
        for (step, v) in variance_steps().iter().zip(VARIANCES_MM2) {
            acc += step;
            assert!(*step > 0.0 && (acc - v).abs() < 1e-12);
        }
    }
}
