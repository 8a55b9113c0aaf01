//! The final camera pass (`shaders/skin.wgsl`, with `lighting.wgsl`
//! prepended): the skin surface, the patch's cut sides and the probe, into
//! a supersampled HDR target with depth.

use super::stage::{mesh_layout, render_pipeline, surface_layout, PipelineSpec};
use crate::gpu::Context;

/// The shader source (without `lighting.wgsl`).
pub const SHADER: &str = include_str!("../../shaders/skin.wgsl");

/// Format of the HDR target.
pub const HDR_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba16Float;

/// The whole module as compiled.
pub fn source() -> String {
    format!(
        "{}\n{}\n{}",
        super::lighting::SHADER,
        super::overlay::SHADER,
        SHADER
    )
}

/// The three pipelines of the pass.
pub struct SkinStage {
    skin: wgpu::RenderPipeline,
    tissue: wgpu::RenderPipeline,
    probe: wgpu::RenderPipeline,
}

/// Vertex buffers and counts of one frame.
pub struct FrameBuffers<'a> {
    /// Top surface.
    pub surface: (&'a wgpu::Buffer, u32),
    /// Cut sides and bottom.
    pub sides: (&'a wgpu::Buffer, u32),
    /// Probe (count 0: not drawn).
    pub probe: (&'a wgpu::Buffer, u32),
}

impl SkinStage {
    /// Compiles the pipelines against the lighting (group 0) and diffused
    /// light (group 1) layouts for targets of `samples` samples a pixel.
    pub fn new(ctx: &Context, layouts: [&wgpu::BindGroupLayout; 2], samples: u32) -> SkinStage {
        let source = source();
        let make = |vertex: (&str, wgpu::VertexBufferLayout<'static>), fragment: &str, cull| {
            render_pipeline(
                ctx,
                &PipelineSpec {
                    label: "skin.wgsl",
                    source: &source,
                    layouts: &layouts,
                    vertex,
                    fragment,
                    targets: &[HDR_FORMAT],
                    depth: true,
                    cull,
                    samples,
                },
            )
        };
        SkinStage {
            skin: make(("vs_surface", surface_layout()), "fs_skin", false),
            tissue: make(("vs_mesh", mesh_layout()), "fs_tissue", false),
            probe: make(("vs_mesh", mesh_layout()), "fs_probe", false),
        }
    }

    /// Records the pass into `hdr` with `depth`; a multisampled `hdr` is
    /// resolved into `resolve`.
    pub fn encode(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        binds: [&wgpu::BindGroup; 2],
        (hdr, resolve): (&wgpu::TextureView, Option<&wgpu::TextureView>),
        depth: &wgpu::TextureView,
        frame: &FrameBuffers<'_>,
    ) {
        // A dark grey studio background (linear).
        let clear = wgpu::Color {
            r: 0.018,
            g: 0.02,
            b: 0.024,
            a: 1.0,
        };
        let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some("skin"),
            color_attachments: &[super::stage::resolved_attachment(hdr, resolve, clear)],
            depth_stencil_attachment: Some(super::stage::depth_attachment(depth)),
            ..Default::default()
        });
        pass.set_bind_group(0, binds[0], &[]);
        pass.set_bind_group(1, binds[1], &[]);
        for (pipeline, (buffer, count)) in [
            (&self.skin, frame.surface),
            (&self.tissue, frame.sides),
            (&self.probe, frame.probe),
        ] {
            if count > 0 {
                pass.set_pipeline(pipeline);
                pass.set_vertex_buffer(0, buffer.slice(..));
                pass.draw(0..count, 0..1);
            }
        }
    }
}
