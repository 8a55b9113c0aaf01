//! Batched counting of kernel-fitting candidates on the GPU
//! (`shaders/fit.wgsl`; CPU reference
//! [`crate::micro::fit::count_histograms`]).
//!
//! The slopes of the resampled neutral map stay resident; per σ the CPU
//! uploads their change per unit α ([`crate::micro::fit::Objective`]) and
//! the GPU counts the normal histograms of up to [`BATCH`] values of α in
//! one submission, read back once. Total-variation distances are taken on
//! the CPU in f64, and the search is [`crate::micro::fit::search`], shared
//! with the CPU.

use bytemuck::{Pod, Zeroable};

use super::{bind_group, buffers, encoder, Context};
use crate::error::{Error, Result};
use crate::micro::fit::{search, FitResult, Objective, Slopes};

/// The shader source.
pub const SHADER: &str = include_str!("../../shaders/fit.wgsl");

/// Candidates per submission.
pub const BATCH: usize = 64;
/// Texels per workgroup (`TILE` in the shader).
const TILE: usize = 4096;
/// Largest `bins × bins` the shader's workgroup histogram holds.
pub const MAX_CELLS: usize = 4096;

/// Mirrors WGSL `FitInfo`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct FitInfo {
    texels: u32,
    bins: u32,
    candidates: u32,
    _pad0: u32,
    range: f32,
    _pad1: [f32; 3],
}

/// The counter with one sample's base slopes resident.
pub struct GpuFit<'a> {
    ctx: &'a Context,
    pipeline: wgpu::ComputePipeline,
    base: wgpu::Buffer,
    texels: usize,
}

fn interleave(s: &Slopes) -> Vec<[f32; 2]> {
    s.x.iter().zip(&s.y).map(|(&x, &y)| [x, y]).collect()
}

impl<'a> GpuFit<'a> {
    /// Compiles the stage and uploads `base`; an error when the histogram
    /// or the slope field does not fit the shader or the device.
    pub fn new(ctx: &'a Context, base: &Slopes, bins: usize) -> Result<GpuFit<'a>> {
        if bins * bins > MAX_CELLS {
            return Err(Error::Gpu(format!(
                "the GPU fit counts at most {MAX_CELLS} histogram cells ({bins}² asked)"
            )));
        }
        let limit = ctx.device.limits().max_storage_buffer_binding_size as usize;
        if 8 * base.len() > limit {
            return Err(Error::Gpu(format!(
                "a fit over {} texels needs {} MB storage buffers; the adapter allows {} MB",
                base.len(),
                (8 * base.len()) >> 20,
                limit >> 20
            )));
        }
        Ok(GpuFit {
            ctx,
            pipeline: super::compute_pipeline(ctx, "fit.wgsl", SHADER, "main"),
            base: buffers::storage(ctx, "fit base slopes", &interleave(base)),
            texels: base.len(),
        })
    }

    /// Counts of `base + α·dir` for each α (as
    /// [`crate::micro::fit::count_histograms`]).
    pub fn count(
        &self,
        dir: &Slopes,
        alphas: &[f32],
        bins: usize,
        range: f64,
    ) -> Result<Vec<Vec<u32>>> {
        let ctx = self.ctx;
        let cells = bins * bins;
        let dir = buffers::storage(ctx, "fit slope change", &interleave(dir));
        let tiles = self.texels.div_ceil(TILE).max(1);
        let gx = tiles.min(65_535);
        let gy = tiles.div_ceil(gx);
        let mut out = Vec::with_capacity(alphas.len());
        for batch in alphas.chunks(BATCH) {
            let info = buffers::uniform(
                ctx,
                "fit info",
                &FitInfo {
                    texels: self.texels as u32,
                    bins: bins as u32,
                    candidates: batch.len() as u32,
                    range: range as f32,
                    ..FitInfo::default()
                },
            );
            let list = buffers::storage(ctx, "fit alphas", batch);
            let counts =
                buffers::storage_zeroed(ctx, "fit counts", 4 * (cells * batch.len()) as u64);
            let bind = bind_group(
                ctx,
                &self.pipeline.get_bind_group_layout(0),
                &[
                    info.as_entire_binding(),
                    self.base.as_entire_binding(),
                    dir.as_entire_binding(),
                    list.as_entire_binding(),
                    counts.as_entire_binding(),
                ],
            );
            let mut enc = encoder(ctx);
            {
                let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
                    label: Some("fit"),
                    timestamp_writes: None,
                });
                pass.set_pipeline(&self.pipeline);
                pass.set_bind_group(0, &bind, &[]);
                pass.dispatch_workgroups(gx as u32, gy as u32, 1);
            }
            ctx.queue.submit([enc.finish()]);
            let all: Vec<u32> = buffers::read(ctx, &counts, cells * batch.len())?;
            out.extend(all.chunks(cells).map(<[u32]>::to_vec));
        }
        Ok(out)
    }

    /// The search of [`crate::micro::fit::fit_params`] with GPU counting.
    pub fn fit_params(
        &self,
        objective: &Objective,
        progress: impl FnMut(f64),
    ) -> Result<FitResult> {
        let hist = objective.hist;
        search(
            objective,
            |_, dir, alphas| self.count(dir, alphas, hist.bins, hist.range),
            progress,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fit_info_matches_wgsl_layout() {
        assert_eq!(std::mem::size_of::<FitInfo>(), 32);
    }
}
