//! PNG maps of the surface strain in texture space, like Nagano et al. 2015's strain
//! figure: `strain/rs_NNNN.png` and `strain/rt_NNNN.png` (stretch ratios
//! with a diverging colour map centred at 1 and a colour bar on the right)
//! and `strain/axes_NNNN.png` (direction of the s axis).
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
            // Top row = 1 + range, bottom row = 1 − range.
            let r = 1.0 + range * (1.0 - 2.0 * (row as f64 + 0.5) / h as f64);
            let tick = (r - 1.0).abs() < range / h as f64;
            let colour = if tick {
                Rgb([0, 0, 0])
            } else {
                diverging(r, range)
            };
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
