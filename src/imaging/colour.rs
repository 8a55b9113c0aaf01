//! Colour: the sRGB transfer functions (shading is linear; files and
//! screens are sRGB) and the colour maps of the strain images, the viewer's
//! overlays and the renderer's difference images.
//!
//! * stretch ratios ([`diverging`]): blue (`1 − range` and below,
//!   compression) → light grey (1, neutral) → red (`1 + range` and above,
//!   stretch), linear in sRGB between the three anchors;
//! * axes ([`direction_colour`]): hue = twice the angle of the s axis from
//!   the u axis (an axis has no sign), saturation = anisotropy
//!   `(r_s − r_t)/range` clamped to 1;
//! * differences ([`heat`]): black → violet → orange → yellow → white.

use image::Rgb;

use crate::strain::Svd2;

/// The sRGB transfer function inverted: encoded `[0, 1]` → linear.
pub fn srgb_to_linear(c: f32) -> f32 {
    if c <= 0.040_45 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

/// The sRGB transfer function: linear → encoded `[0, 1]` (clamped).
pub fn linear_to_srgb(c: f32) -> f32 {
    let c = c.clamp(0.0, 1.0);
    if c <= 0.003_130_8 {
        12.92 * c
    } else {
        1.055 * c.powf(1.0 / 2.4) - 0.055
    }
}

const COMPRESSION: [f64; 3] = [59.0, 76.0, 192.0];
const NEUTRAL: [f64; 3] = [221.0, 221.0, 221.0];
const STRETCH: [f64; 3] = [180.0, 4.0, 38.0];

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

/// False colour of `x` ∈ [0, 1]: black → violet → orange → yellow → white.
pub fn heat(x: f32) -> [u8; 3] {
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
