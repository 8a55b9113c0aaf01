//! The six-Gaussian texture-space diffusion (`shaders/diffusion.wgsl`;
//! CPU reference [`super::profile::diffuse`]): twelve separable passes,
//! Gaussian `i` blurred from Gaussian `i − 1` and stored at its own side
//! ([`super::profile::level_sizes`]: the wide Gaussians coarser).

use bytemuck::{Pod, Zeroable};

use super::profile::{pass_sizes, tap_weights, variance_steps};
use super::stage::{sampler_entry, texture_entry, uniform_entry, view};
use crate::gpu::{buffers, dispatch, Context};

/// The shader source.
pub const SHADER: &str = include_str!("../../shaders/diffusion.wgsl");

/// Format of the blurred textures.
pub const FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba16Float;

/// Per-pass uniforms; mirrors WGSL `BlurInfo`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct BlurInfo {
    /// Tap weights for offsets −3 … 0.
    pub taps_a: [f32; 4],
    /// Tap weights for offsets 1 … 3 (last unused).
    pub taps_b: [f32; 4],
    /// Direction in texels.
    pub axis: [f32; 2],
    /// Variance added (mm²).
    pub variance: f32,
    /// Padding.
    pub pad: f32,
}

impl BlurInfo {
    /// Pass along `axis` (0: u, 1: v) adding `variance` mm².
    pub fn new(axis: usize, variance: f64) -> BlurInfo {
        let w = tap_weights().map(|x| x as f32);
        BlurInfo {
            taps_a: [w[0], w[1], w[2], w[3]],
            taps_b: [w[4], w[5], w[6], 0.0],
            axis: if axis == 0 { [1.0, 0.0] } else { [0.0, 1.0] },
            variance: variance as f32,
            pad: 0.0,
        }
    }
}

/// The compiled stage: its six output textures (one per Gaussian, each at
/// its level size), the u passes' results, and the twelve passes.
pub struct DiffusionStage {
    pipeline: wgpu::ComputePipeline,
    // Bind group and output size of each pass.
    passes: Vec<(wgpu::BindGroup, (usize, usize))>,
    outputs: Vec<wgpu::Texture>,
    views: Vec<wgpu::TextureView>,
}

impl DiffusionStage {
    /// Compiles the stage for the `irradiance` and `stretch` inputs and
    /// makes the six outputs at `sizes` ([`super::profile::level_sizes`]).
    pub fn new(
        ctx: &Context,
        irradiance: &wgpu::TextureView,
        stretch: &wgpu::TextureView,
        sizes: [usize; 6],
    ) -> DiffusionStage {
        let layout = ctx
            .device
            .create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                label: Some("diffusion"),
                entries: &[
                    uniform_entry(0),
                    texture_entry(1, true, false),
                    texture_entry(2, true, false),
                    sampler_entry(3),
                    wgpu::BindGroupLayoutEntry {
                        binding: 4,
                        visibility: wgpu::ShaderStages::COMPUTE,
                        ty: wgpu::BindingType::StorageTexture {
                            access: wgpu::StorageTextureAccess::WriteOnly,
                            format: FORMAT,
                            view_dimension: wgpu::TextureViewDimension::D2,
                        },
                        count: None,
                    },
                ],
            });
        let module = ctx
            .device
            .create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some("diffusion.wgsl"),
                source: wgpu::ShaderSource::Wgsl(SHADER.into()),
            });
        let pipeline_layout = ctx
            .device
            .create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                label: Some("diffusion"),
                bind_group_layouts: &[Some(&layout)],
                immediate_size: 0,
            });
        let pipeline = ctx
            .device
            .create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                label: Some("diffusion.wgsl"),
                layout: Some(&pipeline_layout),
                module: &module,
                entry_point: Some("main"),
                compilation_options: Default::default(),
                cache: None,
            });
        let usage = wgpu::TextureUsages::STORAGE_BINDING
            | wgpu::TextureUsages::TEXTURE_BINDING
            | wgpu::TextureUsages::COPY_SRC;
        let make = |label, side| buffers::texture(ctx, label, (side, side), FORMAT, usage);
        let outputs: Vec<wgpu::Texture> = sizes
            .iter()
            .map(|&side| make("blurred irradiance", side))
            .collect();
        let views: Vec<wgpu::TextureView> = outputs.iter().map(view).collect();
        // The u pass's result, one texture per distinct size.
        let mut scratch: Vec<((usize, usize), wgpu::TextureView)> = Vec::new();
        let mut rows = irradiance.texture().height() as usize;
        let mut plan = Vec::with_capacity(6);
        for &side in &sizes {
            let [along_u, done] = pass_sizes(rows, side);
            let middle = match scratch.iter().position(|(s, _)| *s == along_u) {
                Some(k) => k,
                None => {
                    let texture = buffers::texture(ctx, "blur scratch", along_u, FORMAT, usage);
                    scratch.push((along_u, view(&texture)));
                    scratch.len() - 1
                }
            };
            plan.push((middle, along_u, done));
            rows = side;
        }
        let sampler = super::stage::linear_sampler(ctx);
        let mut passes = Vec::with_capacity(12);
        for (i, (dv, (middle, along_u, done))) in variance_steps().into_iter().zip(plan).enumerate()
        {
            let source = if i == 0 { irradiance } else { &views[i - 1] };
            let middle = &scratch[middle].1;
            for (axis, (src, dst, size)) in [(source, middle, along_u), (middle, &views[i], done)]
                .into_iter()
                .enumerate()
            {
                let info = buffers::uniform(ctx, "blur info", &BlurInfo::new(axis, dv));
                let bind = crate::gpu::bind_group(
                    ctx,
                    &layout,
                    &[
                        info.as_entire_binding(),
                        wgpu::BindingResource::TextureView(src),
                        wgpu::BindingResource::TextureView(stretch),
                        wgpu::BindingResource::Sampler(&sampler),
                        wgpu::BindingResource::TextureView(dst),
                    ],
                );
                passes.push((bind, size));
            }
        }
        DiffusionStage {
            pipeline,
            passes,
            outputs,
            views,
        }
    }

    /// The six blurred textures, narrowest Gaussian first.
    pub fn outputs(&self) -> &[wgpu::TextureView] {
        &self.views
    }

    /// Records the twelve passes.
    pub fn encode(&self, encoder: &mut wgpu::CommandEncoder) {
        for (bind, (width, height)) in &self.passes {
            dispatch(
                encoder,
                "diffusion",
                &self.pipeline,
                &[bind],
                *width,
                *height,
            );
        }
    }
}

/// Runs the chain once on the GPU for `irradiance` and `stretch` (square,
/// same size) with the outputs at `sizes` and reads the six blurred
/// textures back: the comparison with [`super::profile::diffuse`] in the
/// tests.
pub fn diffuse_on_gpu(
    ctx: &Context,
    irradiance: &super::profile::Texture,
    stretch: &super::profile::Texture,
    sizes: [usize; 6],
) -> crate::error::Result<Vec<super::profile::Texture>> {
    let size = irradiance.width;
    let upload = |label, t: &super::profile::Texture| {
        let halves: Vec<u16> = t
            .texels
            .iter()
            .flatten()
            .map(|&x| half::f16::from_f32(x).to_bits())
            .collect();
        crate::gpu::buffers::upload_texture(
            ctx,
            label,
            (size, size),
            FORMAT,
            8,
            bytemuck::cast_slice(&halves),
        )
    };
    let (irr, st) = (upload("irradiance", irradiance), upload("stretch", stretch));
    let stage = DiffusionStage::new(ctx, &view(&irr), &view(&st), sizes);
    let mut enc = crate::gpu::encoder(ctx);
    stage.encode(&mut enc);
    ctx.queue.submit([enc.finish()]);
    let result = stage
        .outputs
        .iter()
        .zip(sizes)
        .map(|(t, side)| {
            let texels = buffers::read_texture_texels::<[u16; 4]>(ctx, t, side, side)?
                .into_iter()
                .map(|h| h.map(|b| half::f16::from_bits(b).to_f32()))
                .collect();
            Ok(super::profile::Texture {
                width: side,
                height: side,
                texels,
            })
        })
        .collect();
    ctx.finish()?;
    result
}
