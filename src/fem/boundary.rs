//! Boundary conditions of the box patch.
//!
//! Node sets are found geometrically on the mesh's bounding box (tolerance
//! 1e-9 of its diagonal), so they work for generated and loaded box meshes:
//! `bottom` (z = z_min), `x_min`, `x_max`, `y_min`, `y_max`, `top` (z = z_max).
//!
//! * bottom: `fixed` (all components) or `rollers` (z only);
//! * sides: `clamped` (all components), `rollers` (normal component only) or `free`;
//! * caliper: the two sides normal to `axis` act as frictionless jaws that
//!   move apart (stretch > 1) or together (< 1): their axis coordinate is
//!   `c + s(t)·(X − c)` about the patch centre c; their other components
//!   are free (the jaws slide);
//! * prescribed displacement of a named node set over time (all components).
//!
//! Keyframed quantities interpolate linearly in time and hold their end values
//! outside the keyframe range.
//!
//! With `bottom = rollers`, `sides = rollers` on the other axis and a free
//! top, a caliper stretch `s` has the exact homogeneous solution
//! `F = diag(s, 1, λ_z)` in every layer (plane strain across the other axis,
//! zero normal stress at the top), so every tet's largest stretch is `s`.

use nalgebra::Vector3;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use super::solve::Filter;
use crate::mesh::{TetMesh, Vec3};

/// Condition on the bottom face (`boundary.bottom`: `fixed`, `rollers`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Deserialize, Serialize, JsonSchema)]
#[serde(rename_all = "kebab-case")]
pub enum BottomCondition {
    #[default]
    /// All components fixed.
    Fixed,
    /// Vertical component fixed, sliding in x and y.
    Rollers,
}

/// Condition on the four side faces (`boundary.sides`: `clamped`,
/// `rollers`, `free`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Deserialize, Serialize, JsonSchema)]
#[serde(rename_all = "kebab-case")]
pub enum SideCondition {
    /// All components fixed.
    Clamped,
    /// Normal component fixed.
    #[default]
    Rollers,
    /// Traction-free.
    Free,
}

/// A piecewise-linear function of time.
#[derive(Clone, Debug, PartialEq)]
pub struct Keyframes<T> {
    /// (time in s, value), strictly increasing in time.
    pub points: Vec<(f64, T)>,
}

impl<T> Keyframes<T>
where
    T: Copy + std::ops::Mul<f64, Output = T> + std::ops::Add<Output = T>,
{
    /// The value at time `t` (held constant outside the range).
    pub fn at(&self, t: f64) -> T {
        let p = &self.points;
        if t <= p[0].0 {
            return p[0].1;
        }
        for w in p.windows(2) {
            let ((t0, v0), (t1, v1)) = (w[0], w[1]);
            if t <= t1 {
                let a = (t - t0) / (t1 - t0);
                return v0 * (1.0 - a) + v1 * a;
            }
        }
        p[p.len() - 1].1
    }
}

/// Caliper jaws on the two sides normal to `axis`.
#[derive(Clone, Debug, PartialEq)]
pub struct Caliper {
    /// 0 for x, 1 for y.
    pub axis: usize,
    /// Stretch ratio of the jaw distance over time.
    pub stretch: Keyframes<f64>,
}

/// Prescribed displacement of a node set.
#[derive(Clone, Debug, PartialEq)]
pub struct Prescribed {
    /// Name of the set (for messages).
    pub name: String,
    /// Nodes of the set.
    pub nodes: Vec<usize>,
    /// Displacement (mm) over time.
    pub displacement: Keyframes<Vector3<f64>>,
}

/// All boundary conditions of a run.
#[derive(Clone, Debug, PartialEq)]
pub struct BoundaryConditions {
    /// Bottom face.
    pub bottom: BottomCondition,
    /// Side faces.
    pub sides: SideCondition,
    /// Optional caliper.
    pub caliper: Option<Caliper>,
    /// Prescribed node sets.
    pub prescribed: Vec<Prescribed>,
}

/// One of the geometric node sets (`top`, `bottom`, `x_min`, `x_max`,
/// `y_min`, `y_max` in scenario files).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize, Serialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum NodeSet {
    /// Nodes at z_max.
    Top,
    /// Nodes at z_min.
    Bottom,
    /// Nodes at x_min.
    XMin,
    /// Nodes at x_max.
    XMax,
    /// Nodes at y_min.
    YMin,
    /// Nodes at y_max.
    YMax,
}

impl NodeSet {
    /// Its name in scenario files.
    pub fn name(self) -> &'static str {
        match self {
            NodeSet::Top => "top",
            NodeSet::Bottom => "bottom",
            NodeSet::XMin => "x_min",
            NodeSet::XMax => "x_max",
            NodeSet::YMin => "y_min",
            NodeSet::YMax => "y_max",
        }
    }
}

/// The geometric node sets of a box mesh.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct NodeSets {
    /// Nodes at z_min.
    pub bottom: Vec<usize>,
    /// Nodes at z_max.
    pub top: Vec<usize>,
    /// Nodes at x_min, x_max, y_min, y_max.
    pub sides: [Vec<usize>; 4],
    /// Centre of the bounding box.
    pub centre: Vec3,
}

impl NodeSets {
    /// Finds the sets on the bounding box of `mesh`.
    pub fn of(mesh: &TetMesh) -> NodeSets {
        let (lo, hi) = mesh.bounds();
        let tol = 1e-9 * (hi - lo).norm();
        let pick = |f: &dyn Fn(&Vec3) -> bool| -> Vec<usize> {
            (0..mesh.num_vertices())
                .filter(|&i| f(&mesh.positions[i]))
                .collect()
        };
        NodeSets {
            bottom: pick(&|p| (p.z - lo.z).abs() <= tol),
            top: pick(&|p| (p.z - hi.z).abs() <= tol),
            sides: [
                pick(&|p| (p.x - lo.x).abs() <= tol),
                pick(&|p| (p.x - hi.x).abs() <= tol),
                pick(&|p| (p.y - lo.y).abs() <= tol),
                pick(&|p| (p.y - hi.y).abs() <= tol),
            ],
            centre: (lo + hi) / 2.0,
        }
    }

    /// The nodes of the set `set`.
    pub fn get(&self, set: NodeSet) -> &[usize] {
        match set {
            NodeSet::Bottom => &self.bottom,
            NodeSet::Top => &self.top,
            NodeSet::XMin => &self.sides[0],
            NodeSet::XMax => &self.sides[1],
            NodeSet::YMin => &self.sides[2],
            NodeSet::YMax => &self.sides[3],
        }
    }
}

impl BoundaryConditions {
    /// Filters and target positions at time `t`.
    pub fn constraints(&self, sets: &NodeSets, rest: &[Vec3], t: f64) -> (Vec<Filter>, Vec<Vec3>) {
        let n = rest.len();
        let mut filters = vec![Filter::Free; n];
        let mut targets = rest.to_vec();
        let axes = [Vector3::x(), Vector3::y(), Vector3::z()];
        let mut fix = |i: usize, axis: usize, value: f64, filters: &mut Vec<Filter>| {
            filters[i] = filters[i].constrain(&axes[axis]);
            targets[i][axis] = value;
        };
        for &i in &sets.bottom {
            match self.bottom {
                BottomCondition::Fixed => (0..3).for_each(|a| fix(i, a, rest[i][a], &mut filters)),
                BottomCondition::Rollers => fix(i, 2, rest[i].z, &mut filters),
            }
        }
        let caliper_axis = self.caliper.as_ref().map(|c| c.axis);
        for (k, side) in sets.sides.iter().enumerate() {
            let normal = k / 2;
            if caliper_axis == Some(normal) {
                continue;
            }
            for &i in side {
                match self.sides {
                    SideCondition::Clamped => {
                        (0..3).for_each(|a| fix(i, a, rest[i][a], &mut filters))
                    }
                    SideCondition::Rollers => fix(i, normal, rest[i][normal], &mut filters),
                    SideCondition::Free => {}
                }
            }
        }
        if let Some(c) = &self.caliper {
            let s = c.stretch.at(t);
            let centre = sets.centre[c.axis];
            for side in &sets.sides[2 * c.axis..2 * c.axis + 2] {
                for &i in side {
                    fix(
                        i,
                        c.axis,
                        centre + s * (rest[i][c.axis] - centre),
                        &mut filters,
                    );
                }
            }
        }
        for p in &self.prescribed {
            let u = p.displacement.at(t);
            for &i in &p.nodes {
                (0..3).for_each(|a| fix(i, a, rest[i][a] + u[a], &mut filters));
            }
        }
        (filters, targets)
    }
}

/// A node held along some directions so that the constraints leave no
/// rigid motion of the patch free (see [`rigid_motion_pins`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pin {
    /// The node.
    pub node: usize,
    /// Its filter with the held directions added.
    pub filter: Filter,
}

/// The rigid motions of `rest` (three translations, three rotations about
/// the centroid) that `filters` leave entirely free, as an orthonormal basis
/// of coefficient vectors (empty when the supports hold every one).
fn free_rigid_motions(rest: &[Vec3], filters: &[Filter]) -> Vec<nalgebra::Vector6<f64>> {
    let n = rest.len().max(1) as f64;
    let centre = rest.iter().sum::<Vec3>() / n;
    // Gram matrix of the modes' constrained parts: Σ_i u_kᵀ (I − S_i) u_l.
    let mut gram = nalgebra::Matrix6::<f64>::zeros();
    let mut size = 0.0;
    for (x, f) in rest.iter().zip(filters) {
        let modes = rigid_modes_at(x, &centre);
        size += modes.iter().map(|u| u.norm_squared()).sum::<f64>();
        if *f == Filter::Free {
            continue;
        }
        let held = modes.map(|u| u - f.apply(&u));
        for k in 0..6 {
            for l in 0..6 {
                gram[(k, l)] += held[k].dot(&held[l]);
            }
        }
    }
    let eigen = gram.symmetric_eigen();
    (0..6)
        .filter(|&k| eigen.eigenvalues[k] <= 1e-12 * size)
        .map(|k| eigen.eigenvectors.column(k).into_owned())
        .collect()
}

/// The displacement of a point at `x` under each unit rigid motion about
/// `centre`: translations along x, y, z, then rotations about them.
fn rigid_modes_at(x: &Vec3, centre: &Vec3) -> [Vec3; 6] {
    let r = x - centre;
    [
        Vec3::x(),
        Vec3::y(),
        Vec3::z(),
        Vec3::x().cross(&r),
        Vec3::y().cross(&r),
        Vec3::z().cross(&r),
    ]
}

/// Pins that remove the rigid motions `filters` leave free (e.g. a bottom
/// on rollers with free sides leaves the patch free to slide along x and y
/// and to turn about z). A quasi-static solve of such a patch has no unique
/// answer, and a frictionless probe on it is a neutral or unstable mode in
/// which Newton's method stalls. The pins are statically determinate — the
/// fewest directions at the fewest nodes, chosen from `pool` (the bottom
/// face, say): the node nearest the pool's centroid is held along every
/// direction in which a free motion moves it, then the node farthest from
/// the pins so far, until no motion is free (at most three nodes). Pins
/// carry no force at an equilibrium whose loads have no net force or
/// moment along the free motions, so they change no answer that exists
/// without them. Targets stay the rest positions.
pub fn rigid_motion_pins(rest: &[Vec3], filters: &[Filter], pool: &[usize]) -> Vec<Pin> {
    let mut filters = filters.to_vec();
    let mut pins: Vec<Pin> = Vec::new();
    let pool: Vec<usize> = if pool.is_empty() {
        (0..rest.len()).collect()
    } else {
        pool.to_vec()
    };
    if pool.is_empty() {
        return pins;
    }
    let centre = rest.iter().sum::<Vec3>() / rest.len() as f64;
    let pool_centre = pool.iter().map(|&i| rest[i]).sum::<Vec3>() / pool.len() as f64;
    for _ in 0..3 {
        let free = free_rigid_motions(rest, &filters);
        if free.is_empty() {
            break;
        }
        // The node nearest the pool's centroid first, then the one farthest
        // from every pin so far (ties: the lower index).
        let score = |i: usize| -> f64 {
            if pins.is_empty() {
                -(rest[i] - pool_centre).norm()
            } else {
                pins.iter()
                    .map(|p| (rest[i] - rest[p.node]).norm())
                    .fold(f64::INFINITY, f64::min)
            }
        };
        let node = pool
            .iter()
            .copied()
            .fold(None, |best: Option<(usize, f64)>, i| {
                let s = score(i);
                match best {
                    Some((_, b)) if b >= s => best,
                    _ => Some((i, s)),
                }
            })
            .map(|(i, _)| i)
            .expect("the pool is not empty");
        let modes = rigid_modes_at(&rest[node], &centre);
        let moves = nalgebra::Matrix3xX::from_columns(
            &free
                .iter()
                .map(|c| filters[node].apply(&(0..6).map(|k| modes[k] * c[k]).sum::<Vec3>()))
                .collect::<Vec<_>>(),
        );
        let svd = moves.svd(true, false);
        let largest = svd.singular_values.max();
        let u = svd.u.expect("asked for U");
        let mut filter = filters[node];
        for (k, &s) in svd.singular_values.iter().enumerate() {
            if s > 1e-9 * largest && largest > 0.0 {
                filter = filter.constrain(&u.column(k).into_owned());
            }
        }
        if filter == filters[node] {
            break;
        }
        filters[node] = filter;
        pins.retain(|p| p.node != node);
        pins.push(Pin { node, filter });
    }
    pins
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keyframes_interpolate_and_hold() {
        let k = Keyframes {
            points: vec![(0.0, 1.0), (1.0, 1.25), (2.0, 0.8)],
        };
        assert_eq!(k.at(-1.0), 1.0);
        assert!((k.at(0.5) - 1.125).abs() < 1e-15);
        assert!((k.at(1.5) - 1.025).abs() < 1e-15);
        assert_eq!(k.at(5.0), 0.8);
    }

    /// A 3 × 3 × 2 lattice with its bottom on rollers can slide along x and
    /// y and turn about z: two pins hold it (the bottom centre along x and
    /// y, the farthest bottom node along its tangent of the turn), and then
    /// no rigid motion is free. Rollers on the sides leave none to pin.
    #[test]
    fn pins_hold_exactly_the_free_rigid_motions() {
        let rest: Vec<Vec3> = (0..18)
            .map(|k| Vec3::new((k % 3) as f64, ((k / 3) % 3) as f64, (k / 9) as f64))
            .collect();
        let bottom: Vec<usize> = (0..9).collect();
        let mut filters = vec![Filter::Free; rest.len()];
        for &i in &bottom {
            filters[i] = Filter::Free.constrain(&Vector3::z());
        }
        assert_eq!(free_rigid_motions(&rest, &filters).len(), 3);
        let pins = rigid_motion_pins(&rest, &filters, &bottom);
        assert_eq!(pins.len(), 2, "{pins:?}");
        assert_eq!(pins[0].node, 4);
        assert_eq!(pins[0].filter, Filter::Fixed);
        assert_eq!(pins[1].node, 0);
        let s = pins[1].filter.matrix();
        // Held along z and the turn's tangent at (−1, −1) from the centre.
        let tangent = Vector3::new(1.0, -1.0, 0.0).normalize();
        assert!((s * tangent).norm() < 1e-12 && (s * Vector3::z()).norm() < 1e-12);
        let radial = Vector3::new(1.0, 1.0, 0.0).normalize();
        assert!((s * radial - radial).norm() < 1e-12);
        for p in &pins {
            filters[p.node] = p.filter;
        }
        assert!(free_rigid_motions(&rest, &filters).is_empty());
        // Sides on rollers hold the sliding and the turn.
        let mut filters = vec![Filter::Free; rest.len()];
        for &i in &bottom {
            filters[i] = Filter::Free.constrain(&Vector3::z());
        }
        for i in 0..rest.len() {
            for axis in 0..2 {
                if rest[i][axis] == 0.0 || rest[i][axis] == 2.0 {
                    let mut e = Vector3::zeros();
                    e[axis] = 1.0;
                    filters[i] = filters[i].constrain(&e);
                }
            }
        }
        assert!(free_rigid_motions(&rest, &filters).is_empty());
        assert!(rigid_motion_pins(&rest, &filters, &bottom).is_empty());
    }
}
