//! Shadow and translucent shadow maps (`shaders/shadow.wgsl`): per light,
//! one layer of an `Rg32Float` array holding the nearest surface's
//! distance to the light and its irradiance factor.

use bytemuck::{Pod, Zeroable};

use super::stage::{mesh_layout, render_pipeline, PipelineSpec};
use crate::gpu::Context;

/// The shader source.
pub const SHADER: &str = include_str!("../../shaders/shadow.wgsl");

/// Format of the shadow-map layers.
pub const FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rg32Float;

/// Value of a texel no surface covers (mm).
pub const FAR_MM: f64 = 1e9;

/// Per-light uniforms; mirrors WGSL `ShadowInfo`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct ShadowInfo {
    /// The light's projection.
    pub view_proj: [[f32; 4]; 4],
    /// Direction of travel (w = 0) or position (w = 1).
    pub where_: [f32; 4],
}

/// The compiled stage.
pub struct ShadowStage {
    /// Layout of the per-light uniform group.
    pub layout: wgpu::BindGroupLayout,
    pipeline: wgpu::RenderPipeline,
}

impl ShadowStage {
    /// Compiles the stage.
    pub fn new(ctx: &Context) -> ShadowStage {
        let layout = ctx
            .device
            .create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                label: Some("shadow info"),
                entries: &[super::stage::uniform_entry(0)],
            });
        let pipeline = render_pipeline(
            ctx,
            &PipelineSpec {
                label: "shadow.wgsl",
                source: SHADER,
                layouts: &[&layout],
                vertex: ("vs_main", mesh_layout()),
                fragment: "fs_main",
                targets: &[FORMAT],
                depth: true,
                cull: false,
                samples: 1,
            },
        );
        ShadowStage { layout, pipeline }
    }

    /// Records one light's map: `meshes` (vertex buffer, vertex count) drawn
    /// into `layer` with `depth` as scratch.
    pub fn encode(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        bind: &wgpu::BindGroup,
        layer: &wgpu::TextureView,
        depth: &wgpu::TextureView,
        meshes: &[(&wgpu::Buffer, u32)],
    ) {
        let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some("shadow"),
            color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                view: layer,
                depth_slice: None,
                resolve_target: None,
                ops: wgpu::Operations {
                    load: wgpu::LoadOp::Clear(wgpu::Color {
                        r: FAR_MM,
                        g: 0.0,
                        b: 0.0,
                        a: 0.0,
                    }),
                    store: wgpu::StoreOp::Store,
                },
            })],
            depth_stencil_attachment: Some(super::stage::depth_attachment(depth)),
            timestamp_writes: None,
            occlusion_query_set: None,
            multiview_mask: None,
        });
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, bind, &[]);
        for (buffer, count) in meshes {
            if *count > 0 {
                pass.set_vertex_buffer(0, buffer.slice(..));
                pass.draw(0..*count, 0..1);
            }
        }
    }
}
