//! Strain-driven anisotropic roughness (Nagano et al. 2014).
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
use super::kernel::{KernelModel, PiecewiseLinear};
use super::map::DisplacementMap;
use super::normals::slope_variance_stretched;

/// Beckmann roughness per stretch ratio: `(r, m)` points, r ascending,
/// linear between them and constant beyond.
pub type RoughnessTable = PiecewiseLinear;

/// Tabulates m(r) at `ratios` (ascending) for `neutral` under `model`.
pub fn tabulate(neutral: &DisplacementMap, model: &KernelModel, ratios: &[f64]) -> RoughnessTable {
    let points = ratios
        .iter()
        .map(|&r| {
            let p = model.params(r);
            let m_axis = |axis: [f32; 2]| {
                let pass = PassParams {
                    axis,
                    alpha: p.alpha as f32,
                    sigma: (p.sigma_um / neutral.texel_um) as f32,
                };
                let convolved = convolve_pass(neutral, &vec![pass; neutral.data.len()]);
                let along = [axis[0] as f64, axis[1] as f64];
                let stretch = [1.0 + (r - 1.0) * along[0], 1.0 + (r - 1.0) * along[1]];
                (2.0 * slope_variance_stretched(&convolved, along, stretch)).sqrt()
            };
            (r, 0.5 * (m_axis([1.0, 0.0]) + m_axis([0.0, 1.0])))
        })
        .collect();
    PiecewiseLinear { points }
}
