//! Maps of the surface strain in texture space. Previews like Nagano et
//! al. 2015's strain figure: `strain/rs_NNNN.png` and `strain/rt_NNNN.png`
//! (stretch ratios with a diverging colour map centred at 1 and a colour
//! bar on the right) and `strain/axes_NNNN.png` (direction of the s axis);
//! and the same field as float data, `strain/strain_NNNN.exr`
//! ([`write_strain_data`]).
//!
//! The maps show UV space with u to the right and v up (the raster's row 0,
//! v = 0, is the image's bottom row). Colours:
//!
//! * stretch ratios: blue (`1 − range` and below, compression) → light grey
//!   (1, neutral) → red (`1 + range` and above, stretch), linear in sRGB
//!   between the three anchors; the bar at the right spans `1 − range`
//!   (bottom) to `1 + range` (top) with a dark tick at 1; texels outside the
//!   surface are mid grey;
//! * axes: hue = twice the angle of the s axis from the u axis (an axis has no
//!   sign: red along u, cyan along v, yellow-green and violet on the
//!   diagonals), saturation = anisotropy `(r_s − r_t)/range` clamped to 1
//!   (white where the stretch is the same in every direction); black outside.

use std::path::{Path, PathBuf};

use image::{Rgb, RgbImage};

use crate::error::{Error, Result};
use crate::imaging::colour::{direction_colour, diverging};
use crate::mesh::io::write_atomically;
use crate::strain::{StrainRaster, Svd2};

const OUTSIDE: Rgb<u8> = Rgb([128, 128, 128]);

/// The three images of one frame's raster.
pub struct StrainImages {
    /// r_s with its colour bar.
    pub rs: RgbImage,
    /// r_t with its colour bar.
    pub rt: RgbImage,
    /// The s-axis direction map.
    pub axes: RgbImage,
}

impl StrainImages {
    /// Renders `raster` with the stretch colour map saturating at `1 ± range`.
    pub fn new(raster: &StrainRaster, range: f64) -> StrainImages {
        let (w, h) = (raster.width as u32, raster.height as u32);
        let bar = (w / 24).max(6);
        let gap = (w / 64).max(2);
        let mut rs = RgbImage::from_pixel(w + gap + bar, h, Rgb([255, 255, 255]));
        let mut rt = rs.clone();
        let mut axes = RgbImage::new(w, h);
        for j in 0..raster.height {
            let row = h - 1 - j as u32; // v up
            for i in 0..raster.width {
                let idx = raster.index(i, j);
                let (a, b, c) = if raster.inside[idx] {
                    let svd = Svd2::of(&raster.t[idx]);
                    let s_uv = raster.uv_frame[idx] * svd.s_axis();
                    (
                        diverging(svd.rs, range),
                        diverging(svd.rt, range),
                        direction_colour(s_uv.x, s_uv.y, &svd, range),
                    )
                } else {
                    (OUTSIDE, OUTSIDE, Rgb([0, 0, 0]))
                };
                rs.put_pixel(i as u32, row, a);
                rt.put_pixel(i as u32, row, b);
                axes.put_pixel(i as u32, row, c);
            }
        }
        for row in 0..h {
            let colour = bar_colour(row, h, range);
            for x in w + gap..w + gap + bar {
                rs.put_pixel(x, row, colour);
                rt.put_pixel(x, row, colour);
            }
        }
        StrainImages { rs, rt, axes }
    }

    /// Writes `strain/rs_NNNN.png`, `rt_NNNN.png` and `axes_NNNN.png` under
    /// `dir`, each atomically; returns their paths.
    pub fn write(&self, dir: &Path, frame: usize) -> Result<Vec<PathBuf>> {
        self.write_tagged(dir, "", frame)
    }

    /// [`Self::write`] with a tag before the frame number (`rs_1001_0004.png`
    /// for UDIM tile 1001's maps, tag `"1001_"`).
    pub fn write_tagged(&self, dir: &Path, tag: &str, frame: usize) -> Result<Vec<PathBuf>> {
        let folder = dir.join("strain");
        let mut written = Vec::new();
        for (name, image) in [("rs", &self.rs), ("rt", &self.rt), ("axes", &self.axes)] {
            let path = folder.join(format!("{name}_{tag}{frame:04}.png"));
            let mut bytes = Vec::new();
            image
                .write_to(
                    &mut std::io::Cursor::new(&mut bytes),
                    image::ImageFormat::Png,
                )
                .map_err(|e| Error::io(&path, std::io::Error::other(e)))?;
            write_atomically(&path, &bytes)?;
            written.push(path);
        }
        Ok(written)
    }
}

/// The colour bar's row `row` of `h`: the diverging colour of its ratio,
/// from `1 + range` (top row) to `1 − range` (bottom row), and black on the
/// one row whose span holds the ratio 1 (for an even `h`, the row just
/// below it).
fn bar_colour(row: u32, h: u32, range: f64) -> Rgb<u8> {
    if row == h / 2 {
        return Rgb([0, 0, 0]);
    }
    let r = 1.0 + range * (1.0 - 2.0 * (row as f64 + 0.5) / h as f64);
    diverging(r, range)
}

/// Writes the raster's strain as float data, `strain/strain_[TAG]NNNN.exr`
/// under `dir`: channels `rs`, `rt` (stretch ratios), `su`, `sv` (the s
/// axis, a unit vector in UV; an axis has no sign, so `su ≥ 0`, and
/// `sv > 0` where `su = 0`) and `A` (1 on the surface, 0 outside, where the
/// ratios are 1 and the axis is u). Rows run with v up, as the previews
/// and the microstructure maps. Returns the path.
pub fn write_strain_data(
    raster: &StrainRaster,
    dir: &Path,
    tag: &str,
    frame: usize,
) -> Result<PathBuf> {
    use exr::prelude::{AnyChannel, FlatSamples, LayerAttributes};
    let (w, h) = (raster.width, raster.height);
    let mut planes = [(); 5].map(|_| Vec::with_capacity(w * h));
    for j in (0..h).rev() {
        for i in 0..w {
            let idx = raster.index(i, j);
            let texel = if raster.inside[idx] {
                let svd = Svd2::of(&raster.t[idx]);
                let s = raster.uv_frame[idx] * svd.s_axis();
                let s = if s.norm() > 0.0 {
                    s / s.norm()
                } else {
                    nalgebra::Vector2::x()
                };
                let s = if s.x < 0.0 || (s.x == 0.0 && s.y < 0.0) {
                    -s
                } else {
                    s
                };
                [svd.rs, svd.rt, s.x, s.y, 1.0]
            } else {
                [1.0, 1.0, 1.0, 0.0, 0.0]
            };
            for (plane, v) in planes.iter_mut().zip(texel) {
                plane.push(v as f32);
            }
        }
    }
    let channels = ["rs", "rt", "su", "sv", "A"]
        .into_iter()
        .zip(planes)
        .map(|(name, plane)| AnyChannel::new(name, FlatSamples::F32(plane)))
        .collect();
    let path = dir
        .join("strain")
        .join(format!("strain_{tag}{frame:04}.exr"));
    crate::micro::io::write_exr_channels(
        &path,
        (w, h),
        LayerAttributes::named("strain"),
        channels,
    )?;
    Ok(path)
}

/// A strain data map read back ([`read_strain_data`]): one value per texel
/// and channel, rows as in the file (the top row first, v = 1).
#[derive(Clone, Debug, PartialEq)]
pub struct StrainData {
    /// Texels across (u).
    pub width: usize,
    /// Texels down (v).
    pub height: usize,
    /// Channels by name: `rs`, `rt`, `su`, `sv`, `A`.
    pub channels: std::collections::BTreeMap<String, Vec<f32>>,
}

impl StrainData {
    /// The channel `name`; an error naming the file's channels if absent.
    pub fn channel(&self, name: &str) -> Result<&[f32]> {
        self.channels
            .get(name)
            .map(Vec::as_slice)
            .ok_or_else(|| Error::Parameter {
                key: name.to_string(),
                reason: format!(
                    "is not a channel of this strain map; it has {:?}",
                    self.channels.keys().collect::<Vec<_>>()
                ),
            })
    }
}

/// Reads a strain data map written by [`write_strain_data`] (or any EXR's
/// first layer of float channels).
pub fn read_strain_data(path: &Path) -> Result<StrainData> {
    let image = exr::prelude::read_first_flat_layer_from_file(path)
        .map_err(|e| Error::malformed(path, format!("not a readable EXR: {e}")))?;
    let layer = &image.layer_data;
    let channels = layer
        .channel_data
        .list
        .iter()
        .map(|c| (c.name.to_string(), c.sample_data.values_as_f32().collect()))
        .collect();
    Ok(StrainData {
        width: layer.size.width(),
        height: layer.size.height(),
        channels,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Matrix2, Vector2};

    /// The bar has exactly one tick row, and the ratio 1 lies within it,
    /// for odd and even heights (the default 512 among them).
    #[test]
    fn the_colour_bar_ticks_ratio_one_once() {
        let range = 0.3;
        for h in [1u32, 2, 3, 7, 8, 511, 512] {
            let ticks: Vec<u32> = (0..h)
                .filter(|&row| bar_colour(row, h, range) == Rgb([0, 0, 0]))
                .collect();
            assert_eq!(ticks.len(), 1, "height {h}: tick rows {ticks:?}");
            // Row i spans ratios from 1 + range(1 − 2(i + 1)/h) to 1 + range(1 − 2i/h).
            let i = ticks[0] as f64;
            let top = 1.0 + range * (1.0 - 2.0 * i / h as f64);
            let bottom = 1.0 + range * (1.0 - 2.0 * (i + 1.0) / h as f64);
            assert!(
                bottom <= 1.0 && 1.0 <= top,
                "height {h}: row {i} spans {bottom}..{top}"
            );
        }
    }

    /// The data map holds the ratios and the axis of a known stretch, and
    /// the neutral values with A = 0 outside the surface.
    #[test]
    fn strain_data_reads_back_as_the_stretch_it_was_given() {
        let (w, h) = (6, 4);
        let mut raster = StrainRaster::outside(w, h);
        let theta = 2.5f64; // the axis (cos θ, sin θ) has su < 0: flipped
        let rot = Matrix2::new(theta.cos(), -theta.sin(), theta.sin(), theta.cos());
        let t = rot * Matrix2::new(1.2, 0.0, 0.0, 0.9) * rot.transpose();
        for j in 0..h {
            for i in 0..w / 2 {
                let k = raster.index(i, j);
                raster.inside[k] = true;
                raster.t[k] = t;
                raster.uv_frame[k] = Matrix2::identity();
            }
        }
        let dir = tempfile::tempdir().unwrap();
        std::fs::create_dir_all(dir.path().join("strain")).unwrap();
        let path = write_strain_data(&raster, dir.path(), "", 7).unwrap();
        assert!(path.ends_with("strain/strain_0007.exr"));
        let data = read_strain_data(&path).unwrap();
        assert_eq!((data.width, data.height), (w, h));
        let channel = |name: &str| data.channel(name).unwrap().to_vec();
        let axis = -Vector2::new(theta.cos(), theta.sin());
        let expected_inside = [1.2, 0.9, axis.x, axis.y, 1.0];
        let expected_outside = [1.0, 1.0, 1.0, 0.0, 0.0];
        for (c, name) in ["rs", "rt", "su", "sv", "A"].iter().enumerate() {
            let values = channel(name);
            for (k, v) in values.iter().enumerate() {
                let i = k % w;
                let expected = if i < w / 2 {
                    expected_inside[c]
                } else {
                    expected_outside[c]
                };
                assert!(
                    (*v as f64 - expected).abs() < 1e-6,
                    "{name}[{k}] = {v}, expected {expected}"
                );
            }
        }
    }
}
