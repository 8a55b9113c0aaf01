//! Diffuse albedo over the patch's UV square: a procedural skin colour or
//! an sRGB image decoded to linear values (Chappuis 2011 §2.7: shading happens in
//! linear space).

use std::path::Path;

use noise::{Fbm, MultiFractal, NoiseFn, Perlin};

use crate::error::{Error, Result};
pub use crate::imaging::colour::{linear_to_srgb, srgb_to_linear};

/// A linear RGBA albedo texture, row 0 at v = 0.
#[derive(Clone, Debug, PartialEq)]
pub struct Albedo {
    /// Width in texels.
    pub width: usize,
    /// Height in texels.
    pub height: usize,
    /// Linear RGBA texels, row-major.
    pub texels: Vec<[f32; 4]>,
}

impl Albedo {
    /// A deterministic skin albedo of `size × size` texels over a patch of
    /// `width_mm`: a light skin tone (sRGB ≈ (0.86, 0.66, 0.57)) with
    /// millimetre-scale blotches of redness (haemoglobin) and a few
    /// freckle-like melanin spots.
    pub fn procedural(size: usize, width_mm: f64) -> Albedo {
        let base = [0.70f32, 0.40, 0.30];
        let redness: Fbm<Perlin> = Fbm::<Perlin>::new(11).set_octaves(3);
        let melanin: Fbm<Perlin> = Fbm::<Perlin>::new(29).set_octaves(2);
        let mut texels = Vec::with_capacity(size * size);
        for j in 0..size {
            for i in 0..size {
                let x = (i as f64 + 0.5) / size as f64 * width_mm;
                let y = (j as f64 + 0.5) / size as f64 * width_mm;
                let red = redness.get([x / 3.0, y / 3.0]) as f32;
                let spot = (melanin.get([x / 0.6, y / 0.6]) as f32 - 0.35).max(0.0) * 2.5;
                let r = base[0] * (1.0 + 0.06 * red) * (1.0 - 0.25 * spot);
                let g = base[1] * (1.0 - 0.10 * red) * (1.0 - 0.35 * spot);
                let b = base[2] * (1.0 - 0.06 * red) * (1.0 - 0.40 * spot);
                texels.push([r, g, b, 1.0].map(|c| c.clamp(0.0, 1.0)));
            }
        }
        Albedo {
            width: size,
            height: size,
            texels,
        }
    }

    /// The albedo a render setup asks for: procedural at `size` texels (at
    /// most 2048) over a patch of `width_mm`, or the scenario's file.
    pub fn from_source(source: &super::AlbedoSource, size: usize, width_mm: f64) -> Result<Albedo> {
        match source {
            super::AlbedoSource::Procedural => Ok(Albedo::procedural(size.min(2048), width_mm)),
            super::AlbedoSource::File(path) => Albedo::load(path),
        }
    }

    /// Reads an 8- or 16-bit sRGB PNG and converts it to linear RGBA.
    pub fn load(path: &Path) -> Result<Albedo> {
        let img = image::ImageReader::open(path)
            .map_err(|e| Error::io(path, e))?
            .with_guessed_format()
            .map_err(|e| Error::io(path, e))?
            .decode()
            .map_err(|e| {
                Error::malformed(
                    path,
                    format!("cannot decode the albedo image (PNG expected): {e}"),
                )
            })?;
        let rgba = img.to_rgba32f();
        let (width, height) = (rgba.width() as usize, rgba.height() as usize);
        let texels = rgba
            .pixels()
            .map(|p| {
                let [r, g, b, a] = p.0;
                [srgb_to_linear(r), srgb_to_linear(g), srgb_to_linear(b), a]
            })
            .collect();
        Ok(Albedo {
            width,
            height,
            texels,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn srgb_round_trip_and_reference_points() {
        for k in 0..=100 {
            let c = k as f32 / 100.0;
            assert!((linear_to_srgb(srgb_to_linear(c)) - c).abs() < 1e-5);
        }
        // Mid grey: sRGB 0.5 is linear 0.214.
        assert!((srgb_to_linear(0.5) - 0.214_041).abs() < 1e-5);
    }

    #[test]
    fn procedural_albedo_is_skin_coloured_and_deterministic() {
        let a = Albedo::procedural(64, 10.0);
        assert_eq!(a, Albedo::procedural(64, 10.0));
        let mean = a
            .texels
            .iter()
            .fold([0.0f32; 3], |m, t| [m[0] + t[0], m[1] + t[1], m[2] + t[2]]);
        let mean = mean.map(|m| m / a.texels.len() as f32);
        assert!(mean[0] > mean[1] && mean[1] > mean[2], "{mean:?}");
        assert!(mean[0] > 0.5 && mean[2] > 0.15, "{mean:?}");
    }
}
