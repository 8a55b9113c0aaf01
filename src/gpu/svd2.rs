//! GPU per-texel 2×2 SVD and kernel parameters (`shaders/svd2.wgsl`; CPU
//! references [`crate::strain::Svd2`], [`crate::micro::KernelField::from_strain`]
//! after [`crate::strain::StrainRaster::dilated`]).
//!
//! Reads the raster textures, dilates past the surface edge while reading,
//! and gives per texel `(r_s, r_t)` and the two passes' parameters
//! `(axis x, axis y, α, σ texels)`. The kernel model's three tables are
//! uploaded once as `(r, value)` pairs. The shader's inputs are bind group
//! 1, shared with the convolution, which evaluates the same functions per
//! texel in the frame chain; this stage's own entry point writes the
//! results to buffers (group 0) for comparison and inspection.

use bytemuck::{Pod, Zeroable};
use nalgebra::Matrix2;

use super::raster::{RasterTargets, FORMAT};
use super::{bind_group, buffers, compute_pipeline, dispatch, encoder, Context};
use crate::error::Result;
use crate::micro::{KernelField, KernelModel, PassParams};
use crate::strain::StrainRaster;

/// The shader source.
pub const SHADER: &str = include_str!("../../shaders/svd2.wgsl");

/// Stage parameters; mirrors WGSL `FieldInfo`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct FieldInfo {
    /// The map's texels along u.
    pub width: u32,
    /// The map's texels along v.
    pub height: u32,
    /// Dilation radius (raster texels).
    pub dilate: u32,
    /// Map texels per raster texel along each side.
    pub step: u32,
    /// First α point in the table.
    pub alpha_start: u32,
    /// α points.
    pub alpha_len: u32,
    /// First σ(r < 1) point.
    pub compression_start: u32,
    /// σ(r < 1) points.
    pub compression_len: u32,
    /// First σ(r ≥ 1) point.
    pub stretch_start: u32,
    /// σ(r ≥ 1) points.
    pub stretch_len: u32,
    /// The raster's texels along u.
    pub raster_width: u32,
    /// The raster's texels along v.
    pub raster_height: u32,
    /// For a window of a larger map: its first texel in the larger map's
    /// raster texels (else 0).
    pub raster_origin: [i32; 2],
    /// Raster texels of the larger map (else the raster's size).
    pub map_raster: [i32; 2],
    /// Whether the larger map wraps (1) or not (0).
    pub wrap: u32,
    _pad: [u32; 3],
}

/// The kernel model's tables, concatenated, and where each starts.
fn model_table(model: &KernelModel) -> (Vec<[f32; 2]>, [(u32, u32); 3]) {
    let mut table = Vec::new();
    let mut spans = [(0, 0); 3];
    for (span, t) in spans.iter_mut().zip([
        &model.alpha,
        &model.sigma_compression_um,
        &model.sigma_stretch_um,
    ]) {
        *span = (table.len() as u32, t.points.len() as u32);
        table.extend(t.points.iter().map(|&(r, v)| [r as f32, v as f32]));
    }
    (table, spans)
}

/// Per-texel outputs on the GPU.
pub struct FieldBuffers {
    /// Two `vec4` per texel: the s pass, then the t pass.
    pub passes: wgpu::Buffer,
    /// `(r_s, r_t)` per texel.
    pub stretch: wgpu::Buffer,
}

impl FieldBuffers {
    /// Buffers for `width × height` texels.
    pub fn new(ctx: &Context, width: usize, height: usize) -> FieldBuffers {
        let n = (width * height) as u64;
        FieldBuffers {
            passes: buffers::storage_zeroed(ctx, "kernel passes", 32 * n),
            stretch: buffers::storage_zeroed(ctx, "texel stretch", 8 * n),
        }
    }
}

/// The compiled stage with its model table resident.
pub struct Svd2Stage {
    pipeline: wgpu::ComputePipeline,
    table: wgpu::Buffer,
    spans: [(u32, u32); 3],
}

impl Svd2Stage {
    /// Compiles the stage for `model`.
    pub fn new(ctx: &Context, model: &KernelModel) -> Svd2Stage {
        let (table, spans) = model_table(model);
        Svd2Stage {
            pipeline: compute_pipeline(ctx, "svd2.wgsl", SHADER, "svd2_main"),
            table: buffers::storage(ctx, "kernel tables", &table),
            spans,
        }
    }

    /// The uniform for a raster of `width × height` dilated by `dilate`.
    pub fn info(&self, width: usize, height: usize, dilate: usize) -> FieldInfo {
        self.info_stepped(width, height, dilate, 1)
    }

    /// The uniform for a `width × height` map whose raster has one texel
    /// per `step × step` map texels, dilated by `dilate` raster texels
    /// (see [`crate::strain::raster::CoarseRaster`]).
    pub fn info_stepped(
        &self,
        width: usize,
        height: usize,
        dilate: usize,
        step: usize,
    ) -> FieldInfo {
        let [a, c, s] = self.spans;
        let step = step.max(1);
        let (rw, rh) = (width.div_ceil(step) as i32, height.div_ceil(step) as i32);
        FieldInfo {
            width: width as u32,
            height: height as u32,
            dilate: dilate as u32,
            step: step as u32,
            raster_width: width.div_ceil(step) as u32,
            raster_height: height.div_ceil(step) as u32,
            alpha_start: a.0,
            alpha_len: a.1,
            compression_start: c.0,
            compression_len: c.1,
            stretch_start: s.0,
            stretch_len: s.1,
            raster_origin: [0, 0],
            map_raster: [rw, rh],
            wrap: 0,
            _pad: [0; 3],
        }
    }

    /// The input group (1) for `layout` — this stage's, or that of a
    /// pipeline that includes the svd2 functions: `info` and `raster`.
    pub fn inputs(
        &self,
        ctx: &Context,
        layout: &wgpu::BindGroupLayout,
        info: &wgpu::Buffer,
        raster: &RasterTargets,
    ) -> wgpu::BindGroup {
        let [tv, fv] = &raster.views;
        bind_group(
            ctx,
            layout,
            &[
                info.as_entire_binding(),
                wgpu::BindingResource::TextureView(tv),
                wgpu::BindingResource::TextureView(fv),
                self.table.as_entire_binding(),
            ],
        )
    }

    /// Runs the stage's own entry point over `raster` into `out`.
    pub fn encode(
        &self,
        ctx: &Context,
        encoder: &mut wgpu::CommandEncoder,
        info: &wgpu::Buffer,
        raster: &RasterTargets,
        out: &FieldBuffers,
    ) {
        let inputs = self.inputs(ctx, &self.pipeline.get_bind_group_layout(1), info, raster);
        let outputs = ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("svd2 outputs"),
            layout: &self.pipeline.get_bind_group_layout(0),
            entries: &[
                wgpu::BindGroupEntry {
                    binding: 8,
                    resource: out.passes.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 9,
                    resource: out.stretch.as_entire_binding(),
                },
            ],
        });
        dispatch(
            encoder,
            "svd2",
            &self.pipeline,
            &[&outputs, &inputs],
            raster.width,
            raster.height,
        );
    }
}

/// Uploads a CPU raster into raster textures (to run this stage on given
/// inputs).
pub fn upload_raster(ctx: &Context, raster: &StrainRaster) -> RasterTargets {
    let targets = RasterTargets::new_with_usage(
        ctx,
        raster.width,
        raster.height,
        wgpu::TextureUsages::COPY_DST,
    );
    let row_major =
        |m: &Matrix2<f64>| [m[(0, 0)], m[(0, 1)], m[(1, 0)], m[(1, 1)]].map(|x| x as f32);
    let write = |texture: &wgpu::Texture, data: Vec<[f32; 4]>| {
        ctx.queue.write_texture(
            texture.as_image_copy(),
            bytemuck::cast_slice(&data),
            wgpu::TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some(raster.width as u32 * 16),
                rows_per_image: Some(raster.height as u32),
            },
            wgpu::Extent3d {
                width: raster.width as u32,
                height: raster.height as u32,
                depth_or_array_layers: 1,
            },
        );
    };
    debug_assert_eq!(FORMAT.block_copy_size(None), Some(16));
    // The raster holds T − I (see raster.wgsl).
    let identity = Matrix2::identity();
    write(
        &targets.t,
        raster
            .t
            .iter()
            .map(|t| row_major(&(t - identity)))
            .collect(),
    );
    // Outside texels carry a zero frame, as the GPU raster leaves them.
    let frames = raster
        .uv_frame
        .iter()
        .zip(&raster.inside)
        .map(|(m, &inside)| if inside { row_major(m) } else { [0.0; 4] })
        .collect();
    write(&targets.frame, frames);
    targets
}

/// Per-texel results read back.
pub struct TexelField {
    /// Kernel parameters of both passes.
    pub kernels: KernelField,
    /// `(r_s, r_t)` per texel.
    pub stretch: Vec<[f32; 2]>,
}

/// Runs the stage on `raster` (dilated by `dilate`) and reads the results.
pub fn kernel_field(
    ctx: &Context,
    raster: &StrainRaster,
    model: &KernelModel,
    dilate: usize,
) -> Result<TexelField> {
    let (w, h) = (raster.width, raster.height);
    ctx.check_map(w, h, 32)?;
    let stage = Svd2Stage::new(ctx, model);
    let targets = upload_raster(ctx, raster);
    let out = FieldBuffers::new(ctx, w, h);
    let info = buffers::uniform(ctx, "field info", &stage.info(w, h, dilate));
    let mut enc = encoder(ctx);
    stage.encode(ctx, &mut enc, &info, &targets, &out);
    ctx.queue.submit([enc.finish()]);
    let passes: Vec<[f32; 4]> = buffers::read(ctx, &out.passes, 2 * w * h)?;
    let stretch: Vec<[f32; 2]> = buffers::read(ctx, &out.stretch, w * h)?;
    Ok(TexelField {
        kernels: kernel_field_of(w, h, &passes),
        stretch,
    })
}

/// The [`KernelField`] of read-back pass parameters.
pub fn kernel_field_of(width: usize, height: usize, passes: &[[f32; 4]]) -> KernelField {
    let params = |p: &[f32; 4]| PassParams {
        axis: [p[0], p[1]],
        alpha: p[2],
        sigma: p[3],
    };
    KernelField {
        width,
        height,
        s: passes.iter().step_by(2).map(params).collect(),
        t: passes.iter().skip(1).step_by(2).map(params).collect(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn field_info_matches_wgsl_layout() {
        assert_eq!(std::mem::size_of::<FieldInfo>(), 80);
    }

    #[test]
    fn model_tables_are_concatenated_in_order() {
        let model = KernelModel::forehead();
        let (table, spans) = model_table(&model);
        assert_eq!(spans[0], (0, 4));
        assert_eq!(spans[1], (4, 2));
        assert_eq!(spans[2], (6, 2));
        assert_eq!(table.len(), 8);
        assert_eq!(table[6], [1.0, (38.2f64 - 26.5) as f32]);
    }
}
