//! GPU pass of the spatially varying convolution (`shaders/convolve.wgsl`;
//! CPU reference [`mod@crate::micro::convolve`]).
//!
//! One dispatch is one 1D pass: the s pass reads the neutral map into an
//! intermediate, the t pass reads that into the output (eq. 4–5). Where a
//! texel's parameters come from is the entry point ([`Params`]): computed
//! from the strain raster by the [`super::svd2`] functions (the frame
//! chain), read from a per-texel buffer, or one constant set (the fitting
//! search).

use bytemuck::{Pod, Zeroable};

use super::map::{with_map_access, GpuMap};
use super::svd2::{self, Svd2Stage};
use super::{buffers, compute_pipeline, dispatch, dispatch_tiles, encoder, Context};
use crate::error::Result;
use crate::micro::{DisplacementMap, KernelField, PassParams};

/// The shader source (without the map access and svd2 functions).
pub const SHADER: &str = include_str!("../../shaders/convolve.wgsl");

/// The whole module: map access, svd2 functions, convolution.
pub fn source() -> String {
    with_map_access(&format!("{}\n{SHADER}", svd2::SHADER))
}

/// The pass and constant parameters; mirrors WGSL `PassInfo`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct PassInfo {
    /// 0: along s; 1: along t.
    pub pass_index: u32,
    _pad: [u32; 3],
    /// `(axis x, axis y, α, σ texels)` for [`Params::Constant`].
    pub params: [f32; 4],
}

impl PassInfo {
    /// The s (0) or t (1) pass.
    pub fn pass(pass_index: u32) -> PassInfo {
        PassInfo {
            pass_index,
            ..PassInfo::default()
        }
    }

    /// The same parameters everywhere.
    pub fn constant(p: &PassParams) -> PassInfo {
        PassInfo {
            params: pass_vec(p),
            ..PassInfo::default()
        }
    }
}

/// Where a pass takes its per-texel parameters from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Params {
    /// The svd2 functions on the raster (bind group 1).
    Strain,
    /// A buffer of two `vec4` per texel.
    Field,
    /// The uniform's `params`.
    Constant,
}

/// A pass's parameters as the shader stores them.
pub fn pass_vec(p: &PassParams) -> [f32; 4] {
    [p.axis[0], p.axis[1], p.alpha, p.sigma]
}

/// The compiled stage (one pipeline per parameter source).
pub struct ConvolveStage {
    strain: wgpu::ComputePipeline,
    field: wgpu::ComputePipeline,
    constant: wgpu::ComputePipeline,
}

impl ConvolveStage {
    /// Compiles the stage.
    pub fn new(ctx: &Context) -> ConvolveStage {
        let source = source();
        let make = |entry| compute_pipeline(ctx, "convolve.wgsl", &source, entry);
        ConvolveStage {
            strain: make("convolve_strain"),
            field: make("convolve_field"),
            constant: make("convolve_constant"),
        }
    }

    fn pipeline(&self, params: Params) -> &wgpu::ComputePipeline {
        match params {
            Params::Strain => &self.strain,
            Params::Field => &self.field,
            Params::Constant => &self.constant,
        }
    }

    /// Group 0: convolving `src` into `dst` (same size) with the pass and
    /// constants of `info`; `extra` is the per-texel parameter buffer for
    /// [`Params::Field`] and the tile list (`tiles.rs`) for
    /// [`Params::Strain`].
    pub fn bind(
        &self,
        ctx: &Context,
        params: Params,
        src: &GpuMap,
        info: wgpu::BindingResource<'_>,
        extra: Option<&wgpu::Buffer>,
        dst: &GpuMap,
    ) -> wgpu::BindGroup {
        let layout = self.pipeline(params).get_bind_group_layout(0);
        let mut entries = vec![
            (0, src.info.as_entire_binding()),
            (1, src.heights.as_entire_binding()),
            (2, info),
            (4, dst.heights.as_entire_binding()),
        ];
        match params {
            Params::Field => {
                let passes = extra.expect("a per-texel pass needs its parameter buffer");
                entries.push((3, passes.as_entire_binding()));
            }
            Params::Strain => {
                let tiles = extra.expect("a strain pass needs its tile list");
                entries.push((5, tiles.as_entire_binding()));
            }
            Params::Constant => {}
        }
        let entries: Vec<wgpu::BindGroupEntry<'_>> = entries
            .into_iter()
            .map(|(binding, resource)| wgpu::BindGroupEntry { binding, resource })
            .collect();
        ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("convolve"),
            layout: &layout,
            entries: &entries,
        })
    }

    /// Group 1 of [`Params::Strain`]: the raster and kernel tables.
    pub fn strain_inputs(
        &self,
        ctx: &Context,
        svd2: &Svd2Stage,
        info: &wgpu::Buffer,
        raster: &super::raster::RasterTargets,
    ) -> wgpu::BindGroup {
        svd2.inputs(ctx, &self.strain.get_bind_group_layout(1), info, raster)
    }

    /// Records a [`Params::Strain`] pass over the first `tiles` tiles of
    /// the list bound in group 0 (group 1: [`ConvolveStage::strain_inputs`]).
    pub fn encode_tiles(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        binds: &[&wgpu::BindGroup],
        tiles: usize,
    ) {
        dispatch_tiles(encoder, "convolve", &self.strain, binds, tiles);
    }

    /// Records one [`Params::Field`] or [`Params::Constant`] pass over
    /// `width × height` texels with `binds` (group 0).
    pub fn encode(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        params: Params,
        binds: &[&wgpu::BindGroup],
        width: usize,
        height: usize,
    ) {
        debug_assert!(params != Params::Strain, "strain passes run over tiles");
        dispatch(
            encoder,
            "convolve",
            self.pipeline(params),
            binds,
            width,
            height,
        );
    }
}

/// Both passes of `field` over `map` on the GPU, read back.
pub fn convolve(
    ctx: &Context,
    map: &DisplacementMap,
    field: &KernelField,
) -> Result<DisplacementMap> {
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
    let infos = [0, 1].map(|k| buffers::uniform(ctx, "pass info", &PassInfo::pass(k)));
    let bind = |s, info: &wgpu::Buffer, d| {
        stage.bind(
            ctx,
            Params::Field,
            s,
            info.as_entire_binding(),
            Some(&passes),
            d,
        )
    };
    let (first, second) = (bind(&src, &infos[0], &mid), bind(&mid, &infos[1], &dst));
    let mut enc = encoder(ctx);
    stage.encode(&mut enc, Params::Field, &[&first], map.width, map.height);
    stage.encode(&mut enc, Params::Field, &[&second], map.width, map.height);
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
