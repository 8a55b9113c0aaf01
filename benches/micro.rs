//! Criterion benchmark of the CPU reference convolution at
//! 2048² against a plain constant-kernel separable Gaussian blur of the same
//! size (integer taps along rows then columns), in one run.
//!
//! The varying field turns the axes across the map and sweeps α over
//! [−1.5, 0.8] and σ over 5 … 25 µm (1 … 5 texels of 5 µm), so every texel
//! pays for a different kernel, as under a real strain field.
//!
//! Run: `cargo bench --bench micro`. Figures go to docs/PERFORMANCE.md.

use criterion::{criterion_group, criterion_main, Criterion};
use rayon::prelude::*;
use skinpatch::micro::convolve::{convolve, KernelField, PassParams};
use skinpatch::micro::procedural::{generate, SkinParams};
use skinpatch::micro::DisplacementMap;

const SIZE: usize = 2048;
const TEXEL_UM: f64 = 5.0;

fn varying_field(map: &DisplacementMap) -> KernelField {
    let n = map.width * map.height;
    let (mut s, mut t) = (Vec::with_capacity(n), Vec::with_capacity(n));
    for j in 0..map.height {
        for i in 0..map.width {
            let (u, v) = (i as f64 / map.width as f64, j as f64 / map.height as f64);
            let angle = std::f64::consts::PI * (u + 0.5 * v);
            let axis = [angle.cos() as f32, angle.sin() as f32];
            let sigma = |w: f64| ((5.0 + 20.0 * w) / TEXEL_UM) as f32;
            s.push(PassParams {
                axis,
                alpha: (-1.5 + 2.3 * u) as f32,
                sigma: sigma(v),
            });
            t.push(PassParams {
                axis: [-axis[1], axis[0]],
                alpha: (0.8 - 2.3 * v) as f32,
                sigma: sigma(u),
            });
        }
    }
    KernelField {
        width: map.width,
        height: map.height,
        s,
        t,
    }
}

/// A constant Gaussian blur of σ texels along rows, then columns, clamped at
/// the edges: the baseline.
fn plain_blur(map: &DisplacementMap, sigma: f64) -> Vec<f32> {
    let taps = skinpatch::micro::kernel::gaussian(sigma);
    let r = (taps.len() / 2) as isize;
    let taps: Vec<f32> = taps.iter().map(|&w| w as f32).collect();
    let (w, h) = (map.width as isize, map.height as isize);
    let mut rows = vec![0.0f32; map.data.len()];
    rows.par_chunks_mut(map.width)
        .enumerate()
        .for_each(|(j, out)| {
            let line = &map.data[j * map.width..(j + 1) * map.width];
            for (i, o) in out.iter_mut().enumerate() {
                *o = (-r..=r)
                    .map(|k| {
                        taps[(k + r) as usize] * line[(i as isize + k).clamp(0, w - 1) as usize]
                    })
                    .sum();
            }
        });
    let mut cols = vec![0.0f32; map.data.len()];
    cols.par_chunks_mut(map.width)
        .enumerate()
        .for_each(|(j, out)| {
            for (i, o) in out.iter_mut().enumerate() {
                *o = (-r..=r)
                    .map(|k| {
                        let jj = (j as isize + k).clamp(0, h - 1) as usize;
                        taps[(k + r) as usize] * rows[jj * map.width + i]
                    })
                    .sum();
            }
        });
    cols
}

fn micro(c: &mut Criterion) {
    let map = generate(&SkinParams {
        size_px: SIZE,
        extent_mm: SIZE as f64 * TEXEL_UM / 1000.0,
        ..SkinParams::default()
    })
    .expect("default parameters are valid");
    let field = varying_field(&map);
    let mut group = c.benchmark_group("convolution_2048");
    group.sample_size(10);
    group.bench_function("two_pass_varying", |b| b.iter(|| convolve(&map, &field)));
    group.bench_function("plain_separable_blur_sigma_25um", |b| {
        b.iter(|| plain_blur(&map, 25.0 / TEXEL_UM))
    });
    group.finish();
}

criterion_group!(benches, micro);
criterion_main!(benches);
