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

/// The stages of one microstructure frame, in order.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MicroStage {
    /// The surface's positions and strains written to the device.
    Upload,
    /// Strain raster over the map (`raster.wgsl`).
    Raster,
    /// The convolution along the first strain axis, each texel's 2 × 2 SVD
    /// of the raster included (`convolve.wgsl` with `svd2.wgsl`).
    PassS,
    /// The convolution along the second strain axis (SVD again).
    PassT,
    /// Normals of D′ (`normals.wgsl`).
    Normals,
    /// D′ (and its normals) read back to the host.
    ReadBack,
}

/// A profile of one frame ([`GpuMicro::time_stages`]), stages in
/// [`MicroStage::ALL`] order.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct StageTimes {
    /// Wall time of each stage submitted alone and waited for (ms).
    pub wall_ms: [f64; MicroStage::COUNT],
    /// GPU time of each shader stage from timestamp queries (ms); `None`
    /// for the transfers and where the adapter has no timestamp queries.
    pub gpu_ms: [Option<f64>; MicroStage::COUNT],
}

impl MicroStage {
    /// Whether the stage runs shaders (the others are transfers).
    pub fn runs_shaders(self) -> bool {
        !matches!(self, MicroStage::Upload | MicroStage::ReadBack)
    }

    /// Number of stages.
    pub const COUNT: usize = 6;
    /// Every stage, in order.
    pub const ALL: [MicroStage; MicroStage::COUNT] = [
        MicroStage::Upload,
        MicroStage::Raster,
        MicroStage::PassS,
        MicroStage::PassT,
        MicroStage::Normals,
        MicroStage::ReadBack,
    ];

    /// Short name for tables.
    pub fn name(self) -> &'static str {
        match self {
            MicroStage::Upload => "upload",
            MicroStage::Raster => "raster",
            MicroStage::PassS => "pass s",
            MicroStage::PassT => "pass t",
            MicroStage::Normals => "normals",
            MicroStage::ReadBack => "read-back",
        }
    }
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
        self.upload(field);
        let mut enc = encoder(&self.ctx);
        for stage in [MicroStage::Raster, MicroStage::PassS, MicroStage::PassT] {
            self.encode_stage(&mut enc, stage);
        }
        if normals {
            self.encode_stage(&mut enc, MicroStage::Normals);
        }
        self.ctx.queue.submit([enc.finish()]);
    }

    /// One frame stage by stage, each submitted alone and waited for; the
    /// wall time of each in ms, in [`MicroStage::ALL`] order (the read-back
    /// fetches D′, and its normals where one buffer holds them). A profile:
    /// the sum is a little above a frame's time.
    pub fn time_stages(&mut self, field: &SurfaceField) -> Result<StageTimes> {
        self.ctx.finish()?;
        let timer = super::timing::GpuTimer::new(&self.ctx, MicroStage::COUNT);
        let mut times = StageTimes::default();
        for (k, stage) in MicroStage::ALL.into_iter().enumerate() {
            let start = std::time::Instant::now();
            match stage {
                MicroStage::Upload => self.upload(field),
                MicroStage::ReadBack => {
                    self.out.download(&self.ctx)?;
                    let bytes = (self.width * self.height * 16) as u64;
                    if bytes <= self.ctx.limits.max_buffer_size {
                        read_normals(&self.ctx, &self.normals, self.width, self.height)?;
                    }
                }
                _ => {
                    let mut enc = encoder(&self.ctx);
                    if let Some(t) = &timer {
                        t.begin(&mut enc, k);
                    }
                    self.encode_stage(&mut enc, stage);
                    if let Some(t) = &timer {
                        t.end(&mut enc, k);
                    }
                    self.ctx.queue.submit([enc.finish()]);
                }
            }
            self.ctx.finish()?;
            times.wall_ms[k] = start.elapsed().as_secs_f64() * 1e3;
        }
        if let Some(t) = &timer {
            let gpu = t.read(&self.ctx)?;
            for (k, stage) in MicroStage::ALL.into_iter().enumerate() {
                if stage.runs_shaders() {
                    times.gpu_ms[k] = Some(gpu[k]);
                }
            }
        }
        Ok(times)
    }

    fn upload(&mut self, field: &SurfaceField) {
        match &self.surface {
            Some(s) if s.fits(field) => s.update(&self.ctx, field),
            _ => self.surface = Some(SurfaceBuffers::new(&self.ctx, field)),
        }
    }

    fn encode_stage(&self, enc: &mut wgpu::CommandEncoder, stage: MicroStage) {
        let (w, h) = (self.width, self.height);
        match stage {
            MicroStage::Raster => {
                let surface = self.surface.as_ref().expect("upload runs first");
                self.raster.encode(enc, surface, &self.targets);
            }
            MicroStage::PassS | MicroStage::PassT => {
                let bind = &self.pass_binds[(stage == MicroStage::PassT) as usize];
                let binds = [bind, &self.strain_inputs];
                self.convolve.encode(enc, Params::Strain, &binds, w, h);
            }
            MicroStage::Normals => self.normals_stage.encode(enc, &self.normals_bind, w, h),
            MicroStage::Upload | MicroStage::ReadBack => {}
        }
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
