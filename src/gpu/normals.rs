//! GPU normal map (`shaders/normals.wgsl`; CPU reference
//! [`crate::micro::normals::normal_map`]). Normals go to an `Rgba32Float`
//! storage texture: 16 bytes a texel would exceed the storage-buffer
//! binding limit of some adapters at 4096² (128 MiB on lavapipe).

use super::map::{with_map_access, GpuMap};
use super::{bind_group, buffers, compute_pipeline, dispatch, dispatch_tiles, encoder, Context};
use crate::error::Result;
use crate::micro::DisplacementMap;

/// The shader source (without the map access functions).
pub const SHADER: &str = include_str!("../../shaders/normals.wgsl");

/// The compiled stage: over every texel, or over the tiles of a list.
pub struct NormalsStage {
    pipeline: wgpu::ComputePipeline,
    tiled: wgpu::ComputePipeline,
}

impl NormalsStage {
    /// Compiles the stage.
    pub fn new(ctx: &Context) -> NormalsStage {
        let source = with_map_access(SHADER);
        NormalsStage {
            pipeline: compute_pipeline(ctx, "normals.wgsl", &source, "main"),
            tiled: compute_pipeline(ctx, "normals.wgsl", &source, "normals_tiles"),
        }
    }

    /// A bind group writing `map`'s normals to `out` (see [`normal_texture`])
    /// over every texel ([`NormalsStage::encode`]), or, given `tiles`, over
    /// the tiles of that list ([`NormalsStage::encode_tiles`]).
    pub fn bind(
        &self,
        ctx: &Context,
        map: &GpuMap,
        out: &wgpu::Texture,
        tiles: Option<&wgpu::Buffer>,
    ) -> wgpu::BindGroup {
        let view = out.create_view(&wgpu::TextureViewDescriptor::default());
        let mut entries = vec![
            map.info.as_entire_binding(),
            map.heights.as_entire_binding(),
            wgpu::BindingResource::TextureView(&view),
        ];
        let pipeline = match tiles {
            Some(t) => {
                entries.push(t.as_entire_binding());
                &self.tiled
            }
            None => &self.pipeline,
        };
        bind_group(ctx, &pipeline.get_bind_group_layout(0), &entries)
    }

    /// Records the pass over the first `tiles` tiles of the list bound in
    /// `bind`.
    pub fn encode_tiles(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        bind: &wgpu::BindGroup,
        tiles: usize,
    ) {
        dispatch_tiles(encoder, "normals", &self.tiled, &[bind], tiles);
    }

    /// Records the dispatch over every texel.
    pub fn encode(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        bind: &wgpu::BindGroup,
        width: usize,
        height: usize,
    ) {
        dispatch(encoder, "normals", &self.pipeline, &[bind], width, height);
    }
}

/// A texture for the normals of `width × height` texels.
pub fn normal_texture(ctx: &Context, width: usize, height: usize) -> wgpu::Texture {
    buffers::texture(
        ctx,
        "normals",
        (width, height),
        wgpu::TextureFormat::Rgba32Float,
        wgpu::TextureUsages::STORAGE_BINDING
            | wgpu::TextureUsages::COPY_SRC
            | wgpu::TextureUsages::TEXTURE_BINDING,
    )
}

/// Reads a normal texture back as `[x, y, z]` per texel.
pub fn read_normals(
    ctx: &Context,
    texture: &wgpu::Texture,
    width: usize,
    height: usize,
) -> Result<Vec<[f32; 3]>> {
    let texels = buffers::read_texture_rgba32(ctx, texture, width, height)?;
    Ok(texels.into_iter().map(|n| [n[0], n[1], n[2]]).collect())
}

/// The normal map of `map` computed on the GPU.
pub fn normal_map(ctx: &Context, map: &DisplacementMap) -> Result<Vec<[f32; 3]>> {
    ctx.check_map(map.width, map.height, 4)?;
    let stage = NormalsStage::new(ctx);
    let src = GpuMap::upload(ctx, map);
    let out = normal_texture(ctx, map.width, map.height);
    let bind = stage.bind(ctx, &src, &out, None);
    let mut enc = encoder(ctx);
    stage.encode(&mut enc, &bind, map.width, map.height);
    ctx.queue.submit([enc.finish()]);
    read_normals(ctx, &out, map.width, map.height)
}
