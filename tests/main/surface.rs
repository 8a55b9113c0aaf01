//! Animated surfaces from other tools (Nagano et al. 2015 §5): round trips of the FEM
//! top surface through glTF and OBJ, analytic deformations on curved
//! surfaces with UV seams and mirrored charts, UDIM and wrapping layouts,
//! GPU parity and bad input.

use crate::common;

use std::path::{Path, PathBuf};

use skinpatch::mesh::Vec3;
use skinpatch::micro::io::{MapDefaults, TexelSize};
use skinpatch::micro::map::Edge;
use skinpatch::scenario::{Setup, SurfaceSetup};
use skinpatch::strain::{StrainRaster, SurfaceField, Svd2};
use skinpatch::surface::{AnimatedSurface, UvLayout};

fn read_map(path: &Path) -> skinpatch::micro::DisplacementMap {
    let defaults = MapDefaults {
        texel: TexelSize::Required("test"),
        height_unit_um: 1.0,
        edge: Edge::Wrap,
    };
    skinpatch::micro::io::read_map(path, &defaults).unwrap()
}

pub(crate) fn temp(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("skinpatch-surface-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// (r_s, r_t) at every inside texel of a `px`² raster of `field`.
fn raster_stretch(field: &SurfaceField, px: usize) -> Vec<Option<(f64, f64)>> {
    let raster = StrainRaster::new(field, px, px);
    (0..px * px)
        .map(|i| {
            raster.inside[i].then(|| {
                let svd = Svd2::of(&raster.t[i]);
                (svd.rs, svd.rt)
            })
        })
        .collect()
}

/// The small press-and-drag fixture with its mesh path made absolute.
fn press_scenario() -> String {
    let root = common::root();
    std::fs::read_to_string(root.join("tests/fixtures/press_small.toml"))
        .unwrap()
        .replace(
            "\"../../meshes/patch_3k.node\"",
            &format!("\"{}\"", root.join("meshes/patch_3k.node").display()),
        )
}

const MICRO: &str = r#"
[microstructure]
formats = ["exr"]
[microstructure.procedural]
size_px = 192
"#;

/// The FEM patch's top surface exported as glTF and as an OBJ sequence and
/// read back as animated surfaces gives the FEM run's strain maps and
/// deformed microstructure.
#[test]
fn fem_top_surface_round_trips_through_gltf_and_obj() {
    let dir = temp("roundtrip");
    let fem_toml = format!(
        "{}\n[output]\ndir = \"{}\"\nsurface_glb = true\nsurface_obj = true\nframes_vtu = false\nmesh_vtu = false\n{MICRO}",
        press_scenario(),
        dir.join("fem").display()
    );
    std::fs::write(dir.join("fem.toml"), fem_toml).unwrap();
    let setup = Setup::load(&dir.join("fem.toml")).unwrap();
    let px = 160;
    let mut fem_maps = Vec::new();
    skinpatch::pipeline::run(&setup, |frame| {
        fem_maps.push(raster_stretch(frame.surface, px))
    })
    .unwrap();
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for (rs, rt) in fem_maps.iter().flatten().flatten() {
        lo = lo.min(rs.min(*rt));
        hi = hi.max(rs.max(*rt));
    }
    let range = hi - lo;
    assert!(
        range > 0.05,
        "the press strains the skin: r in [{lo}, {hi}]"
    );
    let neutral = read_map(&dir.join("fem/micro/height_neutral.exr"));
    for (format, file, units) in [
        ("glb", "fem/surface.glb", ""),
        ("obj", "fem/surface/frame_%04d.obj", "units = \"mm\"\n"),
    ] {
        let toml = format!(
            "[surface]\nfile = \"{file}\"\n{units}frame_rate_hz = 6.0\n[output]\ndir = \"{}\"\nmesh_vtu = false\n{MICRO}",
            dir.join(format).display()
        );
        let path = dir.join(format!("{format}.toml"));
        std::fs::write(&path, toml).unwrap();
        let setup = SurfaceSetup::load(&path).unwrap();
        assert_eq!(setup.surface.num_frames(), fem_maps.len(), "{format}");
        let mut worst: f64 = 0.0;
        let mut frame = 0;
        skinpatch::pipeline::surface::run(&setup, |f| {
            let maps = raster_stretch(f.field, px);
            for (a, b) in maps.iter().zip(&fem_maps[frame]) {
                match (a, b) {
                    (Some(a), Some(b)) => {
                        worst = worst.max((a.0 - b.0).abs()).max((a.1 - b.1).abs())
                    }
                    (None, None) => {}
                    _ => panic!("{format}: the rasters cover different texels"),
                }
            }
            frame += 1;
        })
        .unwrap();
        let strain = worst / range;
        let mut micro: f64 = 0.0;
        for f in 0..fem_maps.len() {
            let name = format!("micro/height_{f:04}.exr");
            let a = read_map(&dir.join("fem").join(&name));
            let b = read_map(&dir.join(format).join(&name));
            assert_eq!((a.width, a.height), (neutral.width, neutral.height));
            micro = micro.max(a.max_difference(&b));
        }
        eprintln!(
            "{format}: strain maps within {strain:.2e} of the r range, deformed maps within \
             {micro:.2e} of the height range"
        );
        assert!(strain <= 1e-6, "{format}: strain {strain:e}");
        assert!(micro <= 1e-6, "{format}: microstructure {micro:e}");
    }
    std::fs::remove_dir_all(&dir).ok();
}

/// A 90° cylinder patch (radius 5 mm, 8 mm long) in two UV charts: the
/// first θ → u, z → v; the second swapped (z → u, θ → v: rotated and
/// mirrored), meeting along θ = 45° where the positions are shared and the
/// UVs are not. Frames: rest, stretched by `a` along the axis, and the
/// same stretch followed by a rigid rotation.
fn cylinder(a: f64, shift_second: [f64; 2], shift_first: [f64; 2]) -> AnimatedSurface {
    let (radius, length, n_theta, n_z) = (5.0, 8.0, 12, 10);
    let theta_max = std::f64::consts::FRAC_PI_2;
    let rotation = nalgebra::Rotation3::from_euler_angles(0.3, -0.2, 0.7);
    let (mut rest, mut uvs, mut triangles) = (Vec::new(), Vec::new(), Vec::new());
    let half = n_theta / 2;
    for chart in 0..2 {
        let base = rest.len();
        let thetas: Vec<usize> = if chart == 0 {
            (0..=half).collect()
        } else {
            (half..=n_theta).collect()
        };
        for j in 0..=n_z {
            for &i in &thetas {
                let theta = theta_max * i as f64 / n_theta as f64;
                let z = length * j as f64 / n_z as f64;
                rest.push(Vec3::new(radius * theta.cos(), radius * theta.sin(), z));
                let t = (i - thetas[0]) as f64 / half as f64;
                let s = j as f64 / n_z as f64;
                uvs.push(if chart == 0 {
                    [
                        0.05 + 0.4 * t + shift_first[0],
                        0.05 + 0.9 * s + shift_first[1],
                    ]
                } else {
                    [
                        0.55 + 0.4 * s + shift_second[0],
                        0.05 + 0.9 * t + shift_second[1],
                    ]
                });
            }
        }
        let row = thetas.len();
        for j in 0..n_z {
            for i in 0..row - 1 {
                let v = |di: usize, dj: usize| base + (j + dj) * row + i + di;
                triangles.push([v(0, 0), v(1, 0), v(1, 1)]);
                triangles.push([v(0, 0), v(1, 1), v(0, 1)]);
            }
        }
    }
    let stretched: Vec<Vec3> = rest.iter().map(|p| Vec3::new(p.x, p.y, a * p.z)).collect();
    let turned = stretched.iter().map(|p| rotation * p).collect();
    AnimatedSurface::from_vertices(
        "cylinder",
        rest.clone(),
        uvs,
        triangles,
        vec![rest, stretched, turned],
        24.0,
    )
    .unwrap()
}

#[test]
fn cylinder_stretched_along_its_axis_is_exact_across_seams_and_mirrored_charts() {
    let a = 1.2;
    let s = cylinder(a, [0.0, 0.0], [0.0, 0.0]);
    // Positions along the seam are shared: 11 × 13 positions, 11 × 14 surface vertices.
    assert_eq!(s.positions.len(), 11 * 13);
    assert_eq!(s.top.vertices.len(), 11 * 14);
    let rotation = nalgebra::Rotation3::from_euler_angles(0.3, -0.2, 0.7);
    let mut worst: f64 = 0.0;
    for (f, x) in s.frames.iter().enumerate().skip(1) {
        let field = SurfaceField::new(&s.top, &s.positions, x);
        assert_eq!(field.degenerate_triangles, 0);
        let axis = if f == 1 {
            Vec3::z()
        } else {
            rotation * Vec3::z()
        };
        for (k, v) in field.vertices.iter().enumerate() {
            let st = v.strain();
            worst = worst.max((st.rs() - a).abs()).max((st.rt() - 1.0).abs());
            // The s axis: v in the first chart, u in the swapped one.
            let first_chart = k < 11 * 7;
            let s_uv = st.s_uv();
            let along = if first_chart {
                s_uv.y.abs()
            } else {
                s_uv.x.abs()
            };
            worst = worst.max((along - 1.0).abs());
            let deformed = v.deformed_axes()[0];
            worst = worst.max((deformed.dot(&axis).abs() - 1.0).abs());
        }
        // And at every texel inside the charts.
        for (rs, rt) in raster_stretch(&field, 96).into_iter().flatten() {
            worst = worst.max((rs - a).abs()).max((rt - 1.0).abs());
        }
    }
    eprintln!("cylinder: r_s, r_t and axes within {worst:.1e}");
    assert!(worst < 1e-12, "{worst:e}");

    // Averaging across the seam would mix the charts' frames (T = diag(1, a)
    // in one, diag(a, 1) in the other): the same surface welded into one
    // chart-less vertex set must not be what we compute.
    let mixed = {
        let t1 = nalgebra::Matrix2::new(1.0, 0.0, 0.0, a);
        let t2 = nalgebra::Matrix2::new(a, 0.0, 0.0, 1.0);
        Svd2::of(&((t1 + t2) * 0.5))
    };
    assert!(
        (mixed.rs - a).abs() > 0.05,
        "the test can tell mixed charts apart"
    );
}

#[test]
fn sphere_cap_scaled_tangentially_with_a_mirrored_half() {
    let (rho, k, n) = (6.0, 1.1, 16);
    let (mut rest, mut uvs, mut triangles) = (Vec::new(), Vec::new(), Vec::new());
    for half in 0..2 {
        let base = rest.len();
        let cols: Vec<usize> = if half == 0 {
            (0..=n / 2).collect()
        } else {
            (n / 2..=n).collect()
        };
        for j in 0..=n {
            for &i in &cols {
                let (u, v) = (
                    0.1 + 0.8 * i as f64 / n as f64,
                    0.1 + 0.8 * j as f64 / n as f64,
                );
                let (x, y) = ((u - 0.5) * 6.0, (v - 0.5) * 6.0);
                rest.push(Vec3::new(x, y, (rho * rho - x * x - y * y).sqrt()));
                // The second half mirrored in u.
                uvs.push(if half == 0 { [u, v] } else { [1.4 - u, v] });
            }
        }
        let row = cols.len();
        for j in 0..n {
            for i in 0..row - 1 {
                let v = |di: usize, dj: usize| base + (j + dj) * row + i + di;
                triangles.push([v(0, 0), v(1, 0), v(1, 1)]);
                triangles.push([v(0, 0), v(1, 1), v(0, 1)]);
            }
        }
    }
    let scaled = rest.iter().map(|p| p * k).collect();
    let s = AnimatedSurface::from_vertices("cap", rest.clone(), uvs, triangles, vec![scaled], 30.0)
        .unwrap();
    let field = SurfaceField::new(&s.top, &s.positions, &s.frames[0]);
    let mut worst: f64 = 0.0;
    for v in &field.vertices {
        let st = v.strain();
        worst = worst.max((st.rs() - k).abs()).max((st.rt() - k).abs());
    }
    for (rs, rt) in raster_stretch(&field, 64).into_iter().flatten() {
        worst = worst.max((rs - k).abs()).max((rt - k).abs());
    }
    eprintln!("sphere cap: r_s = r_t = {k} within {worst:.1e}");
    assert!(worst < 1e-12, "{worst:e}");
}

#[test]
fn udim_tiles_and_wrapped_uvs_raster_each_chart() {
    let a = 1.3;
    // The second chart in UDIM tile 1002 (u + 1).
    let s = cylinder(a, [1.0, 0.0], [0.0, 0.0]);
    assert!(s.pieces(UvLayout::Unit).is_err());
    let pieces = s.pieces(UvLayout::Udim).unwrap();
    assert_eq!(
        pieces.iter().map(|p| p.udim).collect::<Vec<_>>(),
        vec![Some(1001), Some(1002)]
    );
    let field = SurfaceField::new(&s.top, &s.positions, &s.frames[1]);
    for piece in &pieces {
        let view = field.view(&piece.triangles);
        let texels: Vec<(f64, f64)> = raster_stretch(&view, 64).into_iter().flatten().collect();
        assert!(
            texels.len() > 64 * 64 / 4,
            "tile {:?}: {} texels",
            piece.udim,
            texels.len()
        );
        for (rs, rt) in texels {
            assert!((rs - a).abs() < 1e-12 && (rt - 1.0).abs() < 1e-12);
        }
    }
    // The first chart across u = 1 (u in 0.75 … 1.15) on a wrapping map:
    // texels on both sides of the edge are covered.
    let s = cylinder(a, [0.0, 0.0], [0.7, 0.0]);
    let pieces = s.pieces(UvLayout::Wrap).unwrap();
    let field = SurfaceField::new(&s.top, &s.positions, &s.frames[1]);
    let view = field.view(&pieces[0].triangles);
    let raster = raster_stretch(&view, 100);
    let at = |u: f64, v: f64| raster[(v * 100.0) as usize * 100 + (u * 100.0) as usize];
    for (u, v) in [(0.05, 0.5), (0.9, 0.5), (0.7, 0.5)] {
        let (rs, rt) = at(u, v).unwrap_or_else(|| panic!("({u}, {v}) is covered"));
        assert!((rs - a).abs() < 1e-12 && (rt - 1.0).abs() < 1e-12);
    }
    assert!(
        at(0.3, 0.5).is_none(),
        "between the charts nothing is drawn"
    );
}

/// The GPU chain on a surface with seams and a mirrored chart equals the
/// CPU reference.
#[test]
fn gpu_chain_on_seamed_mirrored_surface_matches_cpu() {
    let Some(ctx) = common::context() else { return };
    let s = cylinder(1.25, [0.0, 0.0], [0.0, 0.0]);
    let field = SurfaceField::new(&s.top, &s.positions, &s.frames[2]);
    let params = skinpatch::micro::procedural::SkinParams {
        size_px: 256,
        extent_mm: s.mm_per_uv(),
        ..Default::default()
    };
    let neutral = skinpatch::micro::procedural::generate(&params).unwrap();
    let model = skinpatch::micro::kernel::KernelModel::forehead();
    let cpu = skinpatch::micro::convolve::deform(&neutral, &model, &field);
    let mut chain = skinpatch::gpu::micro::GpuMicro::new(
        ctx,
        &neutral,
        &model,
        skinpatch::strain::raster::DILATE_TEXELS,
    )
    .unwrap();
    let gpu = chain.deform(&field, false).unwrap();
    let d = cpu.max_difference(&gpu.map);
    eprintln!("seamed cylinder: GPU − CPU ≤ {d:.2e} of the height range");
    assert!(d < 1e-4, "{d:e}");
    assert!(
        neutral.max_difference(&cpu) > 0.02,
        "the surface is deformed"
    );
}

pub(crate) fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
    let path = dir.join(name);
    std::fs::write(&path, text).unwrap();
    path
}

pub(crate) fn read_error(path: &Path, units: Option<f64>) -> String {
    let options = skinpatch::surface::ReadOptions {
        mm_per_unit: units,
        ..Default::default()
    };
    AnimatedSurface::read(path, &options)
        .unwrap_err()
        .to_string()
}

const QUAD: &str = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\n";

#[test]
fn bad_obj_input_names_file_and_element() {
    let dir = temp("badobj");
    // Missing UVs.
    let path = write(
        &dir,
        "nouv.obj",
        "o Face\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n",
    );
    let e = read_error(&path, Some(1.0));
    assert!(
        e.contains("nouv.obj") && e.contains("'Face'") && e.contains("texture"),
        "{e}"
    );
    // No unit for an OBJ.
    let e = read_error(&path, None);
    assert!(e.contains("surface.units"), "{e}");
    // NaN position.
    let path = write(
        &dir,
        "nan.obj",
        &format!("{QUAD}v nan 0 0\nvt 0.5 0.5\nf 1/1 2/2 3/3\nf 1/1 3/3 5/5\n"),
    );
    let e = read_error(&path, Some(1.0));
    assert!(
        e.contains("nan.obj") && e.contains("non-finite position"),
        "{e}"
    );
    // A coordinate of 1e308 (once counted as degenerate triangles).
    let path = write(
        &dir,
        "huge.obj",
        &format!("{QUAD}v 1e308 0 0\nvt 0.5 0.5\nf 1/1 2/2 3/3\nf 1/1 3/3 5/5\n"),
    );
    let e = read_error(&path, Some(1.0));
    assert!(
        e.contains("huge.obj") && e.contains("a position beyond ±1e6 mm"),
        "{e}"
    );
    // Unparsable number: the line is named.
    let path = write(
        &dir,
        "syntax.obj",
        "v 0 0 0\nv 1 x 0\nv 0 1 0\nvt 0 0\nf 1/1 2/1 3/1\n",
    );
    let e = read_error(&path, Some(1.0));
    assert!(e.contains("syntax.obj:2"), "{e}");
    // Topology change between frames.
    let seq = dir.join("seq");
    std::fs::create_dir_all(&seq).unwrap();
    let square = format!("{QUAD}f 1/1 2/2 3/3\nf 1/1 3/3 4/4\n");
    let flipped = format!("{QUAD}f 1/1 2/2 4/4\nf 2/2 3/3 4/4\n");
    for (k, text) in [(1, &square), (2, &square), (3, &flipped)] {
        write(&seq, &format!("f_{k:04}.obj"), text);
    }
    let e = read_error(&seq.join("f_%04d.obj"), Some(1.0));
    assert!(
        e.contains("f_0003.obj") && e.contains("triangle 1") && e.contains("topology"),
        "{e}"
    );
    // A gap in the sequence.
    std::fs::remove_file(seq.join("f_0002.obj")).unwrap();
    let e = read_error(&seq.join("f_%04d.obj"), Some(1.0));
    assert!(e.contains("f_0002.obj"), "{e}");
    // A good sequence reads, with its frames in order.
    let moved = square.replace("v 1 1 0", "v 1 1.5 0");
    for (k, text) in [(2, &square), (3, &moved)] {
        write(&seq, &format!("f_{k:04}.obj"), text);
    }
    let options = skinpatch::surface::ReadOptions {
        mm_per_unit: Some(10.0),
        frame_rate_hz: 12.0,
        ..Default::default()
    };
    let s = AnimatedSurface::read(&seq.join("f_%04d.obj"), &options).unwrap();
    assert_eq!(s.num_frames(), 3);
    assert_eq!(s.frames[2][2], Vec3::new(10.0, 15.0, 0.0));
    assert!((s.time(2) - 1.0 / 6.0).abs() < 1e-15);
    std::fs::remove_dir_all(&dir).ok();
}

/// A glTF with one triangle, `targets` morph targets and a weight
/// animation with `values` outputs over two keyframes, buffers embedded as
/// a data URI; `uv` says whether it has TEXCOORD_0.
pub(crate) fn tiny_gltf(targets: usize, values: usize, uv: bool, x0: f32) -> String {
    let mut b = GltfBuffers::default();
    let pos = b.f32s(&[x0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0], 3, "VEC3");
    b.bounds(pos, "[0,0,0]", "[1,1,0]");
    let tex = b.f32s(&[0.0, 1.0, 1.0, 1.0, 0.0, 0.0], 2, "VEC2");
    let delta = b.f32s(&[0.0, 0.0, 0.0, 0.5, 0.0, 0.0, 0.0, 0.0, 0.0], 3, "VEC3");
    b.bounds(delta, "[0,0,0]", "[0.5,0,0]");
    let times = b.f32s(&[0.0, 1.0], 1, "SCALAR");
    let weights: Vec<f32> = (0..values).map(|i| (i % 2) as f32).collect();
    let out = b.f32s(&weights, 1, "SCALAR");
    let targets_json = vec![format!("{{\"POSITION\":{delta}}}"); targets].join(",");
    let attributes = if uv {
        format!("\"POSITION\":{pos},\"TEXCOORD_0\":{tex}")
    } else {
        format!("\"POSITION\":{pos}")
    };
    format!(
        r#"{{"asset":{{"version":"2.0"}},"scene":0,"scenes":[{{"nodes":[0]}}],
"nodes":[{{"name":"Face","mesh":0}}],
"meshes":[{{"name":"FaceMesh","primitives":[{{"attributes":{{{attributes}}},"targets":[{targets_json}]}}]}}],
"animations":[{{"name":"smile","samplers":[{{"input":{times},"output":{out},"interpolation":"LINEAR"}}],"channels":[{{"sampler":0,"target":{{"node":0,"path":"weights"}}}}]}}],
{}}}"#,
        b.json()
    )
}

#[test]
fn gltf_input_is_read_and_bad_gltf_is_named() {
    let dir = temp("gltf");
    // One target, linear weights 0 → 1 over 1 s, sampled at 4 Hz: 5 frames,
    // vertex 1 moving 0.5 m along x (500 mm) in steps of 125 mm.
    let path = write(&dir, "good.gltf", &tiny_gltf(1, 2, true, 0.0));
    let options = skinpatch::surface::ReadOptions {
        frame_rate_hz: 4.0,
        ..Default::default()
    };
    let s = AnimatedSurface::read(&path, &options).unwrap();
    assert_eq!(s.num_frames(), 5);
    for f in 0..5 {
        assert!(
            (s.frames[f][1].x - (1000.0 + 125.0 * f as f64)).abs() < 1e-9,
            "{f}"
        );
    }
    // glTF's v runs down: v = 1 − v_glTF.
    assert_eq!(s.top.uvs[0], [0.0, 0.0]);
    // The uniaxial stretch of the last frame: r_s = 1.5.
    let field = SurfaceField::new(&s.top, &s.positions, &s.frames[4]);
    assert!((field.triangles[0].t.determinant() - 1.5).abs() < 1e-12);

    let e = read_error(
        &write(&dir, "nouv.gltf", &tiny_gltf(1, 2, false, 0.0)),
        None,
    );
    assert!(
        e.contains("nouv.gltf") && e.contains("FaceMesh") && e.contains("TEXCOORD_0"),
        "{e}"
    );
    let e = read_error(
        &write(&dir, "count.gltf", &tiny_gltf(1, 3, true, 0.0)),
        None,
    );
    assert!(
        e.contains("count.gltf") && e.contains("morph target count mismatch"),
        "{e}"
    );
    let e = read_error(
        &write(&dir, "nan.gltf", &tiny_gltf(1, 2, true, f32::NAN)),
        None,
    );
    assert!(
        e.contains("nan.gltf") && e.contains("primitive 0 vertex 0") && e.contains("non-finite"),
        "{e}"
    );
    let e = read_error(&write(&dir, "broken.gltf", "{\"asset\": "), None);
    assert!(e.contains("broken.gltf") && e.contains("glTF"), "{e}");
    let options = skinpatch::surface::ReadOptions {
        node: Some("Nose".into()),
        ..Default::default()
    };
    let e = AnimatedSurface::read(&path, &options)
        .unwrap_err()
        .to_string();
    assert!(e.contains("'Nose'") && e.contains("'Face'"), "{e}");
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn surface_scenarios_refuse_fem_sections_and_bad_keys() {
    let dir = temp("scenario");
    let obj = write(
        &dir,
        "quad.obj",
        &format!("{QUAD}f 1/1 2/2 3/3\nf 1/1 3/3 4/4\n"),
    );
    let load = |extra: &str| {
        let path = write(
            &dir,
            "s.toml",
            &format!("[surface]\nfile = \"{}\"\n{extra}", obj.display()),
        );
        SurfaceSetup::load(&path)
            .map(|_| ())
            .map_err(|e| e.to_string())
    };
    load("units = \"mm\"\n").unwrap();
    let e = load("").unwrap_err();
    assert!(e.contains("surface.units"), "{e}");
    let e = load("units = \"mm\"\n[probe]\nshape = \"sphere\"\nradius_mm = 1.0\npath_mm = [[0.0, 0.0, 0.0, 1.0]]\n").unwrap_err();
    assert!(e.contains("probe") && e.contains("[surface]"), "{e}");
    // FEM sections are refused even when they hold only their defaults.
    for (section, text) in [
        ("time", "[time]\nframe_rate_hz = 60.0\n"),
        ("solver", "[solver]\nlinear = \"two-level\"\n"),
        ("boundary", "[boundary]\nbottom = \"fixed\"\n"),
        ("time", "[time]\n"),
    ] {
        let e = load(&format!("units = \"mm\"\n{text}")).unwrap_err();
        assert!(
            e.starts_with(&format!("{section} has no meaning beside [surface]")),
            "{section}: {e}"
        );
    }
    let e = load("units = \"mm\"\nuv_layout = \"tiles\"\n").unwrap_err();
    assert!(e.contains("surface.uv_layout"), "{e}");
    let e = load("units = \"mm\"\nframe_rate_hz = -3\n").unwrap_err();
    assert!(e.contains("surface.frame_rate_hz"), "{e}");
    let e = load("units = \"furlong\"\n").unwrap_err();
    assert!(
        e.contains("surface.units must be \"mm\", \"cm\", \"m\" or \"in\", got \"furlong\""),
        "{e}"
    );
    let e = load("units = \"mm\"\nnod = \"x\"\n").unwrap_err();
    assert!(e.contains("surface.nod") && e.contains("node"), "{e}");
    let e = load("units = \"mm\"\nnode = \"x\"\n").unwrap_err();
    assert!(e.contains("surface.node") && e.contains("glTF"), "{e}");
    std::fs::remove_dir_all(&dir).ok();
}

/// `examples/surfaces/forehead.glb`: a 12 × 10 mm forehead patch (curved
/// with radii 60 and 90 mm) with two shape keys — `brow_raise` (the lower
/// forehead pushed up, compressing it vertically by up to 24%) and `frown`
/// (skin between the brows pulled towards the centre line, compressed
/// there and stretched beside it) — animated over 2 s.
fn forehead() -> (AnimatedSurface, skinpatch::surface::gltf::MorphAnimation) {
    let (nx, ny) = (48usize, 40usize);
    let (mut rest, mut uvs, mut triangles) = (Vec::new(), Vec::new(), Vec::new());
    for j in 0..=ny {
        for i in 0..=nx {
            let (x, y) = (
                -6.0 + 12.0 * i as f64 / nx as f64,
                -5.0 + 10.0 * j as f64 / ny as f64,
            );
            rest.push(Vec3::new(x, y, -x * x / 120.0 - y * y / 180.0));
            uvs.push([(x + 6.0) / 12.0, (y + 6.0) / 12.0]);
        }
    }
    for j in 0..ny {
        for i in 0..nx {
            let v = |di: usize, dj: usize| (j + dj) * (nx + 1) + i + di;
            triangles.push([v(0, 0), v(1, 0), v(1, 1)]);
            triangles.push([v(0, 0), v(1, 1), v(0, 1)]);
        }
    }
    let brow: Vec<Vec3> = rest
        .iter()
        .map(|p| {
            let b = ((5.0 - p.y) / 10.0).powi(2) * (-(p.x / 8.0).powi(2)).exp();
            Vec3::new(0.0, 1.2 * b, 0.1 * b)
        })
        .collect();
    let frown: Vec<Vec3> = rest
        .iter()
        .map(|p| {
            let h = (-((p.y + 2.0) / 3.0).powi(2)).exp();
            Vec3::new(-0.8 / 6.0 * p.x * (-(p.x * p.x) / 9.0).exp() * h, 0.0, 0.0)
        })
        .collect();
    let surface =
        AnimatedSurface::from_vertices("forehead", rest.clone(), uvs, triangles, vec![rest], 12.0)
            .unwrap();
    let animation = skinpatch::surface::gltf::MorphAnimation {
        names: vec!["brow_raise".into(), "frown".into()],
        targets: vec![brow, frown],
        times_s: vec![0.0, 0.5, 1.0, 1.5, 2.0],
        weights: vec![
            vec![0.0, 0.0],
            vec![1.0, 0.0],
            vec![1.0, 0.8],
            vec![0.0, 0.8],
            vec![0.0, 0.0],
        ],
        linear: true,
    };
    (surface, animation)
}

/// The shipped example surface is what `forehead()` writes
/// (`SKINPATCH_REGENERATE=1` rewrites it), and reads back as 25 frames at
/// 12 Hz with the keyed shapes at the keyframes.
#[test]
fn shipped_forehead_example_is_the_generated_one() {
    let (surface, animation) = forehead();
    let shipped = common::root().join("examples/surfaces/forehead.glb");
    let dir = temp("forehead");
    let fresh = dir.join("forehead.glb");
    skinpatch::surface::gltf::write_glb_animation(&fresh, &surface, &animation, None).unwrap();
    if std::env::var("SKINPATCH_REGENERATE").as_deref() == Ok("1") {
        std::fs::copy(&fresh, &shipped).unwrap();
    }
    assert_eq!(
        std::fs::read(&fresh).unwrap(),
        std::fs::read(&shipped).unwrap(),
        "examples/surfaces/forehead.glb is stale: rerun this test with SKINPATCH_REGENERATE=1"
    );
    let options = skinpatch::surface::ReadOptions {
        frame_rate_hz: 12.0,
        ..Default::default()
    };
    let s = AnimatedSurface::read(&shipped, &options).unwrap();
    assert_eq!(s.num_frames(), 25);
    // Frame 12 (t = 1 s) is brow_raise + 0.8 frown, within f32 storage.
    let worst = (0..s.positions.len())
        .map(|v| {
            let want =
                surface.positions[v] + animation.targets[0][v] + animation.targets[1][v] * 0.8;
            (s.frames[12][v] - want).norm()
        })
        .fold(0.0, f64::max);
    assert!(worst < 1e-5, "{worst} mm");
    let field = SurfaceField::new(&s.top, &s.positions, &s.frames[12]);
    let ((_, rs_max), (rt_min, _), folded) = field.extremes();
    eprintln!("forehead at 1 s: r_s up to {rs_max:.3}, r_t down to {rt_min:.3}");
    assert!(rt_min < 0.8 && rs_max > 1.02 && folded == 0);
    std::fs::remove_dir_all(&dir).ok();
}

/// A UDIM surface run: strain maps and deformed maps per tile, tagged with
/// the tile number; the VTU frames carry the stretch per surface vertex;
/// a rerun replaces the tagged files.
#[test]
fn udim_surface_run_writes_maps_per_tile() {
    let dir = temp("udimrun");
    let s = cylinder(1.2, [1.0, 0.0], [0.0, 0.0]);
    let seq = dir.join("seq");
    std::fs::create_dir_all(&seq).unwrap();
    for f in 0..s.num_frames() {
        skinpatch::surface::obj::write_obj(&seq.join(format!("cyl_{f:03}.obj")), &s, Some(f))
            .unwrap();
    }
    let toml = format!(
        "[surface]\nfile = \"seq/cyl_%03d.obj\"\nunits = \"mm\"\nuv_layout = \"udim\"\nframe_rate_hz = 24.0\n\
         [output]\ndir = \"{}\"\nstrain_images = true\nstrain_image_px = 64\n\
         [microstructure]\nformats = [\"exr\"]\n[microstructure.procedural]\nsize_px = 512\n",
        dir.join("out").display()
    );
    let path = write(&dir, "udim.toml", &toml);
    let setup = SurfaceSetup::load(&path).unwrap();
    assert_eq!(setup.pieces.len(), 2);
    for _ in 0..2 {
        let summary = skinpatch::pipeline::surface::run(&setup, |_| {}).unwrap();
        assert_eq!(summary.frames.len(), 3);
        let m = &summary.frames[1];
        assert!(
            (m.rs_range[0] - 1.2).abs() < 1e-12 && (m.rt_range[1] - 1.0).abs() < 1e-12,
            "{m:?}"
        );
    }
    let out = dir.join("out");
    for tile in [1001, 1002] {
        for f in 0..3 {
            for file in [
                format!("strain/rs_{tile}_{f:04}.png"),
                format!("micro/height_{tile}_{f:04}.exr"),
            ] {
                assert!(out.join(&file).exists(), "{file}");
            }
        }
        // Stretched along the axis: the deformed tile differs from the neutral map.
        let neutral = read_map(&out.join("micro/height_neutral.exr"));
        let deformed = read_map(&out.join(format!("micro/height_{tile}_0001.exr")));
        let d = neutral.max_difference(&deformed);
        eprintln!("tile {tile}: deformed − neutral up to {d:.3} of the height range");
        assert!(d > 0.01, "tile {tile}");
    }
    let grid = skinpatch::mesh::io::read_vtu(&out.join("frames/frame_0001.vtu")).unwrap();
    assert_eq!(grid.triangles.len(), s.top.triangles.len());
    assert_eq!(grid.points.len(), s.top.vertices.len());
    let stretch = grid
        .point_data
        .iter()
        .find(|f| f.name == "surface_stretch")
        .unwrap();
    let skinpatch::mesh::io::Values::F64(values) = &stretch.values else {
        panic!()
    };
    assert!(values
        .chunks(2)
        .all(|r| (r[0] - 1.2).abs() < 1e-9 && (r[1] - 1.0).abs() < 1e-9));
    std::fs::remove_dir_all(&dir).ok();
}

/// The example surface renders through the skin renderer: the deformed
/// microstructure changes the dynamic frames, not the static ones' geometry.
#[test]
fn animated_gltf_surface_renders_with_dynamic_microstructure() {
    if common::context().is_none() {
        return;
    }
    let dir = temp("render");
    let glb = common::root().join("examples/surfaces/forehead.glb");
    let toml = format!(
        "[surface]\nfile = \"{}\"\nframe_rate_hz = 2.0\n[output]\ndir = \"{}\"\nframes_vtu = false\n\
         [microstructure]\nformats = []\n[microstructure.procedural]\nsize_px = 512\n\
         [render]\nwidth_px = 160\nheight_px = 100\nsupersample = 1\ntexture_px = 512\nmodes = [\"static\", \"dynamic\"]\ndifference = true\n\
         [render.camera]\neye_mm = [0.0, -11.0, 6.0]\ntarget_mm = [0.0, -1.0, -0.5]\nfov_deg = 45.0\n",
        glb.display(),
        dir.join("out").display()
    );
    let path = write(&dir, "render.toml", &toml);
    let setup = SurfaceSetup::load(&path).unwrap();
    assert_eq!(setup.surface.num_frames(), 5);
    skinpatch::pipeline::surface::run(&setup, |_| {}).unwrap();
    let out = dir.join("out/render");
    let pixels = |p: PathBuf| {
        image::open(&p)
            .unwrap_or_else(|e| panic!("{}: {e}", p.display()))
            .to_rgb8()
    };
    // Frame 2 (t = 1 s) is the most deformed: static and dynamic differ.
    let (stat, dynamic) = (
        pixels(out.join("static/frame_0002.png")),
        pixels(out.join("dynamic/frame_0002.png")),
    );
    let lit = stat
        .pixels()
        .filter(|p| p.0.iter().map(|&c| c as u32).sum::<u32>() > 120)
        .count();
    assert!(
        lit > 160 * 100 / 5,
        "the surface fills the view: {lit} lit pixels"
    );
    let changed = stat
        .pixels()
        .zip(dynamic.pixels())
        .filter(|(a, b)| a != b)
        .count();
    eprintln!("{changed} of {lit} lit pixels differ between static and dynamic");
    assert!(
        changed > lit / 20,
        "{changed} pixels differ between static and dynamic"
    );
    assert!(out.join("difference/frame_0002.png").exists());
    std::fs::remove_dir_all(&dir).ok();
}

/// Buffer views and accessors of a hand-made glTF (one embedded buffer).
#[derive(Default)]
struct GltfBuffers {
    bin: Vec<u8>,
    views: Vec<String>,
    accessors: Vec<String>,
}

impl GltfBuffers {
    fn push(&mut self, bytes: Vec<u8>, component: u32, count: usize, kind: &str) -> usize {
        while !self.bin.len().is_multiple_of(4) {
            self.bin.push(0);
        }
        self.views.push(format!(
            "{{\"buffer\":0,\"byteOffset\":{},\"byteLength\":{}}}",
            self.bin.len(),
            bytes.len()
        ));
        self.bin.extend(bytes);
        self.accessors.push(format!(
            "{{\"bufferView\":{},\"componentType\":{component},\"count\":{count},\"type\":\"{kind}\"}}",
            self.views.len() - 1
        ));
        self.accessors.len() - 1
    }

    /// Adds `min` and `max` (JSON arrays) to accessor `index` (POSITION
    /// accessors need them).
    fn bounds(&mut self, index: usize, min: &str, max: &str) {
        let acc = &mut self.accessors[index];
        acc.pop();
        acc.push_str(&format!(",\"min\":{min},\"max\":{max}}}"));
    }

    fn f32s(&mut self, v: &[f32], per: usize, kind: &str) -> usize {
        self.push(
            v.iter().flat_map(|x| x.to_le_bytes()).collect(),
            5126,
            v.len() / per,
            kind,
        )
    }

    fn json(&self) -> String {
        use base64::Engine;
        format!(
            "\"buffers\":[{{\"byteLength\":{},\"uri\":\"data:application/octet-stream;base64,{}\"}}],\
             \"bufferViews\":[{}],\"accessors\":[{}]",
            self.bin.len(),
            base64::engine::general_purpose::STANDARD.encode(&self.bin),
            self.views.join(","),
            self.accessors.join(",")
        )
    }
}

/// A strip skinned to two joints (the tip a child of the root) under an
/// armature scaled by 0.5: over 1 s the tip slides 2 armature units (1 m)
/// along the strip and the root turns 30° about z. The middle cell, 0.5 m
/// wide and weighted half to each side, is stretched to 1.0 m at 0.5 s and
/// 1.5 m at 1 s; the rest moves rigidly. The mesh node's own translation is
/// ignored, as glTF says for skinned meshes.
#[test]
fn skinned_gltf_is_posed_by_its_joints() {
    let mut b = GltfBuffers::default();
    let xs = [0.0f32, 0.5, 1.0, 1.5];
    let mut pos = Vec::new();
    let mut uv = Vec::new();
    let (mut joints, mut weights) = (Vec::new(), Vec::new());
    for y in [0.0f32, 0.5] {
        for &x in &xs {
            pos.extend([x, y, 0.0]);
            uv.extend([x / 1.5, 1.0 - y]);
            joints.extend([if x <= 0.5 { 0u16 } else { 1 }, 0, 0, 0]);
            weights.extend([1.0f32, 0.0, 0.0, 0.0]);
        }
    }
    let indices: Vec<u32> = (0..3)
        .flat_map(|i| [i, i + 1, i + 5, i, i + 5, i + 4])
        .collect();
    let position = b.f32s(&pos, 3, "VEC3");
    b.bounds(position, "[0,0,0]", "[1.5,0.5,0]");
    let texcoord = b.f32s(&uv, 2, "VEC2");
    let index = b.push(
        indices.iter().flat_map(|i| i.to_le_bytes()).collect(),
        5125,
        18,
        "SCALAR",
    );
    let joint = b.push(
        joints.iter().flat_map(|j| j.to_le_bytes()).collect(),
        5123,
        8,
        "VEC4",
    );
    let weight = b.f32s(&weights, 4, "VEC4");
    // Inverse bind matrices (column-major): S(2) and T(−2, 0, 0)·S(2).
    let ibm = b.f32s(
        &[
            2.0, 0.0, 0.0, 0.0, 0.0, 2.0, 0.0, 0.0, 0.0, 0.0, 2.0, 0.0, 0.0, 0.0, 0.0, 1.0, //
            2.0, 0.0, 0.0, 0.0, 0.0, 2.0, 0.0, 0.0, 0.0, 0.0, 2.0, 0.0, -2.0, 0.0, 0.0, 1.0,
        ],
        16,
        "MAT4",
    );
    let times = b.f32s(&[0.0, 1.0], 1, "SCALAR");
    let slide = b.f32s(&[2.0, 0.0, 0.0, 4.0, 0.0, 0.0], 3, "VEC3");
    let half = (15.0f32).to_radians();
    let turn = b.f32s(
        &[0.0, 0.0, 0.0, 1.0, 0.0, 0.0, half.sin(), half.cos()],
        4,
        "VEC4",
    );
    let json = format!(
        r#"{{"asset":{{"version":"2.0"}},"scene":0,"scenes":[{{"nodes":[0,3]}}],
"nodes":[{{"name":"Armature","scale":[0.5,0.5,0.5],"children":[1]}},{{"name":"root","children":[2]}},
{{"name":"tip","translation":[2,0,0]}},{{"name":"Strip","mesh":0,"skin":0,"translation":[100,0,0]}}],
"skins":[{{"joints":[1,2],"inverseBindMatrices":{ibm}}}],
"meshes":[{{"name":"StripMesh","primitives":[{{"attributes":{{"POSITION":{position},"TEXCOORD_0":{texcoord},"JOINTS_0":{joint},"WEIGHTS_0":{weight}}},"indices":{index}}}]}}],
"animations":[{{"name":"slide","samplers":[{{"input":{times},"output":{slide}}},{{"input":{times},"output":{turn}}}],
"channels":[{{"sampler":0,"target":{{"node":2,"path":"translation"}}}},{{"sampler":1,"target":{{"node":1,"path":"rotation"}}}}]}}],
{}}}"#,
        b.json()
    );
    let dir = temp("skin");
    let path = write(&dir, "strip.gltf", &json);
    let options = skinpatch::surface::ReadOptions {
        frame_rate_hz: 2.0,
        ..Default::default()
    };
    let s = AnimatedSurface::read(&path, &options).unwrap();
    assert_eq!(s.num_frames(), 3);
    // Rest and frame 0 are the bind pose, without the node's translation.
    assert!(
        (s.positions[3] - Vec3::new(1500.0, 0.0, 0.0)).norm() < 1e-9,
        "{:?}",
        s.positions[3]
    );
    for (f, width) in [(0, 0.5), (1, 1.0), (2, 1.5)] {
        let field = SurfaceField::new(&s.top, &s.positions, &s.frames[f]);
        for (k, t) in field.triangles.iter().enumerate() {
            let svd = Svd2::of(&t.t);
            let cell = k / 2;
            let want = if cell == 1 { width / 0.5 } else { 1.0 };
            assert!(
                (svd.rs - want).abs() < 1e-6 && (svd.rt - 1.0).abs() < 1e-6,
                "frame {f} triangle {k}: {} {}",
                svd.rs,
                svd.rt
            );
        }
    }
    // The root turned 30° about glTF's z at 1 s: the first cell's edge
    // along x points 30° up glTF's y, which is skinpatch's z.
    let e = s.frames[2][1] - s.frames[2][0];
    assert!(
        (e.z.atan2(e.x).to_degrees() - 30.0).abs() < 1e-4 && e.y.abs() < 1e-9,
        "{e:?}"
    );
    // A skinned mesh without weights is named.
    let broken = json.replace(",\"WEIGHTS_0\":", ",\"_W\":");
    let e = read_error(&write(&dir, "noweights.gltf", &broken), None);
    assert!(e.contains("StripMesh") && e.contains("WEIGHTS_0"), "{e}");
    std::fs::remove_dir_all(&dir).ok();
}

/// Two charts side by side in UV with a 0.1 gutter: the dilated raster
/// fills the gutter from the nearer chart only (the charts' T differ:
/// diag(1, a) in the first chart's frame, diag(a, 1) in the swapped one),
/// keeps every inside texel, and a triangle collapsed in UV is left out of
/// the averages without changing them.
#[test]
fn charts_dilate_into_the_gutter_without_bleeding_and_uv_slivers_get_no_weight() {
    let a = 1.2;
    let s = cylinder(a, [0.0, 0.0], [0.0, 0.0]);
    // A sliver: three positions of the first chart's bottom row (an arc in
    // space) given UVs on one line.
    let mut rest: Vec<Vec3> = s.top.vertices.iter().map(|&v| s.positions[v]).collect();
    let mut uvs = s.top.uvs.clone();
    let mut triangles = s.top.triangles.clone();
    let frames: Vec<Vec<Vec3>> = s
        .frames
        .iter()
        .map(|x| s.top.vertices.iter().map(|&v| x[v]).collect())
        .collect();
    let base = rest.len();
    for k in 0..3 {
        rest.push(rest[k]);
        uvs.push([0.05 + 0.01 * k as f64, 0.05]);
    }
    triangles.push([base, base + 1, base + 2]);
    let mut frames_sliver = frames.clone();
    for (x, original) in frames_sliver.iter_mut().zip(&frames) {
        x.extend_from_slice(&original[..3]);
    }
    let sliver =
        AnimatedSurface::from_vertices("sliver", rest, uvs, triangles, frames_sliver, 24.0)
            .unwrap();
    let field = SurfaceField::new(&sliver.top, &sliver.positions, &sliver.frames[1]);
    assert_eq!(field.degenerate_triangles, 1);
    for v in &field.vertices[..base] {
        assert!((v.strain().rs() - a).abs() < 1e-12 && (v.strain().rt() - 1.0).abs() < 1e-12);
    }

    let field = SurfaceField::new(&s.top, &s.positions, &s.frames[1]);
    let px = 100;
    let raster = StrainRaster::new(&field, px, px);
    let dilated = raster
        .clone()
        .dilated(skinpatch::strain::raster::DILATE_TEXELS);
    let (first, second) = (
        nalgebra::Matrix2::new(1.0, 0.0, 0.0, a),
        nalgebra::Matrix2::new(a, 0.0, 0.0, 1.0),
    );
    let mut gutter = 0;
    for j in 0..px {
        for i in 0..px {
            let k = j * px + i;
            if raster.inside[k] {
                assert_eq!(dilated.t[k], raster.t[k], "inside texels stay");
                continue;
            }
            if !dilated.inside[k] {
                continue;
            }
            gutter += 1;
            // Texel centres: u = (i + 0.5) / px; the charts end at 0.45 and start at 0.55.
            let u = (i as f64 + 0.5) / px as f64;
            let want = if (0.45..0.5).contains(&u) {
                first
            } else if (0.5..0.55).contains(&u) {
                second
            } else {
                continue;
            };
            assert!(
                (dilated.t[k] - want).norm() < 1e-12,
                "texel ({i}, {j}) at u = {u}"
            );
        }
    }
    assert!(gutter > 4 * 90, "{gutter} gutter texels filled");
}

/// The planned output of a surface run bounds what it writes, and a run
/// planned over 50 GB is refused before its folder exists, naming the
/// frame rate key.
#[test]
fn surface_runs_are_planned_before_they_write() {
    let dir = temp("plan");
    let glb = common::root().join("examples/surfaces/forehead.glb");
    let scenario = |rate: f64, px: usize, out: &str| {
        format!(
            "[surface]\nfile = \"{}\"\nframe_rate_hz = {rate:?}\n[output]\ndir = \"{}\"\n\
             strain_images = true\nstrain_image_px = {px}\nvtu_compression = \"none\"\n",
            glb.display(),
            dir.join(out).display()
        )
    };
    let setup =
        SurfaceSetup::load(&write(&dir, "small.toml", &scenario(4.0, 128, "small"))).unwrap();
    skinpatch::pipeline::surface::run(&setup, |_| {}).unwrap();
    let written: u64 = walk(&dir.join("small"));
    let planned = skinpatch::pipeline::plan::planned_surface_bytes(&setup);
    eprintln!("planned {planned} bytes, wrote {written}");
    assert!(
        planned >= written && planned < 4 * written,
        "planned {planned}, wrote {written}"
    );
    let big = SurfaceSetup::load(&write(&dir, "big.toml", &scenario(60.0, 8192, "big"))).unwrap();
    let e = skinpatch::pipeline::surface::run(&big, |_| {})
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("surface.frame_rate_hz") && e.contains("--force"),
        "{e}"
    );
    assert!(!dir.join("big").exists());
    std::fs::remove_dir_all(&dir).ok();
}

/// Bytes of the files under `dir`.
fn walk(dir: &Path) -> u64 {
    std::fs::read_dir(dir)
        .unwrap()
        .map(|e| {
            let path = e.unwrap().path();
            if path.is_dir() {
                walk(&path)
            } else {
                std::fs::metadata(&path).unwrap().len()
            }
        })
        .sum()
}
