//! `frames.vtkhdf` (feature `vtkhdf`): every step holds exactly what the
//! frame's VTU holds, the connectivity and unchanged arrays are stored once,
//! and VTK's own reader (the Python `vtk` package, when installed; `.ci/run`
//! requires it) reads the same grid and arrays as from the VTUs.
//!
//! A test binary of its own (the others are modules of `tests/main`): it
//! needs the `vtkhdf` feature, and building the whole suite a second time
//! with that feature would cost minutes for these few cases.

#[allow(dead_code)]
#[path = "main/common.rs"]
mod common;

use std::path::Path;

use hdf5_metno as hdf5;
use skinpatch::mesh::io::{self, Values};

/// Runs `press_small` (7 frames on patch_3k) writing both the VTUs and
/// `frames.vtkhdf` with the given precision and compression.
fn run(
    precision: &str,
    compression: &str,
) -> (skinpatch::pipeline::FemRunSummary, tempfile::TempDir) {
    common::run_fixture("press_small.toml", |text| {
        format!(
            "{text}\n[output]\nframes_vtkhdf = true\nvtu_precision = \"{precision}\"\n\
             vtu_compression = \"{compression}\"\n"
        )
    })
}

fn ints(file: &hdf5::File, name: &str) -> Vec<i64> {
    file.dataset(name).unwrap().read_raw::<i64>().unwrap()
}

/// Rows `from .. from + rows` of a dataset, flattened, as f64.
fn block(file: &hdf5::File, name: &str, from: usize, rows: usize) -> Vec<f64> {
    let ds = file.dataset(name).unwrap();
    let shape = ds.shape();
    let width = shape.get(1).copied().unwrap_or(1);
    let dtype = ds.dtype().unwrap();
    let all: Vec<f64> = if dtype.is::<f32>() {
        ds.read_raw::<f32>()
            .unwrap()
            .into_iter()
            .map(f64::from)
            .collect()
    } else if dtype.is::<i32>() {
        ds.read_raw::<i32>()
            .unwrap()
            .into_iter()
            .map(f64::from)
            .collect()
    } else {
        ds.read_raw::<f64>().unwrap()
    };
    all[from * width..(from + rows) * width].to_vec()
}

fn floats(values: &Values) -> Vec<f64> {
    match values {
        Values::F64(v) => v.clone(),
        Values::I32(v) => v.iter().map(|&x| f64::from(x)).collect(),
    }
}

/// Equal value for value (NaN equal to NaN).
fn same(a: &[f64], b: &[f64]) -> bool {
    a.len() == b.len()
        && a.iter()
            .zip(b)
            .all(|(x, y)| x == y || (x.is_nan() && y.is_nan()))
}

fn check_against_vtus(out: &Path, summary: &skinpatch::pipeline::FemRunSummary) {
    let path = out.join("frames.vtkhdf");
    assert!(summary.written.contains(&path), "{:?}", summary.written);
    let file = hdf5::File::open(&path).unwrap();
    let root = file.group("VTKHDF").unwrap();
    let version: Vec<i64> = root.attr("Version").unwrap().read_raw().unwrap();
    assert_eq!(version, [2, 0]);
    let kind: hdf5::types::FixedAscii<16> = root.attr("Type").unwrap().read_scalar().unwrap();
    assert_eq!(kind.as_str(), "UnstructuredGrid");
    let steps: i64 = root
        .group("Steps")
        .unwrap()
        .attr("NSteps")
        .unwrap()
        .read_scalar()
        .unwrap();
    assert_eq!(steps as usize, summary.frames.len());
    let times = file
        .dataset("VTKHDF/Steps/Values")
        .unwrap()
        .read_raw::<f64>()
        .unwrap();
    let expected: Vec<f64> = summary.frames.iter().map(|m| m.time_s).collect();
    assert_eq!(times, expected);

    let first = io::read_vtu(&out.join("frames/frame_0000.vtu")).unwrap();
    let (n_points, n_cells) = (first.points.len(), first.tets.len());
    // The connectivity once, and every step pointing at it.
    assert_eq!(ints(&file, "VTKHDF/NumberOfPoints"), [n_points as i64]);
    assert_eq!(ints(&file, "VTKHDF/NumberOfCells"), [n_cells as i64]);
    let connectivity: Vec<i64> = first.tets.iter().flatten().map(|&v| v as i64).collect();
    assert_eq!(ints(&file, "VTKHDF/Connectivity"), connectivity);
    assert_eq!(ints(&file, "VTKHDF/Offsets").len(), n_cells + 1);
    for name in ["CellOffsets", "ConnectivityIdOffsets", "PartOffsets"] {
        let v = ints(&file, &format!("VTKHDF/Steps/{name}"));
        assert_eq!(v, vec![0; steps as usize], "{name}");
    }
    // The region ids do not change: stored once.
    assert_eq!(
        file.dataset("VTKHDF/CellData/region").unwrap().shape(),
        [n_cells]
    );
    let point_offsets = ints(&file, "VTKHDF/Steps/PointOffsets");
    for (k, m) in summary.frames.iter().enumerate() {
        let vtu = io::read_vtu(&out.join(format!("frames/frame_{:04}.vtu", m.frame))).unwrap();
        let points: Vec<f64> = vtu.points.iter().flat_map(|p| [p.x, p.y, p.z]).collect();
        let at = point_offsets[k] as usize;
        assert_eq!(at, k * n_points);
        assert!(
            same(&block(&file, "VTKHDF/Points", at, n_points), &points),
            "points of step {k}"
        );
        for (group, fields, rows) in [
            ("Point", &vtu.point_data, n_points),
            ("Cell", &vtu.cell_data, n_cells),
        ] {
            for f in fields.iter() {
                let offsets = ints(
                    &file,
                    &format!("VTKHDF/Steps/{group}DataOffsets/{}", f.name),
                );
                let got = block(
                    &file,
                    &format!("VTKHDF/{group}Data/{}", f.name),
                    offsets[k] as usize,
                    rows,
                );
                assert!(same(&got, &floats(&f.values)), "{} of step {k}", f.name);
            }
        }
    }
}

/// Every step equals its VTU (the VTU and the VTKHDF store the same
/// precision, so equal means bit for bit), for f64 compressed and f32
/// uncompressed files, and the f32 file is about half the f64 one.
#[test]
fn steps_equal_the_vtu_frames() {
    let mut sizes = Vec::new();
    for (precision, compression) in [("f64", "zlib"), ("f32", "none"), ("f64", "none")] {
        let (summary, dir) = run(precision, compression);
        check_against_vtus(dir.path(), &summary);
        sizes.push(
            std::fs::metadata(dir.path().join("frames.vtkhdf"))
                .unwrap()
                .len(),
        );
    }
    let [zlib64, raw32, raw64] = sizes[..] else {
        unreachable!()
    };
    assert!(zlib64 < raw64, "compression shrinks: {zlib64} vs {raw64}");
    let half = raw32 as f64 / raw64 as f64;
    assert!((0.4..0.6).contains(&half), "f32 / f64 = {half}");
}

/// VTK's reader (vtkHDFReader) gives, at every time step, the grid and
/// arrays that VTK's VTU reader gives for that frame.
#[test]
fn vtk_reads_the_same_grid_as_from_the_vtus() {
    let (summary, dir) = run("f64", "zlib");
    let hdf = dir.path().join("frames.vtkhdf");
    let vtus: Vec<String> = summary
        .frames
        .iter()
        .map(|m| {
            dir.path()
                .join(format!("frames/frame_{:04}.vtu", m.frame))
                .to_string_lossy()
                .into_owned()
        })
        .collect();
    let mut args = vec![hdf.to_str().unwrap()];
    args.extend(vtus.iter().map(String::as_str));
    let script = r#"
import sys, numpy as np
from vtkmodules.vtkIOHDF import vtkHDFReader
from vtkmodules.vtkIOXML import vtkXMLUnstructuredGridReader
from vtkmodules.vtkCommonExecutionModel import vtkStreamingDemandDrivenPipeline
from vtkmodules.util.numpy_support import vtk_to_numpy
path, vtus = sys.argv[1], sys.argv[2:]
reader = vtkHDFReader()
reader.SetFileName(path)
reader.UpdateInformation()
times = reader.GetOutputInformation(0).Get(vtkStreamingDemandDrivenPipeline.TIME_STEPS())
assert times is not None and len(times) == len(vtus), (times, len(vtus))
arrays = 0
for t, vtu in zip(times, vtus):
    reader.UpdateTimeStep(t)
    got = reader.GetOutputDataObject(0)
    x = vtkXMLUnstructuredGridReader()
    x.SetFileName(vtu)
    x.Update()
    want = x.GetOutput()
    assert got.GetNumberOfPoints() == want.GetNumberOfPoints(), (t, got.GetNumberOfPoints())
    assert got.GetNumberOfCells() == want.GetNumberOfCells(), (t, got.GetNumberOfCells())
    assert np.array_equal(vtk_to_numpy(got.GetPoints().GetData()), vtk_to_numpy(want.GetPoints().GetData()))
    assert np.array_equal(vtk_to_numpy(got.GetCells().GetConnectivityArray()),
                          vtk_to_numpy(want.GetCells().GetConnectivityArray()))
    assert set(vtk_to_numpy(got.GetCellTypesArray())) == {10}
    for kind in ("GetPointData", "GetCellData"):
        w, g = getattr(want, kind)(), getattr(got, kind)()
        for i in range(w.GetNumberOfArrays()):
            name = w.GetArrayName(i)
            a = g.GetArray(name)
            assert a is not None, (t, name)
            assert np.array_equal(vtk_to_numpy(a), vtk_to_numpy(w.GetArray(i)), equal_nan=True), (t, name)
            arrays += 1
print(len(times), arrays)
"#;
    let Some(out) = common::python_check("vtk", "SKINPATCH_REQUIRE_VTK", script, &args) else {
        return;
    };
    let counts: Vec<usize> = out.split_whitespace().map(|v| v.parse().unwrap()).collect();
    assert_eq!(counts[0], summary.frames.len(), "{out}");
    assert!(
        counts[1] >= 15 * summary.frames.len(),
        "arrays compared: {out}"
    );
}

/// A run that stops keeps the file with the frames it finished, readable.
#[test]
fn a_stopped_run_keeps_its_finished_steps() {
    let fixture = common::root().join("tests/fixtures/press_small.toml");
    let text = std::fs::read_to_string(&fixture).unwrap()
        + "\n[output]\nframes_vtkhdf = true\n[solver]\nmax_newton_iterations = 1\n";
    let scenario = skinpatch::scenario::Scenario::parse(&text, &fixture).unwrap();
    let mut setup = skinpatch::scenario::Setup::from_scenario(&scenario, &fixture).unwrap();
    let dir = tempfile::tempdir().unwrap();
    setup.outputs.dir = dir.path().to_path_buf();
    let err = skinpatch::pipeline::run(&setup, |_| {}).unwrap_err();
    assert!(err.to_string().contains("frame 1"), "{err}");
    let file = hdf5::File::open(dir.path().join("frames.vtkhdf")).unwrap();
    let steps: i64 = file
        .group("VTKHDF/Steps")
        .unwrap()
        .attr("NSteps")
        .unwrap()
        .read_scalar()
        .unwrap();
    assert_eq!(steps, 1);
    let vtu = io::read_vtu(&dir.path().join("frames/frame_0000.vtu")).unwrap();
    let points: Vec<f64> = vtu.points.iter().flat_map(|p| [p.x, p.y, p.z]).collect();
    assert!(same(
        &block(&file, "VTKHDF/Points", 0, vtu.points.len()),
        &points
    ));
}

/// A process started while the file is being written inherits its
/// descriptor (HDF5 does not set close-on-exec); the file must still open
/// once the writer is finished, while that process lives (with HDF5's file
/// lock the inherited descriptor kept it locked).
#[test]
fn a_child_process_does_not_keep_the_file_locked() {
    use skinpatch::export::vtkhdf::VtkHdfWriter;
    let mesh = common::one_tet();
    let grid = io::Grid::from_mesh(&mesh);
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("frames.vtkhdf");
    let mut writer = VtkHdfWriter::create(&path, &grid, io::VtuFormat::default()).unwrap();
    writer.push(0.0, &grid).unwrap();
    let mut child = std::process::Command::new("sleep")
        .arg("5")
        .spawn()
        .unwrap();
    writer.push(0.5, &grid).unwrap();
    assert_eq!(writer.steps(), 2);
    writer.finish().unwrap();
    let opened = hdf5::File::open(&path).map(|f| {
        f.group("VTKHDF/Steps")
            .and_then(|g| g.attr("NSteps"))
            .and_then(|a| a.read_scalar::<i64>())
    });
    child.kill().ok();
    child.wait().ok();
    assert_eq!(opened.unwrap().unwrap(), 2);
}
