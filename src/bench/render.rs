//! `skinpatch bench render`: the whole frame of a scenario — FEM step,
//! microstructure chain, geometry and render — timed per part, without
//! writing files.

use crate::error::Result;
use crate::pipeline::render::{device, no_gpu};
use crate::pipeline::{simulate, texel_mm};
use crate::render::albedo::Albedo;
use crate::render::{FrameStage, Mode, Renderer};
use crate::strain::SurfaceField;

/// Figures of `skinpatch bench render` (means over the timed frames, ms).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct RenderBench {
    /// The adapter.
    pub adapter: String,
    /// Output size and supersampling.
    pub size: (usize, usize, usize),
    /// Frames timed.
    pub frames: usize,
    /// FEM step (CPU).
    pub fem_ms: f64,
    /// Microstructure chain (GPU, no read-back).
    pub micro_ms: f64,
    /// Geometry build and upload (CPU).
    pub geometry_ms: f64,
    /// Render only: shadow maps to resolve, submitted and waited for.
    pub render_ms: f64,
    /// Render with the image read back.
    pub render_readback_ms: f64,
    /// Each pass of the render submitted alone and waited for, in
    /// [`FrameStage::ALL`] order (wall time; a profile, not a throughput).
    pub stages_ms: [f64; FrameStage::COUNT],
}

/// Simulates the first `frames` frames of `setup` and times, per frame, the
/// FEM step, the microstructure chain, the geometry and the render (mean of
/// `repeats` renders) at `width × height`, without writing files. Uses the
/// scenario's `[render]` settings (defaults without one) in the dynamic mode
/// (mode `none` without a microstructure).
pub fn bench_render(
    setup: &crate::scenario::Setup,
    frames: usize,
    (width, height): (usize, usize),
    repeats: usize,
) -> Result<RenderBench> {
    use std::time::Instant;
    let mut setup = setup.clone();
    setup.simulation.frames = frames.max(1).min(setup.simulation.frames);
    let micro = setup.outputs.micro.clone();
    let (render, mode) = bench_settings(&setup, (width, height))?;
    let ctx = crate::gpu::acquire()?.ok_or_else(no_gpu)?;
    let adapter = ctx.describe();
    let mut ctx = Some(ctx);
    let (lo, hi) = setup.mesh.bounds();
    let albedo = Albedo::from_source(&render.albedo, render.texture_px, hi.x - lo.x)?;
    let mut chain = match &micro {
        Some(m) => Some(crate::pipeline::gpu_chain(
            ctx.take().expect("the device is unused so far"),
            m,
        )?),
        None => None,
    };
    let own = ctx;
    let mut renderer = {
        let ctx = device(chain.as_ref(), own.as_ref());
        Renderer::new(
            ctx,
            &render,
            &albedo,
            None,
            chain.as_ref().map(|c| c.normals_texture()),
            [1.0; 16],
            texel_mm((lo, hi), render.texture_px),
        )?
    };
    let mut figures = RenderBench {
        adapter,
        size: (width, height, render.supersample),
        ..Default::default()
    };
    let mesh = &setup.mesh;
    simulate(&setup, |m, stepper| {
        let sim = stepper.simulation();
        let field = SurfaceField::new(&mesh.top, &mesh.positions, sim.positions());
        let start = Instant::now();
        if let Some(chain) = chain.as_mut() {
            chain.run(&field)?;
        }
        let micro_ms = start.elapsed().as_secs_f64() * 1e3;
        let ctx = device(chain.as_ref(), own.as_ref());
        let start = Instant::now();
        let probe = setup.simulation.probe.as_ref().map(|p| p.pose(m.time_s));
        let geometry = crate::render::scene::build(
            mesh,
            sim.positions(),
            &field,
            probe.as_ref(),
            render.tessellate,
        );
        renderer.set_geometry(ctx, &geometry);
        let geometry_ms = start.elapsed().as_secs_f64() * 1e3;
        let (render_ms, readback_ms, stages) = time_frame(&mut renderer, ctx, mode, repeats)?;
        if m.frame > 0 {
            for (sum, t) in figures.stages_ms.iter_mut().zip(stages) {
                *sum += t;
            }
            figures.frames += 1;
            figures.fem_ms += m.step_wall_s * 1e3;
            figures.micro_ms += micro_ms;
            figures.geometry_ms += geometry_ms;
            figures.render_ms += render_ms;
            figures.render_readback_ms += readback_ms;
        }
        Ok(())
    })?;
    let n = figures.frames.max(1) as f64;
    for x in [
        &mut figures.fem_ms,
        &mut figures.micro_ms,
        &mut figures.geometry_ms,
        &mut figures.render_ms,
        &mut figures.render_readback_ms,
    ]
    .into_iter()
    .chain(figures.stages_ms.iter_mut())
    {
        *x /= n;
    }
    Ok(figures)
}

/// The scenario's render settings (defaults without `[render]`) at the
/// bench's size, in the dynamic mode (`none` without a microstructure).
fn bench_settings(
    setup: &crate::scenario::Setup,
    (width, height): (usize, usize),
) -> Result<(crate::render::RenderSetup, Mode)> {
    let has_micro = setup.outputs.micro.is_some();
    let mut render = match &setup.outputs.render {
        Some(r) => r.clone(),
        None => crate::scenario::RenderSection::default_setup(has_micro)?,
    };
    render.width = width;
    render.height = height;
    let mode = if has_micro { Mode::Dynamic } else { Mode::None };
    render.modes = vec![mode];
    Ok((render, mode))
}

/// One frame's render times (ms): the mean of `repeats` submissions after
/// a warm-up, one render with its read-back, and the stages timed alone.
fn time_frame(
    renderer: &mut Renderer,
    ctx: &crate::gpu::Context,
    mode: Mode,
    repeats: usize,
) -> Result<(f64, f64, [f64; FrameStage::COUNT])> {
    use std::time::Instant;
    // Warm-up (pipelines, first use of the resources).
    renderer.submit(ctx, mode);
    ctx.finish()?;
    let start = Instant::now();
    for _ in 0..repeats.max(1) {
        renderer.submit(ctx, mode);
    }
    ctx.finish()?;
    let render_ms = start.elapsed().as_secs_f64() * 1e3 / repeats.max(1) as f64;
    let start = Instant::now();
    renderer.render(ctx, mode)?;
    let readback_ms = start.elapsed().as_secs_f64() * 1e3;
    Ok((render_ms, readback_ms, renderer.time_stages(ctx, mode)?))
}
