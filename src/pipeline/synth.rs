//! `skinpatch synth`: runs a synthesis file and writes its outputs.
//!
//! In the output folder: `synthesized.exr` / `synthesized.png` (B′, heights
//! in µm, with the map metadata every map here carries), their normal maps,
//! `albedo.png` when the exemplar has one (each pixel borrowed from where
//! its height came from), `preview.png` (exemplar, mesostructure, result
//! and the result rendered by the skin renderer, side by side) and
//! `synthesis.json` (parameters, per-level figures, statistics of the
//! result against the exemplar and the mesostructure). Each file is written
//! atomically.

use std::path::{Path, PathBuf};

use glam::Vec3;

use crate::error::{Error, Result};
use crate::micro::io::{write_exr, write_normal_exr, write_normal_png16, write_png16};
use crate::micro::normals::normal_map;
use crate::micro::synth::{statistics, synthesize, LevelReport, SynthStatistics, Synthesis};
use crate::micro::DisplacementMap;
use crate::render::albedo::srgb_to_linear;
use crate::render::{FrameFormat, Image};
use crate::scenario::SynthFile;

/// What a synthesis run produced.
#[derive(Debug)]
pub struct SynthRun {
    /// The output folder.
    pub dir: PathBuf,
    /// Files written, in order.
    pub written: Vec<PathBuf>,
    /// The synthesis.
    pub synthesis: Synthesis,
    /// Its statistics.
    pub statistics: SynthStatistics,
    /// Whether the preview's render came from the GPU renderer (false: the
    /// CPU shading it falls back to without an adapter).
    pub rendered_on_gpu: bool,
}

/// Runs the synthesis file at `path` with `overrides` (`--set`), writing
/// into `dir` (None: the file's `[output] dir`, else `out/<stem>`).
/// `on_level` hears of each pyramid level as it finishes.
pub fn run(
    path: &Path,
    overrides: &[String],
    dir: Option<&Path>,
    on_level: &mut dyn FnMut(&LevelReport),
) -> Result<SynthRun> {
    let file: SynthFile = crate::scenario::load_with(path, overrides)?;
    crate::scenario::bounds::check(&file)?;
    let base = path.parent().unwrap_or(Path::new("."));
    let params = file.synthesis.params("synthesis")?;
    let (exr, png) = file.output.formats()?;
    let sources = file.synthesis.load(base, "synthesis")?;
    let stem = path
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "synth".into());
    let dir = dir
        .map(Path::to_path_buf)
        .or(file.output.dir.clone())
        .unwrap_or_else(|| Path::new("out").join(stem));
    refuse_overwriting_inputs(path, base, &file, &dir, (exr, png))?;
    crate::export::outputs::create_output_dir(&dir)?;

    let synthesis = synthesize(&sources.inputs(), &params, on_level)?;
    crate::error::check_finite(
        "synthesis",
        0,
        synthesis.map.width,
        1,
        synthesis.map.data.iter(),
    )?;
    let map = &synthesis.map;
    // Normals only for the files and the preview that use them.
    let normals = if file.output.normal_maps || file.output.preview {
        normal_map(map)
    } else {
        Vec::new()
    };
    let mut written = write_maps(&dir, map, &normals, (exr, png), file.output.normal_maps)?;
    if let Some(albedo) = &sources.albedo {
        let p = dir.join("albedo.png");
        write_albedo(&p, albedo, &synthesis)?;
        written.push(p);
    }
    let statistics = statistics(&synthesis);
    let mut rendered_on_gpu = false;
    if file.output.preview {
        let p = dir.join("preview.png");
        let (image, gpu) = preview(&synthesis, &normals, file.output.preview_px)?;
        crate::export::frames::write_image(&p, &image, FrameFormat::Png8)?;
        rendered_on_gpu = gpu;
        written.push(p);
    }
    let p = dir.join("synthesis.json");
    write_report(&p, path, &file, &synthesis, &statistics, rendered_on_gpu)?;
    written.push(p);
    Ok(SynthRun {
        dir,
        written,
        synthesis,
        statistics,
        rendered_on_gpu,
    })
}

/// Refuses a run whose output folder `dir` would take a file over one
/// of its inputs (the synthesis file, the exemplar, its albedo, the
/// mesostructure map): a result synthesized again from the last one's
/// `synthesized.exr` would otherwise replace its own exemplar.
fn refuse_overwriting_inputs(
    path: &Path,
    base: &Path,
    file: &SynthFile,
    dir: &Path,
    (exr, png): (bool, bool),
) -> Result<()> {
    let s = &file.synthesis;
    let mut inputs: Vec<(&str, PathBuf)> = vec![("synthesis file", path.to_path_buf())];
    for (what, input) in [
        ("exemplar", &s.exemplar),
        ("exemplar albedo", &s.exemplar_albedo),
        ("mesostructure map", &s.mesostructure),
    ] {
        if let Some(input) = input {
            inputs.push((what, base.join(input)));
        }
    }
    let inputs: Vec<(&str, &Path)> = inputs.iter().map(|(w, p)| (*w, p.as_path())).collect();
    let mut outputs = vec!["albedo.png", "preview.png", "synthesis.json"];
    for (wanted, names) in [
        (exr, ["synthesized.exr", "synthesized_normals.exr"]),
        (png, ["synthesized.png", "synthesized_normals.png"]),
    ] {
        if wanted {
            outputs.extend(names);
        }
    }
    for name in outputs {
        crate::export::outputs::refuse_input_overwrite("output.dir", &dir.join(name), &inputs)?;
    }
    Ok(())
}

/// The synthesized map and its normal map in the asked formats (`exr`,
/// `png`); returns the paths.
fn write_maps(
    dir: &Path,
    map: &DisplacementMap,
    normals: &[[f32; 3]],
    (exr, png): (bool, bool),
    normal_maps: bool,
) -> Result<Vec<PathBuf>> {
    let mut written = Vec::new();
    if exr {
        let p = dir.join("synthesized.exr");
        write_exr(&p, map)?;
        written.push(p);
    }
    if png {
        let p = dir.join("synthesized.png");
        write_png16(&p, map)?;
        written.push(p);
    }
    if normal_maps {
        if exr {
            let p = dir.join("synthesized_normals.exr");
            write_normal_exr(&p, normals, map)?;
            written.push(p);
        }
        if png {
            let p = dir.join("synthesized_normals.png");
            write_normal_png16(&p, normals, map)?;
            written.push(p);
        }
    }
    Ok(written)
}

/// `synthesis.json`: the file's settings, the output's size, the per-level
/// figures and the statistics.
fn write_report(
    p: &Path,
    path: &Path,
    file: &SynthFile,
    synthesis: &Synthesis,
    statistics: &SynthStatistics,
    rendered_on_gpu: bool,
) -> Result<()> {
    let map = &synthesis.map;
    let report = serde_json::json!({
        "file": path.display().to_string(),
        "synthesis": file.synthesis,
        "output": {
            "width": map.width,
            "height": map.height,
            "texel_um": map.texel_um,
            "edge": format!("{:?}", map.edge).to_lowercase(),
        },
        "mesostructure_sigma_um": synthesis.sigmas_um.0,
        "lowpass_sigma_um": synthesis.sigmas_um.1,
        "levels": synthesis.levels.iter().map(|l| serde_json::json!({
            "level": l.level,
            "size": [l.size.0, l.size.1],
            "exemplar": [l.exemplar.0, l.exemplar.1],
            "window": l.window,
            "dims": l.dims,
            "candidates": l.candidates,
            "coherent_share": l.coherent_share,
            "seconds": l.seconds,
        })).collect::<Vec<_>>(),
        "seconds": synthesis.seconds,
        "statistics": statistics,
        "preview_rendered_on_gpu": rendered_on_gpu,
    });
    let text = serde_json::to_string_pretty(&report)
        .map_err(|e| Error::io(p, std::io::Error::other(e)))?;
    crate::mesh::io::write_atomically(p, text.as_bytes())
}

/// The synthesized albedo: each output pixel is the exemplar albedo's
/// pixel its height came from, at the albedo's bit depth.
fn write_albedo(path: &Path, albedo: &image::DynamicImage, synthesis: &Synthesis) -> Result<()> {
    let (w, h) = (synthesis.map.width as u32, synthesis.map.height as u32);
    let aw = albedo.width() as usize;
    // Map rows run with v up, image rows top down: flip both ways.
    let src_row = |p: u32| (albedo.height() as usize - 1 - p as usize / aw) as u32;
    let pick = |x: u32, y: u32| synthesis.source[(h - 1 - y) as usize * w as usize + x as usize];
    let out = if albedo.color().bytes_per_pixel() / albedo.color().channel_count() > 1 {
        let src = albedo.to_rgba16();
        image::DynamicImage::ImageRgba16(image::ImageBuffer::from_fn(w, h, |x, y| {
            let p = pick(x, y);
            *src.get_pixel(p % aw as u32, src_row(p))
        }))
    } else {
        let src = albedo.to_rgba8();
        image::DynamicImage::ImageRgba8(image::ImageBuffer::from_fn(w, h, |x, y| {
            let p = pick(x, y);
            *src.get_pixel(p % aw as u32, src_row(p))
        }))
    };
    let mut bytes = std::io::Cursor::new(Vec::new());
    out.write_to(&mut bytes, image::ImageFormat::Png)
        .map_err(|e| Error::io(path, std::io::Error::other(e)))?;
    crate::mesh::io::write_atomically(path, bytes.get_ref())
}

/// Four panels of `px`: exemplar, mesostructure, result (heights, each
/// over its own 1st–99th percentile) and the result rendered; and whether
/// the render came from the GPU.
fn preview(synthesis: &Synthesis, normals: &[[f32; 3]], px: usize) -> Result<(Image, bool)> {
    let heights = [&synthesis.exemplar, &synthesis.guide, &synthesis.map];
    let (render, gpu) = match render_flat(&synthesis.map, normals, px)? {
        Some(image) => (image, true),
        None => (shade_on_cpu(&synthesis.map, normals, px), false),
    };
    let gap = 4;
    let width = 4 * px + 3 * gap;
    let mut image = Image {
        width,
        height: px,
        pixels: vec![[1.0, 1.0, 1.0, 1.0]; width * px],
    };
    for (k, m) in heights.iter().enumerate() {
        let panel = grey_panel(m, px);
        for j in 0..px {
            for i in 0..px {
                image.pixels[j * width + k * (px + gap) + i] = panel[j * px + i];
            }
        }
    }
    for j in 0..px {
        for i in 0..px {
            image.pixels[j * width + 3 * (px + gap) + i] = render.pixels[j * render.width + i];
        }
    }
    Ok((image, gpu))
}

/// A `px × px` panel showing a `width × height` grid (row 0 at the top, v
/// up, aspect kept, white beyond the grid); `colour` gives the colour of a
/// grid texel by its row-major index.
fn panel(
    width: usize,
    height: usize,
    px: usize,
    colour: impl Fn(usize) -> [f32; 4],
) -> Vec<[f32; 4]> {
    let scale = width.max(height) as f64 / px as f64;
    let mut out = vec![[1.0, 1.0, 1.0, 1.0]; px * px];
    for row in 0..px {
        for i in 0..px {
            let (x, y) = ((i as f64 + 0.5) * scale, (row as f64 + 0.5) * scale);
            if x < width as f64 && y < height as f64 {
                let j = height - 1 - y as usize;
                out[row * px + i] = colour(j * width + x as usize);
            }
        }
    }
    out
}

/// A map's heights in grey over its own 1st–99th percentile.
fn grey_panel(m: &DisplacementMap, px: usize) -> Vec<[f32; 4]> {
    let mut sorted: Vec<f32> = m.data.iter().copied().filter(|v| v.is_finite()).collect();
    sorted.sort_by(f32::total_cmp);
    let at = |q: f64| {
        sorted
            .get(((sorted.len().max(1) - 1) as f64 * q) as usize)
            .copied()
            .unwrap_or(0.0)
    };
    let (lo, hi) = (at(0.01), at(0.99));
    let span = (hi - lo).max(f32::MIN_POSITIVE);
    panel(m.width, m.height, px, |k| {
        let l = srgb_to_linear(((m.data[k] - lo) / span).clamp(0.0, 1.0));
        [l, l, l, 1.0]
    })
}

/// One light grazing from the upper left.
fn light_direction() -> Vec3 {
    Vec3::new(0.55, -0.45, -0.70).normalize()
}

/// The map on a flat square patch through the skin renderer (static
/// mode: the map's normals, the procedural albedo, one grazing light);
/// None without a GPU adapter.
fn render_flat(map: &DisplacementMap, normals: &[[f32; 3]], px: usize) -> Result<Option<Image>> {
    use crate::render::scene::{FrameGeometry, SurfaceVertex};
    use crate::render::{light, Mode, NormalMap, Renderer};
    let Some(ctx) = crate::gpu::acquire()? else {
        return Ok(None);
    };
    let (w_mm, h_mm) = (
        (map.width as f64 * map.texel_um / 1000.0) as f32,
        (map.height as f64 * map.texel_um / 1000.0) as f32,
    );
    let mut setup = crate::scenario::RenderSection::default().setup(Path::new("."), true)?;
    setup.width = px;
    setup.height = px;
    setup.supersample = 2;
    setup.modes = vec![Mode::Static];
    setup.draw_probe = false;
    let side = w_mm.max(h_mm);
    let centre = Vec3::ZERO;
    setup.camera = crate::render::camera::Camera {
        eye: centre + Vec3::new(0.0, -0.35 * side, 1.9 * side),
        target: centre,
        up: Vec3::Y,
        projection: crate::render::camera::Projection::Perspective { fov_deg: 30.0 },
    };
    setup.lights = vec![light::Light {
        kind: light::LightKind::Directional(light_direction()),
        color: Vec3::ONE,
        intensity: 3.0,
    }];
    let albedo = crate::render::albedo::Albedo::procedural(setup.texture_px.min(1024), side as f64);
    let texel_mm = side as f64 / setup.texture_px as f64;
    let mut renderer = Renderer::new(
        &ctx,
        &setup,
        &albedo,
        Some(NormalMap {
            normals,
            width: map.width,
            height: map.height,
        }),
        None,
        [1.0; 16],
        texel_mm,
    )?;
    // A 32 × 32 grid of quads over the map, centred at the origin.
    let n = 32;
    let vertex = |i: usize, j: usize| {
        let (u, v) = (i as f32 / n as f32, j as f32 / n as f32);
        let p = [(u - 0.5) * w_mm, (v - 0.5) * h_mm, 0.0, 1.0];
        SurfaceVertex {
            position: p,
            normal: [0.0, 0.0, 1.0, 0.0],
            tangent: [1.0, 0.0, 0.0, 0.0],
            uv: [u, v, 0.0, 0.0],
            strain: [1.0, 1.0, 1.0, 0.0],
        }
    };
    let mut surface = Vec::with_capacity(6 * n * n);
    for j in 0..n {
        for i in 0..n {
            let (a, b, c, d) = (
                vertex(i, j),
                vertex(i + 1, j),
                vertex(i + 1, j + 1),
                vertex(i, j + 1),
            );
            surface.extend_from_slice(&[a, b, c, a, c, d]);
        }
    }
    renderer.set_geometry(&ctx, &FrameGeometry::of_surface(surface));
    Ok(Some(renderer.render(&ctx, Mode::Static)?))
}

/// Without a GPU: Lambert shading of the normals under the same light,
/// seen from straight above.
fn shade_on_cpu(map: &DisplacementMap, normals: &[[f32; 3]], px: usize) -> Image {
    let l = -light_direction();
    let pixels = panel(map.width, map.height, px, |k| {
        let n = normals[k];
        let c = 0.05 + 0.9 * (n[0] * l.x + n[1] * l.y + n[2] * l.z).max(0.0);
        [c * 0.86, c * 0.62, c * 0.52, 1.0]
    });
    Image {
        width: px,
        height: px,
        pixels,
    }
}
