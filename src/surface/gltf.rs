//! glTF 2.0 animated surfaces (`.gltf` with embedded or external buffers,
//! `.glb`): read and write.
//!
//! Read: the mesh of one node (named, or the only node with a mesh), all its
//! triangle primitives, UVs from `TEXCOORD_0` (glTF's v runs down the image;
//! skinpatch's up, so `v = 1 − v_glTF`), morph targets' position
//! displacements, and one animation (`super::clip`): the node's morph
//! weights and the translation, rotation and scale of the node, its skin's
//! joints and their ancestors, sampled at the scenario's frame rate from
//! the animation's first to its last keyframe. Positions are the morphed
//! mesh placed by the node's world transform, or for a skinned mesh (with
//! `JOINTS_0`/`WEIGHTS_0`) linear blend skinning by the joints' world
//! matrices times their inverse bind matrices (the node's own transform is
//! then ignored, as glTF says). The rest is the scene's own pose without
//! animation or morph weights. glTF stores metres unless told otherwise,
//! with +y up; positions are turned to skinpatch's +z up as they are read
//! (`(x, y, z)` → `(x, −z, y)`), so a face modelled z-up in Blender comes
//! back z-up, in Blender's own coordinates.
//!
//! Write ([`write_glb`], in [`super::gltf_write`]): one primitive with
//! normals, one morph target per frame (the displacement from rest) and a
//! step animation that shows frame `k` at `k / rate` — what Blender and
//! other tools import as shape keys.

use std::path::Path;

use ::gltf::buffer::Source;
use ::gltf::mesh::Mode;
use nalgebra::{Matrix4, Vector4};

pub use super::gltf_write::{write_glb, write_glb_animation, MorphAnimation};

use super::gltf_write::from_y_up;
use super::{clip, AnimatedSurface, ReadOptions, SplitSurface};
use crate::error::{Error, Result};
use crate::mesh::Vec3;

/// Reads a glTF surface (see the module documentation).
pub fn read(path: &Path, options: &ReadOptions) -> Result<AnimatedSurface> {
    if !path.exists() {
        return Err(Error::not_found(path));
    }
    let bytes = read_at_most(path, MAX_FILE_BYTES)?;
    let invalid =
        |e: ::gltf::Error| Error::malformed(path, format!("not a valid glTF 2.0 file: {e}"));
    // The crate's own validation indexes without checking: it runs after
    // ours ([`super::gltf_check`]), which checks every index first.
    let file = ::gltf::Gltf::from_slice_without_validation(&bytes).map_err(invalid)?;
    let buffers = load_buffers(path, &file.document, file.blob.as_deref())?;
    let bad = |message: String| Error::InvalidMesh {
        origin: path.display().to_string(),
        message,
    };
    let declared: Vec<usize> = file.document.buffers().map(|b| b.length()).collect();
    super::gltf_check::check(file.document.as_json(), &declared).map_err(&bad)?;
    let document = ::gltf::Document::from_json(file.document.into_json()).map_err(invalid)?;
    let doc = &document;
    let roots: Vec<::gltf::Node<'_>> = match doc.default_scene().or_else(|| doc.scenes().next()) {
        Some(scene) => scene.nodes().collect(),
        None => Vec::new(),
    };
    let node = pick_node(doc, options.node.as_deref()).map_err(&bad)?;
    let mesh = node.mesh().expect("picked nodes have a mesh");
    let skin = node.skin();
    let mut split = SplitSurface {
        origin: path.display().to_string(),
        ..SplitSurface::default()
    };
    let raw = RawMesh::read(&mesh, skin.as_ref(), &buffers, &mut split).map_err(&bad)?;
    let defaults = default_weights(&node, &mesh, raw.targets.len()).map_err(&bad)?;
    let binding = match &skin {
        Some(skin) => Some(SkinBinding::read(skin, &buffers).map_err(&bad)?),
        None => None,
    };
    let mut movers = binding.as_ref().map_or(Vec::new(), |b| b.joints.clone());
    movers.push(node.index());
    let moving = clip::with_ancestors(doc, &movers);
    let n_targets = raw.targets.len();
    let clip = choose_clip(doc, &buffers, &node, n_targets, &moving, options).map_err(&bad)?;
    let rate = options.frame_rate_hz;
    // Keyframe times are f32: a sample within this of a key takes the key.
    let tol = 1e-4 / rate;
    // Without an animation every node keeps its own transform.
    let still = clip::Clip::default();
    let pose = |t: Option<f64>, weights: &[f64]| -> Vec<Vec3> {
        let local = |n: &::gltf::Node<'_>| clip.as_ref().unwrap_or(&still).local(n, t, tol);
        let world = clip::world_matrices(doc, &roots, &local);
        raw.pose(&world, node.index(), binding.as_ref(), weights)
            .iter()
            .map(from_y_up)
            .collect()
    };
    // Rest: the scene's own pose without morph targets.
    split.rest = pose(None, &vec![0.0; n_targets]);
    split.frames = match &clip {
        Some(c) => {
            let count = ((c.end - c.start) * rate + 1e-4).floor() + 1.0;
            // Each frame holds every vertex's position (24 bytes), twice
            // while the surface is built.
            let bytes = count * raw.positions.len() as f64 * 48.0;
            if let Some((needed, have)) =
                crate::memory::shortfall_gb(bytes.min(u64::MAX as f64) as u64)
            {
                return Err(bad(format!(
                    "{} from {} s to {} s at {rate} Hz is {count} frames of {} vertices, which \
                     need about {needed:.1} GB; {have:.1} GB are available: lower \
                     frame_rate_hz",
                    c.name,
                    c.start,
                    c.end,
                    raw.positions.len()
                )));
            }
            let frames = count as usize;
            log::info!(
                "{}: {} sampled from {} s to {} s at {rate} Hz: {frames} frames",
                path.display(),
                c.name,
                c.start,
                c.end
            );
            (0..frames)
                .map(|f| {
                    let t = c.start + f as f64 / rate;
                    let w = c
                        .weights
                        .as_ref()
                        .map(|w| w.at(t, tol))
                        .unwrap_or_else(|| defaults.clone());
                    pose(Some(t), &w)
                })
                .collect()
        }
        None => {
            log::warn!(
                "{}: no animation moves {}; the surface has one frame",
                path.display(),
                name_of(node.name(), "node", node.index())
            );
            vec![pose(None, &defaults)]
        }
    };
    let mm = options.mm_per_unit.unwrap_or(1000.0);
    AnimatedSurface::from_split(split, mm, options.frame_rate_hz)
}

/// The picked mesh in mesh space, gathered over its primitives (whose UVs,
/// triangles and vertex labels go straight into the [`SplitSurface`]).
struct RawMesh {
    positions: Vec<Vec3>,
    /// Per morph target, one displacement per vertex.
    targets: Vec<Vec<Vec3>>,
    /// Per vertex, (joint, normalised weight) pairs (skinned meshes only).
    influences: Vec<[(usize, f64); 4]>,
}

impl RawMesh {
    fn read(
        mesh: &::gltf::Mesh<'_>,
        skin: Option<&::gltf::Skin<'_>>,
        buffers: &[Vec<u8>],
        split: &mut SplitSurface,
    ) -> std::result::Result<RawMesh, String> {
        let mesh_name = name_of(mesh.name(), "mesh", mesh.index());
        let mut raw = RawMesh {
            positions: Vec::new(),
            targets: Vec::new(),
            influences: Vec::new(),
        };
        for (k, prim) in mesh.primitives().enumerate() {
            let label = format!("{mesh_name} primitive {}", prim.index());
            if prim.mode() != Mode::Triangles {
                return Err(format!(
                    "{label} is drawn as {:?}, not triangles",
                    prim.mode()
                ));
            }
            let reader = prim.reader(|b| buffers.get(b.index()).map(|d| d.as_slice()));
            let positions: Vec<[f32; 3]> = reader
                .read_positions()
                .ok_or_else(|| format!("{label} has no POSITION"))?
                .collect();
            let n = positions.len();
            let uvs: Vec<[f32; 2]> = reader
                .read_tex_coords(0)
                .ok_or_else(|| {
                    format!("{label} has no TEXCOORD_0 (UVs); unwrap the mesh before exporting it")
                })?
                .into_f32()
                .collect();
            if uvs.len() != n {
                return Err(format!("{label} has {} UVs for {n} positions", uvs.len()));
            }
            let indices: Vec<u32> = match reader.read_indices() {
                Some(i) => i.into_u32().collect(),
                None => (0..n as u32).collect(),
            };
            if !indices.len().is_multiple_of(3) {
                return Err(format!(
                    "{label} has {} indices, not a multiple of 3",
                    indices.len()
                ));
            }
            if let Some(&i) = indices.iter().find(|&&i| i as usize >= n) {
                return Err(format!("{label} has index {i}, but {n} vertices"));
            }
            let prim_targets: Vec<Vec<Vec3>> = reader
                .read_morph_targets()
                .map(|(pos, _, _)| match pos {
                    Some(d) => d
                        .map(|d| Vec3::new(d[0] as f64, d[1] as f64, d[2] as f64))
                        .collect(),
                    None => vec![Vec3::zeros(); n],
                })
                .collect();
            if k == 0 {
                raw.targets = vec![Vec::new(); prim_targets.len()];
            } else if raw.targets.len() != prim_targets.len() {
                return Err(format!(
                    "morph target count mismatch: {label} has {} morph targets, primitive 0 \
                     has {}",
                    prim_targets.len(),
                    raw.targets.len()
                ));
            }
            if let Some((t, d)) = prim_targets.iter().enumerate().find(|(_, d)| d.len() != n) {
                return Err(format!(
                    "{label} morph target {t} has {} displacements for {n} vertices",
                    d.len()
                ));
            }
            if let Some(skin) = skin {
                raw.influences
                    .extend(read_influences(&reader, skin, n, &label)?);
            }
            let base = raw.positions.len();
            for (t, d) in prim_targets.into_iter().enumerate() {
                raw.targets[t].extend(d);
            }
            for (i, (pos, uv)) in positions.iter().zip(&uvs).enumerate() {
                raw.positions
                    .push(Vec3::new(pos[0] as f64, pos[1] as f64, pos[2] as f64));
                split.uvs.push([uv[0] as f64, 1.0 - uv[1] as f64]);
                split.labels.push(format!("{label} vertex {i}"));
            }
            split.triangles.extend(
                indices
                    .chunks_exact(3)
                    .map(|c| [0, 1, 2].map(|k| base + c[k] as usize)),
            );
        }
        Ok(raw)
    }

    /// The vertices morphed by `weights` and placed by the nodes' world
    /// matrices `world`: linear blend skinning with `binding`, else the
    /// transform of node `node`.
    fn pose(
        &self,
        world: &[Matrix4<f64>],
        node: usize,
        binding: Option<&SkinBinding>,
        weights: &[f64],
    ) -> Vec<Vec3> {
        let morphed = |v: usize| {
            let mut p = self.positions[v];
            for (k, &w) in weights.iter().enumerate() {
                if w != 0.0 {
                    p += self.targets[k][v] * w;
                }
            }
            p.push(1.0)
        };
        match binding {
            Some(binding) => {
                let matrices: Vec<Matrix4<f64>> = binding
                    .joints
                    .iter()
                    .zip(&binding.inverse_bind)
                    .map(|(&j, ibm)| world[j] * ibm)
                    .collect();
                (0..self.positions.len())
                    .map(|v| {
                        let p = morphed(v);
                        let q: Vector4<f64> = self.influences[v]
                            .iter()
                            .filter(|(_, w)| *w != 0.0)
                            .map(|&(j, w)| matrices[j] * p * w)
                            .sum();
                        Vec3::new(q.x, q.y, q.z)
                    })
                    .collect()
            }
            None => {
                let m = world[node];
                (0..self.positions.len())
                    .map(|v| {
                        let q = m * morphed(v);
                        Vec3::new(q.x, q.y, q.z)
                    })
                    .collect()
            }
        }
    }
}

/// A skinned primitive's `JOINTS_0`/`WEIGHTS_0`, checked against the skin's
/// joint count, with each vertex's weights normalised to sum to one.
fn read_influences<'a, 's, F>(
    reader: &::gltf::mesh::Reader<'a, 's, F>,
    skin: &::gltf::Skin<'_>,
    n: usize,
    label: &str,
) -> std::result::Result<Vec<[(usize, f64); 4]>, String>
where
    F: Clone + Fn(::gltf::Buffer<'a>) -> Option<&'s [u8]>,
{
    let joints: Vec<[u16; 4]> = reader
        .read_joints(0)
        .ok_or_else(|| format!("{label} is skinned but has no JOINTS_0"))?
        .into_u16()
        .collect();
    let weights: Vec<[f32; 4]> = reader
        .read_weights(0)
        .ok_or_else(|| format!("{label} is skinned but has no WEIGHTS_0"))?
        .into_f32()
        .collect();
    let count = skin.joints().count();
    if joints.len() != n || weights.len() != n {
        return Err(format!(
            "{label} has {} JOINTS_0 and {} WEIGHTS_0 for {n} vertices",
            joints.len(),
            weights.len()
        ));
    }
    let mut influences = Vec::with_capacity(n);
    for (i, (j, w)) in joints.iter().zip(&weights).enumerate() {
        let total: f64 = w.iter().map(|&x| x as f64).sum();
        let used = j.iter().zip(w).filter(|(_, &w)| w != 0.0);
        if let Some((&j, _)) = used.clone().find(|(&j, _)| j as usize >= count) {
            return Err(format!(
                "{label} vertex {i} uses joint {j}, but the skin has {count}"
            ));
        }
        if !(total > 0.0 && total.is_finite() && w.iter().all(|&x| x >= 0.0)) {
            return Err(format!("{label} vertex {i} has skin weights {w:?}"));
        }
        influences.push(std::array::from_fn(|k| {
            (j[k] as usize, w[k] as f64 / total)
        }));
    }
    Ok(influences)
}

/// The morph weights without animation: the node's, else the mesh's, else
/// zeros; one per morph target.
fn default_weights(
    node: &::gltf::Node<'_>,
    mesh: &::gltf::Mesh<'_>,
    n_targets: usize,
) -> std::result::Result<Vec<f64>, String> {
    let defaults: Vec<f64> = node
        .weights()
        .or(mesh.weights())
        .map(|w| w.iter().map(|&x| x as f64).collect())
        .unwrap_or_else(|| vec![0.0; n_targets]);
    if defaults.len() != n_targets {
        return Err(format!(
            "morph target count mismatch: {} has {} default morph weights for {n_targets} \
             morph targets",
            name_of(mesh.name(), "mesh", mesh.index()),
            defaults.len()
        ));
    }
    Ok(defaults)
}

/// A skin's joints (node indices) and inverse bind matrices: joint j moves
/// its vertices by world(joint) · inverse bind matrix.
struct SkinBinding {
    joints: Vec<usize>,
    inverse_bind: Vec<Matrix4<f64>>,
}

impl SkinBinding {
    fn read(
        skin: &::gltf::Skin<'_>,
        buffers: &[Vec<u8>],
    ) -> std::result::Result<SkinBinding, String> {
        let joints: Vec<usize> = skin.joints().map(|j| j.index()).collect();
        let inverse_bind: Vec<Matrix4<f64>> = match skin
            .reader(|b| buffers.get(b.index()).map(|d| d.as_slice()))
            .read_inverse_bind_matrices()
        {
            Some(m) => m.map(|m| Matrix4::from_fn(|r, c| m[c][r] as f64)).collect(),
            None => vec![Matrix4::identity(); joints.len()],
        };
        if inverse_bind.len() != joints.len() {
            return Err(format!(
                "the skin has {} inverse bind matrices for {} joints",
                inverse_bind.len(),
                joints.len()
            ));
        }
        Ok(SkinBinding {
            joints,
            inverse_bind,
        })
    }
}

fn name_of(name: Option<&str>, kind: &str, index: usize) -> String {
    match name {
        Some(n) => format!("{kind} '{n}'"),
        None => format!("{kind} {index}"),
    }
}

/// The bytes of every buffer: the GLB's binary chunk, a base64 data URI, or
/// a file beside the glTF.
/// Largest glTF or GLB file, and largest external buffer, read (4 GiB).
const MAX_FILE_BYTES: usize = 1 << 32;

/// The first `limit` bytes of the regular file `path` (a device or a pipe,
/// which may never end, is refused; so is a file longer than
/// [`MAX_FILE_BYTES`]).
fn read_at_most(path: &Path, limit: usize) -> Result<Vec<u8>> {
    use std::io::Read;
    let meta = std::fs::metadata(path).map_err(|e| Error::io(path, e))?;
    if !meta.is_file() {
        return Err(Error::malformed(path, "not a regular file"));
    }
    let limit = limit.min(MAX_FILE_BYTES);
    if meta.len() > MAX_FILE_BYTES as u64 && limit == MAX_FILE_BYTES {
        return Err(Error::malformed(
            path,
            format!(
                "{} bytes: larger than the {MAX_FILE_BYTES} bytes read",
                meta.len()
            ),
        ));
    }
    let file = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
    let mut out = Vec::with_capacity(limit.min(meta.len() as usize));
    file.take(limit as u64)
        .read_to_end(&mut out)
        .map_err(|e| Error::io(path, e))?;
    Ok(out)
}

fn load_buffers(path: &Path, doc: &::gltf::Document, blob: Option<&[u8]>) -> Result<Vec<Vec<u8>>> {
    use base64::Engine;
    let mut out = Vec::new();
    for buffer in doc.buffers() {
        let data = match buffer.source() {
            Source::Bin => blob
                .ok_or_else(|| {
                    Error::malformed(
                        path,
                        format!(
                            "buffer {} refers to a GLB chunk the file lacks",
                            buffer.index()
                        ),
                    )
                })?
                .to_vec(),
            Source::Uri(uri) if uri.starts_with("data:") => {
                let payload = uri.split_once(";base64,").map(|(_, p)| p).ok_or_else(|| {
                    Error::malformed(
                        path,
                        format!(
                            "buffer {} has a data URI that is not base64",
                            buffer.index()
                        ),
                    )
                })?;
                base64::engine::general_purpose::STANDARD
                    .decode(payload)
                    .map_err(|e| {
                        Error::malformed(path, format!("buffer {}: {e}", buffer.index()))
                    })?
            }
            Source::Uri(uri) => {
                let file = path.parent().unwrap_or(Path::new(".")).join(uri);
                if !file.exists() {
                    return Err(Error::malformed(
                        path,
                        format!(
                            "buffer {} is the file {}, which does not exist",
                            buffer.index(),
                            file.display()
                        ),
                    ));
                }
                read_at_most(&file, buffer.length())?
            }
        };
        if data.len() < buffer.length() {
            return Err(Error::malformed(
                path,
                format!(
                    "buffer {} holds {} bytes, the file declares {}",
                    buffer.index(),
                    data.len(),
                    buffer.length()
                ),
            ));
        }
        out.push(data);
    }
    Ok(out)
}

/// The node whose mesh is read.
fn pick_node<'a>(
    doc: &'a ::gltf::Document,
    wanted: Option<&str>,
) -> std::result::Result<::gltf::Node<'a>, String> {
    let with_mesh: Vec<_> = doc.nodes().filter(|n| n.mesh().is_some()).collect();
    let names = || {
        with_mesh
            .iter()
            .map(|n| name_of(n.name(), "node", n.index()))
            .collect::<Vec<_>>()
            .join(", ")
    };
    match wanted {
        Some(name) => with_mesh
            .iter()
            .find(|n| n.name() == Some(name))
            .cloned()
            .ok_or_else(|| {
                format!(
                    "has no node '{name}' with a mesh (surface.node); nodes with meshes: {}",
                    names()
                )
            }),
        None => match with_mesh.len() {
            0 => Err("has no node with a mesh".into()),
            1 => Ok(with_mesh[0].clone()),
            _ => Err(format!(
                "has several nodes with meshes ({}); choose one with surface.node",
                names()
            )),
        },
    }
}

/// The animation that moves the surface: `surface.animation` by name, or
/// the first that animates the node's morph weights or the transform of a
/// node in `moving` (the node, its skin's joints and their ancestors).
fn choose_clip(
    doc: &::gltf::Document,
    buffers: &[Vec<u8>],
    node: &::gltf::Node<'_>,
    n_targets: usize,
    moving: &[bool],
    options: &ReadOptions,
) -> std::result::Result<Option<clip::Clip>, String> {
    let animations: Vec<_> = doc.animations().collect();
    match &options.animation {
        Some(name) => {
            let a = animations
                .iter()
                .find(|a| a.name() == Some(name.as_str()))
                .ok_or_else(|| {
                    let names: Vec<String> = animations
                        .iter()
                        .map(|a| name_of(a.name(), "animation", a.index()))
                        .collect();
                    format!(
                        "has no animation '{name}' (surface.animation); animations: {}",
                        if names.is_empty() {
                            "none".into()
                        } else {
                            names.join(", ")
                        }
                    )
                })?;
            let clip = clip::Clip::read(a, buffers, node.index(), n_targets, moving)?;
            if clip.is_empty() {
                return Err(format!(
                    "animation '{name}' moves neither the morph weights of the mesh's node nor \
                     its transform or joints"
                ));
            }
            Ok(Some(clip))
        }
        None => {
            for a in &animations {
                let clip = clip::Clip::read(a, buffers, node.index(), n_targets, moving)?;
                if !clip.is_empty() {
                    return Ok(Some(clip));
                }
            }
            Ok(None)
        }
    }
}
