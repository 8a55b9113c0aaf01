//! The `skinpatch` command end to end: the README's main job, mesh
//! generation from flags, and error reporting.

use crate::common;

use std::path::Path;
use std::process::{Command, Output};

use common::root;
use skinpatch::mesh::io;

use common::{skinpatch, text};

#[test]
fn run_writes_mesh_frames_and_metrics() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("press");
    let o = skinpatch(&[
        "run",
        "tests/fixtures/press_small.toml",
        "--output",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "stderr: {}", text(&o.stderr));
    let stdout = text(&o.stdout);
    let mesh = io::read_tetgen(&root().join("meshes/patch_3k")).unwrap();
    let grid = io::read_vtu(&out.join("mesh.vtu")).unwrap();
    assert_eq!(
        (grid.points.len(), grid.tets.len()),
        (mesh.num_vertices(), mesh.num_tets())
    );
    assert!(
        stdout.contains(&format!("tets {}", mesh.num_tets())),
        "{stdout}"
    );
    // Seven frames (t = 0 … 1 s at 6 Hz), each a VTU with the deformed mesh.
    let metrics = std::fs::read_to_string(out.join("metrics.csv")).unwrap();
    let rows: Vec<&str> = metrics.lines().collect();
    assert_eq!(rows.len(), 8, "{metrics}");
    assert!(rows[0].starts_with("frame,time_s,probe_force_x_n"));
    let last = io::read_vtu(&out.join("frames/frame_0006.vtu")).unwrap();
    let stretch = last
        .cell_data
        .iter()
        .find(|f| f.name == "principal_stretch")
        .unwrap();
    assert_eq!(stretch.components, 3);
    let displacement = last
        .point_data
        .iter()
        .find(|f| f.name == "displacement_mm")
        .unwrap();
    let io::Values::F64(d) = &displacement.values else {
        panic!("float displacement")
    };
    // The surface under the probe went down about 0.5 mm.
    let deepest = d.chunks(3).map(|c| c[2]).fold(0.0, f64::min);
    assert!(
        (-0.55..-0.4).contains(&deepest),
        "deepest displacement {deepest}"
    );
    // The probe is pushed up and dragged back against +x motion.
    let f: Vec<f64> = rows[7].split(',').map(|v| v.parse().unwrap()).collect();
    assert!(f[4] > 0.0 && f[2] < 0.0, "{}", rows[7]);
    let pvd = std::fs::read_to_string(out.join("frames.pvd")).unwrap();
    assert_eq!(pvd.matches("<DataSet").count(), 7);
    meshio_agrees(
        &out.join("frames/frame_0006.vtu"),
        mesh.num_vertices(),
        mesh.num_tets(),
    );
}

/// Same scenario, same bytes: every output but the wall-time column.
#[test]
fn runs_are_deterministic() {
    let dir = tempfile::tempdir().unwrap();
    let run = |name: &str| {
        let out = dir.path().join(name);
        let o = skinpatch(&[
            "run",
            "tests/fixtures/press_small.toml",
            "--output",
            out.to_str().unwrap(),
        ]);
        assert!(o.status.success(), "stderr: {}", text(&o.stderr));
        out
    };
    let (a, b) = (run("a"), run("b"));
    for k in 0..=6 {
        let f = format!("frames/frame_{k:04}.vtu");
        assert_eq!(
            std::fs::read(a.join(&f)).unwrap(),
            std::fs::read(b.join(&f)).unwrap(),
            "{f}"
        );
    }
    let strip = |p: &Path| -> Vec<String> {
        std::fs::read_to_string(p)
            .unwrap()
            .lines()
            .map(|l| l.rsplit_once(',').unwrap().0.to_string())
            .collect()
    };
    assert_eq!(strip(&a.join("metrics.csv")), strip(&b.join("metrics.csv")));
    assert_eq!(
        std::fs::read(a.join("mesh.vtu")).unwrap(),
        std::fs::read(b.join("mesh.vtu")).unwrap()
    );
}

/// Reads the file with the Python package meshio when it is installed
/// (`.ci/run` installs it and sets SKINPATCH_REQUIRE_MESHIO=1): the counts,
/// integer cells, and a conversion to Gmsh (`.msh`, the arrays with 1, 3 or
/// 9 components that format carries) and back with the same cells and the
/// same point and cell data.
fn meshio_agrees(path: &Path, points: usize, tets: usize) {
    let script = format!(
        r#"
import meshio, numpy as np, os, tempfile
m = meshio.read({path:?})
tetra = [c.data for c in m.cells if c.type == "tetra"]
assert len(tetra) == 1 and np.issubdtype(tetra[0].dtype, np.integer), [c.data.dtype for c in m.cells]
keep = lambda v: v.ndim == 1 or v.shape[1] in (1, 3, 9)
point_data = {{k: v for k, v in m.point_data.items() if keep(v)}}
cell_data = {{k: v for k, v in m.cell_data.items() if keep(v[0])}}
out = meshio.Mesh(m.points, [("tetra", tetra[0])], point_data=point_data, cell_data=cell_data)
msh = os.path.join(tempfile.mkdtemp(), "frame.msh")
meshio.write(msh, out, file_format="gmsh22", binary=True)
back = meshio.read(msh)
assert np.array_equal(back.cells_dict["tetra"], tetra[0])
assert np.array_equal(back.points, m.points)
for k, v in point_data.items():
    assert np.array_equal(back.point_data[k].reshape(v.shape), v, equal_nan=True), k
for k, v in cell_data.items():
    assert np.array_equal(back.cell_data[k][0].reshape(v[0].shape), v[0], equal_nan=True), k
print(len(m.points), len(tetra[0]), len(point_data), len(cell_data))
"#,
        path = path.to_str().unwrap()
    );
    let Some(out) = common::python_check("meshio", "SKINPATCH_REQUIRE_MESHIO", &script, &[]) else {
        return;
    };
    let counts: Vec<usize> = out.split_whitespace().map(|v| v.parse().unwrap()).collect();
    assert_eq!(counts[..2], [points, tets], "{out}");
    assert!(counts[2] >= 3 && counts[3] >= 10, "arrays converted: {out}");
}

#[test]
fn mesh_from_flags_writes_all_files() {
    let dir = tempfile::tempdir().unwrap();
    let base = dir.path().join("m/small");
    let o = skinpatch(&[
        "mesh",
        "--width-mm",
        "3",
        "--depth-mm",
        "2",
        "--top-layer-mm",
        "0.5",
        "--bottom-layer-mm",
        "1",
        "--top-max-volume-mm3",
        "0.02",
        "--bottom-max-volume-mm3",
        "0.1",
        "--refine-sphere",
        "0,0,0.4",
        "--refine-max-volume-mm3",
        "0.001",
        "--out",
        base.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "stderr: {}", text(&o.stderr));
    for ext in ["node", "ele", "face", "vtu", "poly"] {
        assert!(
            dir.path().join(format!("m/small.{ext}")).exists(),
            "{ext} missing"
        );
    }
    let mesh = io::read_tetgen(&base).unwrap();
    assert!((mesh.total_volume() - 9.0).abs() < 1e-9, "3 × 2 × 1.5 mm");
    let stdout = text(&o.stdout);
    assert!(
        stdout.contains(&format!("tets {}", mesh.num_tets())),
        "{stdout}"
    );
    assert!(stdout.contains("dihedral angles: min"), "{stdout}");
}

/// A value refused by the mesh checks is named by the flag that gave it,
/// not by the scenario key the user never typed.
#[test]
fn mesh_flags_are_named_in_refusals() {
    let dir = tempfile::tempdir().unwrap();
    let base = dir.path().join("m");
    let cases: [(&[&str], &str); 3] = [
        (
            &["--top-layer-mm", "1", "--refine-sphere", "0.5,0,1"],
            "--refine-sphere: the zone's depth (a hemisphere's radius) 1 mm coincides with \
             the layer interface at 1 mm",
        ),
        (&["--width-mm=-2"], "--width-mm: must be > 0, got -2"),
        // A negative coordinate is a value, not a flag.
        (
            &["--refine-sphere", "-5.5,0,0.5"],
            "--refine-sphere: zone x ∈ [-6, -5]",
        ),
    ];
    for (flags, expected) in cases {
        let mut args = vec!["mesh", "--refine-max-volume-mm3", "0.001"];
        if !flags.contains(&"--refine-sphere") {
            args.truncate(1);
        }
        args.extend_from_slice(flags);
        args.extend_from_slice(&["--out", base.to_str().unwrap()]);
        let o = skinpatch(&args);
        let stderr = text(&o.stderr);
        assert!(
            !o.status.success() && stderr.contains(expected),
            "{args:?}: {stderr}"
        );
        assert!(!stderr.contains("mesh."), "{stderr}");
    }
}

#[test]
fn mesh_inspects_a_file() {
    let o = skinpatch(&["mesh", "--input", "tests/fixtures/two_layer_box.msh"]);
    assert!(o.status.success(), "stderr: {}", text(&o.stderr));
    let stdout = text(&o.stdout);
    assert!(stdout.contains("tets 1144  vertices 344"), "{stdout}");
    assert!(
        stdout.contains("region hypodermis (id 2): 690 tets"),
        "{stdout}"
    );
}

/// `--renumber` writes a loaded mesh with a banded numbering: the same
/// tets, regions and boundary markers, each tet's vertices closer together
/// than in the file, and the report says so.
#[test]
fn mesh_renumbers_a_loaded_file() {
    let dir = tempfile::tempdir().unwrap();
    let input = "tests/fixtures/two_layer_box.msh";
    let span = |stdout: &str| -> f64 {
        let line = stdout
            .lines()
            .find(|l| l.starts_with("numbering:"))
            .unwrap_or_else(|| panic!("no numbering line in {stdout}"));
        line.split("span ")
            .nth(1)
            .unwrap()
            .split(' ')
            .next()
            .unwrap()
            .parse()
            .unwrap()
    };
    let o = skinpatch(&["mesh", "--input", input]);
    assert!(o.status.success(), "stderr: {}", text(&o.stderr));
    let before = span(&text(&o.stdout));
    let base = dir.path().join("box");
    let o = skinpatch(&[
        "mesh",
        "--input",
        input,
        "--renumber",
        "--out",
        base.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "stderr: {}", text(&o.stderr));
    let stdout = text(&o.stdout);
    let after = span(&stdout);
    assert!(after < 0.5 * before, "span {after} against {before}");
    assert!(!stdout.contains("scattered"), "{stdout}");
    let old = io::read_mesh(Path::new(input)).unwrap();
    let new = io::read_tetgen(&base).unwrap();
    assert_eq!(
        (new.num_tets(), new.num_vertices()),
        (old.num_tets(), old.num_vertices())
    );
    assert!((new.total_volume() - old.total_volume()).abs() < 1e-12);
    assert_eq!(new.region_tet_counts(), old.region_tet_counts());
    let markers = |m: &skinpatch::mesh::TetMesh| {
        let mut counts = std::collections::BTreeMap::new();
        for f in &m.boundary {
            *counts.entry(f.marker).or_insert(0) += 1;
        }
        counts
    };
    assert_eq!(markers(&new), markers(&old));
    assert_eq!(new.top.vertices.len(), old.top.vertices.len());
    // Without --input there is nothing to renumber.
    let o = skinpatch(&["mesh", "--renumber"]);
    assert!(!o.status.success());
    assert!(text(&o.stderr).contains("--input"), "{}", text(&o.stderr));
}

#[test]
fn help_explains_the_commands() {
    let o = skinpatch(&["mesh", "--help"]);
    assert!(o.status.success());
    let help = text(&o.stdout);
    for flag in [
        "--scenario",
        "--out",
        "--refine-sphere",
        "--target-tets",
        "--radius-edge-max",
    ] {
        assert!(help.contains(flag), "{flag} missing from:\n{help}");
    }
    let o = skinpatch(&["--help"]);
    assert!(text(&o.stdout).contains("run"));
    // `run --help` names every output and the sweep flags.
    let o = skinpatch(&["run", "--help"]);
    let help = text(&o.stdout);
    for needle in [
        "mesh.vtu",
        "metrics.csv",
        "summary.json",
        "frames.pvd",
        "frames.vtkhdf",
        "strain/",
        "micro/normal_NNNN.png",
        "roughness.csv",
        "render/<mode>/frame_NNNN.png",
        ".mp4",
        "--set",
        "--quiet",
    ] {
        assert!(help.contains(needle), "{needle} missing from:\n{help}");
    }
}

/// A scenario that fails validation reports the key, exits non-zero, and
/// leaves whatever the output folder held untouched.
#[test]
fn bad_scenarios_fail_cleanly() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    std::fs::create_dir_all(&out).unwrap();
    std::fs::write(out.join("mesh.vtu"), "earlier result").unwrap();
    for (toml, expected) in [
        (
            "[mesh]\nwidht_mm = 10\n",
            "unknown key mesh.widht_mm; did you mean width_mm?",
        ),
        (
            "[mesh]\ntop_layer_mm = -1\n",
            "mesh.top_layer_mm must be > 0, got -1",
        ),
        ("[mesh]\nfile = \"missing.msh\"\n", "missing.msh"),
        ("[mesh\n", "line 1"),
        // Arrays of the wrong length are refused, not truncated.
        (
            "[render.camera]\neye_mm = [0.0, -13.0, 8.0, 5.0]\n",
            "line 2: render.camera.eye_mm: invalid length 4, expected an array of 3 numbers",
        ),
        (
            "[probe]\npath_mm = [[0.0, 0.0, 0.0, 1.0, 9.0]]\n",
            "probe.path_mm[0]: invalid length 5, expected an array of 4 numbers",
        ),
        (
            "[mesh.refine]\ncenter_mm = [1.0]\n",
            "mesh.refine.center_mm: invalid length 1, expected an array of 2 numbers",
        ),
    ] {
        let scenario = dir.path().join("bad.toml");
        std::fs::write(
            &scenario,
            format!("{toml}\n[output]\ndir = {:?}\n", out.to_str().unwrap()),
        )
        .unwrap();
        let o = skinpatch(&["run", scenario.to_str().unwrap()]);
        assert!(!o.status.success());
        let stderr = text(&o.stderr);
        assert!(
            stderr.contains(expected),
            "{stderr:?} should contain {expected:?}"
        );
        assert!(!stderr.contains("panicked"), "{stderr}");
        assert_eq!(
            std::fs::read_to_string(out.join("mesh.vtu")).unwrap(),
            "earlier result"
        );
    }
    let o = skinpatch(&["run", "no/such/scenario.toml"]);
    assert!(text(&o.stderr).contains("no/such/scenario.toml"));
    // A huge bad value is named by its ends, not echoed in full.
    let scenario = dir.path().join("huge.toml");
    let value = "y".repeat(1 << 20);
    std::fs::write(&scenario, format!("[solver]\nlinear = \"{value}\"\n")).unwrap();
    let o = skinpatch(&["run", scenario.to_str().unwrap()]);
    let stderr = text(&o.stderr);
    assert!(!o.status.success());
    assert!(stderr.contains("solver.linear must be") && stderr.contains("characters left out"));
    assert!(stderr.len() < 2000, "{} bytes of stderr", stderr.len());
}

/// [`common::run_press_small_configured`] with the environment as it is.
fn run_press_small_with(dir: &Path, extra: &str) -> (std::path::PathBuf, Output) {
    common::run_press_small_configured(dir, extra, |_| {})
}

/// A run whose solver gives up stops with an error naming the frame and the
/// residual, and keeps every frame written before.
#[test]
fn solver_failure_stops_cleanly_and_keeps_outputs() {
    let dir = tempfile::tempdir().unwrap();
    let (out, o) = run_press_small_with(dir.path(), "\n[solver]\nmax_newton_iterations = 1\n");
    assert!(!o.status.success());
    let stderr = text(&o.stderr);
    assert!(stderr.contains("frame 1 (t = 0.1667 s)"), "{stderr}");
    assert!(stderr.contains("relative residual"), "{stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
    let metrics = std::fs::read_to_string(out.join("metrics.csv")).unwrap();
    assert_eq!(metrics.lines().count(), 2, "header and frame 0: {metrics}");
    io::read_vtu(&out.join("frames/frame_0000.vtu")).unwrap();
    assert!(std::fs::read_to_string(out.join("frames.pvd"))
        .unwrap()
        .contains("frame_0000.vtu"));
}

/// `bench gpu --quick` runs every part of the report on the adapter at
/// hand (lavapipe in CI) and writes the JSON and Markdown: the chain for
/// each strain-raster step at each size, at parity with its CPU reference
/// (and tiled at parity with untiled), the four render cases with the
/// whole frame, the GPU fit counter choosing the CPU's optimum, and the
/// viewer's loop offscreen presenting the renderer's image.
#[test]
fn bench_gpu_quick_writes_every_part_of_the_report() {
    let dir = tempfile::tempdir().unwrap();
    let report = dir.path().join("gpu.json");
    let o = skinpatch(&[
        "bench",
        "gpu",
        "--quick",
        "--scenario",
        "tests/fixtures/press_small.toml",
        "--report",
        report.to_str().unwrap(),
    ]);
    if !o.status.success() {
        // Only without an adapter, and then it says so.
        assert!(
            std::env::var("SKINPATCH_REQUIRE_GPU").map_or(true, |v| v != "1"),
            "stderr: {}",
            text(&o.stderr)
        );
        assert!(text(&o.stderr).contains("GPU"), "{}", text(&o.stderr));
        return;
    }
    let v: serde_json::Value = serde_json::from_slice(&std::fs::read(&report).unwrap()).unwrap();
    let adapter = v["adapter"].as_str().unwrap();
    assert!(!adapter.is_empty());
    assert!(!v["adapters"].as_array().unwrap().is_empty());
    let micro = v["micro"].as_array().unwrap();
    let steps: Vec<u64> = micro
        .iter()
        .map(|m| m["raster_step"].as_u64().unwrap())
        .collect();
    assert_eq!(steps, [1, 2, 4]);
    for m in micro {
        let rows = m["rows"].as_array().unwrap();
        let sizes: Vec<u64> = rows.iter().map(|r| r["size"].as_u64().unwrap()).collect();
        assert_eq!(sizes, [128, 256]);
        for r in rows {
            assert!(r["gpu_ms"].as_f64().unwrap() > 0.0, "{r}");
            assert!(r["cpu_ms"].as_f64().unwrap() > 0.0, "{r}");
            assert!(r["max_difference"].as_f64().unwrap() <= 1e-4, "{r}");
            let stages = r["stages"].as_array().unwrap();
            assert_eq!(stages.len(), skinpatch::gpu::micro::MicroStage::COUNT);
            assert!(
                stages.iter().all(|s| s["bytes"].as_u64().unwrap() > 0),
                "{r}"
            );
            assert!(r["resident_frame_ms"].as_f64().unwrap() > 0.0, "{r}");
            let tiled = &r["tiled"];
            assert!(tiled["max_difference"].as_f64().unwrap() <= 1e-4, "{r}");
        }
        assert_eq!(rows[1]["tiled"]["total"], 4);
    }
    let render = v["render"].as_array().unwrap();
    let cases: Vec<(String, u64)> = render
        .iter()
        .map(|r| {
            let filter = r["microstructure_filter"].as_str().unwrap().to_string();
            (filter, r["msaa"].as_u64().unwrap())
        })
        .collect();
    let expected = [("moments", 4), ("moments", 1), ("none", 4), ("none", 1)];
    assert_eq!(cases, expected.map(|(f, m)| (f.to_string(), m)).to_vec());
    for r in render {
        assert_eq!(
            (r["width"].as_u64(), r["height"].as_u64()),
            (Some(160), Some(90))
        );
        assert!(r["render_ms"].as_f64().unwrap() > 0.0, "{r}");
        assert_eq!(r["passes"].as_array().unwrap().len(), 6);
        let whole = &r["whole_frame"];
        assert!(whole["fem_ms"].as_f64().unwrap() > 0.0, "{r}");
        let fps = whole["frames_per_s"].as_f64().unwrap();
        assert!(fps.is_finite() && fps > 0.0, "{r}");
        let share = whole["gpu_share"].as_f64().unwrap();
        assert!((0.0..=1.0).contains(&share), "{r}");
    }
    let fit = &v["fit"];
    assert_eq!(fit["same_optimum"], true, "{fit}");
    assert!(fit["evaluations"].as_u64().unwrap() > 1000, "{fit}");
    assert!(fit["cpu_s"].as_f64().unwrap() > 0.0 && fit["gpu_s"].as_f64().unwrap() > 0.0);
    if cfg!(feature = "viewer") {
        check_viewer_loop(&v["viewer"]);
    } else {
        assert!(v["viewer"].is_null());
    }
    let md = std::fs::read_to_string(report.with_extension("md")).unwrap();
    for heading in [
        "## Microstructure chain",
        "## Renderer and whole frame",
        "## Fit counter",
        "## Viewer loop, offscreen",
    ] {
        assert!(md.contains(heading), "{md}");
    }
    assert!(md.contains(adapter) && text(&o.stdout).contains(adapter));
}

/// The viewer loop's part of `bench gpu --quick`'s report.
fn check_viewer_loop(viewer: &serde_json::Value) {
    assert_eq!(
        (viewer["width"].as_u64(), viewer["height"].as_u64()),
        (Some(160), Some(90))
    );
    // press_small has no microstructure: the view shows mode none and the
    // chain never runs.
    assert_eq!(viewer["mode"], "none", "{viewer}");
    assert_eq!(viewer["chain_runs"], 0, "{viewer}");
    assert!(viewer["chain_ms"].is_null(), "{viewer}");
    assert!(viewer["seconds"].as_f64().unwrap() >= 2.0, "{viewer}");
    assert!(viewer["frames"].as_u64().unwrap() >= 2, "{viewer}");
    let fps = viewer["frames_per_s"].as_f64().unwrap();
    assert!(fps.is_finite() && fps > 0.0, "{viewer}");
    // The probe's path plays, so the FEM thread solves new frames.
    assert!(viewer["fem_frames"].as_u64().unwrap() >= 1, "{viewer}");
    assert!(viewer["render_ms"].as_f64().unwrap() > 0.0, "{viewer}");
    assert!(viewer["present_ms"].as_f64().unwrap() > 0.0, "{viewer}");
    assert!(
        viewer["present_max_difference"].as_u64().unwrap() <= 1,
        "{viewer}"
    );
}

/// `bench micro` prints each stage's traffic and, given the peak
/// bandwidth, how far a resident frame is from it; a bad bandwidth is
/// refused before any work.
#[test]
fn bench_micro_reports_traffic_against_a_given_bandwidth() {
    let args = [
        "bench",
        "micro",
        "--scenario",
        "tests/fixtures/press_small.toml",
        "--sizes",
        "64",
        "--frames",
        "1",
        "--bandwidth-gbs",
    ];
    let o = skinpatch(&[&args[..], &["50"]].concat());
    assert!(o.status.success(), "stderr: {}", text(&o.stderr));
    let out = text(&o.stdout);
    if !out.contains("no GPU adapter") {
        assert!(out.contains("Bytes each stage must move"), "{out}");
        assert!(out.contains("Achieved GB/s over the wall times"), "{out}");
        let floor = out
            .lines()
            .find(|l| l.contains("× the floor"))
            .unwrap_or_else(|| panic!("no floor line: {out}"));
        // 64² texels: raster 32 B, passes 40 B each, normals 20 B a texel.
        let mb: f64 = floor.split_whitespace().nth(1).unwrap().parse().unwrap();
        let expected = (32.0 + 40.0 + 40.0 + 20.0) * 64.0 * 64.0 * 1e-6;
        assert!(
            (mb - expected).abs() < 0.03 * expected,
            "{floor} vs {expected} MB"
        );
        assert!(out.contains("50 GB/s peak (--bandwidth-gbs)"), "{out}");
    }
    let o = skinpatch(&[&args[..], &["0"]].concat());
    assert_eq!(o.status.code(), Some(1));
    let err = text(&o.stderr);
    assert!(err.contains("--bandwidth-gbs must be a positive"), "{err}");
}

#[test]
fn bench_fem_compares_solvers() {
    let o = skinpatch(&[
        "bench",
        "fem",
        "--scenario",
        "tests/fixtures/press_small.toml",
        "--frames",
        "2",
    ]);
    assert!(o.status.success(), "stderr: {}", text(&o.stderr));
    let out = text(&o.stdout);
    assert!(out.contains("frames/s"), "{out}");
    let rows: Vec<&str> = out
        .lines()
        .filter(|l| {
            ["cg ", "factored ", "direct ", "two-level "]
                .iter()
                .any(|p| l.starts_with(p))
        })
        .collect();
    assert_eq!(rows.len(), 4, "{out}");
    // Columns: solver, frames/s, wall s, Newton, linear iterations, ….
    let column =
        |row: &str, k: usize| -> usize { row.split_whitespace().nth(k).unwrap().parse().unwrap() };
    let (cg, factored, direct, two_level) = (rows[0], rows[1], rows[2], rows[3]);
    assert!(column(cg, 3) > 0 && column(cg, 4) > column(cg, 3), "{out}");
    // The reused factor preconditions far better than block Jacobi.
    assert!(
        column(factored, 3) > 0 && column(factored, 4) * 2 < column(cg, 4),
        "{out}"
    );
    // One factorisation per Newton iteration: one solve, or (with sliding
    // friction, whose coupling is not symmetric) one to three BiCGStab
    // iterations preconditioned by it.
    let (newton, linear) = (column(direct, 3), column(direct, 4));
    assert!(
        newton > 0 && linear >= newton && linear <= 3 * newton,
        "{out}"
    );
    // The coarse correction cuts the conjugate-gradient iterations.
    assert!(
        column(two_level, 3) > 0 && column(two_level, 4) < column(cg, 4),
        "{out}"
    );
    assert!(out.contains("wall-time ratios: cg / factored"), "{out}");
    assert!(out.contains("cg / two-level"), "{out}");
}

/// `strain_images = true` writes three PNG maps per frame; the metrics carry
/// the surface stretch ranges and the frame VTUs the strain fields.
#[test]
fn strain_maps_metrics_and_fields() {
    let dir = tempfile::tempdir().unwrap();
    let (out, o) = run_press_small_with(
        dir.path(),
        "\n[output]\nstrain_images = true\nstrain_image_px = 64\nstrain_image_range = 0.1\n",
    );
    assert!(o.status.success(), "stderr: {}", text(&o.stderr));
    for frame in 0..7 {
        for name in ["rs", "rt", "axes"] {
            let png = out.join(format!("strain/{name}_{frame:04}.png"));
            let image = image::open(&png).unwrap().to_rgb8();
            // The UV square plus, for the stretch maps, a gap and a colour bar.
            let width = if name == "axes" { 64 } else { 64 + 2 + 6 };
            assert_eq!(image.dimensions(), (width, 64), "{}", png.display());
            if frame == 0 && name != "axes" {
                // At rest every texel is neutral grey.
                assert!(
                    (0..64).all(|x| (0..64).all(|y| image.get_pixel(x, y).0 == [221, 221, 221])),
                    "{}",
                    png.display()
                );
            }
        }
    }
    // Under the probe at the end the surface is stretched and compressed:
    // some r_s texels are red, some r_t texels blue.
    let rs = image::open(out.join("strain/rs_0006.png"))
        .unwrap()
        .to_rgb8();
    let rt = image::open(out.join("strain/rt_0006.png"))
        .unwrap()
        .to_rgb8();
    assert!((0..64).any(|x| (0..64).any(|y| {
        let [r, _, b] = rs.get_pixel(x, y).0;
        r > 200 && b < 150
    })));
    assert!((0..64).any(|x| (0..64).any(|y| {
        let [r, _, b] = rt.get_pixel(x, y).0;
        b > 200 && r < 150
    })));

    let metrics = std::fs::read_to_string(out.join("metrics.csv")).unwrap();
    let header: Vec<&str> = metrics.lines().next().unwrap().split(',').collect();
    let column = |name: &str| header.iter().position(|h| *h == name).unwrap();
    let last: Vec<&str> = metrics.lines().last().unwrap().split(',').collect();
    let value = |name: &str| -> f64 { last[column(name)].parse().unwrap() };
    assert!(value("rs_min") <= value("rs_max") && value("rs_max") > 1.01);
    assert!(value("rt_min") < 0.99 && value("rt_min") <= value("rt_max"));
    assert_eq!(value("folded_vertices"), 0.0);

    let mesh = io::read_tetgen(&root().join("meshes/patch_3k")).unwrap();
    let grid = io::read_vtu(&out.join("frames/frame_0006.vtu")).unwrap();
    let field = |name: &str| {
        let f = grid
            .point_data
            .iter()
            .chain(&grid.cell_data)
            .find(|f| f.name == name)
            .unwrap_or_else(|| panic!("no {name}"));
        match &f.values {
            io::Values::F64(v) => (f.components, v.clone()),
            _ => panic!("{name} is not float"),
        }
    };
    let (components, surface) = field("surface_stretch");
    assert_eq!(components, 2);
    for v in 0..mesh.num_vertices() {
        let on_top = mesh.top.surface_vertex(v).is_some();
        assert_eq!(surface[2 * v].is_finite(), on_top, "vertex {v}");
    }
    let (_, stretch) = field("principal_stretch");
    let (_, biot) = field("principal_biot_strain");
    assert!(stretch
        .iter()
        .zip(&biot)
        .all(|(l, b)| (l - 1.0 - b).abs() < 1e-15));
    // One unit 3-vector per principal direction, orthogonal to each other.
    let axes: Vec<Vec<f64>> = (1..=3)
        .map(|k| {
            let (components, v) = field(&format!("principal_axis_{k}_deformed"));
            assert_eq!(components, 3);
            v
        })
        .collect();
    for t in 0..mesh.num_tets() {
        let a = |k: usize| nalgebra::Vector3::from_column_slice(&axes[k][3 * t..3 * t + 3]);
        assert!((a(0).norm() - 1.0).abs() < 1e-9 && a(0).dot(&a(1)).abs() < 1e-9);
        assert!((a(0).cross(&a(1)) - a(2)).norm() < 1e-9, "tet {t}");
    }
    assert_eq!(field("principal_axis_1_rest").0, 3);
    assert_eq!(field("surface_axis_s").0, 3);
    // Component names for ParaView, cells as Int64 (what VTK writes).
    let xml = std::fs::read_to_string(out.join("frames/frame_0006.vtu")).unwrap();
    for needle in [
        r#"Name="principal_stretch" NumberOfComponents="3" ComponentName0="λ1""#,
        r#"Name="surface_stretch" NumberOfComponents="2" ComponentName0="r_s" ComponentName1="r_t""#,
        r#"<DataArray type="Int64" Name="connectivity""#,
    ] {
        assert!(xml.contains(needle), "{needle}");
    }
    vtk_reads_names_and_directions(&out.join("frames/frame_0006.vtu"), &axes);
}

/// VTK's own VTU reader (the Python `vtk` package; `.ci/run` requires it)
/// shows the component names we write, and reads principal direction K of
/// a tet as the 3-vector `principal_axis_K_deformed` holds (what ParaView's
/// Calculator and glyphs use): checked on a few tets against `axes`.
fn vtk_reads_names_and_directions(path: &Path, axes: &[Vec<f64>]) {
    let script = r#"
import sys
from vtkmodules.vtkIOXML import vtkXMLUnstructuredGridReader
r = vtkXMLUnstructuredGridReader()
r.SetFileName(sys.argv[1])
r.Update()
g = r.GetOutput()
def names(data, name):
    a = data.GetArray(name)
    return [a.GetComponentName(i) for i in range(a.GetNumberOfComponents())]
assert names(g.GetCellData(), "principal_stretch") == ["λ1", "λ2", "λ3"], names(g.GetCellData(), "principal_stretch")
assert names(g.GetCellData(), "principal_green_strain") == ["E1", "E2", "E3"]
assert names(g.GetPointData(), "surface_stretch") == ["r_s", "r_t"]
assert names(g.GetPointData(), "displacement_mm") == ["X", "Y", "Z"]
for t in (0, 17, g.GetNumberOfCells() - 1):
    for k in (1, 2, 3):
        print(t, k, *g.GetCellData().GetArray(f"principal_axis_{k}_deformed").GetTuple3(t))
"#;
    let Some(out) = common::python_check(
        "vtk",
        "SKINPATCH_REQUIRE_VTK",
        script,
        &[path.to_str().unwrap()],
    ) else {
        return;
    };
    let mut lines = 0;
    for line in out.lines() {
        let v: Vec<f64> = line
            .split_whitespace()
            .map(|x| x.parse().unwrap())
            .collect();
        let (t, k) = (v[0] as usize, v[1] as usize);
        let ours = &axes[k - 1][3 * t..3 * t + 3];
        // Printed by Python's repr: the shortest text that reads back exactly.
        assert_eq!(&v[2..], ours, "tet {t}, direction {k}");
        lines += 1;
    }
    assert_eq!(lines, 9, "{out}");
}

/// `[microstructure]` writes the neutral map and, every `frame_stride`
/// frames, the deformed height and normal maps; at rest the deformed map is
/// the neutral one, under the probe it differs.
#[test]
fn microstructure_maps_per_frame() {
    use skinpatch::micro::io::{read_png16, MapDefaults, TexelSize};
    let dir = tempfile::tempdir().unwrap();
    let (out, o) = run_press_small_with(
        dir.path(),
        "\n[microstructure]\nframe_stride = 3\nroughness_table = true\nformats = [\"png16\", \"exr\"]\n[microstructure.procedural]\nsize_px = 400\n",
    );
    assert!(o.status.success(), "stderr: {}", text(&o.stderr));
    let micro = out.join("micro");
    let mut names: Vec<String> = std::fs::read_dir(&micro)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    let mut expected: Vec<String> = ["neutral", "0000", "0003", "0006"]
        .iter()
        .flat_map(|t| {
            [
                format!("height_{t}.png"),
                format!("height_{t}.exr"),
                format!("normal_{t}.png"),
                format!("normal_{t}.exr"),
            ]
        })
        .collect();
    expected.push("roughness.csv".into());
    expected.sort();
    assert_eq!(names, expected);
    let defaults = MapDefaults {
        texel: TexelSize::Um(1.0),
        height_unit_um: 1.0,
        edge: skinpatch::micro::Edge::Wrap,
    };
    let read = |name: &str| read_png16(&micro.join(name), &defaults).unwrap();
    let neutral = read("height_neutral.png");
    assert_eq!((neutral.width, neutral.height), (400, 400));
    assert!((neutral.texel_um - 25.0).abs() < 1e-9);
    let rest = read("height_0000.png");
    let (lo, hi) = neutral.range();
    let diff = |m: &skinpatch::micro::DisplacementMap| {
        m.data
            .iter()
            .zip(&neutral.data)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0f32, f32::max)
            / (hi - lo)
    };
    assert!(diff(&rest) < 1e-4, "frame 0 is neutral: {}", diff(&rest));
    let pressed = diff(&read("height_0006.png"));
    assert!(pressed > 0.01, "the pressed frame differs: {pressed}");
    let roughness = std::fs::read_to_string(micro.join("roughness.csv")).unwrap();
    assert_eq!(roughness.lines().count(), 16, "{roughness}");
    assert!(
        roughness.starts_with("stretch_ratio,beckmann_m\n0.70,"),
        "{roughness}"
    );
    let normals = image::open(micro.join("normal_0006.png")).unwrap();
    assert_eq!(normals.color(), image::ColorType::Rgb16);

    // One offset and scale for the whole sequence: the neutral map's range
    // widened by the stated margin, the same bytes in every file, and each
    // PNG within half a quantisation step of its unquantised EXR twin.
    let margin = skinpatch::scenario::HEIGHT_RANGE_MARGIN * (hi - lo) as f64;
    let [offset, scale] = crate::dcc_outputs::png_quantisation(&micro.join("height_neutral.png"));
    let expected_offset = lo as f64 - margin;
    let expected_scale = ((hi - lo) as f64 + 2.0 * margin) / 65535.0;
    // (`lo`, `hi` come from the quantised neutral map: within a step.)
    assert!(
        (offset - expected_offset).abs() < 2.0 * scale,
        "{offset} vs {expected_offset}"
    );
    assert!(
        (scale / expected_scale - 1.0).abs() < 1e-4,
        "{scale} vs {expected_scale}"
    );
    for tag in ["0000", "0003", "0006"] {
        let png = micro.join(format!("height_{tag}.png"));
        assert_eq!(
            crate::dcc_outputs::png_quantisation(&png),
            [offset, scale],
            "{tag}"
        );
        let exr =
            skinpatch::micro::io::read_map(&micro.join(format!("height_{tag}.exr")), &defaults)
                .unwrap();
        let quantised = read(&format!("height_{tag}.png"));
        let worst = quantised
            .data
            .iter()
            .zip(&exr.data)
            .map(|(a, b)| (a - b).abs() as f64)
            .fold(0.0, f64::max);
        assert!(
            worst <= 0.5001 * scale + 1e-6 * (hi - lo) as f64,
            "{tag}: {worst} vs step {scale}"
        );
    }
}

/// `incremental_tolerance = 0` reuses only tiles whose inputs are
/// bit-identical, so the maps equal a run without it; the run says where
/// the passes ran.
#[test]
fn incremental_microstructure_frames_with_tolerance_zero_change_nothing() {
    let section = "\n[microstructure]\nframe_stride = 3\nformats = [\"exr\"]\nnormal_maps = false\n[microstructure.procedural]\nsize_px = 200\n";
    let dirs = [tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap()];
    let whole = run_press_small_with(dirs[0].path(), section);
    let incremental = run_press_small_with(
        dirs[1].path(),
        &section.replace("normal_maps", "incremental_tolerance = 0.0\nnormal_maps"),
    );
    for (_, o) in [&whole, &incremental] {
        assert!(o.status.success(), "stderr: {}", text(&o.stderr));
    }
    let stdout = text(&incremental.1.stdout);
    if !stdout.contains("microstructure stages: GPU") {
        crate::common::skip("no GPU adapter: the CPU reference ran both");
        return;
    }
    assert!(
        stdout.contains("incremental frames, tolerance 0"),
        "{stdout}"
    );
    assert!(text(&whole.1.stdout).contains("of the map's tiles"));
    for frame in ["0000", "0003", "0006"] {
        let name = format!("micro/height_{frame}.exr");
        let a = std::fs::read(whole.0.join(&name)).unwrap();
        let b = std::fs::read(incremental.0.join(&name)).unwrap();
        assert!(a == b, "{name} differs");
    }
}

/// `strain_raster_step = 4`: the GPU and CPU runs write the same maps (the
/// CPU reference reads the same coarse raster), close to the exact raster's,
/// and the report says which raster ran.
#[test]
fn a_coarse_strain_raster_runs_alike_on_gpu_and_cpu() {
    use skinpatch::micro::io::{read_exr, MapDefaults, TexelSize};
    let section = "\n[microstructure]\nframe_stride = 6\nformats = [\"exr\"]\nnormal_maps = false\nstrain_raster_step = 4\n[microstructure.procedural]\nsize_px = 240\n";
    let dirs = [(); 3].map(|_| tempfile::tempdir().unwrap());
    let run = |dir: &Path, section: &str, adapter: Option<&str>| {
        common::run_press_small_configured(dir, section, |cmd| {
            cmd.env_remove("SKINPATCH_ADAPTER")
                .env_remove("SKINPATCH_REQUIRE_GPU");
            if let Some(a) = adapter {
                cmd.env("SKINPATCH_ADAPTER", a);
            }
        })
    };
    let gpu = run(dirs[0].path(), section, None);
    let cpu = run(dirs[1].path(), section, Some("no-such-adapter"));
    let exact = run(
        dirs[2].path(),
        &section.replace("strain_raster_step = 4", "strain_raster_step = 1"),
        Some("no-such-adapter"),
    );
    for (_, o) in [&gpu, &cpu, &exact] {
        assert!(o.status.success(), "stderr: {}", text(&o.stderr));
    }
    for (_, o) in [&gpu, &cpu] {
        let out = text(&o.stdout);
        assert!(
            out.contains("strain raster: one texel per 4 × 4 map texels"),
            "{out}"
        );
    }
    assert!(!text(&exact.1.stdout).contains("strain raster: one texel"));
    let defaults = MapDefaults {
        texel: TexelSize::Um(1.0),
        height_unit_um: 1.0,
        edge: skinpatch::micro::Edge::Wrap,
    };
    let map = |dir: &Path| read_exr(&dir.join("micro/height_0006.exr"), &defaults).unwrap();
    let (g, c, e) = (map(&gpu.0), map(&cpu.0), map(&exact.0));
    let (lo, hi) = e.range();
    let gpu_cpu = c.max_difference(&g);
    let from_exact = c.max_difference(&e);
    eprintln!("strain raster step 4: GPU − CPU {gpu_cpu:.1e}, step 4 − exact {from_exact:.1e}");
    assert!(gpu_cpu < 1e-4, "{gpu_cpu:e} of [{lo}, {hi}]");
    assert!(from_exact > 0.0 && from_exact < 1e-2, "{from_exact:e}");
}

/// `skinpatch fit`: fits a deformed map, adds given points, prints the
/// table and model, and writes a kernel file a scenario can use.
#[test]
fn fit_prints_the_table_and_writes_a_usable_kernel_file() {
    use skinpatch::micro::convolve::convolve_pass;
    use skinpatch::micro::io::write_png16;
    use skinpatch::micro::procedural::{generate, SkinParams};
    use skinpatch::micro::PassParams;
    let dir = tempfile::tempdir().unwrap();
    let neutral = generate(&SkinParams {
        size_px: 128,
        extent_mm: 0.64,
        groove_spacing_um: 120.0,
        ..SkinParams::default()
    })
    .unwrap();
    write_png16(&dir.path().join("neutral.png"), &neutral).unwrap();
    // Blurred along u with α 0.5, σ 15 µm (3 texels), not stretched.
    let pass = PassParams {
        axis: [1.0, 0.0],
        alpha: 0.5,
        sigma: 3.0,
    };
    let blurred = convolve_pass(&neutral, &vec![pass; neutral.data.len()]);
    write_png16(&dir.path().join("blurred.png"), &blurred).unwrap();
    // The same target as a histogram file (64 rows of 64 weights).
    let h = skinpatch::micro::NormalHistogram::of(&blurred, 64, 0.5, [1.0, 1.0]);
    let csv: String = h
        .cells
        .chunks(64)
        .map(|row| {
            row.iter()
                .map(|w| format!("{w:e}"))
                .collect::<Vec<_>>()
                .join(",")
                + "\n"
        })
        .collect();
    std::fs::write(dir.path().join("target.csv"), csv).unwrap();
    let samples = "neutral = \"neutral.png\"\noutput = \"kernel.toml\"\nrange = 0.5\n\
        [[sample]]\nmap = \"blurred.png\"\nr = 1.0\naxis = \"u\"\n\
        [[sample]]\nhistogram = \"target.csv\"\nr = 1.0\naxis = \"u\"\n\
        [[point]]\nr = 0.8\nalpha = -1.5\nsigma_um = 8.0\n\
        [[point]]\nr = 1.2\nalpha = 0.8\nsigma_um = 18.0\n";
    std::fs::write(dir.path().join("samples.toml"), samples).unwrap();
    let o = skinpatch(&["fit", dir.path().join("samples.toml").to_str().unwrap()]);
    assert!(o.status.success(), "stderr: {}", text(&o.stderr));
    let out = text(&o.stdout);
    let row = out
        .lines()
        .find(|l| l.ends_with("blurred.png"))
        .expect(&out);
    let cols: Vec<f64> = row
        .split_whitespace()
        .take(3)
        .map(|v| v.parse().unwrap())
        .collect();
    // The PNG round trip quantises the heights, so allow a little more than the grid.
    assert!(
        (cols[1] - 0.5).abs() <= 0.05 && (cols[2] - 15.0).abs() <= 1.0,
        "{out}"
    );
    assert!(out.contains("model: α ="), "{out}");
    // The kernel file records every sample's fit and histogram window.
    let kernel = dir.path().join("kernel.toml");
    let header = std::fs::read_to_string(&kernel).unwrap();
    assert!(
        header.contains("#   blurred.png: r 1, axis U, bins 64, range 0.5: α "),
        "{header}"
    );
    // The kernel file drives a scenario.
    let (_, o) = run_press_small_with(
        dir.path(),
        &format!(
            "\n[microstructure]\nkernel_file = {:?}\n[microstructure.procedural]\nsize_px = 32\n",
            kernel.to_str().unwrap()
        ),
    );
    assert!(o.status.success(), "stderr: {}", text(&o.stderr));
    // A sample needs exactly one of map and histogram.
    std::fs::write(
        dir.path().join("both.toml"),
        "neutral = \"neutral.png\"\n[[sample]]\nmap = \"blurred.png\"\nhistogram = \"target.csv\"\nr = 1.0\naxis = \"u\"\n",
    )
    .unwrap();
    let o = skinpatch(&["fit", dir.path().join("both.toml").to_str().unwrap()]);
    assert!(text(&o.stderr).contains("sample[0]"), "{}", text(&o.stderr));
    // A histogram target needs the range its cells cover.
    std::fs::write(
        dir.path().join("no_range.toml"),
        "neutral = \"neutral.png\"\n[[sample]]\nhistogram = \"target.csv\"\nr = 1.0\naxis = \"u\"\n",
    )
    .unwrap();
    let o = skinpatch(&["fit", dir.path().join("no_range.toml").to_str().unwrap()]);
    let err = text(&o.stderr);
    assert!(
        !o.status.success() && err.contains("sample[0].histogram") && err.contains("range"),
        "{err}"
    );
    // A broken samples file names itself and the line.
    std::fs::write(
        dir.path().join("bad.toml"),
        "neutral = \"neutral.png\"\n[[sample]]\nmap = 3\n",
    )
    .unwrap();
    let o = skinpatch(&["fit", dir.path().join("bad.toml").to_str().unwrap()]);
    assert!(!o.status.success());
    let err = text(&o.stderr);
    assert!(err.contains("bad.toml:3"), "{err}");
    // An unknown axis names the line, the key and the accepted values.
    std::fs::write(
        dir.path().join("axis.toml"),
        "neutral = \"neutral.png\"\n[[sample]]\nmap = \"blurred.png\"\nr = 1.0\naxis = \"w\"\n",
    )
    .unwrap();
    let o = skinpatch(&["fit", dir.path().join("axis.toml").to_str().unwrap()]);
    let err = text(&o.stderr);
    assert!(
        !o.status.success()
            && err.contains("axis.toml:5")
            && err.contains("axis")
            && err.contains("\"u\" or \"v\"")
            && err.contains("\"w\""),
        "{err}"
    );
}

/// Runs the small press with a microstructure, the GPU variables cleared
/// and then `env` set.
fn run_micro_with_env(dir: &Path, env: &[(&str, &str)]) -> (std::path::PathBuf, Output) {
    let extra =
        "\n[microstructure]\nframe_stride = 6\n[microstructure.procedural]\nsize_px = 300\n";
    common::run_press_small_configured(dir, extra, |cmd| {
        cmd.env_remove("SKINPATCH_ADAPTER")
            .env_remove("SKINPATCH_REQUIRE_GPU")
            .envs(env.iter().copied());
    })
}

/// A software adapter (lavapipe) is slower than the CPU path, so a run
/// that does not render takes the CPU path there unless
/// `SKINPATCH_REQUIRE_GPU=1`; a hardware adapter keeps the chain.
#[test]
fn a_software_adapter_gives_way_to_the_cpu_path() {
    let Some(ctx) = common::context() else { return };
    let software = ctx.info.device_type == wgpu::DeviceType::Cpu;
    drop(ctx);
    let dir = tempfile::tempdir().unwrap();
    let (_, o) = run_micro_with_env(dir.path(), &[]);
    assert!(o.status.success(), "stderr: {}", text(&o.stderr));
    let stdout = text(&o.stdout);
    if software {
        assert!(
            stdout.contains("microstructure stages: CPU reference"),
            "{stdout}"
        );
    } else {
        assert!(stdout.contains("microstructure stages: GPU: "), "{stdout}");
    }
    let (_, o) = run_micro_with_env(dir.path(), &[("SKINPATCH_REQUIRE_GPU", "1")]);
    assert!(o.status.success(), "stderr: {}", text(&o.stderr));
    let stdout = text(&o.stdout);
    assert!(stdout.contains("microstructure stages: GPU: "), "{stdout}");
}

#[test]
fn gpu_and_cpu_runs_write_the_same_maps_and_say_where_they_ran() {
    use skinpatch::micro::io::{read_png16, MapDefaults, TexelSize};
    let required = std::env::var("SKINPATCH_REQUIRE_GPU").is_ok_and(|v| v == "1");
    let gpu_dir = tempfile::tempdir().unwrap();
    // Required, the GPU runs even where it is a software adapter.
    let require = [("SKINPATCH_REQUIRE_GPU", if required { "1" } else { "0" })];
    let (gpu_out, o) = run_micro_with_env(gpu_dir.path(), &require);
    assert!(o.status.success(), "stderr: {}", text(&o.stderr));
    let gpu_used = text(&o.stdout).contains("microstructure stages: GPU: ");
    assert!(gpu_used || !required, "stdout: {}", text(&o.stdout));
    // A name no adapter has: the run falls back to the CPU and says so.
    let cpu_dir = tempfile::tempdir().unwrap();
    let (cpu_out, o) =
        run_micro_with_env(cpu_dir.path(), &[("SKINPATCH_ADAPTER", "no-such-adapter")]);
    assert!(o.status.success(), "stderr: {}", text(&o.stderr));
    assert!(
        text(&o.stdout).contains("microstructure stages: CPU reference"),
        "stdout: {}",
        text(&o.stdout)
    );
    assert!(
        text(&o.stderr).contains("no-such-adapter"),
        "the fallback is logged"
    );
    let defaults = MapDefaults {
        texel: TexelSize::Um(1.0),
        height_unit_um: 1.0,
        edge: skinpatch::micro::Edge::Wrap,
    };
    for name in ["height_0006.png", "normal_0006.png"] {
        let a = std::fs::read(gpu_out.join("micro").join(name)).unwrap();
        let b = std::fs::read(cpu_out.join("micro").join(name)).unwrap();
        if a == b {
            continue;
        }
        // 16-bit quantisation may round a texel either way.
        if name.starts_with("height") {
            let (ga, cb) = (
                read_png16(&gpu_out.join("micro").join(name), &defaults).unwrap(),
                read_png16(&cpu_out.join("micro").join(name), &defaults).unwrap(),
            );
            let (lo, hi) = cb.range();
            let worst = ga
                .data
                .iter()
                .zip(&cb.data)
                .map(|(x, y)| (x - y).abs())
                .fold(0.0f32, f32::max);
            assert!(worst / (hi - lo) < 1e-4, "{name}: {}", worst / (hi - lo));
        } else {
            let (ia, ib) = (
                image::open(gpu_out.join("micro").join(name))
                    .unwrap()
                    .into_rgb16(),
                image::open(cpu_out.join("micro").join(name))
                    .unwrap()
                    .into_rgb16(),
            );
            let worst = ia
                .as_raw()
                .iter()
                .zip(ib.as_raw())
                .map(|(x, y)| x.abs_diff(*y))
                .max()
                .unwrap();
            assert!(worst <= 8, "{name}: {worst} of 65535");
        }
    }
    // Required but not available: a clear error, not a silent fallback.
    let dir = tempfile::tempdir().unwrap();
    let (_, o) = run_micro_with_env(
        dir.path(),
        &[
            ("SKINPATCH_ADAPTER", "no-such-adapter"),
            ("SKINPATCH_REQUIRE_GPU", "1"),
        ],
    );
    assert!(!o.status.success());
    let err = text(&o.stderr);
    assert!(
        err.contains("SKINPATCH_REQUIRE_GPU=1") && err.contains("no-such-adapter"),
        "{err}"
    );
}

#[test]
fn gpu_info_lists_adapters_or_says_there_are_none() {
    let o = skinpatch(&["gpu-info"]);
    let out = text(&o.stdout);
    if o.status.success() {
        assert!(
            out.contains("adapter 0: ") && out.contains("max_texture_dimension_2d"),
            "{out}"
        );
        assert!(out.contains("in use: "), "{out}");
    } else {
        assert!(
            text(&o.stderr).contains("no Vulkan adapter"),
            "{}",
            text(&o.stderr)
        );
        assert!(std::env::var("SKINPATCH_REQUIRE_GPU").map_or(true, |v| v != "1"));
    }
}

/// `--set` overrides scenario keys (dotted keys, TOML values, bare words as
/// strings) and is validated like the file; `--quiet` prints nothing.
#[test]
fn set_overrides_keys_and_quiet_prints_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("o");
    let run_small = |out: &Path, extra: &[&str]| {
        let mut args = vec![
            "run",
            "tests/fixtures/press_small.toml",
            "--output",
            out.to_str().unwrap(),
        ];
        args.extend_from_slice(extra);
        skinpatch(&args)
    };
    let o = run_small(
        &out,
        &[
            "--quiet",
            "--set",
            "time.frame_rate_hz=2",
            "--set",
            "probe.friction=0.3",
            "--set",
            "output.frames_vtu=false",
        ],
    );
    assert!(o.status.success(), "stderr: {}", text(&o.stderr));
    assert_eq!(text(&o.stdout), "", "--quiet prints no report");
    assert!(!text(&o.stderr).contains("frame 1/"), "{}", text(&o.stderr));
    let metrics = std::fs::read_to_string(out.join("metrics.csv")).unwrap();
    // 2 frames per second over 1 s instead of the file's 6: rows 0, 1, 2.
    assert_eq!(metrics.lines().count(), 1 + 3, "{metrics}");
    assert!(!out.join("frames").join("frame_0001.vtu").exists());
    // μ = 0.3 drags the probe less than the file's μ = 0.8 at the same frame.
    let drag = |metrics: &str| -> f64 {
        let last: Vec<f64> = metrics
            .lines()
            .last()
            .unwrap()
            .split(',')
            .map(|v| v.parse().unwrap())
            .collect();
        last[2].abs() / last[4]
    };
    let file_out = dir.path().join("file");
    let o = run_small(&file_out, &["--quiet", "--set", "time.frame_rate_hz=2"]);
    assert!(o.status.success(), "stderr: {}", text(&o.stderr));
    let file_metrics = std::fs::read_to_string(file_out.join("metrics.csv")).unwrap();
    let (low, high) = (drag(&metrics), drag(&file_metrics));
    assert!(low < 0.8 * high, "μ 0.3: {low}, μ 0.8: {high}");
    // summary.json records the overrides, the scenario as run and the same
    // per-frame metrics as metrics.csv.
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    assert_eq!(summary["overrides"][1], "probe.friction=0.3");
    assert_eq!(summary["scenario"]["probe"]["friction"], 0.3);
    assert_eq!(summary["scenario"]["time"]["frame_rate_hz"], 2.0);
    let frames = summary["run"]["frames"].as_array().unwrap();
    assert_eq!(frames.len(), metrics.lines().count() - 1);
    for (row, frame) in metrics.lines().skip(1).zip(frames) {
        let cols: Vec<f64> = row.split(',').map(|v| v.parse().unwrap()).collect();
        assert_eq!(frame["frame"], cols[0] as u64);
        for k in 0..3 {
            assert_eq!(
                frame["probe_force_n"][k].as_f64().unwrap(),
                cols[2 + k],
                "{row}"
            );
        }
        assert_eq!(frame["newton_iterations"], cols[8] as u64);
    }
    assert!(
        summary["skinpatch_version"].is_string()
            && summary["run"]["quality"]["tets"].as_u64() > Some(1000)
    );
    for (set, needle) in [
        (
            "probe.radius_mm=\"big\"",
            "--set: probe.radius_mm: invalid type",
        ),
        ("probe.radus_mm=1.0", "did you mean radius_mm?"),
        ("probe.friction=-1", "probe.friction"),
        ("probe", "--set probe: expected key=value"),
        (
            "probe.shape.x=1",
            "--set probe.shape.x: probe.shape is a value",
        ),
        (
            "render.lights.3.intensity=1",
            "with --set: render.lights: invalid type",
        ),
    ] {
        let o = run_small(&out, &["--set", set]);
        let err = text(&o.stderr);
        assert!(!o.status.success() && err.contains(needle), "{set}: {err}");
    }
}

/// A build without HDF5 refuses `frames_vtkhdf` before writing anything,
/// naming the key and how to get a build that has it.
#[cfg(not(feature = "vtkhdf"))]
#[test]
fn vtkhdf_without_the_feature_is_a_clear_error() {
    let dir = tempfile::tempdir().unwrap();
    let (out, o) = run_press_small_with(dir.path(), "\n[output]\nframes_vtkhdf = true\n");
    assert!(!o.status.success());
    let stderr = text(&o.stderr);
    for needle in ["output.frames_vtkhdf", "--features vtkhdf", "libhdf5-dev"] {
        assert!(stderr.contains(needle), "{needle}: {stderr}");
    }
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert!(!out.exists(), "nothing written");
}

/// The library example (`examples/press_api.rs`, built by `cargo test`)
/// runs the press on patch_3k with a changed modulus, and what its
/// callback read from the fields equals what the run wrote to metrics.csv.
#[test]
fn the_api_example_reads_the_fields_the_run_writes() {
    // target/<profile>/deps/cli-… → target/<profile>/examples/press_api
    let exe = std::env::current_exe().unwrap();
    let example = exe
        .parent()
        .and_then(Path::parent)
        .unwrap()
        .join("examples")
        .join(format!("press_api{}", std::env::consts::EXE_SUFFIX));
    assert!(
        example.exists(),
        "{} is missing: cargo test builds the examples",
        example.display()
    );
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("api");
    let o = Command::new(&example)
        .args(["examples/press.toml", "--dermis-kpa", "75", "--mesh"])
        .arg(root().join("meshes/patch_3k.node"))
        .arg("--out")
        .arg(&out)
        .current_dir(root())
        .output()
        .unwrap();
    assert!(o.status.success(), "stderr: {}", text(&o.stderr));
    assert!(
        text(&o.stderr).contains("dermis E = 75 kPa"),
        "{}",
        text(&o.stderr)
    );
    let stdout = text(&o.stdout);
    let rows: Vec<Vec<f64>> = stdout
        .lines()
        .skip(1)
        .take_while(|l| !l.starts_with("peak"))
        .map(|l| l.split_whitespace().map(|v| v.parse().unwrap()).collect())
        .collect();
    assert_eq!(rows.len(), 61, "{stdout}");
    let metrics = std::fs::read_to_string(out.join("metrics.csv")).unwrap();
    let header: Vec<&str> = metrics.lines().next().unwrap().split(',').collect();
    let column = |name: &str| header.iter().position(|h| *h == name).unwrap();
    for (row, line) in rows.iter().zip(metrics.lines().skip(1)) {
        let m: Vec<f64> = line.split(',').map(|v| v.parse().unwrap()).collect();
        assert_eq!(row[0], m[column("frame")]);
        // Printed to 5 and 4 decimals.
        assert!(
            (row[2] - m[column("probe_force_z_n")]).abs() <= 5e-6,
            "{row:?} vs {line}"
        );
        assert!(
            (row[3] - m[column("contact_area_mm2")]).abs() <= 5e-5,
            "{row:?} vs {line}"
        );
        assert!(
            (row[4] - m[column("rs_max")]).abs() <= 5e-5,
            "{row:?} vs {line}"
        );
        assert!(
            (row[5] - m[column("rt_min")]).abs() <= 5e-5,
            "{row:?} vs {line}"
        );
    }
    let peak = rows.iter().map(|r| r[2]).fold(f64::MIN, f64::max);
    assert!(peak > 0.05, "{stdout}");
    assert!(
        stdout.contains(&format!("peak force {peak:.5} N")),
        "{stdout}"
    );
    // The largest displacement is the press depth, 1 mm, give or take the
    // drag's tangential pull.
    let u = rows.iter().map(|r| r[7]).fold(0.0, f64::max);
    assert!((0.9..1.5).contains(&u), "{u}");
}

/// `skinpatch tiles split` and `join` round-trip a map bit for bit; a file
/// without a texel size and an unknown action are clear errors.
#[test]
fn tiles_split_and_join_round_trip() {
    use skinpatch::micro::io::{read_exr, write_exr, MapDefaults, TexelSize};
    use skinpatch::micro::{DisplacementMap, Edge};
    let dir = tempfile::tempdir().unwrap();
    let map = DisplacementMap::from_fn(150, 90, 12.5, Edge::Clamp, |i, j| {
        ((i * 7 + j * 13) % 29) as f32 * 0.125 - 1.0
    });
    let file = dir.path().join("map.exr");
    write_exr(&file, &map).unwrap();
    let folder = dir.path().join("map.tiles");
    let p = |p: &std::path::Path| p.to_str().unwrap().to_string();
    let o = skinpatch(&[
        "tiles",
        "split",
        &p(&file),
        "-o",
        &p(&folder),
        "--tile",
        "64",
    ]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    assert!(
        text(&o.stdout).contains("3 × 2 tiles of 64"),
        "{}",
        text(&o.stdout)
    );
    assert!(folder.join("tile_0002_0001.exr").is_file());
    let joined = dir.path().join("joined.exr");
    let o = skinpatch(&["tiles", "join", &p(&folder), "-o", &p(&joined)]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    let defaults = MapDefaults {
        texel: TexelSize::Um(1.0),
        height_unit_um: 1.0,
        edge: Edge::Wrap,
    };
    assert_eq!(read_exr(&joined, &defaults).unwrap(), map);
    // A 16-bit PNG without skinpatch metadata needs --texel-um.
    let png = dir.path().join("plain.png");
    image::ImageBuffer::<image::Luma<u16>, _>::from_fn(20, 20, |i, j| {
        image::Luma([(i * j) as u16])
    })
    .save(&png)
    .unwrap();
    let o = skinpatch(&["tiles", "split", &p(&png), "-o", &p(&folder)]);
    assert!(!o.status.success());
    assert!(
        text(&o.stderr).contains("--texel-um"),
        "{}",
        text(&o.stderr)
    );
    // An unknown action is refused by name.
    let o = skinpatch(&["tiles", "merge", &p(&folder), "-o", &p(&joined)]);
    assert!(!o.status.success());
    assert!(
        text(&o.stderr).contains("unrecognized subcommand 'merge'"),
        "{}",
        text(&o.stderr)
    );
}

/// A tiled neutral map (`map` naming a tiled map's folder) runs on the GPU
/// chains tile by tile and writes every frame as a tiled map, equal to the
/// run of the same map held whole within 1e-5 of the height range; the
/// keys that need the map whole are refused by name.
#[test]
fn a_tiled_neutral_map_runs_tile_by_tile() {
    use skinpatch::micro::io::{read_exr, write_exr, MapDefaults, TexelSize};
    use skinpatch::micro::procedural::{generate, SkinParams};
    use skinpatch::micro::tiled::TiledMap;
    let dir = tempfile::tempdir().unwrap();
    let map = generate(&SkinParams {
        size_px: 320,
        extent_mm: 10.0,
        seed: 4,
        ..SkinParams::default()
    })
    .unwrap();
    let whole_file = dir.path().join("neutral.exr");
    write_exr(&whole_file, &map).unwrap();
    let tiles = dir.path().join("neutral.tiles");
    TiledMap::write(&tiles, &map, 128).unwrap();
    let section = |file: &std::path::Path| {
        format!(
            "\n[microstructure]\nmap = \"{}\"\nframe_stride = 3\nformats = [\"exr\"]\n",
            file.display()
        )
    };
    let runs = [tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap()];
    let (tiled_out, o) = run_press_small_with(runs[0].path(), &section(&tiles));
    if !o.status.success() && text(&o.stderr).contains("no usable GPU adapter") {
        crate::common::skip("no GPU adapter");
        return;
    }
    assert!(o.status.success(), "stderr: {}", text(&o.stderr));
    assert!(
        text(&o.stdout).contains("tiled map of 3 × 3 tiles"),
        "{}",
        text(&o.stdout)
    );
    let (whole_out, o) = run_press_small_with(runs[1].path(), &section(&whole_file));
    assert!(o.status.success(), "stderr: {}", text(&o.stderr));
    let defaults = MapDefaults {
        texel: TexelSize::Um(1.0),
        height_unit_um: 1.0,
        edge: skinpatch::micro::Edge::Wrap,
    };
    let (lo, hi) = map.range();
    for frame in ["0000", "0006"] {
        let tiled = TiledMap::open(&tiled_out.join(format!("micro/height_{frame}.tiles")))
            .unwrap()
            .read_all()
            .unwrap();
        let whole = read_exr(
            &whole_out.join(format!("micro/height_{frame}.exr")),
            &defaults,
        )
        .unwrap();
        let worst = tiled
            .data
            .iter()
            .zip(&whole.data)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0f32, f32::max)
            / (hi - lo);
        assert!(worst <= 1e-5, "frame {frame}: tiled − whole {worst:e}");
        assert!(tiled_out
            .join(format!("micro/height_{frame}.tiles/normal_0002_0002.exr"))
            .is_file());
    }
    assert!(tiled_out
        .join("micro/height_neutral.tiles/normal_0001_0001.exr")
        .is_file());
    // Keys that need the map whole.
    for (extra, key) in [
        ("roughness_table = true\n", "microstructure.roughness_table"),
        ("texel_um = 5.0\n", "microstructure.texel_um"),
    ] {
        let (_, o) = run_press_small_with(dir.path(), &(section(&tiles) + extra));
        assert!(!o.status.success());
        assert!(text(&o.stderr).contains(key), "{}", text(&o.stderr));
    }
    let png = section(&tiles).replace("formats = [\"exr\"]", "formats = [\"png16\"]");
    let (_, o) = run_press_small_with(dir.path(), &png);
    assert!(
        text(&o.stderr).contains("microstructure.formats"),
        "{}",
        text(&o.stderr)
    );
    let render = section(&tiles) + "[render]\nwidth_px = 64\nheight_px = 48\n";
    let (_, o) = run_press_small_with(dir.path(), &render);
    assert!(
        text(&o.stderr).contains("needs the map whole"),
        "{}",
        text(&o.stderr)
    );
}

/// `[microstructure.synthesis]` synthesizes the neutral map once: the run
/// writes it to `cache/` and a rerun reads it back instead of
/// synthesizing again; the neutral map the run writes is that map.
#[test]
fn a_synthesized_neutral_map_is_cached_between_runs() {
    use skinpatch::micro::io::{read_exr, MapDefaults, TexelSize};
    let dir = tempfile::tempdir().unwrap();
    let section =
        "\n[microstructure]\nframe_stride = 6\nformats = [\"exr\"]\nnormal_maps = false\n\
        [microstructure.synthesis]\nsize_px = 128\nlevels = 2\n\
        [microstructure.synthesis.exemplar_generated]\nextent_mm = 0.64\n\
        [microstructure.synthesis.exemplar_generated.skin]\nsize_px = 128\n";
    let (out, o) = run_press_small_with(dir.path(), section);
    assert!(o.status.success(), "stderr: {}", text(&o.stderr));
    let cached: Vec<_> = std::fs::read_dir(out.join("cache"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    assert_eq!(cached.len(), 1, "{cached:?}");
    let name = cached[0]
        .file_name()
        .unwrap()
        .to_string_lossy()
        .into_owned();
    assert!(
        name.starts_with("synthesis-") && name.ends_with(".exr"),
        "{name}"
    );
    let modified = std::fs::metadata(&cached[0]).unwrap().modified().unwrap();
    let defaults = MapDefaults {
        texel: TexelSize::Um(1.0),
        height_unit_um: 1.0,
        edge: skinpatch::micro::Edge::Wrap,
    };
    let neutral = read_exr(&out.join("micro/height_neutral.exr"), &defaults).unwrap();
    let synthesized = read_exr(&cached[0], &defaults).unwrap();
    assert_eq!(neutral.data, synthesized.data);
    assert_eq!((neutral.width, neutral.texel_um), (128, 5.0));
    // The rerun reads the cache (the file is not written again) and gives
    // the same neutral map.
    let (_, o) = common::run_press_small_configured(dir.path(), section, |cmd| {
        cmd.arg("-v");
    });
    assert!(o.status.success(), "stderr: {}", text(&o.stderr));
    assert!(
        text(&o.stderr).contains("synthesized earlier"),
        "{}",
        text(&o.stderr)
    );
    assert_eq!(
        std::fs::metadata(&cached[0]).unwrap().modified().unwrap(),
        modified
    );
    let again = read_exr(&out.join("micro/height_neutral.exr"), &defaults).unwrap();
    assert_eq!(again.data, neutral.data);
    // A map file beside the synthesis is refused by name.
    let (_, o) = run_press_small_with(
        dir.path(),
        &section.replace(
            "normal_maps = false\n",
            "normal_maps = false\nmap = \"x.png\"\n",
        ),
    );
    assert!(!o.status.success());
    assert!(
        text(&o.stderr).contains("microstructure.synthesis"),
        "{}",
        text(&o.stderr)
    );
}

/// `skinpatch run` of a `[surface]` scenario: the patch's top surface
/// exported as an OBJ sequence by one run and animated by the next, with
/// `--set`, the report and `summary.json`; a missing surface file is an
/// error naming it, before the output folder is touched.
#[test]
fn surface_scenarios_run_from_the_command_line() {
    let dir = std::env::temp_dir().join(format!("skinpatch-cli-surface-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let (fem, out) = run_press_small_with(
        &dir,
        "\n[output]\nsurface_obj = true\nframes_vtu = false\nmesh_vtu = false\n",
    );
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert!(fem.join("surface/frame_0006.obj").exists());
    let scenario = dir.join("surface.toml");
    std::fs::write(
        &scenario,
        "[surface]\nfile = \"out/surface/frame_%04d.obj\"\nunits = \"mm\"\n\
         [output]\nstrain_images = true\nstrain_image_px = 64\n",
    )
    .unwrap();
    let animated = dir.join("animated");
    let args = [
        "run",
        scenario.to_str().unwrap(),
        "--output",
        animated.to_str().unwrap(),
        "--set",
        "surface.frame_rate_hz=6.0",
    ];
    let out = skinpatch(&args);
    let stdout = text(&out.stdout);
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert!(stdout.contains("7 frames at 6 Hz"), "{stdout}");
    assert!(animated.join("strain/rs_0006.png").exists());
    assert!(animated.join("frames/frame_0006.vtu").exists());
    let summary: serde_json::Value =
        serde_json::from_slice(&std::fs::read(animated.join("summary.json")).unwrap()).unwrap();
    assert_eq!(summary["run"]["frames"].as_array().unwrap().len(), 7);
    assert_eq!(summary["overrides"][0], "surface.frame_rate_hz=6.0");
    // The same record as a FEM run's: the same fields at the top and in
    // "run", with the kind of run named.
    let fem_summary: serde_json::Value =
        serde_json::from_slice(&std::fs::read(fem.join("summary.json")).unwrap()).unwrap();
    let keys = |v: &serde_json::Value| {
        let mut k: Vec<String> = v.as_object().unwrap().keys().cloned().collect();
        k.sort();
        k
    };
    assert_eq!(keys(&summary), keys(&fem_summary));
    assert_eq!(keys(&summary["run"]), keys(&fem_summary["run"]));
    assert_eq!(summary["run"]["kind"], "surface");
    assert_eq!(fem_summary["run"]["kind"], "fem");
    // The strain of the last frame is the FEM run's (same surface, exact OBJ).
    let metrics = std::fs::read_to_string(fem.join("metrics.csv")).unwrap();
    let header: Vec<&str> = metrics.lines().next().unwrap().split(',').collect();
    let last: Vec<&str> = metrics.lines().last().unwrap().split(',').collect();
    let col = |name: &str| {
        last[header.iter().position(|h| *h == name).unwrap()]
            .parse::<f64>()
            .unwrap()
    };
    let rs_max = summary["run"]["frames"][6]["rs_range"][1].as_f64().unwrap();
    assert!(
        (rs_max - col("rs_max")).abs() < 1e-12,
        "{rs_max} vs {}",
        col("rs_max")
    );
    // A missing file: an error naming it, nothing written.
    std::fs::write(&scenario, "[surface]\nfile = \"gone.glb\"\n").unwrap();
    let fresh = dir.join("fresh");
    let out = skinpatch(&[
        "run",
        scenario.to_str().unwrap(),
        "--output",
        fresh.to_str().unwrap(),
    ]);
    assert_eq!(out.status.code(), Some(1));
    assert!(
        text(&out.stderr).contains("gone.glb"),
        "{}",
        text(&out.stderr)
    );
    assert!(!fresh.exists());
    std::fs::remove_dir_all(&dir).ok();
}

/// The main job's material (ν = 0.49, locking-free, stable Neo-Hookean)
/// and friction keep every tet above 0.8 of its volume through the whole
/// press and drag, and each layer its volume within 1%, with no frame lost:
/// its FEM in memory, without maps or renders. Without the locking-free
/// tet's volume limit the smallest ratio here is 0.57 (docs/VERIFICATION.md,
/// "Tets that keep their volume": 0.826 measured).
#[test]
fn the_main_job_keeps_every_tet_above_four_fifths_of_its_volume() {
    use skinpatch::scenario::{Scenario, Setup};
    let path = crate::common::root().join("examples/press.toml");
    let mut scenario = Scenario::load(&path).unwrap();
    scenario.microstructure = None;
    scenario.render = None;
    let setup = Setup::from_scenario(&scenario, &path).unwrap();
    let mut run = skinpatch::pipeline::Run::new(&setup);
    let materials = &setup.simulation.tet_material;
    assert!(materials
        .iter()
        .all(|m| m.poisson >= 0.49 && m.volumetric == skinpatch::fem::Volumetric::LockingFree));
    let mut smallest = f64::INFINITY;
    for _ in 0..=setup.simulation.frames {
        let frame = run.step().unwrap();
        smallest = smallest.min(frame.metrics.min_volume_ratio);
        for region in frame.volumes {
            let change = region.deformed_mm3 / region.rest_mm3 - 1.0;
            assert!(change.abs() < 0.01, "{region:?}");
        }
    }
    assert!(
        (0.8..1.0).contains(&smallest),
        "smallest volume ratio {smallest}"
    );
}
