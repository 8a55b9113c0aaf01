//! A glTF animation as the surface reader samples it: the mesh node's
//! morph weights and the translation, rotation and scale of nodes, each a
//! keyframe track with glTF's sampler rules (step, linear — spherical for
//! rotations — and cubic spline), and the node hierarchy's world matrices
//! at any time (for the node's own motion and for skinning).

use std::collections::HashMap;

use ::gltf::animation::util::ReadOutputs;
use ::gltf::animation::{Interpolation, Property};
use nalgebra::{Matrix4, Quaternion, UnitQuaternion, Vector3};

/// Keyframes of one animated property.
#[derive(Clone, Debug)]
pub(super) struct Track {
    pub times: Vec<f64>,
    /// `n` values per keyframe (×3 for cubic spline: in-tangent, value,
    /// out-tangent).
    pub values: Vec<f64>,
    pub interpolation: Interpolation,
    pub n: usize,
}

impl Track {
    /// The values at `t`; keyframes within `tol` of `t` are taken as they are.
    pub fn at(&self, t: f64, tol: f64) -> Vec<f64> {
        sample(
            &self.times,
            &self.values,
            self.interpolation,
            self.n,
            t,
            tol,
        )
    }

    /// A rotation track at `t` (unit quaternion xyzw): spherical
    /// interpolation between linear keys, normalised cubic splines.
    fn rotation_at(&self, t: f64, tol: f64) -> UnitQuaternion<f64> {
        let q =
            |v: &[f64]| UnitQuaternion::from_quaternion(Quaternion::new(v[3], v[0], v[1], v[2]));
        if self.interpolation != Interpolation::Linear {
            return q(&self.at(t, tol));
        }
        let k = self
            .times
            .partition_point(|&x| x <= t + tol)
            .saturating_sub(1);
        let key = |k: usize| q(&self.values[4 * k..4 * k + 4]);
        if (self.times[k] - t).abs() <= tol || k + 1 == self.times.len() || t < self.times[0] {
            return key(k);
        }
        let s = (t - self.times[k]) / (self.times[k + 1] - self.times[k]);
        let (a, mut b) = (key(k), key(k + 1));
        // The shorter arc.
        if a.coords.dot(&b.coords) < 0.0 {
            b = UnitQuaternion::new_unchecked(-b.into_inner());
        }
        a.try_slerp(&b, s, 1e-12).unwrap_or_else(|| {
            UnitQuaternion::from_quaternion(a.into_inner().lerp(&b.into_inner(), s))
        })
    }
}

/// The values at time `t` by glTF's sampler rules (clamped outside the keys).
pub(super) fn sample(
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

/// The chosen animation's tracks that move the surface.
#[derive(Clone, Debug, Default)]
pub(super) struct Clip {
    /// Name for messages.
    pub name: String,
    /// The mesh node's morph weights.
    pub weights: Option<Track>,
    /// Per node index: translation, rotation, scale tracks.
    pub trs: HashMap<usize, [Option<Track>; 3]>,
    /// First and last keyframe time over the tracks.
    pub start: f64,
    pub end: f64,
}

/// One channel's keyframes, checked: finite times, strictly increasing,
/// and the values their count and interpolation need (`n_targets` a
/// keyframe for morph weights). `name` names the animation in errors.
fn read_track(
    channel: &::gltf::animation::Channel<'_>,
    buffers: &[Vec<u8>],
    name: &str,
    n_targets: usize,
) -> Result<Track, String> {
    let property = channel.target().property();
    let reader = channel.reader(|b| buffers.get(b.index()).map(|d| d.as_slice()));
    let times: Vec<f64> = reader
        .read_inputs()
        .ok_or_else(|| format!("{name} channel {} has no keyframe times", channel.index()))?
        .map(|t| t as f64)
        .collect();
    let (values, n): (Vec<f64>, usize) = match reader.read_outputs() {
        Some(ReadOutputs::MorphTargetWeights(w)) => {
            (w.into_f32().map(|x| x as f64).collect(), n_targets)
        }
        Some(ReadOutputs::Translations(v)) | Some(ReadOutputs::Scales(v)) => {
            (v.flat_map(|x| x.map(|c| c as f64)).collect(), 3)
        }
        Some(ReadOutputs::Rotations(r)) => {
            (r.into_f32().flat_map(|x| x.map(|c| c as f64)).collect(), 4)
        }
        None => return Err(format!("{name} channel {} has no values", channel.index())),
    };
    let interpolation = channel.sampler().interpolation();
    let per_key = n * if interpolation == Interpolation::CubicSpline {
        3
    } else {
        1
    };
    if let Some(k) = times.iter().position(|t| !t.is_finite()) {
        return Err(format!(
            "{name} channel {}: keyframe {k} has time {}",
            channel.index(),
            times[k]
        ));
    }
    if times.is_empty() || values.len() != times.len() * per_key {
        let what = if property == Property::MorphTargetWeights {
            format!(
                "morph target count mismatch: {name} has {} weight values for {} \
                 keyframes, but the mesh has {n_targets} morph targets ({per_key} values \
                 per keyframe expected)",
                values.len(),
                times.len()
            )
        } else {
            format!(
                "{name} channel {} has {} values for {} keyframes ({per_key} per keyframe expected)",
                channel.index(),
                values.len(),
                times.len()
            )
        };
        return Err(what);
    }
    if let Some(k) = (1..times.len())
        .find(|&k| times[k].partial_cmp(&times[k - 1]) != Some(std::cmp::Ordering::Greater))
    {
        return Err(format!(
            "{name} channel {}: keyframe times are not increasing at keyframe {k} ({} after {})",
            channel.index(),
            times[k],
            times[k - 1]
        ));
    }
    Ok(Track {
        times,
        values,
        interpolation,
        n,
    })
}

impl Clip {
    /// Reads the tracks of `animation` that target the weights of node
    /// `weights_node` (with `n_targets` targets) or the transform of a node
    /// in `moving`; an error names what does not fit.
    pub fn read(
        animation: &::gltf::Animation<'_>,
        buffers: &[Vec<u8>],
        weights_node: usize,
        n_targets: usize,
        moving: &[bool],
    ) -> Result<Clip, String> {
        let name = match animation.name() {
            Some(n) => format!("animation '{n}'"),
            None => format!("animation {}", animation.index()),
        };
        let mut clip = Clip {
            name: name.clone(),
            start: f64::INFINITY,
            end: f64::NEG_INFINITY,
            ..Clip::default()
        };
        for channel in animation.channels() {
            let target = channel.target();
            let node = target.node().index();
            let property = target.property();
            let wanted = match property {
                Property::MorphTargetWeights => node == weights_node,
                _ => moving.get(node).copied().unwrap_or(false),
            };
            if !wanted {
                continue;
            }
            let track = read_track(&channel, buffers, &name, n_targets)?;
            clip.start = clip.start.min(track.times[0]);
            clip.end = clip.end.max(track.times[track.times.len() - 1]);
            match property {
                Property::MorphTargetWeights => clip.weights = Some(track),
                Property::Translation => clip.trs.entry(node).or_default()[0] = Some(track),
                Property::Rotation => clip.trs.entry(node).or_default()[1] = Some(track),
                Property::Scale => clip.trs.entry(node).or_default()[2] = Some(track),
            }
        }
        Ok(clip)
    }

    /// Whether the clip moves anything.
    pub fn is_empty(&self) -> bool {
        self.weights.is_none() && self.trs.is_empty()
    }

    /// The local matrix of `node` at `t` (`None`: the node's own transform).
    pub fn local(&self, node: &::gltf::Node<'_>, t: Option<f64>, tol: f64) -> Matrix4<f64> {
        let (tr, rot, sc) = node.transform().decomposed();
        let mut translation = Vector3::new(tr[0] as f64, tr[1] as f64, tr[2] as f64);
        let mut rotation = UnitQuaternion::from_quaternion(Quaternion::new(
            rot[3] as f64,
            rot[0] as f64,
            rot[1] as f64,
            rot[2] as f64,
        ));
        let mut scale = Vector3::new(sc[0] as f64, sc[1] as f64, sc[2] as f64);
        if let (Some(t), Some([tt, rt, st])) = (t, self.trs.get(&node.index())) {
            if let Some(track) = tt {
                translation = Vector3::from_column_slice(&track.at(t, tol));
            }
            if let Some(track) = rt {
                rotation = track.rotation_at(t, tol);
            }
            if let Some(track) = st {
                scale = Vector3::from_column_slice(&track.at(t, tol));
            }
        }
        Matrix4::new_translation(&translation)
            * rotation.to_homogeneous()
            * Matrix4::new_nonuniform_scaling(&scale)
    }
}

/// World matrices of every node (by index) of the scene `roots`, each
/// node's local matrix from `local`; nodes outside the scene get their
/// local matrix alone.
pub(super) fn world_matrices(
    doc: &::gltf::Document,
    roots: &[::gltf::Node<'_>],
    local: &dyn Fn(&::gltf::Node<'_>) -> Matrix4<f64>,
) -> Vec<Matrix4<f64>> {
    fn walk(
        node: &::gltf::Node<'_>,
        parent: &Matrix4<f64>,
        local: &dyn Fn(&::gltf::Node<'_>) -> Matrix4<f64>,
        out: &mut Vec<Option<Matrix4<f64>>>,
    ) {
        let world = parent * local(node);
        for child in node.children() {
            walk(&child, &world, local, out);
        }
        out[node.index()] = Some(world);
    }
    let mut out = vec![None; doc.nodes().count()];
    for root in roots {
        walk(root, &Matrix4::identity(), local, &mut out);
    }
    doc.nodes()
        .map(|n| out[n.index()].unwrap_or_else(|| local(&n)))
        .collect()
}

/// Whether each node (by index) is one of `nodes` or an ancestor of one.
pub(super) fn with_ancestors(doc: &::gltf::Document, nodes: &[usize]) -> Vec<bool> {
    let count = doc.nodes().count();
    let mut parent = vec![None; count];
    for n in doc.nodes() {
        for c in n.children() {
            parent[c.index()] = Some(n.index());
        }
    }
    let mut out = vec![false; count];
    for &n in nodes {
        let mut at = Some(n);
        while let Some(k) = at {
            if out[k] {
                break;
            }
            out[k] = true;
            at = parent[k];
        }
    }
    out
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

    #[test]
    fn linear_rotations_are_spherical_on_the_shorter_arc() {
        // 0° and 90° about z (the second key given as −q): 45° at the middle.
        let h = std::f64::consts::FRAC_PI_4;
        let track = Track {
            times: vec![0.0, 1.0],
            values: vec![0.0, 0.0, 0.0, 1.0, 0.0, 0.0, -h.sin(), -h.cos()],
            interpolation: Interpolation::Linear,
            n: 4,
        };
        let q = track.rotation_at(0.5, 1e-9);
        let want = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), std::f64::consts::FRAC_PI_4);
        assert!(q.angle_to(&want) < 1e-12, "{q:?}");
    }
}
