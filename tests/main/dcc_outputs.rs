//! Outputs as the tools users open them in read them: 16-bit PNG height
//! sequences on one fixed scale (Blender, Houdini and Maya ignore the scale
//! metadata) and the surface strain as float EXR data.

use std::path::Path;

use crate::common;

use skinpatch::micro::io::{read_map, MapDefaults, TexelSize};

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

fn defaults() -> MapDefaults {
    MapDefaults {
        texel: TexelSize::Um(1.0),
        height_unit_um: 1.0,
        edge: skinpatch::micro::Edge::Wrap,
    }
}

/// The `skinpatch:height_offset` and `skinpatch:height_scale` texts of a PNG.
pub fn png_quantisation(path: &Path) -> [f64; 2] {
    let decoder = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(path).unwrap()));
    let reader = decoder.read_info().unwrap();
    let text = &reader.info().uncompressed_latin1_text;
    let value = |key: &str| -> f64 {
        text.iter()
            .find(|c| c.keyword == key)
            .unwrap_or_else(|| panic!("{key} in {}", path.display()))
            .text
            .parse()
            .unwrap()
    };
    [
        value("skinpatch:height_offset"),
        value("skinpatch:height_scale"),
    ]
}

/// A `height_range_um` narrower than the heights clips them to its ends,
/// and the run says how many texels it clipped, in which file; the EXR maps
/// keep the heights.
#[test]
fn a_narrow_height_range_clips_and_says_so() {
    let dir = tempfile::tempdir().unwrap();
    let (out, o) = common::run_press_small_configured(
        dir.path(),
        "\n[microstructure]\nframe_stride = 6\nformats = [\"png16\", \"exr\"]\nnormal_maps = false\n\
         height_range_um = [-20.0, 0.0]\n[microstructure.procedural]\nsize_px = 128\n",
        |_| {},
    );
    let stderr = text(&o.stderr);
    assert!(o.status.success(), "stderr: {stderr}");
    let micro = out.join("micro");
    let exr = read_map(&micro.join("height_0006.exr"), &defaults()).unwrap();
    let png = read_map(&micro.join("height_0006.png"), &defaults()).unwrap();
    let outside = exr
        .data
        .iter()
        .filter(|&&h| !(-20.0..=0.0).contains(&h))
        .count();
    assert!(outside > 0, "the fixture's grooves reach below -20 µm");
    let step = 20.0 / 65535.0;
    for (p, e) in png.data.iter().zip(&exr.data) {
        let expected = e.clamp(-20.0, 0.0);
        assert!((p - expected).abs() <= 0.51 * step, "{p} vs {e}");
    }
    // Clipping is counted texel by texel (a texel within half a step of an
    // end rounds onto it without being clipped).
    let counted = stderr
        .lines()
        .find(|l| l.contains("height_0006.png") && l.contains("clipped"))
        .unwrap_or_else(|| panic!("no clipping report: {stderr}"));
    let n: usize = counted
        .split(": ")
        .nth(1)
        .and_then(|rest| rest.split(' ').next())
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("{counted}"));
    let near_ends = exr
        .data
        .iter()
        .filter(|&&h| !(-20.0 - 0.5 * step..=0.5 * step).contains(&h))
        .count();
    assert_eq!(n, near_ends, "{counted}");
    assert!(counted.contains("-20.00, 0.00"), "{counted}");
}

/// `strain_data` writes each frame's strain as float EXR data at the
/// microstructure map's size: neutral at rest, unit axes, A covering the
/// surface, and r_s within metrics.csv's per-vertex range (the raster
/// interpolates the vertices' stretch tensors, and the larger singular
/// value of a blend is at most the largest of the blended ones).
#[test]
fn strain_data_maps_hold_the_frame_strain() {
    let dir = tempfile::tempdir().unwrap();
    let (out, o) = common::run_press_small_configured(
        dir.path(),
        "\n[output]\nframes_vtu = false\nstrain_data = true\n\
         [microstructure]\nformats = []\nnormal_maps = false\n\
         [microstructure.procedural]\nsize_px = 96\n",
        |_| {},
    );
    assert!(o.status.success(), "stderr: {}", text(&o.stderr));
    let metrics = std::fs::read_to_string(out.join("metrics.csv")).unwrap();
    let header: Vec<&str> = metrics.lines().next().unwrap().split(',').collect();
    let column = |row: &str, name: &str| -> f64 {
        let i = header.iter().position(|c| *c == name).unwrap();
        row.split(',').nth(i).unwrap().parse().unwrap()
    };
    let rows: Vec<&str> = metrics.lines().skip(1).collect();
    assert_eq!(rows.len(), 7);
    assert!(
        !out.join("strain/rs_0000.png").exists(),
        "previews only with strain_images"
    );
    for (f, row) in rows.iter().enumerate() {
        let path = out.join(format!("strain/strain_{f:04}.exr"));
        let image = exr::prelude::read_first_flat_layer_from_file(&path).unwrap();
        let layer = &image.layer_data;
        assert_eq!((layer.size.width(), layer.size.height()), (96, 96));
        let channel = |name: &str| -> Vec<f32> {
            let c = layer
                .channel_data
                .list
                .iter()
                .find(|c| c.name.eq(name))
                .unwrap();
            c.sample_data.values_as_f32().collect()
        };
        let (rs, rt, su, sv, a) = (
            channel("rs"),
            channel("rt"),
            channel("su"),
            channel("sv"),
            channel("A"),
        );
        let inside: Vec<usize> = (0..a.len()).filter(|&k| a[k] == 1.0).collect();
        assert!(
            inside.len() > 96 * 96 * 9 / 10,
            "the patch fills its UV square"
        );
        let [lo, hi] = [column(row, "rs_min"), column(row, "rs_max")];
        let tlo = column(row, "rt_min");
        for &k in &inside {
            let tol = 1e-5;
            assert!(
                rs[k] as f64 >= tlo.min(lo) - tol && rs[k] as f64 <= hi + tol,
                "frame {f}: r_s {} outside [{lo}, {hi}]",
                rs[k]
            );
            assert!(
                rt[k] as f64 >= tlo - tol && rt[k] <= rs[k] + 1e-6,
                "frame {f}"
            );
            assert!((su[k].hypot(sv[k]) - 1.0).abs() < 1e-5 && su[k] >= 0.0);
        }
        if f == 0 {
            assert!(inside
                .iter()
                .all(|&k| (rs[k] - 1.0).abs() < 1e-6 && (rt[k] - 1.0).abs() < 1e-6));
        } else if f == 6 {
            let max = inside.iter().map(|&k| rs[k] as f64).fold(0.0, f64::max);
            assert!(
                max > 1.0 + 0.5 * (hi - 1.0),
                "frame 6 reaches {max} of {hi}"
            );
        }
    }
}
