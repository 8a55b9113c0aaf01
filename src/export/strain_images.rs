//! PNG maps of the surface strain in texture space, like seed 000's strain
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
use crate::mesh::io::write_atomically;
use crate::strain::{StrainRaster, Svd2};

const COMPRESSION: [f64; 3] = [59.0, 76.0, 192.0];
const NEUTRAL: [f64; 3] = [221.0, 221.0, 221.0];
const STRETCH: [f64; 3] = [180.0, 4.0, 38.0];
const OUTSIDE: Rgb<u8> = Rgb([128, 128, 128]);

/// Diverging colour of stretch ratio `r`: `1 ± range` saturate.
pub fn diverging(r: f64, range: f64) -> Rgb<u8> {
    let x = ((r - 1.0) / range).clamp(-1.0, 1.0);
    let (to, k) = if x < 0.0 {
        (COMPRESSION, -x)
    } else {
        (STRETCH, x)
    };
    Rgb([0, 1, 2].map(|c| (NEUTRAL[c] + (to[c] - NEUTRAL[c]) * k).round() as u8))
}

/// Colour of the s axis `(du, dv)` with stretch ratios `svd`.
pub fn direction_colour(du: f64, dv: f64, svd: &Svd2, range: f64) -> Rgb<u8> {
    let angle = dv.atan2(du).rem_euclid(std::f64::consts::PI);
    let hue = 2.0 * angle / std::f64::consts::TAU; // in [0, 1)
    let saturation = ((svd.rs - svd.rt) / range).clamp(0.0, 1.0);
    hsv(hue, saturation, 1.0)
}

fn hsv(h: f64, s: f64, v: f64) -> Rgb<u8> {
    let h6 = (h * 6.0).rem_euclid(6.0);
    let sector = h6.floor();
    let f = h6 - sector;
    let (p, q, t) = (v * (1.0 - s), v * (1.0 - s * f), v * (1.0 - s * (1.0 - f)));
    let (r, g, b) = match sector as u32 {
        0 => (v, t, p),
        1 => (q, v, p),
        2 => (p, v, t),
        3 => (p, q, v),
        4 => (t, p, v),
        _ => (v, p, q),
    };
    Rgb([r, g, b].map(|c| (c * 255.0).round() as u8))
}

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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn colour_maps_hit_their_anchors() {
        assert_eq!(diverging(1.0, 0.2), Rgb([221, 221, 221]));
        assert_eq!(diverging(0.5, 0.2), Rgb([59, 76, 192]));
        assert_eq!(diverging(1.3, 0.2), Rgb([180, 4, 38]));
        let stretched = Svd2::of(&nalgebra::Matrix2::new(1.5, 0.0, 0.0, 1.0));
        // Along u: red; along v: cyan; isotropic: white.
        assert_eq!(
            direction_colour(1.0, 0.0, &stretched, 0.2),
            Rgb([255, 0, 0])
        );
        assert_eq!(
            direction_colour(0.0, 1.0, &stretched, 0.2),
            Rgb([0, 255, 255])
        );
        assert_eq!(
            direction_colour(0.0, -1.0, &stretched, 0.2),
            Rgb([0, 255, 255])
        );
        let iso = Svd2::of(&nalgebra::Matrix2::identity());
        assert_eq!(direction_colour(1.0, 1.0, &iso, 0.2), Rgb([255, 255, 255]));
    }
}
