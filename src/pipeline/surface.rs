//! Runs a [`SurfaceSetup`]: an animated surface from another tool through
//! the same strain, microstructure, render and export stages as the FEM
//! patch's top surface (seed 000 §5, "novel surface animation").
//!
//! Per frame: the surface field (eq. 10–13) from the rest and frame
//! positions, a `metrics.csv` row, `frames/frame_NNNN.vtu` (the surface with
//! r_s, r_t and axes per vertex), and per map — the unit square, or each
//! UDIM tile with its triangles moved into the square — the strain maps and
//! the deformed microstructure (`micro/height_[TILE_]NNNN.*`), then the
//! rendered frames. A failing frame stops the run with an error naming it;
//! what was written stays.

use std::io::Write as _;
use std::path::PathBuf;
use std::time::Instant;

use super::{clear_previous_run, render, write_micro_frame, write_neutral, MicroEngine};
use crate::error::{Error, Result};
use crate::export;
use crate::mesh::{io, Vec3};
use crate::scenario::SurfaceSetup;
use crate::strain::{StrainRaster, SurfaceField};
use crate::surface::{AnimatedSurface, UvLayout};

/// One frame's row of `metrics.csv`.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct SurfaceMetrics {
    /// Frame index (0 is the first sample of the animation).
    pub frame: usize,
    /// Time (s).
    pub time_s: f64,
    /// Least and greatest r_s over the surface vertices.
    pub rs_range: [f64; 2],
    /// Least and greatest r_t over the surface vertices.
    pub rt_range: [f64; 2],
    /// Surface vertices whose averaged T folds (det T < 0).
    pub folded_vertices: usize,
    /// Triangles without area at rest, in UV or in this frame.
    pub degenerate_triangles: usize,
    /// Wall time of the frame's stages (s).
    pub wall_s: f64,
}

/// What a surface run produced.
#[derive(Clone, Debug, serde::Serialize)]
pub struct SurfaceRunSummary {
    /// Files written, in order (per-frame files are summarised by folder).
    pub written: Vec<PathBuf>,
    /// Metrics of every frame.
    pub frames: Vec<SurfaceMetrics>,
    /// Where the microstructure stages ran (`None` without microstructure).
    pub micro_device: Option<String>,
}

/// One finished frame as [`run`]'s callback sees it.
pub struct SurfaceFrame<'a> {
    /// The frame's row of `metrics.csv`.
    pub metrics: &'a SurfaceMetrics,
    /// Frames in the run.
    pub total_frames: usize,
    /// The surface (rest positions, UV layout).
    pub surface: &'a AnimatedSurface,
    /// The frame's positions, indexed like `surface.positions`.
    pub positions: &'a [Vec3],
    /// The surface's deformation in texture space.
    pub field: &'a SurfaceField,
}

const METRICS_HEADER: &str =
    "frame,time_s,rs_min,rs_max,rt_min,rt_max,folded_vertices,degenerate_triangles,wall_s\n";

/// Runs the surface scenario and writes its outputs; `on_frame` is called
/// after each frame's files are written.
pub fn run(
    setup: &SurfaceSetup,
    mut on_frame: impl FnMut(&SurfaceFrame<'_>),
) -> Result<SurfaceRunSummary> {
    let dir = &setup.output_dir;
    let surface = &setup.surface;
    // Everything that can fail before the first frame is checked before
    // the folder is touched: the planned output size and the adapters.
    super::plan::check_surface(setup, setup.force_large_output)?;
    // One chain per map (the unit square, or each UDIM tile).
    let mut engines = Vec::new();
    if let Some(micro) = &setup.micro {
        for _ in &setup.pieces {
            engines.push(MicroEngine::new(micro)?);
        }
    }
    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    let extent = surface.mm_per_uv();
    let mut renderer = match &setup.render {
        Some(r) => Some(render::RenderEngine::new(
            dir,
            r,
            setup.micro.as_ref(),
            engines.first(),
            (extent, extent / r.texture_px as f64),
        )?),
        None => None,
    };
    // Checks and adapters first; then the previous run's files go.
    clear_previous_run(dir)?;
    let mut written = Vec::new();
    for (folder, wanted) in [
        ("frames", setup.write_frames),
        ("strain", setup.strain_images.is_some()),
    ] {
        if wanted {
            let path = dir.join(folder);
            std::fs::create_dir_all(&path).map_err(|e| Error::io(&path, e))?;
        }
    }
    if setup.write_surface_vtu {
        let rest_field = SurfaceField::new(&surface.top, &surface.positions, &surface.positions);
        let path = dir.join("surface.vtu");
        let grid = export::surface_grid(surface, &surface.positions, &rest_field);
        io::write_vtu_as(&path, &grid, setup.vtu_format)?;
        written.push(path);
    }
    if let Some(micro) = &setup.micro {
        written.extend(write_neutral(dir, extent, micro)?);
    }
    let metrics_path = dir.join("metrics.csv");
    let mut metrics = std::fs::File::create(&metrics_path)
        .map(std::io::BufWriter::new)
        .map_err(|e| Error::io(&metrics_path, e))?;
    metrics
        .write_all(METRICS_HEADER.as_bytes())
        .map_err(|e| Error::io(&metrics_path, e))?;
    written.push(metrics_path.clone());
    let mut frames = Vec::new();
    let mut collection = Vec::new();
    // The unit square's one piece is every triangle in place: no view.
    let whole = setup.layout == UvLayout::Unit;
    let total_frames = surface.num_frames();
    let result = (|| -> Result<()> {
        for (f, x) in surface.frames.iter().enumerate() {
            let start = Instant::now();
            let field = SurfaceField::new(&surface.top, &surface.positions, x);
            if setup.write_frames {
                let grid = export::surface_grid(surface, x, &field);
                collection.push((
                    surface.time(f),
                    export::write_frame(dir, f, &grid, setup.vtu_format)?,
                ));
                export::write_collection(dir, &collection)?;
            }
            let mut fresh_normals = false;
            for (k, piece) in setup.pieces.iter().enumerate() {
                let view;
                let map_field = if whole {
                    &field
                } else {
                    view = field.view(&piece.triangles);
                    &view
                };
                let tag = piece.tag();
                if let Some(images) = setup.strain_images {
                    let raster = StrainRaster::new(map_field, images.px, images.px);
                    export::strain_images::StrainImages::new(&raster, images.range)
                        .write_tagged(dir, &tag, f)?;
                }
                if let (Some(micro), Some(engine)) = (&setup.micro, engines.get_mut(k)) {
                    if f % micro.frame_stride == 0 {
                        let (deformed, normals) = engine.deform(micro, map_field)?;
                        let stage = format!("the microstructure ({})", engine.describe());
                        crate::error::check_finite(&stage, f, deformed.width, 1, &deformed.data)?;
                        fresh_normals = micro.normal_maps;
                        write_micro_frame(
                            &dir.join("micro"),
                            &format!("{tag}{f:04}"),
                            micro,
                            &deformed,
                            normals,
                        )?;
                    }
                }
            }
            if let (Some(r), Some(renderer)) = (&setup.render, renderer.as_mut()) {
                if f % r.frame_stride == 0 {
                    let geometry =
                        crate::render::scene::build_surface(&surface.top, x, &field, r.tessellate);
                    renderer.frame(&geometry, &field, engines.first_mut(), f, fresh_normals)?;
                }
            }
            let (rs, rt, folded) = field.extremes();
            let m = SurfaceMetrics {
                frame: f,
                time_s: surface.time(f),
                rs_range: [rs.0, rs.1],
                rt_range: [rt.0, rt.1],
                folded_vertices: folded,
                degenerate_triangles: field.degenerate_triangles,
                wall_s: start.elapsed().as_secs_f64(),
            };
            writeln!(
                metrics,
                "{},{},{},{},{},{},{},{},{:.6}",
                m.frame,
                m.time_s,
                m.rs_range[0],
                m.rs_range[1],
                m.rt_range[0],
                m.rt_range[1],
                m.folded_vertices,
                m.degenerate_triangles,
                m.wall_s
            )
            .and_then(|_| metrics.flush())
            .map_err(|e| Error::io(&metrics_path, e))?;
            frames.push(m);
            on_frame(&SurfaceFrame {
                metrics: &m,
                total_frames,
                surface,
                positions: x,
                field: &field,
            });
        }
        Ok(())
    })();
    if !collection.is_empty() {
        written.push(dir.join("frames.pvd"));
    }
    result?;
    for (folder, wanted) in [
        ("frames", setup.write_frames),
        ("strain", setup.strain_images.is_some()),
        ("micro", setup.micro.is_some()),
    ] {
        if wanted {
            written.push(dir.join(folder));
        }
    }
    if let (Some(r), Some(renderer)) = (&setup.render, &renderer) {
        written.extend(renderer.finish(r, surface.frame_rate_hz)?);
    }
    Ok(SurfaceRunSummary {
        written,
        frames,
        micro_device: engines
            .first()
            .zip(setup.micro.as_ref())
            .map(|(e, m)| e.summary(m)),
    })
}
