//! The per-frame microstructure chain on the GPU: raster → pass along s →
//! pass along t → normals, each pass computing its texel's SVD and kernel
//! parameters from the raster (the svd2 functions) (CPU reference
//! [`crate::micro::convolve::deform`] and
//! [`crate::micro::normals::normal_map`]).
//!
//! The neutral map, kernel tables, triangle indices, intermediate maps and
//! bind groups are created once and stay resident; a frame uploads only the
//! surface's per-vertex matrices (40 bytes a vertex) and records the four
//! stages into one command buffer.

use super::convolve::{ConvolveStage, Params, PassInfo};
use super::map::GpuMap;
use super::normals::{normal_texture, read_normals, NormalsStage};
use super::raster::{RasterStage, RasterTargets, SurfaceBuffers};
use super::svd2::Svd2Stage;
use super::{buffers, encoder, Context};
use crate::error::Result;
use crate::micro::{DisplacementMap, KernelModel};
use crate::strain::SurfaceField;

/// Bytes per texel of the largest storage buffer a frame binds (a map of
/// f32 heights; the raster and normals are textures, and the kernel
/// parameters are computed where they are used).
pub const LARGEST_BYTES_PER_TEXEL: u64 = 4;

/// A frame's outputs read back.
pub struct DeformedFrame {
    /// The deformed map D′.
    pub map: DisplacementMap,
    /// Its normals when asked for.
    pub normals: Option<Vec<[f32; 3]>>,
}

/// The resident per-frame chain.
pub struct GpuMicro {
    ctx: Context,
    width: usize,
    height: usize,
    out: GpuMap,
    normals: wgpu::Texture,
    raster: RasterStage,
    targets: RasterTargets,
    surface: Option<SurfaceBuffers>,
    strain_inputs: wgpu::BindGroup,
    convolve: ConvolveStage,
    pass_binds: [wgpu::BindGroup; 2],
    normals_stage: NormalsStage,
    normals_bind: wgpu::BindGroup,
}

impl GpuMicro {
    /// Uploads `neutral` and `model` and builds the chain, dilating the
    /// raster by `dilate` texels.
    pub fn new(
        ctx: Context,
        neutral: &DisplacementMap,
        model: &KernelModel,
        dilate: usize,
    ) -> Result<GpuMicro> {
        let (w, h) = (neutral.width, neutral.height);
        ctx.check_map(w, h, LARGEST_BYTES_PER_TEXEL)?;
        let source = GpuMap::upload(&ctx, neutral);
        let mid = GpuMap::scratch(&ctx, neutral);
        let out = GpuMap::scratch(&ctx, neutral);
        let normals = normal_texture(&ctx, w, h);
        let targets = RasterTargets::new(&ctx, w, h);
        let svd2 = Svd2Stage::new(&ctx, model);
        let info = buffers::uniform(&ctx, "field info", &svd2.info(w, h, dilate));
        let convolve = ConvolveStage::new(&ctx);
        let strain_inputs = convolve.strain_inputs(&ctx, &svd2, &info, &targets);
        let pass_info = [0, 1].map(|k| buffers::uniform(&ctx, "pass info", &PassInfo::pass(k)));
        let bind = |src, info: &wgpu::Buffer, dst| {
            convolve.bind(
                &ctx,
                Params::Strain,
                src,
                info.as_entire_binding(),
                None,
                dst,
            )
        };
        let pass_binds = [
            bind(&source, &pass_info[0], &mid),
            bind(&mid, &pass_info[1], &out),
        ];
        let normals_stage = NormalsStage::new(&ctx);
        let normals_bind = normals_stage.bind(&ctx, &out, &normals);
        ctx.finish()?;
        Ok(GpuMicro {
            raster: RasterStage::new(&ctx),
            ctx,
            width: w,
            height: h,
            out,
            normals,
            targets,
            surface: None,
            strain_inputs,
            convolve,
            pass_binds,
            normals_stage,
            normals_bind,
        })
    }

    /// The device in use.
    pub fn context(&self) -> &Context {
        &self.ctx
    }

    /// The texture D′'s normals are written to (the renderer samples it).
    pub fn normals_texture(&self) -> &wgpu::Texture {
        &self.normals
    }

    /// Gives the device back (the chain's buffers are freed).
    pub fn into_context(self) -> Context {
        self.ctx
    }

    /// Uploads `field` and submits the whole chain (normals too when
    /// `normals`), without waiting.
    pub fn submit(&mut self, field: &SurfaceField, normals: bool) {
        match &self.surface {
            Some(s) if s.fits(field) => s.update(&self.ctx, field),
            _ => self.surface = Some(SurfaceBuffers::new(&self.ctx, field)),
        }
        let surface = self
            .surface
            .as_ref()
            .expect("surface buffers were just made");
        let (w, h) = (self.width, self.height);
        let mut enc = encoder(&self.ctx);
        self.raster.encode(&mut enc, surface, &self.targets);
        for bind in &self.pass_binds {
            let binds = [bind, &self.strain_inputs];
            self.convolve.encode(&mut enc, Params::Strain, &binds, w, h);
        }
        if normals {
            self.normals_stage
                .encode(&mut enc, &self.normals_bind, w, h);
        }
        self.ctx.queue.submit([enc.finish()]);
    }

    /// Runs one frame and waits for it (for timing: nothing is read back).
    pub fn run(&mut self, field: &SurfaceField) -> Result<()> {
        self.submit(field, true);
        self.ctx.finish()
    }

    /// Runs one frame and reads back D′ (and its normals when `normals`).
    pub fn deform(&mut self, field: &SurfaceField, normals: bool) -> Result<DeformedFrame> {
        self.submit(field, normals);
        let map = self.out.download(&self.ctx)?;
        let normals = if normals {
            Some(read_normals(
                &self.ctx,
                &self.normals,
                self.width,
                self.height,
            )?)
        } else {
            None
        };
        Ok(DeformedFrame { map, normals })
    }
}
