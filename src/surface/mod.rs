//! Animated surfaces made by other tools (Nagano et al. 2015 §5, "novel surface
//! animation"): a rest triangle mesh with UVs and its positions per frame,
//! read from glTF 2.0 (morph targets and skins with their animation,
//! [`gltf`]) or an OBJ sequence ([`obj`]), in millimetres.
//!
//! The strain of such a surface is the FEM top surface's (eq. 10–13 per
//! triangle, area-weighted per vertex, interpolated per texel): an
//! [`AnimatedSurface`] carries a [`TopSurface`] whose surface vertices are
//! the (position, UV) pairs of the file, so a position on a UV seam has one
//! surface vertex per chart and the per-vertex averages never mix charts.
//! Positions are welded (vertices with the same rest position and the same
//! trajectory are one position) only for what is geometric: shading normals
//! and the exported surface.
//!
//! UVs outside the unit square follow the scenario's [`UvLayout`]: refused
//! (`unit`), UDIM tiles each with its own maps (`udim`), or a repeating
//! texture (`wrap`). [`AnimatedSurface::pieces`] turns a layout into the
//! triangles (and UV offsets) each map rasterises.

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use std::collections::HashMap;
use std::path::Path;

use crate::error::{shown, Error, Result};
use crate::mesh::{TopSurface, Vec3};

mod clip;
pub mod gltf;
mod gltf_check;
pub mod gltf_write;
pub mod obj;

/// A triangle surface with UVs and its positions over time (mm).
#[derive(Clone, Debug)]
pub struct AnimatedSurface {
    /// The file (or pattern) it came from, for messages.
    pub origin: String,
    /// Rest positions (mm), one per welded position.
    pub positions: Vec<Vec3>,
    /// Surface vertices (position index + UV), triangles and UVs.
    pub top: TopSurface,
    /// Positions of every frame (mm), indexed like `positions`.
    pub frames: Vec<Vec<Vec3>>,
    /// Frames per second.
    pub frame_rate_hz: f64,
}

/// How UVs outside the unit square are read (`unit`, `udim` or `wrap` in
/// scenario files).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Deserialize, Serialize, JsonSchema)]
#[serde(rename_all = "lowercase")]
pub enum UvLayout {
    /// Every UV lies in [0, 1]² (an error otherwise).
    #[default]
    Unit,
    /// UDIM tiles: tile `1001 + u + 10 v` holds u ∈ [u, u + 1), v ∈ [v, v + 1);
    /// each tile has its own maps.
    Udim,
    /// One repeating texture: UVs are taken modulo 1 and triangles crossing
    /// an edge of the square are drawn on both sides.
    Wrap,
}

impl UvLayout {
    /// Its name in scenario files.
    pub fn name(self) -> &'static str {
        match self {
            UvLayout::Unit => "unit",
            UvLayout::Udim => "udim",
            UvLayout::Wrap => "wrap",
        }
    }
}

/// The triangles one map rasterises: a UDIM tile or the whole unit square.
#[derive(Clone, Debug, PartialEq)]
pub struct UvPiece {
    /// UDIM tile number (1001, 1002, …), `None` for the unit square.
    pub udim: Option<u32>,
    /// (triangle, UV offset moving it into the unit square).
    pub triangles: Vec<(usize, [f64; 2])>,
}

impl UvPiece {
    /// The file-name tag of this piece's maps: `"1001_"` for a UDIM tile,
    /// empty for the unit square.
    pub fn tag(&self) -> String {
        self.udim.map(|u| format!("{u}_")).unwrap_or_default()
    }
}

/// Tolerance of the UV range checks (UVs a little outside [0, 1] from
/// rounding in the exporting tool are inside).
const UV_TOL: f64 = 1e-6;

/// Per-vertex data of a surface as a reader produces it, before welding:
/// one entry per (position, UV) pair.
#[derive(Clone, Debug, Default)]
pub(crate) struct SplitSurface {
    pub origin: String,
    pub rest: Vec<Vec3>,
    pub uvs: Vec<[f64; 2]>,
    pub triangles: Vec<[usize; 3]>,
    /// Per frame, per split vertex.
    pub frames: Vec<Vec<Vec3>>,
    /// Names of the split vertices' elements for messages (e.g. "object
    /// 'Face', vertex 12"), or empty to say "vertex k".
    pub labels: Vec<String>,
}

impl SplitSurface {
    fn label(&self, k: usize) -> String {
        self.labels
            .get(k)
            .cloned()
            .unwrap_or_else(|| format!("vertex {k}"))
    }
}

/// Largest coordinate of a surface's vertex (mm): a kilometre. Beyond it
/// areas and normals overflow (a coordinate of 10³⁰⁸ made every triangle
/// degenerate).
pub const MAX_COORDINATE_MM: f64 = 1e6;

impl AnimatedSurface {
    /// Checks a reader's surface (finite positions and UVs, indices in
    /// range, at least one triangle with area), scales it to millimetres
    /// and welds its positions.
    pub(crate) fn from_split(
        split: SplitSurface,
        mm_per_unit: f64,
        frame_rate_hz: f64,
    ) -> Result<AnimatedSurface> {
        let bad = |message: String| Error::InvalidMesh {
            origin: split.origin.clone(),
            message,
        };
        let n = split.rest.len();
        if split.triangles.is_empty() {
            return Err(bad("has no triangles".into()));
        }
        for (t, tri) in split.triangles.iter().enumerate() {
            if let Some(&v) = tri.iter().find(|&&v| v >= n) {
                return Err(bad(format!(
                    "triangle {t} uses vertex {v}, but there are {n} vertices"
                )));
            }
        }
        for (k, uv) in split.uvs.iter().enumerate() {
            if !uv.iter().all(|c| c.is_finite()) {
                return Err(bad(format!(
                    "{} has a non-finite UV {uv:?}",
                    split.label(k)
                )));
            }
        }
        for (f, frame) in std::iter::once(&split.rest)
            .chain(&split.frames)
            .enumerate()
        {
            if frame.len() != n {
                return Err(bad(format!(
                    "frame {} has {} vertices, the rest mesh {n}",
                    f - 1,
                    frame.len()
                )));
            }
            let fits = |c: f64| c.is_finite() && (c * mm_per_unit).abs() <= MAX_COORDINATE_MM;
            if let Some(k) = frame.iter().position(|p| !p.iter().all(|&c| fits(c))) {
                let when = if f == 0 {
                    "at rest".to_string()
                } else {
                    format!("in frame {}", f - 1)
                };
                let what = if frame[k].iter().all(|c| c.is_finite()) {
                    format!("a position beyond ±{MAX_COORDINATE_MM:e} mm")
                } else {
                    "a non-finite position".to_string()
                };
                return Err(bad(format!(
                    "{} has {what} {when}: {:?}",
                    split.label(k),
                    frame[k].as_slice()
                )));
            }
        }
        if split.frames.is_empty() {
            return Err(bad("has no frames".into()));
        }
        // Welding: same rest position and same trajectory, bit for bit.
        let mut key_of = HashMap::with_capacity(n);
        let mut vertices = Vec::with_capacity(n);
        let mut first = Vec::new();
        for k in 0..n {
            let key: Vec<u64> = std::iter::once(&split.rest[k])
                .chain(split.frames.iter().map(|f| &f[k]))
                .flat_map(|p| p.iter().map(|c| c.to_bits()).collect::<Vec<_>>())
                .collect();
            let id = *key_of.entry(key).or_insert_with(|| {
                first.push(k);
                first.len() - 1
            });
            vertices.push(id);
        }
        let scale = |p: &Vec3| p * mm_per_unit;
        let positions = first.iter().map(|&k| scale(&split.rest[k])).collect();
        let frames = split
            .frames
            .iter()
            .map(|f| first.iter().map(|&k| scale(&f[k])).collect())
            .collect();
        let surface = AnimatedSurface {
            origin: split.origin.clone(),
            positions,
            top: TopSurface::from_layout(vertices, split.triangles, split.uvs),
            frames,
            frame_rate_hz,
        };
        if surface.area() <= 0.0 {
            return Err(bad(
                "has no triangle with a non-zero area at rest and in UV".into(),
            ));
        }
        Ok(surface)
    }

    /// A surface from per-vertex data in millimetres: one vertex per
    /// (position, UV) pair as in glTF, `frames[f][k]` the position of
    /// vertex `k` in frame `f`. Vertices with the same rest position and
    /// trajectory are welded into one position; the checks of the readers
    /// apply (finite values, indices in range, some area).
    pub fn from_vertices(
        origin: &str,
        rest: Vec<Vec3>,
        uvs: Vec<[f64; 2]>,
        triangles: Vec<[usize; 3]>,
        frames: Vec<Vec<Vec3>>,
        frame_rate_hz: f64,
    ) -> Result<AnimatedSurface> {
        if uvs.len() != rest.len() {
            return Err(Error::InvalidMesh {
                origin: origin.into(),
                message: format!("has {} UVs for {} vertices", uvs.len(), rest.len()),
            });
        }
        let split = SplitSurface {
            origin: origin.into(),
            rest,
            uvs,
            triangles,
            frames,
            labels: Vec::new(),
        };
        AnimatedSurface::from_split(split, 1.0, frame_rate_hz)
    }

    /// An FEM patch's top surface with the positions of its frames (`x[f]`
    /// indexed like the tet mesh), e.g. to export it as an animation.
    pub fn from_top(
        origin: &str,
        top: &TopSurface,
        mesh_positions: &[Vec3],
        frames: &[Vec<Vec3>],
        frame_rate_hz: f64,
    ) -> AnimatedSurface {
        let pick = |x: &[Vec3]| top.vertices.iter().map(|&v| x[v]).collect::<Vec<_>>();
        AnimatedSurface {
            origin: origin.into(),
            positions: pick(mesh_positions),
            top: TopSurface::from_layout(
                (0..top.vertices.len()).collect(),
                top.triangles.clone(),
                top.uvs.clone(),
            ),
            frames: frames.iter().map(|x| pick(x)).collect(),
            frame_rate_hz,
        }
    }

    /// Reads a surface file by its extension: `.gltf`/`.glb`, or `.obj` (one
    /// file, or a sequence when the name holds a `%d`-style pattern).
    pub fn read(path: &Path, options: &ReadOptions) -> Result<AnimatedSurface> {
        let name = path.to_string_lossy().to_lowercase();
        if name.ends_with(".gltf") || name.ends_with(".glb") {
            gltf::read(path, options)
        } else if name.ends_with(".obj") {
            obj::read(path, options)
        } else {
            Err(Error::parameter(
                "surface.file",
                format!(
                    "{} is neither glTF (.gltf, .glb) nor OBJ (.obj, or a sequence like \
                     frame_%04d.obj)",
                    path.display()
                ),
            ))
        }
    }

    /// Number of frames.
    pub fn num_frames(&self) -> usize {
        self.frames.len()
    }

    /// Time of frame `f` (s).
    pub fn time(&self, f: usize) -> f64 {
        f as f64 / self.frame_rate_hz
    }

    /// Rest area of the triangles that are not degenerate in space or UV (mm²).
    pub fn area(&self) -> f64 {
        self.areas().0
    }

    /// (Rest area in mm², UV area) over the triangles that are not
    /// degenerate at rest or in UV.
    fn areas(&self) -> (f64, f64) {
        let (mut area, mut uv_area) = (0.0, 0.0);
        for tri in &self.top.triangles {
            let [a, b, c] = tri.map(|s| self.positions[self.top.vertices[s]]);
            let [p, q, r] = tri.map(|s| self.top.uvs[s]);
            let a3 = 0.5 * (b - a).cross(&(c - a)).norm();
            let a2 = 0.5 * ((q[0] - p[0]) * (r[1] - p[1]) - (r[0] - p[0]) * (q[1] - p[1])).abs();
            if a3 > 0.0 && a2 > 0.0 {
                area += a3;
                uv_area += a2;
            }
        }
        (area, uv_area)
    }

    /// Millimetres of rest surface per unit of UV (the square root of
    /// surface area over UV area): the extent the unit square's texture
    /// covers on average, used for a generated map's texel size and the
    /// renderer's texture-space texel.
    pub fn mm_per_uv(&self) -> f64 {
        let (area, uv_area) = self.areas();
        (area / uv_area).sqrt()
    }

    /// Axis-aligned bounds of the rest positions (mm).
    pub fn bounds(&self) -> (Vec3, Vec3) {
        crate::mesh::bounds(&self.positions)
    }

    /// The triangles each map rasterises under `layout`, with the offsets
    /// that move them into the unit square; an error naming the first
    /// vertex or triangle that does not fit the layout.
    pub fn pieces(&self, layout: UvLayout) -> Result<Vec<UvPiece>> {
        let uv = |s: usize| self.top.uvs[s];
        let bbox = |k: usize| {
            let w = self.top.triangles[k].map(uv);
            let lo = [0, 1].map(|i| w.iter().map(|p| p[i]).fold(f64::INFINITY, f64::min));
            let hi = [0, 1].map(|i| w.iter().map(|p| p[i]).fold(f64::NEG_INFINITY, f64::max));
            (lo, hi)
        };
        let all: Vec<usize> = (0..self.top.triangles.len()).collect();
        match layout {
            UvLayout::Unit => {
                let outside = self
                    .top
                    .uvs
                    .iter()
                    .position(|p| p.iter().any(|&c| !(-UV_TOL..=1.0 + UV_TOL).contains(&c)));
                if let Some(s) = outside {
                    return Err(Error::InvalidMesh {
                        origin: self.origin.clone(),
                        message: format!(
                            "surface vertex {s} (position {}) has UV ({}, {}) outside [0, 1]; \
                             set surface.uv_layout = \"udim\" for UDIM tiles or \"wrap\" for a \
                             repeating texture",
                            self.top.vertices[s],
                            shown(uv(s)[0]),
                            shown(uv(s)[1])
                        ),
                    });
                }
                Ok(vec![UvPiece {
                    udim: None,
                    triangles: all.into_iter().map(|k| (k, [0.0, 0.0])).collect(),
                }])
            }
            UvLayout::Udim => {
                let mut tiles: std::collections::BTreeMap<u32, Vec<(usize, [f64; 2])>> =
                    Default::default();
                for k in all {
                    let (lo, hi) = bbox(k);
                    let centre = [0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1])];
                    let (tu, tv) = (centre[0].floor(), centre[1].floor());
                    let fits = (0..2).all(|i| {
                        let t = [tu, tv][i];
                        lo[i] >= t - UV_TOL && hi[i] <= t + 1.0 + UV_TOL
                    });
                    if !(0.0..10.0).contains(&tu) || !(0.0..=99.0).contains(&tv) || !fits {
                        return Err(Error::InvalidMesh {
                            origin: self.origin.clone(),
                            message: format!(
                                "triangle {k} spans UV [{}, {}] × [{}, {}], which is not inside \
                                 one UDIM tile (u in 0..10, v ≥ 0, no triangle across a tile \
                                 edge)",
                                shown(lo[0]),
                                shown(hi[0]),
                                shown(lo[1]),
                                shown(hi[1])
                            ),
                        });
                    }
                    let number = 1001 + tu as u32 + 10 * tv as u32;
                    tiles.entry(number).or_default().push((k, [-tu, -tv]));
                }
                Ok(tiles
                    .into_iter()
                    .map(|(number, triangles)| UvPiece {
                        udim: Some(number),
                        triangles,
                    })
                    .collect())
            }
            UvLayout::Wrap => {
                let mut triangles = Vec::new();
                for k in all {
                    let (lo, hi) = bbox(k);
                    // Every period the triangle overlaps, moved onto the square.
                    let range = |i: usize| lo[i].floor() as i64..=(hi[i] - 1e-12).floor() as i64;
                    for pv in range(1) {
                        for pu in range(0) {
                            triangles.push((k, [-(pu as f64), -(pv as f64)]));
                        }
                    }
                }
                Ok(vec![UvPiece {
                    udim: None,
                    triangles,
                }])
            }
        }
    }
}

/// How a surface file is read (the scenario's `[surface]` keys).
#[derive(Clone, Debug, PartialEq)]
pub struct ReadOptions {
    /// Millimetres per file unit; `None`: the format's own unit (glTF:
    /// metres) or an error where it has none (OBJ).
    pub mm_per_unit: Option<f64>,
    /// Frames per second at which an animation is sampled (glTF) or played
    /// (OBJ sequence).
    pub frame_rate_hz: f64,
    /// glTF: the node whose mesh is read (default: the only node with a mesh).
    pub node: Option<String>,
    /// glTF: the animation (default: the first that animates the node's
    /// morph weights).
    pub animation: Option<String>,
    /// OBJ: a separate rest mesh (default: the first frame is the rest).
    pub rest: Option<std::path::PathBuf>,
}

impl Default for ReadOptions {
    fn default() -> Self {
        ReadOptions {
            mm_per_unit: None,
            frame_rate_hz: 30.0,
            node: None,
            animation: None,
            rest: None,
        }
    }
}

/// The length unit of a surface file (`mm`, `cm`, `m` or `in` in
/// scenario files).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize, Serialize, JsonSchema)]
#[serde(rename_all = "lowercase")]
pub enum LengthUnit {
    /// Millimetres.
    Mm,
    /// Centimetres.
    Cm,
    /// Metres.
    M,
    /// Inches.
    In,
}

impl LengthUnit {
    /// Millimetres per unit.
    pub fn mm(self) -> f64 {
        match self {
            LengthUnit::Mm => 1.0,
            LengthUnit::Cm => 10.0,
            LengthUnit::M => 1000.0,
            LengthUnit::In => 25.4,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn square(uvs: [[f64; 2]; 4]) -> AnimatedSurface {
        let rest = vec![
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(1.0, 0.0, 0.0),
            Vec3::new(1.0, 1.0, 0.0),
            Vec3::new(0.0, 1.0, 0.0),
        ];
        AnimatedSurface::from_split(
            SplitSurface {
                origin: "test".into(),
                frames: vec![rest.clone()],
                rest,
                uvs: uvs.to_vec(),
                triangles: vec![[0, 1, 2], [0, 2, 3]],
                labels: Vec::new(),
            },
            1.0,
            30.0,
        )
        .unwrap()
    }

    #[test]
    fn udim_tiles_and_wrap_copies() {
        let s = square([[1.2, 0.1], [1.8, 0.1], [1.8, 0.9], [1.2, 0.9]]);
        let pieces = s.pieces(UvLayout::Udim).unwrap();
        assert_eq!(pieces.len(), 1);
        assert_eq!(pieces[0].udim, Some(1002));
        assert_eq!(pieces[0].tag(), "1002_");
        assert!(s
            .pieces(UvLayout::Unit)
            .unwrap_err()
            .to_string()
            .contains("udim"));
        // Across u = 1: one copy per period it overlaps.
        let s = square([[0.8, 0.1], [1.3, 0.1], [1.3, 0.6], [0.8, 0.6]]);
        let wrap = s.pieces(UvLayout::Wrap).unwrap();
        assert_eq!(wrap[0].triangles.len(), 4);
        assert!(wrap[0].triangles.contains(&(0, [-1.0, -0.0])));
        let err = s.pieces(UvLayout::Udim).unwrap_err().to_string();
        assert!(err.contains("not inside one UDIM tile"), "{err}");
    }

    #[test]
    fn welding_keeps_seams_as_surface_vertices() {
        // Two charts meeting along the diagonal: vertices 0 and 2 twice.
        let rest = vec![
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(1.0, 0.0, 0.0),
            Vec3::new(1.0, 1.0, 0.0),
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(1.0, 1.0, 0.0),
            Vec3::new(0.0, 1.0, 0.0),
        ];
        let s = AnimatedSurface::from_split(
            SplitSurface {
                origin: "test".into(),
                frames: vec![rest.clone()],
                rest,
                uvs: vec![
                    [0.0, 0.0],
                    [0.4, 0.0],
                    [0.4, 0.4],
                    [0.6, 0.6],
                    [1.0, 1.0],
                    [0.6, 1.0],
                ],
                triangles: vec![[0, 1, 2], [3, 4, 5]],
                labels: Vec::new(),
            },
            10.0,
            30.0,
        )
        .unwrap();
        assert_eq!(s.positions.len(), 4);
        assert_eq!(s.top.vertices, vec![0, 1, 2, 0, 2, 3]);
        assert_eq!(s.positions[1], Vec3::new(10.0, 0.0, 0.0));
        assert!((s.area() - 100.0).abs() < 1e-12);
    }
}
