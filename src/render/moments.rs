//! GPU slope-moment pyramid (`shaders/moments.wgsl`; CPU reference
//! [`crate::micro::moments`]): from a normal texture, texture A with
//! `(x̃, ỹ, x̃², ỹ²)` and texture B with `x̃ỹ`, each with every mip level
//! down to 1 × 1, resident for the skin pass. Rebuilt by [`MomentStage::encode`]
//! whenever the normals change (every dynamic frame).

use crate::error::Result;
use crate::gpu::{buffers, compute_pipeline, dispatch, Context};
use crate::micro::moments::{level_count, level_side, MomentLevel, MomentPyramid};

/// The shader source.
pub const SHADER: &str = include_str!("../../shaders/moments.wgsl");

/// Format of texture A (four moments a texel).
pub const FORMAT_A: wgpu::TextureFormat = wgpu::TextureFormat::Rgba32Float;
/// Format of texture B (the cross moment).
pub const FORMAT_B: wgpu::TextureFormat = wgpu::TextureFormat::R32Float;

/// The two textures of a pyramid and the bind groups that fill them.
pub struct MomentPyramidGpu {
    /// `(x̃, ỹ, x̃², ỹ²)`, every mip level.
    pub a: wgpu::Texture,
    /// `x̃ỹ`, every mip level.
    pub b: wgpu::Texture,
    /// Width and height of level 0.
    pub size: (usize, usize),
    /// Per pass: the bind group and the size written.
    passes: Vec<(wgpu::BindGroup, (usize, usize))>,
}

/// The compiled stage.
pub struct MomentStage {
    texel: wgpu::ComputePipeline,
    down: wgpu::ComputePipeline,
}

fn level_view(texture: &wgpu::Texture, level: u32) -> wgpu::TextureView {
    texture.create_view(&wgpu::TextureViewDescriptor {
        base_mip_level: level,
        mip_level_count: Some(1),
        ..Default::default()
    })
}

fn level_size((w, h): (usize, usize), level: usize) -> (usize, usize) {
    (level_side(w, level), level_side(h, level))
}

impl MomentStage {
    /// Compiles the stage.
    pub fn new(ctx: &Context) -> MomentStage {
        MomentStage {
            texel: compute_pipeline(ctx, "moments.wgsl", SHADER, "texel_moments"),
            down: compute_pipeline(ctx, "moments.wgsl", SHADER, "downsample"),
        }
    }

    /// The pyramid of the `width × height` normal texture `normals`
    /// (`Rgba32Float`, sampled), allocated and bound, not yet filled.
    pub fn pyramid(
        &self,
        ctx: &Context,
        normals: &wgpu::Texture,
        (width, height): (usize, usize),
    ) -> MomentPyramidGpu {
        let levels = level_count(width, height);
        let texture = |label, format| {
            ctx.device.create_texture(&wgpu::TextureDescriptor {
                label: Some(label),
                size: wgpu::Extent3d {
                    width: width as u32,
                    height: height as u32,
                    depth_or_array_layers: 1,
                },
                mip_level_count: levels as u32,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D2,
                format,
                usage: wgpu::TextureUsages::STORAGE_BINDING
                    | wgpu::TextureUsages::TEXTURE_BINDING
                    | wgpu::TextureUsages::COPY_SRC,
                view_formats: &[],
            })
        };
        let a = texture("slope moments", FORMAT_A);
        let b = texture("slope cross moment", FORMAT_B);
        let normals_view = normals.create_view(&wgpu::TextureViewDescriptor::default());
        // The first pass reads no `src_b`: its bindings are 0, 2 and 3.
        let (a0, b0) = (level_view(&a, 0), level_view(&b, 0));
        let entries =
            [(0, &normals_view), (2, &a0), (3, &b0)].map(|(binding, view)| wgpu::BindGroupEntry {
                binding,
                resource: wgpu::BindingResource::TextureView(view),
            });
        let first = ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("slope moments"),
            layout: &self.texel.get_bind_group_layout(0),
            entries: &entries,
        });
        let mut passes = vec![(first, (width, height))];
        for level in 1..levels as u32 {
            let layout = self.down.get_bind_group_layout(0);
            let entries = [
                level_view(&a, level - 1),
                level_view(&b, level - 1),
                level_view(&a, level),
                level_view(&b, level),
            ];
            let resources: Vec<_> = entries
                .iter()
                .map(wgpu::BindingResource::TextureView)
                .collect();
            passes.push((
                crate::gpu::bind_group(ctx, &layout, &resources),
                level_size((width, height), level as usize),
            ));
        }
        MomentPyramidGpu {
            a,
            b,
            size: (width, height),
            passes,
        }
    }

    /// Records the passes that fill `pyramid` from its normals.
    pub fn encode(&self, encoder: &mut wgpu::CommandEncoder, pyramid: &MomentPyramidGpu) {
        for (k, (bind, (w, h))) in pyramid.passes.iter().enumerate() {
            let pipeline = if k == 0 { &self.texel } else { &self.down };
            dispatch(encoder, "slope moments", pipeline, &[bind], *w, *h);
        }
    }
}

impl MomentPyramidGpu {
    /// Levels, level 0 first.
    pub fn levels(&self) -> usize {
        self.passes.len()
    }

    /// Reads every level back (for tests against the CPU reference).
    pub fn read(&self, ctx: &Context) -> Result<MomentPyramid> {
        let mut levels = Vec::with_capacity(self.levels());
        for level in 0..self.levels() {
            let (width, height) = level_size(self.size, level);
            let a: Vec<[f32; 4]> = read_level(ctx, &self.a, level, width, height)?;
            let b: Vec<f32> = read_level(ctx, &self.b, level, width, height)?;
            let texels = a
                .iter()
                .zip(&b)
                .map(|(a, &b)| [a[0], a[1], a[2], a[3], b])
                .collect();
            levels.push(MomentLevel {
                width,
                height,
                texels,
            });
        }
        Ok(MomentPyramid { levels })
    }
}

/// Reads mip `level` of `texture` through a one-level copy.
fn read_level<T: bytemuck::Pod>(
    ctx: &Context,
    texture: &wgpu::Texture,
    level: usize,
    width: usize,
    height: usize,
) -> Result<Vec<T>> {
    let copy = buffers::texture(
        ctx,
        "moment level",
        (width, height),
        texture.format(),
        wgpu::TextureUsages::COPY_DST | wgpu::TextureUsages::COPY_SRC,
    );
    let mut encoder = crate::gpu::encoder(ctx);
    encoder.copy_texture_to_texture(
        wgpu::TexelCopyTextureInfo {
            texture,
            mip_level: level as u32,
            origin: wgpu::Origin3d::ZERO,
            aspect: wgpu::TextureAspect::All,
        },
        copy.as_image_copy(),
        wgpu::Extent3d {
            width: width as u32,
            height: height as u32,
            depth_or_array_layers: 1,
        },
    );
    ctx.queue.submit([encoder.finish()]);
    buffers::read_texture_texels(ctx, &copy, width, height)
}

/// The pyramid of `normals` computed on the GPU (for tests and tools).
pub fn moment_pyramid(
    ctx: &Context,
    normals: &[[f32; 3]],
    width: usize,
    height: usize,
) -> Result<MomentPyramid> {
    ctx.check_map(width, height, 16)?;
    let rgba: Vec<[f32; 4]> = normals.iter().map(|n| [n[0], n[1], n[2], 0.0]).collect();
    let texture = buffers::upload_texture(
        ctx,
        "normals",
        (width, height),
        wgpu::TextureFormat::Rgba32Float,
        16,
        bytemuck::cast_slice(&rgba),
    );
    let stage = MomentStage::new(ctx);
    let pyramid = stage.pyramid(ctx, &texture, (width, height));
    let mut encoder = crate::gpu::encoder(ctx);
    stage.encode(&mut encoder, &pyramid);
    ctx.queue.submit([encoder.finish()]);
    pyramid.read(ctx)
}
