//! The geometry of one frame: the deformed top surface (optionally
//! tessellated), every other boundary face (shadow casters and the patch's
//! cut sides) and the probe.
//!
//! Tessellation splits each surface triangle into `k²` and places the new
//! points by Phong tessellation (Boubekeur & Alexa 2008): the linear point
//! is replaced by the barycentric blend of its projections onto the three
//! vertex tangent planes (shape factor 3/4), which rounds the indentation
//! without moving the original vertices.

use bytemuck::{Pod, Zeroable};
use glam::Vec3 as V3;

use crate::fem::probe::{ProbePose, ProbeShape};
use crate::mesh::{TetMesh, TopSurface, Vec3};
use crate::strain::SurfaceField;

/// A top-surface vertex; mirrors WGSL `SurfaceVertex` (lighting.wgsl).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct SurfaceVertex {
    /// Deformed position (mm), w = 1.
    pub position: [f32; 4],
    /// Unit mesoscale normal.
    pub normal: [f32; 4],
    /// Direction of increasing u on the deformed surface.
    pub tangent: [f32; 4],
    /// Texture coordinates (zw unused).
    pub uv: [f32; 4],
    /// r_s, r_t and the s axis in texture space.
    pub strain: [f32; 4],
}

/// A vertex of the other meshes; mirrors WGSL `MeshVertex` (shadow.wgsl,
/// skin.wgsl).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct MeshVertex {
    /// Position (mm), w = 1.
    pub position: [f32; 4],
    /// Unit normal.
    pub normal: [f32; 4],
}

/// Triangle lists of one frame.
#[derive(Clone, Debug, Default)]
pub struct FrameGeometry {
    /// Top surface, non-indexed triangle list.
    pub surface: Vec<SurfaceVertex>,
    /// The same triangles as shadow casters.
    pub top: Vec<MeshVertex>,
    /// Boundary faces other than the top, non-indexed triangle list.
    pub sides: Vec<MeshVertex>,
    /// The probe, non-indexed triangle list (empty when not drawn).
    pub probe: Vec<MeshVertex>,
}

fn v3(p: &Vec3) -> V3 {
    V3::new(p.x as f32, p.y as f32, p.z as f32)
}

fn mesh_vertex(p: V3, n: V3) -> MeshVertex {
    MeshVertex {
        position: [p.x, p.y, p.z, 1.0],
        normal: [n.x, n.y, n.z, 0.0],
    }
}

/// Builds the frame's geometry from the deformed positions `x`.
pub fn build(
    mesh: &TetMesh,
    x: &[Vec3],
    field: &SurfaceField,
    probe: Option<&ProbePose>,
    tessellate: usize,
) -> FrameGeometry {
    FrameGeometry {
        sides: sides(mesh, x),
        probe: probe.map(probe_mesh).unwrap_or_default(),
        ..build_surface(&mesh.top, x, field, tessellate)
    }
}

impl FrameGeometry {
    /// A surface alone (also its own shadow caster), without sides or probe.
    pub fn of_surface(surface: Vec<SurfaceVertex>) -> FrameGeometry {
        let top = surface
            .iter()
            .map(|v| MeshVertex {
                position: v.position,
                normal: v.normal,
            })
            .collect();
        FrameGeometry {
            surface,
            top,
            sides: Vec::new(),
            probe: Vec::new(),
        }
    }
}

/// The deformed surface of an animated surface (or any [`TopSurface`])
/// alone: `x` indexed like the positions `top.vertices` point into.
pub fn build_surface(
    top: &TopSurface,
    x: &[Vec3],
    field: &SurfaceField,
    tessellate: usize,
) -> FrameGeometry {
    FrameGeometry::of_surface(surface(top, x, field, tessellate))
}

/// Per-vertex normals (area-weighted, summed per position so a UV seam does
/// not split them) and u-tangents (per surface vertex: mirrored charts have
/// opposite ones) of the deformed top.
fn surface(top: &TopSurface, x: &[Vec3], field: &SurfaceField, k: usize) -> Vec<SurfaceVertex> {
    let pos: Vec<V3> = top.vertices.iter().map(|&v| v3(&x[v])).collect();
    let mut position_normals = vec![V3::ZERO; x.len()];
    let mut tangents = vec![V3::ZERO; pos.len()];
    for tri in &top.triangles {
        let [a, b, c] = tri.map(|s| pos[s]);
        let n = (b - a).cross(c - a);
        let [ua, ub, uc] = tri.map(|s| top.uvs[s]);
        // dp/du from the triangle's UV gradient.
        let (du1, dv1) = ((ub[0] - ua[0]) as f32, (ub[1] - ua[1]) as f32);
        let (du2, dv2) = ((uc[0] - ua[0]) as f32, (uc[1] - ua[1]) as f32);
        let det = du1 * dv2 - du2 * dv1;
        let dpdu = if det.abs() > 1e-12 {
            ((b - a) * dv2 - (c - a) * dv1) / det
        } else {
            V3::ZERO
        };
        for &s in tri {
            position_normals[top.vertices[s]] += n;
            tangents[s] += dpdu * n.length();
        }
    }
    let normals: Vec<V3> = top.vertices.iter().map(|&v| position_normals[v]).collect();
    let strain: Vec<[f32; 4]> = field
        .vertices
        .iter()
        .map(|v| {
            let st = v.strain();
            let s = st.s_uv();
            [st.rs() as f32, st.rt() as f32, s.x as f32, s.y as f32]
        })
        .collect();
    let vertex = |s: usize| SurfaceVertex {
        position: pos[s].extend(1.0).to_array(),
        normal: normals[s].normalize_or(V3::Z).extend(0.0).to_array(),
        tangent: tangents[s].normalize_or(V3::X).extend(0.0).to_array(),
        uv: [top.uvs[s][0] as f32, top.uvs[s][1] as f32, 0.0, 0.0],
        strain: strain.get(s).copied().unwrap_or([1.0, 1.0, 1.0, 0.0]),
    };
    let mut out = Vec::with_capacity(top.triangles.len() * 3 * k * k);
    for tri in &top.triangles {
        let corners = tri.map(vertex);
        if k == 1 {
            out.extend(corners);
            continue;
        }
        for (a, b, c) in sub_triangles(k) {
            out.extend([a, b, c].map(|w| phong_point(&corners, w)));
        }
    }
    out
}

/// Barycentric corners of the `k²` sub-triangles of a triangle.
fn sub_triangles(k: usize) -> Vec<([f32; 3], [f32; 3], [f32; 3])> {
    let kf = k as f32;
    let w = |i: usize, j: usize| {
        let (a, b) = (i as f32 / kf, j as f32 / kf);
        [1.0 - a - b, a, b]
    };
    let mut out = Vec::with_capacity(k * k);
    for j in 0..k {
        for i in 0..k - j {
            out.push((w(i, j), w(i + 1, j), w(i, j + 1)));
            if i + j + 1 < k {
                out.push((w(i + 1, j), w(i + 1, j + 1), w(i, j + 1)));
            }
        }
    }
    out
}

/// Phong tessellation of a point with barycentric weights `w`.
fn phong_point(c: &[SurfaceVertex; 3], w: [f32; 3]) -> SurfaceVertex {
    let lerp4 = |f: fn(&SurfaceVertex) -> [f32; 4]| {
        let mut out = [0.0; 4];
        for (v, wi) in c.iter().zip(w) {
            for (o, x) in out.iter_mut().zip(f(v)) {
                *o += wi * x;
            }
        }
        out
    };
    let p: Vec<V3> = c.iter().map(|v| V3::from_slice(&v.position[..3])).collect();
    let n: Vec<V3> = c.iter().map(|v| V3::from_slice(&v.normal[..3])).collect();
    let linear = p[0] * w[0] + p[1] * w[1] + p[2] * w[2];
    let mut projected = V3::ZERO;
    for i in 0..3 {
        projected += w[i] * (linear - (linear - p[i]).dot(n[i]) * n[i]);
    }
    let q = linear * 0.25 + projected * 0.75;
    let normal = V3::from_slice(&lerp4(|v| v.normal)[..3]).normalize_or(V3::Z);
    SurfaceVertex {
        position: q.extend(1.0).to_array(),
        normal: normal.extend(0.0).to_array(),
        tangent: lerp4(|v| v.tangent),
        uv: lerp4(|v| v.uv),
        strain: lerp4(|v| v.strain),
    }
}

/// Boundary faces other than the top, with flat normals.
fn sides(mesh: &TetMesh, x: &[Vec3]) -> Vec<MeshVertex> {
    let mut is_top = vec![false; mesh.boundary.len()];
    for &f in &mesh.top.boundary_face {
        is_top[f] = true;
    }
    let mut out = Vec::new();
    for (face, _) in mesh.boundary.iter().zip(&is_top).filter(|(_, top)| !**top) {
        let [a, b, c] = face.nodes.map(|v| v3(&x[v]));
        let n = (b - a).cross(c - a).normalize_or(V3::Z);
        out.extend([a, b, c].map(|p| mesh_vertex(p, n)));
    }
    out
}

/// A triangulated probe: sphere, capsule, or a punch drawn as a short
/// cylinder above its face.
fn probe_mesh(pose: &ProbePose) -> Vec<MeshVertex> {
    let c = v3(&pose.centre);
    let (rings, segments) = (24usize, 48usize);
    let mut out = Vec::new();
    // A surface of revolution about `axis` given by (radius, height) profile
    // points with their profile normals (nr, nh).
    let mut revolve = |axis: V3, origin: V3, profile: &[(f32, f32, f32, f32)]| {
        let e1 = axis.any_orthonormal_vector();
        let e2 = axis.cross(e1);
        let at = |k: usize, (r, h, nr, nh): (f32, f32, f32, f32)| {
            let phi = std::f32::consts::TAU * k as f32 / segments as f32;
            let radial = e1 * phi.cos() + e2 * phi.sin();
            mesh_vertex(
                origin + radial * r + axis * h,
                (radial * nr + axis * nh).normalize_or(axis),
            )
        };
        for w in profile.windows(2) {
            for k in 0..segments {
                let (a, b) = (at(k, w[0]), at(k + 1, w[0]));
                let (c2, d) = (at(k, w[1]), at(k + 1, w[1]));
                out.extend([a, b, d, a, d, c2]);
            }
        }
    };
    let hemi = |r: f32, h0: f32, up: bool| -> Vec<(f32, f32, f32, f32)> {
        (0..=rings / 2)
            .map(|i| {
                let t = std::f32::consts::FRAC_PI_2 * i as f32 / (rings / 2) as f32;
                let (s, co) = (t.sin(), t.cos());
                if up {
                    (r * co, h0 + r * s, co, s)
                } else {
                    (r * s, h0 - r * co, s, -co)
                }
            })
            .collect()
    };
    match pose.shape {
        ProbeShape::Sphere { radius_mm } => {
            let r = radius_mm as f32;
            let mut profile = hemi(r, 0.0, false);
            profile.extend(hemi(r, 0.0, true).into_iter().skip(1));
            revolve(V3::Z, c, &profile);
        }
        ProbeShape::Capsule {
            radius_mm,
            length_mm,
        } => {
            let (r, half) = (radius_mm as f32, 0.5 * length_mm as f32);
            let mut profile = hemi(r, -half, false);
            profile.extend(hemi(r, half, true));
            revolve(v3(&pose.axis).normalize_or(V3::X), c, &profile);
        }
        ProbeShape::Punch { radius_mm } => {
            let r = radius_mm as f32;
            let profile = [
                (0.0, 0.0, 0.0, -1.0),
                (r, 0.0, 0.0, -1.0),
                (r, 0.0, 1.0, 0.0),
                (r, 3.0 * r, 1.0, 0.0),
                (r, 3.0 * r, 0.0, 1.0),
                (0.0, 3.0 * r, 0.0, 1.0),
            ];
            revolve(V3::Z, c, &profile);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sub_triangles_tile_the_triangle() {
        for k in 1..=5 {
            let tris = sub_triangles(k);
            assert_eq!(tris.len(), k * k);
            let area = |(a, b, c): &([f32; 3], [f32; 3], [f32; 3])| {
                0.5 * ((b[1] - a[1]) * (c[2] - a[2]) - (c[1] - a[1]) * (b[2] - a[2]))
            };
            let total: f32 = tris.iter().map(area).sum();
            assert!((total - 0.5).abs() < 1e-5, "k = {k}: {total}");
            assert!(tris.iter().all(|t| area(t) > 0.0), "k = {k}: orientation");
        }
    }

    #[test]
    fn phong_points_keep_corners_and_flat_planes() {
        let flat = |x: f32, y: f32| SurfaceVertex {
            position: [x, y, 0.0, 1.0],
            normal: [0.0, 0.0, 1.0, 0.0],
            ..Default::default()
        };
        let c = [flat(0.0, 0.0), flat(1.0, 0.0), flat(0.0, 1.0)];
        let p = phong_point(&c, [1.0, 0.0, 0.0]);
        assert_eq!(p.position, [0.0, 0.0, 0.0, 1.0]);
        let q = phong_point(&c, [0.2, 0.3, 0.5]);
        assert!(q.position[2].abs() < 1e-7 && (q.position[0] - 0.3).abs() < 1e-6);
    }
}
