//! Presentation: the rendered view and the panel drawn into the window,
//! and captures of the whole window (written as PNG).

use super::panel::PanelOutput;
use super::{device, App, Gpu};
use crate::error::{Error, Result};
use crate::gpu::Context;
use crate::viewer::present::{begin_pass, copy_out, read_rgb};
use crate::viewer::state::Command;

impl App {
    /// Draws the image and the panel into the window.
    pub(super) fn present(&mut self) -> Result<()> {
        let output = self.run_panel()?;
        let egui_ctx = self.egui.clone();
        let gpu = self.gpu.as_mut().expect("started");
        gpu.egui_state
            .handle_platform_output(&gpu.window, output.platform_output);
        let ppp = output.pixels_per_point;
        let jobs = egui_ctx.tessellate(output.shapes, ppp);
        let Some(frame) = gpu.next_frame() else {
            return Ok(());
        };
        let ctx = device(&gpu.chain, &gpu.own);
        for (id, deltas) in &output.textures_delta.set {
            for delta in deltas {
                gpu.egui_renderer
                    .update_texture(&ctx.device, &ctx.queue, *id, delta);
            }
        }
        let screen = egui_wgpu::ScreenDescriptor {
            size_in_pixels: [gpu.config.width, gpu.config.height],
            pixels_per_point: ppp,
        };
        let mut enc = ctx
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor::default());
        let extra =
            gpu.egui_renderer
                .update_buffers(&ctx.device, &ctx.queue, &mut enc, &jobs, &screen);
        gpu.draw(
            &mut enc,
            &frame.texture,
            self.shown.is_some(),
            &jobs,
            &screen,
        );
        let ctx = device(&gpu.chain, &gpu.own);
        let capture = if self.window_shots.is_empty() {
            None
        } else {
            Some(capture_window(ctx, &mut enc, &frame.texture, &gpu.config)?)
        };
        ctx.queue
            .submit(extra.into_iter().chain(std::iter::once(enc.finish())));
        if let Some((staging, row)) = capture {
            let (size, rgb) = captured_rgb(ctx, &staging, row, &gpu.config)?;
            for path in std::mem::take(&mut self.window_shots) {
                if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
                    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
                }
                crate::imaging::encode::write_rgb8_png(&path, size, &rgb)?;
                self.written.push(path);
            }
        }
        gpu.window.pre_present_notify();
        ctx.queue.present(frame);
        for id in &output.textures_delta.free {
            gpu.egui_renderer.free_texture(id);
        }
        ctx.take_device_errors()
    }

    /// Lays out the panel and applies what was clicked in it.
    fn run_panel(&mut self) -> Result<egui::FullOutput> {
        let raw = {
            let gpu = self.gpu.as_mut().expect("started");
            gpu.egui_state.take_egui_input(&gpu.window)
        };
        let egui_ctx = self.egui.clone();
        let mut panel = PanelOutput::default();
        let output = egui_ctx.run_ui(raw, |ui| self.panel(ui, &mut panel));
        if panel.toggle_probe_tool {
            self.probe_tool = !self.probe_tool;
            self.state.apply(Command::Live);
        }
        for c in panel.commands {
            self.state.apply(c);
            self.dirty = true;
        }
        for a in panel.actions {
            self.key_action(a)?;
        }
        Ok(output)
    }
}

impl Gpu {
    /// The window's next frame; none (and a redraw asked for) when the
    /// surface is outdated or lost (then reconfigured) or has no frame now.
    fn next_frame(&mut self) -> Option<wgpu::SurfaceTexture> {
        match self.surface.get_current_texture() {
            wgpu::CurrentSurfaceTexture::Success(f)
            | wgpu::CurrentSurfaceTexture::Suboptimal(f) => Some(f),
            wgpu::CurrentSurfaceTexture::Outdated | wgpu::CurrentSurfaceTexture::Lost => {
                let size = self.window.inner_size();
                self.config.width = size.width.max(1);
                self.config.height = size.height.max(1);
                let ctx = device(&self.chain, &self.own);
                self.surface.configure(&ctx.device, &self.config);
                self.window.request_redraw();
                None
            }
            other => {
                log::debug!("no window frame this time: {other:?}");
                self.window.request_redraw();
                None
            }
        }
    }

    /// Records the window pass: cleared, the rendered image at the top
    /// left (when there is one and it fits), the panel over it.
    fn draw(
        &mut self,
        enc: &mut wgpu::CommandEncoder,
        target: &wgpu::Texture,
        image: bool,
        jobs: &[egui::ClippedPrimitive],
        screen: &egui_wgpu::ScreenDescriptor,
    ) {
        let pass = begin_pass(enc, target, "window");
        let mut pass = pass.forget_lifetime();
        if image {
            let (w, h) = self.render_size;
            if w as u32 <= self.config.width && h as u32 <= self.config.height {
                self.present.draw(
                    &mut pass,
                    &self.present_bind,
                    [0.0, 0.0, w as f32, h as f32],
                );
            }
        }
        pass.set_viewport(
            0.0,
            0.0,
            self.config.width as f32,
            self.config.height as f32,
            0.0,
            1.0,
        );
        self.egui_renderer.render(&mut pass, jobs, screen);
    }
}

/// The captured window (`capture_window`'s buffer of padded rows `row`
/// bytes long) as tightly packed RGB, with its size.
fn captured_rgb(
    ctx: &Context,
    staging: &wgpu::Buffer,
    row: usize,
    config: &wgpu::SurfaceConfiguration,
) -> Result<((usize, usize), Vec<u8>)> {
    let bgra = matches!(
        config.format,
        wgpu::TextureFormat::Bgra8Unorm | wgpu::TextureFormat::Bgra8UnormSrgb
    );
    let size = (config.width, config.height);
    let rgb = read_rgb(ctx, staging, row, size, bgra)?;
    Ok(((size.0 as usize, size.1 as usize), rgb))
}

/// Records a copy of the window's frame into a read-back buffer; returns it
/// with its padded row length (bytes). Needs an 8-bit RGBA or BGRA window
/// format that allows copies.
fn capture_window(
    ctx: &Context,
    enc: &mut wgpu::CommandEncoder,
    texture: &wgpu::Texture,
    config: &wgpu::SurfaceConfiguration,
) -> Result<(wgpu::Buffer, usize)> {
    use wgpu::TextureFormat as F;
    if !config.usage.contains(wgpu::TextureUsages::COPY_SRC)
        || !matches!(
            config.format,
            F::Bgra8Unorm | F::Bgra8UnormSrgb | F::Rgba8Unorm | F::Rgba8UnormSrgb
        )
    {
        return Err(Error::Gpu(format!(
            "window screenshots need a window that allows copies in 8-bit RGBA or BGRA; this one \
             is {:?} ({:?}): take view screenshots instead",
            config.format, config.usage
        )));
    }
    Ok(copy_out(ctx, enc, texture, (config.width, config.height)))
}
