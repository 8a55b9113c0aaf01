//! Shadow and translucent shadow maps (`shaders/shadow.wgsl`): per light,
//! one layer of an `Rg32Float` array holding the nearest surface's
//! distance to the light and its irradiance factor.

use bytemuck::{Pod, Zeroable};

use super::stage::{mesh_layout, render_pipeline, view, PipelineSpec, DEPTH_FORMAT};
use super::RenderSetup;
use crate::gpu::{bind_group, buffers, Context};

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

/// The shadow pass's resources: one depth-map layer per light (at least
/// one), each with its own uniform and bind group.
pub struct ShadowMaps {
    pub(crate) stage: ShadowStage,
    pub(crate) infos: Vec<wgpu::Buffer>,
    pub(crate) binds: Vec<wgpu::BindGroup>,
    /// One view per layer (the render targets).
    pub(crate) layers: Vec<wgpu::TextureView>,
    pub(crate) depth: wgpu::TextureView,
    /// All layers as one array (what the lighting samples).
    pub(crate) array: wgpu::TextureView,
}

impl ShadowMaps {
    pub fn new(ctx: &Context, setup: &RenderSetup) -> ShadowMaps {
        let layers = setup.lights.len().max(1);
        let s = setup.shadow_map_px;
        let maps = ctx.device.create_texture(&wgpu::TextureDescriptor {
            label: Some("shadow maps"),
            size: wgpu::Extent3d {
                width: s as u32,
                height: s as u32,
                depth_or_array_layers: layers as u32,
            },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: FORMAT,
            usage: wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::TEXTURE_BINDING,
            view_formats: &[],
        });
        let layer_views = (0..layers as u32)
            .map(|k| {
                maps.create_view(&wgpu::TextureViewDescriptor {
                    dimension: Some(wgpu::TextureViewDimension::D2),
                    base_array_layer: k,
                    array_layer_count: Some(1),
                    ..Default::default()
                })
            })
            .collect();
        let array = maps.create_view(&wgpu::TextureViewDescriptor {
            dimension: Some(wgpu::TextureViewDimension::D2Array),
            ..Default::default()
        });
        let depth = view(&buffers::texture(
            ctx,
            "shadow depth",
            (s, s),
            DEPTH_FORMAT,
            wgpu::TextureUsages::RENDER_ATTACHMENT,
        ));
        let stage = ShadowStage::new(ctx);
        let infos: Vec<wgpu::Buffer> = (0..layers)
            .map(|_| buffers::uniform(ctx, "shadow info", &ShadowInfo::default()))
            .collect();
        let binds = infos
            .iter()
            .map(|b| bind_group(ctx, &stage.layout, &[b.as_entire_binding()]))
            .collect();
        ShadowMaps {
            stage,
            infos,
            binds,
            layers: layer_views,
            depth,
            array,
        }
    }
}
