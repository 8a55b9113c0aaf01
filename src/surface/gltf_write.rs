//! Writing animated surfaces as binary glTF 2.0 (`.glb`), as Blender,
//! Houdini and three.js import them.
//!
//! - Axes: glTF is +y up (right-handed, metres); skinpatch is +z up (mm). A
//!   position `(x, y, z)` is written as `(x, z, −y)` metres — a rotation, so
//!   windings and handedness hold — and [`super::gltf::read`] turns it back.
//! - One primitive: `POSITION`, `NORMAL` (area-weighted vertex normals, the
//!   same on both sides of a UV seam), `TANGENT` (along u, with the sign
//!   that makes the bitangent point up the image), `TEXCOORD_0` (glTF's v
//!   runs down the image: `1 − v`) and the indices.
//! - One morph target per shape with `POSITION`, `NORMAL` and `TANGENT`
//!   (xyz) displacements,
//!   and an animation of the morph weights (keyed at the frame times in
//!   seconds; a tool keying at its own frame rate places a key every
//!   `its rate / the scenario's rate` frames).
//! - A skin-like material (`pbrMetallicRoughness`, not metallic) that names
//!   the neutral microstructure normal map as its `normalTexture` when the
//!   run wrote one (tangent space, +x along u, +y along v: glTF's own
//!   convention).

use std::path::Path;

use super::AnimatedSurface;
use crate::error::{Error, Result};
use crate::mesh::Vec3;

/// `ARRAY_BUFFER` and `ELEMENT_ARRAY_BUFFER`: a buffer view's target.
const VERTEX_DATA: u32 = 34962;
const INDEX_DATA: u32 = 34963;

/// A skinpatch position (z up) in glTF's axes (y up), same unit.
pub fn to_y_up(p: &Vec3) -> Vec3 {
    Vec3::new(p.x, p.z, -p.y)
}

/// A glTF position (y up) in skinpatch's axes (z up), same unit.
pub fn from_y_up(p: &Vec3) -> Vec3 {
    Vec3::new(p.x, -p.z, p.y)
}

/// Writes `surface` as a binary glTF: one morph target per frame (the
/// displacement from rest) and a step animation showing frame `k` at
/// `k / rate` seconds. `normal_texture`: the URI of a normal map for the
/// material (relative to the file), if any.
pub fn write_glb(
    path: &Path,
    surface: &AnimatedSurface,
    normal_texture: Option<&str>,
) -> Result<()> {
    let n = surface.frames.len();
    let animation = MorphAnimation {
        names: (0..n).map(|k| format!("frame_{k:04}")).collect(),
        targets: surface
            .frames
            .iter()
            .map(|x| {
                x.iter()
                    .zip(&surface.positions)
                    .map(|(a, b)| a - b)
                    .collect()
            })
            .collect(),
        times_s: (0..n).map(|k| surface.time(k)).collect(),
        weights: (0..n)
            .map(|k| (0..n).map(|t| if t == k { 1.0 } else { 0.0 }).collect())
            .collect(),
        linear: false,
    };
    write_glb_animation(path, surface, &animation, normal_texture)
}

/// Named morph targets and an animation of their weights.
#[derive(Clone, Debug, PartialEq)]
pub struct MorphAnimation {
    /// Target names (glTF `extras.targetNames`, Blender's shape key names).
    pub names: Vec<String>,
    /// Per target, the displacement of every position (mm).
    pub targets: Vec<Vec<Vec3>>,
    /// Keyframe times (s), increasing.
    pub times_s: Vec<f64>,
    /// Per keyframe, the weight of every target.
    pub weights: Vec<Vec<f64>>,
    /// Linear interpolation between keyframes (else step).
    pub linear: bool,
}

/// Unit normals of the surface vertices with the rest positions moved by
/// `displacement` (mm, per position; none: at rest), in glTF's axes: the
/// area-weighted sum over the triangles at each position, so the vertices
/// a UV seam splits share one normal.
fn vertex_normals(surface: &AnimatedSurface, displacement: Option<&[Vec3]>) -> Vec<Vec3> {
    let top = &surface.top;
    let at = |v: usize| {
        let p = surface.positions[top.vertices[v]];
        displacement.map_or(p, |d| p + d[top.vertices[v]])
    };
    let mut sums = vec![Vec3::zeros(); surface.positions.len()];
    for t in &top.triangles {
        let [a, b, c] = t.map(at);
        // Twice the area times the unit normal.
        let n = (b - a).cross(&(c - a));
        for &v in t {
            sums[top.vertices[v]] += n;
        }
    }
    top.vertices
        .iter()
        .map(|&p| {
            let n = sums[p];
            let len = n.norm();
            to_y_up(&if len > 0.0 { n / len } else { Vec3::z() })
        })
        .collect()
}

/// Tangents of the surface vertices with the rest positions moved by
/// `displacement` (as [`vertex_normals`]), in glTF's axes, `[x, y, z, w]`:
/// `xyz` the unit direction of increasing u in the tangent plane of
/// `normals` (glTF axes, of the same shape), `w` = ±1 so that
/// `w · normal × xyz` points along increasing skinpatch v (up the image, the
/// +y of the normal maps).
fn vertex_tangents(
    surface: &AnimatedSurface,
    displacement: Option<&[Vec3]>,
    normals: &[Vec3],
) -> Vec<[f32; 4]> {
    let top = &surface.top;
    let at = |v: usize| {
        let p = surface.positions[top.vertices[v]];
        to_y_up(&displacement.map_or(p, |d| p + d[top.vertices[v]]))
    };
    let mut along_u = vec![Vec3::zeros(); top.vertices.len()];
    let mut along_v = along_u.clone();
    for t in &top.triangles {
        let [p0, p1, p2] = t.map(at);
        let [w0, w1, w2] = t.map(|v| top.uvs[v]);
        let (e1, e2) = (p1 - p0, p2 - p0);
        let (du1, dv1, du2, dv2) = (w1[0] - w0[0], w1[1] - w0[1], w2[0] - w0[0], w2[1] - w0[1]);
        let det = du1 * dv2 - du2 * dv1;
        if det == 0.0 || !det.is_finite() {
            continue;
        }
        // dP/du and dP/dv of the triangle, weighted by its UV area's sign.
        let tu = (e1 * dv2 - e2 * dv1) / det.abs();
        let tv = (e2 * du1 - e1 * du2) / det.abs();
        for &v in t {
            along_u[v] += tu;
            along_v[v] += tv;
        }
    }
    normals
        .iter()
        .zip(along_u.iter().zip(&along_v))
        .map(|(n, (u, v))| {
            let mut t = u - n * n.dot(u);
            let degenerate = t.norm() <= 1e-12 * u.norm().max(1e-300) || !t.norm().is_finite();
            if degenerate {
                // No UV gradient: any direction in the tangent plane.
                let helper = if n.x.abs() < 0.9 {
                    Vec3::x()
                } else {
                    Vec3::y()
                };
                t = helper - n * n.dot(&helper);
            }
            let t = t / t.norm();
            let w = if n.cross(&t).dot(v) < 0.0 { -1.0 } else { 1.0 };
            [t.x as f32, t.y as f32, t.z as f32, w]
        })
        .collect()
}

/// Writes the rest of `surface` (its positions and UV layout; its frames are
/// not used) with the morph targets and weight animation of `animation` as
/// a binary glTF (see the module documentation). `normal_texture`: the URI
/// of the material's normal map (relative to the file), if any.
pub fn write_glb_animation(
    path: &Path,
    surface: &AnimatedSurface,
    animation: &MorphAnimation,
    normal_texture: Option<&str>,
) -> Result<()> {
    let top = &surface.top;
    // Positions relative to the centre of the bounds (the node's
    // translation), so f32 keeps more of them; displacements from the f64
    // difference, so a frame's strain loses only the rounding of the rest.
    let (lo, hi) = surface.bounds();
    let centre = ((lo + hi) * 0.5).map(|c| ((c / 1000.0) as f32) as f64 * 1000.0);
    let metres = |p: &Vec3| {
        let q = to_y_up(p);
        [q.x, q.y, q.z].map(|c| (c / 1000.0) as f32)
    };
    let unit = |n: &Vec3| [n.x, n.y, n.z].map(|c| c as f32);
    let mut glb = GlbBuffers::default();
    let rest: Vec<f32> = top
        .vertices
        .iter()
        .flat_map(|&v| metres(&(surface.positions[v] - centre)))
        .collect();
    let position = glb.floats(&rest, "VEC3", 3, true, Some(VERTEX_DATA));
    let rest_normals = vertex_normals(surface, None);
    let normals: Vec<f32> = rest_normals.iter().flat_map(unit).collect();
    let normal = glb.floats(&normals, "VEC3", 3, false, Some(VERTEX_DATA));
    let rest_tangents = vertex_tangents(surface, None, &rest_normals);
    let tangents: Vec<f32> = rest_tangents.iter().flatten().copied().collect();
    let tangent = glb.floats(&tangents, "VEC4", 4, false, Some(VERTEX_DATA));
    let uvs: Vec<f32> = top
        .uvs
        .iter()
        .flat_map(|w| [w[0] as f32, (1.0 - w[1]) as f32])
        .collect();
    let texcoord = glb.floats(&uvs, "VEC2", 2, false, Some(VERTEX_DATA));
    let mut targets = Vec::new();
    for displacement in &animation.targets {
        let delta: Vec<f32> = top
            .vertices
            .iter()
            .flat_map(|&v| metres(&displacement[v]))
            .collect();
        let deformed_normals = vertex_normals(surface, Some(displacement));
        let turned: Vec<f32> = deformed_normals
            .iter()
            .zip(&rest_normals)
            .flat_map(|(n, n0)| unit(&(n - n0)))
            .collect();
        let swung: Vec<f32> = vertex_tangents(surface, Some(displacement), &deformed_normals)
            .iter()
            .zip(&rest_tangents)
            .flat_map(|(t, t0)| [t[0] - t0[0], t[1] - t0[1], t[2] - t0[2]])
            .collect();
        targets.push(serde_json::json!({
            "POSITION": glb.floats(&delta, "VEC3", 3, true, Some(VERTEX_DATA)),
            "NORMAL": glb.floats(&turned, "VEC3", 3, false, Some(VERTEX_DATA)),
            "TANGENT": glb.floats(&swung, "VEC3", 3, false, Some(VERTEX_DATA)),
        }));
    }
    let n_targets = animation.targets.len();
    let times: Vec<f32> = animation.times_s.iter().map(|&t| t as f32).collect();
    let input = glb.floats(&times, "SCALAR", 1, true, None);
    let weights: Vec<f32> = animation
        .weights
        .iter()
        .flat_map(|w| w.iter().map(|&x| x as f32))
        .collect();
    let output = glb.floats(&weights, "SCALAR", 1, false, None);
    // Indices after the floats, so every view stays 4-byte aligned.
    let indices = glb.indices(&top.triangles);
    let name = Path::new(&surface.origin)
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "surface".into());
    let mut material = serde_json::json!({
        "name": "skin",
        "pbrMetallicRoughness": {
            "baseColorFactor": [0.80, 0.57, 0.47, 1.0],
            "metallicFactor": 0.0,
            "roughnessFactor": 0.45
        }
    });
    let mut json = serde_json::json!({
        "asset": {
            "version": "2.0",
            "generator": concat!("skinpatch ", env!("CARGO_PKG_VERSION")),
            "extras": { "frame_rate_hz": surface.frame_rate_hz }
        },
        "scene": 0,
        "scenes": [{ "nodes": [0] }],
        "nodes": [{ "name": name, "mesh": 0, "translation": metres(&centre) }],
        "meshes": [{
            "name": name,
            "primitives": [{
                "attributes": {
                    "POSITION": position, "NORMAL": normal, "TANGENT": tangent,
                    "TEXCOORD_0": texcoord
                },
                "indices": indices,
                "material": 0,
                "mode": 4,
                "targets": targets
            }],
            "weights": vec![0.0; n_targets],
            "extras": { "targetNames": animation.names }
        }],
        "animations": [{
            "name": "animation",
            "samplers": [{
                "input": input, "output": output,
                "interpolation": if animation.linear { "LINEAR" } else { "STEP" }
            }],
            "channels": [{ "sampler": 0, "target": { "node": 0, "path": "weights" } }]
        }],
        "buffers": [{ "byteLength": glb.bin.len() }],
        "bufferViews": glb.views,
        "accessors": glb.accessors
    });
    if let Some(uri) = normal_texture {
        material["normalTexture"] = serde_json::json!({ "index": 0 });
        json["textures"] = serde_json::json!([{ "source": 0, "sampler": 0 }]);
        json["images"] = serde_json::json!([{ "uri": uri, "mimeType": "image/png" }]);
        // Linear filtering with mipmaps; the map repeats like the skin.
        json["samplers"] = serde_json::json!([{
            "magFilter": 9729, "minFilter": 9987, "wrapS": 10497, "wrapT": 10497
        }]);
    }
    json["materials"] = serde_json::json!([material]);
    let text = serde_json::to_vec(&json).map_err(|e| Error::malformed(path, e.to_string()))?;
    crate::mesh::io::write_atomically(path, &glb_container(text, glb.bin))
}

/// The binary chunk of a GLB file with its buffer views and accessors.
#[derive(Default)]
struct GlbBuffers {
    bin: Vec<u8>,
    views: Vec<serde_json::Value>,
    accessors: Vec<serde_json::Value>,
}

impl GlbBuffers {
    /// Appends `data` as a float accessor of `components` per element
    /// (`kind`: "SCALAR", "VEC2", "VEC3"), with per-component min/max when
    /// `bounds` (POSITION requires them) and the view's `target` when given;
    /// returns the accessor's index.
    fn floats(
        &mut self,
        data: &[f32],
        kind: &str,
        components: usize,
        bounds: bool,
        target: Option<u32>,
    ) -> usize {
        let offset = self.bin.len();
        self.bin.extend(data.iter().flat_map(|x| x.to_le_bytes()));
        let mut view = serde_json::json!({
            "buffer": 0, "byteOffset": offset, "byteLength": data.len() * 4
        });
        if let Some(target) = target {
            view["target"] = serde_json::json!(target);
        }
        self.views.push(view);
        let mut acc = serde_json::json!({
            "bufferView": self.views.len() - 1, "componentType": 5126,
            "count": data.len() / components, "type": kind
        });
        if bounds {
            let (lo, hi): (Vec<f32>, Vec<f32>) = (0..components)
                .map(|c| {
                    let col = data.iter().skip(c).step_by(components);
                    (
                        col.clone().copied().fold(f32::INFINITY, f32::min),
                        col.copied().fold(f32::NEG_INFINITY, f32::max),
                    )
                })
                .unzip();
            acc["min"] = serde_json::json!(lo);
            acc["max"] = serde_json::json!(hi);
        }
        self.accessors.push(acc);
        self.accessors.len() - 1
    }

    /// Appends the triangles' vertex indices as a u32 accessor; returns its
    /// index.
    fn indices(&mut self, triangles: &[[usize; 3]]) -> usize {
        let offset = self.bin.len();
        self.bin.extend(
            triangles
                .iter()
                .flatten()
                .flat_map(|&i| (i as u32).to_le_bytes()),
        );
        self.views.push(serde_json::json!({
            "buffer": 0, "byteOffset": offset, "byteLength": triangles.len() * 12,
            "target": INDEX_DATA
        }));
        self.accessors.push(serde_json::json!({
            "bufferView": self.views.len() - 1, "componentType": 5125,
            "count": triangles.len() * 3, "type": "SCALAR"
        }));
        self.accessors.len() - 1
    }
}

/// A GLB file: the 12-byte header, the JSON chunk (padded with spaces) and
/// the binary chunk (padded with zeros), each 4-byte aligned.
fn glb_container(mut text: Vec<u8>, mut bin: Vec<u8>) -> Vec<u8> {
    while !text.len().is_multiple_of(4) {
        text.push(b' ');
    }
    while !bin.len().is_multiple_of(4) {
        bin.push(0);
    }
    let total = 12 + 8 + text.len() + 8 + bin.len();
    let mut out = Vec::with_capacity(total);
    out.extend(b"glTF");
    out.extend(2u32.to_le_bytes());
    out.extend((total as u32).to_le_bytes());
    out.extend((text.len() as u32).to_le_bytes());
    out.extend(b"JSON");
    out.extend(text);
    out.extend((bin.len() as u32).to_le_bytes());
    out.extend(b"BIN\0");
    out.extend(bin);
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn axes_turn_as_a_rotation_and_back() {
        let p = Vec3::new(1.0, 2.0, 3.0);
        assert_eq!(to_y_up(&p), Vec3::new(1.0, 3.0, -2.0));
        assert_eq!(from_y_up(&to_y_up(&p)), p);
        // z up becomes y up; a right-handed frame stays right-handed.
        let [x, y, z] = [Vec3::x(), Vec3::y(), Vec3::z()].map(|e| to_y_up(&e));
        assert_eq!(z, Vec3::y());
        assert_eq!(x.cross(&y), z);
    }
}
