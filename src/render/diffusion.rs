//! The six-Gaussian texture-space diffusion (`shaders/diffusion.wgsl`;
//! CPU reference [`super::profile::diffuse`]): twelve separable passes,
//! Gaussian `i` blurred from Gaussian `i − 1`.

use bytemuck::{Pod, Zeroable};

use super::profile::{tap_weights, variance_steps};
use super::stage::{sampler_entry, texture_entry, uniform_entry};
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

/// The compiled stage with its twelve bind groups.
pub struct DiffusionStage {
    pipeline: wgpu::ComputePipeline,
    binds: Vec<wgpu::BindGroup>,
    size: usize,
}

impl DiffusionStage {
    /// Compiles the stage for `irradiance` and `stretch` inputs, the
    /// `scratch` texture and the six `outputs` (all `size²`).
    pub fn new(
        ctx: &Context,
        size: usize,
        irradiance: &wgpu::TextureView,
        stretch: &wgpu::TextureView,
        scratch: &wgpu::TextureView,
        outputs: &[wgpu::TextureView],
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
        let sampler = super::stage::linear_sampler(ctx);
        let mut binds = Vec::with_capacity(12);
        for (i, dv) in variance_steps().into_iter().enumerate() {
            let source = if i == 0 { irradiance } else { &outputs[i - 1] };
            for (axis, (src, dst)) in [(source, scratch), (scratch, &outputs[i])]
                .into_iter()
                .enumerate()
            {
                let info = buffers::uniform(ctx, "blur info", &BlurInfo::new(axis, dv));
                binds.push(crate::gpu::bind_group(
                    ctx,
                    &layout,
                    &[
                        info.as_entire_binding(),
                        wgpu::BindingResource::TextureView(src),
                        wgpu::BindingResource::TextureView(stretch),
                        wgpu::BindingResource::Sampler(&sampler),
                        wgpu::BindingResource::TextureView(dst),
                    ],
                ));
            }
        }
        DiffusionStage {
            pipeline,
            binds,
            size,
        }
    }

    /// Records the twelve passes.
    pub fn encode(&self, encoder: &mut wgpu::CommandEncoder) {
        for bind in &self.binds {
            dispatch(
                encoder,
                "diffusion",
                &self.pipeline,
                &[bind],
                self.size,
                self.size,
            );
        }
    }
}

/// Runs the chain once on the GPU for `irradiance` and `stretch` (square,
/// same size) and reads the six blurred textures back: the comparison with
/// [`super::profile::diffuse`] in the tests.
pub fn diffuse_on_gpu(
    ctx: &Context,
    irradiance: &super::profile::Texture,
    stretch: &super::profile::Texture,
) -> crate::error::Result<Vec<super::profile::Texture>> {
    let size = irradiance.width;
    let upload = |label, t: &super::profile::Texture| {
        let halves: Vec<u16> = t
            .texels
            .iter()
            .flatten()
            .map(|&x| half::f16::from_f32(x).to_bits())
            .collect();
        super::renderer::upload_texture(
            ctx,
            label,
            (size, size),
            FORMAT,
            8,
            bytemuck::cast_slice(&halves),
        )
    };
    let (irr, st) = (upload("irradiance", irradiance), upload("stretch", stretch));
    let usage = wgpu::TextureUsages::STORAGE_BINDING
        | wgpu::TextureUsages::TEXTURE_BINDING
        | wgpu::TextureUsages::COPY_SRC;
    let make = |label| buffers::texture(ctx, label, (size, size), FORMAT, usage);
    let scratch = make("blur scratch");
    let outputs: Vec<wgpu::Texture> = (0..6).map(|_| make("blurred")).collect();
    let view = |t: &wgpu::Texture| t.create_view(&wgpu::TextureViewDescriptor::default());
    let out_views: Vec<wgpu::TextureView> = outputs.iter().map(view).collect();
    let stage = DiffusionStage::new(
        ctx,
        size,
        &view(&irr),
        &view(&st),
        &view(&scratch),
        &out_views,
    );
    let mut enc = crate::gpu::encoder(ctx);
    stage.encode(&mut enc);
    ctx.queue.submit([enc.finish()]);
    let result = outputs
        .iter()
        .map(|t| {
            let texels = buffers::read_texture_texels::<[u16; 4]>(ctx, t, size, size)?
                .into_iter()
                .map(|h| h.map(|b| half::f16::from_bits(b).to_f32()))
                .collect();
            Ok(super::profile::Texture {
                width: size,
                height: size,
                texels,
            })
        })
        .collect();
    ctx.finish()?;
    result
}
