//! Tetrahedral meshes of the skin patch.
//!
//! A [`TetMesh`] is the validated, plain-data form every later stage consumes:
//! vertex positions in millimetres, positively oriented linear tetrahedra, a
//! region id per tetrahedron (one region per tissue layer), the boundary
//! faces with their markers, and the top (skin) surface with its UV layout.
//!
//! Every source of meshes — TetGen generation ([`generate`]), TetGen and Gmsh
//! files ([`io`]) — produces a [`RawMesh`], and [`TetMesh::from_raw`] is the
//! one place where a raw mesh is checked and completed:
//!
//! * coordinates are finite, indices in range and distinct within a tet;
//! * no tet is degenerate: `|6V| > 1e-10·ℓ³` with ℓ its longest edge;
//! * all tets share one orientation. A mesh whose tets are *all* negatively
//!   oriented is a convention difference and is flipped (swap of the last two
//!   vertices); a mesh with mixed signs has inverted elements and is rejected;
//! * no triangle is shared by more than two tets;
//! * every named region owns at least one tet.
//!
//! Vertex positions follow the project's convention: z up, skin surface at the top (largest z).

pub mod generate;
pub mod io;
pub mod order;
pub mod quality;
mod surface;

use std::collections::{BTreeMap, HashMap};

use nalgebra::Vector3;

pub use quality::QualityReport;
pub use surface::TopSurface;

use crate::error::{Error, Result};

/// A point or vector in model space (millimetres).
pub type Vec3 = Vector3<f64>;

/// Boundary face markers written by the generator (and read back from `.face` files).
///
/// TetGen gives every boundary face the marker 1 when no markers are supplied,
/// so the generator avoids 0 and 1 for named sides.
pub mod markers {
    /// An unmarked face.
    pub const NONE: i32 = 0;
    /// The top (skin) surface, z = 0.
    pub const TOP: i32 = 2;
    /// The bottom surface of the patch, usually fixed.
    pub const BOTTOM: i32 = 3;
    /// The side at minimum x.
    pub const X_MIN: i32 = 4;
    /// The side at maximum x.
    pub const X_MAX: i32 = 5;
    /// The side at minimum y.
    pub const Y_MIN: i32 = 6;
    /// The side at maximum y.
    pub const Y_MAX: i32 = 7;

    /// A human-readable name of a generator marker, if it is one.
    pub fn name(marker: i32) -> Option<&'static str> {
        Some(match marker {
            TOP => "top",
            BOTTOM => "bottom",
            X_MIN => "x_min",
            X_MAX => "x_max",
            Y_MIN => "y_min",
            Y_MAX => "y_max",
            _ => return None,
        })
    }
}

/// A tissue region: a set of tets sharing one material.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Region {
    /// Region id as stored per tet (TetGen attribute, Gmsh physical tag).
    pub id: i32,
    /// Name used by scenario sections such as `[material.<name>]`.
    pub name: String,
}

/// A triangle on the boundary of the tetrahedral mesh.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct BoundaryFace {
    /// Vertex indices, counter-clockwise seen from outside (outward normal).
    pub nodes: [usize; 3],
    /// Boundary marker (see [`markers`]); 0 when the source had none.
    pub marker: i32,
    /// The tet this face belongs to.
    pub tet: usize,
}

/// A mesh as read or generated, before validation.
#[derive(Clone, Debug, Default)]
pub struct RawMesh {
    /// Vertex positions (mm).
    pub positions: Vec<Vec3>,
    /// Four vertex indices per tet, either orientation.
    pub tets: Vec<[usize; 4]>,
    /// Region id per tet.
    pub tet_region: Vec<i32>,
    /// Names of region ids; ids without a name are called `region_<id>`.
    pub region_names: BTreeMap<i32, String>,
    /// Markers of boundary faces, keyed by their sorted vertex indices.
    pub face_markers: HashMap<[usize; 3], i32>,
}

/// A validated tetrahedral mesh with its top surface. See the module docs.
#[derive(Clone, Debug)]
pub struct TetMesh {
    /// Vertex positions at rest (mm).
    pub positions: Vec<Vec3>,
    /// Tets with positive signed volume `det[x1−x0, x2−x0, x3−x0] / 6`.
    pub tets: Vec<[usize; 4]>,
    /// Region id of each tet.
    pub tet_region: Vec<i32>,
    /// All regions, sorted by id; each owns at least one tet.
    pub regions: Vec<Region>,
    /// Boundary faces, outward oriented, in a deterministic order.
    pub boundary: Vec<BoundaryFace>,
    /// The top (skin) surface with UVs; empty when the mesh has none.
    pub top: TopSurface,
}

/// Signed volume of the tet (a, b, c, d): `det[b−a, c−a, d−a] / 6`.
pub fn signed_volume(a: &Vec3, b: &Vec3, c: &Vec3, d: &Vec3) -> f64 {
    (b - a).cross(&(c - a)).dot(&(d - a)) / 6.0
}

/// The four faces of a positively oriented tet, each counter-clockwise seen
/// from outside, as local vertex indices (face `i` is opposite vertex `i`).
pub const TET_FACES: [[usize; 3]; 4] = [[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]];

/// Sorted copy of a triangle's vertex indices: the key of a face.
pub fn face_key(mut f: [usize; 3]) -> [usize; 3] {
    f.sort_unstable();
    f
}

impl TetMesh {
    /// Validates and completes a raw mesh. `origin` names its source in errors.
    pub fn from_raw(origin: &str, raw: RawMesh) -> Result<TetMesh> {
        let bad = |message: String| Error::InvalidMesh {
            origin: origin.to_string(),
            message,
        };
        let RawMesh {
            positions,
            mut tets,
            tet_region,
            region_names,
            face_markers,
        } = raw;
        if tets.is_empty() {
            return Err(bad("the mesh has no tetrahedra".into()));
        }
        if tet_region.len() != tets.len() {
            return Err(bad(format!(
                "{} region ids for {} tetrahedra",
                tet_region.len(),
                tets.len()
            )));
        }
        if let Some(i) = positions
            .iter()
            .position(|p| !p.iter().all(|c| c.is_finite()))
        {
            return Err(bad(format!(
                "vertex {i} has a non-finite coordinate {:?}",
                positions[i].as_slice()
            )));
        }
        check_indices(&tets, positions.len()).map_err(bad)?;
        orient(origin, &positions, &mut tets).map_err(bad)?;
        let regions = collect_regions(&tet_region, region_names).map_err(bad)?;
        let (mut positions, mut face_markers) = (positions, face_markers);
        drop_unused_vertices(&mut positions, &mut tets, &mut face_markers);
        let boundary = surface::boundary_faces(&tets, &face_markers).map_err(bad)?;
        let top = TopSurface::extract(&positions, &boundary).map_err(bad)?;
        if top.is_empty() {
            log::warn!(
                "{origin}: no top surface (no boundary face marked {} and none facing +z at \
                 the highest z); the FEM runs, but a probe, strain maps, the microstructure \
                 and rendering need one",
                markers::TOP
            );
        }
        Ok(TetMesh {
            positions,
            tets,
            tet_region,
            regions,
            boundary,
            top,
        })
    }

    /// Number of tets.
    pub fn num_tets(&self) -> usize {
        self.tets.len()
    }

    /// Number of vertices.
    pub fn num_vertices(&self) -> usize {
        self.positions.len()
    }

    /// The four rest positions of tet `t`.
    pub fn tet_points(&self, t: usize) -> [Vec3; 4] {
        self.tets[t].map(|v| self.positions[v])
    }

    /// Signed (positive) rest volume of tet `t` (mm³).
    pub fn tet_volume(&self, t: usize) -> f64 {
        let [a, b, c, d] = self.tet_points(t);
        signed_volume(&a, &b, &c, &d)
    }

    /// Centroid of tet `t`.
    pub fn tet_centroid(&self, t: usize) -> Vec3 {
        let [a, b, c, d] = self.tet_points(t);
        (a + b + c + d) / 4.0
    }

    /// Total volume, summed in index order (deterministic).
    pub fn total_volume(&self) -> f64 {
        (0..self.num_tets()).map(|t| self.tet_volume(t)).sum()
    }

    /// Axis-aligned bounding box `(min, max)` of all vertices.
    pub fn bounds(&self) -> (Vec3, Vec3) {
        bounds(&self.positions)
    }

    /// The region named `name`, if any.
    pub fn region_by_name(&self, name: &str) -> Option<&Region> {
        self.regions.iter().find(|r| r.name == name)
    }

    /// Number of tets in each region, in the order of [`TetMesh::regions`].
    pub fn region_tet_counts(&self) -> Vec<usize> {
        self.regions
            .iter()
            .map(|r| self.tet_region.iter().filter(|&&id| id == r.id).count())
            .collect()
    }

    /// Checks that the boundary is a closed, consistently oriented 2-manifold:
    /// every boundary edge is used by exactly two boundary faces, once in each
    /// direction. Returns a description of the first offending edge otherwise.
    pub fn check_closed_manifold(&self) -> std::result::Result<(), String> {
        surface::check_closed_manifold(&self.boundary)
    }

    /// The Euler characteristic V − E + F of the boundary surface (2 for a
    /// surface of genus 0 such as a box).
    pub fn boundary_euler_characteristic(&self) -> i64 {
        surface::euler_characteristic(&self.boundary)
    }
}

/// Axis-aligned bounding box of a point set; `(+∞, −∞)` for an empty set.
pub fn bounds(points: &[Vec3]) -> (Vec3, Vec3) {
    let mut lo = Vec3::repeat(f64::INFINITY);
    let mut hi = Vec3::repeat(f64::NEG_INFINITY);
    for p in points {
        lo = lo.inf(p);
        hi = hi.sup(p);
    }
    (lo, hi)
}

fn check_indices(tets: &[[usize; 4]], num_vertices: usize) -> std::result::Result<(), String> {
    for (t, tet) in tets.iter().enumerate() {
        if let Some(&v) = tet.iter().find(|&&v| v >= num_vertices) {
            return Err(format!(
                "tet {t} refers to vertex {v}, but there are only {num_vertices} vertices"
            ));
        }
        for i in 0..4 {
            for j in i + 1..4 {
                if tet[i] == tet[j] {
                    return Err(format!("tet {t} repeats vertex {} ({tet:?})", tet[i]));
                }
            }
        }
    }
    Ok(())
}

/// Makes every tet positively oriented; rejects degenerate and inverted tets.
fn orient(
    origin: &str,
    positions: &[Vec3],
    tets: &mut [[usize; 4]],
) -> std::result::Result<(), String> {
    let mut signs = Vec::with_capacity(tets.len());
    for (t, tet) in tets.iter().enumerate() {
        let [a, b, c, d] = tet.map(|v| positions[v]);
        let v6 = 6.0 * signed_volume(&a, &b, &c, &d);
        let longest = [b - a, c - a, d - a, c - b, d - b, d - c]
            .iter()
            .map(|e| e.norm())
            .fold(0.0, f64::max);
        if v6.is_nan() || v6.abs() <= 1e-10 * longest.powi(3) {
            return Err(format!(
                "tet {t} is degenerate (volume {:.3e} mm³, longest edge {longest:.3e} mm)",
                v6 / 6.0
            ));
        }
        signs.push(v6 > 0.0);
    }
    let positive = signs.iter().filter(|&&s| s).count();
    let negative = signs.len() - positive;
    if positive > 0 && negative > 0 {
        let majority = positive >= negative;
        let t = signs.iter().position(|&s| s != majority).unwrap_or(0);
        return Err(format!(
            "tet {t} is inverted: {positive} tets are positively and {negative} negatively oriented"
        ));
    }
    if negative > 0 {
        log::warn!("{origin}: all {negative} tets are negatively oriented (the opposite vertex order); flipping them");
        for tet in tets.iter_mut() {
            tet.swap(2, 3);
        }
    }
    Ok(())
}

fn collect_regions(
    tet_region: &[i32],
    mut names: BTreeMap<i32, String>,
) -> std::result::Result<Vec<Region>, String> {
    let mut counts: BTreeMap<i32, usize> = BTreeMap::new();
    for &id in tet_region {
        *counts.entry(id).or_default() += 1;
    }
    if let Some((id, name)) = names.iter().find(|(id, _)| !counts.contains_key(id)) {
        return Err(format!("region '{name}' (id {id}) has no tetrahedra"));
    }
    let regions: Vec<Region> = counts
        .keys()
        .map(|&id| Region {
            id,
            name: names.remove(&id).unwrap_or_else(|| format!("region_{id}")),
        })
        .collect();
    let mut seen = BTreeMap::new();
    for r in &regions {
        if let Some(other) = seen.insert(r.name.clone(), r.id) {
            return Err(format!(
                "regions {other} and {} share the name '{}'",
                r.id, r.name
            ));
        }
    }
    Ok(regions)
}

/// Removes vertices that no tet uses and renumbers the rest in order.
fn drop_unused_vertices(
    positions: &mut Vec<Vec3>,
    tets: &mut [[usize; 4]],
    face_markers: &mut HashMap<[usize; 3], i32>,
) {
    let mut used = vec![false; positions.len()];
    for tet in tets.iter() {
        for &v in tet {
            used[v] = true;
        }
    }
    let unused = used.iter().filter(|&&u| !u).count();
    if unused == 0 {
        return;
    }
    log::warn!("dropping {unused} vertices that belong to no tetrahedron");
    let mut new_index = vec![usize::MAX; positions.len()];
    let mut kept = 0;
    for (i, &u) in used.iter().enumerate() {
        if u {
            new_index[i] = kept;
            positions[kept] = positions[i];
            kept += 1;
        }
    }
    positions.truncate(kept);
    for tet in tets.iter_mut() {
        *tet = tet.map(|v| new_index[v]);
    }
    *face_markers = std::mem::take(face_markers)
        .into_iter()
        .filter(|(k, _)| k.iter().all(|&v| v < used.len() && used[v]))
        .map(|(k, m)| (face_key(k.map(|v| new_index[v])), m))
        .collect();
}
