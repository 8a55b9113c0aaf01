//! Supersampling resolve (`shaders/resolve.wgsl`): box-filters the
//! `factor × size` HDR image to the output size as linear RGBA floats.

use bytemuck::{Pod, Zeroable};

use crate::gpu::{bind_group, buffers, compute_pipeline, dispatch, Context};

/// The shader source.
pub const SHADER: &str = include_str!("../../shaders/resolve.wgsl");

/// Uniforms; mirrors WGSL `ResolveInfo`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct ResolveInfo {
    /// Output width.
    pub width: u32,
    /// Output height.
    pub height: u32,
    /// Supersampling factor.
    pub factor: u32,
    /// Padding.
    pub pad: u32,
}

/// The compiled stage bound to its input and output.
pub struct ResolveStage {
    pipeline: wgpu::ComputePipeline,
    bind: wgpu::BindGroup,
    /// The linear RGBA pixels, row 0 at the top.
    pub pixels: wgpu::Buffer,
    width: usize,
    height: usize,
}

impl ResolveStage {
    /// Resolves `hdr` (`factor` times the output size) to `width × height`.
    pub fn new(
        ctx: &Context,
        hdr: &wgpu::TextureView,
        width: usize,
        height: usize,
        factor: usize,
    ) -> ResolveStage {
        let pipeline = compute_pipeline(ctx, "resolve.wgsl", SHADER, "main");
        let info = ResolveInfo {
            width: width as u32,
            height: height as u32,
            factor: factor as u32,
            pad: 0,
        };
        let info = buffers::uniform(ctx, "resolve info", &info);
        let pixels = buffers::storage_zeroed(ctx, "pixels", (width * height * 16) as u64);
        let bind = bind_group(
            ctx,
            &pipeline.get_bind_group_layout(0),
            &[
                info.as_entire_binding(),
                wgpu::BindingResource::TextureView(hdr),
                pixels.as_entire_binding(),
            ],
        );
        ResolveStage {
            pipeline,
            bind,
            pixels,
            width,
            height,
        }
    }

    /// Records the pass.
    pub fn encode(&self, encoder: &mut wgpu::CommandEncoder) {
        dispatch(
            encoder,
            "resolve",
            &self.pipeline,
            &[&self.bind],
            self.width,
            self.height,
        );
    }
}
