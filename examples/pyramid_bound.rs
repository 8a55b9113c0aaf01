//! How far a pre-blurred pyramid of the neutral map can stand in for the
//! exact strain-driven convolution, measured on the CPU
//! reference.
//!
//! ```sh
//! cargo run --release --example pyramid_bound                  # 1024², 2 µm texels
//! cargo run --release --example pyramid_bound -- --size 2048 --texel-um 1
//! ```
//!
//! A pyramid saves taps only if a pass reads a map that was blurred
//! *before* the frame, by σ_L texels, and adds the rest, σ′ = √(σ² − σ_L²),
//! itself. The neutral map's pre-blur can only be isotropic (the axes turn
//! from texel to texel), while a pass blurs along one axis. With kernel
//! field parameters held constant, the two passes expand exactly into
//!
//! `D′ = (1−α_s)(1−α_t)·D + α_s(1−α_t)·G_s D + (1−α_s)α_t·G_t D + α_s α_t·G_t G_s D`,
//!
//! and the best any pyramid can do — before downsampling, which only adds
//! error — is to read `G_s′ G_L D`, `G_t′ G_L D` and `G_t′ G_s′ G_L D` in
//! place of the three blurred terms (G_L the isotropic pre-blur). The last
//! term is exact: a 2D Gaussian factors into isotropic σ_L and the residual
//! axes. The two one-axis terms are not: they gain σ_L of blur across
//! their axis. The program prints that best case's error against the exact
//! two-pass convolution, as a fraction of the neutral map's height range,
//! for stretch pairs of the forehead model and pre-blurs of 1 … 8 texels
//! (a level L of a pyramid needs σ_L ≈ 2^L texels before its 2^L-fold
//! subsampling stops aliasing, so σ_L = 8 texels saves ≤ 8× the taps).
//! σ_L = 0 checks the expansion itself (round-off).

use clap::Parser;
use skinpatch::micro::convolve::{blur_along_axis, convolve, convolve_pass, KernelField};
use skinpatch::micro::kernel::KernelModel;
use skinpatch::micro::procedural::{generate, SkinParams};
use skinpatch::micro::DisplacementMap;

#[derive(Parser)]
#[command(about = "Best-case error of a pyramid pre-blur against the exact convolution")]
struct Args {
    /// Map side (texels).
    #[arg(long, default_value_t = 1024)]
    size: usize,
    /// Texel side (µm); small texels make σ span many texels.
    #[arg(long, default_value_t = 2.0)]
    texel_um: f64,
    /// Angle of the s axis against the map's u axis (degrees).
    #[arg(long, default_value_t = 30.0)]
    angle_deg: f64,
}

/// `Σ c_i · maps_i` texel by texel.
fn combine(terms: &[(f64, &DisplacementMap)]) -> Vec<f64> {
    let n = terms[0].1.data.len();
    (0..n)
        .map(|k| terms.iter().map(|(c, m)| c * m.data[k] as f64).sum())
        .collect()
}

/// The Gaussian half (α = 1) of a constant pass with σ texels along `axis`.
fn gaussian_pass(
    map: &DisplacementMap,
    field: &KernelField,
    s_axis: bool,
    sigma: f32,
) -> DisplacementMap {
    let mut params = if s_axis {
        field.s.clone()
    } else {
        field.t.clone()
    };
    for p in &mut params {
        p.alpha = 1.0;
        p.sigma = sigma;
    }
    convolve_pass(map, &params)
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args = Args::parse();
    if args.size < 64 || !args.texel_um.is_finite() || args.texel_um <= 0.0 {
        return Err("--size must be ≥ 64 and --texel-um finite and > 0".into());
    }
    let map = generate(&SkinParams {
        size_px: args.size,
        extent_mm: args.size as f64 * args.texel_um * 1e-3,
        ..SkinParams::default()
    })?;
    let (lo, hi) = map.range();
    let range = (hi - lo) as f64;
    let model = KernelModel::forehead();
    let angle = args.angle_deg.to_radians();
    let axis = [angle.cos(), angle.sin()];
    println!(
        "neutral map {0}² of {1} µm texels (height range {2:.2} µm), s axis at {3}°",
        args.size, args.texel_um, range, args.angle_deg
    );
    println!(
        "| r_s | r_t | α_s | α_t | σ_s px | σ_t px | σ_L px | max |Δ| / range | RMS / range |"
    );
    println!("|---|---|---|---|---|---|---|---|---|");
    // Uniaxial stretch, stretch with lateral compression, compression, and
    // strong equibiaxial stretch (α = 1 on both axes: only the 2D term).
    // The isotropic pre-blurs, once for every stretch pair.
    let pre_blurred: Vec<(f32, DisplacementMap)> = [0.0f32, 1.0, 2.0, 4.0, 8.0]
        .into_iter()
        .map(|s| {
            (
                s,
                blur_along_axis(&blur_along_axis(&map, true, s), false, s),
            )
        })
        .collect();
    for (rs, rt) in [(1.2, 1.0), (1.2, 0.95), (0.9, 0.85), (1.35, 1.35)] {
        let (ps, pt) = (model.params(rs), model.params(rt));
        let field = KernelField::constant(&map, axis, ps, pt);
        let exact = convolve(&map, &field);
        let (ss, st) = (field.s[0].sigma, field.t[0].sigma);
        let (a_s, a_t) = (ps.alpha, pt.alpha);
        for &(sigma_l, ref pre) in &pre_blurred {
            // Only the axes that blur (α ≠ 0) limit the pre-blur.
            let limit = [(a_s, ss), (a_t, st)]
                .iter()
                .filter(|(a, _)| *a != 0.0)
                .map(|&(_, s)| s)
                .fold(f32::INFINITY, f32::min);
            if sigma_l > limit {
                continue;
            }
            let rest = |s: f32| (s * s - sigma_l * sigma_l).max(0.0).sqrt();
            let gs = gaussian_pass(pre, &field, true, rest(ss));
            let gt = gaussian_pass(pre, &field, false, rest(st));
            let gts = gaussian_pass(&gs, &field, false, rest(st));
            let approx = combine(&[
                ((1.0 - a_s) * (1.0 - a_t), &map),
                (a_s * (1.0 - a_t), &gs),
                ((1.0 - a_s) * a_t, &gt),
                (a_s * a_t, &gts),
            ]);
            let (mut max, mut sum2) = (0.0f64, 0.0f64);
            for (a, e) in approx.iter().zip(&exact.data) {
                let d = (a - *e as f64).abs();
                max = max.max(d);
                sum2 += d * d;
            }
            let rms = (sum2 / approx.len() as f64).sqrt();
            println!(
                "| {rs} | {rt} | {a_s:.3} | {a_t:.3} | {ss:.2} | {st:.2} | {sigma_l} | {:.1e} | {:.1e} |",
                max / range,
                rms / range
            );
        }
    }
    Ok(())
}
