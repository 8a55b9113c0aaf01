//! One frame of the view on the GPU, the same in the window and in the
//! offscreen loop ([`super::offscreen`]): the renderer built for a view
//! size, a solved state's geometry uploaded, the microstructure chain run
//! on its surface strain, and the view rendered as the state shows it.

use std::time::Instant;

use super::state::{Overlay, ViewerState};
use super::worker::Solved;
use crate::error::Result;
use crate::gpu::micro::GpuMicro;
use crate::gpu::Context;
use crate::mesh::TetMesh;
use crate::render::albedo::Albedo;
use crate::render::overlay::OverlayKind;
use crate::render::{NormalMap, RenderSetup, Renderer};
use crate::scenario::Setup;
use crate::strain::SurfaceField;

/// Inputs the renderer is rebuilt from when the view changes size.
pub(super) struct RenderInputs {
    pub(super) setup: RenderSetup,
    albedo: Albedo,
    // The neutral map's normals and its width and height.
    neutral: Option<(Vec<[f32; 3]>, usize, usize)>,
    curve: [f32; 16],
    texel_mm: f64,
}

impl RenderInputs {
    /// The inputs for `setup`'s patch drawn with `render`: the albedo, the
    /// neutral map's normals and the roughness curve of the anisotropic
    /// mode (the viewer switches modes without rebuilding).
    pub(super) fn new(setup: &Setup, render: RenderSetup) -> Result<RenderInputs> {
        let (lo, hi) = setup.mesh.bounds();
        let albedo = Albedo::from_source(&render.albedo, render.texture_px, hi.x - lo.x)?;
        let neutral = setup
            .outputs
            .micro
            .as_ref()
            .map(|m| m.neutral.whole("skinpatch view"))
            .transpose()?
            .map(|map| {
                (
                    crate::micro::normals::normal_map(map),
                    map.width,
                    map.height,
                )
            });
        let mut anisotropic = render.clone();
        anisotropic.roughness = crate::render::Roughness::Anisotropic;
        let curve = crate::pipeline::roughness_curve(&anisotropic, setup.outputs.micro.as_ref());
        let texel_mm = crate::pipeline::texel_mm((lo, hi), render.texture_px);
        Ok(RenderInputs {
            setup: render,
            albedo,
            neutral,
            curve,
            texel_mm,
        })
    }

    /// The renderer for a view of `size` pixels (one sample a pixel).
    pub(super) fn renderer(
        &self,
        ctx: &Context,
        chain: Option<&GpuMicro>,
        size: (usize, usize),
    ) -> Result<Renderer> {
        let mut setup = self.setup.clone();
        setup.width = size.0;
        setup.height = size.1;
        setup.supersample = 1;
        let neutral = self
            .neutral
            .as_ref()
            .map(|(normals, width, height)| NormalMap {
                normals,
                width: *width,
                height: *height,
            });
        Renderer::new(
            ctx,
            &setup,
            &self.albedo,
            neutral,
            chain.map(GpuMicro::normals_texture),
            self.curve,
            self.texel_mm,
        )
    }
}

/// Uploads a solved state's geometry to `renderer`; returns the surface
/// strain field the chain runs on.
pub(super) fn upload_solved(
    ctx: &Context,
    renderer: &mut Renderer,
    mesh: &TetMesh,
    solved: &Solved,
    tessellate: usize,
) -> SurfaceField {
    let field = SurfaceField::new(&mesh.top, &mesh.positions, &solved.positions);
    let geometry = crate::render::scene::build(
        mesh,
        &solved.positions,
        &field,
        solved.pose.as_ref(),
        tessellate,
    );
    renderer.set_geometry(ctx, &geometry);
    field
}

/// Runs the microstructure chain on `field` and waits for it; returns its
/// wall time (ms).
pub(super) fn run_chain(chain: &mut GpuMicro, field: &SurfaceField) -> Result<f64> {
    let start = Instant::now();
    chain.submit(field, true);
    chain.context().finish()?;
    Ok(start.elapsed().as_secs_f64() * 1e3)
}

/// Renders the view `state` shows (camera, lights, mode, overlay) and
/// waits for it; returns its wall time (ms).
pub(super) fn render_state(
    ctx: &Context,
    renderer: &mut Renderer,
    state: &ViewerState,
) -> Result<f64> {
    let (mode, roughness) = state.mode.render();
    let overlay = match state.overlay {
        Overlay::Off => OverlayKind::Off,
        Overlay::Rs => OverlayKind::Rs,
        Overlay::Rt => OverlayKind::Rt,
        Overlay::Axes => OverlayKind::Axes,
    };
    let start = Instant::now();
    renderer.set_view(state.camera.camera(), &state.lights())?;
    renderer.set_roughness(roughness);
    renderer.set_overlay(overlay, state.overlay_range as f32);
    renderer.submit(ctx, mode);
    ctx.finish()?;
    Ok(start.elapsed().as_secs_f64() * 1e3)
}
