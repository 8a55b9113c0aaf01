//! Procedural neutral skin microstructure.
//!
//! Skin surface detail is a network of fine grooves bounding polygonal
//! plateaus, a finer network inside those, pores, and fine texture. The
//! generator builds it from:
//!
//! * two cell networks (Worley/Voronoi cells on jittered periodic lattices):
//!   each texel's distance to the border between its nearest and
//!   second-nearest cell centres, `((p−c₂)² − (p−c₁)²)/(2|c₂−c₁|)`, gives a
//!   groove of Gaussian cross-section; each border (cell pair) has its own
//!   depth, varied by `depth_spread`. The fine network has a third of the
//!   spacing and depth of the primary one;
//! * cells elongated along u by `1 + 2·(1 − orientation_spread)`: with
//!   spread 1 the grooves run in every direction, with spread 0 they mostly
//!   follow u;
//! * pores: Gaussian pits at jittered lattice points, present with a
//!   probability that gives `pore_density_per_mm2`;
//! * fine noise: fractal Perlin noise (the `noise` crate) sampled on a 4D
//!   torus so that it tiles.
//!
//! Every lattice wraps at the map's edge, so the map tiles (edge handling
//! `Wrap`). Random numbers come from a hash of (seed, layer, cell), and texels
//! are computed independently: the same parameters give the same bits on any
//! thread count.

use noise::{Fbm, MultiFractal, NoiseFn, Perlin};

use super::map::{DisplacementMap, Edge};
use crate::error::{shown, Error, Result};

/// Parameters of the generator (lengths in µm unless named otherwise).
#[derive(Clone, Debug, PartialEq)]
pub struct SkinParams {
    /// Texels per side.
    pub size_px: usize,
    /// Side of the map on the skin (mm).
    pub extent_mm: f64,
    /// Random seed.
    pub seed: u64,
    /// Mean spacing of the primary grooves.
    pub groove_spacing_um: f64,
    /// Mean depth of the primary grooves.
    pub groove_depth_um: f64,
    /// Width (Gaussian 1/e half-width) of the primary grooves.
    pub groove_width_um: f64,
    /// Relative spread of groove depths between borders, in [0, 1].
    pub depth_spread: f64,
    /// 1: grooves in every direction; 0: mostly along u.
    pub orientation_spread: f64,
    /// Pores per mm².
    pub pore_density_per_mm2: f64,
    /// Pore radius (Gaussian 1/e).
    pub pore_radius_um: f64,
    /// Pore depth.
    pub pore_depth_um: f64,
    /// Amplitude of the fine noise.
    pub noise_amplitude_um: f64,
    /// Feature size of the fine noise.
    pub noise_scale_um: f64,
}

impl Default for SkinParams {
    /// 2048² over 10 mm (4.9 µm texels), grooves ~250 µm apart and ~30 µm
    /// deep, about 12 pores per mm², 1.5 µm of fine texture.
    fn default() -> Self {
        SkinParams {
            size_px: 2048,
            extent_mm: 10.0,
            seed: 1,
            groove_spacing_um: 250.0,
            groove_depth_um: 30.0,
            groove_width_um: 18.0,
            depth_spread: 0.5,
            orientation_spread: 0.6,
            pore_density_per_mm2: 12.0,
            pore_radius_um: 25.0,
            pore_depth_um: 20.0,
            noise_amplitude_um: 1.5,
            noise_scale_um: 40.0,
        }
    }
}

/// Most texels per side of a generated map.
pub const MAX_SIZE_PX: usize = 16384;

/// Range of the feature sizes — groove spacing and width, pore radius,
/// noise scale (µm): a nanometre to a metre.
pub const FEATURE_UM: (f64, f64) = (1e-3, 1e6);

/// Deepest groove, pore or noise amplitude (µm): a centimetre, twice the
/// patch's thickness. The map's heights are f32 and their sum must stay
/// finite.
pub const MAX_DEPTH_UM: f64 = 1e4;

/// Most pores per mm² (one per µm²).
pub const MAX_PORES_PER_MM2: f64 = 1e6;

/// Widest generated map (mm).
pub const MAX_EXTENT_MM: f64 = 1e3;

impl SkinParams {
    /// Checks every parameter; `key` prefixes the names in errors.
    pub fn validate(&self, key: &str) -> Result<()> {
        if !(1..=MAX_SIZE_PX).contains(&self.size_px) {
            return Err(Error::parameter(
                format!("{key}.size_px"),
                format!("must be in 1 … {MAX_SIZE_PX}, got {}", self.size_px),
            ));
        }
        let positive = [
            ("extent_mm", self.extent_mm),
            ("groove_spacing_um", self.groove_spacing_um),
            ("groove_width_um", self.groove_width_um),
            ("pore_radius_um", self.pore_radius_um),
            ("noise_scale_um", self.noise_scale_um),
        ];
        for (name, v) in positive {
            if !(v.is_finite() && v > 0.0) {
                return Err(Error::parameter(
                    format!("{key}.{name}"),
                    format!("must be finite and > 0, got {}", shown(v)),
                ));
            }
        }
        // Feature sizes between a nanometre and a metre: outside, the
        // lattices would need more cells than an integer holds, Gaussian
        // profiles would divide 0 by 0, and the noise coordinates would
        // leave the range its lattice indices can take.
        let (lo, hi) = FEATURE_UM;
        for (name, v) in &positive[1..] {
            if !(lo..=hi).contains(v) {
                return Err(Error::parameter(
                    format!("{key}.{name}"),
                    format!("must be in [{lo:e}, {hi:e}] µm, got {}", shown(*v)),
                ));
            }
        }
        if self.extent_mm > MAX_EXTENT_MM {
            return Err(Error::parameter(
                format!("{key}.extent_mm"),
                format!(
                    "must be at most {MAX_EXTENT_MM:e} mm, got {}",
                    shown(self.extent_mm)
                ),
            ));
        }
        let non_negative = [
            ("groove_depth_um", self.groove_depth_um),
            ("pore_density_per_mm2", self.pore_density_per_mm2),
            ("pore_depth_um", self.pore_depth_um),
            ("noise_amplitude_um", self.noise_amplitude_um),
        ];
        for (name, v) in non_negative {
            if !(v.is_finite() && v >= 0.0) {
                return Err(Error::parameter(
                    format!("{key}.{name}"),
                    format!("must be finite and ≥ 0, got {}", shown(v)),
                ));
            }
            let most = if name == "pore_density_per_mm2" {
                MAX_PORES_PER_MM2
            } else {
                MAX_DEPTH_UM
            };
            if v > most {
                return Err(Error::parameter(
                    format!("{key}.{name}"),
                    format!("must be at most {most:e}, got {}", shown(v)),
                ));
            }
        }
        for (name, v) in [
            ("depth_spread", self.depth_spread),
            ("orientation_spread", self.orientation_spread),
        ] {
            if !(0.0..=1.0).contains(&v) {
                return Err(Error::parameter(
                    format!("{key}.{name}"),
                    format!("must be in [0, 1], got {v}"),
                ));
            }
        }
        Ok(())
    }

    /// Texel side (µm).
    pub fn texel_um(&self) -> f64 {
        self.extent_mm * 1000.0 / self.size_px as f64
    }
}

/// A 64-bit mix (splitmix64 finaliser); also the synthesis's random starts.
pub(crate) fn mix(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// A uniform number in [0, 1) from (seed, layer, a, b, k).
fn uniform(seed: u64, layer: u64, a: i64, b: i64, k: u64) -> f64 {
    let h = mix(seed ^ mix(layer ^ mix(a as u64 ^ mix(b as u64 ^ mix(k)))));
    (h >> 11) as f64 / (1u64 << 53) as f64
}

/// A periodic jittered lattice of `n[0] × n[1]` cells over the map.
struct Lattice {
    n: [i64; 2],
    layer: u64,
    seed: u64,
}

impl Lattice {
    /// Cell centre of lattice cell (a, b) (wrapped), in cell units.
    fn centre(&self, a: i64, b: i64) -> [f64; 2] {
        let (wa, wb) = (a.rem_euclid(self.n[0]), b.rem_euclid(self.n[1]));
        [
            a as f64 + 0.1 + 0.8 * uniform(self.seed, self.layer, wa, wb, 0),
            b as f64 + 0.1 + 0.8 * uniform(self.seed, self.layer, wa, wb, 1),
        ]
    }

    /// Distance (cell units, x and y scaled by `scale`) from `p` to the
    /// border of its Voronoi cell, and a per-border random number.
    fn border(&self, p: [f64; 2], scale: [f64; 2]) -> (f64, f64) {
        let (ca, cb) = (p[0].floor() as i64, p[1].floor() as i64);
        let mut best = [(f64::INFINITY, 0i64, 0i64, [0.0; 2]); 2];
        // Cells are up to 3× longer along u than along v: search further in v.
        for b in cb - 3..=cb + 3 {
            for a in ca - 2..=ca + 2 {
                let c = self.centre(a, b);
                let d = [(p[0] - c[0]) * scale[0], (p[1] - c[1]) * scale[1]];
                let d2 = d[0] * d[0] + d[1] * d[1];
                if d2 < best[0].0 {
                    best[1] = best[0];
                    best[0] = (d2, a, b, c);
                } else if d2 < best[1].0 {
                    best[1] = (d2, a, b, c);
                }
            }
        }
        let (c1, c2) = (best[0].3, best[1].3);
        let sep = [(c2[0] - c1[0]) * scale[0], (c2[1] - c1[1]) * scale[1]];
        let dist = (best[1].0 - best[0].0) / (2.0 * (sep[0] * sep[0] + sep[1] * sep[1]).sqrt());
        // The border's random number: symmetric in the two (wrapped) cells.
        let key = |a: i64, b: i64| a.rem_euclid(self.n[0]) + self.n[0] * b.rem_euclid(self.n[1]);
        let (k1, k2) = (key(best[0].1, best[0].2), key(best[1].1, best[1].2));
        let r = uniform(self.seed, self.layer + 100, k1.min(k2), k1.max(k2), 2);
        (dist, r)
    }
}

/// Generates a neutral skin map.
pub fn generate(p: &SkinParams) -> Result<DisplacementMap> {
    p.validate("microstructure.procedural")?;
    let size = p.size_px;
    let extent_um = p.extent_mm * 1000.0;
    let elongation = 1.0 + 2.0 * (1.0 - p.orientation_spread);
    // Cells per side: spacing·√e along u, spacing/√e along v.
    let cells =
        |spacing: f64, stretch: f64| ((extent_um / (spacing * stretch)).round() as i64).max(1);
    let networks: Vec<(Lattice, [f64; 2], f64, f64)> = [(0u64, 1.0), (1, 1.0 / 3.0)]
        .into_iter()
        .map(|(layer, k)| {
            let spacing = p.groove_spacing_um * k;
            let n = [
                cells(spacing, elongation.sqrt()),
                cells(spacing, 1.0 / elongation.sqrt()),
            ];
            // Scale from cell units to µm along each axis.
            let scale = [extent_um / n[0] as f64, extent_um / n[1] as f64];
            let lattice = Lattice {
                n,
                layer,
                seed: p.seed,
            };
            (
                lattice,
                scale,
                p.groove_depth_um * k,
                p.groove_width_um * k.sqrt(),
            )
        })
        .collect();
    let pore_cells = ((p.pore_density_per_mm2.max(1e-9) * p.extent_mm * p.extent_mm)
        .sqrt()
        .round() as i64)
        .max(1);
    let pore_lattice = Lattice {
        n: [pore_cells, pore_cells],
        layer: 7,
        seed: p.seed,
    };
    let pore_cell_um = extent_um / pore_cells as f64;
    let pore_probability = (p.pore_density_per_mm2 * (pore_cell_um * 1e-3).powi(2)).min(1.0);
    let fbm: Fbm<Perlin> = Fbm::<Perlin>::new((p.seed & 0xffff_ffff) as u32).set_octaves(4);
    let torus_radius = extent_um / (std::f64::consts::TAU * p.noise_scale_um);
    let texel = p.texel_um();
    let map = DisplacementMap::from_fn(size, size, texel, Edge::Wrap, |i, j| {
        let x = (i as f64 + 0.5) * texel;
        let y = (j as f64 + 0.5) * texel;
        let mut h = 0.0;
        for (lattice, scale, depth, width) in &networks {
            let q = [x / scale[0], y / scale[1]];
            let (d, r) = lattice.border(q, *scale);
            let depth = depth * (1.0 + p.depth_spread * (2.0 * r - 1.0));
            h -= depth * (-(d / width) * (d / width)).exp();
        }
        // Pores: the nearest jittered lattice point, if that cell has one.
        let q = [x / pore_cell_um, y / pore_cell_um];
        let (ca, cb) = (q[0].floor() as i64, q[1].floor() as i64);
        for b in cb - 1..=cb + 1 {
            for a in ca - 1..=ca + 1 {
                let (wa, wb) = (a.rem_euclid(pore_cells), b.rem_euclid(pore_cells));
                if uniform(p.seed, 9, wa, wb, 3) >= pore_probability {
                    continue;
                }
                let c = pore_lattice.centre(a, b);
                let d2 =
                    ((q[0] - c[0]).powi(2) + (q[1] - c[1]).powi(2)) * pore_cell_um * pore_cell_um;
                h -= p.pore_depth_um * (-d2 / (p.pore_radius_um * p.pore_radius_um)).exp();
            }
        }
        let (su, cu) = (std::f64::consts::TAU * x / extent_um).sin_cos();
        let (sv, cv) = (std::f64::consts::TAU * y / extent_um).sin_cos();
        let r = torus_radius;
        h += p.noise_amplitude_um * fbm.get([r * cu, r * su, r * cv, r * sv]);
        h as f32
    });
    if let Some(k) = map.data.iter().position(|h| !h.is_finite()) {
        return Err(Error::parameter(
            "microstructure.procedural",
            format!(
                "the generated map has a non-finite height at texel ({}, {}); the parameters \
                 are out of the range the generator can represent",
                k % size,
                k / size
            ),
        ));
    }
    Ok(map)
}
