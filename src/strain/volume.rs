//! How much of its volume each region of the mesh has lost or gained in a
//! frame, and its most compressed tets: skin and fat are nearly
//! incompressible, so a region whose volume drops by more than a few
//! percent, or a tet squeezed to half its volume, points at a material
//! model (or a Poisson ratio) that lets tissue compress more than it can.

use crate::mesh::{signed_volume, TetMesh, Vec3};

/// One region's volume in a frame.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct RegionVolume {
    /// The region's name (as in `[material.<name>]`).
    pub name: String,
    /// Volume at rest (mm³).
    pub rest_mm3: f64,
    /// Volume in the frame (mm³; signed volumes summed, so an inverted tet
    /// subtracts).
    pub deformed_mm3: f64,
    /// Smallest volume ratio J = det F of the region's tets.
    pub min_volume_ratio: f64,
    /// Tets of the region whose volume ratio is below the run's warning
    /// threshold.
    pub tets_below: usize,
}

impl RegionVolume {
    /// Relative volume change `V/V₀ − 1` (negative: lost volume).
    pub fn change(&self) -> f64 {
        self.deformed_mm3 / self.rest_mm3 - 1.0
    }
}

/// Each region's volume at positions `x`, in the order of `mesh.regions`,
/// counting tets whose volume ratio is below `threshold`. Sums run in tet
/// order, so the result has the same bits on every run.
pub fn region_volumes(mesh: &TetMesh, x: &[Vec3], threshold: f64) -> Vec<RegionVolume> {
    let mut out: Vec<RegionVolume> = mesh
        .regions
        .iter()
        .map(|r| RegionVolume {
            name: r.name.clone(),
            rest_mm3: 0.0,
            deformed_mm3: 0.0,
            min_volume_ratio: f64::INFINITY,
            tets_below: 0,
        })
        .collect();
    for (tet, &id) in mesh.tets.iter().zip(&mesh.tet_region) {
        // Regions are sorted by id and own every tet's id.
        let Ok(k) = mesh.regions.binary_search_by_key(&id, |r| r.id) else {
            continue;
        };
        let [a, b, c, d] = tet.map(|v| mesh.positions[v]);
        let rest = signed_volume(&a, &b, &c, &d);
        let [a, b, c, d] = tet.map(|v| x[v]);
        let now = signed_volume(&a, &b, &c, &d);
        let j = now / rest;
        let r = &mut out[k];
        r.rest_mm3 += rest;
        r.deformed_mm3 += now;
        // A non-finite ratio is the worst there is.
        r.min_volume_ratio = if j.is_nan() || r.min_volume_ratio.is_nan() {
            f64::NAN
        } else {
            r.min_volume_ratio.min(j)
        };
        r.tets_below += usize::from(j < threshold || j.is_nan());
    }
    out
}

/// A column name made of a region name: characters other than ASCII
/// letters, digits and `_` become `_`, so the CSV header needs no quoting.
pub fn column_name(region: &str) -> String {
    region
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '_' {
                c
            } else {
                '_'
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::Region;

    /// Two unit-cube halves (regions 1 and 2) of six tets each.
    fn two_regions() -> TetMesh {
        let mut positions = Vec::new();
        for z in 0..2 {
            for y in 0..2 {
                for x in 0..3 {
                    positions.push(Vec3::new(x as f64, y as f64, z as f64));
                }
            }
        }
        let idx = |x: usize, y: usize, z: usize| x + 3 * (y + 2 * z);
        let mut tets = Vec::new();
        let mut tet_region = Vec::new();
        for cx in 0..2 {
            let c = |dx: usize, dy: usize, dz: usize| idx(cx + dx, dy, dz);
            // Six tets around the cube diagonal (0,0,0)–(1,1,1), all positive.
            let (v0, v7) = (c(0, 0, 0), c(1, 1, 1));
            for [p, q] in [
                [c(1, 0, 0), c(1, 1, 0)],
                [c(1, 1, 0), c(0, 1, 0)],
                [c(0, 1, 0), c(0, 1, 1)],
                [c(0, 1, 1), c(0, 0, 1)],
                [c(0, 0, 1), c(1, 0, 1)],
                [c(1, 0, 1), c(1, 0, 0)],
            ] {
                tets.push([v0, p, q, v7]);
                tet_region.push(cx as i32 + 1);
            }
        }
        let regions = ["left", "right half"]
            .iter()
            .enumerate()
            .map(|(k, n)| Region {
                id: k as i32 + 1,
                name: n.to_string(),
            })
            .collect();
        TetMesh {
            positions,
            tets,
            tet_region,
            regions,
            boundary: Vec::new(),
            top: Default::default(),
        }
    }

    #[test]
    fn volumes_follow_a_uniform_squeeze_per_region() {
        let mesh = two_regions();
        for (t, tet) in mesh.tets.iter().enumerate() {
            let [a, b, c, d] = tet.map(|v| mesh.positions[v]);
            assert!(signed_volume(&a, &b, &c, &d) > 0.0, "tet {t}");
        }
        // Squeeze z by 0.6 where x > 1 (the right cube's far face only):
        // the right region shrinks, the left keeps its volume.
        let x: Vec<Vec3> = mesh
            .positions
            .iter()
            .map(|p| Vec3::new(p.x, p.y, if p.x > 1.5 { 0.6 * p.z } else { p.z }))
            .collect();
        let v = region_volumes(&mesh, &x, 0.5);
        assert_eq!(v[0].name, "left");
        assert!((v[0].rest_mm3 - 1.0).abs() < 1e-15 && v[0].change().abs() < 1e-15);
        assert!((v[0].min_volume_ratio - 1.0).abs() < 1e-15 && v[0].tets_below == 0);
        // The right cube: a linear taper from 1 to 0.6 in z, mean height 0.8.
        assert!(
            (v[1].deformed_mm3 - 0.8).abs() < 1e-14,
            "{}",
            v[1].deformed_mm3
        );
        assert!((v[1].change() + 0.2).abs() < 1e-14);
        assert!(v[1].min_volume_ratio < 0.8 && v[1].min_volume_ratio >= 0.6 - 1e-12);
        let strict = region_volumes(&mesh, &x, 0.99);
        assert_eq!(strict[0].tets_below, 0);
        assert!(strict[1].tets_below > 0);
        assert_eq!(column_name(&v[1].name), "right_half");
    }

    #[test]
    fn a_non_finite_position_is_reported_not_hidden() {
        let mesh = two_regions();
        let mut x = mesh.positions.clone();
        x[mesh.tets[7][1]].z = f64::NAN;
        let v = region_volumes(&mesh, &x, 0.5);
        assert!(v[1].min_volume_ratio.is_nan() && v[1].tets_below > 0);
        assert!(v[0].min_volume_ratio == 1.0);
    }
}
