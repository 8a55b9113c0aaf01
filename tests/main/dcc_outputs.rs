//! Outputs as the tools users open them in read them: 16-bit PNG height
//! sequences on one fixed scale (Blender, Houdini and Maya ignore the scale
//! metadata) and the surface strain as float EXR data.

use std::path::Path;

use crate::common;

use skinpatch::micro::io::{read_map, MapDefaults, TexelSize};

use crate::common::text;

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
        let data = skinpatch::export::strain_images::read_strain_data(&path).unwrap();
        assert_eq!((data.width, data.height), (96, 96));
        let channel = |name: &str| data.channel(name).unwrap().to_vec();
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

/// The JSON chunk and the binary chunk of a GLB file.
fn glb_chunks(bytes: &[u8]) -> (serde_json::Value, Vec<u8>) {
    let word = |at: usize| u32::from_le_bytes(bytes[at..at + 4].try_into().unwrap()) as usize;
    assert_eq!(&bytes[..4], b"glTF");
    let json_len = word(12);
    let json = serde_json::from_slice(&bytes[20..20 + json_len]).unwrap();
    let bin_at = 20 + json_len;
    (json, bytes[bin_at + 8..bin_at + 8 + word(bin_at)].to_vec())
}

/// The floats of accessor `index`, in groups of three.
fn vec3s(json: &serde_json::Value, bin: &[u8], index: usize) -> Vec<[f32; 3]> {
    let accessor = &json["accessors"][index];
    assert_eq!(accessor["type"], "VEC3");
    let view = &json["bufferViews"][accessor["bufferView"].as_u64().unwrap() as usize];
    let offset = view["byteOffset"].as_u64().unwrap() as usize;
    let count = accessor["count"].as_u64().unwrap() as usize;
    bin[offset..offset + 12 * count]
        .chunks_exact(12)
        .map(|c| [0, 4, 8].map(|k| f32::from_le_bytes(c[k..k + 4].try_into().unwrap())))
        .collect()
}

/// `surface.glb` as Blender and the Khronos validator read it: +y up (the
/// patch lies in glTF's x–z plane and its normals point up), unit normals
/// with per-frame normal targets, a material whose normal texture is the
/// run's neutral normal map, the frame rate stated; 0 errors and 0 warnings
/// from the Khronos glTF validator, and pygltflib reads the same.
#[test]
fn surface_glb_is_y_up_with_normals_and_validates() {
    let dir = tempfile::tempdir().unwrap();
    let (out, o) = common::run_press_small_configured(
        dir.path(),
        "\n[output]\nframes_vtu = false\nsurface_glb = true\n\
         [microstructure]\nformats = [\"png16\"]\nframe_stride = 6\n\
         [microstructure.procedural]\nsize_px = 64\n",
        |_| {},
    );
    assert!(o.status.success(), "stderr: {}", text(&o.stderr));
    let glb = out.join("surface.glb");
    let (json, bin) = glb_chunks(&std::fs::read(&glb).unwrap());
    let primitive = &json["meshes"][0]["primitives"][0];
    let positions = vec3s(
        &json,
        &bin,
        primitive["attributes"]["POSITION"].as_u64().unwrap() as usize,
    );
    let normals = vec3s(
        &json,
        &bin,
        primitive["attributes"]["NORMAL"].as_u64().unwrap() as usize,
    );
    assert_eq!(positions.len(), normals.len());
    let extent = |c: usize| {
        let (lo, hi) = positions.iter().fold((f32::MAX, f32::MIN), |(lo, hi), p| {
            (lo.min(p[c]), hi.max(p[c]))
        });
        hi - lo
    };
    // patch_3k's top is 10 × 10 mm and flat at rest.
    assert!((extent(0) - 0.01).abs() < 1e-5 && (extent(2) - 0.01).abs() < 1e-5);
    assert!(extent(1) < 1e-7, "the rest top is flat in y: {}", extent(1));
    for n in &normals {
        let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
        assert!((len - 1.0).abs() < 1e-5 && n[1] > 0.999, "{n:?}");
    }
    // Tangents along u (+x) with the bitangent up the image (+v, skinpatch
    // +y, glTF −z): w = +1.
    let accessor = primitive["attributes"]["TANGENT"].as_u64().unwrap() as usize;
    let view =
        &json["bufferViews"][json["accessors"][accessor]["bufferView"].as_u64().unwrap() as usize];
    let offset = view["byteOffset"].as_u64().unwrap() as usize;
    let rest_tangents: Vec<[f32; 4]> = bin[offset..offset + 16 * positions.len()]
        .chunks_exact(16)
        .map(|t| [0, 4, 8, 12].map(|k| f32::from_le_bytes(t[k..k + 4].try_into().unwrap())))
        .collect();
    for t in &rest_tangents {
        assert!((t[0] - 1.0).abs() < 1e-5 && t[3] == 1.0, "{t:?}");
    }
    let targets = primitive["targets"].as_array().unwrap();
    assert_eq!(targets.len(), 7);
    // The pressed frame's normals tilt around the probe.
    let last = &targets[6];
    let turned = vec3s(&json, &bin, last["NORMAL"].as_u64().unwrap() as usize);
    let tilt = turned
        .iter()
        .map(|d| d[0].abs().max(d[2].abs()))
        .fold(0.0, f32::max);
    assert!(tilt > 0.05, "{tilt}");
    // Its tangents turn with the skin: rest + delta is a unit vector in the
    // deformed tangent plane (rest + delta of the normal).
    let swung = vec3s(&json, &bin, last["TANGENT"].as_u64().unwrap() as usize);
    let mut largest = 0.0f32;
    for (k, d) in swung.iter().enumerate() {
        let t: [f32; 3] = std::array::from_fn(|i| rest_tangents[k][i] + d[i]);
        let n: [f32; 3] = std::array::from_fn(|i| normals[k][i] + turned[k][i]);
        let dot = |a: &[f32; 3], b: &[f32; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
        assert!(
            (dot(&t, &t).sqrt() - 1.0).abs() < 1e-5,
            "tangent {k}: {t:?}"
        );
        assert!(
            dot(&t, &n).abs() < 1e-5,
            "tangent {k} off the plane: {t:?} · {n:?}"
        );
        largest = largest.max(d.iter().fold(0.0, |m: f32, c| m.max(c.abs())));
    }
    assert!(
        largest > 0.02,
        "the tangents turn under the probe: {largest}"
    );
    let moved = vec3s(&json, &bin, last["POSITION"].as_u64().unwrap() as usize);
    let deepest = moved.iter().map(|d| d[1]).fold(0.0, f32::min);
    assert!(deepest < -4e-4, "the probe presses down (−y): {deepest} m");
    assert_eq!(json["images"][0]["uri"], "micro/normal_neutral.png");
    assert!(out.join("micro/normal_neutral.png").exists());
    assert_eq!(json["materials"][0]["normalTexture"]["index"], 0);
    assert_eq!(json["asset"]["extras"]["frame_rate_hz"], 6.0);

    // The Khronos validator (npm `gltf-validator`, through NODE_PATH).
    let required = std::env::var("SKINPATCH_REQUIRE_GLTF_VALIDATOR").is_ok_and(|v| v == "1");
    let script = common::root().join("tests/gltf/validate.js");
    match std::process::Command::new("node")
        .arg(&script)
        .arg(&glb)
        .output()
    {
        Ok(o) if o.status.success() => {
            let report: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
            let issues = &report["issues"];
            assert_eq!(issues["numErrors"], 0, "{issues:#}");
            assert_eq!(issues["numWarnings"], 0, "{issues:#}");
        }
        other => {
            let why = match other {
                Ok(o) => text(&o.stderr),
                Err(e) => format!("node does not run: {e}"),
            };
            assert!(!required, "glTF validator required: {why}");
            crate::common::skip(&format!(
                "glTF validator ({why}; set SKINPATCH_REQUIRE_GLTF_VALIDATOR=1 to fail)"
            ));
        }
    }
    // An independent reader.
    let script = r#"
import sys
from pygltflib import GLTF2
g = GLTF2().load(sys.argv[1])
p = g.meshes[0].primitives[0]
assert p.attributes.NORMAL is not None and p.attributes.TEXCOORD_0 is not None
a = g.accessors[p.attributes.POSITION]
span = [hi - lo for lo, hi in zip(a.min, a.max)]
assert span[1] < 1e-7 < span[0] and span[2] > 1e-3, span
assert g.materials[0].normalTexture.index == 0
print(len(p.targets), g.animations[0].samplers[0].interpolation)
"#;
    if let Some(out) = common::python_check(
        "pygltflib",
        "SKINPATCH_REQUIRE_PYGLTFLIB",
        script,
        &[glb.to_str().unwrap()],
    ) {
        assert_eq!(out.trim(), "7 STEP");
    }
}
