//! The viewer's render loop without a window, timed for `skinpatch bench
//! gpu`: the FEM thread, the microstructure chain, the renderer and the
//! present pass run as in `skinpatch view`, on the same frame code
//! (`super::frame`), but the present pass draws into an offscreen
//! texture and nothing waits for a display refresh.
//!
//! The probe plays the scenario's path in a loop at display time, so the
//! FEM thread always has a newer target to solve; every displayed frame
//! turns the camera by a quarter degree, as a user orbiting the patch
//! would, so every one of them renders.

use std::sync::Arc;
use std::time::{Duration, Instant};

use super::frame::{render_state, run_chain, upload_solved, RenderInputs};
use super::present::{begin_pass, copy_out, read_rgb, PresentStage};
use super::state::{Command, ViewerState};
use super::worker::{FemWorker, Solved};
use crate::bench::gpu::ViewerLoopFigures;
use crate::error::{Error, Result};
use crate::gpu::micro::GpuMicro;
use crate::gpu::Context;
use crate::imaging::colour::linear_to_srgb;
use crate::render::Renderer;
use crate::scenario::Setup;
use crate::strain::SurfaceField;

/// The offscreen target's format: 8-bit, not sRGB, so the present pass
/// encodes sRGB itself as it does for the usual window formats.
const FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8Unorm;

/// How long the first frame (the probe's first target, from rest) may take.
const FIRST_FRAME: Duration = Duration::from_secs(600);

/// Runs the viewer's loop on `setup` in a view of `size` pixels for
/// `seconds` (at least two frames are drawn) and reports its rates;
/// `texture_px` replaces the side of the texture-space and shadow-map
/// targets (as `bench gpu` does for its render cases). The clock starts
/// once the FEM thread has solved its first frame.
pub fn bench_loop(
    setup: &Setup,
    size: (usize, usize),
    seconds: f64,
    texture_px: Option<usize>,
) -> Result<ViewerLoopFigures> {
    if !(seconds.is_finite() && seconds > 0.0) {
        return Err(Error::parameter(
            "viewer loop duration",
            format!("must be > 0 s, got {seconds}"),
        ));
    }
    if size.0 < 8 || size.1 < 8 {
        return Err(Error::parameter(
            "viewer loop size",
            format!("must be at least 8 × 8 px, got {} × {}", size.0, size.1),
        ));
    }
    let mut view = View::open(setup, size, texture_px)?;
    let mut state = super::initial_state(setup, &view.inputs.setup, [size.0 as f32, size.1 as f32]);
    state.apply(Command::Play(0.0));
    state.apply(Command::Loop(true));
    let worker = start_worker(setup, &state)?;

    let solved_before = worker.status().solved;
    let start = Instant::now();
    let mut last = start;
    let mut shown: Option<Arc<Solved>> = None;
    let mut field = None;
    let mut chain_on = None;
    let (mut chain_ms, mut render_ms, mut present_ms) = (Vec::new(), Vec::new(), Vec::new());
    while present_ms.len() < 2 || start.elapsed().as_secs_f64() < seconds {
        let now = Instant::now();
        if let Some(p) = state.probe.as_mut() {
            p.advance(now.duration_since(last).as_secs_f64());
        }
        last = now;
        let latest = worker.latest().expect("the first frame was solved");
        if !shown.as_ref().is_some_and(|s| Arc::ptr_eq(s, &latest)) {
            field = Some(view.upload(&setup.mesh, &latest));
            shown = Some(latest.clone());
        }
        let frame = latest.metrics.frame;
        if state.mode.needs_deformed_map() && chain_on != Some(frame) {
            if let (Some(chain), Some(field)) = (view.chain.as_mut(), &field) {
                chain_ms.push(run_chain(chain, field)?);
                chain_on = Some(frame);
            }
        }
        if let Some(p) = &state.probe {
            worker.set_target(p.target());
        }
        state.apply(Command::Orbit(0.25, 0.0));
        render_ms.push(render_state(&view.ctx, &mut view.renderer, &state)?);
        let t = Instant::now();
        view.present()?;
        present_ms.push(t.elapsed().as_secs_f64() * 1e3);
    }
    let seconds = start.elapsed().as_secs_f64();
    let status = worker.status();
    if let Some(why) = &status.failure {
        log::warn!("viewer loop: the FEM's last frame failed: {why}");
    }
    drop(worker);
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len().max(1) as f64;
    Ok(ViewerLoopFigures {
        size,
        mode: state.mode.name().to_string(),
        seconds,
        frames: present_ms.len(),
        fem_frames: status.solved - solved_before,
        chain_runs: chain_ms.len(),
        chain_ms: (!chain_ms.is_empty()).then(|| mean(&chain_ms)),
        render_ms: mean(&render_ms),
        present_ms: mean(&present_ms),
        present_max_difference: view.presented_difference()?,
    })
}

/// The FEM thread on `setup`, once it has solved its first frame (the
/// probe's first target in `state`, from rest).
fn start_worker(setup: &Setup, state: &ViewerState) -> Result<FemWorker> {
    let worker = FemWorker::spawn(
        setup.simulation.clone(),
        setup.mesh.clone(),
        state.probe.as_ref().map(|p| p.target()),
        Box::new(|| {}),
    );
    worker.wait_idle(FIRST_FRAME);
    if worker.latest().is_none() {
        let why = worker
            .status()
            .failure
            .unwrap_or_else(|| format!("not solved within {} s", FIRST_FRAME.as_secs()));
        return Err(Error::Solver(format!("the viewer's first frame: {why}")));
    }
    Ok(worker)
}

/// Everything on the GPU: the device, the chain (with a microstructure),
/// the renderer, and the present pass bound to the renderer's image and
/// drawing into an offscreen texture.
struct View {
    ctx: Context,
    chain: Option<GpuMicro>,
    inputs: RenderInputs,
    renderer: Renderer,
    present: PresentStage,
    bind: wgpu::BindGroup,
    target: wgpu::Texture,
    size: (usize, usize),
}

impl View {
    fn open(setup: &Setup, size: (usize, usize), texture_px: Option<usize>) -> Result<View> {
        let ctx = crate::gpu::acquire()?.ok_or_else(|| {
            Error::Gpu(
                "the viewer's loop needs a GPU adapter (the warning above says why none is \
                 usable)"
                    .into(),
            )
        })?;
        let chain = setup
            .outputs
            .micro
            .as_ref()
            .map(|m| crate::pipeline::gpu_chain(ctx.clone(), m))
            .transpose()?;
        let mut render = super::view_render(setup)?;
        if let Some(px) = texture_px {
            (render.texture_px, render.shadow_map_px) = (px, px);
        }
        let inputs = RenderInputs::new(setup, render)?;
        let renderer = inputs.renderer(&ctx, chain.as_ref(), size)?;
        let present = PresentStage::new(&ctx, FORMAT);
        let bind = {
            let (pixels, w, h) = renderer.pixels();
            present.bind(&ctx, pixels, (w, h), [0.0, 0.0])
        };
        let target = offscreen_target(&ctx, size);
        Ok(View {
            ctx,
            chain,
            inputs,
            renderer,
            present,
            bind,
            target,
            size,
        })
    }

    /// Uploads a solved state's geometry; returns its surface strain.
    fn upload(&mut self, mesh: &crate::mesh::TetMesh, solved: &Solved) -> SurfaceField {
        let tessellate = self.inputs.setup.tessellate;
        upload_solved(&self.ctx, &mut self.renderer, mesh, solved, tessellate)
    }

    /// The present pass into the offscreen texture, waited for.
    fn present(&self) -> Result<()> {
        let mut enc = self
            .ctx
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor::default());
        {
            let mut pass = begin_pass(&mut enc, &self.target, "offscreen view");
            let (w, h) = self.size;
            self.present
                .draw(&mut pass, &self.bind, [0.0, 0.0, w as f32, h as f32]);
        }
        self.ctx.queue.submit(std::iter::once(enc.finish()));
        self.ctx.finish()
    }

    /// Largest difference (8-bit levels, any channel) between the
    /// presented image and the renderer's pixels sRGB-encoded here.
    fn presented_difference(&self) -> Result<u8> {
        let ctx = &self.ctx;
        let extent = (self.size.0 as u32, self.size.1 as u32);
        let mut enc = ctx
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor::default());
        let (staging, row) = copy_out(ctx, &mut enc, &self.target, extent);
        ctx.queue.submit(std::iter::once(enc.finish()));
        let shown = read_rgb(ctx, &staging, row, extent, false)?;
        let (pixels, w, h) = self.renderer.pixels();
        let linear: Vec<[f32; 4]> = crate::gpu::buffers::read(ctx, pixels, w * h)?;
        let expected = linear
            .iter()
            .flat_map(|p| [p[0], p[1], p[2]])
            .map(|c| (linear_to_srgb(c) * 255.0).round() as u8);
        Ok(shown
            .iter()
            .zip(expected)
            .map(|(&a, b)| a.abs_diff(b))
            .max()
            .unwrap_or(0))
    }
}

/// The texture the present pass draws into, in place of a window's frame.
fn offscreen_target(ctx: &Context, size: (usize, usize)) -> wgpu::Texture {
    ctx.device.create_texture(&wgpu::TextureDescriptor {
        label: Some("offscreen view"),
        size: wgpu::Extent3d {
            width: size.0 as u32,
            height: size.1 as u32,
            depth_or_array_layers: 1,
        },
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format: FORMAT,
        usage: wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
        view_formats: &[],
    })
}
