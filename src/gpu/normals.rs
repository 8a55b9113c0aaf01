//! GPU normal map (`shaders/normals.wgsl`; CPU reference
//! [`crate::micro::normals::normal_map`]).

use super::map::{with_map_access, GpuMap};
use super::{bind_group, buffers, compute_pipeline, dispatch, encoder, Context};
use crate::error::Result;
use crate::micro::DisplacementMap;

/// The shader source (without the map access functions).
pub const SHADER: &str = include_str!("../../shaders/normals.wgsl");

/// The compiled stage.
pub struct NormalsStage {
    pipeline: wgpu::ComputePipeline,
}

impl NormalsStage {
    /// Compiles the stage.
    pub fn new(ctx: &Context) -> NormalsStage {
        NormalsStage {
            pipeline: compute_pipeline(ctx, "normals.wgsl", &with_map_access(SHADER), "main"),
        }
    }

    /// A bind group writing `map`'s normals (3 floats per texel) to `out`.
    pub fn bind(&self, ctx: &Context, map: &GpuMap, out: &wgpu::Buffer) -> wgpu::BindGroup {
        bind_group(
            ctx,
            &self.pipeline.get_bind_group_layout(0),
            &[
                map.info.as_entire_binding(),
                map.heights.as_entire_binding(),
                out.as_entire_binding(),
            ],
        )
    }

    /// Records the dispatch.
    pub fn encode(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        bind: &wgpu::BindGroup,
        width: usize,
        height: usize,
    ) {
        dispatch(encoder, "normals", &self.pipeline, bind, width, height);
    }
}

/// A buffer for the normals of `width × height` texels.
pub fn normal_buffer(ctx: &Context, width: usize, height: usize) -> wgpu::Buffer {
    buffers::storage_zeroed(ctx, "normals", 12 * (width * height) as u64)
}

/// The normal map of `map` computed on the GPU.
pub fn normal_map(ctx: &Context, map: &DisplacementMap) -> Result<Vec<[f32; 3]>> {
    ctx.check_map(map.width, map.height, 12)?;
    let stage = NormalsStage::new(ctx);
    let src = GpuMap::upload(ctx, map);
    let out = normal_buffer(ctx, map.width, map.height);
    let bind = stage.bind(ctx, &src, &out);
    let mut enc = encoder(ctx);
    stage.encode(&mut enc, &bind, map.width, map.height);
    ctx.queue.submit([enc.finish()]);
    buffers::read(ctx, &out, map.width * map.height)
}
