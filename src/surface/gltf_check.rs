//! Checks a glTF document against the parts of the glTF 2.0 specification
//! that [`super::gltf`] relies on, before anything is read through the
//! `gltf` crate (whose readers assume them and panic, or recurse without
//! end, where they do not hold):
//!
//! * every index (buffer, view, accessor, mesh, skin, node, sampler) in range;
//! * every buffer view inside its buffer, every accessor's bytes (offset,
//!   stride, count) inside its view, sparse parts included;
//! * every accessor of a kind its use allows (type, component type,
//!   normalisation), as the specification's attribute and animation tables
//!   list them;
//! * nodes forming trees: no node its own descendant, none with two parents.
//!
//! An error names the accessor, view or node and where it is used.

use ::gltf::json;
use json::accessor::{ComponentType, Type};
use json::validation::Checked;

/// Largest element count of an accessor without a buffer view (sparse
/// accessors, whose other elements are zero): 2²⁶.
const MAX_VIEWLESS_COUNT: u64 = 1 << 26;

/// Checks `root` with the loaded buffers' lengths (bytes).
pub(super) fn check(root: &json::Root, buffer_lengths: &[usize]) -> Result<(), String> {
    check_views(root, buffer_lengths)?;
    for k in 0..root.accessors.len() {
        check_accessor(root, k)?;
    }
    check_meshes(root)?;
    check_nodes(root)?;
    check_skins(root)?;
    check_animations(root)?;
    Ok(())
}

fn check_views(root: &json::Root, buffer_lengths: &[usize]) -> Result<(), String> {
    for (k, view) in root.buffer_views.iter().enumerate() {
        let b = view.buffer.value();
        let Some(&length) = buffer_lengths.get(b) else {
            return Err(format!(
                "buffer view {k} refers to buffer {b}, but the file has {}",
                buffer_lengths.len()
            ));
        };
        let offset = view.byte_offset.map_or(0, |o| o.0);
        let end = offset.checked_add(view.byte_length.0);
        if end.is_none_or(|e| e > length as u64) {
            return Err(format!(
                "buffer view {k} spans bytes {offset}..{offset}+{} of buffer {b}, which holds \
                 {length}",
                view.byte_length.0
            ));
        }
    }
    Ok(())
}

fn components(t: Type) -> u64 {
    match t {
        Type::Scalar => 1,
        Type::Vec2 => 2,
        Type::Vec3 => 3,
        Type::Vec4 | Type::Mat2 => 4,
        Type::Mat3 => 9,
        Type::Mat4 => 16,
    }
}

fn component_size(c: ComponentType) -> u64 {
    match c {
        ComponentType::I8 | ComponentType::U8 => 1,
        ComponentType::I16 | ComponentType::U16 => 2,
        ComponentType::U32 | ComponentType::F32 => 4,
    }
}

/// The accessor's type and component type, when both are valid values.
fn kind(a: &json::Accessor) -> Option<(Type, ComponentType)> {
    match (&a.type_, &a.component_type) {
        (Checked::Valid(t), Checked::Valid(c)) => Some((*t, c.0)),
        _ => None,
    }
}

/// Whether bytes `offset .. offset + (count − 1)·stride + size` lie in view
/// `v` (a length in bytes).
fn fits(offset: u64, count: u64, stride: u64, size: u64, view_length: u64) -> bool {
    count
        .checked_sub(1)
        .and_then(|c| c.checked_mul(stride))
        .and_then(|b| b.checked_add(size))
        .and_then(|b| b.checked_add(offset))
        .is_some_and(|end| end <= view_length)
}

fn view_length(root: &json::Root, v: usize, what: &str) -> Result<(u64, Option<u64>), String> {
    let view = root.buffer_views.get(v).ok_or_else(|| {
        format!(
            "{what} refers to buffer view {v}, but the file has {}",
            root.buffer_views.len()
        )
    })?;
    Ok((view.byte_length.0, view.byte_stride.map(|s| s.0 as u64)))
}

fn check_accessor(root: &json::Root, k: usize) -> Result<(), String> {
    let a = &root.accessors[k];
    let what = format!("accessor {k}");
    let (t, c) = kind(a).ok_or_else(|| format!("{what} has an unknown type or component type"))?;
    let count = a.count.0;
    if count == 0 {
        return Err(format!("{what} has count 0"));
    }
    let size = components(t) * component_size(c);
    match a.buffer_view {
        Some(v) => {
            let (length, stride) = view_length(root, v.value(), &what)?;
            let stride = stride.unwrap_or(size);
            if stride < size {
                return Err(format!(
                    "{what}: its view's byte stride {stride} is less than an element ({size} bytes)"
                ));
            }
            let offset = a.byte_offset.map_or(0, |o| o.0);
            if !fits(offset, count, stride, size, length) {
                return Err(format!(
                    "{what}: {count} elements of {size} bytes (stride {stride}) from byte \
                     {offset} overrun its buffer view {} of {length} bytes",
                    v.value()
                ));
            }
        }
        None if a.sparse.is_none() => {
            return Err(format!(
                "{what} has neither a buffer view nor sparse values (zero-filled accessors are \
                 not supported)"
            ));
        }
        None if count > MAX_VIEWLESS_COUNT => {
            return Err(format!(
                "{what} declares {count} elements without a buffer view (at most \
                 {MAX_VIEWLESS_COUNT})"
            ));
        }
        None => {}
    }
    if let Some(sparse) = &a.sparse {
        let n = sparse.count.0;
        if n == 0 || n > count {
            return Err(format!(
                "{what}: {n} sparse elements for an accessor of {count}"
            ));
        }
        let index_size = match &sparse.indices.component_type {
            Checked::Valid(ic)
                if matches!(
                    ic.0,
                    ComponentType::U8 | ComponentType::U16 | ComponentType::U32
                ) =>
            {
                component_size(ic.0)
            }
            _ => {
                return Err(format!(
                    "{what}: sparse indices must be unsigned bytes, shorts or ints"
                ))
            }
        };
        for (part, view, offset, element) in [
            (
                "sparse indices",
                sparse.indices.buffer_view.value(),
                sparse.indices.byte_offset.0,
                index_size,
            ),
            (
                "sparse values",
                sparse.values.buffer_view.value(),
                sparse.values.byte_offset.0,
                size,
            ),
        ] {
            let (length, _) = view_length(root, view, &format!("{what}'s {part}"))?;
            if !fits(offset, n, element, element, length) {
                return Err(format!(
                    "{what}: its {part} ({n} of {element} bytes from byte {offset}) overrun \
                     buffer view {view} of {length} bytes"
                ));
            }
        }
    }
    Ok(())
}

/// The kinds a use allows: types, and per component type whether it must be
/// normalised (`Some(true)`), must not be (`Some(false)`), or is a float.
struct Allowed {
    use_name: &'static str,
    types: &'static [Type],
    components: &'static [(ComponentType, bool)],
}

const FLOAT: (ComponentType, bool) = (ComponentType::F32, false);
const U8N: (ComponentType, bool) = (ComponentType::U8, true);
const U16N: (ComponentType, bool) = (ComponentType::U16, true);
const I8N: (ComponentType, bool) = (ComponentType::I8, true);
const I16N: (ComponentType, bool) = (ComponentType::I16, true);

const POSITION: Allowed = Allowed {
    use_name: "POSITION",
    types: &[Type::Vec3],
    components: &[FLOAT],
};
const TEXCOORD: Allowed = Allowed {
    use_name: "TEXCOORD_0",
    types: &[Type::Vec2],
    components: &[FLOAT, U8N, U16N],
};
const JOINTS: Allowed = Allowed {
    use_name: "JOINTS_0",
    types: &[Type::Vec4],
    components: &[(ComponentType::U8, false), (ComponentType::U16, false)],
};
const WEIGHTS: Allowed = Allowed {
    use_name: "WEIGHTS_0",
    types: &[Type::Vec4],
    components: &[FLOAT, U8N, U16N],
};
const INDICES: Allowed = Allowed {
    use_name: "indices",
    types: &[Type::Scalar],
    components: &[
        (ComponentType::U8, false),
        (ComponentType::U16, false),
        (ComponentType::U32, false),
    ],
};
const TARGET_POSITION: Allowed = Allowed {
    use_name: "a morph target's POSITION",
    types: &[Type::Vec3],
    components: &[FLOAT],
};
const INVERSE_BIND: Allowed = Allowed {
    use_name: "inverseBindMatrices",
    types: &[Type::Mat4],
    components: &[FLOAT],
};
const KEY_TIMES: Allowed = Allowed {
    use_name: "keyframe times",
    types: &[Type::Scalar],
    components: &[FLOAT],
};
const VECTOR_KEYS: Allowed = Allowed {
    use_name: "translation or scale keyframes",
    types: &[Type::Vec3],
    components: &[FLOAT],
};
const ROTATION_KEYS: Allowed = Allowed {
    use_name: "rotation keyframes",
    types: &[Type::Vec4],
    components: &[FLOAT, I8N, U8N, I16N, U16N],
};
const WEIGHT_KEYS: Allowed = Allowed {
    use_name: "morph weight keyframes",
    types: &[Type::Scalar],
    components: &[FLOAT, I8N, U8N, I16N, U16N],
};

/// Checks that accessor `index` exists and is of a kind `allowed` lists;
/// `place` says where it is used.
fn check_use(
    root: &json::Root,
    index: usize,
    allowed: &Allowed,
    place: &str,
) -> Result<(), String> {
    let a = root.accessors.get(index).ok_or_else(|| {
        format!(
            "{place}: {} is accessor {index}, but the file has {}",
            allowed.use_name,
            root.accessors.len()
        )
    })?;
    // Checked by check_accessor already.
    let Some((t, c)) = kind(a) else {
        return Ok(());
    };
    let float = c == ComponentType::F32;
    let ok = allowed.types.contains(&t)
        && allowed
            .components
            .iter()
            .any(|&(ac, normalised)| ac == c && (float || normalised == a.normalized));
    if ok {
        return Ok(());
    }
    let accepted: Vec<String> = allowed
        .components
        .iter()
        .map(|&(ac, normalised)| {
            format!(
                "{ac:?}{}",
                if normalised && ac != ComponentType::F32 {
                    " normalized"
                } else {
                    ""
                }
            )
        })
        .collect();
    Err(format!(
        "{place}: {} is accessor {index} of {t:?} {c:?}{}; it must be {:?} of {}",
        allowed.use_name,
        if a.normalized { " normalized" } else { "" },
        allowed.types,
        accepted.join(", ")
    ))
}

fn check_meshes(root: &json::Root) -> Result<(), String> {
    use json::mesh::Semantic;
    for (m, mesh) in root.meshes.iter().enumerate() {
        for (p, prim) in mesh.primitives.iter().enumerate() {
            let place = format!("mesh {m} primitive {p}");
            for (semantic, accessor) in &prim.attributes {
                let index = accessor.value();
                let allowed = match semantic {
                    Checked::Valid(Semantic::Positions) => Some(&POSITION),
                    Checked::Valid(Semantic::TexCoords(0)) => Some(&TEXCOORD),
                    Checked::Valid(Semantic::Joints(0)) => Some(&JOINTS),
                    Checked::Valid(Semantic::Weights(0)) => Some(&WEIGHTS),
                    _ => None,
                };
                match allowed {
                    Some(allowed) => check_use(root, index, allowed, &place)?,
                    None if index >= root.accessors.len() => {
                        return Err(format!(
                            "{place}: an attribute is accessor {index}, but the file has {}",
                            root.accessors.len()
                        ))
                    }
                    None => {}
                }
            }
            if let Some(i) = prim.indices {
                check_use(root, i.value(), &INDICES, &place)?;
            }
            for (t, target) in prim.targets.iter().flatten().enumerate() {
                let place = format!("{place} morph target {t}");
                if let Some(a) = target.positions {
                    check_use(root, a.value(), &TARGET_POSITION, &place)?;
                }
                for a in [target.normals, target.tangents].into_iter().flatten() {
                    if a.value() >= root.accessors.len() {
                        return Err(format!(
                            "{place} refers to accessor {}, but the file has {}",
                            a.value(),
                            root.accessors.len()
                        ));
                    }
                }
            }
        }
    }
    Ok(())
}

fn in_range(index: usize, count: usize, what: &str, place: &str) -> Result<(), String> {
    if index < count {
        Ok(())
    } else {
        Err(format!(
            "{place} refers to {what} {index}, but the file has {count}"
        ))
    }
}

fn check_nodes(root: &json::Root) -> Result<(), String> {
    let count = root.nodes.len();
    let mut parent: Vec<Option<usize>> = vec![None; count];
    for (k, node) in root.nodes.iter().enumerate() {
        let place = format!("node {k}");
        if let Some(m) = node.mesh {
            in_range(m.value(), root.meshes.len(), "mesh", &place)?;
        }
        if let Some(s) = node.skin {
            in_range(s.value(), root.skins.len(), "skin", &place)?;
        }
        if let Some(c) = node.camera {
            in_range(c.value(), root.cameras.len(), "camera", &place)?;
        }
        for child in node.children.iter().flatten() {
            let c = child.value();
            in_range(c, count, "child node", &place)?;
            if c == k {
                return Err(format!("node {k} lists itself as a child"));
            }
            if let Some(p) = parent[c] {
                return Err(format!(
                    "node {c} is a child of both node {p} and node {k} (glTF nodes form trees)"
                ));
            }
            parent[c] = Some(k);
        }
    }
    // With one parent each, a cycle is a walk up that never ends.
    for start in 0..count {
        let mut at = parent[start];
        let mut steps = 0;
        while let Some(p) = at {
            if p == start || steps > count {
                return Err(format!(
                    "node {start} is its own ancestor (the node tree has a cycle)"
                ));
            }
            at = parent[p];
            steps += 1;
        }
    }
    for (s, scene) in root.scenes.iter().enumerate() {
        for n in &scene.nodes {
            in_range(n.value(), count, "node", &format!("scene {s}"))?;
        }
    }
    if let Some(s) = root.scene {
        in_range(s.value(), root.scenes.len(), "scene", "the default scene")?;
    }
    Ok(())
}

fn check_skins(root: &json::Root) -> Result<(), String> {
    for (s, skin) in root.skins.iter().enumerate() {
        let place = format!("skin {s}");
        if skin.joints.is_empty() {
            return Err(format!("{place} has no joints"));
        }
        for j in &skin.joints {
            in_range(j.value(), root.nodes.len(), "joint node", &place)?;
        }
        if let Some(n) = skin.skeleton {
            in_range(n.value(), root.nodes.len(), "skeleton node", &place)?;
        }
        if let Some(a) = skin.inverse_bind_matrices {
            check_use(root, a.value(), &INVERSE_BIND, &place)?;
        }
    }
    Ok(())
}

fn check_animations(root: &json::Root) -> Result<(), String> {
    use json::animation::Property;
    for (k, animation) in root.animations.iter().enumerate() {
        for (c, channel) in animation.channels.iter().enumerate() {
            let place = format!("animation {k} channel {c}");
            let s = channel.sampler.value();
            in_range(s, animation.samplers.len(), "sampler", &place)?;
            in_range(
                channel.target.node.value(),
                root.nodes.len(),
                "target node",
                &place,
            )?;
            let sampler = &animation.samplers[s];
            check_use(root, sampler.input.value(), &KEY_TIMES, &place)?;
            let allowed = match &channel.target.path {
                Checked::Valid(Property::Translation) | Checked::Valid(Property::Scale) => {
                    &VECTOR_KEYS
                }
                Checked::Valid(Property::Rotation) => &ROTATION_KEYS,
                Checked::Valid(Property::MorphTargetWeights) => &WEIGHT_KEYS,
                Checked::Invalid => return Err(format!("{place} targets an unknown property")),
            };
            check_use(root, sampler.output.value(), allowed, &place)?;
        }
    }
    Ok(())
}
