//! `Run` (a stepped FEM run that owns its scenario) and `Frame` (one
//! solved frame's fields as numpy arrays).

use std::path::PathBuf;
use std::sync::{Arc, Mutex, OnceLock};

use numpy::{PyArray1, PyArray2, PyArray3};
use pyo3::exceptions::{PyRuntimeError, PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use skinpatch::export::FrameMetrics;
use skinpatch::fem::contact::ContactForces;
use skinpatch::mesh::Vec3;
use skinpatch::pipeline::MapDeformer;
use skinpatch::scenario::Setup;
use skinpatch::strain::volume::RegionVolume;
use skinpatch::strain::{element_stresses, ElementStrains, SurfaceField, TetStress};

use crate::arrays;
use crate::errors::{this_process, to_py, SkinpatchError};
use crate::scenario::Scenario;

type RunOf<'a> = skinpatch::pipeline::Run<'a>;

self_cell::self_cell!(
    /// A library run together with the setup it borrows.
    struct OwnedRun {
        owner: Arc<Setup>,
        #[not_covariant]
        dependent: RunOf,
    }
);

/// The microstructure engine of a run, made on first use and shared with
/// its frames.
type Deformer = Arc<Mutex<Option<MapDeformer>>>;

/// The run behind `inner`, reached through `&mut` (so never locked, never
/// poisoned: a panic cannot happen while it is held).
fn exclusive(inner: &mut Mutex<OwnedRun>) -> &mut OwnedRun {
    inner
        .get_mut()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// A FEM run stepped frame by frame. `Run(scenario)` keeps everything in
/// memory; `Run(scenario, outputs=True)` also writes the scenario's files
/// (VTU frames, metrics.csv, maps, renders — what `skinpatch run` writes)
/// into `output_dir` or the scenario's output folder.
///
/// `run.step()` solves the next frame on the scenario's probe path;
/// `run.step(probe_target=(x, y, z))` moves the probe's centre there
/// instead (from then on the path is no longer followed). Iterating
/// (`for frame in run`) steps to the scenario's last frame. The solve runs
/// without the GIL; Ctrl-C stops the run between frames. A run and its
/// frames may be used from any thread, one call at a time: a call while
/// another thread's step is running raises `RuntimeError` ("Already
/// borrowed").
#[pyclass(module = "skinpatch")]
pub struct Run {
    /// Behind a mutex only to be `Sync` (a library run holds `OnceCell`s):
    /// every method takes `&mut self`, which Python's borrow flag makes
    /// exclusive, and reaches it with `get_mut`, never locking.
    inner: Mutex<OwnedRun>,
    setup: Arc<Setup>,
    writing: bool,
    deformer: Deformer,
    written: Option<Vec<PathBuf>>,
}

#[pymethods]
impl Run {
    #[new]
    #[pyo3(signature = (scenario, outputs=false, output_dir=None))]
    fn new(
        py: Python<'_>,
        scenario: &Scenario,
        outputs: bool,
        output_dir: Option<PathBuf>,
    ) -> PyResult<Run> {
        let setup = match output_dir {
            Some(dir) => {
                let mut s = (*scenario.setup).clone();
                s.outputs.dir = dir;
                Arc::new(s)
            }
            None => scenario.setup.clone(),
        };
        this_process()?;
        let inner = if outputs {
            let made = py.detach(|| OwnedRun::try_new(setup.clone(), |s| RunOf::writing(s)));
            made.map_err(|e| to_py(py, e, Some(&scenario.source())))?
        } else {
            OwnedRun::new(setup.clone(), |s| RunOf::new(s))
        };
        Ok(Run {
            inner: Mutex::new(inner),
            setup,
            writing: outputs,
            deformer: Arc::new(Mutex::new(None)),
            written: None,
        })
    }

    /// Solves the next frame and returns it. `probe_target`: where the
    /// probe's centre is to be (mm); `probe_axis`: a capsule's axis.
    #[pyo3(signature = (probe_target=None, probe_axis=None))]
    fn step(
        &mut self,
        py: Python<'_>,
        probe_target: Option<Bound<'_, PyAny>>,
        probe_axis: Option<Bound<'_, PyAny>>,
    ) -> PyResult<Frame> {
        py.check_signals()?;
        this_process()?;
        let probe_target = point(py, "probe_target", probe_target)?;
        let probe_axis = point(py, "probe_axis", probe_axis)?;
        if self.written.is_some() {
            return Err(SkinpatchError::new_err(
                "the run is finished; start a new Run to go on",
            ));
        }
        let setup = self.setup.clone();
        let deformer = self.deformer.clone();
        let inner = exclusive(&mut self.inner);
        let solved = py.detach(move || {
            inner.with_dependent_mut(|_, run| {
                match (probe_target, probe_axis) {
                    (Some(c), Some(a)) => run.set_probe_pose(Vec3::from(c), Vec3::from(a))?,
                    (Some(c), None) => run.set_probe_target(Vec3::from(c))?,
                    (None, Some(_)) => {
                        return Err(skinpatch::Error::parameter(
                            "probe_axis",
                            "needs a probe_target with it",
                        ))
                    }
                    (None, None) => {}
                }
                let mut solved = Frame::of(&run.step()?, setup, deformer);
                solved.probe = run.probe_pose().map(|p| p.centre);
                Ok(solved)
            })
        });
        solved.map_err(|e| to_py(py, e, None))
    }

    fn __iter__(slf: PyRef<'_, Self>) -> PyRef<'_, Self> {
        slf
    }

    fn __next__(&mut self, py: Python<'_>) -> PyResult<Option<Frame>> {
        if self.written.is_some() || self.next_frame() >= self.scenario_frames() {
            if self.writing && self.written.is_none() {
                self.finish(py)?;
            }
            return Ok(None);
        }
        self.step(py, None, None).map(Some)
    }

    /// The frame `step` solves next (0: the rest frame).
    #[getter]
    fn next_frame(&mut self) -> usize {
        exclusive(&mut self.inner).with_dependent_mut(|_, run| run.next_frame())
    }

    /// Frames in the scenario, the rest frame included.
    #[getter]
    fn scenario_frames(&mut self) -> usize {
        exclusive(&mut self.inner).with_dependent_mut(|_, run| run.scenario_frames())
    }

    /// Time between frames (s).
    #[getter]
    fn frame_dt(&mut self) -> f64 {
        exclusive(&mut self.inner).with_dependent_mut(|_, run| run.frame_dt())
    }

    /// Ends the run; a run with outputs closes its files (the VTKHDF file,
    /// the surface GLB, the MP4) and returns the files written (an in-memory
    /// run: an empty list). Later steps raise. Iterating to the end and
    /// leaving a `with` block finish the run too.
    fn finish(&mut self, py: Python<'_>) -> PyResult<Vec<PathBuf>> {
        if let Some(w) = &self.written {
            return Ok(w.clone());
        }
        this_process()?;
        let inner = exclusive(&mut self.inner);
        let summary = py.detach(move || inner.with_dependent_mut(|_, run| run.close()));
        let written = summary.map_err(|e| to_py(py, e, None))?.written;
        self.written = Some(written.clone());
        Ok(written)
    }

    fn __enter__(slf: PyRef<'_, Self>) -> PyRef<'_, Self> {
        slf
    }

    #[pyo3(signature = (*_args))]
    fn __exit__(
        &mut self,
        py: Python<'_>,
        _args: &Bound<'_, pyo3::types::PyTuple>,
    ) -> PyResult<bool> {
        self.finish(py)?;
        Ok(false)
    }

    fn __repr__(&mut self) -> String {
        let (next, frames) = (self.next_frame(), self.scenario_frames());
        format!(
            "Run('{}', next frame {next} of {frames}{})",
            self.setup.name,
            if self.writing {
                ", writing outputs"
            } else {
                ""
            }
        )
    }
}

impl Drop for Run {
    fn drop(&mut self) {
        // A run with outputs left unfinished still closes its files.
        if self.writing && self.written.is_none() {
            if let Err(e) = exclusive(&mut self.inner).with_dependent_mut(|_, run| run.close()) {
                log::warn!("closing the run's files: {e}");
            }
        }
    }
}

/// One solved frame: its metrics and fields, copied out of the run (a
/// frame stays valid after later steps). Arrays are new on every access.
#[pyclass(module = "skinpatch", frozen)]
pub struct Frame {
    /// The probe's centre where the frame was solved.
    probe: Option<Vec3>,
    setup: Arc<Setup>,
    deformer: Deformer,
    metrics: FrameMetrics,
    positions: Vec<Vec3>,
    field: SurfaceField,
    contact: ContactForces,
    volumes: Vec<RegionVolume>,
    strains: OnceLock<ElementStrains>,
    stresses: OnceLock<Vec<TetStress>>,
}

impl Frame {
    fn of(frame: &skinpatch::pipeline::Frame<'_>, setup: Arc<Setup>, deformer: Deformer) -> Frame {
        Frame {
            probe: None,
            setup,
            deformer,
            metrics: *frame.metrics,
            positions: frame.positions.to_vec(),
            field: frame.surface.clone(),
            contact: frame.contact.clone(),
            volumes: frame.volumes.to_vec(),
            strains: OnceLock::new(),
            stresses: OnceLock::new(),
        }
    }

    fn strain_data(&self) -> PyResult<&ElementStrains> {
        this_process()?;
        Ok(self
            .strains
            .get_or_init(|| ElementStrains::compute(&self.setup.mesh, &self.positions)))
    }

    fn stress_data(&self) -> PyResult<&[TetStress]> {
        this_process()?;
        Ok(self
            .stresses
            // A Python run keeps the scenario's materials (it has no
            // set_materials), so the setup's are the frame's.
            .get_or_init(|| {
                let materials = &self.setup.simulation.tet_material;
                element_stresses(&self.setup.mesh, &self.positions, materials)
            }))
    }
}

#[pymethods]
impl Frame {
    /// Frame number (0: the rest frame).
    #[getter]
    fn index(&self) -> usize {
        self.metrics.frame
    }

    /// Simulated time (s).
    #[getter]
    fn time(&self) -> f64 {
        self.metrics.time_s
    }

    /// The frame's row of metrics.csv as a dict, by the same column names
    /// and with the same values.
    #[getter]
    fn metrics<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let m = &self.metrics;
        let d = PyDict::new(py);
        d.set_item("frame", m.frame)?;
        d.set_item("time_s", m.time_s)?;
        d.set_item("probe_force_x_n", m.probe_force_n[0])?;
        d.set_item("probe_force_y_n", m.probe_force_n[1])?;
        d.set_item("probe_force_z_n", m.probe_force_n[2])?;
        d.set_item("contact_nodes", m.contact_nodes)?;
        d.set_item("contact_area_mm2", m.contact_area_mm2)?;
        d.set_item("max_penetration_mm", m.max_penetration_mm)?;
        d.set_item("newton_iterations", m.newton_iterations)?;
        d.set_item("linear_iterations", m.linear_iterations)?;
        d.set_item("rel_residual", m.rel_residual)?;
        d.set_item("rs_min", m.rs_range[0])?;
        d.set_item("rs_max", m.rs_range[1])?;
        d.set_item("rt_min", m.rt_range[0])?;
        d.set_item("rt_max", m.rt_range[1])?;
        d.set_item("folded_vertices", m.folded_vertices)?;
        d.set_item("inverted_tets", m.inverted_tets)?;
        d.set_item("min_volume_ratio", m.min_volume_ratio)?;
        d.set_item("energy_balance", m.energy_balance)?;
        d.set_item("free_node_force_ratio", m.free_node_force_ratio)?;
        d.set_item("step_wall_s", m.step_wall_s)?;
        Ok(d)
    }

    /// Deformed vertex positions, `(n_vertices, 3)` float64, mm.
    #[getter]
    fn positions<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        arrays::vec3s(py, &self.positions)
    }

    /// Displacements from the rest positions, `(n_vertices, 3)` float64, mm.
    #[getter]
    fn displacements<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let d: Vec<Vec3> = self
            .positions
            .iter()
            .zip(&self.setup.mesh.positions)
            .map(|(x, p)| x - p)
            .collect();
        arrays::vec3s(py, &d)
    }

    /// Principal stretches of every tet, λ1 ≥ λ2 ≥ λ3, `(n_tets, 3)` float64.
    #[getter]
    fn principal_stretches<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let flat = self
            .strain_data()?
            .tets
            .iter()
            .flat_map(|s| s.stretch.iter().copied().collect::<Vec<_>>())
            .collect();
        arrays::rows(py, flat, 3)
    }

    /// Principal (Biot) strains of every tet, λ − 1 in the order of
    /// `principal_stretches`, `(n_tets, 3)` float64.
    #[getter]
    fn principal_strains<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let flat = self
            .strain_data()?
            .tets
            .iter()
            .flat_map(|s| s.biot().iter().copied().collect::<Vec<_>>())
            .collect();
        arrays::rows(py, flat, 3)
    }

    /// Volume ratio J = det F of every tet, `(n_tets,)` float64.
    #[getter]
    fn volume_ratio<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray1<f64>>> {
        Ok(PyArray1::from_vec(
            py,
            self.strain_data()?
                .tets
                .iter()
                .map(|s| s.volume_ratio())
                .collect(),
        ))
    }

    /// Surface stretch ratios (r_s, r_t) at every vertex, `(n_vertices, 2)`
    /// float64: the top-surface vertices' area-weighted averages, NaN off
    /// the top surface (as in the VTU frames).
    #[getter]
    fn surface_stretch<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let mut flat = vec![f64::NAN; 2 * self.positions.len()];
        for (k, &v) in self.setup.mesh.top.vertices.iter().enumerate() {
            let svd = self.field.vertices[k].strain().svd;
            flat[2 * v] = svd.rs;
            flat[2 * v + 1] = svd.rt;
        }
        arrays::rows(py, flat, 2)
    }

    /// The probe's centre where the frame was solved, `(3,)` float64, mm
    /// (None without a probe).
    #[getter]
    fn probe_centre<'py>(&self, py: Python<'py>) -> Option<Bound<'py, PyArray1<f64>>> {
        self.probe
            .map(|c| PyArray1::from_vec(py, vec![c.x, c.y, c.z]))
    }

    /// The force the skin exerts on the probe, `(3,)` float64, N.
    #[getter]
    fn probe_force<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        PyArray1::from_vec(py, self.metrics.probe_force_n.to_vec())
    }

    /// Vertices in contact with the probe, ascending, `(n_contact,)` int64.
    #[getter]
    fn contact_nodes<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<i64>> {
        arrays::indices(py, self.contact.nodes.iter().copied())
    }

    /// The probe's force on each contact node, `(n_contact, 3)` float64, N.
    #[getter]
    fn contact_forces<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        arrays::vec3s(py, &self.contact.force_n)
    }

    /// Contact pressure at each contact node (normal force over the node's
    /// share of the deformed surface), `(n_contact,)` float64, N/mm² (MPa).
    #[getter]
    fn contact_pressure<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        let c = &self.contact;
        PyArray1::from_vec(py, (0..c.nodes.len()).map(|k| c.pressure(k)).collect())
    }

    /// Cauchy stress of every tet, `(n_tets, 3, 3)` float64, N/mm² (MPa).
    #[getter]
    fn stresses<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray3<f64>>> {
        let m: Vec<_> = self.stress_data()?.iter().map(|s| s.cauchy).collect();
        arrays::mat3s(py, &m)
    }

    /// Von Mises stress of every tet, `(n_tets,)` float64, N/mm² (MPa).
    #[getter]
    fn von_mises<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray1<f64>>> {
        Ok(PyArray1::from_vec(
            py,
            self.stress_data()?.iter().map(|s| s.von_mises()).collect(),
        ))
    }

    /// Each region's volume: `{region: {"rest_mm3", "deformed_mm3",
    /// "change", "min_volume_ratio", "tets_below"}}` (the frame's
    /// volume.csv row; `tets_below` counts tets under
    /// `solver.warn_volume_ratio`).
    #[getter]
    fn region_volumes<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let out = PyDict::new(py);
        for r in &self.volumes {
            let d = PyDict::new(py);
            d.set_item("rest_mm3", r.rest_mm3)?;
            d.set_item("deformed_mm3", r.deformed_mm3)?;
            d.set_item("change", r.change())?;
            d.set_item("min_volume_ratio", r.min_volume_ratio)?;
            d.set_item("tets_below", r.tets_below)?;
            out.set_item(&r.name, d)?;
        }
        Ok(out)
    }

    /// The microstructure deformed by this frame's surface strain:
    /// `(height, width)` float32 heights in µm, row v, column u. Runs on
    /// the GPU when an adapter is usable, else on the CPU reference stages
    /// (as `skinpatch run` does). The scenario needs a `[microstructure]`
    /// with a whole (untiled) map.
    fn deformed_map<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f32>>> {
        let micro = self.setup.outputs.micro.as_ref().ok_or_else(|| {
            SkinpatchError::new_err("the scenario has no [microstructure] to deform")
        })?;
        this_process()?;
        let deformer = self.deformer.clone();
        let frame = self.metrics.frame;
        let map = py.detach(|| {
            let mut slot = deformer.lock().unwrap_or_else(|p| p.into_inner());
            if slot.is_none() {
                *slot = Some(MapDeformer::new(micro)?);
            }
            slot.as_mut()
                .expect("made above")
                .deform(micro, &self.field, frame)
        });
        let map = map.map_err(|e| to_py(py, e, None))?;
        heights_um(py, &map)
    }

    /// Writes the frame as a VTU file with the arrays, names and encoding of
    /// `skinpatch run`'s `frames/frame_NNNN.vtu`.
    fn write_vtu(&self, py: Python<'_>, path: PathBuf) -> PyResult<()> {
        let grid = skinpatch::export::frame_grid(
            &self.setup.mesh,
            &self.positions,
            self.strain_data()?,
            self.stress_data()?,
            &self.contact,
            &self.field,
        );
        let format = self.setup.outputs.vtu_format;
        py.detach(|| skinpatch::mesh::io::write_vtu_as(&path, &grid, format))
            .map_err(|e| to_py(py, e, None))
    }

    fn __repr__(&self) -> String {
        let f = self.metrics.probe_force_n;
        format!(
            "Frame({}, t = {} s, probe force ({:.4}, {:.4}, {:.4}) N, {} contact nodes)",
            self.metrics.frame,
            self.metrics.time_s,
            f[0],
            f[1],
            f[2],
            self.contact.nodes.len()
        )
    }
}

/// A displacement map's heights in µm as a `(height, width)` float32 array.
pub fn heights_um<'py>(
    py: Python<'py>,
    map: &skinpatch::micro::DisplacementMap,
) -> PyResult<Bound<'py, PyArray2<f32>>> {
    let unit = map.height_unit_um as f32;
    let data: Vec<f32> = map.data.iter().map(|&h| h * unit).collect();
    arrays::rows(py, data, map.width).map_err(|e| PyRuntimeError::new_err(e.to_string()))
}

/// A point or direction argument: three real numbers (a tuple, list or
/// array). Complex values are refused, where numpy would drop their
/// imaginary parts with only a warning.
fn point(
    py: Python<'_>,
    name: &str,
    value: Option<Bound<'_, PyAny>>,
) -> PyResult<Option<[f64; 3]>> {
    let Some(value) = value.filter(|v| !v.is_none()) else {
        return Ok(None);
    };
    let kind: Option<String> = py
        .import("numpy")?
        .call_method1("asarray", (&value,))
        .and_then(|a| a.getattr("dtype")?.getattr("kind")?.extract())
        .ok();
    if kind.as_deref() == Some("c") {
        return Err(PyValueError::new_err(format!(
            "{name}: complex values; give three real numbers (mm)"
        )));
    }
    value
        .extract::<[f64; 3]>()
        .map(Some)
        .map_err(|e| PyTypeError::new_err(format!("{name}: three real numbers expected ({e})")))
}
