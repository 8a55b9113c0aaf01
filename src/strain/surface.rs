//! The 2×2 deformation field of the top surface in texture space
//! (Nagano et al. 2015 §5 eq. 10–13).
//!
//! Per top triangle with rest vertices `v_i`, deformed `v′_i` and UVs `w_i`:
//!
//! * `Q` (2×3) is the affine map world → UV of the rest triangle:
//!   `Q (v_i − v_0) = w_i − w_0` and `Q n = 0`, i.e. `Q = W (EᵀE)⁻¹ Eᵀ` with
//!   edge matrices `E = [v1−v0, v2−v0]`, `W = [w1−w0, w2−w0]`;
//! * `R` is the closest rotation to `[q1; q2; q1×q2]` (rows), truncated to
//!   its first two rows: an orthonormal tangent frame of the triangle, turned
//!   to follow the UV axes; `R′` likewise from the deformed triangle's `Q′`;
//! * `T` (2×2) maps the rest edges in the rest frame onto the deformed edges
//!   in the deformed frame: `[e′1 e′2] = T [e1 e2]`, `e_i = R(v_i − v_0)`,
//!   `e′_i = R′(v′_i − v′_0)` (eq. 10).
//!
//! Because `R` and `R′` are orthonormal, the singular values of `T` are the
//! principal stretches of the surface whatever the UV layout; the layout
//! only turns the frames. For a linear tet owning the face, `T = R′ F Rᵀ`.
//! `R` and `R′` are proper rotations and `Q`, `Q′` share the UVs, so a
//! single triangle always has `det T > 0`; interpolated per-vertex averages
//! can fold (`det T < 0`) where neighbours disagree strongly, which
//! [`super::Svd2`] reports as a negative `r_t`.
//!
//! Per surface vertex, `T` and `Q Rᵀ` (UV per tangent-frame millimetre) are
//! averaged over the incident triangles weighted by rest area; degenerate
//! triangles (rest or deformed area below 1e-12 of the squared edge length,
//! or a degenerate UV triangle) get no weight and are counted. At a UV point
//! both are interpolated barycentrically, `T = U Σ Vᵀ` (eq. 11–12) and the
//! principal axes in UV are the columns of `S = Q Rᵀ V` (eq. 13): unit
//! direction and UV length per world millimetre.

use nalgebra::{Matrix2, Matrix2x3, Matrix3, Matrix3x2, Vector2, Vector3};
use rayon::prelude::*;

use super::svd2::Svd2;
use crate::fem::Corotation;
use crate::mesh::{TopSurface, Vec3};

/// Frames and map of one surface triangle.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TriangleStrain {
    /// World → UV map of the rest triangle (2×3).
    pub q: Matrix2x3<f64>,
    /// Rest tangent frame (rows).
    pub r: Matrix2x3<f64>,
    /// Deformed tangent frame (rows).
    pub r_deformed: Matrix2x3<f64>,
    /// Surface deformation in tangent space (eq. 10).
    pub t: Matrix2<f64>,
    /// Rest area (mm²); 0 for a degenerate triangle.
    pub weight: f64,
}

/// Tangent frame and world → UV map of a triangle with points `p` and UVs
/// `w`; `None` when the triangle or its UV image is degenerate.
pub fn tangent_frame(
    p: &[Vec3; 3],
    w: &[Vector2<f64>; 3],
) -> Option<(Matrix2x3<f64>, Matrix2x3<f64>)> {
    let e = Matrix3x2::from_columns(&[p[1] - p[0], p[2] - p[0]]);
    let uv = Matrix2::from_columns(&[w[1] - w[0], w[2] - w[0]]);
    let scale = e.norm_squared();
    let area2 = e.column(0).cross(&e.column(1)).norm();
    let uv_scale = uv.norm_squared();
    // Written so that NaN coordinates also count as degenerate.
    let flat = area2.partial_cmp(&(1e-12 * scale)) != Some(std::cmp::Ordering::Greater);
    let uv_flat = uv.determinant().abs().partial_cmp(&(1e-12 * uv_scale))
        != Some(std::cmp::Ordering::Greater);
    if flat || uv_flat {
        return None;
    }
    let gram = e.transpose() * e;
    let q = uv * gram.try_inverse()? * e.transpose();
    let (q1, q2) = (q.row(0).transpose(), q.row(1).transpose());
    let m = Matrix3::from_rows(&[q1.transpose(), q2.transpose(), q1.cross(&q2).transpose()]);
    let rot = Corotation::of(&m).r;
    let r = Matrix2x3::from_rows(&[rot.row(0), rot.row(1)]);
    Some((q, r))
}

/// Edge matrix `[e1 e2]` of `p` in the frame `r`.
fn frame_edges(r: &Matrix2x3<f64>, p: &[Vec3; 3]) -> Matrix2<f64> {
    Matrix2::from_columns(&[r * (p[1] - p[0]), r * (p[2] - p[0])])
}

/// The strain of the surface at one point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SurfaceStrain {
    /// Interpolated `T`.
    pub t: Matrix2<f64>,
    /// Interpolated `Q Rᵀ` (UV per tangent-frame millimetre).
    pub uv_frame: Matrix2<f64>,
    /// SVD of `t`: `r_s`, `r_t` and the tangent-frame axes.
    pub svd: Svd2,
    /// `S = Q Rᵀ V` (eq. 13): columns are the s and t axes in UV, with
    /// length = UV distance per millimetre along the axis.
    pub s_matrix: Matrix2<f64>,
}

impl SurfaceStrain {
    fn of(t: Matrix2<f64>, uv_frame: Matrix2<f64>) -> SurfaceStrain {
        let svd = Svd2::of(&t);
        SurfaceStrain {
            t,
            uv_frame,
            svd,
            s_matrix: uv_frame * svd.v(),
        }
    }

    /// Larger stretch ratio.
    pub fn rs(&self) -> f64 {
        self.svd.rs
    }

    /// Smaller stretch ratio (negative when folded).
    pub fn rt(&self) -> f64 {
        self.svd.rt
    }

    /// Unit s axis in UV.
    pub fn s_uv(&self) -> Vector2<f64> {
        self.s_matrix.column(0).normalize()
    }

    /// Unit t axis in UV.
    pub fn t_uv(&self) -> Vector2<f64> {
        self.s_matrix.column(1).normalize()
    }
}

/// Per-vertex data of the field.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VertexStrain {
    /// Area-weighted `T`.
    pub t: Matrix2<f64>,
    /// Area-weighted `Q Rᵀ`.
    pub uv_frame: Matrix2<f64>,
    /// Area-weighted rest frame `Rᵀ` (3×2; tangent → world).
    pub rest_frame: Matrix3x2<f64>,
    /// Area-weighted deformed frame `R′ᵀ`.
    pub deformed_frame: Matrix3x2<f64>,
}

impl VertexStrain {
    /// The strain at the vertex.
    pub fn strain(&self) -> SurfaceStrain {
        SurfaceStrain::of(self.t, self.uv_frame)
    }

    /// Unit principal axes (s, t) in the rest world frame.
    pub fn rest_axes(&self) -> [Vec3; 2] {
        let svd = Svd2::of(&self.t);
        [
            unit(self.rest_frame * svd.s_axis()),
            unit(self.rest_frame * svd.t_axis()),
        ]
    }

    /// Unit principal axes (s, t) in the deformed world frame (columns of
    /// `R′ᵀ U`).
    pub fn deformed_axes(&self) -> [Vec3; 2] {
        let u = Svd2::of(&self.t).u();
        [
            unit(self.deformed_frame * u.column(0)),
            unit(self.deformed_frame * u.column(1)),
        ]
    }
}

fn unit(v: Vector3<f64>) -> Vec3 {
    v.try_normalize(1e-300).unwrap_or_else(Vec3::zeros)
}

/// The surface deformation field of one frame.
#[derive(Clone, Debug)]
pub struct SurfaceField {
    /// Per top triangle, in [`TopSurface::triangles`] order.
    pub triangles: Vec<TriangleStrain>,
    /// Per surface vertex, in [`TopSurface::vertices`] order.
    pub vertices: Vec<VertexStrain>,
    /// Triangles left out of the averages (degenerate at rest or deformed).
    pub degenerate_triangles: usize,
    /// Triangles as surface-vertex indices.
    tri: Vec<[usize; 3]>,
    /// UVs of the surface vertices.
    uvs: Vec<Vector2<f64>>,
    locator: UvLocator,
}

impl SurfaceField {
    /// The field of `top` (rest positions `rest`, UVs from `top.uvs`) at
    /// positions `x` (indexed like `rest`). Parallel over triangles, then
    /// per vertex in triangle order (deterministic).
    pub fn new(top: &TopSurface, rest: &[Vec3], x: &[Vec3]) -> SurfaceField {
        let uvs: Vec<Vector2<f64>> = top.uvs.iter().map(|w| Vector2::new(w[0], w[1])).collect();
        let triangles: Vec<TriangleStrain> = top
            .triangles
            .par_iter()
            .map(|tri| {
                let w = tri.map(|s| uvs[s]);
                let p = tri.map(|s| rest[top.vertices[s]]);
                let p_def = tri.map(|s| x[top.vertices[s]]);
                triangle_strain(&p, &p_def, &w)
            })
            .collect();
        let mut sums = vec![(0.0, VertexStrain::zero()); top.vertices.len()];
        for (tri, ts) in top.triangles.iter().zip(&triangles) {
            for &s in tri {
                let (w, acc) = &mut sums[s];
                *w += ts.weight;
                acc.t += ts.t * ts.weight;
                acc.uv_frame += ts.q * ts.r.transpose() * ts.weight;
                acc.rest_frame += ts.r.transpose() * ts.weight;
                acc.deformed_frame += ts.r_deformed.transpose() * ts.weight;
            }
        }
        let vertices = sums
            .into_iter()
            .map(|(w, acc)| if w > 0.0 { acc.scaled(1.0 / w) } else { acc })
            .collect();
        SurfaceField {
            degenerate_triangles: triangles.iter().filter(|t| t.weight == 0.0).count(),
            triangles,
            vertices,
            tri: top.triangles.clone(),
            locator: UvLocator::new(&top.triangles, &uvs),
            uvs,
        }
    }

    /// The same field over copies of some of its triangles moved in UV:
    /// `pieces` lists (triangle, UV offset). Vertex data are those of the
    /// whole field (so a vertex averages over all its triangles, not only
    /// the copied ones); a vertex copied with two offsets becomes two
    /// vertices. This is how a UDIM tile (its triangles moved into the unit
    /// square) or a wrapping layout (triangles also drawn one period over)
    /// is rasterised.
    pub fn view(&self, pieces: &[(usize, [f64; 2])]) -> SurfaceField {
        let mut index = std::collections::HashMap::new();
        let (mut vertices, mut uvs) = (Vec::new(), Vec::new());
        let mut tri = Vec::with_capacity(pieces.len());
        let mut triangles = Vec::with_capacity(pieces.len());
        for &(k, offset) in pieces {
            let key_offset = offset.map(f64::to_bits);
            tri.push(self.tri[k].map(|s| {
                *index.entry((s, key_offset)).or_insert_with(|| {
                    vertices.push(self.vertices[s]);
                    uvs.push(self.uvs[s] + Vector2::new(offset[0], offset[1]));
                    vertices.len() - 1
                })
            }));
            triangles.push(self.triangles[k]);
        }
        SurfaceField {
            degenerate_triangles: triangles.iter().filter(|t| t.weight == 0.0).count(),
            triangles,
            vertices,
            locator: UvLocator::new(&tri, &uvs),
            tri,
            uvs,
        }
    }

    /// The field at UV point `uv`, or `None` outside the surface's UV image.
    pub fn at(&self, uv: Vector2<f64>) -> Option<SurfaceStrain> {
        let (k, bary) = self.locator.locate(uv, &self.tri, &self.uvs)?;
        Some(self.interpolate(k, bary))
    }

    /// The field inside triangle `k` at barycentric coordinates `bary`.
    pub fn interpolate(&self, k: usize, bary: [f64; 3]) -> SurfaceStrain {
        let (t, frame) = self.interpolate_matrices(k, bary);
        SurfaceStrain::of(t, frame)
    }

    /// `T` and `Q Rᵀ` inside triangle `k` at barycentric coordinates `bary`:
    /// [`SurfaceField::interpolate`] without the decomposition (what the
    /// strain raster stores; the kernel field decomposes each texel later).
    pub fn interpolate_matrices(&self, k: usize, bary: [f64; 3]) -> (Matrix2<f64>, Matrix2<f64>) {
        let mut t = Matrix2::zeros();
        let mut frame = Matrix2::zeros();
        for (&s, b) in self.tri[k].iter().zip(bary) {
            t += self.vertices[s].t * b;
            frame += self.vertices[s].uv_frame * b;
        }
        (t, frame)
    }

    /// Triangles (surface-vertex indices) and vertex UVs.
    pub fn layout(&self) -> (&[[usize; 3]], &[Vector2<f64>]) {
        (&self.tri, &self.uvs)
    }

    /// Per-vertex extremes: ((min r_s, max r_s), (min r_t, max r_t)) and the
    /// number of folded vertices (det T < 0).
    pub fn extremes(&self) -> ((f64, f64), (f64, f64), usize) {
        if self.vertices.is_empty() {
            // A mesh without a top surface has no stretch ratios.
            return ((f64::NAN, f64::NAN), (f64::NAN, f64::NAN), 0);
        }
        let mut rs = (f64::INFINITY, f64::NEG_INFINITY);
        let mut rt = rs;
        let mut folded = 0;
        for v in &self.vertices {
            let svd = Svd2::of(&v.t);
            rs = (rs.0.min(svd.rs), rs.1.max(svd.rs));
            rt = (rt.0.min(svd.rt), rt.1.max(svd.rt));
            folded += usize::from(svd.folded());
        }
        (rs, rt, folded)
    }
}

impl VertexStrain {
    fn zero() -> VertexStrain {
        VertexStrain {
            t: Matrix2::zeros(),
            uv_frame: Matrix2::zeros(),
            rest_frame: Matrix3x2::zeros(),
            deformed_frame: Matrix3x2::zeros(),
        }
    }

    fn scaled(self, k: f64) -> VertexStrain {
        VertexStrain {
            t: self.t * k,
            uv_frame: self.uv_frame * k,
            rest_frame: self.rest_frame * k,
            deformed_frame: self.deformed_frame * k,
        }
    }
}

/// Eq. 10 for one triangle (rest points `p`, deformed `p_def`, UVs `w`).
pub fn triangle_strain(p: &[Vec3; 3], p_def: &[Vec3; 3], w: &[Vector2<f64>; 3]) -> TriangleStrain {
    let rest = tangent_frame(p, w);
    let deformed = tangent_frame(p_def, w);
    match (rest, deformed) {
        (Some((q, r)), Some((_, r_def))) => {
            let e = frame_edges(&r, p);
            let e_def = frame_edges(&r_def, p_def);
            match e.try_inverse() {
                Some(inv) => TriangleStrain {
                    q,
                    r,
                    r_deformed: r_def,
                    t: e_def * inv,
                    weight: 0.5 * (p[1] - p[0]).cross(&(p[2] - p[0])).norm(),
                },
                None => TriangleStrain::degenerate(),
            }
        }
        _ => TriangleStrain::degenerate(),
    }
}

impl TriangleStrain {
    fn degenerate() -> TriangleStrain {
        TriangleStrain {
            q: Matrix2x3::zeros(),
            r: Matrix2x3::zeros(),
            r_deformed: Matrix2x3::zeros(),
            t: Matrix2::zeros(),
            weight: 0.0,
        }
    }
}

/// Barycentric coordinates of `p` in the triangle `w` (None if degenerate).
pub fn barycentric(w: &[Vector2<f64>; 3], p: Vector2<f64>) -> Option<[f64; 3]> {
    let m = Matrix2::from_columns(&[w[1] - w[0], w[2] - w[0]]);
    let l = m.try_inverse()? * (p - w[0]);
    Some([1.0 - l.x - l.y, l.x, l.y])
}

/// A uniform grid over the UV bounding box listing the triangles whose UV
/// bounding boxes overlap each cell.
#[derive(Clone, Debug)]
struct UvLocator {
    origin: Vector2<f64>,
    cell: Vector2<f64>,
    n: [usize; 2],
    cells: Vec<Vec<usize>>,
}

impl UvLocator {
    fn new(tri: &[[usize; 3]], uvs: &[Vector2<f64>]) -> UvLocator {
        let (mut lo, mut hi) = (
            Vector2::repeat(f64::INFINITY),
            Vector2::repeat(f64::NEG_INFINITY),
        );
        for w in uvs {
            lo = lo.inf(w);
            hi = hi.sup(w);
        }
        if uvs.is_empty() {
            lo = Vector2::zeros();
            hi = Vector2::repeat(1.0);
        }
        let side = ((tri.len() as f64).sqrt().ceil() as usize).clamp(1, 1024);
        let n = [side, side];
        let cell = (hi - lo).map(|d| d.max(1e-300)) / side as f64;
        let mut cells = vec![Vec::new(); side * side];
        let index =
            |v: f64, o: f64, c: f64| (((v - o) / c).floor().max(0.0) as usize).min(side - 1);
        for (k, t) in tri.iter().enumerate() {
            let w = t.map(|s| uvs[s]);
            let (a, b) = (w[0].inf(&w[1]).inf(&w[2]), w[0].sup(&w[1]).sup(&w[2]));
            for j in index(a.y, lo.y, cell.y)..=index(b.y, lo.y, cell.y) {
                for i in index(a.x, lo.x, cell.x)..=index(b.x, lo.x, cell.x) {
                    cells[j * side + i].push(k);
                }
            }
        }
        UvLocator {
            origin: lo,
            cell,
            n,
            cells,
        }
    }

    /// The first triangle (in index order) containing `p`, with barycentric
    /// coordinates.
    fn locate(
        &self,
        p: Vector2<f64>,
        tri: &[[usize; 3]],
        uvs: &[Vector2<f64>],
    ) -> Option<(usize, [f64; 3])> {
        let rel = (p - self.origin).component_div(&self.cell);
        let tol = 1e-9;
        if rel.x < -tol
            || rel.y < -tol
            || rel.x > self.n[0] as f64 + tol
            || rel.y > self.n[1] as f64 + tol
        {
            return None;
        }
        let i = (rel.x.floor().max(0.0) as usize).min(self.n[0] - 1);
        let j = (rel.y.floor().max(0.0) as usize).min(self.n[1] - 1);
        self.cells[j * self.n[0] + i].iter().find_map(|&k| {
            let b = barycentric(&tri[k].map(|s| uvs[s]), p)?;
            (b.iter().all(|&l| l >= -1e-12)).then_some((k, b))
        })
    }
}
