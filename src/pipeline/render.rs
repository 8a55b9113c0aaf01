//! The rendered frames of a run: builds the renderer on the device the
//! microstructure chain uses (or its own), and per rendered frame builds the
//! geometry, makes sure D′'s normals are current, renders every comparison
//! mode and writes `render/<mode>/frame_NNNN.<ext>` atomically (and, when
//! asked, `render/difference/` and `render/comparison/frame_NNNN.png`).

use std::path::{Path, PathBuf};

use super::micro::MicroEngine;
use crate::error::{Error, Result};
use crate::export::frames;
use crate::gpu::micro::GpuMicro;
use crate::gpu::Context;
use crate::mesh::Vec3;
use crate::render::albedo::Albedo;
use crate::render::scene::FrameGeometry;
use crate::render::{Mode, NormalMap, RenderSetup, Renderer, Roughness};
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
    /// `render/comparison/` when asked.
    comparison: Option<PathBuf>,
    rendered: Vec<usize>,
}

/// The message for a render request without a GPU.
pub(crate) fn no_gpu() -> Error {
    let why = crate::gpu::vulkan::explain(&crate::gpu::vulkan::look());
    Error::Gpu(format!(
        "[render] needs a GPU adapter — or remove the [render] section; {why}"
    ))
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
    /// Builds the renderer, then creates `render/<mode>/` folders under
    /// `dir`.
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
        // The folders only once the renderer exists: a run refused for
        // lack of a GPU leaves none behind.
        let mut folders = Vec::new();
        for &mode in &setup.modes {
            let folder = dir.join("render").join(mode.name());
            std::fs::create_dir_all(&folder).map_err(|e| Error::io(&folder, e))?;
            probe_writable(&folder)?;
            folders.push((mode, folder));
        }
        let extra = |asked: bool, name: &str| -> Result<Option<PathBuf>> {
            if !asked {
                return Ok(None);
            }
            let folder = dir.join("render").join(name);
            std::fs::create_dir_all(&folder).map_err(|e| Error::io(&folder, e))?;
            probe_writable(&folder)?;
            Ok(Some(folder))
        };
        let difference = extra(setup.difference, "difference")?;
        let comparison = extra(setup.comparison, "comparison")?;
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
            comparison,
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
        if let [Some(stat), Some(dynamic)] = &kept {
            let name = frames::frame_name(frame, crate::render::FrameFormat::Png8);
            if let Some(folder) = &self.difference {
                frames::write_difference(&folder.join(&name), stat, dynamic)?;
            }
            if let Some(folder) = &self.comparison {
                frames::write_comparison(&folder.join(&name), stat, dynamic)?;
            }
        }
        self.rendered.push(frame);
        Ok(())
    }

    /// Encodes the MP4s (when asked).
    pub(super) fn finish(&self, setup: &RenderSetup, frame_rate_hz: f64) -> Result<()> {
        if setup.mp4 && !self.rendered.is_empty() {
            let fps = frame_rate_hz / setup.frame_stride as f64;
            for (mode, folder) in &self.folders {
                let out = folder.with_file_name(format!("{}.mp4", mode.name()));
                frames::encode_mp4(folder, &self.rendered, fps, &out)?;
            }
        }
        Ok(())
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
pub(crate) fn device<'a>(chain: Option<&'a GpuMicro>, own: Option<&'a Context>) -> &'a Context {
    chain
        .map(GpuMicro::context)
        .or(own)
        .expect("a device: the chain's or its own")
}
