//! The rendered frames of a run: builds the renderer on the device the
//! microstructure chain uses (or its own), and per rendered frame builds the
//! geometry, makes sure D′'s normals are current, renders every comparison
//! mode and writes `render/<mode>/frame_NNNN.<ext>` atomically (and, when
//! asked, `render/difference/frame_NNNN.png`).

use std::path::{Path, PathBuf};

use super::MicroEngine;
use crate::error::{Error, Result};
use crate::export::frames;
use crate::gpu::micro::GpuMicro;
use crate::gpu::Context;
use crate::mesh::Vec3;
use crate::render::albedo::Albedo;
use crate::render::scene::FrameGeometry;
use crate::render::{FrameStage, Mode, NormalMap, RenderSetup, Renderer, Roughness};
use crate::scenario::MicroSetup;
use crate::strain::SurfaceField;

/// The renderer and, without a GPU microstructure chain, its own device.
pub(super) struct RenderEngine {
    renderer: Renderer,
    own: Option<Context>,
    folders: Vec<(Mode, PathBuf)>,
    format: crate::render::FrameFormat,
    /// `render/difference/` when asked.
    difference: Option<PathBuf>,
    rendered: Vec<usize>,
}

/// The message for a render request without a GPU.
fn no_gpu() -> Error {
    Error::Gpu(
        "[render] needs a GPU adapter (the warning above says why none is usable) — or remove \
         the [render] section"
            .into(),
    )
}

/// m(r)/m(1) of the map under the kernel model at the curve's ratios
/// (ones unless `setup` asks for anisotropic roughness).
pub fn roughness_curve(setup: &RenderSetup, micro: Option<&MicroSetup>) -> [f32; 16] {
    let ratios = crate::render::lighting::curve_ratios();
    match micro {
        Some(m) if setup.roughness == Roughness::Anisotropic => {
            // A tiled map is refused with [render] when the scenario loads.
            let crate::scenario::NeutralMap::Whole(map) = &m.neutral else {
                return [1.0; 16];
            };
            let table = crate::micro::roughness::tabulate(map, &m.model, &ratios);
            let at_one = table
                .points
                .iter()
                .find(|(r, _)| (r - 1.0).abs() < 1e-9)
                .map(|p| p.1)
                .unwrap_or(1.0);
            std::array::from_fn(|i| (table.points[i].1 / at_one) as f32)
        }
        _ => [1.0; 16],
    }
}

impl RenderEngine {
    /// Builds the renderer; creates `render/<mode>/` folders under `dir`.
    pub(super) fn new(
        dir: &Path,
        setup: &RenderSetup,
        micro: Option<&MicroSetup>,
        engine: Option<&MicroEngine>,
        (albedo_extent_mm, texel_mm): (f64, f64),
    ) -> Result<RenderEngine> {
        if setup.mp4 && !frames::ffmpeg_available() {
            return Err(Error::MissingTool(
                "render.mp4 = true needs ffmpeg on the PATH (e.g. `apt-get install ffmpeg`); \
                 install it or set render.mp4 = false"
                    .into(),
            ));
        }
        let mut folders = Vec::new();
        for &mode in &setup.modes {
            let folder = dir.join("render").join(mode.name());
            std::fs::create_dir_all(&folder).map_err(|e| Error::io(&folder, e))?;
            probe_writable(&folder)?;
            folders.push((mode, folder));
        }
        let difference = if setup.difference {
            let folder = dir.join("render").join("difference");
            std::fs::create_dir_all(&folder).map_err(|e| Error::io(&folder, e))?;
            probe_writable(&folder)?;
            Some(folder)
        } else {
            None
        };
        let albedo = Albedo::from_source(&setup.albedo, setup.texture_px, albedo_extent_mm)?;
        let neutral_map = micro.map(|m| m.neutral.whole("[render]")).transpose()?;
        let neutral_normals = neutral_map.map(crate::micro::normals::normal_map);
        let neutral = match (neutral_map, &neutral_normals) {
            (Some(m), Some(n)) => Some(NormalMap {
                normals: n,
                width: m.width,
                height: m.height,
            }),
            _ => None,
        };
        let curve = roughness_curve(setup, micro);
        let (renderer, own) = match engine {
            Some(MicroEngine::Gpu(chain)) => (
                Renderer::new(
                    chain.context(),
                    setup,
                    &albedo,
                    neutral,
                    Some(chain.normals_texture()),
                    curve,
                    texel_mm,
                )?,
                None,
            ),
            Some(MicroEngine::Cpu) => return Err(no_gpu()),
            Some(MicroEngine::Tiled(_)) => unreachable!("a tiled map is refused above"),
            None => {
                let ctx = crate::gpu::acquire()?.ok_or_else(no_gpu)?;
                let renderer = Renderer::new(&ctx, setup, &albedo, neutral, None, curve, texel_mm)?;
                (renderer, Some(ctx))
            }
        };
        log::info!(
            "rendering {} × {} px (×{} supersampling), modes {:?}",
            setup.width,
            setup.height,
            setup.supersample,
            setup.modes
        );
        Ok(RenderEngine {
            renderer,
            own,
            folders,
            format: setup.format,
            difference,
            rendered: Vec::new(),
        })
    }

    /// Renders frame `frame` (its geometry, and the surface field the
    /// chain deforms the map with) in every mode. `fresh_normals` says
    /// whether the chain already computed this frame's D′ normals.
    pub(super) fn frame(
        &mut self,
        geometry: &FrameGeometry,
        field: &SurfaceField,
        engine: Option<&mut MicroEngine>,
        frame: usize,
        fresh_normals: bool,
    ) -> Result<()> {
        let needs_dynamic = self.folders.iter().any(|(m, _)| *m == Mode::Dynamic);
        let ctx: &Context = match (engine, &self.own) {
            (Some(MicroEngine::Gpu(chain)), _) => {
                if needs_dynamic && !fresh_normals {
                    chain.submit(field, true);
                }
                chain.context()
            }
            (_, Some(ctx)) => ctx,
            _ => return Err(no_gpu()),
        };
        self.renderer.set_geometry(ctx, geometry);
        let mut kept = [None, None];
        for (mode, folder) in &self.folders {
            let image = self
                .renderer
                .render(ctx, *mode)
                .map_err(|e| at_frame(e, frame, *mode))?;
            crate::error::check_finite(
                &format!("rendering ({})", mode.name()),
                frame,
                image.width,
                4,
                image.pixels.iter().flatten(),
            )?;
            let path = folder.join(frames::frame_name(frame, self.format));
            frames::write_image(&path, &image, self.format)?;
            match mode {
                Mode::Static => kept[0] = Some(image),
                Mode::Dynamic => kept[1] = Some(image),
                Mode::None => {}
            }
        }
        if let (Some(folder), [Some(stat), Some(dynamic)]) = (&self.difference, &kept) {
            let path = folder.join(frames::frame_name(frame, crate::render::FrameFormat::Png8));
            frames::write_difference(&path, stat, dynamic)?;
        }
        self.rendered.push(frame);
        Ok(())
    }

    /// Encodes the MP4s (when asked) and returns the files written.
    pub(super) fn finish(&self, setup: &RenderSetup, frame_rate_hz: f64) -> Result<Vec<PathBuf>> {
        let mut written: Vec<PathBuf> = self.folders.iter().map(|(_, f)| f.clone()).collect();
        written.extend(self.difference.iter().cloned());
        if setup.mp4 && !self.rendered.is_empty() {
            let fps = frame_rate_hz / setup.frame_stride as f64;
            for (mode, folder) in &self.folders {
                let out = folder.with_file_name(format!("{}.mp4", mode.name()));
                written.push(frames::encode_mp4(folder, &self.rendered, fps, &out)?);
            }
        }
        Ok(written)
    }
}

/// Millimetres a texel of the texture-space targets covers on the patch at
/// rest, from the mesh's bounds (the wider of the two axes: the UVs
/// stretch the top surface's bounding rectangle over the unit square).
pub fn texel_mm((lo, hi): (Vec3, Vec3), texture_px: usize) -> f64 {
    (hi.x - lo.x).max(hi.y - lo.y) / texture_px as f64
}

fn at_frame(e: Error, frame: usize, mode: Mode) -> Error {
    match e {
        Error::Gpu(m) => Error::Gpu(format!("rendering frame {frame} ({}): {m}", mode.name())),
        other => other,
    }
}

/// Fails early, naming the folder, when frames cannot be written there.
fn probe_writable(folder: &Path) -> Result<()> {
    let probe = folder.join(".write-test");
    std::fs::write(&probe, b"").map_err(|e| Error::io(folder, e))?;
    std::fs::remove_file(&probe).map_err(|e| Error::io(folder, e))
}

/// The device of the microstructure chain, or `own` without one.
fn device<'a>(chain: Option<&'a GpuMicro>, own: Option<&'a Context>) -> &'a Context {
    chain
        .map(GpuMicro::context)
        .or(own)
        .expect("a device: the chain's or its own")
}

/// Figures of `skinpatch bench render` (means over the timed frames, ms).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct RenderBench {
    /// The adapter.
    pub adapter: String,
    /// Output size and supersampling.
    pub size: (usize, usize, usize),
    /// Frames timed.
    pub frames: usize,
    /// FEM step (CPU).
    pub fem_ms: f64,
    /// Microstructure chain (GPU, no read-back).
    pub micro_ms: f64,
    /// Geometry build and upload (CPU).
    pub geometry_ms: f64,
    /// Render only: shadow maps to resolve, submitted and waited for.
    pub render_ms: f64,
    /// Render with the image read back.
    pub render_readback_ms: f64,
    /// Each pass of the render submitted alone and waited for, in
    /// [`FrameStage::ALL`] order (wall time; a profile, not a throughput).
    pub stages_ms: [f64; FrameStage::COUNT],
}

/// Simulates the first `frames` frames of `setup` and times, per frame, the
/// FEM step, the microstructure chain, the geometry and the render (mean of
/// `repeats` renders) at `width × height`, without writing files. Uses the
/// scenario's `[render]` settings (defaults without one) in the dynamic mode
/// (mode `none` without a microstructure).
pub fn bench_render(
    setup: &crate::scenario::Setup,
    frames: usize,
    (width, height): (usize, usize),
    repeats: usize,
) -> Result<RenderBench> {
    use std::time::Instant;
    let mut setup = setup.clone();
    setup.simulation.frames = frames.max(1).min(setup.simulation.frames);
    let micro = setup.micro.clone();
    let mut render = match &setup.render {
        Some(r) => r.clone(),
        None => crate::scenario::RenderSection::default().setup(Path::new("."), micro.is_some())?,
    };
    render.width = width;
    render.height = height;
    let mode = if micro.is_some() {
        Mode::Dynamic
    } else {
        Mode::None
    };
    render.modes = vec![mode];
    let ctx = crate::gpu::acquire()?.ok_or_else(no_gpu)?;
    let adapter = ctx.describe();
    let mut ctx = Some(ctx);
    let (lo, hi) = setup.mesh.bounds();
    let albedo = Albedo::from_source(&render.albedo, render.texture_px, hi.x - lo.x)?;
    let mut chain = match &micro {
        Some(m) => Some(GpuMicro::for_scenario(
            ctx.take().expect("the device is unused so far"),
            m,
        )?),
        None => None,
    };
    let own = ctx;
    let mut renderer = {
        let ctx = device(chain.as_ref(), own.as_ref());
        Renderer::new(
            ctx,
            &render,
            &albedo,
            None,
            chain.as_ref().map(|c| c.normals_texture()),
            [1.0; 16],
            texel_mm((lo, hi), render.texture_px),
        )?
    };
    let mut figures = RenderBench {
        adapter,
        size: (width, height, render.supersample),
        ..Default::default()
    };
    let mesh = &setup.mesh;
    super::simulate(&setup, |m, sim| {
        let field = SurfaceField::new(&mesh.top, &mesh.positions, &sim.x);
        let start = Instant::now();
        if let Some(chain) = chain.as_mut() {
            chain.run(&field)?;
        }
        let micro_ms = start.elapsed().as_secs_f64() * 1e3;
        let ctx = device(chain.as_ref(), own.as_ref());
        let start = Instant::now();
        let probe = setup.simulation.probe.as_ref().map(|p| p.pose(m.time_s));
        let geometry =
            crate::render::scene::build(mesh, &sim.x, &field, probe.as_ref(), render.tessellate);
        renderer.set_geometry(ctx, &geometry);
        let geometry_ms = start.elapsed().as_secs_f64() * 1e3;
        // Warm-up (pipelines, first use of the resources).
        renderer.submit(ctx, mode);
        ctx.finish()?;
        let start = Instant::now();
        for _ in 0..repeats.max(1) {
            renderer.submit(ctx, mode);
        }
        ctx.finish()?;
        let render_ms = start.elapsed().as_secs_f64() * 1e3 / repeats.max(1) as f64;
        let start = Instant::now();
        renderer.render(ctx, mode)?;
        let readback_ms = start.elapsed().as_secs_f64() * 1e3;
        let stages = renderer.time_stages(ctx, mode)?;
        if m.frame > 0 {
            for (sum, t) in figures.stages_ms.iter_mut().zip(stages) {
                *sum += t;
            }
            figures.frames += 1;
            figures.fem_ms += m.step_wall_s * 1e3;
            figures.micro_ms += micro_ms;
            figures.geometry_ms += geometry_ms;
            figures.render_ms += render_ms;
            figures.render_readback_ms += readback_ms;
        }
        Ok(())
    })?;
    let n = figures.frames.max(1) as f64;
    for x in [
        &mut figures.fem_ms,
        &mut figures.micro_ms,
        &mut figures.geometry_ms,
        &mut figures.render_ms,
        &mut figures.render_readback_ms,
    ]
    .into_iter()
    .chain(figures.stages_ms.iter_mut())
    {
        *x /= n;
    }
    Ok(figures)
}
