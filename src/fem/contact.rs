//! The rigid probe's contact with the top surface. The probe's shapes, path
//! and distance queries are in [`super::probe`] (re-exported here).
//!
//! Contact is node-to-surface with exact constraints, resolved inside one
//! Newton loop as a primal–dual active set (semi-smooth Newton; Hüeber,
//! Stadler & Wohlmuth 2008), see [`solve_with_contact`]:
//!
//! * at every Newton iteration a top-surface node is in contact when its
//!   normal reaction minus its stiffness times its signed gap is positive;
//! * frictionless and slipping nodes are held on the tangent plane of their
//!   closest probe point and slide freely or against a Coulomb slip load of
//!   magnitude `μ·F_n` along the trial force `λ_t − c·s`, which opposes
//!   their slip at a solution (Alart & Curnier 1991; its derivative is in
//!   the Newton matrix, see [`super::simulation::SlipLoad`]); a sliding
//!   node's plane is re-projected at every Newton
//!   iteration with the probe's curvature times its normal reaction (and,
//!   under friction, the turning of that reaction) in the matrix, so Newton
//!   converges quadratically on the curved surface;
//! * a probe that slips between the surface nodes (the surface above its
//!   lowest point higher than that point) stops the solve with an error;
//! * sticking and bonded nodes are held at an anchor that moves rigidly with
//!   the probe from where the node was at the start of the frame;
//! * a Coulomb node's slip over a step is relative to the probe: from where
//!   the node would be had it moved with the probe since the step began —
//!   also for a node the probe reaches during the step, which starts
//!   sliding (the probe slides over it; its friction drags the skin along);
//! * a Coulomb node sticks while `|c·s_t − F_t| ≤ μ F_n` and slides
//!   otherwise; bonded nodes are never released, and a bonded node that
//!   touches sticks where it touched.
//!
//! A solve has converged when an iteration changes no contact or stick/slip
//! state and the residual and every constraint are within tolerance. The
//! probe force is minus the sum of the contact forces on the nodes; at
//! equilibrium it also equals the supports' total reaction, which the tests
//! check.

pub use super::probe::{ContactMode, Probe, ProbePose, ProbeShape};
use crate::mesh::Vec3;

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
    /// Per active node the slip reference: where the node would be had it
    /// moved rigidly with the probe since the solve started (for a bonded or
    /// frictionless node that touched during the solve, where it touched).
    /// Slip is measured from it and a sticking node is held at its
    /// projection.
    reference: std::collections::BTreeMap<usize, Vec3>,
    /// Every node's position at the end of the previous solve (before the
    /// first, at its start): slip references are carried from here. The
    /// solve itself starts where the caller put the nodes (a predicted
    /// start moves the surface on with the rest; a surface held back where
    /// it was solved would leave a start residual of several times the
    /// load).
    solved: Vec<Vec3>,
    /// Per sliding node the constraint plane in use (point, normal): the
    /// tangent plane where the node is, taken at every iteration (with the
    /// probe's curvature in the matrix); checked against the probe's normal
    /// on the nearly converged iterate ([`max_tilt`]).
    planes: std::collections::BTreeMap<usize, (Vec3, Vec3)>,
    /// Complementarity constants: each node's rest stiffness (N/mm), which
    /// turns a gap or a slip into a comparable force.
    stiffness: Vec<f64>,
    /// The last solve's force and traction per contact node.
    forces: ContactForces,
}

/// The probe's force on each skin node in contact after a solve, with the
/// contact normal and the node's share of the deformed surface: what the
/// nodal contact pressure and shear traction are made of.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ContactForces {
    /// Mesh vertices in contact, ascending.
    pub nodes: Vec<usize>,
    /// Force of the probe on the node (N).
    pub force_n: Vec<Vec3>,
    /// The probe surface's outward unit normal at the node.
    pub normal: Vec<Vec3>,
    /// The node's lumped area of the deformed top surface (mm²): a third of
    /// each top triangle at the node.
    pub area_mm2: Vec<f64>,
}

impl ContactForces {
    /// Contact pressure at the `k`-th node in contact (N/mm²): the normal
    /// force over the node's area, positive when the probe pushes.
    pub fn pressure(&self, k: usize) -> f64 {
        self.force_n[k].dot(&self.normal[k]) / self.area_mm2[k]
    }

    /// Shear traction at the `k`-th node in contact (N/mm²): the
    /// tangential force over the node's area.
    pub fn shear(&self, k: usize) -> f64 {
        tangential(&self.force_n[k], &self.normal[k]).norm() / self.area_mm2[k]
    }

    /// The traction `(pressure · normal + shear traction) · area` summed over
    /// the contact: the force the skin feels from the probe (N).
    pub fn total(&self) -> Vec3 {
        self.force_n.iter().sum()
    }
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
    /// Newton iterations of the solve.
    pub newton_iterations: usize,
    /// Linear-solver iterations of the solve.
    pub cg_iterations: usize,
    /// Final relative residual.
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
            reference: Default::default(),
            solved: Default::default(),
            planes: Default::default(),
            stiffness: Vec::new(),
            forces: ContactForces::default(),
        }
    }

    /// The last solve's force and traction per contact node.
    pub fn forces(&self) -> &ContactForces {
        &self.forces
    }

    /// Allowed penetration at node `v` (mm).
    pub fn tolerance(&self, v: usize) -> f64 {
        self.tolerance[v]
    }

    /// The Coulomb slip load of sliding node `v` (normal `n`, current
    /// friction force `friction`).
    fn slip_load(&self, v: usize, n: Vec3, friction: Vec3, mu: f64) -> super::simulation::SlipLoad {
        super::simulation::SlipLoad {
            node: v,
            reference: self.reference[&v],
            normal: n,
            magnitude: friction.norm(),
            mu,
            stiffness: self.stiffness[v],
        }
    }
}

/// After this many Newton iterations the contact update stops switching
/// nodes on a knife edge: it activates only nodes past the penetration
/// tolerance and releases only clearly adhesive ones (hysteresis against
/// cycling).
const HYSTERESIS_AFTER: usize = 12;

/// After this many Newton iterations no node leaves contact and no node
/// changes between stick and slip (with a warning): the set only takes in
/// nodes inside the probe beyond their tolerance, so it cannot cycle (on
/// the Hertz block at ν 0.4999 it did, for good) and leaves no node inside.
const FREEZE_AFTER: usize = 30;

/// Angle (rad) by which a kept constraint plane may differ from the tangent
/// plane at the node's closest probe point at convergence.
const MAX_TILT: f64 = 2e-4;

/// One contact solve: the probe, the mode and the base problem.
struct Frame<'a> {
    base_filters: &'a [super::solve::Filter],
    base_targets: &'a [Vec3],
    base_ext: &'a [Vec3],
    pose: &'a ProbePose,
    mode: ContactMode,
    /// The probe at the end of the last solve.
    previous: ProbePose,
}

/// Solves static equilibrium with the probe at `pose`, on top of the base
/// constraints (`filters`, `targets`) and loads (`f_ext`).
///
/// Contact is resolved inside one Newton loop, a primal–dual active set
/// (semi-smooth Newton; Hüeber, Stadler & Wohlmuth 2008): at every Newton
/// iteration, from the current positions and reactions, a node is in
/// contact when `F_n − c·g > 0` (normal reaction `F_n`, signed gap `g`,
/// node stiffness `c`), and a Coulomb node sticks when
/// `|−F_t + c·s_t| ≤ μ F_n` (tangential force `F_t`, slip `s_t` since the
/// solve started) and otherwise slides against the friction force
/// `−μ F_n` along that vector. A sliding node is held on the tangent plane
/// of its closest probe point, re-projected at every iteration with the
/// probe's curvature in the Newton matrix. The
/// solve ends with an error when the probe has passed through the skin
/// between the nodes (see `passed_through`). The first iteration judges
/// no carried-over node (its positions and reactions are the last solve's).
/// The solve has converged when an iteration changes no contact or
/// stick/slip state and the residual and constraint gaps are within
/// tolerance.
pub fn solve_with_contact(
    sim: &mut super::simulation::Simulation,
    base: (&[super::solve::Filter], &[Vec3], &[Vec3]),
    pose: &ProbePose,
    mode: ContactMode,
    state: &mut ContactState,
    context: &str,
) -> crate::error::Result<ContactReport> {
    let (base_filters, base_targets, base_ext) = base;
    if state.stiffness.len() != sim.num_nodes() {
        state.stiffness = sim.rest_node_stiffness();
    }
    let previous = state.last_pose.unwrap_or(*pose);
    if state.solved.len() != sim.num_nodes() {
        state.solved = sim.state.x.clone();
    }
    // A new solve: every active node's slip reference rides along with the
    // probe from where the node is; sticking nodes are held there, sliding
    // ones keep last solve's friction as their first guess.
    state.reference = state
        .active
        .keys()
        .map(|&v| (v, previous.carry(pose, &state.solved[v])))
        .collect();
    for (&v, c) in state.active.iter_mut() {
        *c = match (mode, *c) {
            (ContactMode::Frictionless, _) => NodeContact::Slide {
                friction: Vec3::zeros(),
            },
            (ContactMode::Coulomb(_), slide @ NodeContact::Slide { .. }) => slide,
            _ => NodeContact::Stick {
                anchor: pose.project(&state.reference[&v]).0,
            },
        };
    }
    state.planes.clear();
    let frame = Frame {
        base_filters,
        base_targets,
        base_ext,
        pose,
        mode,
        previous,
    };
    let mut warned = false;
    let stats = sim.solve_with(context, |sim, it, converged| {
        if converged {
            let tilted = drop_tilted_planes(sim, &frame, state);
            if tilted {
                apply_contact(sim, &frame, state);
            }
            return tilted;
        }
        let changed = if it < FREEZE_AFTER {
            update_active_set(sim, &frame, state, it)
        } else if !warned {
            log::warn!(
                "{context}: contact set still changing after {FREEZE_AFTER} Newton iterations; \
                 from now on it only takes in nodes inside the probe"
            );
            warned = true;
            // The frozen set is a new problem: Newton restarts on it with
            // the exact tangent.
            true
        } else {
            // Only growing, the set cannot cycle, and no node is left
            // inside the probe beyond its tolerance.
            activate(sim, &frame, state, 1.0) > 0
        };
        apply_contact(sim, &frame, state);
        changed
    })?;
    state.last_pose = Some(*pose);
    state.solved.clone_from(&sim.state.x);
    let mut report = ContactReport {
        newton_iterations: stats.iterations,
        cg_iterations: stats.cg_iterations,
        rel_residual: stats.rel_residual,
        ..Default::default()
    };
    finish_report(sim, base_ext, pose, state, &mut report);
    refuse_penetration(sim.positions(), pose, state, context)?;
    if let Some(depth) = passed_through(sim, pose, state) {
        let p = pose.lowest_point();
        return Err(crate::error::Error::Solver(format!(
            "{context}: the probe has passed through the skin: its lowest point ({:.3}, {:.3}, \
             {:.3}) mm is {depth:.3} mm below the deformed surface above it, and {} nodes hold \
             it (node-to-surface contact cannot keep a probe this deep out of this mesh: press \
             less deep, or refine the top layer)",
            p.x, p.y, p.z, report.contact_nodes
        )));
    }
    Ok(report)
}

/// Refuses a solve that ends with surface nodes inside the probe by more
/// than their tolerance (1% of the mean edge length at the node). The
/// contact update takes such a node in, so a solve cannot converge with
/// one — this is the backstop that keeps it so (before the set only grew
/// after [`FREEZE_AFTER`] iterations, a frozen set left nodes 8 times
/// their tolerance inside); the error names the penetration, the nodes and
/// what to try, and the load step is cut back like any failed solve.
fn refuse_penetration(
    x: &[Vec3],
    pose: &ProbePose,
    state: &ContactState,
    context: &str,
) -> crate::error::Result<()> {
    let inside: Vec<(usize, f64)> = state
        .candidates
        .iter()
        .map(|&v| (v, -pose.distance(&x[v]).0))
        .filter(|&(v, depth)| depth > state.tolerance[v])
        .collect();
    let Some(&(node, depth)) = inside.iter().max_by(|a, b| a.1.total_cmp(&b.1)) else {
        return Ok(());
    };
    let p = x[node];
    Err(crate::error::Error::Solver(format!(
        "{context}: {} surface node(s) are inside the probe by more than their tolerance \
         (1% of the edge length at the node); the deepest, node {node} at ({:.3}, {:.3}, \
         {:.3}) mm, by {depth:.2e} mm ({:.0} times its tolerance): more load steps \
         (time.substeps) let the contact set settle",
        inside.len(),
        p.x,
        p.y,
        p.z,
        depth / state.tolerance[node],
    )))
}

/// Whether the probe has slipped through the skin between the surface
/// nodes (which node-to-surface contact cannot see): the deformed top
/// surface right above the probe's lowest point — the lowest triangle whose
/// horizontal projection holds it — lies above that point by more than the
/// triangle's longest edge, so the probe is inside the skin. A probe the
/// skin holds has that surface on its own, within the sag of a triangle's
/// chord. Returns how deep the point is below the surface (mm).
fn passed_through(
    sim: &super::simulation::Simulation,
    pose: &ProbePose,
    state: &ContactState,
) -> Option<f64> {
    let p = pose.lowest_point();
    let x = sim.positions();
    let mut lowest: Option<(f64, f64)> = None;
    for tri in &state.top_triangles {
        let [a, b, c] = tri.map(|v| x[v]);
        let Some(z) = height_above(&a, &b, &c, &p) else {
            continue;
        };
        let edge = [(b - a).norm(), (c - b).norm(), (a - c).norm()]
            .into_iter()
            .fold(0.0, f64::max);
        if lowest.is_none_or(|(lz, _)| z < lz) {
            lowest = Some((z, edge));
        }
    }
    let (z, edge) = lowest?;
    (z - p.z > edge).then_some(z - p.z)
}

/// The height at `p`'s (x, y) of the triangle `a b c` if its horizontal
/// projection holds that point (edges included).
fn height_above(a: &Vec3, b: &Vec3, c: &Vec3, p: &Vec3) -> Option<f64> {
    let det = (b.x - a.x) * (c.y - a.y) - (c.x - a.x) * (b.y - a.y);
    if det.abs() < 1e-300 {
        return None;
    }
    let u = ((p.x - a.x) * (c.y - a.y) - (c.x - a.x) * (p.y - a.y)) / det;
    let v = ((b.x - a.x) * (p.y - a.y) - (p.x - a.x) * (b.y - a.y)) / det;
    let eps = -1e-12;
    (u >= eps && v >= eps && u + v <= 1.0 - eps).then(|| a.z + u * (b.z - a.z) + v * (c.z - a.z))
}

/// Contact force on node `v`: what balances the rest (at equilibrium; at an
/// iterate, the force the constraints exert).
fn contact_force(sim: &super::simulation::Simulation, base_ext: &[Vec3], v: usize) -> Vec3 {
    -(sim.internal_forces()[v] + base_ext[v])
}

/// `v` without its component along the unit vector `n`.
fn tangential(v: &Vec3, n: &Vec3) -> Vec3 {
    v - n * v.dot(n)
}

/// The semi-smooth Newton update of the contact set and the stick/slip
/// states from the current positions and reactions (see
/// [`solve_with_contact`]) at Newton `iteration` (the hysteresis is on from
/// [`HYSTERESIS_AFTER`]). Returns
/// whether any node entered or left contact or changed between stick and slip.
fn update_active_set(
    sim: &super::simulation::Simulation,
    frame: &Frame,
    state: &mut ContactState,
    iteration: usize,
) -> bool {
    let settled = iteration >= HYSTERESIS_AFTER;
    let mut changed = false;
    let mut counts = [0usize; 4];
    // Before the first step the positions and reactions are the last
    // solve's (or a prediction from it), not an equilibrium with the moved
    // probe: judging the carried-over nodes on them would release every
    // node the probe moves away from. They keep the states set up for the
    // solve; only new contacts are found.
    let forces: Vec<(usize, Vec3)> = if iteration == 0 {
        Vec::new()
    } else {
        state
            .active
            .keys()
            .map(|&v| (v, contact_force(sim, frame.base_ext, v)))
            .collect()
    };
    let largest = forces.iter().map(|(_, f)| f.norm()).fold(0.0, f64::max);
    let release_below = if settled { -1e-3 } else { -1e-9 } * largest;
    for (v, f) in forces {
        let (gap, n) = frame.pose.distance(&sim.state.x[v]);
        let normal = f.dot(&n);
        let c = state.stiffness[v];
        // A sliding Coulomb node whose normal reaction vanishes is released
        // without hysteresis: at F_n = 0 its friction μ·max(F_n, 0) has a
        // kink that, with the node held, stalls Newton.
        let sliding = matches!(frame.mode, ContactMode::Coulomb(_))
            && matches!(state.active[&v], NodeContact::Slide { .. });
        let below = if sliding {
            release_below.max(-1e-9 * largest)
        } else {
            release_below
        };
        if frame.mode != ContactMode::Bonded && normal - c * gap < below {
            state.active.remove(&v);
            state.reference.remove(&v);
            changed = true;
            counts[0] += 1;
            continue;
        }
        let ContactMode::Coulomb(mu) = frame.mode else {
            continue;
        };
        let limit = mu * normal.max(0.0);
        let reference = state.reference[&v];
        let next = match state.active[&v] {
            NodeContact::Stick { anchor } => {
                let xi = tangential(&(c * (sim.state.x[v] - anchor) - f), &n);
                if xi.norm() > limit * (1.0 + 1e-9) + 1e-12 * largest {
                    changed = true;
                    counts[1] += 1;
                    NodeContact::Slide {
                        friction: -xi.normalize() * limit,
                    }
                } else {
                    continue;
                }
            }
            NodeContact::Slide { friction } => {
                // The trial force `λ_t − c·s`: a node whose tangential
                // reaction and slip no longer exceed the cone sticks.
                let load = state.slip_load(v, n, friction, mu);
                let xi = load.trial(&sim.state.x[v], &f);
                if xi.norm() <= limit {
                    changed = true;
                    counts[2] += 1;
                    NodeContact::Stick {
                        anchor: frame.pose.project(&reference).0,
                    }
                } else {
                    // The solver recomputes the force from the reaction at
                    // every residual (its derivative is in the Newton
                    // matrix); this is the current value.
                    NodeContact::Slide {
                        friction: xi.normalize() * limit,
                    }
                }
            }
        };
        state.active.insert(v, next);
    }
    let activate_below = if settled { 1.0 } else { 0.1 };
    counts[3] = activate(sim, frame, state, activate_below);
    changed |= counts[3] > 0;
    if changed {
        log::debug!(
            "contact: {} released, {} stick→slip, {} slip→stick, {} new",
            counts[0],
            counts[1],
            counts[2],
            counts[3]
        );
    }
    changed
}

/// Takes into contact every candidate node inside the probe by more than
/// `activate_below` times its tolerance, each in the state its mode starts
/// it in; returns how many.
fn activate(
    sim: &super::simulation::Simulation,
    frame: &Frame,
    state: &mut ContactState,
    activate_below: f64,
) -> usize {
    let mut added = 0;
    for &v in &state.candidates {
        if state.active.contains_key(&v) {
            continue;
        }
        let (gap, n) = frame.pose.distance(&sim.state.x[v]);
        if gap < -activate_below * state.tolerance[v] {
            let q = frame.pose.project(&sim.state.x[v]).0;
            let (c, reference) = match frame.mode {
                ContactMode::Frictionless => (
                    NodeContact::Slide {
                        friction: Vec3::zeros(),
                    },
                    q,
                ),
                ContactMode::Bonded => (NodeContact::Stick { anchor: q }, q),
                // Coulomb slip over the solve is relative to the probe:
                // measured from where the node would be had it moved with
                // the probe since the solve started (the probe slides over
                // a node it reaches during the step). The node has no
                // reaction yet; its penalty trial force (c·|g| normal,
                // c·|s_t| tangential for its tangential offset s_t from
                // the anchor) decides: inside the cone it starts sticking,
                // otherwise sliding with its friction following its
                // normal reaction. (New nodes that all started sliding
                // cost most pressing frames a Newton iteration: they stick.)
                ContactMode::Coulomb(mu) => {
                    let reference = frame.previous.carry(frame.pose, &state.solved[v]);
                    let anchor = frame.pose.project(&reference).0;
                    let shift = tangential(&(sim.state.x[v] - anchor), &n).norm();
                    if shift <= -mu * gap {
                        (NodeContact::Stick { anchor }, reference)
                    } else {
                        (
                            NodeContact::Slide {
                                friction: Vec3::zeros(),
                            },
                            reference,
                        )
                    }
                }
            };
            state.active.insert(v, c);
            state.reference.insert(v, reference);
            added += 1;
        }
    }
    added
}

/// Whether any sliding node's plane (taken where the node was at the start
/// of the last Newton step) differs from the probe normal at the node's
/// closest point now by more than [`max_tilt`]; those planes are forgotten
/// and the caller re-applies the constraints ([`apply_contact`]) at the
/// current positions. Called on a nearly converged iterate: a plane the
/// node slid along has tilted by its drift over the probe radius, and the
/// node's reaction with it, which gives a frictionless probe a tangential
/// force of that order and turns a Coulomb node's force out of its cone by
/// the tilt (|f_t|/f_n off by about θ(1 + μ²)).
fn drop_tilted_planes(
    sim: &super::simulation::Simulation,
    frame: &Frame,
    state: &mut ContactState,
) -> bool {
    let limit = max_tilt(frame.mode);
    let before = state.planes.len();
    state
        .planes
        .retain(|&v, plane| (plane.1 - frame.pose.distance(&sim.state.x[v]).1).norm() <= limit);
    state.planes.len() != before
}

/// Angle (rad) by which a kept constraint plane may differ from the
/// tangent plane at the node's closest probe point at convergence:
/// [`MAX_TILT`] without friction; under Coulomb friction small enough that
/// no node's |f_t|/f_n exceeds μ by more than 5e-4 of itself (half the
/// bound the tests hold it to), `5e-4·μ/(1 + μ²)`.
fn max_tilt(mode: ContactMode) -> f64 {
    match mode {
        ContactMode::Coulomb(mu) if mu > 0.0 => MAX_TILT.min(5e-4 * mu / (1.0 + mu * mu)),
        _ => MAX_TILT,
    }
}

/// Sets the solver's constraints and loads for the current contact state:
/// sticking nodes fixed at their anchors, sliding nodes held along the
/// normal at their closest probe point with their friction force.
fn apply_contact(sim: &mut super::simulation::Simulation, frame: &Frame, state: &mut ContactState) {
    sim.loads.filters.copy_from_slice(frame.base_filters);
    sim.loads.targets.copy_from_slice(frame.base_targets);
    sim.loads.f_ext.copy_from_slice(frame.base_ext);
    sim.loads.slip_loads.clear();
    sim.loads.curvature.clear();
    state.planes.retain(|v, _| state.active.contains_key(v));
    for (&v, c) in &state.active {
        match *c {
            NodeContact::Stick { anchor } => {
                sim.loads.filters[v] = super::solve::Filter::Fixed;
                sim.loads.targets[v] = anchor;
            }
            NodeContact::Slide { friction } => {
                // The constraint linearised where the node is: the tangent
                // plane at its closest probe point, with the second-order
                // terms of the curved surface in the matrix.
                let x = sim.state.x[v];
                let (q, n) = frame.pose.project(&x);
                let fc = contact_force(sim, frame.base_ext, v);
                let reaction = fc.dot(&n).max(0.0);
                if reaction > 0.0 {
                    let h = frame.pose.distance_hessian(&x);
                    // The normal reaction holding the node on the curved
                    // surface: −F_n ∇²g.
                    let mut k = -h * reaction;
                    if let ContactMode::Coulomb(mu) = frame.mode {
                        // The friction magnitude μ·F_n follows the normal
                        // reaction, which turns with the normal:
                        // δF_n ⊃ (H f_c)·δx, so the friction force
                        // (along the trial direction ξ̂) gains
                        // μ ξ̂ (H f_c)ᵀ δx (symmetric on a sphere; its
                        // symmetric part elsewhere).
                        let load = state.slip_load(v, n, friction, mu);
                        let dir = -load
                            .trial(&x, &fc)
                            .try_normalize(0.0)
                            .unwrap_or_else(Vec3::zeros);
                        let t = dir * (h * fc).transpose() * mu;
                        k += (t + t.transpose()) * 0.5;
                    }
                    sim.loads.curvature.push((v, k));
                }
                state.planes.insert(v, (q, n));
                sim.loads.filters[v] = sim.loads.filters[v].constrain(&n);
                sim.loads.targets[v] = q;
                if let ContactMode::Coulomb(mu) = frame.mode {
                    sim.loads
                        .slip_loads
                        .push(state.slip_load(v, n, friction, mu));
                }
            }
        }
    }
}

fn finish_report(
    sim: &super::simulation::Simulation,
    base_ext: &[Vec3],
    pose: &ProbePose,
    state: &mut ContactState,
    report: &mut ContactReport,
) {
    let mut force = Vec3::zeros();
    let mut forces = ContactForces::default();
    for &v in state.active.keys() {
        let f = contact_force(sim, base_ext, v);
        force -= f;
        forces.nodes.push(v);
        forces.force_n.push(f);
        forces.normal.push(pose.distance(&sim.state.x[v]).1);
    }
    forces.area_mm2 = vec![0.0; forces.nodes.len()];
    for tri in &state.top_triangles {
        let [a, b, c] = tri.map(|v| sim.state.x[v]);
        let third = (b - a).cross(&(c - a)).norm() / 6.0;
        for v in tri {
            if let Ok(k) = forces.nodes.binary_search(v) {
                forces.area_mm2[k] += third;
            }
        }
    }
    state.forces = forces;
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
            let [a, b, c] = tri.map(|v| sim.state.x[v]);
            (b - a).cross(&(c - a)).norm() / 2.0 * touching as f64 / 3.0
        })
        .sum();
    for &v in &state.candidates {
        let pen = (-pose.distance(&sim.state.x[v]).0).max(0.0);
        report.max_penetration_mm = report.max_penetration_mm.max(pen);
        report.max_penetration_ratio = report
            .max_penetration_ratio
            .max(pen / state.tolerance[v] * 0.01);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fem::probe::ProbeShape;

    /// A node left inside the probe by more than its tolerance fails the
    /// solve, naming the node, its depth and the remedy; one within its
    /// tolerance does not.
    #[test]
    fn a_node_inside_the_probe_fails_the_solve() {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("meshes/patch_3k.node");
        let mesh = crate::mesh::io::read_mesh(&path).unwrap();
        let state = ContactState::new(&mesh, &[]);
        let node = state.candidates[state.candidates.len() / 2];
        let mut x = mesh.positions.clone();
        let (radius, top) = (1.0, x[node]);
        let pose = |sink: f64| ProbePose {
            shape: ProbeShape::Sphere { radius_mm: radius },
            centre: top + Vec3::z() * (radius - sink),
            axis: Vec3::x(),
        };
        let tol = state.tolerance(node);
        assert!(refuse_penetration(&x, &pose(0.5 * tol), &state, "frame 3").is_ok());
        let e = refuse_penetration(&x, &pose(3.0 * tol), &state, "frame 3")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("frame 3: 1 surface node(s) are inside the probe"),
            "{e}"
        );
        assert!(e.contains(&format!("node {node} at")), "{e}");
        assert!(e.contains("(3 times its tolerance)"), "{e}");
        assert!(e.contains("time.substeps"), "{e}");
        x[node].z += 10.0;
        assert!(refuse_penetration(&x, &pose(3.0 * tol), &state, "frame 3").is_ok());
    }
}
