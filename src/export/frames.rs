//! Rendered frame files: numbered sequences as 8-bit or 16-bit sRGB PNG or
//! linear float EXR, each written atomically (a temporary file renamed into
//! place, so an interrupted run leaves only complete frames), and an
//! optional MP4 per sequence through an installed `ffmpeg` (also renamed
//! into place when complete).

use std::path::{Path, PathBuf};
use std::process::Command;

use crate::error::{Error, Result};
use crate::mesh::io::write_atomically;
use crate::render::albedo::linear_to_srgb;
use crate::render::{FrameFormat, Image};

/// File name of frame `frame` in `format`.
pub fn frame_name(frame: usize, format: FrameFormat) -> String {
    format!("frame_{frame:04}.{}", format.extension())
}

/// Writes `image` to `path` in `format`.
pub fn write_image(path: &Path, image: &Image, format: FrameFormat) -> Result<()> {
    match format {
        FrameFormat::Png8 | FrameFormat::Png16 => {
            write_png(path, image, format == FrameFormat::Png16)
        }
        FrameFormat::Exr => write_exr(path, image),
    }
}

fn write_png(path: &Path, image: &Image, sixteen: bool) -> Result<()> {
    let failed = |e: png::EncodingError| Error::io(path, std::io::Error::other(e));
    let mut bytes = Vec::with_capacity(image.pixels.len() * if sixteen { 6 } else { 3 });
    for p in &image.pixels {
        for &c in &p[..3] {
            let s = linear_to_srgb(c);
            if sixteen {
                bytes.extend_from_slice(&((s * 65535.0).round() as u16).to_be_bytes());
            } else {
                bytes.push((s * 255.0).round() as u8);
            }
        }
    }
    let mut out = Vec::new();
    {
        let mut encoder = png::Encoder::new(&mut out, image.width as u32, image.height as u32);
        encoder.set_color(png::ColorType::Rgb);
        encoder.set_depth(if sixteen {
            png::BitDepth::Sixteen
        } else {
            png::BitDepth::Eight
        });
        encoder.set_source_srgb(png::SrgbRenderingIntent::Perceptual);
        let mut writer = encoder.write_header().map_err(failed)?;
        writer.write_image_data(&bytes).map_err(failed)?;
        writer.finish().map_err(failed)?;
    }
    write_atomically(path, &out)
}

fn write_exr(path: &Path, image: &Image) -> Result<()> {
    use exr::prelude::{AnyChannel, FlatSamples, LayerAttributes};
    let channel = |name: &str, c: usize| {
        AnyChannel::new(
            name,
            FlatSamples::F32(image.pixels.iter().map(|p| p[c]).collect()),
        )
    };
    crate::micro::io::write_exr_channels(
        path,
        (image.width, image.height),
        LayerAttributes::named("rendered frame"),
        vec![channel("R", 0), channel("G", 1), channel("B", 2)],
    )
}

/// Relative difference at which the false colour saturates (white).
pub const DIFFERENCE_RANGE: f32 = 0.5;

/// False colour of `x` ∈ [0, 1]: black → violet → orange → yellow → white.
fn heat(x: f32) -> [u8; 3] {
    const STOPS: [[f32; 3]; 5] = [
        [0.0, 0.0, 0.0],
        [0.35, 0.05, 0.55],
        [0.9, 0.35, 0.1],
        [1.0, 0.85, 0.2],
        [1.0, 1.0, 1.0],
    ];
    let t = x.clamp(0.0, 1.0) * (STOPS.len() - 1) as f32;
    let k = (t.floor() as usize).min(STOPS.len() - 2);
    let f = t - k as f32;
    std::array::from_fn(|c| {
        ((STOPS[k][c] + (STOPS[k + 1][c] - STOPS[k][c]) * f) * 255.0).round() as u8
    })
}

/// |dynamic − static| / static of the linear luminance per pixel, in false
/// colour saturating at [`DIFFERENCE_RANGE`], as an 8-bit RGB PNG.
pub fn write_difference(path: &Path, stat: &Image, dynamic: &Image) -> Result<()> {
    let lum = |p: &[f32; 4]| 0.2126 * p[0] + 0.7152 * p[1] + 0.0722 * p[2];
    let bytes: Vec<u8> = stat
        .pixels
        .iter()
        .zip(&dynamic.pixels)
        .flat_map(|(s, d)| {
            let (s, d) = (lum(s), lum(d));
            heat((d - s).abs() / s.max(1e-4) / DIFFERENCE_RANGE)
        })
        .collect();
    let failed = |e: png::EncodingError| Error::io(path, std::io::Error::other(e));
    let mut out = Vec::new();
    {
        let mut encoder = png::Encoder::new(&mut out, stat.width as u32, stat.height as u32);
        encoder.set_color(png::ColorType::Rgb);
        encoder.set_depth(png::BitDepth::Eight);
        let mut writer = encoder.write_header().map_err(failed)?;
        writer.write_image_data(&bytes).map_err(failed)?;
        writer.finish().map_err(failed)?;
    }
    write_atomically(path, &out)
}

/// Whether an `ffmpeg` executable runs.
pub fn ffmpeg_available() -> bool {
    Command::new("ffmpeg")
        .arg("-version")
        .output()
        .is_ok_and(|o| o.status.success())
}

/// Encodes the PNG frames of `folder` (`frame_NNNN.png`, `frame_numbers`
/// in order) into `out` (H.264, yuv420p) at `fps` with ffmpeg: the files are
/// piped to it in order, one video frame each, so gaps from a frame stride
/// do not matter.
pub fn encode_mp4(folder: &Path, frame_numbers: &[usize], fps: f64, out: &Path) -> Result<PathBuf> {
    use std::io::Write as _;
    use std::process::Stdio;
    if !ffmpeg_available() {
        return Err(Error::MissingTool(format!(
            "render.mp4 needs ffmpeg on the PATH (e.g. `apt-get install ffmpeg`); \
             the frames in {} are complete without it",
            folder.display()
        )));
    }
    let failed = |e: std::io::Error| Error::io(out, e);
    // Encoded beside the target and renamed into place when complete.
    let partial = out.with_extension("partial.mp4");
    let mut child = Command::new("ffmpeg")
        .args(["-y", "-loglevel", "error", "-f", "image2pipe", "-framerate"])
        .arg(format!("{fps}"))
        .args(["-i", "-", "-vf", "pad=ceil(iw/2)*2:ceil(ih/2)*2"])
        .args(["-c:v", "libx264", "-pix_fmt", "yuv420p"])
        .arg(&partial)
        .stdin(Stdio::piped())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .map_err(failed)?;
    let fed = (|| -> Result<()> {
        let mut stdin = child.stdin.take().expect("stdin was piped");
        for &f in frame_numbers {
            let path = folder.join(frame_name(f, FrameFormat::Png8));
            let bytes = std::fs::read(&path).map_err(|e| Error::io(&path, e))?;
            stdin.write_all(&bytes).map_err(failed)?;
        }
        Ok(())
    })();
    let output = child.wait_with_output().map_err(failed)?;
    if !output.status.success() || fed.is_err() {
        let _ = std::fs::remove_file(&partial);
        fed?;
        return Err(failed(std::io::Error::other(format!(
            "ffmpeg failed: {}",
            String::from_utf8_lossy(&output.stderr).trim()
        ))));
    }
    std::fs::rename(&partial, out).map_err(failed)?;
    Ok(out.to_path_buf())
}
