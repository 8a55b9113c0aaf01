//! Presentation: the rendered view and the panel drawn into the window,
//! and captures of the whole window (written as PNG).

use super::panel::PanelOutput;
use super::{device, App};
use crate::error::{Error, Result};
use crate::gpu::Context;
use crate::viewer::state::Command;

impl App {
    /// Draws the image and the panel into the window.
    pub(super) fn present(&mut self) -> Result<()> {
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
        let gpu = self.gpu.as_mut().expect("started");
        gpu.egui_state
            .handle_platform_output(&gpu.window, output.platform_output);
        let ppp = output.pixels_per_point;
        let jobs = egui_ctx.tessellate(output.shapes, ppp);
        let frame = match gpu.surface.get_current_texture() {
            wgpu::CurrentSurfaceTexture::Success(f)
            | wgpu::CurrentSurfaceTexture::Suboptimal(f) => f,
            wgpu::CurrentSurfaceTexture::Outdated | wgpu::CurrentSurfaceTexture::Lost => {
                let size = gpu.window.inner_size();
                gpu.config.width = size.width.max(1);
                gpu.config.height = size.height.max(1);
                let ctx = device(&gpu.chain, &gpu.own);
                gpu.surface.configure(&ctx.device, &gpu.config);
                gpu.window.request_redraw();
                return Ok(());
            }
            other => {
                log::debug!("no window frame this time: {other:?}");
                gpu.window.request_redraw();
                return Ok(());
            }
        };
        let view = frame
            .texture
            .create_view(&wgpu::TextureViewDescriptor::default());
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
        {
            let pass = enc.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("window"),
                color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                    view: &view,
                    resolve_target: None,
                    depth_slice: None,
                    ops: wgpu::Operations {
                        load: wgpu::LoadOp::Clear(wgpu::Color {
                            r: 0.02,
                            g: 0.02,
                            b: 0.025,
                            a: 1.0,
                        }),
                        store: wgpu::StoreOp::Store,
                    },
                })],
                depth_stencil_attachment: None,
                timestamp_writes: None,
                occlusion_query_set: None,
                multiview_mask: None,
            });
            let mut pass = pass.forget_lifetime();
            if self.shown.is_some() {
                let (w, h) = gpu.render_size;
                let fits = w as u32 <= gpu.config.width && h as u32 <= gpu.config.height;
                if fits {
                    gpu.present
                        .draw(&mut pass, &gpu.present_bind, [0.0, 0.0, w as f32, h as f32]);
                }
            }
            pass.set_viewport(
                0.0,
                0.0,
                gpu.config.width as f32,
                gpu.config.height as f32,
                0.0,
                1.0,
            );
            gpu.egui_renderer.render(&mut pass, &jobs, &screen);
        }
        let capture = if self.window_shots.is_empty() {
            None
        } else {
            Some(capture_window(ctx, &mut enc, &frame.texture, &gpu.config)?)
        };
        ctx.queue
            .submit(extra.into_iter().chain(std::iter::once(enc.finish())));
        if let Some((staging, row)) = capture {
            let (w, h) = (gpu.config.width as usize, gpu.config.height as usize);
            let bytes: Vec<u8> = crate::gpu::buffers::map_read(ctx, &staging, row * h)?;
            let bgra = matches!(
                gpu.config.format,
                wgpu::TextureFormat::Bgra8Unorm | wgpu::TextureFormat::Bgra8UnormSrgb
            );
            let mut rgb = Vec::with_capacity(w * h * 3);
            for y in 0..h {
                for px in bytes[y * row..y * row + 4 * w].chunks(4) {
                    if bgra {
                        rgb.extend_from_slice(&[px[2], px[1], px[0]]);
                    } else {
                        rgb.extend_from_slice(&px[..3]);
                    }
                }
            }
            for path in std::mem::take(&mut self.window_shots) {
                if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
                    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
                }
                crate::imaging::encode::write_rgb8_png(&path, (w, h), &rgb)?;
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
    let row =
        (4 * config.width as usize).next_multiple_of(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT as usize);
    let staging = crate::gpu::buffers::staging(ctx, (row * config.height as usize) as u64);
    enc.copy_texture_to_buffer(
        wgpu::TexelCopyTextureInfo {
            texture,
            mip_level: 0,
            origin: wgpu::Origin3d::ZERO,
            aspect: wgpu::TextureAspect::All,
        },
        wgpu::TexelCopyBufferInfo {
            buffer: &staging,
            layout: wgpu::TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some(row as u32),
                rows_per_image: None,
            },
        },
        wgpu::Extent3d {
            width: config.width,
            height: config.height,
            depth_or_array_layers: 1,
        },
    );
    Ok((staging, row))
}
