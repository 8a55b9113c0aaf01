//! Boundary extraction and the top (skin) surface with its UV layout.
//!
//! A boundary face is a tet face that no other tet shares. The top surface is
//! the set of boundary faces marked [`markers::TOP`]; a mesh without such
//! markers (e.g. a Gmsh file) uses the boundary faces that face +z and lie at
//! the highest z instead. UVs follow the project's convention: `u = (x − x_min)/width`,
//! `v = (y − y_min)/depth` over the top surface's rest bounding box.

use std::collections::HashMap;

use super::{bounds, face_key, markers, BoundaryFace, Vec3, TET_FACES};

/// The top surface of a mesh: the triangles the microstructure lives on.
#[derive(Clone, Debug, Default)]
pub struct TopSurface {
    /// Mesh vertex index of each surface vertex: ascending for a tet mesh's
    /// top; for a surface from another tool ([`TopSurface::from_layout`])
    /// one surface vertex per (position, UV) pair, so a position on a UV
    /// seam has several surface vertices.
    pub vertices: Vec<usize>,
    /// Triangles as surface-vertex indices, counter-clockwise seen from above.
    pub triangles: Vec<[usize; 3]>,
    /// Rest UV coordinates of each surface vertex, in [0, 1]².
    pub uvs: Vec<[f64; 2]>,
    /// The tet owning each triangle.
    pub face_tet: Vec<usize>,
    /// Index into `TetMesh::boundary` of each triangle.
    pub boundary_face: Vec<usize>,
    mesh_to_surface: HashMap<usize, usize>,
}

impl TopSurface {
    /// Whether the mesh has no top surface (no boundary face marked top and
    /// none facing +z at the highest z). The FEM runs on such a mesh; the
    /// stages that work on the skin surface refuse it.
    pub fn is_empty(&self) -> bool {
        self.triangles.is_empty()
    }

    /// The surface vertex of mesh vertex `v`, if `v` lies on the top surface
    /// (the first one where a seam gives it several).
    pub fn surface_vertex(&self, v: usize) -> Option<usize> {
        self.mesh_to_surface.get(&v).copied()
    }

    /// A surface of any UV layout: `vertices[s]` is the position index of
    /// surface vertex `s`, `triangles` index surface vertices and `uvs` are
    /// per surface vertex (charts, seams and UVs outside the unit square
    /// allowed). It has no owning tets (`face_tet`, `boundary_face` empty).
    pub fn from_layout(
        vertices: Vec<usize>,
        triangles: Vec<[usize; 3]>,
        uvs: Vec<[f64; 2]>,
    ) -> TopSurface {
        debug_assert_eq!(vertices.len(), uvs.len());
        let mut mesh_to_surface = HashMap::with_capacity(vertices.len());
        for (s, &v) in vertices.iter().enumerate() {
            mesh_to_surface.entry(v).or_insert(s);
        }
        TopSurface {
            vertices,
            triangles,
            uvs,
            face_tet: Vec::new(),
            boundary_face: Vec::new(),
            mesh_to_surface,
        }
    }

    /// Area of the surface at rest, from the mesh positions (mm²).
    pub fn area(&self, positions: &[Vec3]) -> f64 {
        self.triangles
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|s| positions[self.vertices[s]]);
                0.5 * (b - a).cross(&(c - a)).norm()
            })
            .sum()
    }

    pub(super) fn extract(
        positions: &[Vec3],
        boundary: &[BoundaryFace],
    ) -> Result<TopSurface, String> {
        let faces = select_top_faces(positions, boundary);
        if faces.is_empty() {
            return Ok(TopSurface::default());
        }
        let mut vertices: Vec<usize> = faces
            .iter()
            .flat_map(|&f| boundary[f].nodes)
            .collect::<Vec<_>>();
        vertices.sort_unstable();
        vertices.dedup();
        let mesh_to_surface: HashMap<usize, usize> =
            vertices.iter().enumerate().map(|(s, &v)| (v, s)).collect();
        let points: Vec<Vec3> = vertices.iter().map(|&v| positions[v]).collect();
        let (lo, hi) = bounds(&points);
        let (width, depth) = (hi.x - lo.x, hi.y - lo.y);
        if !(width > 0.0 && depth > 0.0) {
            return Err(format!(
                "the top surface has no extent in x or y ({width} × {depth} mm); cannot lay out UVs"
            ));
        }
        let uvs = points
            .iter()
            .map(|p| [(p.x - lo.x) / width, (p.y - lo.y) / depth])
            .collect();
        Ok(TopSurface {
            triangles: faces
                .iter()
                .map(|&f| boundary[f].nodes.map(|v| mesh_to_surface[&v]))
                .collect(),
            face_tet: faces.iter().map(|&f| boundary[f].tet).collect(),
            boundary_face: faces,
            vertices,
            uvs,
            mesh_to_surface,
        })
    }
}

/// Indices of the boundary faces forming the top surface: those marked
/// top, else those facing +z at the highest z; none when neither exists.
fn select_top_faces(positions: &[Vec3], boundary: &[BoundaryFace]) -> Vec<usize> {
    let marked: Vec<usize> = (0..boundary.len())
        .filter(|&f| boundary[f].marker == markers::TOP)
        .collect();
    if !marked.is_empty() {
        return marked;
    }
    let (lo, hi) = bounds(positions);
    let tol = 1e-9 * (hi - lo).norm();
    let top: Vec<usize> = (0..boundary.len())
        .filter(|&f| {
            let [a, b, c] = boundary[f].nodes.map(|v| positions[v]);
            let n = (b - a).cross(&(c - a)).normalize();
            n.z > 1.0 - 1e-9 && [a, b, c].iter().all(|p| (p.z - hi.z).abs() <= tol)
        })
        .collect();
    top
}

/// Boundary faces of a positively oriented tet mesh, outward oriented, ordered
/// by (tet, local face). Fails on a triangle shared by more than two tets.
pub(super) fn boundary_faces(
    tets: &[[usize; 4]],
    face_markers: &HashMap<[usize; 3], i32>,
) -> Result<Vec<BoundaryFace>, String> {
    let mut uses: HashMap<[usize; 3], (u32, usize)> = HashMap::with_capacity(tets.len() * 2);
    for (t, tet) in tets.iter().enumerate() {
        for local in TET_FACES {
            let key = face_key(local.map(|i| tet[i]));
            let entry = uses.entry(key).or_insert((0, t));
            entry.0 += 1;
            if entry.0 > 2 {
                return Err(format!(
                    "triangle {key:?} is shared by more than two tets (tets {} and {t} among them)",
                    entry.1
                ));
            }
        }
    }
    let mut faces = Vec::new();
    for (t, tet) in tets.iter().enumerate() {
        for local in TET_FACES {
            let nodes = local.map(|i| tet[i]);
            let key = face_key(nodes);
            if uses[&key].0 == 1 {
                faces.push(BoundaryFace {
                    nodes,
                    marker: face_markers.get(&key).copied().unwrap_or(markers::NONE),
                    tet: t,
                });
            }
        }
    }
    Ok(faces)
}

/// Directed edges of each face, checked for a closed, oriented 2-manifold.
pub(super) fn check_closed_manifold(boundary: &[BoundaryFace]) -> Result<(), String> {
    let mut directed: HashMap<(usize, usize), u32> = HashMap::new();
    for f in boundary {
        let [a, b, c] = f.nodes;
        for e in [(a, b), (b, c), (c, a)] {
            *directed.entry(e).or_default() += 1;
        }
    }
    let mut offending: Vec<_> = directed
        .iter()
        .filter(|(&(a, b), &n)| n != 1 || directed.get(&(b, a)) != Some(&1))
        .map(|(&e, &n)| (e, n))
        .collect();
    offending.sort_unstable();
    match offending.first() {
        None => Ok(()),
        Some(&((a, b), n)) => Err(format!(
            "boundary edge {a}→{b} is used {n} time(s) and its reverse {} time(s)",
            directed.get(&(b, a)).copied().unwrap_or(0)
        )),
    }
}

/// V − E + F of the boundary surface.
pub(super) fn euler_characteristic(boundary: &[BoundaryFace]) -> i64 {
    let mut vertices = std::collections::HashSet::new();
    let mut edges = std::collections::HashSet::new();
    for f in boundary {
        let [a, b, c] = f.nodes;
        vertices.extend([a, b, c]);
        for (p, q) in [(a, b), (b, c), (c, a)] {
            edges.insert((p.min(q), p.max(q)));
        }
    }
    vertices.len() as i64 - edges.len() as i64 + boundary.len() as i64
}
