//! The rigid probe and its contact with the top surface (DESIGN §5.2).
//!
//! Shapes: sphere (centre, radius), capsule (segment through the centre
//! along an axis, radius) and flat cylindrical punch (circular flat face of a
//! radius, pressing along −z; its rim is sharp). A keyframed path gives the
//! centre (and the capsule's axis) over time, linearly interpolated.
//!
//! Contact is node-to-surface with exact constraints (an active set):
//!
//! * a top-surface node that penetrates the probe becomes active;
//! * frictionless (and slipping) nodes are held on the probe surface along
//!   its normal — a filter direction in the solver — and slide freely or
//!   against a Coulomb force `μ·λ_n` opposing the reaction that held them;
//! * sticking and bonded nodes are held at an anchor that moves rigidly with
//!   the probe from where the node was at the start of the frame;
//! * a node whose normal reaction turns adhesive (pulls the probe) is
//!   released, except when bonded; a sticking node whose tangential reaction
//!   exceeds `μ·λ_n` starts to slip.
//!
//! The active set, slip states and constraint normals are updated between
//! equilibrium solves until nothing changes and every node lies within
//! `penetration_tol` of the surface. The probe force is minus the sum of the
//! contact forces on the nodes; at equilibrium it also equals the supports'
//! total reaction, which the tests check.

use nalgebra::Vector3;

use super::boundary::Keyframes;
use crate::mesh::Vec3;

/// Probe geometry.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ProbeShape {
    /// A ball.
    Sphere {
        /// Radius (mm).
        radius_mm: f64,
    },
    /// A cylinder with hemispherical ends, of `length_mm` between the end
    /// centres, along the keyframed axis.
    Capsule {
        /// Radius (mm).
        radius_mm: f64,
        /// Distance between the two end centres (mm).
        length_mm: f64,
    },
    /// A flat circular face of `radius_mm` facing −z at the probe position.
    Punch {
        /// Radius (mm).
        radius_mm: f64,
    },
}

/// How contact nodes interact with the probe.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ContactMode {
    /// No friction.
    Frictionless,
    /// Coulomb friction with this coefficient (stick and slip).
    Coulomb(f64),
    /// Nodes that touch stay attached.
    Bonded,
}

/// The probe: shape, path and contact mode.
#[derive(Clone, Debug, PartialEq)]
pub struct Probe {
    /// Geometry.
    pub shape: ProbeShape,
    /// Position of the centre (sphere, capsule) or face centre (punch) over time (mm).
    pub path: Keyframes<Vector3<f64>>,
    /// Capsule axis over time (normalised after interpolation); ignored otherwise.
    pub axis: Keyframes<Vector3<f64>>,
    /// Contact mode.
    pub mode: ContactMode,
}

/// The probe at one instant.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ProbePose {
    /// Geometry.
    pub shape: ProbeShape,
    /// Centre (mm).
    pub centre: Vec3,
    /// Unit axis (capsule).
    pub axis: Vec3,
}

impl Probe {
    /// The pose at time `t`.
    pub fn pose(&self, t: f64) -> ProbePose {
        let axis = self.axis.at(t);
        let axis = if axis.norm() > 0.0 {
            axis.normalize()
        } else {
            Vector3::x()
        };
        ProbePose {
            shape: self.shape,
            centre: self.path.at(t),
            axis,
        }
    }
}

impl ProbePose {
    /// Signed distance of `p` to the probe surface (negative inside) and the
    /// outward unit normal of the closest surface point.
    pub fn distance(&self, p: &Vec3) -> (f64, Vec3) {
        match self.shape {
            ProbeShape::Sphere { radius_mm } => sphere_distance(&self.centre, radius_mm, p),
            ProbeShape::Capsule {
                radius_mm,
                length_mm,
            } => {
                let d = p - self.centre;
                let s = d.dot(&self.axis).clamp(-length_mm / 2.0, length_mm / 2.0);
                sphere_distance(&(self.centre + self.axis * s), radius_mm, p)
            }
            ProbeShape::Punch { radius_mm } => {
                let d = p - self.centre;
                let r = (d.x * d.x + d.y * d.y).sqrt();
                if r <= radius_mm {
                    // Below the face is outside; above it is inside.
                    (-d.z, -Vec3::z())
                } else {
                    (f64::INFINITY, -Vec3::z())
                }
            }
        }
    }

    /// The closest point on the probe surface to `p`, with its outward normal.
    pub fn project(&self, p: &Vec3) -> (Vec3, Vec3) {
        let (d, n) = self.distance(p);
        if d.is_finite() {
            (p - n * d, n)
        } else {
            (*p, n)
        }
    }

    /// The rigid motion from `self` to `other` applied to `p` (translation,
    /// plus the rotation taking one capsule axis to the other).
    pub fn carry(&self, other: &ProbePose, p: &Vec3) -> Vec3 {
        let rot = nalgebra::Rotation3::rotation_between(&self.axis, &other.axis)
            .unwrap_or_else(nalgebra::Rotation3::identity);
        other.centre + rot * (p - self.centre)
    }
}

fn sphere_distance(c: &Vec3, r: f64, p: &Vec3) -> (f64, Vec3) {
    let d = p - c;
    let len = d.norm();
    let n = if len > 0.0 { d / len } else { Vec3::z() };
    (len - r, n)
}

/// Contact state of one node.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum NodeContact {
    /// Held at `anchor`, which moves with the probe.
    Stick {
        /// Anchor on the probe surface (current frame).
        anchor: Vec3,
    },
    /// Held on the surface along the normal, free or against friction.
    Slide {
        /// Friction force applied to the node (N); zero when frictionless.
        friction: Vec3,
    },
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pose(shape: ProbeShape) -> ProbePose {
        ProbePose {
            shape,
            centre: Vec3::new(0.0, 0.0, 1.0),
            axis: Vec3::x(),
        }
    }

    #[test]
    fn distances_and_normals() {
        let s = pose(ProbeShape::Sphere { radius_mm: 1.5 });
        let (d, n) = s.distance(&Vec3::new(0.0, 0.0, -0.2));
        assert!((d - -0.3).abs() < 1e-15 && (n + Vec3::z()).norm() < 1e-15);
        let c = pose(ProbeShape::Capsule {
            radius_mm: 1.0,
            length_mm: 4.0,
        });
        let (d, n) = c.distance(&Vec3::new(1.7, 0.0, 0.5));
        assert!((d + 0.5).abs() < 1e-15 && (n + Vec3::z()).norm() < 1e-15);
        let (d, _) = c.distance(&Vec3::new(3.0, 0.0, 1.0));
        assert!((d - 0.0).abs() < 1e-15, "end cap at x = 2 + 1");
        let p = pose(ProbeShape::Punch { radius_mm: 1.0 });
        // Below the face (z = 1) is outside, above it inside.
        assert!((p.distance(&Vec3::new(0.5, 0.5, 0.8)).0 - 0.2).abs() < 1e-15);
        assert!((p.distance(&Vec3::new(0.5, 0.5, 1.2)).0 + 0.2).abs() < 1e-15);
        assert!(p.distance(&Vec3::new(1.5, 0.0, 0.8)).0.is_infinite());
        let (q, _) = s.project(&Vec3::new(0.0, 0.0, 0.0));
        assert!((q - Vec3::new(0.0, 0.0, -0.5)).norm() < 1e-15);
    }

    #[test]
    fn carry_moves_rigidly() {
        let a = pose(ProbeShape::Capsule {
            radius_mm: 1.0,
            length_mm: 2.0,
        });
        let mut b = a;
        b.centre = Vec3::new(1.0, 0.0, 1.0);
        b.axis = Vec3::y();
        let p = Vec3::new(1.0, 0.0, 0.0);
        // Offset (1, 0, −1) from the centre turns with the axis into (0, 1, −1).
        assert!((a.carry(&b, &p) - Vec3::new(1.0, 1.0, 0.0)).norm() < 1e-12);
    }
}

/// Active contact nodes and their states, carried from frame to frame.
#[derive(Clone, Debug)]
pub struct ContactState {
    /// Nodes that may touch the probe (top surface, not on the sides).
    candidates: Vec<usize>,
    /// Allowed penetration per node: 1% of the mean incident edge length (mm).
    tolerance: Vec<f64>,
    /// Top-surface triangles as mesh vertex indices (for the contact area).
    top_triangles: Vec<[usize; 3]>,
    /// Active nodes, in ascending order (deterministic iteration).
    pub active: std::collections::BTreeMap<usize, NodeContact>,
    /// Probe pose at the end of the previous solve.
    last_pose: Option<ProbePose>,
    /// Where each active node would be had it moved rigidly with the probe
    /// since the current solve started (to detect re-sticking).
    carried: std::collections::BTreeMap<usize, Vec3>,
    /// Limit on active-set rounds per solve.
    pub max_rounds: usize,
}

/// What a contact solve found.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ContactReport {
    /// Force the skin exerts on the probe (N).
    pub probe_force: Vec3,
    /// Number of nodes in contact.
    pub contact_nodes: usize,
    /// Area of the skin in contact (mm², deformed): each top triangle
    /// counts a third of its area per vertex in contact (lumped nodal areas).
    pub contact_area_mm2: f64,
    /// Largest penetration of any top-surface node (mm, ≥ 0).
    pub max_penetration_mm: f64,
    /// Largest penetration relative to the local element size (the mean
    /// edge length at the node); the contact solve keeps it ≤ 0.01.
    pub max_penetration_ratio: f64,
    /// Active-set rounds taken.
    pub rounds: usize,
    /// Newton iterations over all rounds.
    pub newton_iterations: usize,
    /// CG iterations over all rounds.
    pub cg_iterations: usize,
    /// Final relative residual of the last equilibrium solve.
    pub rel_residual: f64,
}

impl ContactState {
    /// Contact candidates of `mesh`: top-surface nodes not on a side face.
    pub fn new(mesh: &crate::mesh::TetMesh, side_nodes: &[usize]) -> ContactState {
        let side: std::collections::HashSet<usize> = side_nodes.iter().copied().collect();
        let candidates: Vec<usize> = mesh
            .top
            .vertices
            .iter()
            .copied()
            .filter(|v| !side.contains(v))
            .collect();
        let mut edge_sum = vec![0.0; mesh.num_vertices()];
        let mut edge_count = vec![0usize; mesh.num_vertices()];
        for tet in &mesh.tets {
            for i in 0..4 {
                for j in i + 1..4 {
                    let l = (mesh.positions[tet[i]] - mesh.positions[tet[j]]).norm();
                    for v in [tet[i], tet[j]] {
                        edge_sum[v] += l;
                        edge_count[v] += 1;
                    }
                }
            }
        }
        let tolerance = (0..mesh.num_vertices())
            .map(|v| 0.01 * edge_sum[v] / edge_count[v].max(1) as f64)
            .collect();
        ContactState {
            candidates,
            tolerance,
            top_triangles: mesh
                .top
                .triangles
                .iter()
                .map(|t| t.map(|s| mesh.top.vertices[s]))
                .collect(),
            active: Default::default(),
            last_pose: None,
            carried: Default::default(),
            max_rounds: 40,
        }
    }

    /// Allowed penetration at node `v` (mm).
    pub fn tolerance(&self, v: usize) -> f64 {
        self.tolerance[v]
    }
}

/// Solves static equilibrium with the probe at `pose`, on top of the base
/// constraints (`filters`, `targets`) and loads (`f_ext`).
pub fn solve_with_contact(
    sim: &mut super::integrate::Simulation,
    base: (&[super::solve::Filter], &[Vec3], &[Vec3]),
    pose: &ProbePose,
    mode: ContactMode,
    state: &mut ContactState,
    context: &str,
) -> crate::error::Result<ContactReport> {
    let (base_filters, base_targets, base_ext) = base;
    let previous = state.last_pose.unwrap_or(*pose);
    // A new frame: sticking nodes ride along with the probe; sliding nodes
    // keep sliding with last frame's friction (a steady drag then settles in
    // a round or two) and stick again if they end up moving with the probe.
    state.carried = state
        .active
        .keys()
        .map(|&v| (v, previous.carry(pose, &sim.x[v])))
        .collect();
    for (&v, c) in state.active.iter_mut() {
        *c = match (mode, *c) {
            (ContactMode::Frictionless, _) => NodeContact::Slide {
                friction: Vec3::zeros(),
            },
            (ContactMode::Coulomb(_), slide @ NodeContact::Slide { .. }) => slide,
            _ => NodeContact::Stick {
                anchor: pose.project(&previous.carry(pose, &sim.x[v])).0,
            },
        };
    }
    let mut report = ContactReport::default();
    // Rounds solve loosely until the active set settles, then once tightly
    // (and check again): most rounds then cost one or two Newton iterations.
    let final_tol = sim.settings.rel_tol;
    let loose_tol = final_tol.max(1e-3);
    let mut tight = false;
    let mut outcome = Ok(());
    for round in 0..state.max_rounds {
        report.rounds = round + 1;
        sim.filters.copy_from_slice(base_filters);
        sim.targets.copy_from_slice(base_targets);
        sim.f_ext.copy_from_slice(base_ext);
        for (&v, c) in &state.active {
            match *c {
                NodeContact::Stick { anchor } => {
                    sim.filters[v] = super::solve::Filter::Fixed;
                    sim.targets[v] = anchor;
                }
                NodeContact::Slide { friction } => {
                    let (q, n) = pose.project(&sim.x[v]);
                    sim.filters[v] = sim.filters[v].constrain(&n);
                    sim.targets[v] = q;
                    sim.f_ext[v] += friction;
                }
            }
        }
        sim.settings.rel_tol = if tight { final_tol } else { loose_tol };
        let stats = match sim.solve_static(context) {
            Ok(s) => s,
            Err(e) => {
                outcome = Err(e);
                break;
            }
        };
        report.newton_iterations += stats.iterations;
        report.cg_iterations += stats.cg_iterations;
        report.rel_residual = stats.rel_residual;
        let changed = update_active_set(sim, base_ext, pose, mode, state, tight);
        match (changed, tight) {
            (false, true) => break,
            (false, false) => tight = true,
            (true, _) if round + 1 == state.max_rounds => log::warn!(
                "{context}: contact set still changing after {} rounds; keeping the last equilibrium",
                state.max_rounds
            ),
            (true, _) => {}
        }
    }
    sim.settings.rel_tol = final_tol;
    outcome?;
    state.last_pose = Some(*pose);
    finish_report(sim, base_ext, pose, state, &mut report);
    Ok(report)
}

/// Contact force on node `v` at equilibrium: what balances the rest.
fn contact_force(sim: &super::integrate::Simulation, base_ext: &[Vec3], v: usize) -> Vec3 {
    -(sim.internal_forces()[v] + base_ext[v])
}

/// Releases adhesive nodes, switches stick/slip, adds penetrating nodes and
/// flags nodes that drifted off a curved surface. Returns whether anything changed.
fn update_active_set(
    sim: &super::integrate::Simulation,
    base_ext: &[Vec3],
    pose: &ProbePose,
    mode: ContactMode,
    state: &mut ContactState,
    tight: bool,
) -> bool {
    // Friction forces are settled to 1e-3 of their size in tight rounds, 1e-2 before.
    let friction_tol = if tight { 1e-3 } else { 1e-2 };
    let mut changed = false;
    let forces: Vec<(usize, Vec3)> = state
        .active
        .keys()
        .map(|&v| (v, contact_force(sim, base_ext, v)))
        .collect();
    let largest = forces.iter().map(|(_, f)| f.norm()).fold(0.0, f64::max);
    for (v, f) in forces {
        let (dist, n) = pose.distance(&sim.x[v]);
        let normal = f.dot(&n);
        if mode != ContactMode::Bonded && normal < -1e-9 * largest {
            state.active.remove(&v);
            changed = true;
            continue;
        }
        let tol = state.tolerance[v];
        let entry = state.active.get_mut(&v).expect("active node");
        match (mode, *entry) {
            (ContactMode::Coulomb(mu), NodeContact::Stick { .. }) => {
                let ft = f - n * normal;
                if ft.norm() > mu * normal.max(0.0) * (1.0 + 1e-9) {
                    *entry = NodeContact::Slide {
                        friction: ft.normalize() * (mu * normal.max(0.0)),
                    };
                    changed = true;
                }
            }
            (ContactMode::Coulomb(mu), NodeContact::Slide { friction }) => {
                // Slip over this solve relative to the probe surface: if the
                // node ends up moving along its friction force, it sticks.
                if let Some(&carried) = state.carried.get(&v) {
                    let slip = sim.x[v] - carried;
                    let slip_t = slip - n * slip.dot(&n);
                    if friction.dot(&slip_t) > 0.0 && slip_t.norm() > 0.1 * tol {
                        *entry = NodeContact::Stick {
                            anchor: pose.project(&carried).0,
                        };
                        changed = true;
                        continue;
                    }
                }
                let magnitude = mu * normal.max(0.0);
                let dir = if friction.norm() > 0.0 {
                    friction.normalize()
                } else {
                    Vec3::zeros()
                };
                // Keep the direction, tangent to the current normal.
                let dir = (dir - n * dir.dot(&n)).try_normalize(1e-12).unwrap_or(dir);
                let updated = dir * magnitude;
                if (updated - friction).norm() > friction_tol * magnitude.max(1e-12) {
                    *entry = NodeContact::Slide { friction: updated };
                    changed = true;
                }
                if dist.abs() > tol {
                    changed = true;
                }
            }
            (_, NodeContact::Slide { .. }) if dist.abs() > tol => changed = true,
            _ => {}
        }
    }
    for &v in &state.candidates {
        if state.active.contains_key(&v) {
            continue;
        }
        let (dist, _) = pose.distance(&sim.x[v]);
        if dist < -state.tolerance[v] {
            let (q, _) = pose.project(&sim.x[v]);
            let c = match mode {
                ContactMode::Frictionless => NodeContact::Slide {
                    friction: Vec3::zeros(),
                },
                _ => NodeContact::Stick { anchor: q },
            };
            state.active.insert(v, c);
            changed = true;
        }
    }
    changed
}

fn finish_report(
    sim: &super::integrate::Simulation,
    base_ext: &[Vec3],
    pose: &ProbePose,
    state: &ContactState,
    report: &mut ContactReport,
) {
    let mut force = Vec3::zeros();
    for &v in state.active.keys() {
        force -= contact_force(sim, base_ext, v);
    }
    report.probe_force = force;
    report.contact_nodes = state.active.len();
    report.contact_area_mm2 = state
        .top_triangles
        .iter()
        .map(|tri| {
            let touching = tri.iter().filter(|v| state.active.contains_key(v)).count();
            if touching == 0 {
                return 0.0;
            }
            let [a, b, c] = tri.map(|v| sim.x[v]);
            (b - a).cross(&(c - a)).norm() / 2.0 * touching as f64 / 3.0
        })
        .sum();
    for &v in &state.candidates {
        let pen = (-pose.distance(&sim.x[v]).0).max(0.0);
        report.max_penetration_mm = report.max_penetration_mm.max(pen);
        report.max_penetration_ratio = report
            .max_penetration_ratio
            .max(pen / state.tolerance[v] * 0.01);
    }
}
