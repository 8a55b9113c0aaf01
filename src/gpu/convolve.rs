//! GPU pass of the spatially varying convolution (`shaders/convolve.wgsl`;
//! CPU reference [`crate::micro::convolve`]).
//!
//! One dispatch is one 1D pass: the s pass reads the neutral map into an
//! intermediate, the t pass reads that into the output (eq. 4–5). Per-texel
//! parameters come from the [`super::svd2`] stage's buffer; a constant mode
//! (one parameter set in the uniform) serves the fitting search.

use bytemuck::{Pod, Zeroable};

use super::map::{with_map_access, GpuMap};
use super::{bind_group, buffers, compute_pipeline, dispatch, encoder, Context};
use crate::error::Result;
use crate::micro::{DisplacementMap, KernelField, PassParams};

/// The shader source (without the map access functions).
pub const SHADER: &str = include_str!("../../shaders/convolve.wgsl");

/// Which parameters a pass uses; mirrors WGSL `PassInfo`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct PassInfo {
    /// 0: along s; 1: along t.
    pub pass_index: u32,
    /// 1: `params` at every texel.
    pub constant: u32,
    _pad: [u32; 2],
    /// `(axis x, axis y, α, σ texels)` in constant mode.
    pub params: [f32; 4],
}

impl PassInfo {
    /// The s (0) or t (1) pass with per-texel parameters.
    pub fn per_texel(pass_index: u32) -> PassInfo {
        PassInfo {
            pass_index,
            ..PassInfo::default()
        }
    }

    /// The same parameters everywhere.
    pub fn constant(p: &PassParams) -> PassInfo {
        PassInfo {
            constant: 1,
            params: pass_vec(p),
            ..PassInfo::default()
        }
    }
}

/// A pass's parameters as the shader stores them.
pub fn pass_vec(p: &PassParams) -> [f32; 4] {
    [p.axis[0], p.axis[1], p.alpha, p.sigma]
}

/// The compiled stage.
pub struct ConvolveStage {
    pipeline: wgpu::ComputePipeline,
    no_passes: wgpu::Buffer,
}

impl ConvolveStage {
    /// Compiles the stage.
    pub fn new(ctx: &Context) -> ConvolveStage {
        ConvolveStage {
            pipeline: compute_pipeline(ctx, "convolve.wgsl", &with_map_access(SHADER), "main"),
            no_passes: buffers::storage(ctx, "no per-texel passes", &[[0.0f32; 4]; 2]),
        }
    }

    /// A bind group convolving `src` into `dst` (same size) with the pass
    /// selected by `info` and, unless constant, parameters from `passes`.
    pub fn bind(
        &self,
        ctx: &Context,
        src: &GpuMap,
        info: wgpu::BindingResource<'_>,
        passes: Option<&wgpu::Buffer>,
        dst: &GpuMap,
    ) -> wgpu::BindGroup {
        bind_group(
            ctx,
            &self.pipeline.get_bind_group_layout(0),
            &[
                src.info.as_entire_binding(),
                src.heights.as_entire_binding(),
                info,
                passes.unwrap_or(&self.no_passes).as_entire_binding(),
                dst.heights.as_entire_binding(),
            ],
        )
    }

    /// Records one pass over the map's texels.
    pub fn encode(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        bind: &wgpu::BindGroup,
        width: usize,
        height: usize,
    ) {
        dispatch(encoder, "convolve", &self.pipeline, bind, width, height);
    }
}

/// Both passes of `field` over `map` on the GPU, read back.
pub fn convolve(ctx: &Context, map: &DisplacementMap, field: &KernelField) -> Result<DisplacementMap> {
    assert_eq!((field.width, field.height), (map.width, map.height));
    ctx.check_map(map.width, map.height, 32)?;
    let stage = ConvolveStage::new(ctx);
    let src = GpuMap::upload(ctx, map);
    let mid = GpuMap::scratch(ctx, map);
    let dst = GpuMap::scratch(ctx, map);
    let interleaved: Vec<[f32; 4]> = field
        .s
        .iter()
        .zip(&field.t)
        .flat_map(|(s, t)| [pass_vec(s), pass_vec(t)])
        .collect();
    let passes = buffers::storage(ctx, "kernel passes", &interleaved);
    let infos = [0, 1].map(|k| buffers::uniform(ctx, "pass info", &PassInfo::per_texel(k)));
    let first = stage.bind(ctx, &src, infos[0].as_entire_binding(), Some(&passes), &mid);
    let second = stage.bind(ctx, &mid, infos[1].as_entire_binding(), Some(&passes), &dst);
    let mut enc = encoder(ctx);
    stage.encode(&mut enc, &first, map.width, map.height);
    stage.encode(&mut enc, &second, map.width, map.height);
    ctx.queue.submit([enc.finish()]);
    dst.download(ctx)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pass_info_matches_wgsl_layout() {
        assert_eq!(std::mem::size_of::<PassInfo>(), 32);
    }
}
