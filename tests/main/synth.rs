//! Microstructure synthesis (Graham et al. 2013 §4): the result against the exemplar
//! and the mesostructure it details, seams, determinism and bad input.
//!
//! The data: an exemplar of procedural skin at 5 µm texels (seed 1), and a
//! scan-like mesostructure map from another seed with coarser, deeper
//! features, blurred by σ = 40 µm and sampled at 20 µm.

use skinpatch::micro::fit::auto_range;
use skinpatch::micro::procedural::{generate, SkinParams};
use skinpatch::micro::spectrum::{band_difference, octaves};
use skinpatch::micro::synth::{gauss, synthesize, SynthInputs, SynthParams, Synthesis};
use skinpatch::micro::{DisplacementMap, Edge, NormalHistogram};

const TEXEL_UM: f64 = 5.0;
/// The mesostructure map's blur (µm): the detail it holds.
const MESO_BLUR_UM: f64 = 40.0;

/// Skin at 5 µm texels with features scaled to a small exemplar.
fn skin(seed: u64, size_px: usize) -> DisplacementMap {
    generate(&SkinParams {
        size_px,
        extent_mm: size_px as f64 * TEXEL_UM / 1000.0,
        seed,
        groove_spacing_um: 140.0,
        groove_width_um: 10.0,
        pore_radius_um: 12.0,
        pore_density_per_mm2: 40.0,
        noise_scale_um: 20.0,
        ..SkinParams::default()
    })
    .unwrap()
}

/// The mesostructure map over `size_px` output texels (a quarter as many
/// of its own).
fn mesostructure(size_px: usize) -> DisplacementMap {
    let fine = generate(&SkinParams {
        size_px,
        extent_mm: size_px as f64 * TEXEL_UM / 1000.0,
        seed: 2,
        groove_spacing_um: 500.0,
        groove_width_um: 40.0,
        groove_depth_um: 40.0,
        ..SkinParams::default()
    })
    .unwrap();
    gauss(&fine, MESO_BLUR_UM / TEXEL_UM).resampled(size_px / 4, size_px / 4)
}

fn params() -> SynthParams {
    SynthParams {
        mesostructure_sigma_um: Some(MESO_BLUR_UM),
        ..SynthParams::default()
    }
}

fn run(
    exemplar: &DisplacementMap,
    meso: Option<&DisplacementMap>,
    size: Option<(usize, usize)>,
    p: &SynthParams,
) -> Synthesis {
    synthesize(
        &SynthInputs {
            exemplar,
            mesostructure: meso,
            texel_um: None,
            size,
            edge: None,
        },
        p,
        &mut |_| {},
    )
    .unwrap()
}

fn rms(a: &[f32], b: &[f32]) -> f64 {
    (a.iter()
        .zip(b)
        .map(|(x, y)| ((x - y) as f64).powi(2))
        .sum::<f64>()
        / a.len() as f64)
        .sqrt()
}

fn correlation(a: &[f32], b: &[f32]) -> f64 {
    let n = a.len() as f64;
    let mean = |v: &[f32]| v.iter().map(|&x| x as f64).sum::<f64>() / n;
    let (ma, mb) = (mean(a), mean(b));
    let (mut ab, mut aa, mut bb) = (0.0, 0.0, 0.0);
    for (&x, &y) in a.iter().zip(b) {
        let (x, y) = (x as f64 - ma, y as f64 - mb);
        ab += x * y;
        aa += x * x;
        bb += y * y;
    }
    ab / (aa * bb).sqrt()
}

/// Total variation between the 64 × 64 normal histograms (the fit's
/// function and range rule) of `map` and `exemplar`.
fn histogram_distance(map: &DisplacementMap, exemplar: &DisplacementMap) -> f64 {
    let range = auto_range(&[exemplar, map]);
    NormalHistogram::of(map, 64, range, [1.0, 1.0]).distance(&NormalHistogram::of(
        exemplar,
        64,
        range,
        [1.0, 1.0],
    ))
}

/// Worst per-octave power ratio error over the microstructure band: from
/// where the mesostructure blur passes e⁻² of the amplitude,
/// f = 1/(π σ_m), to Nyquist.
fn spectrum_distance(map: &DisplacementMap, exemplar: &DisplacementMap) -> f64 {
    let from = 1.0 / (std::f64::consts::PI * MESO_BLUR_UM);
    band_difference(&octaves(map), &octaves(exemplar), from, 1.0)
        .expect("octaves in the band")
        .0
}

/// A "skin" of uniform noise with the exemplar's mean and standard deviation.
fn uniform_noise(like: &DisplacementMap) -> DisplacementMap {
    let n = like.data.len() as f64;
    let mean = like.data.iter().map(|&v| v as f64).sum::<f64>() / n;
    let sd = (like
        .data
        .iter()
        .map(|&v| (v as f64 - mean).powi(2))
        .sum::<f64>()
        / n)
        .sqrt();
    let half = (3.0f64).sqrt() * sd;
    let mut z = 0x2545_f491_4f6c_dd1du64;
    like.with_data(
        like.data
            .iter()
            .map(|_| {
                z ^= z << 13;
                z ^= z >> 7;
                z ^= z << 17;
                let u = (z >> 11) as f64 / (1u64 << 53) as f64;
                (mean + (2.0 * u - 1.0) * half) as f32
            })
            .collect(),
    )
}

#[test]
fn synthesis_keeps_the_mesostructure_and_reproduces_the_exemplar() {
    let exemplar = skin(1, 512);
    let meso = mesostructure(640);
    let out = run(&exemplar, Some(&meso), None, &params());
    assert_eq!((out.map.width, out.map.height), (640, 640));
    assert_eq!(out.map.texel_um, TEXEL_UM);
    assert_eq!(out.levels.len(), 3);
    assert_eq!(
        out.levels
            .iter()
            .map(|l| (l.window, l.dims))
            .collect::<Vec<_>>(),
        [(5, 5), (9, 9), (13, 13)],
        "windows grow from 5 × 5 to 13 × 13, PCA to n dimensions"
    );

    // Low frequencies: B′ and B seen at B's resolution (through the same
    // Gaussian, σ_m) agree within 2 % of B's range RMS.
    let (lo, hi) = out.guide.range();
    let sm = MESO_BLUR_UM / TEXEL_UM;
    let low_error = rms(&gauss(&out.map, sm).data, &gauss(&out.guide, sm).data) / (hi - lo) as f64;
    println!("low-frequency RMS error: {low_error:.4} of B's range");
    assert!(low_error <= 0.02, "{low_error}");

    // The exemplar's statistics.
    let tv = histogram_distance(&out.map, &exemplar);
    let spectrum = spectrum_distance(&out.map, &exemplar);
    println!("normal histogram TV {tv:.3}, spectrum worst octave {spectrum:.3}");
    assert!(spectrum <= 0.2, "{spectrum}");
    assert!(tv <= 0.25, "{tv}");

    // A uniform-noise "exemplar" gives a map that fails both.
    let noise = uniform_noise(&exemplar);
    let from_noise = run(&noise, Some(&meso), None, &params());
    let (tv_n, spectrum_n) = (
        histogram_distance(&from_noise.map, &exemplar),
        spectrum_distance(&from_noise.map, &exemplar),
    );
    println!("from noise: normal histogram TV {tv_n:.3}, spectrum {spectrum_n:.3}");
    assert!(tv_n > 0.5 && spectrum_n > 0.5, "{tv_n} {spectrum_n}");
}

#[test]
fn the_mesostructure_constraint_matters() {
    // α = 1 ignores B in the match (Graham et al. 2013 Fig. 9d): B′'s medium
    // frequencies follow B's much less. Measured before the restoring
    // passes, which would put B's medium frequencies back either way.
    let exemplar = skin(1, 256);
    let meso = mesostructure(320);
    let corr = |alpha: f64| {
        let out = run(
            &exemplar,
            Some(&meso),
            None,
            &SynthParams {
                alpha,
                restore_passes: 0,
                ..params()
            },
        );
        let sl = out.sigmas_um.1 / TEXEL_UM;
        let sm = out.sigmas_um.0 / TEXEL_UM;
        let band = |m: &DisplacementMap| {
            let seen = gauss(m, sm);
            let low = gauss(&seen, sl);
            seen.data
                .iter()
                .zip(&low.data)
                .map(|(x, l)| x - l)
                .collect::<Vec<f32>>()
        };
        correlation(&band(&out.map), &band(&out.guide))
    };
    let (constrained, free) = (corr(0.5), corr(1.0));
    println!("correlation with B's high pass: α = 0.5 {constrained:.3}, α = 1 {free:.3}");
    assert!(
        constrained > 0.6 && constrained - free > 0.3,
        "{constrained} {free}"
    );
}

#[test]
fn a_wrapping_output_tiles_without_a_seam() {
    let exemplar = skin(1, 128);
    let p = SynthParams {
        levels: 2,
        ..params()
    };
    // Largest and mean |Δh| between neighbours across the wrap and inside.
    let steps = |m: &DisplacementMap| {
        let (w, h) = (m.width, m.height);
        let mut inside = Vec::new();
        let mut across = Vec::new();
        for j in 0..h {
            for i in 0..w {
                let here = m.data[j * w + i];
                let right = (m.data[j * w + (i + 1) % w] - here).abs();
                let up = (m.data[((j + 1) % h) * w + i] - here).abs();
                if i + 1 == w {
                    across.push(right)
                } else {
                    inside.push(right)
                }
                if j + 1 == h {
                    across.push(up)
                } else {
                    inside.push(up)
                }
            }
        }
        inside.sort_by(f32::total_cmp);
        let p99 = inside[inside.len() * 99 / 100];
        let mean = |v: &[f32]| v.iter().sum::<f32>() / v.len() as f32;
        (
            across.iter().copied().fold(0.0f32, f32::max),
            mean(&across),
            p99,
            mean(&inside),
        )
    };
    let torus = synthesize(
        &SynthInputs {
            exemplar: &exemplar,
            mesostructure: None,
            texel_um: None,
            size: Some((200, 180)),
            edge: Some(Edge::Wrap),
        },
        &p,
        &mut |_| {},
    )
    .unwrap();
    let (max_across, mean_across, p99, mean_inside) = steps(&torus.map);
    println!("wrap: across max {max_across:.3} mean {mean_across:.3}; inside p99 {p99:.3} mean {mean_inside:.3}");
    assert!(
        mean_across <= 1.25 * mean_inside,
        "{mean_across} {mean_inside}"
    );
    assert!(max_across <= 2.0 * p99, "{max_across} {p99}");
    // The same synthesis on a clamped grid has a seam where it would wrap.
    let flat = synthesize(
        &SynthInputs {
            edge: Some(Edge::Clamp),
            exemplar: &exemplar,
            mesostructure: None,
            texel_um: None,
            size: Some((200, 180)),
        },
        &p,
        &mut |_| {},
    )
    .unwrap();
    let (_, mean_flat, _, mean_flat_inside) = steps(&flat.map);
    println!("clamp: across mean {mean_flat:.3}, inside {mean_flat_inside:.3}");
    assert!(
        mean_flat > 1.5 * mean_flat_inside,
        "{mean_flat} {mean_flat_inside}"
    );
}

#[test]
fn same_seed_same_bits_on_any_thread_count() {
    let exemplar = skin(1, 128);
    let meso = mesostructure(160);
    let p = params();
    let on = |threads: usize, seed: u64| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| {
                run(
                    &exemplar,
                    Some(&meso),
                    None,
                    &SynthParams { seed, ..p.clone() },
                )
            })
    };
    let one = on(1, 7);
    let two = on(2, 7);
    let three = on(3, 7);
    assert_eq!(one.map.data, two.map.data);
    assert_eq!(one.map.data, three.map.data);
    assert_eq!(one.source, two.source);
    let other = on(2, 8);
    assert_ne!(one.source, other.source, "another seed, another start");
}

#[test]
fn bad_inputs_are_named() {
    let exemplar = skin(1, 64);
    let meso = mesostructure(64);
    let err = |inputs: SynthInputs<'_>, p: &SynthParams| {
        synthesize(&inputs, p, &mut |_| {}).unwrap_err().to_string()
    };
    let base = SynthInputs {
        exemplar: &exemplar,
        mesostructure: Some(&meso),
        texel_um: None,
        size: None,
        edge: None,
    };
    // An exemplar smaller than the window (one that does not wrap): 12
    // texels are 3 at the coarsest of three levels, the window 5.
    let small = DisplacementMap {
        edge: Edge::Clamp,
        ..skin(1, 12)
    };
    let e = err(
        SynthInputs {
            exemplar: &small,
            ..base
        },
        &params(),
    );
    assert!(
        e.contains("synthesis.exemplar") && e.contains("too small"),
        "{e}"
    );
    // A size beside a mesostructure map: ambiguous.
    let e = err(
        SynthInputs {
            size: Some((10, 10)),
            ..base
        },
        &params(),
    );
    assert!(e.contains("synthesis.size_px"), "{e}");
    // Neither.
    let e = err(
        SynthInputs {
            mesostructure: None,
            ..base
        },
        &params(),
    );
    assert!(e.contains("synthesis.size_px"), "{e}");
    // Non-finite heights, named by texel.
    let mut nan = exemplar.clone();
    nan.data[3 * 64 + 5] = f32::NAN;
    let e = err(
        SynthInputs {
            exemplar: &nan,
            ..base
        },
        &params(),
    );
    assert!(
        e.contains("synthesis.exemplar") && e.contains("(5, 3)"),
        "{e}"
    );
    // Heights near f32's limit (which overflowed the feature distances and
    // crashed the k-d tree), named by texel.
    let mut huge = exemplar.clone();
    huge.data.iter_mut().for_each(|h| *h *= 1e36);
    huge.data[7 * 64 + 2] = 3e38;
    let e = err(
        SynthInputs {
            exemplar: &huge,
            ..base
        },
        &params(),
    );
    assert!(
        e.contains("synthesis.exemplar") && e.contains("texel (") && e.contains("±1e6 µm"),
        "{e}"
    );
    // Memory: the estimate matches the measured peaks within 15 %, and an
    // output beyond what is available is refused before any work.
    use skinpatch::micro::synth::{check_memory, estimated_bytes};
    let at_4096 = estimated_bytes(4096 * 4096, 1024 * 1024, &params()) as f64;
    assert!((at_4096 / 0.879e9 - 1.0).abs() < 0.15, "{at_4096}");
    let no_pca = SynthParams {
        pca_dims: Some(0),
        ..params()
    };
    let at_1024 = estimated_bytes(1024 * 1024, 1024 * 1024, &no_pca) as f64;
    assert!((at_1024 / 2.91e9 - 1.0).abs() < 0.15, "{at_1024}");
    let e = check_memory(60_000_000_000, Some(16_000_000_000))
        .unwrap_err()
        .to_string();
    assert!(e.contains("60.0 GB") && e.contains("16.0 GB"), "{e}");
    assert!(check_memory(1, Some(2)).is_ok() && check_memory(3, None).is_ok());
    // Parameters.
    for (p, key) in [
        (
            SynthParams {
                alpha: 1.5,
                ..params()
            },
            "synthesis.alpha",
        ),
        (
            SynthParams {
                window_fine: 12,
                ..params()
            },
            "synthesis.window_fine",
        ),
        (
            SynthParams {
                window_coarse: 15,
                ..params()
            },
            "synthesis.window_coarse",
        ),
        (
            SynthParams {
                levels: 0,
                ..params()
            },
            "synthesis.levels",
        ),
        (
            SynthParams {
                kappa: f64::NAN,
                ..params()
            },
            "synthesis.kappa",
        ),
        (
            SynthParams {
                mesostructure_sigma_um: Some(-1.0),
                ..params()
            },
            "synthesis.mesostructure_sigma_um",
        ),
        // A blur of a kilometre (whose kernel took memory without bound).
        (
            SynthParams {
                mesostructure_sigma_um: Some(1e9),
                ..params()
            },
            "synthesis.mesostructure_sigma_um is 1e9 µm, wider than the largest map",
        ),
        (
            SynthParams {
                mesostructure_sigma_um: Some(300.0),
                ..params()
            },
            "synthesis.lowpass_sigma_um (by default 4 × mesostructure_sigma_um) is 1200 µm, wider",
        ),
    ] {
        let e = err(base, &p);
        assert!(e.contains(key), "{key}: {e}");
    }
}

/// A small synthesis file over generated inputs, with `extra` keys in
/// `[synthesis]`.
fn small_file(dir: &std::path::Path, synthesis_extra: &str, rest: &str) -> std::path::PathBuf {
    let text = format!(
        "[synthesis]\nmesostructure_sigma_um = 40.0\nlevels = 2\n{synthesis_extra}\n{rest}\n\
         [output]\npreview_px = 64\n"
    );
    let path = dir.join("synth.toml");
    std::fs::write(&path, text).unwrap();
    path
}

const GENERATED: &str = "[synthesis.exemplar_generated]\nextent_mm = 0.64\n\
    [synthesis.exemplar_generated.skin]\nsize_px = 128\ngroove_spacing_um = 140.0\n\
    [synthesis.mesostructure_generated]\nextent_mm = 0.8\nblur_um = 40.0\ntexel_um = 20.0\n\
    [synthesis.mesostructure_generated.skin]\nsize_px = 160\nseed = 2\ngroove_spacing_um = 500.0\n";

#[test]
fn a_synthesis_file_writes_maps_preview_and_report() {
    let dir = tempfile::tempdir().unwrap();
    let path = small_file(dir.path(), "", GENERATED);
    let out = dir.path().join("out");
    let mut levels = 0;
    let run =
        skinpatch::pipeline::synth::run(&path, &[], Some(&out), &mut |_| levels += 1).unwrap();
    assert_eq!(levels, 2);
    let names: Vec<String> = run
        .written
        .iter()
        .map(|p| p.file_name().unwrap().to_string_lossy().into_owned())
        .collect();
    assert_eq!(
        names,
        [
            "synthesized.exr",
            "synthesized.png",
            "synthesized_normals.exr",
            "synthesized_normals.png",
            "preview.png",
            "synthesis.json"
        ]
    );
    // The map reads back with its metadata: 160 texels of 5 µm, µm heights.
    let defaults = skinpatch::micro::io::MapDefaults {
        texel: skinpatch::micro::io::TexelSize::Required("test"),
        height_unit_um: 1.0,
        edge: Edge::Clamp,
    };
    let map = skinpatch::micro::io::read_map(&out.join("synthesized.exr"), &defaults).unwrap();
    assert_eq!(
        (map.width, map.height, map.texel_um, map.edge),
        (160, 160, 5.0, Edge::Wrap)
    );
    assert_eq!(map.data, run.synthesis.map.data);
    let preview = image::open(out.join("preview.png")).unwrap();
    assert_eq!((preview.width(), preview.height()), (4 * 64 + 12, 64));
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("synthesis.json")).unwrap())
            .unwrap();
    assert_eq!(report["levels"].as_array().unwrap().len(), 2);
    assert_eq!(report["levels"][1]["window"], 13);
    let tv = report["statistics"]["histogram_tv"].as_f64().unwrap();
    assert!(tv > 0.0 && tv < 2.0, "{tv}");
    let low = report["statistics"]["low_frequency_rms"].as_f64().unwrap();
    assert!(low < 0.1, "{low}");
    // --set overrides, and the same file gives the same bytes.
    let again = dir.path().join("again");
    skinpatch::pipeline::synth::run(&path, &[], Some(&again), &mut |_| {}).unwrap();
    assert_eq!(
        std::fs::read(out.join("synthesized.exr")).unwrap(),
        std::fs::read(again.join("synthesized.exr")).unwrap()
    );
    let other = dir.path().join("other");
    let r = skinpatch::pipeline::synth::run(
        &path,
        &["synthesis.seed=5".into()],
        Some(&other),
        &mut |_| {},
    )
    .unwrap();
    assert_ne!(r.synthesis.map.data, run.synthesis.map.data);
}

/// The albedo output borrows, per texel, the exemplar albedo pixel whose
/// height the texel took: an albedo that spells out each pixel's
/// coordinates gives them back, and the heights there agree.
#[test]
fn the_albedo_borrows_the_pixels_the_heights_came_from() {
    let dir = tempfile::tempdir().unwrap();
    let exemplar = skin(1, 96);
    let exemplar = exemplar.resampled(96, 80);
    skinpatch::micro::io::write_exr(&dir.path().join("ex.exr"), &exemplar).unwrap();
    // 16-bit RGB: R = x, G = y of the map texel (rows flipped: images run
    // top down, maps v up).
    let (w, h) = (exemplar.width as u32, exemplar.height as u32);
    let albedo = image::ImageBuffer::from_fn(w, h, |x, y| {
        image::Rgb([x as u16, (h - 1 - y) as u16, 7u16])
    });
    image::DynamicImage::ImageRgb16(albedo)
        .save(dir.path().join("albedo.png"))
        .unwrap();
    let path = small_file(
        dir.path(),
        "exemplar = \"ex.exr\"\nexemplar_albedo = \"albedo.png\"\nsize_px = 120\n\
         blend_radius = 0\nrestore_passes = 0\nlowpass_sigma_um = 80.0",
        "",
    );
    let out = dir.path().join("out");
    let run = skinpatch::pipeline::synth::run(&path, &[], Some(&out), &mut |_| {}).unwrap();
    let result = image::open(out.join("albedo.png")).unwrap().to_rgba16();
    assert_eq!(result.dimensions(), (120, 120));
    // Without B and without blending, B′ = A′_h(S): A′ less its 80 µm low pass.
    let low = gauss(&exemplar, 80.0 / TEXEL_UM);
    let map = &run.synthesis.map;
    for j in 0..map.height {
        for i in 0..map.width {
            let px = result.get_pixel(i as u32, (map.height - 1 - j) as u32);
            let (x, y) = (px[0] as usize, px[1] as usize);
            assert_eq!(px[2], 7);
            let k = y * exemplar.width + x;
            assert_eq!(
                map.data[j * map.width + i],
                exemplar.data[k] - low.data[k],
                "texel ({i}, {j})"
            );
        }
    }
    // An albedo of another size is refused by name.
    image::DynamicImage::ImageRgb8(image::RgbImage::new(10, 10))
        .save(dir.path().join("albedo.png"))
        .unwrap();
    let e = skinpatch::pipeline::synth::run(&path, &[], Some(&out), &mut |_| {})
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("synthesis.exemplar_albedo") && e.contains("same size"),
        "{e}"
    );
}

/// An 8-bit PNG says nothing of its texel size: without
/// `exemplar_texel_um` it is refused, naming the file and the key; with
/// it, it reads.
#[test]
fn maps_without_a_texel_size_need_one() {
    let dir = tempfile::tempdir().unwrap();
    let img =
        image::GrayImage::from_fn(64, 64, |x, y| image::Luma([((x * 7 + y * 3) % 256) as u8]));
    image::DynamicImage::ImageLuma8(img)
        .save(dir.path().join("ex8.png"))
        .unwrap();
    let path = small_file(dir.path(), "exemplar = \"ex8.png\"\nsize_px = 64\n", "");
    let out = dir.path().join("out");
    let e = skinpatch::pipeline::synth::run(&path, &[], Some(&out), &mut |_| {})
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("ex8.png") && e.contains("exemplar_texel_um"),
        "{e}"
    );
    let run = skinpatch::pipeline::synth::run(
        &path,
        &["synthesis.exemplar_texel_um=10".into()],
        Some(&out),
        &mut |_| {},
    );
    assert_eq!(run.unwrap().synthesis.map.texel_um, 10.0);
    // Unknown keys and conflicting sources are named.
    let e = skinpatch::pipeline::synth::run(
        &path,
        &["synthesis.alhpa=1".into()],
        Some(&out),
        &mut |_| {},
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("alhpa") && e.contains("alpha"), "{e}");
    let both = small_file(
        dir.path(),
        "exemplar = \"ex8.png\"\nexemplar_texel_um = 5.0",
        GENERATED,
    );
    let e = skinpatch::pipeline::synth::run(&both, &[], Some(&out), &mut |_| {})
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("synthesis.exemplar") && e.contains("keep one"),
        "{e}"
    );
}
