//! GPU raster of the surface field into UV textures (`shaders/raster.wgsl`;
//! CPU reference [`crate::strain::StrainRaster::new`]).
//!
//! A render pass draws the surface triangles with their UVs as positions
//! into two `Rgba32Float` targets holding the interpolated `T − I` and
//! `Q Rᵀ` (row-major). The triangle indices stay resident; per frame only the
//! per-vertex matrices are uploaded. A texel whose `Q Rᵀ` is zero lies off
//! the surface (inside the surface `Q Rᵀ` has full rank).

use bytemuck::{Pod, Zeroable};
use nalgebra::Matrix2;

use super::{buffers, Context};
use crate::error::Result;
use crate::strain::{StrainRaster, SurfaceField};

/// The shader source.
pub const SHADER: &str = include_str!("../../shaders/raster.wgsl");

/// Format of both raster targets.
pub const FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba32Float;

/// One surface vertex as the raster reads it; mirrors WGSL `RasterVertex`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct RasterVertex {
    /// Texture coordinates.
    pub uv: [f32; 2],
    /// `T − I`, row-major (full f32 precision in the small deviations).
    pub t: [f32; 4],
    /// `Q Rᵀ`, row-major.
    pub frame: [f32; 4],
}

fn row_major(m: &Matrix2<f64>) -> [f32; 4] {
    [m[(0, 0)], m[(0, 1)], m[(1, 0)], m[(1, 1)]].map(|x| x as f32)
}

/// The raster vertices of a surface field.
pub fn vertices(field: &SurfaceField) -> Vec<RasterVertex> {
    let (_, uvs) = field.layout();
    field
        .vertices
        .iter()
        .zip(uvs)
        .map(|(v, uv)| RasterVertex {
            uv: [uv.x as f32, uv.y as f32],
            t: row_major(&(v.t - Matrix2::identity())),
            frame: row_major(&v.uv_frame),
        })
        .collect()
}

/// The surface on the GPU: resident triangle indices, per-frame vertices.
pub struct SurfaceBuffers {
    vertices: wgpu::Buffer,
    indices: wgpu::Buffer,
    vertex_count: usize,
    index_count: u32,
}

impl SurfaceBuffers {
    /// Buffers for `field`'s layout, holding its current vertices.
    pub fn new(ctx: &Context, field: &SurfaceField) -> SurfaceBuffers {
        SurfaceBuffers::from_parts(ctx, field.layout().0, &vertices(field))
    }

    /// Buffers for triangles `tri` over raster vertices `verts`.
    pub fn from_parts(ctx: &Context, tri: &[[usize; 3]], verts: &[RasterVertex]) -> SurfaceBuffers {
        let indices: Vec<u32> = tri.iter().flatten().map(|&k| k as u32).collect();
        SurfaceBuffers {
            vertices: buffers::init(
                ctx,
                "raster vertices",
                bytemuck::cast_slice(verts),
                wgpu::BufferUsages::VERTEX | wgpu::BufferUsages::COPY_DST,
            ),
            indices: buffers::init(
                ctx,
                "raster indices",
                bytemuck::cast_slice(&indices),
                wgpu::BufferUsages::INDEX,
            ),
            vertex_count: verts.len(),
            index_count: indices.len() as u32,
        }
    }

    /// Whether `field` has the layout these buffers were made for.
    pub fn fits(&self, field: &SurfaceField) -> bool {
        let (tri, _) = field.layout();
        field.vertices.len() == self.vertex_count && tri.len() * 3 == self.index_count as usize
    }

    /// Uploads `field`'s per-vertex matrices (same layout).
    pub fn update(&self, ctx: &Context, field: &SurfaceField) {
        debug_assert!(self.fits(field));
        self.write(ctx, &vertices(field));
    }

    /// Uploads raster vertices (one per vertex of the layout).
    pub fn write(&self, ctx: &Context, vertices: &[RasterVertex]) {
        assert_eq!(vertices.len(), self.vertex_count);
        ctx.queue
            .write_buffer(&self.vertices, 0, bytemuck::cast_slice(vertices));
    }
}

/// The two raster targets of one size.
pub struct RasterTargets {
    /// Texels along u.
    pub width: usize,
    /// Texels along v.
    pub height: usize,
    /// Interpolated `T − I`.
    pub t: wgpu::Texture,
    /// Interpolated `Q Rᵀ`.
    pub frame: wgpu::Texture,
    /// Views of `t` and `frame`, made once for every pass that uses them.
    pub views: [wgpu::TextureView; 2],
}

impl RasterTargets {
    /// Targets of `width × height` texels.
    pub fn new(ctx: &Context, width: usize, height: usize) -> RasterTargets {
        RasterTargets::new_with_usage(ctx, width, height, wgpu::TextureUsages::empty())
    }

    /// Targets with `extra` usages besides rendering, binding and copying out.
    pub fn new_with_usage(
        ctx: &Context,
        width: usize,
        height: usize,
        extra: wgpu::TextureUsages,
    ) -> RasterTargets {
        let usage = wgpu::TextureUsages::RENDER_ATTACHMENT
            | wgpu::TextureUsages::TEXTURE_BINDING
            | wgpu::TextureUsages::COPY_SRC
            | extra;
        let make = |label| buffers::texture(ctx, label, (width, height), FORMAT, usage);
        let (t, frame) = (make("raster T"), make("raster Q R^T"));
        let views = [&t, &frame].map(|x| x.create_view(&wgpu::TextureViewDescriptor::default()));
        RasterTargets {
            width,
            height,
            t,
            frame,
            views,
        }
    }
}

/// The raster render pipeline.
pub struct RasterStage {
    pipeline: wgpu::RenderPipeline,
}

impl RasterStage {
    /// Compiles the stage.
    pub fn new(ctx: &Context) -> RasterStage {
        let module = ctx
            .device
            .create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some("raster.wgsl"),
                source: wgpu::ShaderSource::Wgsl(SHADER.into()),
            });
        let attributes = wgpu::vertex_attr_array![0 => Float32x2, 1 => Float32x4, 2 => Float32x4];
        let target = Some(wgpu::ColorTargetState {
            format: FORMAT,
            blend: None,
            write_mask: wgpu::ColorWrites::ALL,
        });
        let pipeline = ctx
            .device
            .create_render_pipeline(&wgpu::RenderPipelineDescriptor {
                label: Some("raster"),
                layout: None,
                vertex: wgpu::VertexState {
                    module: &module,
                    entry_point: Some("vs_main"),
                    compilation_options: Default::default(),
                    buffers: &[Some(wgpu::VertexBufferLayout {
                        array_stride: std::mem::size_of::<RasterVertex>() as u64,
                        step_mode: wgpu::VertexStepMode::Vertex,
                        attributes: &attributes,
                    })],
                },
                primitive: wgpu::PrimitiveState {
                    topology: wgpu::PrimitiveTopology::TriangleList,
                    // UV layouts may wind either way.
                    cull_mode: None,
                    ..Default::default()
                },
                depth_stencil: None,
                multisample: wgpu::MultisampleState::default(),
                fragment: Some(wgpu::FragmentState {
                    module: &module,
                    entry_point: Some("fs_main"),
                    compilation_options: Default::default(),
                    targets: &[target.clone(), target],
                }),
                multiview_mask: None,
                cache: None,
            });
        RasterStage { pipeline }
    }

    /// Records the pass drawing `surface` into `targets`, cleared first when
    /// `clear`. Without the clear the texels the triangles do not cover keep
    /// their values: a chain redrawing the same UV layout clears once, as
    /// every covered texel is written again each frame.
    pub fn encode(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        surface: &SurfaceBuffers,
        targets: &RasterTargets,
        clear: bool,
    ) {
        let mut pass = begin(encoder, "raster", targets, clear);
        pass.set_pipeline(&self.pipeline);
        pass.set_vertex_buffer(0, surface.vertices.slice(..));
        pass.set_index_buffer(surface.indices.slice(..), wgpu::IndexFormat::Uint32);
        pass.draw_indexed(0..surface.index_count, 0, 0..1);
    }
}

impl RasterStage {
    /// Records a pass clearing `targets` to zero (off the surface).
    pub fn clear(&self, encoder: &mut wgpu::CommandEncoder, targets: &RasterTargets) {
        begin(encoder, "raster clear", targets, true);
    }
}

/// A render pass into both targets, cleared first when `clear`.
fn begin<'e>(
    encoder: &'e mut wgpu::CommandEncoder,
    label: &str,
    targets: &RasterTargets,
    clear: bool,
) -> wgpu::RenderPass<'e> {
    let attachment = |view| {
        Some(wgpu::RenderPassColorAttachment {
            view,
            depth_slice: None,
            resolve_target: None,
            ops: wgpu::Operations {
                load: if clear {
                    wgpu::LoadOp::Clear(wgpu::Color::TRANSPARENT)
                } else {
                    wgpu::LoadOp::Load
                },
                store: wgpu::StoreOp::Store,
            },
        })
    };
    let views = &targets.views;
    encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
        label: Some(label),
        color_attachments: &[attachment(&views[0]), attachment(&views[1])],
        ..Default::default()
    })
}

/// Rasterises `field` at `width × height` on the GPU and reads the result
/// back as a [`StrainRaster`] (inside where `Q Rᵀ ≠ 0`), for comparison
/// with the CPU reference.
pub fn rasterize(
    ctx: &Context,
    field: &SurfaceField,
    width: usize,
    height: usize,
) -> Result<StrainRaster> {
    ctx.check_map(width, height, 16)?;
    let stage = RasterStage::new(ctx);
    let surface = SurfaceBuffers::new(ctx, field);
    let targets = RasterTargets::new(ctx, width, height);
    let mut encoder = ctx
        .device
        .create_command_encoder(&wgpu::CommandEncoderDescriptor::default());
    stage.encode(&mut encoder, &surface, &targets, true);
    ctx.queue.submit([encoder.finish()]);
    ctx.finish()?;
    let t = buffers::read_texture_rgba32(ctx, &targets.t, width, height)?;
    let frame = buffers::read_texture_rgba32(ctx, &targets.frame, width, height)?;
    let matrix = |m: &[f32; 4]| Matrix2::new(m[0], m[1], m[2], m[3]).map(f64::from);
    let inside: Vec<bool> = frame.iter().map(|f| f.iter().any(|&x| x != 0.0)).collect();
    Ok(StrainRaster {
        width,
        height,
        t: t.iter()
            .zip(&inside)
            .map(|(m, &i)| {
                if i {
                    matrix(m) + Matrix2::identity()
                } else {
                    Matrix2::zeros()
                }
            })
            .collect(),
        uv_frame: frame.iter().map(matrix).collect(),
        inside,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn vertex_layout_matches_wgsl() {
        // vec2 + vec4 + vec4 as vertex attributes, tightly packed.
        assert_eq!(std::mem::size_of::<RasterVertex>(), 40);
    }
}
