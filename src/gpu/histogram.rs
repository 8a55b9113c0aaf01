//! GPU normal histogram with atomics (`shaders/histogram.wgsl`; CPU
//! reference [`crate::micro::NormalHistogram::of`]).
//!
//! Counts are integers, so the order in which texels add to a cell does not
//! matter; they are normalised on the CPU. Several histograms can share one
//! counts buffer (`offset`), which the batched fit uses.

use bytemuck::{Pod, Zeroable};

use super::map::{with_map_access, GpuMap, MapInfo};
use super::{bind_group, buffers, compute_pipeline, dispatch, encoder, Context};
use crate::error::Result;
use crate::micro::{DisplacementMap, NormalHistogram};

/// The shader source (without the map access functions).
pub const SHADER: &str = include_str!("../../shaders/histogram.wgsl");

/// Histogram settings; mirrors WGSL `HistogramInfo`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct HistogramInfo {
    /// Cells per side.
    pub bins: u32,
    /// First count of this histogram in the counts buffer.
    pub offset: u32,
    _pad0: [u32; 2],
    /// Half range of the normal components.
    pub range: f32,
    _pad1: [f32; 3],
}

impl HistogramInfo {
    /// `bins × bins` cells over ±`range`, stored from `offset`.
    pub fn new(bins: usize, range: f64, offset: usize) -> HistogramInfo {
        HistogramInfo {
            bins: bins as u32,
            offset: offset as u32,
            range: range as f32,
            ..HistogramInfo::default()
        }
    }
}

/// The compiled stage.
pub struct HistogramStage {
    pipeline: wgpu::ComputePipeline,
}

impl HistogramStage {
    /// Compiles the stage.
    pub fn new(ctx: &Context) -> HistogramStage {
        HistogramStage {
            pipeline: compute_pipeline(ctx, "histogram.wgsl", &with_map_access(SHADER), "main"),
        }
    }

    /// A bind group adding the normals of `heights` (described by
    /// `map_info`) into `counts` as `info` says.
    pub fn bind(
        &self,
        ctx: &Context,
        map_info: wgpu::BindingResource<'_>,
        heights: &wgpu::Buffer,
        info: wgpu::BindingResource<'_>,
        counts: &wgpu::Buffer,
    ) -> wgpu::BindGroup {
        bind_group(
            ctx,
            &self.pipeline.get_bind_group_layout(0),
            &[
                map_info,
                heights.as_entire_binding(),
                info,
                counts.as_entire_binding(),
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
        dispatch(encoder, "histogram", &self.pipeline, &[bind], width, height);
    }
}

/// Normalises integer counts into a histogram.
pub fn normalise(counts: &[u32], bins: usize, range: f64) -> NormalHistogram {
    let total: f64 = counts.iter().map(|&c| c as f64).sum();
    let cells = counts
        .iter()
        .map(|&c| if total > 0.0 { c as f64 / total } else { 0.0 })
        .collect();
    NormalHistogram { bins, range, cells }
}

/// The histogram of `map` stretched by `stretch`, on the GPU.
pub fn histogram(
    ctx: &Context,
    map: &DisplacementMap,
    bins: usize,
    range: f64,
    stretch: [f64; 2],
) -> Result<NormalHistogram> {
    ctx.check_map(map.width, map.height, 4)?;
    let bins = bins.max(1);
    let stage = HistogramStage::new(ctx);
    let src = GpuMap::upload(ctx, map);
    let map_info = buffers::uniform(ctx, "map info", &MapInfo::of(map, stretch));
    let info = buffers::uniform(ctx, "histogram info", &HistogramInfo::new(bins, range, 0));
    let counts = buffers::storage_zeroed(ctx, "histogram counts", 4 * (bins * bins) as u64);
    let bind = stage.bind(
        ctx,
        map_info.as_entire_binding(),
        &src.heights,
        info.as_entire_binding(),
        &counts,
    );
    let mut enc = encoder(ctx);
    stage.encode(&mut enc, &bind, map.width, map.height);
    ctx.queue.submit([enc.finish()]);
    let counts: Vec<u32> = buffers::read(ctx, &counts, bins * bins)?;
    Ok(normalise(&counts, bins, range))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn histogram_info_matches_wgsl_layout() {
        assert_eq!(std::mem::size_of::<HistogramInfo>(), 32);
    }
}
