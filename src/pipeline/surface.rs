//! Runs a [`SurfaceSetup`]: an animated surface from another tool through
//! the same strain, microstructure, render and export stages as the FEM
//! patch's top surface (Nagano et al. 2015 §5, "novel surface animation").
//!
//! Per frame: the surface field (eq. 10–13) from the rest and frame
//! positions, a `metrics.csv` row, `frames/frame_NNNN.vtu` (the surface with
//! r_s, r_t and axes per vertex), and per map — the unit square, or each
//! UDIM tile with its triangles moved into the square — the strain maps and
//! the deformed microstructure (`micro/height_[TILE_]NNNN.*`), then the
//! rendered frames. A failing frame stops the run with an error naming it;
//! what was written stays.

use std::time::Instant;

use super::outputs::{FrameInput, FrameOutputs, MapPiece, OutputSpec, RunKind, RunSummary};
use super::plan;
use crate::error::Result;
use crate::export;
pub use crate::export::SurfaceMetrics;
use crate::mesh::{io, Vec3};
use crate::scenario::SurfaceSetup;
use crate::strain::SurfaceField;
use crate::surface::{AnimatedSurface, UvLayout};

/// What a surface run produced.
pub type SurfaceRunSummary = RunSummary<SurfaceMetrics>;

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

/// Runs the surface scenario and writes its outputs; `on_frame` is called
/// after each frame's files are written.
pub fn run(
    setup: &SurfaceSetup,
    mut on_frame: impl FnMut(&SurfaceFrame<'_>),
) -> Result<SurfaceRunSummary> {
    let dir = &setup.outputs.dir;
    let surface = &setup.surface;
    // Everything that can fail before the first frame is checked before
    // the folder is touched: the planned output size and the adapters
    // (opening the outputs).
    plan::check_surface(setup, setup.outputs.force_large_output)?;
    let extent = surface.mm_per_uv();
    let texel_mm = |r: &crate::render::RenderSetup| extent / r.texture_px as f64;
    let spec = OutputSpec {
        outputs: &setup.outputs,
        extent_mm: (extent, setup.outputs.render.as_ref().map_or(0.0, texel_mm)),
        frame_rate_hz: surface.frame_rate_hz,
    };
    // One map per piece: the unit square's one piece is every triangle in
    // place (no view), a UDIM tile's its triangles moved into the square.
    let whole = setup.layout == UvLayout::Unit;
    let pieces = setup
        .pieces
        .iter()
        .map(|piece| MapPiece {
            tag: piece.tag(),
            triangles: (!whole).then_some(&piece.triangles[..]),
        })
        .collect();
    let mut outputs = FrameOutputs::open(spec, pieces)?;
    if setup.write_surface_vtu {
        let rest_field = SurfaceField::new(&surface.top, &surface.positions, &surface.positions);
        let path = dir.join("surface.vtu");
        let grid = export::surface_grid(surface, &surface.positions, &rest_field);
        io::write_vtu_as(&path, &grid, setup.outputs.vtu_format)?;
    }
    outputs.start()?;
    let total_frames = surface.num_frames();
    for (f, x) in surface.frames.iter().enumerate() {
        let start = Instant::now();
        let field = SurfaceField::new(&surface.top, &surface.positions, x);
        let grid = outputs
            .wants_grid()
            .then(|| export::surface_grid(surface, x, &field));
        let geometry = |tessellate: usize| {
            crate::render::scene::build_surface(&surface.top, x, &field, tessellate)
        };
        outputs.frame(&FrameInput {
            frame: f,
            time_s: surface.time(f),
            field: &field,
            grid: grid.as_ref(),
            geometry: &geometry,
        })?;
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
        outputs.row(m)?;
        on_frame(&SurfaceFrame {
            metrics: &m,
            total_frames,
            surface,
            positions: x,
            field: &field,
        });
    }
    let finished = outputs.finish()?;
    Ok(RunSummary {
        kind: RunKind::Surface,
        written: export::outputs::run_files(dir),
        quality: None,
        frames: finished.rows,
        micro_device: finished.micro_device,
    })
}
