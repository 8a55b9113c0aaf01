//! The per-frame microstructure chain on the GPU: raster → pass along s →
//! pass along t → normals, each pass computing its texel's SVD and kernel
//! parameters from the raster (the svd2 functions) (CPU reference
//! [`crate::micro::convolve::deform`] and
//! [`crate::micro::normals::normal_map`]).
//!
//! The neutral map, kernel tables, triangle indices, intermediate maps and
//! bind groups are created once and stay resident; a frame uploads only the
//! surface's per-vertex matrices (40 bytes a vertex) and its tile lists, and
//! records the four stages into one command buffer. The passes and normals
//! run only on the tiles the surface can change ([`super::active_tiles`]): the
//! rest of the map keeps the neutral map's values, exactly what a pass over
//! every texel would write there.

use super::active_tiles::{TileMask, TilePlanner};
use super::convolve::{ConvolveStage, Params, PassInfo};
use super::map::GpuMap;
use super::normals::{normal_texture, read_normals, NormalsStage};
use super::raster::{vertices, RasterStage, RasterTargets, RasterVertex, SurfaceBuffers};
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
    /// Bytes each stage must move at least ([`GpuMicro::frame_bytes`]).
    pub bytes: [u64; MicroStage::COUNT],
}

impl StageTimes {
    /// A stage's time: GPU time where the adapter has timestamp queries,
    /// wall time otherwise (ms).
    pub fn ms(&self, k: usize) -> f64 {
        self.gpu_ms[k].unwrap_or(self.wall_ms[k])
    }

    /// Bytes a stage moved per second over [`StageTimes::ms`] (GB/s).
    pub fn gb_per_s(&self, k: usize) -> f64 {
        self.bytes[k] as f64 / (self.ms(k) * 1e6)
    }

    /// Bytes the shader stages of a resident frame (raster, both passes,
    /// normals; no transfers) must move at least.
    pub fn resident_bytes(&self) -> u64 {
        MicroStage::ALL
            .iter()
            .zip(&self.bytes)
            .filter(|(s, _)| s.runs_shaders())
            .map(|(_, b)| b)
            .sum()
    }
}

/// Bytes per texel the raster writes: `T − I` and `Q Rᵀ`, two `rgba32float`
/// texels.
pub const RASTER_BYTES_PER_TEXEL: u64 = 32;
/// Bytes per texel a convolution pass moves at least: the two raster
/// texels it takes its SVD from, the centre height read and the height
/// written. The other taps are neighbours' heights, which a cache serves.
pub const PASS_BYTES_PER_TEXEL: u64 = 32 + 4 + 4;
/// Bytes per texel of the normals: the height read (its neighbours come from
/// a cache) and an `rgba32float` normal written.
pub const NORMALS_BYTES_PER_TEXEL: u64 = 4 + 16;

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

/// How many tiles ([`super::active_tiles::TILE`]² texels) each stage of the last
/// frame ran on.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct FrameTiles {
    /// Tiles of the pass along s.
    pub pass_s: usize,
    /// Tiles of the pass along t.
    pub pass_t: usize,
    /// Tiles whose normals were computed (0 in a frame without normals).
    pub normals: usize,
    /// Tiles in the map.
    pub total: usize,
    /// Texels in the tiles of the pass along s, the pass along t and the
    /// normals.
    pub texels: [usize; 3],
    /// Bytes uploaded: the raster vertices and the tile lists.
    pub upload_bytes: u64,
}

/// Texels a raster of `width × height` covers: the UV area of the
/// triangles (UVs in the map's unit square) in texels, at most the map's
/// texel count (copies beyond the edges and overlaps are counted, so this
/// is an estimate, exact for one chart inside the map).
fn covered_texels(triangles: &[[usize; 3]], uvs: &[[f32; 2]], width: usize, height: usize) -> u64 {
    let area: f64 = triangles
        .iter()
        .map(|t| {
            let [a, b, c] = t.map(|k| uvs[k].map(f64::from));
            0.5 * ((b[0] - a[0]) * (c[1] - a[1]) - (c[0] - a[0]) * (b[1] - a[1])).abs()
        })
        .sum();
    let texels = (width * height) as f64;
    (area * texels).min(texels).round() as u64
}

/// Triangles and raster UVs of a surface as the raster draws them.
type RasterLayout = (Vec<[usize; 3]>, Vec<[f32; 2]>);

/// Where a chain's map lies in a larger map: it holds texels `origin ..
/// origin + its size` of a `map_size` map (a tile and its halo, see
/// [`super::tiled`]); texels beyond the larger map's edges follow its edge
/// rule, so with `wrap` the surface is drawn again across each edge.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct UvWindow {
    /// Texel of the larger map at the chain's texel (0, 0) (may be negative).
    pub origin: [isize; 2],
    /// Size of the larger map (texels).
    pub map_size: [usize; 2],
    /// Whether the larger map wraps around.
    pub wrap: bool,
}

/// The resident per-frame chain.
pub struct GpuMicro {
    ctx: Context,
    width: usize,
    height: usize,
    source: GpuMap,
    mid: GpuMap,
    out: GpuMap,
    normals: wgpu::Texture,
    raster: RasterStage,
    targets: RasterTargets,
    svd2: Svd2Stage,
    field_info: wgpu::Buffer,
    /// Map texels per raster texel along each side.
    step: usize,
    surface: Option<SurfaceBuffers>,
    /// The triangles and raster UVs `surface` and the planner were made for.
    layout: Option<RasterLayout>,
    /// Where this chain's map lies in a larger one (none: it is the map).
    window: Option<UvWindow>,
    strain_inputs: wgpu::BindGroup,
    convolve: ConvolveStage,
    pass_binds: [wgpu::BindGroup; 2],
    normals_stage: NormalsStage,
    normals_bind: wgpu::BindGroup,
    /// Tile lists of the s pass, the t pass and the normals.
    tile_lists: [wgpu::Buffer; 3],
    dilate: usize,
    sigma_max_um: f64,
    tolerance: Option<f64>,
    planner: Option<TilePlanner>,
    /// Tiles whose normals changed since they were last computed.
    normals_due: TileMask,
    tiles: FrameTiles,
    /// Tiles the passes ran on, and tiles in the map, over all frames so far.
    pass_tiles: (u64, u64),
    /// Texels the raster covers (the UV area of the layout's triangles in
    /// texels, at most the map's).
    raster_texels: u64,
}

impl GpuMicro {
    /// Uploads `neutral` and `model` and builds the chain, dilating the
    /// raster by `dilate` texels. Every frame convolves every tile the
    /// surface can reach; see [`GpuMicro::set_incremental`].
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
        let field_info = buffers::uniform(&ctx, "field info", &svd2.info(w, h, dilate));
        let convolve = ConvolveStage::new(&ctx);
        let strain_inputs = convolve.strain_inputs(&ctx, &svd2, &field_info, &targets);
        let all_tiles = TileMask::full(w, h).total() as u64;
        let tile_lists =
            [0, 1, 2].map(|_| buffers::storage_zeroed(&ctx, "tile list", 4 * (1 + all_tiles)));
        let pass_info = [0, 1].map(|k| buffers::uniform(&ctx, "pass info", &PassInfo::pass(k)));
        let bind = |src, k: usize, dst| {
            convolve.bind(
                &ctx,
                Params::Strain,
                src,
                pass_info[k].as_entire_binding(),
                Some(&tile_lists[k]),
                dst,
            )
        };
        let pass_binds = [bind(&source, 0, &mid), bind(&mid, 1, &out)];
        let normals_stage = NormalsStage::new(&ctx);
        let normals_bind = normals_stage.bind(&ctx, &out, &normals, Some(&tile_lists[2]));
        ctx.finish()?;
        Ok(GpuMicro {
            raster: RasterStage::new(&ctx),
            ctx,
            width: w,
            height: h,
            source,
            mid,
            out,
            normals,
            targets,
            svd2,
            field_info,
            step: 1,
            surface: None,
            layout: None,
            window: None,
            strain_inputs,
            convolve,
            pass_binds,
            normals_stage,
            normals_bind,
            tile_lists,
            dilate,
            sigma_max_um: model.max_sigma_um(),
            tolerance: None,
            planner: None,
            normals_due: TileMask::empty(w, h),
            tiles: FrameTiles::default(),
            pass_tiles: (0, 0),
            raster_texels: 0,
        })
    }

    /// A chain over `window_map`, the texels of a larger map that `window`
    /// says (the surface field's UVs stay those of the larger map).
    pub fn for_window(
        ctx: Context,
        window_map: &DisplacementMap,
        model: &KernelModel,
        dilate: usize,
        window: UvWindow,
    ) -> Result<GpuMicro> {
        let mut chain = GpuMicro::new(ctx, window_map, model, dilate)?;
        chain.window = Some(window);
        Ok(chain)
    }

    /// Makes frames incremental (`Some(tolerance)`): a tile is convolved
    /// again only when the raster values of a vertex it depends on moved by
    /// more than `tolerance` since they were last convolved (`T − I`
    /// entries, and `Q Rᵀ` entries relative to the largest; see
    /// [`super::active_tiles`]). `Some(0.0)` gives every frame's bits exactly;
    /// `None` (the default) convolves every tile the surface can reach in
    /// every frame. The next frame is a full one either way.
    pub fn set_incremental(&mut self, tolerance: Option<f64>) {
        self.tolerance = tolerance;
        self.planner = None;
    }

    /// Rasterises the strain at one texel per `step × step` map texels and
    /// reads it bilinearly in the passes (the CPU reference is
    /// [`crate::micro::convolve::deform_stepped`]); 1 (the default) gives a
    /// raster texel per map texel. The raster's dilation becomes
    /// [`crate::strain::raster::raster_dilation`] raster texels. The next
    /// frame starts over (maps and raster reset).
    pub fn set_raster_step(&mut self, step: usize) {
        let step = step.max(1);
        let (w, h) = (self.width, self.height);
        let dilate = crate::strain::raster::raster_dilation(self.dilate, step);
        let mut info = self.svd2.info_stepped(w, h, dilate, step);
        if let Some(win) = self.window {
            // Reads clamp at the larger map's edges, as its own chain's do
            // (the window starts on its raster grid: the origin is a
            // multiple of the step, see `TiledMicro::set_raster_step`).
            for k in 0..2 {
                info.raster_origin[k] = (win.origin[k] / step as isize) as i32;
                info.map_raster[k] = win.map_size[k].div_ceil(step) as i32;
            }
            info.wrap = win.wrap as u32;
        }
        self.ctx
            .queue
            .write_buffer(&self.field_info, 0, bytemuck::bytes_of(&info));
        self.targets = RasterTargets::new(&self.ctx, w.div_ceil(step), h.div_ceil(step));
        self.strain_inputs =
            self.convolve
                .strain_inputs(&self.ctx, &self.svd2, &self.field_info, &self.targets);
        self.step = step;
        self.layout = None;
        self.surface = None;
        self.planner = None;
    }

    /// Map texels per raster texel ([`GpuMicro::set_raster_step`]).
    pub fn raster_step(&self) -> usize {
        self.step
    }

    /// The tiles each stage of the last frame ran on.
    pub fn last_tiles(&self) -> FrameTiles {
        self.tiles
    }

    /// The share of the map's tiles the two passes ran on, over every frame
    /// so far (`None` before the first).
    pub fn pass_tile_share(&self) -> Option<f64> {
        let (run, all) = self.pass_tiles;
        (all > 0).then(|| run as f64 / all as f64)
    }

    /// The incremental frames' tolerance (`None`: whole frames).
    pub fn incremental(&self) -> Option<f64> {
        self.tolerance
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
        self.prepare(field, normals);
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
                MicroStage::Upload => self.prepare(field, true),
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
        let read_normals_too =
            (self.width * self.height * 16) as u64 <= self.ctx.limits.max_buffer_size;
        times.bytes = self.frame_bytes(read_normals_too);
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

    /// The bytes each stage of the last frame had to move at least, in
    /// [`MicroStage::ALL`] order: what was uploaded, the raster's covered
    /// texels, each pass's and the normals' texels (the `*_BYTES_PER_TEXEL`
    /// constants) and the read-back of D′ (with its normals when
    /// `normals_read`). A lower bound on memory traffic: a stage at the
    /// device's bandwidth takes its bytes over that bandwidth.
    pub fn frame_bytes(&self, normals_read: bool) -> [u64; MicroStage::COUNT] {
        let t = &self.tiles;
        let texels = (self.width * self.height) as u64;
        MicroStage::ALL.map(|stage| match stage {
            MicroStage::Upload => t.upload_bytes,
            MicroStage::Raster => RASTER_BYTES_PER_TEXEL * self.raster_texels,
            MicroStage::PassS => self.pass_bytes(t.texels[0]),
            MicroStage::PassT => self.pass_bytes(t.texels[1]),
            MicroStage::Normals => NORMALS_BYTES_PER_TEXEL * t.texels[2] as u64,
            MicroStage::ReadBack => texels * if normals_read { 4 + 16 } else { 4 },
        })
    }

    /// Bytes a pass over `texels` map texels moves at least: their heights
    /// read and written, and the raster texels they read (one per map texel
    /// with a step of 1, one per `step²` with a coarse raster).
    fn pass_bytes(&self, texels: usize) -> u64 {
        let raster = RASTER_BYTES_PER_TEXEL as f64 / (self.step * self.step) as f64;
        ((PASS_BYTES_PER_TEXEL - RASTER_BYTES_PER_TEXEL) as f64 * texels as f64
            + raster * texels as f64)
            .round() as u64
    }

    /// The triangles and raster vertices of `field` in this chain's map:
    /// as they are, or moved into the window (with the copies a wrapping map
    /// shows across its edges).
    fn raster_layout(&self, field: &SurfaceField) -> (Vec<[usize; 3]>, Vec<RasterVertex>) {
        let (tri, _) = field.layout();
        let verts = vertices(field);
        let Some(win) = self.window else {
            return (tri.to_vec(), verts);
        };
        let (mw, mh) = (win.map_size[0] as f64, win.map_size[1] as f64);
        let (w, h) = (self.width as f64, self.height as f64);
        let shifts: &[[f64; 2]] = if win.wrap {
            &[
                [0.0, 0.0],
                [-1.0, 0.0],
                [1.0, 0.0],
                [0.0, -1.0],
                [0.0, 1.0],
                [-1.0, -1.0],
                [1.0, -1.0],
                [-1.0, 1.0],
                [1.0, 1.0],
            ]
        } else {
            &[[0.0, 0.0]]
        };
        let (su, sv) = ((mw / w) as f32, (mh / h) as f32);
        let uvs = field.layout().1;
        let mut out_tri = Vec::with_capacity(tri.len() * shifts.len());
        let mut out = Vec::with_capacity(verts.len() * shifts.len());
        for shift in shifts {
            let base = out.len();
            out_tri.extend(tri.iter().map(|t| t.map(|k| k + base)));
            out.extend(verts.iter().zip(uvs).map(|(v, uv)| {
                let f = v.frame;
                RasterVertex {
                    uv: [
                        (((uv.x + shift[0]) * mw - win.origin[0] as f64) / w) as f32,
                        (((uv.y + shift[1]) * mh - win.origin[1] as f64) / h) as f32,
                    ],
                    t: v.t,
                    frame: [f[0] * su, f[1] * su, f[2] * sv, f[3] * sv],
                }
            }));
        }
        (out_tri, out)
    }

    /// Uploads `field`'s raster vertices and this frame's tile lists (the
    /// normals' list when `normals`, else they stay due).
    fn prepare(&mut self, field: &SurfaceField, normals: bool) {
        let (tri, verts) = self.raster_layout(field);
        let uvs: Vec<[f32; 2]> = verts.iter().map(|v| v.uv).collect();
        let (w, h) = (self.width, self.height);
        let step = self.step;
        let (rw, rh) = (w.div_ceil(step), h.div_ceil(step));
        // A coarse raster spans rw·step ≥ w map texels: UVs in its square.
        let drawn = if step == 1 {
            std::borrow::Cow::Borrowed(&verts)
        } else {
            let scale = [
                (w as f64 / (rw * step) as f64) as f32,
                (h as f64 / (rh * step) as f64) as f32,
            ];
            let mut v = verts.clone();
            for x in &mut v {
                x.uv = [x.uv[0] * scale[0], x.uv[1] * scale[1]];
            }
            std::borrow::Cow::Owned(v)
        };
        match (&self.surface, &self.layout) {
            (Some(s), Some(layout)) if layout.0 == tri && layout.1 == uvs => {
                s.write(&self.ctx, &drawn)
            }
            _ => {
                // A new UV layout: the maps and raster start over.
                self.surface = Some(SurfaceBuffers::from_parts(&self.ctx, &tri, &drawn));
                let drawn_uvs: Vec<[f32; 2]> = drawn.iter().map(|v| v.uv).collect();
                self.raster_texels = covered_texels(&tri, &drawn_uvs, rw, rh);
                self.layout = Some((tri.clone(), uvs.clone()));
                self.planner = None;
                self.reset();
            }
        }
        let planner = self.planner.get_or_insert_with(|| {
            let uvs: Vec<[f64; 2]> = uvs.iter().map(|uv| uv.map(f64::from)).collect();
            TilePlanner::new(
                (self.width, self.height),
                &tri,
                &uvs,
                crate::strain::raster::stepped_reach(self.dilate, self.step),
                self.sigma_max_um,
                self.tolerance.map(|t| t as f32),
            )
        });
        let plan = planner.plan(&verts);
        self.normals_due.add(&plan.normals);
        let mut upload_bytes = std::mem::size_of_val(verts.as_slice()) as u64;
        let mut write = |k: usize, mask: &TileMask| {
            let list = mask.list();
            self.ctx
                .queue
                .write_buffer(&self.tile_lists[k], 0, bytemuck::cast_slice(&list));
            upload_bytes += 4 * list.len() as u64;
            list.len() - 1
        };
        let pass_s = write(0, &plan.pass_s);
        let pass_t = write(1, &plan.pass_t);
        let normals_tiles = if normals {
            write(2, &self.normals_due)
        } else {
            0
        };
        self.tiles = FrameTiles {
            pass_s,
            pass_t,
            normals: normals_tiles,
            total: plan.pass_s.total(),
            texels: [
                plan.pass_s.texels(w, h),
                plan.pass_t.texels(w, h),
                if normals {
                    self.normals_due.texels(w, h)
                } else {
                    0
                },
            ],
            upload_bytes,
        };
        self.pass_tiles.0 += (self.tiles.pass_s + self.tiles.pass_t) as u64;
        self.pass_tiles.1 += 2 * self.tiles.total as u64;
        if normals {
            self.normals_due = TileMask::empty(w, h);
        }
    }

    /// The intermediate and output maps set to the neutral map (the tiles no
    /// pass runs on keep it) and the raster cleared (the texels no triangle
    /// covers stay off the surface); runs before the next frame.
    fn reset(&mut self) {
        let mut enc = encoder(&self.ctx);
        let bytes = 4 * (self.width * self.height) as u64;
        for dst in [&self.mid, &self.out] {
            enc.copy_buffer_to_buffer(&self.source.heights, 0, &dst.heights, 0, bytes);
        }
        self.raster.clear(&mut enc, &self.targets);
        self.ctx.queue.submit([enc.finish()]);
    }

    fn encode_stage(&self, enc: &mut wgpu::CommandEncoder, stage: MicroStage) {
        match stage {
            MicroStage::Raster => {
                let surface = self.surface.as_ref().expect("upload runs first");
                self.raster.encode(enc, surface, &self.targets, false);
            }
            MicroStage::PassS | MicroStage::PassT => {
                let k = (stage == MicroStage::PassT) as usize;
                let binds = [&self.pass_binds[k], &self.strain_inputs];
                let tiles = [self.tiles.pass_s, self.tiles.pass_t][k];
                self.convolve.encode_tiles(enc, &binds, tiles);
            }
            MicroStage::Normals => {
                self.normals_stage
                    .encode_tiles(enc, &self.normals_bind, self.tiles.normals)
            }
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
