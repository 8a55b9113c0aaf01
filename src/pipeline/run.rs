//! The FEM run: [`run`] steps a validated [`Setup`] frame by frame (the
//! [`Stepper`](super::Stepper)) and writes each frame's outputs — the VTU
//! and VTKHDF frames, strain maps, the top surface's animation, the
//! deformed microstructure, rendered frames and a `metrics.csv` row. A
//! failing frame stops the run with an error naming it; everything written
//! before stays.

use super::outputs::{FrameInput, FrameOutputs, MapPiece, OutputSpec, RunKind, RunSummary};
use super::{plan, stepper::simulate, texel_mm, vtkhdf};
use crate::error::{Error, Result};
use crate::export::{self, FrameMetrics};
use crate::fem::contact::ContactForces;
use crate::mesh::{io, QualityReport, Vec3};
use crate::scenario::Setup;
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
    materials: &'a [crate::fem::Material],
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
/// (for progress, or to read results without going through files).
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
    let dir = &setup.outputs.dir;
    let mesh = &setup.mesh;
    // Everything that can fail before the first frame is checked before
    // the folder is touched: the planned output size, the adapters and
    // ffmpeg (opening the outputs).
    plan::check(setup, setup.outputs.force_large_output)?;
    let whole = MapPiece {
        tag: String::new(),
        triangles: None,
    };
    let mut outputs = FrameOutputs::open(output_spec(setup), vec![whole])?;
    write_rest_mesh(setup)?;
    outputs.start()?;
    let mut hdf = None;
    let mut exported = SurfaceExport::open(setup)?;
    let materials = &setup.simulation.tet_material;
    let result = simulate(setup, |m, stepper| {
        let (sim, contact) = (stepper.simulation(), stepper.contact_forces());
        let mut m = *m;
        let field = SurfaceField::new(&mesh.top, &mesh.positions, sim.positions());
        let (rs, rt, folded) = field.extremes();
        m.rs_range = [rs.0, rs.1];
        m.rt_range = [rt.0, rt.1];
        m.folded_vertices = folded;
        let (strains, stresses) = (std::cell::OnceCell::new(), std::cell::OnceCell::new());
        let grid = (outputs.wants_grid() || setup.write_vtkhdf).then(|| {
            let x = sim.positions();
            let strains = strains.get_or_init(|| ElementStrains::compute(mesh, x));
            let stresses = stresses.get_or_init(|| element_stresses(mesh, x, materials));
            export::frame_grid(mesh, x, strains, stresses, contact, &field)
        });
        if let (true, Some(grid)) = (setup.write_vtkhdf, &grid) {
            vtkhdf::push(&mut hdf, dir, setup, m.time_s, grid)?;
        }
        exported.push(sim.positions(), m.frame)?;
        let probe = setup.simulation.probe.as_ref().map(|p| p.pose(m.time_s));
        let geometry = |tessellate: usize| {
            crate::render::scene::build(mesh, sim.positions(), &field, probe.as_ref(), tessellate)
        };
        outputs.frame(&FrameInput {
            frame: m.frame,
            time_s: m.time_s,
            field: &field,
            grid: grid.as_ref(),
            geometry: &geometry,
        })?;
        outputs.row(m)?;
        on_frame(&Frame {
            metrics: &m,
            total_frames: setup.simulation.frames + 1,
            mesh,
            positions: sim.positions(),
            surface: &field,
            contact,
            materials,
            strains: &strains,
            stresses: &stresses,
        });
        Ok(())
    });
    // Closed whether or not the run finished: the steps so far stay. The
    // run's own error, if any, is the one reported.
    let closed = vtkhdf::finish(hdf);
    result?;
    closed?;
    exported.finish()?;
    let finished = outputs.finish()?;
    Ok(RunSummary {
        kind: RunKind::Fem,
        written: export::outputs::run_files(&setup.outputs.dir),
        quality: Some(QualityReport::of(mesh)),
        frames: finished.rows,
        micro_device: finished.micro_device,
    })
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
