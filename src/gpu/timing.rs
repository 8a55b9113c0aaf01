//! GPU time of recorded work from timestamp queries: a pair of timestamps
//! around each span of commands in an encoder, resolved and read back
//! after the submission finished. Available where the adapter has
//! `TIMESTAMP_QUERY` and `TIMESTAMP_QUERY_INSIDE_ENCODERS` (see
//! [`super::OPTIONAL_FEATURES`]); profiles fall back to wall time without.

use super::{buffers, Context};
use crate::error::Result;

/// Timestamp pairs around spans of recorded commands.
pub struct GpuTimer {
    set: wgpu::QuerySet,
    resolved: wgpu::Buffer,
    staging: wgpu::Buffer,
    spans: u32,
    period_ns: f64,
}

impl GpuTimer {
    /// A timer for `spans` spans, or `None` when the adapter cannot write
    /// timestamps inside encoders.
    pub fn new(ctx: &Context, spans: usize) -> Option<GpuTimer> {
        let needed =
            wgpu::Features::TIMESTAMP_QUERY | wgpu::Features::TIMESTAMP_QUERY_INSIDE_ENCODERS;
        if !ctx.features.contains(needed) || spans == 0 {
            return None;
        }
        let count = 2 * spans as u32;
        let set = ctx.device.create_query_set(&wgpu::QuerySetDescriptor {
            label: Some("stage timestamps"),
            ty: wgpu::QueryType::Timestamp,
            count,
        });
        let bytes = 8 * count as u64;
        let resolved = ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("resolved timestamps"),
            size: bytes,
            usage: wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        Some(GpuTimer {
            set,
            resolved,
            staging: buffers::staging(ctx, bytes),
            spans: spans as u32,
            period_ns: ctx.queue.get_timestamp_period() as f64,
        })
    }

    /// Marks the start of span `k`.
    pub fn begin(&self, enc: &mut wgpu::CommandEncoder, k: usize) {
        enc.write_timestamp(&self.set, 2 * k as u32);
    }

    /// Marks the end of span `k`.
    pub fn end(&self, enc: &mut wgpu::CommandEncoder, k: usize) {
        enc.write_timestamp(&self.set, 2 * k as u32 + 1);
    }

    /// Reads the spans' GPU times (ms) after every span was written and
    /// submitted; spans never written read as 0 or garbage, so callers
    /// time every span they ask for.
    pub fn read(&self, ctx: &Context) -> Result<Vec<f64>> {
        let count = 2 * self.spans;
        let mut enc = super::encoder(ctx);
        enc.resolve_query_set(&self.set, 0..count, &self.resolved, 0);
        enc.copy_buffer_to_buffer(&self.resolved, 0, &self.staging, 0, 8 * count as u64);
        ctx.queue.submit([enc.finish()]);
        let ticks: Vec<u64> = buffers::map_read(ctx, &self.staging, count as usize)?;
        Ok(ticks
            .chunks(2)
            .map(|t| t[1].saturating_sub(t[0]) as f64 * self.period_ns * 1e-6)
            .collect())
    }
}
