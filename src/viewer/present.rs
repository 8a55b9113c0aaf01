//! Presenting a rendered frame in the window (`shaders/present.wgsl`): the
//! renderer's resolved image is drawn into the view rectangle straight from
//! its storage buffer, one texel a pixel, sRGB-encoded like the frame files.

use bytemuck::{Pod, Zeroable};

use crate::gpu::{buffers, Context};

/// The shader source.
pub const SHADER: &str = include_str!("../../shaders/present.wgsl");

/// The background around the view (the window's clear colour).
pub const BACKGROUND: wgpu::Color = wgpu::Color {
    r: 0.02,
    g: 0.02,
    b: 0.025,
    a: 1.0,
};

/// Uniforms; mirrors WGSL `PresentInfo`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct PresentInfo {
    /// Top-left pixel of the rectangle.
    pub origin: [f32; 2],
    /// Image width and height.
    pub size: [u32; 2],
    /// 1 when the shader encodes sRGB.
    pub encode: u32,
    /// Padding.
    pub pad: [u32; 3],
}

/// The compiled pass for one window format.
pub struct PresentStage {
    pipeline: wgpu::RenderPipeline,
    info: wgpu::Buffer,
    encode: bool,
}

impl PresentStage {
    /// The pass for a window of `format`.
    pub fn new(ctx: &Context, format: wgpu::TextureFormat) -> PresentStage {
        let module = ctx
            .device
            .create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some("present.wgsl"),
                source: wgpu::ShaderSource::Wgsl(SHADER.into()),
            });
        let pipeline = ctx
            .device
            .create_render_pipeline(&wgpu::RenderPipelineDescriptor {
                label: Some("present.wgsl"),
                layout: None,
                vertex: wgpu::VertexState {
                    module: &module,
                    entry_point: Some("vs_main"),
                    compilation_options: Default::default(),
                    buffers: &[],
                },
                primitive: wgpu::PrimitiveState::default(),
                depth_stencil: None,
                multisample: wgpu::MultisampleState::default(),
                fragment: Some(wgpu::FragmentState {
                    module: &module,
                    entry_point: Some("fs_main"),
                    compilation_options: Default::default(),
                    targets: &[Some(wgpu::ColorTargetState {
                        format,
                        blend: None,
                        write_mask: wgpu::ColorWrites::ALL,
                    })],
                }),
                multiview_mask: None,
                cache: None,
            });
        PresentStage {
            pipeline,
            info: buffers::uniform(ctx, "present info", &PresentInfo::default()),
            encode: !format.is_srgb(),
        }
    }

    /// A bind group for `pixels` (`width × height` linear RGBA texels)
    /// shown with its top-left corner at `origin`.
    pub fn bind(
        &self,
        ctx: &Context,
        pixels: &wgpu::Buffer,
        size: (usize, usize),
        origin: [f32; 2],
    ) -> wgpu::BindGroup {
        let info = PresentInfo {
            origin,
            size: [size.0 as u32, size.1 as u32],
            encode: self.encode as u32,
            pad: [0; 3],
        };
        ctx.queue
            .write_buffer(&self.info, 0, bytemuck::bytes_of(&info));
        crate::gpu::bind_group(
            ctx,
            &self.pipeline.get_bind_group_layout(0),
            &[self.info.as_entire_binding(), pixels.as_entire_binding()],
        )
    }

    /// Draws the image into `rect` (x, y, width, height in pixels) of the
    /// pass's target.
    pub fn draw(&self, pass: &mut wgpu::RenderPass<'_>, bind: &wgpu::BindGroup, rect: [f32; 4]) {
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, bind, &[]);
        pass.set_viewport(rect[0], rect[1], rect[2], rect[3], 0.0, 1.0);
        pass.draw(0..3, 0..1);
    }
}

/// A render pass into `target` (a window's frame or an offscreen
/// texture), cleared to [`BACKGROUND`].
pub fn begin_pass<'e>(
    enc: &'e mut wgpu::CommandEncoder,
    target: &wgpu::Texture,
    label: &str,
) -> wgpu::RenderPass<'e> {
    let view = target.create_view(&wgpu::TextureViewDescriptor::default());
    enc.begin_render_pass(&wgpu::RenderPassDescriptor {
        label: Some(label),
        color_attachments: &[Some(wgpu::RenderPassColorAttachment {
            view: &view,
            resolve_target: None,
            depth_slice: None,
            ops: wgpu::Operations {
                load: wgpu::LoadOp::Clear(BACKGROUND),
                store: wgpu::StoreOp::Store,
            },
        })],
        depth_stencil_attachment: None,
        timestamp_writes: None,
        occlusion_query_set: None,
        multiview_mask: None,
    })
}

/// Records a copy of an 8-bit RGBA or BGRA `texture` of `size` pixels
/// into a read-back buffer; returns it with its padded row length (bytes).
pub fn copy_out(
    ctx: &Context,
    enc: &mut wgpu::CommandEncoder,
    texture: &wgpu::Texture,
    size: (u32, u32),
) -> (wgpu::Buffer, usize) {
    let row = (4 * size.0 as usize).next_multiple_of(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT as usize);
    let staging = buffers::staging(ctx, (row * size.1 as usize) as u64);
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
            width: size.0,
            height: size.1,
            depth_or_array_layers: 1,
        },
    );
    (staging, row)
}

/// A copy made by [`copy_out`] (rows `row` bytes apart) as tightly packed
/// RGB; `bgra` swaps the channels of a BGRA texture.
pub fn read_rgb(
    ctx: &Context,
    staging: &wgpu::Buffer,
    row: usize,
    size: (u32, u32),
    bgra: bool,
) -> crate::error::Result<Vec<u8>> {
    let (w, h) = (size.0 as usize, size.1 as usize);
    let bytes: Vec<u8> = buffers::map_read(ctx, staging, row * h)?;
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
    Ok(rgb)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn present_info_matches_wgsl_layout() {
        assert_eq!(std::mem::size_of::<PresentInfo>(), 32);
    }
}
