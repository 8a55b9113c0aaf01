//! glTF 2.0 animated surfaces (`.gltf` with embedded or external buffers,
//! `.glb`): read and write.
//!
//! Read: the mesh of one node (named, or the only node with a mesh), all its
//! triangle primitives, positions with the node's world transform, UVs from
//! `TEXCOORD_0` (glTF's v runs down the image; skinpatch's up, so
//! `v = 1 − v_glTF`), morph targets' position displacements, and one
//! animation of the node's morph weights (step, linear or cubic-spline
//! sampler) sampled at the scenario's frame rate from its first to its last
//! keyframe. glTF stores metres unless told otherwise. Skins and node
//! animations are not applied (a warning says so): rigid motion does not
//! change the strain.
//!
//! Write ([`write_glb`]): one primitive, one morph target per frame (the
//! displacement from rest) and a step animation that shows frame `k` at
//! `k / rate` — what Blender and other tools import as shape keys.

use std::path::Path;

use ::gltf::animation::{Interpolation, Property};
use ::gltf::buffer::Source;
use ::gltf::mesh::Mode;
use nalgebra::{Matrix4, Vector4};

use super::{AnimatedSurface, ReadOptions, SplitSurface};
use crate::error::{Error, Result};
use crate::mesh::Vec3;

/// Reads a glTF surface (see the module documentation).
pub fn read(path: &Path, options: &ReadOptions) -> Result<AnimatedSurface> {
    if !path.exists() {
        return Err(Error::not_found(path));
    }
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    let file = ::gltf::Gltf::from_slice(&bytes)
        .map_err(|e| Error::malformed(path, format!("not a valid glTF 2.0 file: {e}")))?;
    let doc = &file.document;
    let buffers = load_buffers(path, doc, file.blob.as_deref())?;
    let bad = |message: String| Error::InvalidMesh {
        origin: path.display().to_string(),
        message,
    };
    let (node, world) = pick_node(doc, options.node.as_deref()).map_err(&bad)?;
    let mesh = node.mesh().expect("picked nodes have a mesh");
    let mesh_name = name_of(mesh.name(), "mesh", mesh.index());
    if node.skin().is_some() {
        log::warn!(
            "{}: node {} has a skin; skinning is not applied (the mesh is read at its bind \
             pose with its morph targets)",
            path.display(),
            name_of(node.name(), "node", node.index())
        );
    }
    let linear = world.fixed_view::<3, 3>(0, 0).into_owned();
    let place = |p: [f32; 3]| {
        let q = world * Vector4::new(p[0] as f64, p[1] as f64, p[2] as f64, 1.0);
        Vec3::new(q.x, q.y, q.z)
    };
    let mut split = SplitSurface {
        origin: path.display().to_string(),
        ..SplitSurface::default()
    };
    // Per target, per split vertex: the displacement (world, file units).
    let mut targets: Vec<Vec<Vec3>> = Vec::new();
    let mut target_count = None;
    for prim in mesh.primitives() {
        let p = prim.index();
        if prim.mode() != Mode::Triangles {
            return Err(bad(format!(
                "{mesh_name} primitive {p} is drawn as {:?}, not triangles",
                prim.mode()
            )));
        }
        let reader = prim.reader(|b| buffers.get(b.index()).map(|d| d.as_slice()));
        let positions: Vec<[f32; 3]> = reader
            .read_positions()
            .ok_or_else(|| bad(format!("{mesh_name} primitive {p} has no POSITION")))?
            .collect();
        let uvs: Vec<[f32; 2]> = reader
            .read_tex_coords(0)
            .ok_or_else(|| {
                bad(format!(
                    "{mesh_name} primitive {p} has no TEXCOORD_0 (UVs); unwrap the mesh \
                     before exporting it"
                ))
            })?
            .into_f32()
            .collect();
        if uvs.len() != positions.len() {
            return Err(bad(format!(
                "{mesh_name} primitive {p} has {} UVs for {} positions",
                uvs.len(),
                positions.len()
            )));
        }
        let n = positions.len();
        let indices: Vec<u32> = match reader.read_indices() {
            Some(i) => i.into_u32().collect(),
            None => (0..n as u32).collect(),
        };
        if !indices.len().is_multiple_of(3) {
            return Err(bad(format!(
                "{mesh_name} primitive {p} has {} indices, not a multiple of 3",
                indices.len()
            )));
        }
        if let Some(&i) = indices.iter().find(|&&i| i as usize >= n) {
            return Err(bad(format!(
                "{mesh_name} primitive {p} has index {i}, but {n} vertices"
            )));
        }
        let prim_targets: Vec<Vec<Vec3>> = reader
            .read_morph_targets()
            .map(|(pos, _, _)| match pos {
                Some(d) => d
                    .map(|d| linear * Vec3::new(d[0] as f64, d[1] as f64, d[2] as f64))
                    .collect(),
                None => vec![Vec3::zeros(); n],
            })
            .collect();
        match target_count {
            None => {
                target_count = Some(prim_targets.len());
                targets = vec![Vec::new(); prim_targets.len()];
            }
            Some(count) if count != prim_targets.len() => {
                return Err(bad(format!(
                    "{mesh_name} primitive {p} has {} morph targets, primitive 0 has {count}",
                    prim_targets.len()
                )));
            }
            Some(_) => {}
        }
        if let Some((t, d)) = prim_targets.iter().enumerate().find(|(_, d)| d.len() != n) {
            return Err(bad(format!(
                "{mesh_name} primitive {p} morph target {t} has {} displacements for {n} \
                 vertices",
                d.len()
            )));
        }
        let base = split.rest.len();
        for (t, d) in prim_targets.into_iter().enumerate() {
            targets[t].extend(d);
        }
        for (i, (pos, uv)) in positions.iter().zip(&uvs).enumerate() {
            split.rest.push(place(*pos));
            split.uvs.push([uv[0] as f64, 1.0 - uv[1] as f64]);
            split
                .labels
                .push(format!("{mesh_name} primitive {p} vertex {i}"));
        }
        split.triangles.extend(
            indices
                .chunks_exact(3)
                .map(|c| [0, 1, 2].map(|k| base + c[k] as usize)),
        );
    }
    let n_targets = target_count.unwrap_or(0);
    let defaults: Vec<f64> = node
        .weights()
        .or(mesh.weights())
        .map(|w| w.iter().map(|&x| x as f64).collect())
        .unwrap_or_else(|| vec![0.0; n_targets]);
    if defaults.len() != n_targets {
        return Err(bad(format!(
            "{mesh_name} has {} default morph weights for {n_targets} morph targets",
            defaults.len()
        )));
    }
    let weights = sample_animation(doc, &buffers, &node, options, n_targets)
        .map_err(&bad)?
        .unwrap_or_else(|| {
            log::warn!(
                "{}: no animation of {}'s morph weights; the surface has one frame",
                path.display(),
                name_of(node.name(), "node", node.index())
            );
            vec![defaults]
        });
    split.frames = weights
        .iter()
        .map(|w| {
            (0..split.rest.len())
                .map(|v| {
                    let mut p = split.rest[v];
                    for (t, &wt) in w.iter().enumerate() {
                        if wt != 0.0 {
                            p += targets[t][v] * wt;
                        }
                    }
                    p
                })
                .collect()
        })
        .collect();
    let mm = options.mm_per_unit.unwrap_or(1000.0);
    AnimatedSurface::from_split(split, mm, options.frame_rate_hz)
}

fn name_of(name: Option<&str>, kind: &str, index: usize) -> String {
    match name {
        Some(n) => format!("{kind} '{n}'"),
        None => format!("{kind} {index}"),
    }
}

/// The bytes of every buffer: the GLB's binary chunk, a base64 data URI, or
/// a file beside the glTF.
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
                std::fs::read(&file).map_err(|e| Error::io(&file, e))?
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

/// The node whose mesh is read, with its world matrix.
fn pick_node<'a>(
    doc: &'a ::gltf::Document,
    wanted: Option<&str>,
) -> std::result::Result<(::gltf::Node<'a>, Matrix4<f64>), String> {
    fn walk<'a>(
        node: ::gltf::Node<'a>,
        parent: Matrix4<f64>,
        out: &mut Vec<(::gltf::Node<'a>, Matrix4<f64>)>,
    ) {
        let m = node.transform().matrix();
        let local = Matrix4::from_fn(|r, c| m[c][r] as f64);
        let world = parent * local;
        for child in node.children() {
            walk(child, world, out);
        }
        out.push((node, world));
    }
    let mut nodes = Vec::new();
    match doc.default_scene().or_else(|| doc.scenes().next()) {
        Some(scene) => {
            for root in scene.nodes() {
                walk(root, Matrix4::identity(), &mut nodes);
            }
        }
        // No scene: every node with its own transform.
        None => {
            for node in doc.nodes() {
                let m = node.transform().matrix();
                nodes.push((node, Matrix4::from_fn(|r, c| m[c][r] as f64)));
            }
        }
    }
    nodes.sort_by_key(|(n, _)| n.index());
    let with_mesh: Vec<_> = nodes
        .into_iter()
        .filter(|(n, _)| n.mesh().is_some())
        .collect();
    let names = || {
        with_mesh
            .iter()
            .map(|(n, _)| name_of(n.name(), "node", n.index()))
            .collect::<Vec<_>>()
            .join(", ")
    };
    match wanted {
        Some(name) => with_mesh
            .iter()
            .find(|(n, _)| n.name() == Some(name))
            .cloned()
            .ok_or_else(|| {
                format!(
                    "has no node '{name}' with a mesh (surface.node); nodes with meshes: {}",
                    names()
                )
            }),
        None => match with_mesh.len() {
            0 => Err("has no node with a mesh in its scene".into()),
            1 => Ok(with_mesh[0].clone()),
            _ => Err(format!(
                "has several nodes with meshes ({}); choose one with surface.node",
                names()
            )),
        },
    }
}

/// The morph weights of every frame from the node's weight animation;
/// `None` when no animation moves them.
fn sample_animation<'a>(
    doc: &'a ::gltf::Document,
    buffers: &[Vec<u8>],
    node: &::gltf::Node<'_>,
    options: &ReadOptions,
    n_targets: usize,
) -> std::result::Result<Option<Vec<Vec<f64>>>, String> {
    fn weights_channel<'a>(
        a: &::gltf::Animation<'a>,
        node: usize,
    ) -> Option<::gltf::animation::Channel<'a>> {
        a.channels().find(|c| {
            c.target().node().index() == node
                && c.target().property() == Property::MorphTargetWeights
        })
    }
    let moves_weights = |a: &::gltf::Animation<'a>| weights_channel(a, node.index());
    let animations: Vec<_> = doc.animations().collect();
    let chosen = match &options.animation {
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
            Some(moves_weights(a).ok_or_else(|| {
                format!("animation '{name}' does not animate the morph weights of the mesh's node")
            })?)
        }
        None => animations.iter().find_map(moves_weights),
    };
    let Some(channel) = chosen else {
        return Ok(None);
    };
    if animations.iter().any(|a| {
        a.channels().any(|c| {
            c.target().node().index() == node.index()
                && c.target().property() != Property::MorphTargetWeights
        })
    }) {
        log::warn!("the node's translation/rotation/scale animation is not applied (rigid motion does not change the strain)");
    }
    let reader = channel.reader(|b| buffers.get(b.index()).map(|d| d.as_slice()));
    let times: Vec<f64> = reader
        .read_inputs()
        .ok_or("the weight animation has no keyframe times")?
        .map(|t| t as f64)
        .collect();
    let values: Vec<f64> = match reader.read_outputs() {
        Some(::gltf::animation::util::ReadOutputs::MorphTargetWeights(w)) => {
            w.into_f32().map(|x| x as f64).collect()
        }
        _ => return Err("the weight animation has no weights".into()),
    };
    let interpolation = channel.sampler().interpolation();
    let per_key = n_targets
        * if interpolation == Interpolation::CubicSpline {
            3
        } else {
            1
        };
    if let Some(k) = times.iter().position(|t| !t.is_finite()) {
        return Err(format!("the weight animation's keyframe {k} has time {}", times[k]));
    }
    if times.is_empty() || values.len() != times.len() * per_key {
        return Err(format!(
            "morph target count mismatch: the weight animation has {} values for {} keyframes, \
             but the mesh has {n_targets} morph targets ({per_key} values per keyframe expected)",
            values.len(),
            times.len()
        ));
    }
    if let Some(k) = (1..times.len())
        .find(|&k| times[k].partial_cmp(&times[k - 1]) != Some(std::cmp::Ordering::Greater))
    {
        return Err(format!(
            "the weight animation's keyframe times are not increasing at keyframe {k} ({} after {})",
            times[k],
            times[k - 1]
        ));
    }
    let rate = options.frame_rate_hz;
    let (t0, t1) = (times[0], times[times.len() - 1]);
    let frames = ((t1 - t0) * rate + 1e-4).floor() as usize + 1;
    // Keyframe times are f32: a sample within this of a key takes the key.
    let tol = 1e-4 / rate;
    Ok(Some(
        (0..frames)
            .map(|f| {
                let t = t0 + f as f64 / rate;
                sample(&times, &values, interpolation, n_targets, t, tol)
            })
            .collect(),
    ))
}

/// The weights at time `t` (glTF's sampler rules; clamped outside the keys).
fn sample(
    times: &[f64],
    values: &[f64],
    interpolation: Interpolation,
    n: usize,
    t: f64,
    tol: f64,
) -> Vec<f64> {
    let cubic = interpolation == Interpolation::CubicSpline;
    let value = |k: usize| -> &[f64] {
        if cubic {
            &values[(3 * k + 1) * n..(3 * k + 2) * n]
        } else {
            &values[k * n..(k + 1) * n]
        }
    };
    // The last key at or before t (within tol).
    let k = times.partition_point(|&x| x <= t + tol).saturating_sub(1);
    if (times[k] - t).abs() <= tol || k + 1 == times.len() || t < times[0] {
        return value(k).to_vec();
    }
    let (ta, tb) = (times[k], times[k + 1]);
    let dt = tb - ta;
    let s = (t - ta) / dt;
    match interpolation {
        Interpolation::Step => value(k).to_vec(),
        Interpolation::Linear => value(k)
            .iter()
            .zip(value(k + 1))
            .map(|(a, b)| a + (b - a) * s)
            .collect(),
        Interpolation::CubicSpline => {
            let out_tangent = &values[(3 * k + 2) * n..(3 * k + 3) * n];
            let in_tangent = &values[3 * (k + 1) * n..(3 * (k + 1) + 1) * n];
            let (s2, s3) = (s * s, s * s * s);
            (0..n)
                .map(|i| {
                    (2.0 * s3 - 3.0 * s2 + 1.0) * value(k)[i]
                        + (s3 - 2.0 * s2 + s) * dt * out_tangent[i]
                        + (-2.0 * s3 + 3.0 * s2) * value(k + 1)[i]
                        + (s3 - s2) * dt * in_tangent[i]
                })
                .collect()
        }
    }
}

/// Writes `surface` as a binary glTF: positions in metres, one morph target
/// per frame and a step animation showing frame `k` at `k / rate` seconds.
/// Vertices are the surface vertices (split at UV seams, as glTF needs).
pub fn write_glb(path: &Path, surface: &AnimatedSurface) -> Result<()> {
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
    write_glb_animation(path, surface, &animation)
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

/// Writes the rest of `surface` (its positions and UV layout; its frames are
/// not used) with the morph targets and weight animation of `animation` as
/// a binary glTF, positions in metres.
pub fn write_glb_animation(
    path: &Path,
    surface: &AnimatedSurface,
    animation: &MorphAnimation,
) -> Result<()> {
    let top = &surface.top;
    // Positions relative to the centre of the bounds (the node's
    // translation), so f32 keeps more of them; displacements from the f64
    // difference, so a frame's strain loses only the rounding of the rest.
    let (lo, hi) = surface.bounds();
    let centre = ((lo + hi) * 0.5).map(|c| ((c / 1000.0) as f32) as f64 * 1000.0);
    let metres = |p: &Vec3| [p.x, p.y, p.z].map(|c| (c / 1000.0) as f32);
    let mut bin: Vec<u8> = Vec::new();
    let mut views = Vec::new();
    let mut accessors = Vec::new();
    // Appends a float accessor (with min/max, which POSITION requires).
    let mut push = |data: &[f32], kind: &str, components: usize, bounds: bool| -> usize {
        let offset = bin.len();
        bin.extend(data.iter().flat_map(|x| x.to_le_bytes()));
        views.push(serde_json::json!({
            "buffer": 0, "byteOffset": offset, "byteLength": data.len() * 4
        }));
        let mut acc = serde_json::json!({
            "bufferView": views.len() - 1, "componentType": 5126,
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
        accessors.push(acc);
        accessors.len() - 1
    };
    let rest: Vec<f32> = top
        .vertices
        .iter()
        .flat_map(|&v| metres(&(surface.positions[v] - centre)))
        .collect();
    let position = push(&rest, "VEC3", 3, true);
    let uvs: Vec<f32> = top
        .uvs
        .iter()
        .flat_map(|w| [w[0] as f32, (1.0 - w[1]) as f32])
        .collect();
    let texcoord = push(&uvs, "VEC2", 2, false);
    let mut targets = Vec::new();
    for displacement in &animation.targets {
        let delta: Vec<f32> = top
            .vertices
            .iter()
            .flat_map(|&v| metres(&displacement[v]))
            .collect();
        targets.push(serde_json::json!({ "POSITION": push(&delta, "VEC3", 3, true) }));
    }
    let n_targets = animation.targets.len();
    let times: Vec<f32> = animation.times_s.iter().map(|&t| t as f32).collect();
    let input = push(&times, "SCALAR", 1, true);
    let weights: Vec<f32> = animation
        .weights
        .iter()
        .flat_map(|w| w.iter().map(|&x| x as f32))
        .collect();
    let output = push(&weights, "SCALAR", 1, false);
    // Indices (u32), after the floats so every view stays 4-byte aligned.
    let offset = bin.len();
    bin.extend(
        top.triangles
            .iter()
            .flatten()
            .flat_map(|&i| (i as u32).to_le_bytes()),
    );
    views.push(serde_json::json!({
        "buffer": 0, "byteOffset": offset, "byteLength": top.triangles.len() * 12
    }));
    accessors.push(serde_json::json!({
        "bufferView": views.len() - 1, "componentType": 5125,
        "count": top.triangles.len() * 3, "type": "SCALAR"
    }));
    let indices = accessors.len() - 1;
    let name = Path::new(&surface.origin)
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "surface".into());
    let json = serde_json::json!({
        "asset": { "version": "2.0", "generator": concat!("skinpatch ", env!("CARGO_PKG_VERSION")) },
        "scene": 0,
        "scenes": [{ "nodes": [0] }],
        "nodes": [{ "name": name, "mesh": 0, "translation": [centre.x / 1000.0, centre.y / 1000.0, centre.z / 1000.0] }],
        "meshes": [{
            "name": name,
            "primitives": [{
                "attributes": { "POSITION": position, "TEXCOORD_0": texcoord },
                "indices": indices,
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
        "buffers": [{ "byteLength": bin.len() }],
        "bufferViews": views,
        "accessors": accessors
    });
    let mut text = serde_json::to_vec(&json).map_err(|e| Error::malformed(path, e.to_string()))?;
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
    crate::mesh::io::write_atomically(path, &out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn samplers_follow_the_spec() {
        let times = [0.0, 1.0, 3.0];
        let values = [0.0, 1.0, 1.0, 0.0, 0.5, 0.5];
        let at = |i, t| sample(&times, &values, i, 2, t, 1e-9);
        assert_eq!(at(Interpolation::Step, 0.5), vec![0.0, 1.0]);
        assert_eq!(at(Interpolation::Linear, 0.25), vec![0.25, 0.75]);
        assert_eq!(at(Interpolation::Linear, 2.0), vec![0.75, 0.25]);
        assert_eq!(at(Interpolation::Linear, 5.0), vec![0.5, 0.5]);
        assert_eq!(at(Interpolation::Linear, -1.0), vec![0.0, 1.0]);
        // Cubic spline with zero tangents: smoothstep between the keys.
        let cubic = [0.0, 0.0, 0.0, 0.0, 1.0, 0.0];
        let w = sample(
            &[0.0, 2.0],
            &cubic,
            Interpolation::CubicSpline,
            1,
            1.0,
            1e-9,
        );
        assert!((w[0] - 0.5).abs() < 1e-12);
        let w = sample(
            &[0.0, 2.0],
            &cubic,
            Interpolation::CubicSpline,
            1,
            0.5,
            1e-9,
        );
        assert!((w[0] - 0.15625).abs() < 1e-12);
    }
}
