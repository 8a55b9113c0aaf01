//! Element quality measures and the mesh quality report.
//!
//! * Dihedral angles: the six angles between pairs of faces, each π minus the
//!   angle between the two outward face normals (a regular tet has 70.53°).
//! * Radius–edge ratio: circumradius over shortest edge (√6/4 ≈ 0.612 for a
//!   regular tet); TetGen's `-q` bound limits it during refinement.

use std::fmt;

use super::{TetMesh, Vec3, TET_FACES};

/// Summary statistics of a mesh, printed by `skinpatch mesh`.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct QualityReport {
    /// Number of tets.
    pub tets: usize,
    /// Number of vertices.
    pub vertices: usize,
    /// Number of boundary triangles.
    pub boundary_faces: usize,
    /// Number of top-surface triangles.
    pub top_triangles: usize,
    /// Smallest tet volume (mm³).
    pub min_volume_mm3: f64,
    /// Largest tet volume (mm³).
    pub max_volume_mm3: f64,
    /// Sum of tet volumes (mm³).
    pub total_volume_mm3: f64,
    /// Shortest edge (mm).
    pub min_edge_mm: f64,
    /// Longest edge (mm).
    pub max_edge_mm: f64,
    /// Smallest dihedral angle over all tets (degrees).
    pub min_dihedral_deg: f64,
    /// Largest dihedral angle over all tets (degrees).
    pub max_dihedral_deg: f64,
    /// Largest radius–edge ratio over all tets.
    pub max_radius_edge: f64,
    /// Per region: (name, id, tet count, volume in mm³).
    pub regions: Vec<(String, i32, usize, f64)>,
}

/// The six dihedral angles of a tet, in radians.
pub fn dihedral_angles(p: &[Vec3; 4]) -> [f64; 6] {
    let normals = TET_FACES.map(|[a, b, c]| (p[b] - p[a]).cross(&(p[c] - p[a])).normalize());
    let mut out = [0.0; 6];
    let mut k = 0;
    for i in 0..4 {
        for j in i + 1..4 {
            let cos = normals[i].dot(&normals[j]).clamp(-1.0, 1.0);
            out[k] = std::f64::consts::PI - cos.acos();
            k += 1;
        }
    }
    out
}

/// Lengths of the six edges of a tet.
pub fn edge_lengths(p: &[Vec3; 4]) -> [f64; 6] {
    [
        (p[1] - p[0]).norm(),
        (p[2] - p[0]).norm(),
        (p[3] - p[0]).norm(),
        (p[2] - p[1]).norm(),
        (p[3] - p[1]).norm(),
        (p[3] - p[2]).norm(),
    ]
}

/// Circumradius of a tet.
pub fn circumradius(p: &[Vec3; 4]) -> f64 {
    let (a, b, c) = (p[1] - p[0], p[2] - p[0], p[3] - p[0]);
    let det = a.dot(&b.cross(&c));
    let centre = (a.norm_squared() * b.cross(&c)
        + b.norm_squared() * c.cross(&a)
        + c.norm_squared() * a.cross(&b))
        / (2.0 * det);
    centre.norm()
}

/// Circumradius over shortest edge.
pub fn radius_edge_ratio(p: &[Vec3; 4]) -> f64 {
    let shortest = edge_lengths(p).into_iter().fold(f64::INFINITY, f64::min);
    circumradius(p) / shortest
}

impl QualityReport {
    /// Computes the report of a mesh (serially, so figures are reproducible).
    pub fn of(mesh: &TetMesh) -> QualityReport {
        let mut r = QualityReport {
            tets: mesh.num_tets(),
            vertices: mesh.num_vertices(),
            boundary_faces: mesh.boundary.len(),
            top_triangles: mesh.top.triangles.len(),
            min_volume_mm3: f64::INFINITY,
            max_volume_mm3: 0.0,
            total_volume_mm3: 0.0,
            min_edge_mm: f64::INFINITY,
            max_edge_mm: 0.0,
            min_dihedral_deg: 180.0,
            max_dihedral_deg: 0.0,
            max_radius_edge: 0.0,
            regions: Vec::new(),
        };
        let mut region_volume = vec![0.0; mesh.regions.len()];
        for t in 0..mesh.num_tets() {
            let p = mesh.tet_points(t);
            let v = mesh.tet_volume(t);
            r.min_volume_mm3 = r.min_volume_mm3.min(v);
            r.max_volume_mm3 = r.max_volume_mm3.max(v);
            r.total_volume_mm3 += v;
            for e in edge_lengths(&p) {
                r.min_edge_mm = r.min_edge_mm.min(e);
                r.max_edge_mm = r.max_edge_mm.max(e);
            }
            for a in dihedral_angles(&p) {
                r.min_dihedral_deg = r.min_dihedral_deg.min(a.to_degrees());
                r.max_dihedral_deg = r.max_dihedral_deg.max(a.to_degrees());
            }
            r.max_radius_edge = r.max_radius_edge.max(radius_edge_ratio(&p));
            if let Some(k) = mesh.regions.iter().position(|g| g.id == mesh.tet_region[t]) {
                region_volume[k] += v;
            }
        }
        r.regions = mesh
            .regions
            .iter()
            .zip(mesh.region_tet_counts())
            .zip(region_volume)
            .map(|((g, n), v)| (g.name.clone(), g.id, n, v))
            .collect();
        r
    }
}

impl fmt::Display for QualityReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(
            f,
            "tets {}  vertices {}  boundary faces {}  top triangles {}",
            self.tets, self.vertices, self.boundary_faces, self.top_triangles
        )?;
        writeln!(
            f,
            "volume: total {:.6} mm³, per tet min {:.3e} max {:.3e} mm³",
            self.total_volume_mm3, self.min_volume_mm3, self.max_volume_mm3
        )?;
        writeln!(
            f,
            "edges: min {:.4} max {:.4} mm",
            self.min_edge_mm, self.max_edge_mm
        )?;
        writeln!(
            f,
            "dihedral angles: min {:.2}° max {:.2}°   max radius-edge ratio {:.3}",
            self.min_dihedral_deg, self.max_dihedral_deg, self.max_radius_edge
        )?;
        for (name, id, n, v) in &self.regions {
            writeln!(f, "region {name} (id {id}): {n} tets, {v:.6} mm³")?;
        }
        Ok(())
    }
}

/// Longest edge among the tets that have a vertex within `radius` of `centre`
/// (mm), and how many such tets there are: a check of local resolution.
pub fn max_edge_within(mesh: &TetMesh, centre: &Vec3, radius: f64) -> (f64, usize) {
    let mut longest: f64 = 0.0;
    let mut count = 0;
    for t in 0..mesh.num_tets() {
        let p = mesh.tet_points(t);
        if p.iter().any(|q| (q - centre).norm() <= radius) {
            count += 1;
            longest = edge_lengths(&p).into_iter().fold(longest, f64::max);
        }
    }
    (longest, count)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn regular() -> [Vec3; 4] {
        [
            Vec3::new(1.0, 1.0, 1.0),
            Vec3::new(1.0, -1.0, -1.0),
            Vec3::new(-1.0, 1.0, -1.0),
            Vec3::new(-1.0, -1.0, 1.0),
        ]
    }

    #[test]
    fn regular_tet_measures() {
        let p = regular();
        let expected = (1.0f64 / 3.0).acos();
        for a in dihedral_angles(&p) {
            assert!((a - expected).abs() < 1e-12, "{a} vs {expected}");
        }
        assert!((radius_edge_ratio(&p) - 6f64.sqrt() / 4.0).abs() < 1e-12);
        assert!((circumradius(&p) - 3f64.sqrt()).abs() < 1e-12);
    }

    #[test]
    fn right_corner_tet_has_right_dihedral_angles() {
        let p = [Vec3::zeros(), Vec3::x(), Vec3::y(), Vec3::z()];
        let mut a = dihedral_angles(&p).map(f64::to_degrees);
        a.sort_by(f64::total_cmp);
        // Three 90° angles at the corner edges, three of atan(√2) at the slanted face.
        let slanted = 2f64.sqrt().atan().to_degrees();
        for (got, want) in a.iter().zip([slanted, slanted, slanted, 90.0, 90.0, 90.0]) {
            assert!((got - want).abs() < 1e-9, "{got} vs {want}");
        }
    }
}
