//! The FEM run. [`Run`] is a run a caller steps frame by frame (through
//! the [`Stepper`](super::Stepper)): probe targets set from code, each
//! frame's fields read in memory, and — for [`Run::writing`] — each frame's
//! outputs written as it is solved: the VTU and VTKHDF frames, strain maps,
//! the top surface's animation, the deformed microstructure, rendered
//! frames, a `volume.csv` row (each region's volume change) and a
//! `metrics.csv` row. [`run`] steps one through a scenario's
//! frames. A failing frame stops a writing run with an error naming it;
//! everything written before stays.

use super::outputs::{FrameInput, FrameOutputs, MapPiece, OutputSpec, RunKind, RunSummary};
use super::{plan, texel_mm, vtkhdf, Stepper};
use crate::error::{Error, Result};
use crate::export::{self, FrameMetrics};
use crate::fem::contact::ContactForces;
use crate::fem::material::Material;
use crate::fem::probe::{ContactMode, Probe, ProbePose};
use crate::mesh::{io, QualityReport, TetMesh, Vec3};
use crate::scenario::{Setup, SimulationSetup};
use crate::strain::volume::{self, region_volumes, RegionVolume};
use crate::strain::{element_stresses, ElementStrains, SurfaceField, TetStress};
use crate::surface::AnimatedSurface;

/// What a FEM run produced.
pub type FemRunSummary = RunSummary<FrameMetrics>;

/// One finished frame as [`run`]'s callback sees it: the metrics row and the
/// frame's fields, borrowed for the duration of the call.
pub struct Frame<'a> {
    /// The frame's row of `metrics.csv` (probe force, contact, ranges, …).
    pub metrics: &'a FrameMetrics,
    /// Frames in the run, the rest frame included (for progress).
    pub total_frames: usize,
    /// The rest mesh (its `positions` are the rest positions, mm).
    pub mesh: &'a crate::mesh::TetMesh,
    /// Deformed positions of every mesh vertex (mm), indexed like the mesh.
    pub positions: &'a [Vec3],
    /// The deformation of the top surface in texture space: per top
    /// triangle T (eq. 10) and per top vertex its area-weighted average
    /// with stretch ratios and axes (eq. 11–13).
    pub surface: &'a SurfaceField,
    /// The probe's force on each node in contact, with the contact normal
    /// and the node's area: nodal contact pressure and shear traction.
    pub contact: &'a ContactForces,
    /// Each region's volume change and its tets below
    /// `solver.warn_volume_ratio` (the frame's row of `volume.csv`).
    pub volumes: &'a [RegionVolume],
    materials: &'a [Material],
    strains: &'a std::cell::OnceCell<ElementStrains>,
    stresses: &'a std::cell::OnceCell<Vec<TetStress>>,
}

impl Frame<'_> {
    /// Displacement of vertex `v` from its rest position (mm).
    pub fn displacement(&self, v: usize) -> Vec3 {
        self.positions[v] - self.mesh.positions[v]
    }

    /// Principal strains of every tet (computed on first use, and shared
    /// with the frame's VTU when frames are written).
    pub fn strains(&self) -> &ElementStrains {
        self.strains
            .get_or_init(|| ElementStrains::compute(self.mesh, self.positions))
    }

    /// Cauchy stress, von Mises stress and strain energy density of every
    /// tet (computed on first use, and shared with the frame's VTU).
    pub fn stresses(&self) -> &[TetStress] {
        self.stresses
            .get_or_init(|| element_stresses(self.mesh, self.positions, self.materials))
    }
}

/// Runs the scenario and writes its outputs; `on_frame` is called after
/// each frame's files are written, with the frame's metrics and fields
/// (for progress, or to read results without going through files). It is
/// [`Run::writing`] stepped through the scenario's frames; use [`Run`]
/// itself to drive the probe from code or to stop early.
///
/// ```
/// # fn main() -> skinpatch::Result<()> {
/// use skinpatch::scenario::Setup;
/// let mut setup = Setup::load(std::path::Path::new("tests/fixtures/press_small.toml"))?;
/// let out = std::env::temp_dir().join(format!("skinpatch-doc-{}", std::process::id()));
/// setup.outputs.dir = out.clone();
/// let (mut forces, mut peak_rs) = (Vec::new(), 0.0f64);
/// let summary = skinpatch::pipeline::run(&setup, |frame| {
///     forces.push(frame.metrics.probe_force_n[2]);
///     for v in &frame.surface.vertices {
///         peak_rs = peak_rs.max(v.strain().svd.rs);
///     }
/// })?;
/// assert_eq!(forces.len(), 7);
/// assert!(forces[3] > 0.01, "the skin pushes the probe back: {forces:?}");
/// assert!(peak_rs > 1.01, "the skin stretches around the probe");
/// assert!(summary.written.contains(&out.join("metrics.csv")));
/// std::fs::remove_dir_all(&out).ok();
/// # Ok(())
/// # }
/// ```
pub fn run(setup: &Setup, mut on_frame: impl FnMut(&Frame<'_>)) -> Result<FemRunSummary> {
    let mut run = Run::writing(setup)?;
    for _ in 0..=setup.simulation.frames {
        match run.step() {
            Ok(frame) => on_frame(&frame),
            // The files written so far stay; the run's own error is the
            // one reported.
            Err(e) => {
                run.close_after_error();
                return Err(e);
            }
        }
    }
    run.finish()
}

/// A FEM run a caller steps frame by frame: set the probe's target, step,
/// read the frame (positions, strains, stresses, contact), and stop when
/// it likes. [`Run::new`] keeps everything in memory; [`Run::writing`]
/// also writes the scenario's outputs, frame by frame as `skinpatch run`
/// does (which is this object stepped through the scenario's frames).
///
/// Without targets the probe follows the scenario's path. The first
/// [`Run::set_probe_target`] replaces the path from the next frame on: each
/// target becomes a keyframe at its frame's time, and the probe moves
/// linearly (in load steps, as any probe motion) from where it was, then
/// stays at the last target. The same targets give the same frames, bit for
/// bit; a scenario whose `path_mm` lists them solves to the same states.
///
/// A frame that fails leaves an in-memory run at its last good frame (the
/// failed target dropped), so the caller may try another; a writing run
/// stops at the first failure, keeping what it wrote.
///
/// ```
/// # fn main() -> skinpatch::Result<()> {
/// use skinpatch::pipeline::Run;
/// use skinpatch::scenario::Setup;
/// let setup = Setup::load(std::path::Path::new("tests/fixtures/press_small.toml"))?;
/// let mut run = Run::new(&setup);
/// let start = run.probe_pose().expect("the scenario has a probe").centre;
/// // Press straight down 0.1 mm a frame until the skin pushes back with 20 mN.
/// for k in 1..=10 {
///     run.set_probe_target(start - skinpatch::mesh::Vec3::z() * (0.1 * k as f64))?;
///     let frame = run.step()?;
///     if frame.contact.total().norm() >= 0.02 {
///         break;
///     }
/// }
/// let frame = run.frame().expect("a frame was solved");
/// assert!(frame.metrics.probe_force_n[2] >= 0.02);
/// assert!(frame.stresses().iter().any(|s| s.von_mises() > 0.0));
/// # Ok(())
/// # }
/// ```
pub struct Run<'a> {
    simulation: &'a SimulationSetup,
    mesh: &'a TetMesh,
    materials: std::borrow::Cow<'a, [Material]>,
    stepper: Stepper,
    probe: Option<Probe>,
    /// The target of the next frame, when set.
    target: Option<(Vec3, Option<Vec3>)>,
    /// Whether targets have replaced the scenario's path.
    driven: bool,
    writer: Option<Writer<'a>>,
    last: Option<LastFrame>,
    rows: Vec<FrameMetrics>,
    /// Why a writing run stopped.
    failed: Option<String>,
    /// Regions already warned about for over-compressed tets.
    volume_warned: Vec<bool>,
}

/// The fields of the last solved frame.
struct LastFrame {
    metrics: FrameMetrics,
    field: SurfaceField,
    volumes: Vec<RegionVolume>,
    strains: std::cell::OnceCell<ElementStrains>,
    stresses: std::cell::OnceCell<Vec<TetStress>>,
}

/// The files of a writing run.
struct Writer<'a> {
    setup: &'a Setup,
    outputs: FrameOutputs<'a, FrameMetrics>,
    hdf: Option<vtkhdf::Writer>,
    exported: SurfaceExport<'a>,
    volume: export::CsvFile,
}

impl<'a> Run<'a> {
    /// A run of `setup` kept in memory: it writes no files.
    pub fn new(setup: &'a Setup) -> Run<'a> {
        Run::from_parts(&setup.simulation, &setup.mesh)
    }

    /// A run of the simulation part of a setup on `mesh`, in memory.
    pub fn from_parts(simulation: &'a SimulationSetup, mesh: &'a TetMesh) -> Run<'a> {
        Run {
            simulation,
            mesh,
            materials: std::borrow::Cow::Borrowed(&simulation.tet_material),
            stepper: Stepper::new(simulation, mesh),
            probe: simulation.probe.clone(),
            target: None,
            driven: false,
            writer: None,
            last: None,
            rows: Vec::new(),
            failed: None,
            volume_warned: vec![false; mesh.regions.len()],
        }
    }

    /// A run that writes `setup`'s outputs as it goes. Everything that can
    /// fail before the first frame — the planned output size, the GPU
    /// adapter, ffmpeg — is checked before the output folder is touched.
    /// It writes at most the scenario's frames (the size that was checked).
    pub fn writing(setup: &'a Setup) -> Result<Run<'a>> {
        plan::check(setup, setup.outputs.force_large_output)?;
        let whole = MapPiece {
            tag: String::new(),
            triangles: None,
        };
        let mut outputs = FrameOutputs::open(output_spec(setup), vec![whole])?;
        write_rest_mesh(setup)?;
        outputs.start()?;
        let exported = SurfaceExport::open(setup)?;
        let volume = export::CsvFile::create(
            &setup.outputs.dir.join("volume.csv"),
            &volume_header(&setup.mesh),
        )?;
        let mut run = Run::new(setup);
        run.writer = Some(Writer {
            setup,
            outputs,
            hdf: None,
            exported,
            volume,
        });
        Ok(run)
    }

    /// The frame [`Run::step`] solves next (0: the rest state with the
    /// probe at its start).
    pub fn next_frame(&self) -> usize {
        self.stepper.next_frame()
    }

    /// Time between frames (s).
    pub fn frame_dt(&self) -> f64 {
        self.simulation.frame_dt
    }

    /// Frames in the scenario, the rest frame included.
    pub fn scenario_frames(&self) -> usize {
        self.simulation.frames + 1
    }

    /// The probe where the last frame was solved (before frame 0: where the
    /// run starts it); `None` without a probe.
    pub fn probe_pose(&self) -> Option<ProbePose> {
        let t = self.last.as_ref().map_or(0.0, |l| l.metrics.time_s);
        let probe = self.probe.as_ref()?;
        (!probe.path.points.is_empty()).then(|| probe.pose(t))
    }

    /// Where the probe's centre (mm) is to be at the next frame; a capsule
    /// keeps its axis. From the first target on, the scenario's path is
    /// no longer followed (see [`Run`]).
    pub fn set_probe_target(&mut self, centre: Vec3) -> Result<()> {
        self.set_target(centre, None)
    }

    /// [`Run::set_probe_target`] with the capsule's axis as well (any
    /// length but zero; normalised where used).
    pub fn set_probe_pose(&mut self, centre: Vec3, axis: Vec3) -> Result<()> {
        if !(axis.iter().all(|v| v.is_finite()) && axis.norm() > 0.0) {
            return Err(Error::parameter(
                "probe axis",
                format!(
                    "({}, {}, {}) must be finite and not zero",
                    axis.x, axis.y, axis.z
                ),
            ));
        }
        self.set_target(centre, Some(axis))
    }

    fn set_target(&mut self, centre: Vec3, axis: Option<Vec3>) -> Result<()> {
        if self.probe.is_none() {
            return Err(Error::parameter(
                "probe target",
                "the scenario has no [probe] to move",
            ));
        }
        if !centre.iter().all(|v| v.is_finite()) {
            return Err(Error::parameter(
                "probe target",
                format!(
                    "({}, {}, {}) mm must be finite",
                    centre.x, centre.y, centre.z
                ),
            ));
        }
        self.target = Some((centre, axis));
        Ok(())
    }

    /// New materials (one per tet) from the next frame on; the deformed
    /// state is kept.
    pub fn set_materials(&mut self, tet_material: Vec<Material>) -> Result<()> {
        if tet_material.len() != self.mesh.num_tets() {
            return Err(Error::parameter(
                "materials",
                format!(
                    "{} given for {} tets; one per tet",
                    tet_material.len(),
                    self.mesh.num_tets()
                ),
            ));
        }
        self.stepper.set_materials(self.mesh, &tet_material);
        self.materials = std::borrow::Cow::Owned(tet_material);
        Ok(())
    }

    /// The probe's contact mode from the next frame on.
    pub fn set_contact_mode(&mut self, mode: ContactMode) -> Result<()> {
        match self.probe.as_mut() {
            Some(p) => {
                p.mode = mode;
                Ok(())
            }
            None => Err(Error::parameter(
                "contact mode",
                "the scenario has no [probe]",
            )),
        }
    }

    /// Solves the next frame (and writes its files, for a writing run).
    pub fn step(&mut self) -> Result<Frame<'_>> {
        if let Some(why) = &self.failed {
            return Err(Error::Solver(format!("the run cannot go on: {why}")));
        }
        let frame = self.stepper.next_frame();
        if self.writer.is_some() && frame > self.simulation.frames {
            return Err(Error::parameter(
                "time.duration_s",
                format!(
                    "the run writes files for the scenario's {} frames and has written them \
                     all; make the scenario longer to write more",
                    self.simulation.frames + 1
                ),
            ));
        }
        let t = frame as f64 * self.simulation.frame_dt;
        let target = self.target.take();
        // An in-memory run goes back to its last good frame on failure.
        let before = self
            .writer
            .is_none()
            .then(|| (self.stepper.clone(), self.probe.clone(), self.driven));
        if let (Some(probe), Some(target)) = (self.probe.as_mut(), target) {
            let t_prev = self.last.as_ref().map(|l| l.metrics.time_s);
            drive(probe, &mut self.driven, t_prev, t, target);
        }
        let solved = self
            .stepper
            .step(self.simulation, self.mesh, self.probe.as_ref())
            .and_then(|m| self.finish_frame(m));
        if let Err(e) = solved {
            match before {
                Some((stepper, probe, driven)) => {
                    self.stepper = stepper;
                    self.probe = probe;
                    self.driven = driven;
                }
                None => self.failed = Some(format!("it stopped at an earlier error: {e}")),
            }
            return Err(e);
        }
        Ok(self.frame().expect("a frame was just solved"))
    }

    /// Fills a solved frame's surface ranges, keeps its fields and writes
    /// its files.
    fn finish_frame(&mut self, mut m: FrameMetrics) -> Result<()> {
        let (mesh, x) = (self.mesh, self.stepper.simulation().positions());
        let field = SurfaceField::new(&mesh.top, &mesh.positions, x);
        let (rs, rt, folded) = field.extremes();
        m.rs_range = [rs.0, rs.1];
        m.rt_range = [rt.0, rt.1];
        m.folded_vertices = folded;
        let threshold = self.simulation.warn_volume_ratio;
        let volumes = region_volumes(mesh, x, threshold);
        let model_of = |region: usize| {
            let id = mesh.regions[region].id;
            let tet = mesh.tet_region.iter().position(|&r| r == id);
            tet.map(|t| self.simulation.tet_material[t].model)
        };
        warn_compressed(&mut self.volume_warned, threshold, &m, &volumes, model_of);
        let last = LastFrame {
            metrics: m,
            field,
            volumes,
            strains: std::cell::OnceCell::new(),
            stresses: std::cell::OnceCell::new(),
        };
        if let Some(w) = self.writer.as_mut() {
            let pose = self.probe.as_ref().map(|p| p.pose(m.time_s));
            w.frame(
                &last,
                x,
                self.stepper.contact_forces(),
                &self.materials,
                pose,
            )?;
        }
        self.rows.push(m);
        self.last = Some(last);
        Ok(())
    }

    /// The last solved frame.
    pub fn frame(&self) -> Option<Frame<'_>> {
        let last = self.last.as_ref()?;
        Some(Frame {
            metrics: &last.metrics,
            total_frames: self.simulation.frames + 1,
            mesh: self.mesh,
            positions: self.stepper.simulation().positions(),
            surface: &last.field,
            contact: self.stepper.contact_forces(),
            volumes: &last.volumes,
            materials: &self.materials,
            strains: &last.strains,
            stresses: &last.stresses,
        })
    }

    /// Ends the run: a writing run closes its files (the surface GLB, the
    /// MP4, the VTKHDF file) and lists them. The summary holds every
    /// frame's metrics.
    pub fn finish(mut self) -> Result<FemRunSummary> {
        self.close()
    }

    /// [`Run::finish`] for a caller that cannot give the run up (one that
    /// owns it behind a reference, as the Python package does): the same
    /// summary, after which the run refuses further steps. A second call
    /// returns an empty summary.
    pub fn close(&mut self) -> Result<FemRunSummary> {
        let rows = std::mem::take(&mut self.rows);
        self.failed = Some("it was finished".into());
        let Some(w) = self.writer.take() else {
            return Ok(RunSummary {
                kind: RunKind::Fem,
                written: Vec::new(),
                quality: Some(QualityReport::of(self.mesh)),
                frames: rows,
                micro_device: None,
            });
        };
        vtkhdf::finish(w.hdf)?;
        w.exported.finish()?;
        let finished = w.outputs.finish()?;
        Ok(RunSummary {
            kind: RunKind::Fem,
            written: export::outputs::run_files(&w.setup.outputs.dir),
            quality: Some(QualityReport::of(self.mesh)),
            frames: finished.rows,
            micro_device: finished.micro_device,
        })
    }

    /// After a failed frame: closes what must be closed for the frames
    /// written so far to stay readable (the VTKHDF file).
    pub fn close_after_error(self) {
        if let Some(w) = self.writer {
            if let Err(e) = vtkhdf::finish(w.hdf) {
                log::warn!("{e}");
            }
        }
    }
}

/// Makes `target` the probe's keyframe at `t`. The first time, the
/// scenario's path is cut at the last frame (`t_prev`, its pose there kept
/// as a keyframe so the probe starts from where it was).
fn drive(
    probe: &mut Probe,
    driven: &mut bool,
    t_prev: Option<f64>,
    t: f64,
    (centre, axis): (Vec3, Option<Vec3>),
) {
    let axis = axis.unwrap_or_else(|| probe.pose(t_prev.unwrap_or(0.0)).axis);
    if !*driven {
        let start = t_prev.map(|tp| (tp, probe.pose(tp)));
        probe.path.points.clear();
        probe.axis.points.clear();
        if let Some((tp, pose)) = start {
            probe.path.points.push((tp, pose.centre));
            probe.axis.points.push((tp, pose.axis));
        }
        *driven = true;
    }
    probe.path.points.push((t, centre));
    probe.axis.points.push((t, axis));
}

impl Writer<'_> {
    /// Writes one frame's files and its metrics row.
    fn frame(
        &mut self,
        last: &LastFrame,
        x: &[Vec3],
        contact: &ContactForces,
        materials: &[Material],
        probe: Option<ProbePose>,
    ) -> Result<()> {
        let (setup, mesh, m) = (self.setup, &self.setup.mesh, &last.metrics);
        let grid = (self.outputs.wants_grid() || setup.write_vtkhdf).then(|| {
            let strains = last
                .strains
                .get_or_init(|| ElementStrains::compute(mesh, x));
            let stresses = last
                .stresses
                .get_or_init(|| element_stresses(mesh, x, materials));
            export::frame_grid(mesh, x, strains, stresses, contact, &last.field)
        });
        if let (true, Some(grid)) = (setup.write_vtkhdf, &grid) {
            vtkhdf::push(&mut self.hdf, &setup.outputs.dir, setup, m.time_s, grid)?;
        }
        self.exported.push(x, m.frame)?;
        let geometry = |tessellate: usize| {
            crate::render::scene::build(mesh, x, &last.field, probe.as_ref(), tessellate)
        };
        self.outputs.frame(&FrameInput {
            frame: m.frame,
            time_s: m.time_s,
            field: &last.field,
            grid: grid.as_ref(),
            geometry: &geometry,
        })?;
        self.volume
            .write_line(&volume_row(m.frame, m.time_s, &last.volumes))?;
        self.outputs.row(*m)
    }
}

/// Warns, once per region and run, of the first frame in which a
/// region has tets below the warning ratio, with the remedy that fits the
/// region's model (`model_of` gives it by region index).
fn warn_compressed(
    warned: &mut [bool],
    threshold: f64,
    m: &FrameMetrics,
    volumes: &[RegionVolume],
    model_of: impl Fn(usize) -> Option<crate::fem::Model>,
) {
    for (k, (v, warned)) in volumes.iter().zip(warned).enumerate() {
        if v.tets_below > 0 && !*warned {
            *warned = true;
            let remedy = match model_of(k) {
                Some(crate::fem::Model::Corotational) | None => format!(
                    "model = \"stable-neo-hookean\" in [material.{}] resists this \
                     (docs/SCENARIO.md, `model`)",
                    v.name
                ),
                // A Neo-Hookean energy already.
                Some(_) => format!(
                    "a Poisson's ratio closer to 0.5 in [material.{}] resists this \
                     (poisson_ratio, with volumetric = \"locking-free\" above 0.49), as does a \
                     gentler press",
                    v.name
                ),
            };
            log::warn!(
                "frame {}: {} tets of region '{}' are squeezed below volume ratio {threshold} \
                 (smallest {:.3}, region volume {:+.2}%), which no skin or fat does; {remedy}",
                m.frame,
                v.tets_below,
                v.name,
                v.min_volume_ratio,
                100.0 * v.change(),
            );
        }
    }
}

/// The header of `volume.csv`: per region its relative volume change,
/// smallest volume ratio and tets below the warning ratio.
fn volume_header(mesh: &TetMesh) -> String {
    let mut header = String::from("frame,time_s");
    for r in &mesh.regions {
        let name = volume::column_name(&r.name);
        header += &format!(",{name}_volume_change,{name}_min_volume_ratio,{name}_tets_below");
    }
    header
}

/// One frame's row of `volume.csv`.
fn volume_row(frame: usize, time_s: f64, volumes: &[RegionVolume]) -> String {
    let mut row = format!("{frame},{}", export::csv_number(time_s));
    for v in volumes {
        row += &format!(
            ",{},{},{}",
            export::csv_number(v.change()),
            export::csv_number(v.min_volume_ratio),
            v.tets_below
        );
    }
    row + "\n"
}

/// What the shared output stage needs of a FEM scenario.
fn output_spec(setup: &Setup) -> OutputSpec<'_> {
    let (lo, hi) = setup.mesh.bounds();
    let render = setup.outputs.render.as_ref();
    OutputSpec {
        outputs: &setup.outputs,
        extent_mm: (
            hi.x - lo.x,
            render.map_or(0.0, |r| texel_mm((lo, hi), r.texture_px)),
        ),
        frame_rate_hz: 1.0 / setup.simulation.frame_dt,
    }
}

/// The rest mesh as VTU and TetGen files, as asked for.
fn write_rest_mesh(setup: &Setup) -> Result<()> {
    let (dir, mesh) = (&setup.outputs.dir, &setup.mesh);
    if setup.write_mesh_vtu {
        let path = dir.join("mesh.vtu");
        io::write_vtu_as(&path, &io::Grid::from_mesh(mesh), setup.outputs.vtu_format)?;
    }
    if setup.write_mesh_tetgen {
        io::write_tetgen(mesh, &dir.join("mesh"))?;
    }
    Ok(())
}

/// The top surface's animation, when exported: an OBJ per frame as the
/// run goes, one GLB at the end.
struct SurfaceExport<'a> {
    setup: &'a Setup,
    surface: Option<AnimatedSurface>,
}

impl<'a> SurfaceExport<'a> {
    fn open(setup: &'a Setup) -> Result<SurfaceExport<'a>> {
        let mesh = &setup.mesh;
        let surface = (setup.write_surface_glb || setup.write_surface_obj).then(|| {
            AnimatedSurface::from_top(
                &setup.name,
                &mesh.top,
                &mesh.positions,
                &[],
                1.0 / setup.simulation.frame_dt,
            )
        });
        if setup.write_surface_obj {
            let folder = setup.outputs.dir.join("surface");
            std::fs::create_dir_all(&folder).map_err(|e| Error::io(&folder, e))?;
        }
        Ok(SurfaceExport { setup, surface })
    }

    /// Adds frame `frame` with the mesh's deformed `positions`.
    fn push(&mut self, positions: &[Vec3], frame: usize) -> Result<()> {
        let Some(surface) = self.surface.as_mut() else {
            return Ok(());
        };
        let top = &self.setup.mesh.top;
        surface
            .frames
            .push(top.vertices.iter().map(|&v| positions[v]).collect());
        if self.setup.write_surface_obj {
            let path = self
                .setup
                .outputs
                .dir
                .join("surface")
                .join(format!("frame_{frame:04}.obj"));
            crate::surface::obj::write_obj(&path, surface, Some(surface.frames.len() - 1))?;
        }
        Ok(())
    }

    /// Writes the GLB.
    fn finish(self) -> Result<()> {
        if let (true, Some(surface)) = (self.setup.write_surface_glb, &self.surface) {
            let path = self.setup.outputs.dir.join("surface.glb");
            // The neutral microstructure normal map, where the run wrote one
            // beside the file.
            let normals = self.setup.outputs.micro.as_ref().is_some_and(|m| {
                m.normal_maps && matches!(m.neutral, crate::scenario::NeutralMap::Whole(_))
            });
            let texture = normals.then_some("micro/normal_neutral.png");
            crate::surface::gltf::write_glb(&path, surface, texture)?;
        }
        Ok(())
    }
}
