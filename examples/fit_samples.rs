//! Makes the sample maps of `examples/fit/` for `skinpatch fit`: a neutral
//! skin map and two "measured" deformed maps whose kernels are known, so
//! the fit can be checked against the answer.
//!
//! ```sh
//! cargo run --release --example fit_samples            # rewrites examples/fit/*.png
//! ```
//!
//! The neutral map is the procedural skin (`micro::procedural`), 256² texels
//! of 5 µm, written as skinpatch's 16-bit PNG (its metadata gives the texel
//! size and height scale). Each sample is what a scan of the deformed skin
//! would show: the neutral map convolved along u with the built-in forehead
//! kernel at its stretch ratio (Nagano et al. 2015 eq. 8–9), then resampled
//! to the stretched shape (`micro::fit::resample`: features r times longer
//! along u). Samples are written as plain 16-bit PNGs without metadata, as
//! a scanner would, with black at the map's lowest height and white
//! `HEIGHT_RANGE_UM` above it; `samples.toml` gives `texel_um` and
//! `height_unit_um` for them.

use std::path::Path;

use skinpatch::micro::fit::{resample, Axis};
use skinpatch::micro::{convolve::convolve_pass, DisplacementMap, KernelModel, PassParams};

/// Texel size of every map (µm).
const TEXEL_UM: f64 = 5.0;
/// Height of white in the plain sample PNGs (µm): `height_unit_um` in
/// samples.toml.
const HEIGHT_RANGE_UM: f64 = 120.0;
/// The samples: file name and stretch ratio along u.
const SAMPLES: [(&str, f64); 2] = [("stretched_115.png", 1.15), ("compressed_085.png", 0.85)];

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let dir = Path::new("examples/fit");
    std::fs::create_dir_all(dir)?;
    let neutral = skinpatch::micro::procedural::generate(&skinpatch::micro::SkinParams {
        size_px: 256,
        extent_mm: 256.0 * TEXEL_UM / 1000.0,
        seed: 7,
        ..skinpatch::micro::SkinParams::default()
    })?;
    skinpatch::micro::io::write_png16(&dir.join("neutral.png"), &neutral)?;
    let model = KernelModel::forehead();
    for (name, r) in SAMPLES {
        let p = model.params(r);
        let pass = PassParams {
            axis: Axis::U.unit(),
            alpha: p.alpha as f32,
            sigma: (p.sigma_um / neutral.texel_um) as f32,
        };
        let deformed = resample(
            &convolve_pass(&neutral, &vec![pass; neutral.data.len()]),
            Axis::U,
            r,
        );
        write_plain_png(&dir.join(name), &deformed)?;
        println!(
            "{name}: r = {r} along u, α = {:.3}, σ = {:.2} µm, {} × {} texels",
            p.alpha, p.sigma_um, deformed.width, deformed.height
        );
    }
    println!("written under {}", dir.display());
    Ok(())
}

/// A 16-bit greyscale PNG with no metadata: 0 at the lowest height,
/// 65535 at `HEIGHT_RANGE_UM` above it. Image row 0 is the top of the
/// picture, the largest v (map row `height − 1`), as skinpatch reads it.
fn write_plain_png(path: &Path, map: &DisplacementMap) -> Result<(), Box<dyn std::error::Error>> {
    let heights: Vec<f64> = map
        .data
        .iter()
        .map(|&h| h as f64 * map.height_unit_um)
        .collect();
    let low = heights.iter().copied().fold(f64::INFINITY, f64::min);
    let high = heights.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    if high - low > HEIGHT_RANGE_UM {
        return Err(format!(
            "{}: heights span {:.1} µm, more than the {HEIGHT_RANGE_UM} µm of white",
            path.display(),
            high - low
        )
        .into());
    }
    let levels: Vec<u16> = heights
        .chunks(map.width)
        .rev()
        .flatten()
        .map(|h| ((h - low) / HEIGHT_RANGE_UM * 65535.0).round() as u16)
        .collect();
    let image = image::ImageBuffer::<image::Luma<u16>, _>::from_raw(
        map.width as u32,
        map.height as u32,
        levels,
    )
    .ok_or("map size does not match its data")?;
    image.save(path)?;
    Ok(())
}
