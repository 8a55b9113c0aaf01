//! Texture-space irradiance (`shaders/irradiance.wgsl`, with
//! `lighting.wgsl` prepended): the top surface drawn into UV space writes
//! the pre-scatter irradiance, the stretch map (mm per texel along u and v),
//! the light transmitted from behind (translucent shadow map) and each
//! light's shadow factor.

use super::stage::{render_pipeline, surface_layout, PipelineSpec};
use crate::gpu::Context;

/// The shader source (without `lighting.wgsl`).
pub const SHADER: &str = include_str!("../../shaders/irradiance.wgsl");

/// Format of the four targets (irradiance, stretch, transmitted, shadows).
pub const FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba16Float;

/// The whole module as compiled.
pub fn source() -> String {
    format!("{}\n{}", super::lighting::SHADER, SHADER)
}

/// The compiled stage.
pub struct IrradianceStage {
    pipeline: wgpu::RenderPipeline,
}

impl IrradianceStage {
    /// Compiles the stage against the lighting group layout.
    pub fn new(ctx: &Context, lighting: &wgpu::BindGroupLayout) -> IrradianceStage {
        let source = source();
        IrradianceStage {
            pipeline: render_pipeline(
                ctx,
                &PipelineSpec {
                    label: "irradiance.wgsl",
                    source: &source,
                    layouts: &[lighting],
                    vertex: ("vs_main", surface_layout()),
                    fragment: "fs_main",
                    targets: &[FORMAT; 4],
                    depth: false,
                    cull: false,
                    samples: 1,
                },
            ),
        }
    }

    /// Records the pass into `targets` (irradiance, stretch, transmitted,
    /// shadow factors).
    pub fn encode(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        lighting: &wgpu::BindGroup,
        targets: [&wgpu::TextureView; 4],
        surface: (&wgpu::Buffer, u32),
    ) {
        let clear = wgpu::Color::TRANSPARENT;
        let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some("irradiance"),
            color_attachments: &targets.map(|v| super::stage::color_attachment(v, clear)),
            ..Default::default()
        });
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, lighting, &[]);
        pass.set_vertex_buffer(0, surface.0.slice(..));
        pass.draw(0..surface.1, 0..1);
    }
}
