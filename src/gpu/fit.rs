//! Batched evaluation of fitting candidates on the GPU (CPU reference
//! [`crate::micro::fit::fit_params`]).
//!
//! Each candidate (α, σ) is one constant-kernel [`super::convolve`] pass of
//! the resident neutral map along the sample's axis into a scratch map and
//! one [`super::histogram`] of it seen stretched by r, into its own slot of
//! a shared counts buffer. A batch of candidates is recorded into one
//! command buffer (the scratch map is reused: passes run in order) and read
//! back once; total-variation distances are taken on the CPU in f64. The
//! search itself is [`crate::micro::fit::search`], shared with the CPU.

use std::num::NonZeroU64;

use super::convolve::{ConvolveStage, Params, PassInfo};
use super::histogram::{normalise, HistogramInfo, HistogramStage};
use super::map::{GpuMap, MapInfo};
use super::{buffers, encoder, Context};
use crate::error::Result;
use crate::micro::fit::{search, Axis, FitResult, HistogramSettings};
use crate::micro::{DisplacementMap, KernelParams, NormalHistogram, PassParams};

/// Candidates per submission.
pub const BATCH: usize = 64;
/// Byte stride of per-candidate uniforms (the largest offset alignment
/// WebGPU allows adapters to require).
const STRIDE: u64 = 256;

/// The fitting evaluator with the neutral map resident.
pub struct GpuFit<'a> {
    ctx: &'a Context,
    neutral: GpuMap,
    scratch: GpuMap,
    convolve: ConvolveStage,
    histogram: HistogramStage,
}

impl<'a> GpuFit<'a> {
    /// Uploads `neutral` and compiles the stages.
    pub fn new(ctx: &'a Context, neutral: &DisplacementMap) -> Result<GpuFit<'a>> {
        ctx.check_map(neutral.width, neutral.height, 4)?;
        Ok(GpuFit {
            ctx,
            neutral: GpuMap::upload(ctx, neutral),
            scratch: GpuMap::scratch(ctx, neutral),
            convolve: ConvolveStage::new(ctx),
            histogram: HistogramStage::new(ctx),
        })
    }

    /// Histograms of the neutral map convolved along `axis` with each
    /// candidate and seen stretched by `r` (as
    /// [`crate::micro::fit::candidate_histogram`]).
    pub fn histograms(
        &self,
        axis: Axis,
        r: f64,
        candidates: &[KernelParams],
        hist: HistogramSettings,
    ) -> Result<Vec<NormalHistogram>> {
        let ctx = self.ctx;
        let meta = &self.neutral.meta;
        let (w, h) = (meta.width, meta.height);
        let bins = hist.bins.max(1);
        let cells = bins * bins;
        let stretched = buffers::uniform(
            ctx,
            "stretched map info",
            &MapInfo::of(meta, axis.stretch(r)),
        );
        let mut out = Vec::with_capacity(candidates.len());
        for batch in candidates.chunks(BATCH) {
            let mut uniforms = vec![0u8; 2 * STRIDE as usize * batch.len()];
            for (c, p) in batch.iter().enumerate() {
                let pass = PassInfo::constant(&PassParams {
                    axis: axis.unit(),
                    alpha: p.alpha as f32,
                    sigma: (p.sigma_um / meta.texel_um) as f32,
                });
                let info = HistogramInfo::new(bins, hist.range, c * cells);
                let at = 2 * STRIDE as usize * c;
                uniforms[at..at + 32].copy_from_slice(bytemuck::bytes_of(&pass));
                let at = at + STRIDE as usize;
                uniforms[at..at + 32].copy_from_slice(bytemuck::bytes_of(&info));
            }
            let uniforms = buffers::init(
                ctx,
                "fit candidates",
                &uniforms,
                wgpu::BufferUsages::UNIFORM,
            );
            let counts =
                buffers::storage_zeroed(ctx, "fit counts", 4 * (cells * batch.len()) as u64);
            let slot = |k: u64| {
                wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                    buffer: &uniforms,
                    offset: k * STRIDE,
                    size: NonZeroU64::new(32),
                })
            };
            let mut enc = encoder(ctx);
            for c in 0..batch.len() as u64 {
                let conv = self.convolve.bind(
                    ctx,
                    Params::Constant,
                    &self.neutral,
                    slot(2 * c),
                    None,
                    &self.scratch,
                );
                self.convolve
                    .encode(&mut enc, Params::Constant, &[&conv], w, h);
                let hist_bind = self.histogram.bind(
                    ctx,
                    stretched.as_entire_binding(),
                    &self.scratch.heights,
                    slot(2 * c + 1),
                    &counts,
                );
                self.histogram.encode(&mut enc, &hist_bind, w, h);
            }
            ctx.queue.submit([enc.finish()]);
            let all: Vec<u32> = buffers::read(ctx, &counts, cells * batch.len())?;
            out.extend(all.chunks(cells).map(|c| normalise(c, bins, hist.range)));
        }
        Ok(out)
    }

    /// The fit of [`crate::micro::fit::fit_params`] with batched GPU
    /// evaluation.
    pub fn fit_params(
        &self,
        target: &NormalHistogram,
        axis: Axis,
        r: f64,
        hist: HistogramSettings,
    ) -> Result<FitResult> {
        search(|batch| {
            Ok(self
                .histograms(axis, r, batch, hist)?
                .iter()
                .map(|h| h.distance(target))
                .collect())
        })
    }
}
