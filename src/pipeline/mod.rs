//! Runs a validated [`Setup`] frame by frame and writes its outputs.
//!
//! Per frame: boundary conditions and probe pose at the frame time (split
//! into load substeps), quasi-static equilibrium with contact, the strain
//! fields (per tet and on the top surface), then the frame's VTU, strain
//! maps, deformed microstructure and a `metrics.csv` row. A failing frame
//! stops the run with an error naming it; everything written before stays.
//! [`fit`] runs a `skinpatch fit` samples file.
//!
//! The microstructure stages run on the GPU ([`crate::gpu::micro`]) when an
//! adapter exists and on their CPU references otherwise (see
//! [`crate::gpu::acquire`]); both write the same files.

use std::path::PathBuf;
use std::time::Instant;

pub mod plan;
mod render;
pub mod surface;
pub mod synth;
mod vtkhdf;

pub use render::{bench_render, roughness_curve, texel_mm, RenderBench};

use crate::error::{Error, Result};
use crate::export::{self, FrameMetrics, MetricsWriter};
use crate::fem::contact::{solve_with_contact, ContactState};
use crate::fem::integrate::{Dynamics, Simulation};
use crate::gpu::tiled::TileFrame;
use crate::mesh::{io, QualityReport, Vec3};
use crate::micro::tiled::TiledMap;
use crate::scenario::{MicroSetup, NeutralMap, Setup};
use crate::strain::{ElementStrains, StrainRaster, SurfaceField};

/// What a run produced.
#[derive(Clone, Debug, serde::Serialize)]
pub struct RunSummary {
    /// Files written, in order (frame files are summarised by the collection).
    pub written: Vec<PathBuf>,
    /// Quality of the mesh used.
    pub quality: QualityReport,
    /// Metrics of every frame.
    pub frames: Vec<FrameMetrics>,
    /// Where the microstructure stages ran (`None` without microstructure).
    pub micro_device: Option<String>,
}

/// Where the per-frame microstructure stages run.
enum MicroEngine {
    /// The GPU chain with the neutral map resident.
    Gpu(Box<crate::gpu::micro::GpuMicro>),
    /// The GPU chains of a tiled map, one per tile within the surface's reach.
    Tiled(Box<crate::gpu::tiled::TiledMicro>),
    /// The CPU references.
    Cpu,
}

impl MicroEngine {
    /// The GPU chain when an adapter is usable, else the CPU (an error
    /// instead when `SKINPATCH_REQUIRE_GPU=1`). A tiled map needs the GPU.
    fn new(micro: &MicroSetup) -> Result<MicroEngine> {
        if let NeutralMap::Tiled(map) = &micro.neutral {
            let ctx = crate::gpu::acquire()?.ok_or_else(|| {
                Error::Gpu(format!(
                    "microstructure.map {} is a tiled map, which only the GPU chain \
                     convolves, and there is no usable GPU adapter",
                    map.dir.display()
                ))
            })?;
            let mut chains = crate::gpu::tiled::TiledMicro::new(
                ctx,
                map.clone(),
                &micro.model,
                crate::strain::raster::DILATE_TEXELS,
            );
            chains.set_incremental(micro.incremental_tolerance);
            chains.set_raster_step(micro.raster_step)?;
            return Ok(MicroEngine::Tiled(Box::new(chains)));
        }
        let Some(ctx) = crate::gpu::acquire()? else {
            return Ok(MicroEngine::Cpu);
        };
        let name = ctx.describe();
        let built = crate::gpu::micro::GpuMicro::for_scenario(ctx, micro);
        Ok(match crate::gpu::or_cpu(built)? {
            Some(chain) => {
                log::info!("microstructure stages on the GPU: {name}");
                MicroEngine::Gpu(Box::new(chain))
            }
            None => MicroEngine::Cpu,
        })
    }

    /// Where the stages ran and, for a coarse strain raster, its step (the
    /// run's report).
    fn summary(&self, micro: &MicroSetup) -> String {
        let mut text = self.describe();
        if micro.raster_step > 1 {
            text += &format!(
                "; strain raster: one texel per {0} × {0} map texels",
                micro.raster_step
            );
        }
        text
    }

    fn describe(&self) -> String {
        match self {
            MicroEngine::Gpu(chain) => {
                let mut text = format!("GPU: {}", chain.context().describe());
                if let Some(share) = chain.pass_tile_share() {
                    text += &format!(
                        "; convolution passes ran on {:.1}% of the map's tiles",
                        100.0 * share
                    );
                    if let Some(t) = chain.incremental() {
                        text += &format!(
                            " (incremental frames, tolerance {})",
                            crate::error::shown(t)
                        );
                    }
                }
                text
            }
            MicroEngine::Tiled(chains) => {
                let (cols, rows) = chains.source().grid();
                format!(
                    "GPU, tiled map of {cols} × {rows} tiles, {} within the surface's reach",
                    chains.active_tiles().len()
                )
            }
            MicroEngine::Cpu => "CPU reference stages".into(),
        }
    }

    /// The deformed map of a frame and, when asked, its normals.
    fn deform(
        &mut self,
        micro: &MicroSetup,
        field: &SurfaceField,
    ) -> Result<(crate::micro::DisplacementMap, Option<Vec<[f32; 3]>>)> {
        match self {
            MicroEngine::Gpu(chain) => {
                let frame = chain.deform(field, micro.normal_maps)?;
                Ok((frame.map, frame.normals))
            }
            MicroEngine::Cpu => Ok((
                crate::micro::convolve::deform_stepped(
                    micro.neutral.whole("the CPU microstructure stages")?,
                    &micro.model,
                    field,
                    micro.raster_step,
                ),
                None,
            )),
            MicroEngine::Tiled(_) => unreachable!("tiled frames are written by write_tiled_frame"),
        }
    }

    /// A frame of a tiled map written as the tiled map `micro/height_TAG.tiles`:
    /// the tiles within the surface's reach deformed (with their normals),
    /// the others linked to the neutral tiles.
    fn write_tiled_frame(
        &mut self,
        micro: &MicroSetup,
        field: &SurfaceField,
        folder: &std::path::Path,
        frame: usize,
    ) -> Result<PathBuf> {
        let MicroEngine::Tiled(chains) = self else {
            unreachable!("only a tiled map has tiled frames");
        };
        let neutral = TiledMap::open(&folder.join("height_neutral.tiles"))?;
        let out_dir = folder.join(format!("height_{frame:04}.tiles"));
        let out = TiledMap::create(
            &out_dir,
            &neutral.metadata(neutral.width, neutral.height),
            neutral.tile,
        )?;
        chains.deform(field, micro.normal_maps, |col, row, tile| match tile {
            TileFrame::Deformed { map, normals } => {
                let stage = format!("the microstructure (GPU, tiled map, tile ({col}, {row}))");
                crate::error::check_finite(&stage, frame, map.width, 1, &map.data)?;
                if let Some(n) = &normals {
                    crate::error::check_finite(&stage, frame, map.width, 3, n.iter().flatten())?;
                }
                out.write_tile(col, row, &map, normals.as_deref())
            }
            TileFrame::Neutral => {
                link_or_copy(&neutral.tile_path(col, row), &out.tile_path(col, row))?;
                if micro.normal_maps {
                    link_or_copy(&neutral.normal_path(col, row), &out.normal_path(col, row))?;
                }
                Ok(())
            }
        })?;
        Ok(out_dir)
    }
}

/// Removes an earlier run's files from the output folder (and says so).
fn clear_previous_run(dir: &std::path::Path) -> Result<()> {
    let cleared = export::outputs::clear_previous_run(dir)?;
    if cleared > 0 {
        log::info!(
            "removed {cleared} files of an earlier run from {}",
            dir.display()
        );
    }
    Ok(())
}

/// `dst` as a hard link to `src` (no space taken), or a copy where the
/// file system has no links. An existing `dst` is removed first: copying
/// onto a link to `src` would truncate `src` itself.
fn link_or_copy(src: &std::path::Path, dst: &std::path::Path) -> Result<()> {
    match std::fs::remove_file(dst) {
        Err(e) if e.kind() != std::io::ErrorKind::NotFound => return Err(Error::io(dst, e)),
        _ => {}
    }
    if std::fs::hard_link(src, dst).is_ok() {
        return Ok(());
    }
    std::fs::copy(src, dst).map_err(|e| Error::io(dst, e))?;
    Ok(())
}

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
    strains: &'a std::cell::OnceCell<ElementStrains>,
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
/// setup.output_dir = out.clone();
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
pub fn run(setup: &Setup, mut on_frame: impl FnMut(&Frame<'_>)) -> Result<RunSummary> {
    let dir = &setup.output_dir;
    // Everything that can fail before the first frame is checked before
    // the folder is touched: the planned output size, the adapters and
    // ffmpeg.
    plan::check(setup, setup.force_large_output)?;
    let mut engine = match &setup.micro {
        Some(micro) => Some(MicroEngine::new(micro)?),
        None => None,
    };
    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    let mesh = &setup.mesh;
    let mut renderer = match &setup.render {
        Some(r) => Some(render::RenderEngine::new(
            dir,
            r,
            setup.micro.as_ref(),
            engine.as_ref(),
            {
                let (lo, hi) = mesh.bounds();
                (hi.x - lo.x, texel_mm((lo, hi), r.texture_px))
            },
        )?),
        None => None,
    };
    // Then the previous run's files go, so the folder holds one run.
    clear_previous_run(dir)?;
    std::fs::create_dir_all(dir.join("frames")).map_err(|e| Error::io(dir, e))?;
    let mut written = Vec::new();
    if setup.write_mesh_vtu {
        let path = dir.join("mesh.vtu");
        io::write_vtu_as(&path, &io::Grid::from_mesh(&setup.mesh), setup.vtu_format)?;
        written.push(path);
    }
    if setup.write_mesh_tetgen {
        let base = dir.join("mesh");
        io::write_tetgen(&setup.mesh, &base)?;
        written.extend(io::tetgen_paths(&base));
    }
    let metrics_path = dir.join("metrics.csv");
    let mut metrics = MetricsWriter::create(&metrics_path)?;
    written.push(metrics_path);
    let mut frames = Vec::new();
    let mut collection = Vec::new();
    if setup.strain_images.is_some() {
        let folder = dir.join("strain");
        std::fs::create_dir_all(&folder).map_err(|e| Error::io(&folder, e))?;
    }
    if let Some(micro) = &setup.micro {
        let (lo, hi) = setup.mesh.bounds();
        written.extend(write_neutral(dir, hi.x - lo.x, micro)?);
    }
    let mut hdf = None;
    // The top surface's animation, when exported.
    let mut exported = (setup.write_surface_glb || setup.write_surface_obj).then(|| {
        crate::surface::AnimatedSurface::from_top(
            &setup.name,
            &mesh.top,
            &mesh.positions,
            &[],
            1.0 / setup.simulation.frame_dt,
        )
    });
    if setup.write_surface_obj {
        let folder = dir.join("surface");
        std::fs::create_dir_all(&folder).map_err(|e| Error::io(&folder, e))?;
    }
    let result = simulate(setup, |m, sim| {
        let mut m = *m;
        let field = SurfaceField::new(&mesh.top, &mesh.positions, &sim.x);
        let (rs, rt, folded) = field.extremes();
        m.rs_range = [rs.0, rs.1];
        m.rt_range = [rt.0, rt.1];
        m.folded_vertices = folded;
        metrics.push(&m)?;
        let strains = std::cell::OnceCell::new();
        if setup.write_frames || setup.write_vtkhdf {
            let strains = strains.get_or_init(|| ElementStrains::compute(mesh, &sim.x));
            let grid = export::frame_grid(mesh, &sim.x, strains, &field);
            if setup.write_frames {
                collection.push((
                    m.time_s,
                    export::write_frame(dir, m.frame, &grid, setup.vtu_format)?,
                ));
                // Rewritten (atomically) after every frame, so a killed
                // run's frames open in ParaView too.
                export::write_collection(dir, &collection)?;
            }
            if setup.write_vtkhdf {
                vtkhdf::push(&mut hdf, dir, setup, m.time_s, &grid)?;
            }
        }
        if let Some(images) = setup.strain_images {
            let raster = StrainRaster::new(&field, images.px, images.px);
            export::strain_images::StrainImages::new(&raster, images.range).write(dir, m.frame)?;
        }
        if let Some(surface) = exported.as_mut() {
            surface
                .frames
                .push(mesh.top.vertices.iter().map(|&v| sim.x[v]).collect());
            if setup.write_surface_obj {
                let path = dir
                    .join("surface")
                    .join(format!("frame_{:04}.obj", m.frame));
                crate::surface::obj::write_obj(&path, surface, Some(surface.frames.len() - 1))?;
            }
        }
        let mut fresh_normals = false;
        if let (Some(micro), Some(engine)) = (&setup.micro, engine.as_mut()) {
            if m.frame % micro.frame_stride == 0 && matches!(engine, MicroEngine::Tiled(_)) {
                engine.write_tiled_frame(micro, &field, &dir.join("micro"), m.frame)?;
            } else if m.frame % micro.frame_stride == 0 {
                let (deformed, normals) = engine.deform(micro, &field)?;
                let stage = format!("the microstructure ({})", engine.describe());
                crate::error::check_finite(&stage, m.frame, deformed.width, 1, &deformed.data)?;
                if let Some(n) = &normals {
                    crate::error::check_finite(
                        &format!("{stage}, normals"),
                        m.frame,
                        deformed.width,
                        3,
                        n.iter().flatten(),
                    )?;
                }
                fresh_normals = micro.normal_maps;
                let folder = dir.join("micro");
                let tag = format!("{:04}", m.frame);
                write_micro_frame(&folder, &tag, micro, &deformed, normals)?;
            }
        }
        if let (Some(r), Some(renderer)) = (&setup.render, renderer.as_mut()) {
            if m.frame % r.frame_stride == 0 {
                let probe = setup.simulation.probe.as_ref().map(|p| p.pose(m.time_s));
                let geometry =
                    crate::render::scene::build(mesh, &sim.x, &field, probe.as_ref(), r.tessellate);
                renderer.frame(&geometry, &field, engine.as_mut(), m.frame, fresh_normals)?;
            }
        }
        frames.push(m);
        on_frame(&Frame {
            metrics: &m,
            total_frames: setup.simulation.frames + 1,
            mesh,
            positions: &sim.x,
            surface: &field,
            strains: &strains,
        });
        Ok(())
    });
    if !collection.is_empty() {
        written.push(dir.join("frames.pvd"));
    }
    // Closed whether or not the run finished: the steps so far stay. The
    // run's own error, if any, is the one reported.
    let closed = vtkhdf::finish(hdf);
    result?;
    written.extend(closed?);
    if setup.write_surface_obj {
        written.push(dir.join("surface"));
    }
    if let (true, Some(surface)) = (setup.write_surface_glb, &exported) {
        let path = dir.join("surface.glb");
        crate::surface::gltf::write_glb(&path, surface)?;
        written.push(path);
    }
    if let (Some(r), Some(renderer)) = (&setup.render, &renderer) {
        written.extend(renderer.finish(r, 1.0 / setup.simulation.frame_dt)?);
    }
    Ok(RunSummary {
        written,
        quality: QualityReport::of(&setup.mesh),
        frames,
        micro_device: engine
            .as_ref()
            .zip(setup.micro.as_ref())
            .map(|(e, m)| e.summary(m)),
    })
}

/// Writes the neutral map (and its normals) under `micro/`; warns when the
/// map's texel size disagrees with the patch it is stretched over.
fn write_neutral(
    dir: &std::path::Path,
    patch_width_mm: f64,
    micro: &MicroSetup,
) -> Result<Vec<PathBuf>> {
    let folder = dir.join("micro");
    std::fs::create_dir_all(&folder).map_err(|e| Error::io(&folder, e))?;
    let map = match &micro.neutral {
        NeutralMap::Whole(map) => map,
        NeutralMap::Tiled(tiled) => return write_neutral_tiles(&folder, micro, tiled),
    };
    let patch_texel_um = patch_width_mm * 1000.0 / map.width as f64;
    if (map.texel_um / patch_texel_um - 1.0).abs() > 0.01 {
        log::warn!(
            "the microstructure map has {:.3} µm texels but spans the {:.1} mm patch at {:.3} µm per texel; \
             kernel widths follow the patch",
            map.texel_um,
            patch_width_mm,
            patch_texel_um
        );
    }
    let mut written = write_micro_frame(&folder, "neutral", micro, map, None)?;
    if micro.roughness_table {
        let ratios: Vec<f64> = (0..=14).map(|k| 0.7 + 0.05 * k as f64).collect();
        let table = crate::micro::roughness::tabulate(map, &micro.model, &ratios);
        let mut csv = String::from("stretch_ratio,beckmann_m\n");
        for (r, m) in &table.points {
            csv.push_str(&format!("{r:.2},{m:e}\n"));
        }
        let path = folder.join("roughness.csv");
        io::write_atomically(&path, csv.as_bytes())?;
        written.push(path);
    }
    Ok(written)
}

/// The neutral tiled map as `micro/height_neutral.tiles`: its tiles linked
/// (or copied) from the input and, when asked, each tile's normals (from the
/// tile and the one-texel ring of its neighbours around it, so they equal
/// the whole map's).
fn write_neutral_tiles(
    folder: &std::path::Path,
    micro: &MicroSetup,
    tiled: &TiledMap,
) -> Result<Vec<PathBuf>> {
    let dir = folder.join("height_neutral.tiles");
    let out = TiledMap::create(&dir, &tiled.metadata(tiled.width, tiled.height), tiled.tile)?;
    let (cols, rows) = tiled.grid();
    for row in 0..rows {
        for col in 0..cols {
            link_or_copy(&tiled.tile_path(col, row), &out.tile_path(col, row))?;
            if micro.normal_maps {
                let [x0, y0, w, h] = tiled.tile_rect(col, row);
                let ring = tiled.read_window([x0 as isize - 1, y0 as isize - 1], [w + 2, h + 2])?;
                let normals = crate::micro::normals::normal_map(&ring);
                let inner = crate::micro::tiled::crop_values(&normals, w + 2, [1, 1, w, h]);
                let meta = tiled.metadata(w, h);
                crate::micro::io::write_normal_exr(&out.normal_path(col, row), &inner, &meta)?;
            }
        }
    }
    Ok(vec![dir])
}

/// Writes a map as `height_TAG.{png,exr}` and, when asked, its normals as
/// `normal_TAG.{png,exr}` (`normals` if already computed, else from the map).
fn write_micro_frame(
    folder: &std::path::Path,
    tag: &str,
    micro: &MicroSetup,
    map: &crate::micro::DisplacementMap,
    normals: Option<Vec<[f32; 3]>>,
) -> Result<Vec<PathBuf>> {
    use crate::micro::io;
    let mut written = Vec::new();
    if micro.png16 {
        let path = folder.join(format!("height_{tag}.png"));
        io::write_png16(&path, map)?;
        written.push(path);
    }
    if micro.exr {
        let path = folder.join(format!("height_{tag}.exr"));
        io::write_exr(&path, map)?;
        written.push(path);
    }
    if micro.normal_maps {
        let path = folder.join(format!("normal_{tag}.png"));
        let normals = normals.unwrap_or_else(|| crate::micro::normals::normal_map(map));
        io::write_normal_png16(&path, &normals, map)?;
        written.push(path);
        if micro.exr {
            let path = folder.join(format!("normal_{tag}.exr"));
            io::write_normal_exr(&path, &normals, map)?;
            written.push(path);
        }
    }
    Ok(written)
}

/// Figures of one benchmark run (see [`bench_fem`]).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct BenchFigures {
    /// Frames simulated (after the rest frame).
    pub frames: usize,
    /// Wall time of those frames (s).
    pub wall_s: f64,
    /// Newton iterations.
    pub newton_iterations: usize,
    /// Linear-solver iterations.
    pub linear_iterations: usize,
    /// Solver time split.
    pub timings: crate::fem::integrate::Timings,
}

/// Simulates the first `frames` frames of `setup` without writing anything
/// and reports where the time went.
pub fn bench_fem(setup: &Setup, frames: usize) -> Result<BenchFigures> {
    let mut setup = setup.clone();
    setup.simulation.frames = frames.min(setup.simulation.frames);
    let mut figures = BenchFigures::default();
    let start = Instant::now();
    let timings = simulate(&setup, |m, _| {
        figures.newton_iterations += m.newton_iterations;
        figures.linear_iterations += m.linear_iterations;
        Ok(())
    })?;
    figures.wall_s = start.elapsed().as_secs_f64();
    figures.frames = setup.simulation.frames;
    figures.timings = timings;
    Ok(figures)
}

/// The frame loop; `emit` receives each finished frame. Returns the solver
/// timings.
fn simulate(
    setup: &Setup,
    mut emit: impl FnMut(&FrameMetrics, &Simulation) -> Result<()>,
) -> Result<crate::fem::integrate::Timings> {
    let s = &setup.simulation;
    let mut stepper = Stepper::new(s, &setup.mesh);
    for _ in 0..=s.frames {
        let m = stepper.step(s, &setup.mesh, s.probe.as_ref())?;
        emit(&m, stepper.simulation())?;
    }
    Ok(stepper.simulation().timings)
}

/// The state carried from one frame to the next: the simulation, the
/// contact set, the last solved state (for the predicted start of the next
/// solve) and the warnings already given. [`simulate`] steps it through a
/// scenario's frames; the viewer steps it frame by frame with a probe path
/// that grows as the user drives it — the same frames, so a recorded path
/// replays to the same states.
#[derive(Clone)]
pub struct Stepper {
    sim: Simulation,
    contact: ContactState,
    no_loads: Vec<Vec3>,
    frame: usize,
    t_prev: f64,
    // The last solved state and its time.
    last_solved: Option<(Vec<Vec3>, f64)>,
    inverted_before: usize,
    split_before: bool,
}

impl Stepper {
    /// The patch at rest, before frame 0.
    pub fn new(s: &crate::scenario::SimulationSetup, mesh: &crate::mesh::TetMesh) -> Stepper {
        let mut sim = Simulation::new(mesh, &s.tet_material);
        sim.settings = s.newton;
        sim.dynamics = s.dynamics;
        let sides: Vec<usize> = s.sets.sides.iter().flatten().copied().collect();
        Stepper {
            sim,
            contact: ContactState::new(mesh, &sides),
            no_loads: vec![Vec3::zeros(); mesh.num_vertices()],
            frame: 0,
            t_prev: 0.0,
            last_solved: None,
            inverted_before: 0,
            split_before: false,
        }
    }

    /// The frame [`Stepper::step`] solves next.
    pub fn next_frame(&self) -> usize {
        self.frame
    }

    /// The simulation as last solved.
    pub fn simulation(&self) -> &Simulation {
        &self.sim
    }

    /// New materials (one per tet) from the next frame on; the deformed
    /// state is kept.
    pub fn set_materials(
        &mut self,
        mesh: &crate::mesh::TetMesh,
        tet_material: &[crate::fem::material::Material],
    ) {
        self.sim.set_materials(mesh, tet_material);
    }

    /// Solves the next frame (at `frame × frame_dt`) with `probe` — the
    /// scenario's, or one whose path reaches at least that time — and
    /// returns its metrics. After an error the stepper must not be stepped
    /// again.
    pub fn step(
        &mut self,
        s: &crate::scenario::SimulationSetup,
        mesh: &crate::mesh::TetMesh,
        probe: Option<&crate::fem::contact::Probe>,
    ) -> Result<FrameMetrics> {
        let sim = &mut self.sim;
        let frame = self.frame;
        let t_prev = self.t_prev;
        let start = Instant::now();
        let t = frame as f64 * s.frame_dt;
        let mut m = FrameMetrics {
            frame,
            time_s: t,
            ..Default::default()
        };
        // A probe that starts inside the skin is pressed in from just above
        // it during frame 0, in steps like any other motion.
        let mut lift = 0.0;
        let substeps = if frame == 0 {
            let (height, n) = press_in(probe, mesh, sim.position_tol());
            lift = height;
            n
        } else {
            let n = load_steps(probe, s.substeps, t_prev, t, frame)?;
            if n > s.substeps {
                if !self.split_before {
                    log::warn!(
                        "frame {frame}: the probe moves more than {MAX_PROBE_STEP} of its radius in \
                         a load step; the frame is split into {n} load steps (and so is any later \
                         frame that needs it) so that it cannot pass through the skin"
                    );
                    self.split_before = true;
                }
                log::info!("frame {frame}: {n} load steps for the probe's motion");
            }
            if let Some(d) = s.dynamics {
                // A split frame takes shorter backward-Euler steps.
                let dt = if n == s.substeps {
                    d.dt
                } else {
                    (t - t_prev) / n as f64
                };
                sim.dynamics = Some(Dynamics { dt, ..d });
            }
            n
        };
        for k in 1..=substeps {
            let ts = t_prev + (t - t_prev) * k as f64 / substeps as f64;
            let context = format!("frame {frame} (t = {ts:.4} s)");
            let (filters, targets) = s.boundary.constraints(&s.sets, &mesh.positions, ts);
            if sim.dynamics.is_some() {
                sim.begin_step();
            }
            // Start from the last state moved on by the last increment
            // (constant velocity), scaled to this step's length (the contact
            // solve starts its candidates where they were solved).
            if s.predict {
                let solved = sim.x.clone();
                let t_solved = t_prev + (t - t_prev) * (k - 1) as f64 / substeps as f64;
                if let Some((before, t_before)) = &self.last_solved {
                    if t_solved > *t_before {
                        let ratio = (ts - t_solved) / (t_solved - t_before);
                        sim.predict(before, ratio.min(MAX_PREDICTION_RATIO));
                    }
                }
                self.last_solved = Some((solved, t_solved));
            }
            match probe {
                Some(probe) => {
                    let r = solve_with_contact(
                        sim,
                        (&filters, &targets, &self.no_loads),
                        &probe
                            .pose(ts)
                            .lifted(lift * (1.0 - k as f64 / substeps as f64)),
                        probe.mode,
                        &mut self.contact,
                        &context,
                    )?;
                    m.probe_force_n = r.probe_force.into();
                    m.contact_nodes = r.contact_nodes;
                    m.contact_area_mm2 = r.contact_area_mm2;
                    m.max_penetration_mm = r.max_penetration_mm;
                    m.newton_iterations += r.newton_iterations;
                    m.linear_iterations += r.cg_iterations;
                    m.rel_residual = r.rel_residual;
                }
                None => {
                    sim.filters = filters;
                    sim.targets = targets;
                    let st = sim.solve_static(&context)?;
                    m.newton_iterations += st.iterations;
                    m.linear_iterations += st.cg_iterations;
                    m.rel_residual = st.rel_residual;
                }
            }
            sim.end_step();
        }
        self.t_prev = t;
        self.frame += 1;
        let inversion = sim.inversion();
        m.inverted_tets = inversion.inverted;
        m.min_volume_ratio = inversion.min_volume_ratio;
        check_inversion(
            &m,
            mesh.num_tets(),
            s.max_inverted_fraction,
            &mut self.inverted_before,
        )?;
        m.step_wall_s = start.elapsed().as_secs_f64();
        log::info!(
            "frame {frame}: t = {t:.4} s, probe force {:?} N, {} contact nodes, {} Newton / {} CG iterations",
            m.probe_force_n,
            m.contact_nodes,
            m.newton_iterations,
            m.linear_iterations
        );
        Ok(m)
    }
}

/// Frame 0's load steps and the height (mm) its probe starts above its
/// t = 0 pose: one step from that pose, or, for a probe that starts inside
/// the skin, steps of at most [`MAX_PROBE_STEP`] of its radius from just
/// above the patch (with a warning).
fn press_in(
    probe: Option<&crate::fem::contact::Probe>,
    mesh: &crate::mesh::TetMesh,
    tol: f64,
) -> (f64, usize) {
    let Some(probe) = probe else {
        return (0.0, 1);
    };
    let lift = embedded_lift(mesh, &probe.pose(0.0), tol);
    if lift == 0.0 {
        return (0.0, 1);
    }
    let n = ((lift / (MAX_PROBE_STEP * probe.radius_mm())).ceil() as usize).max(1);
    log::warn!(
        "the probe starts inside the skin at t = 0; frame 0 presses it in from {lift:.4} mm \
         higher in {n} load steps (start its path above the surface to choose how it gets there)"
    );
    (lift, n)
}

/// How far (mm) `pose` must be lifted so that no node of `mesh` at rest is
/// inside it by more than `tol`: 0 when none is, else the height that takes
/// its lowest point to the top of the patch.
fn embedded_lift(
    mesh: &crate::mesh::TetMesh,
    pose: &crate::fem::contact::ProbePose,
    tol: f64,
) -> f64 {
    let inside = mesh.positions.iter().any(|p| pose.distance(p).0 < -tol);
    if !inside {
        return 0.0;
    }
    let (_, hi) = mesh.bounds();
    (hi.z - pose.lowest_z()).max(0.0)
}

/// Largest distance the probe may move in one load step, as a fraction of
/// its radius. A frame whose probe moves further is split into more load
/// steps than `time.substeps` asks for, so no surface node can be passed
/// over (a node passed in one step would end outside the probe and never
/// touch it).
pub const MAX_PROBE_STEP: f64 = 0.25;

/// Longest prediction, in increments of the last step. A step much longer
/// than the last (the first after a frame split for a fast probe) would
/// carry the skin on at the old speed after the load has stopped, through
/// and past the probe.
const MAX_PREDICTION_RATIO: f64 = 1.5;

/// Most load steps a frame may be split into (configured or automatic).
pub const MAX_LOAD_STEPS: usize = 10_000;

/// Load steps for the frame from `t0` to `t1`: `configured`, or the
/// smallest multiple of it in which no step moves the probe more than
/// [`MAX_PROBE_STEP`] of its radius. An error when that takes more than
/// [`MAX_LOAD_STEPS`].
fn load_steps(
    probe: Option<&crate::fem::contact::Probe>,
    configured: usize,
    t0: f64,
    t1: f64,
    frame: usize,
) -> Result<usize> {
    let Some(probe) = probe else {
        return Ok(configured);
    };
    let limit = MAX_PROBE_STEP * probe.radius_mm();
    let mut n = configured;
    loop {
        let at = |k: usize| t0 + (t1 - t0) * k as f64 / n as f64;
        let worst = (0..n)
            .map(|k| probe.travel(at(k), at(k + 1)))
            .fold(0.0, f64::max);
        if worst <= limit {
            return Ok(n);
        }
        let next = n.saturating_mul((worst / limit).ceil().max(2.0) as usize);
        if next > MAX_LOAD_STEPS {
            return Err(Error::Solver(format!(
                "frame {frame} (t = {t1:.4} s): the probe moves {:.4} mm, {:.1} times its radius; \
                 more than {MAX_LOAD_STEPS} load steps of {MAX_PROBE_STEP} radius would be needed \
                 for contact to follow it. Slow the probe path or raise time.frame_rate_hz",
                probe.travel(t0, t1),
                probe.travel(t0, t1) / probe.radius_mm()
            )));
        }
        n = next;
    }
}

/// Applies the inversion rule to a solved frame: a warning when inverted
/// tets appear (or their number changes from none), an error when more
/// than `max_fraction` of the `tets` are inverted. The frame is not
/// written then: its state has no physical meaning.
fn check_inversion(
    m: &FrameMetrics,
    tets: usize,
    max_fraction: f64,
    inverted_before: &mut usize,
) -> Result<()> {
    let fraction = m.inverted_tets as f64 / tets.max(1) as f64;
    if fraction > max_fraction || m.min_volume_ratio.is_nan() {
        return Err(Error::Solver(format!(
            "frame {} (t = {:.4} s): {} of {tets} tets ({:.2}%) are inverted, the smallest volume \
             ratio is {:.3}; solver.max_inverted_fraction is {max_fraction}. The patch has turned \
             inside out (a load beyond what the mesh and material can follow): reduce the load, \
             add substeps, or raise the limit to keep going",
            m.frame,
            m.time_s,
            m.inverted_tets,
            100.0 * fraction,
            m.min_volume_ratio
        )));
    }
    if m.inverted_tets > 0 && *inverted_before == 0 {
        log::warn!(
            "frame {}: {} tets are inverted (smallest volume ratio {:.3}); their strains are not \
             physical",
            m.frame,
            m.inverted_tets,
            m.min_volume_ratio
        );
    }
    *inverted_before = m.inverted_tets;
    Ok(())
}

/// One row of a fit: a sample's stretch ratio and fitted parameters.
#[derive(Clone, Debug, PartialEq)]
pub struct FitRow {
    /// Where the row came from (map file or `point`).
    pub source: String,
    /// Stretch ratio.
    pub r: f64,
    /// α.
    pub alpha: f64,
    /// σ (µm).
    pub sigma_um: f64,
    /// The search's outcome (fitted samples only).
    pub fit: Option<SampleFit>,
}

/// What the search found for one sample.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SampleFit {
    /// Axis of the sample.
    pub axis: crate::micro::fit::Axis,
    /// Histogram half range used for target and candidates.
    pub range: f64,
    /// The optimum, its distance and valley.
    pub result: crate::micro::fit::FitResult,
    /// Seconds the search took.
    pub seconds: f64,
}

/// What `skinpatch fit` found.
#[derive(Clone, Debug)]
pub struct FitReport {
    /// Per sample, in file order (samples, then points).
    pub rows: Vec<FitRow>,
    /// The fitted model.
    pub model: crate::micro::KernelModel,
    /// Its lines, for the report.
    pub lines: crate::micro::fit::ModelLines,
    /// The kernel file written, if the samples file names one.
    pub written: Option<PathBuf>,
    /// Where the candidates were counted (`None` without map samples).
    pub device: Option<String>,
}

/// Whether the fit counts on the GPU: a hardware adapter only (a software
/// one such as lavapipe counts slower than the CPU path), unless
/// `SKINPATCH_REQUIRE_GPU=1` asks for the GPU.
fn fit_on_gpu(ctx: &crate::gpu::Context) -> bool {
    ctx.info.device_type != wgpu::DeviceType::Cpu || crate::gpu::gpu_required()
}

/// Runs a `skinpatch fit` samples file (see [`crate::scenario::FitSamples`]).
/// `progress(sample, samples, fraction)` follows each sample's search.
pub fn fit(
    path: &std::path::Path,
    mut progress: impl FnMut(usize, usize, f64),
) -> Result<FitReport> {
    use crate::micro::fit::{fit_model, Axis, FittedPoint, HistogramSettings, Objective};
    use crate::micro::io::{read_map, MapDefaults, TexelSize};
    use crate::micro::NormalHistogram;
    let samples: crate::scenario::FitSamples = crate::scenario::read_toml_file(path)?;
    let base = path.parent().unwrap_or(std::path::Path::new("."));
    let bins = samples
        .bins
        .unwrap_or(crate::micro::normals::HISTOGRAM_BINS);
    if !(2..=1024).contains(&bins) {
        return Err(Error::parameter(
            "bins",
            format!("must be in 2..=1024, got {bins}"),
        ));
    }
    if let Some(range) = samples.range {
        if !(range.is_finite() && range > 0.0 && range <= 1.0) {
            return Err(Error::parameter(
                "range",
                format!("must be in (0, 1] (a normal's tangent component), got {range}"),
            ));
        }
    }
    let defaults = MapDefaults {
        texel: TexelSize::Um(samples.texel_um.unwrap_or(1.0)),
        height_unit_um: 1.0,
        edge: crate::micro::Edge::Clamp,
    };
    let mut rows = Vec::new();
    let mut device = None;
    if !samples.sample.is_empty() {
        let neutral_path = samples
            .neutral
            .as_ref()
            .ok_or_else(|| Error::parameter("neutral", "is required to fit [[sample]] maps"))?;
        let neutral = read_map(&base.join(neutral_path), &defaults)?;
        let ctx = crate::gpu::acquire()?.filter(fit_on_gpu);
        device = Some(match &ctx {
            Some(c) => format!("GPU: {}", c.describe()),
            None => "CPU".to_string(),
        });
        let total = samples.sample.len();
        for (k, s) in samples.sample.iter().enumerate() {
            let axis = match s.axis.as_str() {
                "u" => Axis::U,
                "v" => Axis::V,
                other => {
                    return Err(Error::parameter(
                        format!("sample[{k}].axis"),
                        format!("must be \"u\" or \"v\", got \"{other}\""),
                    ))
                }
            };
            if !(s.r.is_finite() && s.r >= 0.1 && s.r <= 10.0) {
                return Err(Error::parameter(
                    format!("sample[{k}].r"),
                    format!("must be in [0.1, 10], got {}", s.r),
                ));
            }
            let (target, range, source) = match (&s.map, &s.histogram) {
                (Some(map), None) => {
                    let deformed = read_map(&base.join(map), &defaults)?;
                    let range = samples.range.unwrap_or_else(|| {
                        crate::micro::fit::auto_range(&[
                            &crate::micro::fit::resample(&neutral, axis, s.r),
                            &deformed,
                        ])
                    });
                    let h = NormalHistogram::of(&deformed, bins, range, [1.0, 1.0]);
                    (h, range, map.display().to_string())
                }
                (None, Some(file)) => {
                    let range = samples.range.ok_or_else(|| {
                        Error::parameter(
                            format!("sample[{k}].histogram"),
                            "needs `range` in the samples file: the half range its cells cover",
                        )
                    })?;
                    let hist = HistogramSettings { bins, range };
                    (
                        read_histogram(&base.join(file), hist)?,
                        range,
                        file.display().to_string(),
                    )
                }
                _ => {
                    return Err(Error::parameter(
                        format!("sample[{k}]"),
                        "needs exactly one of map and histogram",
                    ))
                }
            };
            let hist = HistogramSettings { bins, range };
            let objective = Objective::new(&neutral, &target, axis, s.r, hist);
            let start = std::time::Instant::now();
            let on_gpu = match &ctx {
                Some(c) => {
                    crate::gpu::or_cpu(crate::gpu::fit::GpuFit::new(c, &objective.base, bins))?
                }
                None => None,
            };
            let result = match &on_gpu {
                Some(f) => f.fit_params(&objective, |x| progress(k, total, x))?,
                None => crate::micro::fit::search(
                    &objective,
                    |b, d, alphas| {
                        Ok(crate::micro::fit::count_histograms(
                            b, d, alphas, bins, range,
                        ))
                    },
                    |x| progress(k, total, x),
                )?,
            };
            let seconds = start.elapsed().as_secs_f64();
            log::info!(
                "fitted {source}: α {:.2}, σ {:.1} µm, TV {:.4} ({} candidates, {seconds:.1} s)",
                result.alpha,
                result.sigma_um,
                result.distance,
                result.evaluations
            );
            rows.push(FitRow {
                source,
                r: s.r,
                alpha: result.alpha,
                sigma_um: result.sigma_um,
                fit: Some(SampleFit {
                    axis,
                    range,
                    result,
                    seconds,
                }),
            });
        }
    }
    for p in &samples.point {
        rows.push(FitRow {
            source: "point".into(),
            r: p.r,
            alpha: p.alpha,
            sigma_um: p.sigma_um,
            fit: None,
        });
    }
    let points: Vec<FittedPoint> = rows
        .iter()
        .map(|r| FittedPoint {
            r: r.r,
            alpha: r.alpha,
            sigma_um: r.sigma_um,
        })
        .collect();
    let (model, lines) = fit_model(&points, &samples.alpha_breaks)?;
    let written = match &samples.output {
        Some(out) => {
            let out = base.join(out);
            let section = crate::scenario::KernelSection::of(&model);
            let body =
                toml::to_string(&section).map_err(|e| Error::io(&out, std::io::Error::other(e)))?;
            let mut fitted = String::new();
            for row in &rows {
                match &row.fit {
                    Some(f) => {
                        let v = &f.result;
                        fitted += &format!(
                            "#   {}: r {}, axis {:?}, bins {bins}, range {}: α {:.2}, σ {:.1} µm, \
                             TV {:.4}; within {:.4}: α {:.2}…{:.2}, σ {:.1}…{:.1} µm\n",
                            row.source,
                            row.r,
                            f.axis,
                            f.range,
                            v.alpha,
                            v.sigma_um,
                            v.distance,
                            crate::micro::fit::valley_margin(v.distance),
                            v.alpha_range.0,
                            v.alpha_range.1,
                            v.sigma_range_um.0,
                            v.sigma_range_um.1
                        )
                    }
                    None => {
                        fitted += &format!(
                            "#   point: r {}, α {}, σ {} µm\n",
                            row.r, row.alpha, row.sigma_um
                        )
                    }
                }
            }
            let text = format!(
                "# Kernel model fitted by `skinpatch fit` from {}:\n{fitted}\
                 # Use it with [microstructure] kernel_file = \"…\".\n{body}",
                path.display()
            );
            io::write_atomically(&out, text.as_bytes())?;
            Some(out)
        }
        None => None,
    };
    Ok(FitReport {
        rows,
        model,
        lines,
        written,
        device,
    })
}

/// Reads a target histogram: `bins` lines of `bins` comma-separated
/// non-negative weights, normalised to sum 1.
fn read_histogram(
    path: &std::path::Path,
    hist: crate::micro::fit::HistogramSettings,
) -> Result<crate::micro::NormalHistogram> {
    let text = io::read_input_text(path)?;
    let bad = |line: usize, message: String| Error::Parse {
        path: path.to_path_buf(),
        line,
        message,
    };
    let rows: Vec<&str> = text.lines().filter(|l| !l.trim().is_empty()).collect();
    if rows.len() != hist.bins {
        return Err(bad(
            0,
            format!(
                "expected {} rows of weights, found {}",
                hist.bins,
                rows.len()
            ),
        ));
    }
    let mut cells = Vec::with_capacity(hist.bins * hist.bins);
    for (k, row) in rows.iter().enumerate() {
        let values: Vec<&str> = row.split(',').collect();
        if values.len() != hist.bins {
            return Err(bad(
                k + 1,
                format!("expected {} weights, found {}", hist.bins, values.len()),
            ));
        }
        for v in values {
            let w: f64 = v
                .trim()
                .parse()
                .ok()
                .filter(|w: &f64| w.is_finite() && *w >= 0.0)
                .ok_or_else(|| {
                    bad(
                        k + 1,
                        format!("{:?} is not a non-negative number", v.trim()),
                    )
                })?;
            cells.push(w);
        }
    }
    let total: f64 = cells.iter().sum();
    if total <= 0.0 {
        return Err(bad(0, "the histogram is empty (all weights 0)".into()));
    }
    cells.iter_mut().for_each(|c| *c /= total);
    Ok(crate::micro::NormalHistogram {
        bins: hist.bins,
        range: hist.range,
        cells,
    })
}
