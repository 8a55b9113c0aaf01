//! Strain-driven anisotropic roughness (seed 003; DESIGN §5.4).
//!
//! Where the renderer does not use the deformed microgeometry itself, it can
//! use an anisotropic Beckmann lobe whose roughness along each principal
//! axis follows the stretch along it. For a stretch ratio r along an axis,
//! the neutral map is convolved along that axis with the kernel model's
//! (α(r), σ(r)) and its slopes along the axis are taken in the deformed
//! coordinates (divided by r). A Beckmann distribution of roughness m has
//! slope variance m²/2 along each axis, so `m(r) = √(2·Var(slope))`.
//! Averaging the tables of the u and v axes makes them independent of the
//! neutral map's own orientation.

use super::convolve::{convolve_pass, PassParams};
use super::kernel::KernelModel;
use super::map::DisplacementMap;
use super::normals::slope;
use rayon::prelude::*;

/// Beckmann roughness per stretch ratio.
#[derive(Clone, Debug, PartialEq)]
pub struct RoughnessTable {
    /// `(r, m)` pairs, r ascending.
    pub points: Vec<(f64, f64)>,
}

/// Slope variance along `axis` (0 = u, 1 = v) with the spacing along it
/// scaled by `r`.
fn variance_along(map: &DisplacementMap, axis: usize, r: f64) -> f64 {
    let stretch = if axis == 0 { [r, 1.0] } else { [1.0, r] };
    let rows: Vec<(f64, f64)> = (0..map.height)
        .into_par_iter()
        .map(|j| {
            (0..map.width).fold((0.0, 0.0), |(s, s2), i| {
                let d = slope(map, i, j, stretch)[axis];
                (s + d, s2 + d * d)
            })
        })
        .collect();
    let (s, s2) = rows.iter().fold((0.0, 0.0), |a, b| (a.0 + b.0, a.1 + b.1));
    let n = (map.width * map.height) as f64;
    s2 / n - (s / n).powi(2)
}

/// Tabulates m(r) at `ratios` for `neutral` under `model`.
pub fn tabulate(neutral: &DisplacementMap, model: &KernelModel, ratios: &[f64]) -> RoughnessTable {
    let points = ratios
        .iter()
        .map(|&r| {
            let p = model.params(r);
            let m_axis = |axis: usize| {
                let pass = PassParams {
                    axis: if axis == 0 { [1.0, 0.0] } else { [0.0, 1.0] },
                    alpha: p.alpha as f32,
                    sigma: (p.sigma_um / neutral.texel_um) as f32,
                };
                let convolved = convolve_pass(neutral, &vec![pass; neutral.data.len()]);
                (2.0 * variance_along(&convolved, axis, r)).sqrt()
            };
            (r, 0.5 * (m_axis(0) + m_axis(1)))
        })
        .collect();
    RoughnessTable { points }
}

impl RoughnessTable {
    /// m at `r`, linear between the tabulated ratios, constant beyond.
    pub fn at(&self, r: f64) -> f64 {
        super::kernel::PiecewiseLinear {
            points: self.points.clone(),
        }
        .at(r)
    }
}
