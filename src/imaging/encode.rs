//! Image files: a linear [`Image`] as 8-bit or 16-bit sRGB PNG or linear
//! float EXR, and the false-colour difference of two images; each file is
//! written atomically (an interrupted run leaves only complete files).

use std::path::Path;

use super::colour::{heat, linear_to_srgb};
use super::{FrameFormat, Image};
use crate::error::{Error, Result};
use crate::mesh::io::write_atomically;

/// Relative difference at which the false colour saturates (white).
pub const DIFFERENCE_RANGE: f32 = 0.5;

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

/// |dynamic − static| / static of the linear luminance per pixel, in false
/// colour saturating at [`DIFFERENCE_RANGE`], as an 8-bit RGB PNG.
pub fn write_difference(path: &Path, stat: &Image, dynamic: &Image) -> Result<()> {
    write_rgb8_png(
        path,
        (stat.width, stat.height),
        &difference_rgb8(stat, dynamic),
    )
}

/// The false-colour difference as 8-bit RGB bytes.
fn difference_rgb8(stat: &Image, dynamic: &Image) -> Vec<u8> {
    let lum = |p: &[f32; 4]| 0.2126 * p[0] + 0.7152 * p[1] + 0.0722 * p[2];
    stat.pixels
        .iter()
        .zip(&dynamic.pixels)
        .flat_map(|(s, d)| {
            let (s, d) = (lum(s), lum(d));
            heat((d - s).abs() / s.max(1e-4) / DIFFERENCE_RANGE)
        })
        .collect()
}

/// An image as 8-bit sRGB bytes (what a PNG frame holds).
fn srgb8(image: &Image) -> Vec<u8> {
    image
        .pixels
        .iter()
        .flat_map(|p| {
            p[..3]
                .iter()
                .map(|&c| (linear_to_srgb(c) * 255.0).round() as u8)
        })
        .collect()
}

/// White pixels between the panels of a comparison strip.
pub const COMPARISON_GAP_PX: usize = 10;

/// The comparison strip of one frame: static | dynamic | their difference
/// (as [`write_difference`]), side by side with [`COMPARISON_GAP_PX`] of
/// white between them, as an 8-bit sRGB PNG.
pub fn write_comparison(path: &Path, stat: &Image, dynamic: &Image) -> Result<()> {
    let (w, h) = (stat.width, stat.height);
    let panels = [srgb8(stat), srgb8(dynamic), difference_rgb8(stat, dynamic)];
    let width = 3 * w + 2 * COMPARISON_GAP_PX;
    let mut rgb = Vec::with_capacity(width * h * 3);
    for row in 0..h {
        for (k, panel) in panels.iter().enumerate() {
            if k > 0 {
                rgb.extend(std::iter::repeat_n(255u8, 3 * COMPARISON_GAP_PX));
            }
            rgb.extend_from_slice(&panel[3 * w * row..3 * w * (row + 1)]);
        }
    }
    write_rgb8_png(path, (width, h), &rgb)
}

/// Writes already encoded 8-bit RGB pixels (`width × height × 3` bytes,
/// row 0 at the top) as a PNG, atomically: the false-colour images and the
/// viewer's window captures.
pub fn write_rgb8_png(path: &Path, (width, height): (usize, usize), rgb: &[u8]) -> Result<()> {
    let failed = |e: png::EncodingError| Error::io(path, std::io::Error::other(e));
    let mut out = Vec::new();
    {
        let mut encoder = png::Encoder::new(&mut out, width as u32, height as u32);
        encoder.set_color(png::ColorType::Rgb);
        encoder.set_depth(png::BitDepth::Eight);
        let mut writer = encoder.write_header().map_err(failed)?;
        writer.write_image_data(rgb).map_err(failed)?;
        writer.finish().map_err(failed)?;
    }
    write_atomically(path, &out)
}
