//! Time integration: quasi-static equilibrium or implicit (backward) Euler
//! dynamics, each step solved by Newton iterations.
//!
//! Backward Euler with lumped mass `m` and Rayleigh damping `C = αM + βK`
//! solves, for the end-of-step positions x (step h, start x_n, v_n),
//! `m (x − x_n − h v_n)/h² + α m (x − x_n)/h − (1 + β/h) f(x) + (β/h) f(x_n) = f_ext`,
//! where the stiffness-proportional term uses `f(x) − f(x_n) ≈ −K (x − x_n)`,
//! so its derivative is exactly `−(β/h) K`. The Newton matrix is
//! `(1 + β/h) K + (1/h² + α/h) m I`; afterwards `v = (x − x_n)/h`.
//!
//! A [`Simulation`] owns the element rest data, the assembly pattern, the
//! current positions and the constraint filters. Each Newton iteration
//! evaluates rotations and forces in a parallel element loop, gathers them
//! per node, assembles the consistent tangent (see [`super::corotation`])
//! and solves the filtered system (see [`super::solve`]), with a
//! backtracking line search on the residual. [`Simulation::solve_with`]
//! lets a caller change constraints and loads at every iteration (the
//! contact solve does); each step moves constrained directions onto their
//! targets and solves the free ones with that move's coupling. Each solve starts with the
//! exact tangent, which converges quadratically; if the linear solver meets
//! a direction of non-positive curvature (compressed tets no longer held by
//! their neighbours) the solve switches to the positive semi-definite
//! projected tangent for its remaining iterations.
//!
//! Convergence: the relative residual is `‖S r‖ / scale`, where `r` is the
//! net nodal force and `scale` the larger of the reaction forces on the
//! constrained directions and the external loads — the load level the
//! residual is measured against. A load-free state (scale → 0) converges
//! when `‖S r‖` reaches round-off, `1e-15·E·L²` with L the mesh diagonal.

use nalgebra::Matrix3;
use rayon::prelude::*;

use super::assembly::Assembly;
use super::coarse::Coarse;
use super::corotation::{Corotation, RestElement, Tangent, TangentKind};
use super::material::Material;
use super::solve::{self, CgSettings, CgWorkspace, Coupling, Factor, Filter, Preconditioner};
use crate::error::{Error, Result};
use crate::mesh::{TetMesh, Vec3};

/// Which linear solver Newton steps use (`solver.linear`: `cg`, `direct`,
/// `factored-cg`, `two-level`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Deserialize, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum LinearSolver {
    /// Block-Jacobi preconditioned conjugate gradients.
    Cg,
    /// Sparse Cholesky (falls back to CG if the factorisation fails).
    Direct,
    /// Conjugate gradients preconditioned by a Cholesky factor of an earlier
    /// Newton matrix, reused across iterations and frames and refactorised
    /// when a solve needs more than [`REFACTOR_AFTER`] iterations.
    FactoredCg,
    /// Conjugate gradients preconditioned by block Jacobi plus a coarse
    /// correction on the rigid modes of node aggregates
    /// ([`super::coarse::Coarse`]), whose coarse matrix is rebuilt at the
    /// first Newton step of every solve.
    #[default]
    TwoLevel,
}

/// A factored-CG solve that needs more iterations than this refactorises
/// (the factor has drifted too far from the matrix) and starts again.
pub const REFACTOR_AFTER: usize = 12;

/// Refinements of a nearly converged iterate's constraints per solve (see
/// [`Simulation::solve_with`]); the last refined problem is accepted once
/// converged.
pub const MAX_REFINEMENTS: usize = 4;

/// An iterate is offered for refinement once its relative residual is below
/// this multiple of the Newton tolerance, so the step that follows a
/// refinement is one the solve would take anyway.
pub const REFINE_BELOW: f64 = 100.0;

/// Newton iteration settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NewtonSettings {
    /// Linear solver.
    pub linear: LinearSolver,
    /// Converged when the relative residual is at most this.
    pub rel_tol: f64,
    /// Iteration limit per solve.
    pub max_iterations: usize,
    /// Linear solver settings for each Newton step.
    pub cg: CgSettings,
}

impl Default for NewtonSettings {
    fn default() -> Self {
        NewtonSettings {
            linear: LinearSolver::TwoLevel,
            rel_tol: 1e-6,
            max_iterations: 50,
            cg: CgSettings {
                rel_tol: 1e-4,
                max_iterations: 2000,
            },
        }
    }
}

/// Time spent in each part of the solver, accumulated until reset (s).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Timings {
    /// Element loop: rotations, forces and their gather.
    pub forces_s: f64,
    /// Element tangents and stiffness assembly.
    pub assembly_s: f64,
    /// Linear solves (including factorisations).
    pub linear_s: f64,
    /// Of which Cholesky factorisations.
    pub factor_s: f64,
}

/// Backward-Euler step size and Rayleigh damping.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Dynamics {
    /// Time step (s).
    pub dt: f64,
    /// Mass-proportional damping α (1/s).
    pub alpha: f64,
    /// Stiffness-proportional damping β (s).
    pub beta: f64,
}

/// Inverted elements of a state (see [`Simulation::inversion`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Inversion {
    /// Tets with det F ≤ 0 (or not finite).
    pub inverted: usize,
    /// Smallest det F over all tets.
    pub min_volume_ratio: f64,
}

/// What one equilibrium solve did.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct NewtonStats {
    /// Newton iterations.
    pub iterations: usize,
    /// Total conjugate-gradient iterations.
    pub cg_iterations: usize,
    /// Final relative residual.
    pub rel_residual: f64,
    /// Load scale the residual is relative to (N).
    pub scale: f64,
}

/// A Coulomb sliding-friction load on one node: a force of magnitude
/// `m = μ F_n` (the node's normal reaction) opposing its tangential slip from
/// `reference`, `f = −m·ŝ`, `ŝ = s/|s|`, `s = (I − n nᵀ)(x − reference)`.
/// Its derivative at fixed `m` enters the Newton matrix as
/// `(m/|s|)(I − n nᵀ − ŝ ŝᵀ)` — symmetric and positive semi-definite, the
/// stiffness of `m·|s|` — so a slipping node's direction converges with
/// Newton's rate instead of as a fixed point; the magnitude's dependence on
/// the normal reaction enters as a [`Coupling`], which makes the matrix
/// non-symmetric (solved by BiCGStab). Below a slip of `min_slip` the force
/// is regularised to `−m·s/min_slip` (stiffness `(m/min_slip)(I − n nᵀ)`),
/// so force and stiffness stay consistent through `s = 0`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SlipLoad {
    /// The node.
    pub node: usize,
    /// Where slip is measured from (mm).
    pub reference: Vec3,
    /// Unit normal of the contact surface.
    pub normal: Vec3,
    /// Force magnitude `μ·F_n` (N); with `mu > 0` recomputed from the
    /// normal reaction at every residual evaluation.
    pub magnitude: f64,
    /// The friction coefficient μ the magnitude follows (the normal
    /// reaction's change enters the Newton matrix, see
    /// [`solve::Coupling`]); 0 for a magnitude that does not.
    pub mu: f64,
    /// Slip below which the force is regularised (mm, > 0).
    pub min_slip: f64,
}

impl SlipLoad {
    /// The tangential slip at `x`.
    fn slip(&self, x: &Vec3) -> Vec3 {
        let d = x - self.reference;
        d - self.normal * d.dot(&self.normal)
    }

    /// The friction force on the node at `x` (N).
    pub fn force(&self, x: &Vec3) -> Vec3 {
        let s = self.slip(x);
        -s * (self.magnitude / s.norm().max(self.min_slip))
    }

    /// Its contribution to the node's diagonal stiffness block (N/mm).
    fn stiffness(&self, x: &Vec3) -> Matrix3<f64> {
        let s = self.slip(x);
        let len = s.norm();
        let n = self.normal;
        let tangent = Matrix3::identity() - n * n.transpose();
        if len > self.min_slip {
            let dir = s / len;
            (tangent - dir * dir.transpose()) * (self.magnitude / len)
        } else {
            tangent * (self.magnitude / self.min_slip)
        }
    }
}

/// The simulated patch: rest data, state and workspaces.
#[derive(Clone, Debug)]
pub struct Simulation {
    /// Tets (positively oriented at rest).
    pub tets: Vec<[usize; 4]>,
    /// Per-tet rest data.
    pub elements: Vec<RestElement>,
    /// Current positions (mm).
    pub x: Vec<Vec3>,
    /// External nodal loads (N).
    pub f_ext: Vec<Vec3>,
    /// Sliding-friction loads, which depend on the positions (see [`SlipLoad`]).
    pub slip_loads: Vec<SlipLoad>,
    /// Per-node constraint filters.
    pub filters: Vec<Filter>,
    /// Positions imposed on each node's constrained directions.
    pub targets: Vec<Vec3>,
    /// Newton settings.
    pub settings: NewtonSettings,
    /// Accumulated solver timings (reset by the caller).
    pub timings: Timings,
    /// Implicit-Euler dynamics; `None` for quasi-static solves.
    pub dynamics: Option<Dynamics>,
    /// Nodal velocities (mm/s), updated by [`Simulation::end_step`].
    pub v: Vec<Vec3>,
    /// Lumped nodal masses (t).
    pub mass: Vec<f64>,
    x_n: Vec<Vec3>,
    f_elastic: Vec<Vec3>,
    f_elastic_n: Vec<Vec3>,
    assembly: Assembly,
    corotations: Vec<Corotation>,
    x_start: Vec<Vec3>,
    tet_forces: Vec<[Vec3; 4]>,
    f_int: Vec<Vec3>,
    cg: CgWorkspace,
    coarse: Coarse,
    /// Whether the coarse matrix must be rebuilt before the next solve.
    coarse_stale: bool,
    factor: Factor,
    /// The friction couplings of the current Newton matrix.
    couplings: Vec<Coupling>,
    dx: Vec<f64>,
    rhs: Vec<f64>,
    r_free: Vec<f64>,
    f_slip: Vec<Vec3>,
    prescribed: Vec<f64>,
    kd: Vec<f64>,
    force_floor: f64,
    position_tol: f64,
    tangent_kind: TangentKind,
}

/// What depends on the materials: the rest elements, the lumped nodal
/// masses and the force floor (round-off of the forces at rest).
fn material_data(mesh: &TetMesh, tet_material: &[Material]) -> (Vec<RestElement>, Vec<f64>, f64) {
    let elements: Vec<RestElement> = (0..mesh.num_tets())
        .into_par_iter()
        .map(|t| RestElement::new(mesh.tet_points(t), &tet_material[t]))
        .collect();
    let (lo, hi) = mesh.bounds();
    let size = (hi - lo).norm();
    // The largest modulus an element has: λ + 2μ (uniaxial strain),
    // which grows without bound as ν → 0.5, and with it the round-off
    // of the forces at rest.
    let stiffest = tet_material
        .iter()
        .map(|m| m.lambda() + 2.0 * m.mu())
        .fold(0.0, f64::max);
    (
        elements,
        lumped_mass(mesh, tet_material),
        1e-15 * stiffest * size * size,
    )
}

impl Simulation {
    /// Sets up a simulation of `mesh` with one material per tet.
    pub fn new(mesh: &TetMesh, tet_material: &[Material]) -> Simulation {
        let (elements, mass, force_floor) = material_data(mesh, tet_material);
        let n = mesh.num_vertices();
        let (lo, hi) = mesh.bounds();
        let size = (hi - lo).norm();
        Simulation {
            tets: mesh.tets.clone(),
            assembly: Assembly::new(n, &mesh.tets),
            corotations: vec![Corotation::of(&Matrix3::identity()); elements.len()],
            x_start: Vec::new(),
            tet_forces: vec![[Vec3::zeros(); 4]; elements.len()],
            elements,
            x: mesh.positions.clone(),
            f_ext: vec![Vec3::zeros(); n],
            slip_loads: Vec::new(),
            filters: vec![Filter::Free; n],
            targets: mesh.positions.clone(),
            settings: NewtonSettings::default(),
            timings: Timings::default(),
            dynamics: None,
            v: vec![Vec3::zeros(); n],
            mass,
            x_n: mesh.positions.clone(),
            f_elastic: vec![Vec3::zeros(); n],
            f_elastic_n: vec![Vec3::zeros(); n],
            f_int: vec![Vec3::zeros(); n],
            cg: CgWorkspace::default(),
            coarse: Coarse::new(&mesh.positions),
            coarse_stale: true,
            factor: Factor::default(),
            couplings: Vec::new(),
            dx: vec![0.0; 3 * n],
            rhs: vec![0.0; 3 * n],
            r_free: vec![0.0; 3 * n],
            f_slip: vec![Vec3::zeros(); n],
            prescribed: vec![0.0; 3 * n],
            kd: vec![0.0; 3 * n],
            force_floor,
            position_tol: 1e-7 * size,
            tangent_kind: TangentKind::Exact,
        }
    }

    /// Replaces the materials (one per tet of `mesh`, the mesh this
    /// simulation was built on) and keeps the deformed state: the rest
    /// elements, the lumped masses and the force floor follow the new
    /// moduli, and the preconditioners are rebuilt at the next solve.
    pub fn set_materials(&mut self, mesh: &TetMesh, tet_material: &[Material]) {
        (self.elements, self.mass, self.force_floor) = material_data(mesh, tet_material);
        self.factor = Factor::default();
        self.coarse_stale = true;
    }

    /// Number of nodes.
    pub fn num_nodes(&self) -> usize {
        self.x.len()
    }

    /// How close (mm) a constrained node must be to its target for a solve
    /// to converge: 1e-7 of the mesh diagonal.
    pub fn position_tol(&self) -> f64 {
        self.position_tol
    }

    /// Internal elastic forces at the last evaluation (N).
    pub fn internal_forces(&self) -> &[Vec3] {
        &self.f_int
    }

    /// Per-tet rotation data (R, U, V, σ̂) at the last evaluation.
    pub fn corotations(&self) -> &[Corotation] {
        &self.corotations
    }

    /// Deformation gradient of tet `t` at the current positions.
    pub fn deformation_gradient(&self, t: usize) -> Matrix3<f64> {
        let x = self.tets[t].map(|v| self.x[v]);
        self.elements[t].deformation_gradient(&x)
    }

    /// Inverted tets at the current positions (det F ≤ 0, or not finite)
    /// and the smallest volume ratio J = det F over all tets (NaN when a
    /// position is not finite). Exact for any thread count: the count is an
    /// integer sum and the minimum does not depend on the order.
    pub fn inversion(&self) -> Inversion {
        let (x, tets, elements) = (&self.x, &self.tets, &self.elements);
        let (inverted, worst) = (0..tets.len())
            .into_par_iter()
            .map(|t| {
                let j = elements[t]
                    .deformation_gradient(&tets[t].map(|v| x[v]))
                    .determinant();
                // NaN sorts below everything: a non-finite tet is the worst.
                let key = if j.is_nan() { f64::NEG_INFINITY } else { j };
                (usize::from(j <= 0.0 || j.is_nan()), (key, j))
            })
            .reduce(
                || (0, (f64::INFINITY, f64::INFINITY)),
                |a, b| (a.0 + b.0, if b.1 .0 < a.1 .0 { b.1 } else { a.1 }),
            );
        Inversion {
            inverted,
            min_volume_ratio: worst.1,
        }
    }

    /// Evaluates rotations and internal forces at the current positions.
    pub fn evaluate_forces(&mut self) {
        let start = std::time::Instant::now();
        let (x, tets, elements) = (&self.x, &self.tets, &self.elements);
        self.corotations
            .par_iter_mut()
            .zip(self.tet_forces.par_iter_mut())
            .enumerate()
            .for_each(|(t, (c, f))| {
                let xe = tets[t].map(|v| x[v]);
                let e = &elements[t];
                *c = Corotation::of(&e.deformation_gradient(&xe));
                *f = e.forces(&xe, &c.r);
            });
        self.assembly
            .gather_forces(&self.tet_forces, &mut self.f_int);
        if let Some(d) = self.dynamics {
            // f_int becomes the effective force: elastic, damping and inertia.
            let (h, k) = (d.dt, d.beta / d.dt);
            self.f_elastic.copy_from_slice(&self.f_int);
            for i in 0..self.f_int.len() {
                let dx = self.x[i] - self.x_n[i];
                let inertia = (dx - self.v[i] * h) * (self.mass[i] / (h * h))
                    + dx * (d.alpha * self.mass[i] / h);
                self.f_int[i] = self.f_elastic[i] * (1.0 + k) - self.f_elastic_n[i] * k - inertia;
            }
        }
        self.timings.forces_s += start.elapsed().as_secs_f64();
    }

    /// Starts a backward-Euler step from the current state.
    pub fn begin_step(&mut self) {
        let dynamics = self.dynamics.take();
        self.evaluate_forces();
        self.dynamics = dynamics;
        self.x_n.copy_from_slice(&self.x);
        self.f_elastic_n.copy_from_slice(&self.f_int);
    }

    /// Moves every node on by `ratio` times its change since `previous`: a
    /// constant-velocity prediction of the next solve's start. Constraints
    /// and contact are imposed by the solve as usual.
    pub fn predict(&mut self, previous: &[Vec3], ratio: f64) {
        self.x
            .par_iter_mut()
            .zip(previous)
            .for_each(|(x, p)| *x += (*x - p) * ratio);
    }

    /// Ends a backward-Euler step: velocities from the position change.
    pub fn end_step(&mut self) {
        if let Some(d) = self.dynamics {
            for ((v, x), xn) in self.v.iter_mut().zip(&self.x).zip(&self.x_n) {
                *v = (x - xn) / d.dt;
            }
        }
    }

    /// The tangent stiffness of `kind` at the current positions (evaluates
    /// forces first).
    pub fn stiffness(&mut self, kind: TangentKind) -> &nalgebra_sparse::CsrMatrix<f64> {
        self.evaluate_forces();
        self.tangent_kind = kind;
        self.assemble_tangent();
        &self.assembly.matrix
    }

    /// Assembles the tangent stiffness (of `self.tangent_kind`) at the last
    /// evaluation.
    fn assemble_tangent(&mut self) {
        let start = std::time::Instant::now();
        let (elements, corotations, kind) = (&self.elements, &self.corotations, self.tangent_kind);
        let tangents: Vec<Tangent> = (0..elements.len())
            .into_par_iter()
            .map(|t| elements[t].tangent(&corotations[t], kind))
            .collect();
        let k = self.dynamics.map_or(1.0, |d| 1.0 + d.beta / d.dt);
        self.assembly
            .assemble_stiffness(|t, a, b| tangents[t].block(a, b) * k);
        if let Some(d) = self.dynamics {
            let c = 1.0 / (d.dt * d.dt) + d.alpha / d.dt;
            let diagonal: Vec<f64> = self.mass.iter().map(|m| m * c).collect();
            self.assembly.add_to_diagonal(&diagonal);
        }
        self.couplings.clear();
        for load in &self.slip_loads {
            let x = &self.x[load.node];
            let k = load.stiffness(x);
            self.assembly.add_to_diagonal_block(load.node, &k);
            if load.mu > 0.0 && load.magnitude > 0.0 {
                let g = load.force(x) * (load.mu / load.magnitude);
                self.couplings.push(Coupling {
                    node: load.node,
                    g: self.filters[load.node].apply(&g),
                    n: load.normal,
                });
            }
        }
        self.timings.assembly_s += start.elapsed().as_secs_f64();
    }

    /// Per node the stiffness of its rest diagonal block, `tr(K0_ii)/3`
    /// (N/mm): the force it takes to move the node alone by 1 mm.
    pub fn rest_node_stiffness(&self) -> Vec<f64> {
        let mut k = vec![0.0; self.num_nodes()];
        for (tet, e) in self.tets.iter().zip(&self.elements) {
            for (a, &v) in tet.iter().enumerate() {
                k[v] += e.k0[a][a].trace() / 3.0;
            }
        }
        k
    }

    /// Residual norms after [`Simulation::evaluate_forces`]: (‖S r‖, scale).
    /// Leaves `S r` in `rhs`.
    fn residual(&mut self) -> (f64, f64) {
        let mut free = 0.0;
        let mut reaction = 0.0;
        let mut external = 0.0;
        self.f_slip.iter_mut().for_each(|f| *f = Vec3::zeros());
        self.f_slip.resize(self.num_nodes(), Vec3::zeros());
        for load in &mut self.slip_loads {
            let i = load.node;
            if load.mu > 0.0 {
                // Coulomb: the magnitude follows the current normal reaction.
                let normal = -load.normal.dot(&(self.f_int[i] + self.f_ext[i]));
                load.magnitude = load.mu * normal.max(0.0);
            }
            self.f_slip[i] += load.force(&self.x[i]);
        }
        for i in 0..self.num_nodes() {
            let r = self.f_int[i] + self.f_ext[i] + self.f_slip[i];
            let s = self.filters[i].apply(&r);
            self.rhs[3 * i..3 * i + 3].copy_from_slice(s.as_slice());
            free += s.norm_squared();
            reaction += (self.f_int[i] - self.filters[i].apply(&self.f_int[i])).norm_squared();
            external += (self.f_ext[i] + self.f_slip[i]).norm_squared();
        }
        let scale = reaction.sqrt().max(external.sqrt()).max(self.force_floor);
        (free.sqrt(), scale)
    }

    /// Fills `prescribed` with each node's move onto its targets along its
    /// constrained directions, `(I − S)(target − x)`, and returns the
    /// largest such distance (mm).
    fn constraint_violation(&mut self) -> f64 {
        let mut largest: f64 = 0.0;
        for i in 0..self.num_nodes() {
            let f = &self.filters[i];
            let d = if *f == Filter::Free {
                Vec3::zeros()
            } else {
                let gap = self.targets[i] - self.x[i];
                gap - f.apply(&gap)
            };
            largest = largest.max(d.norm());
            self.prescribed[3 * i..3 * i + 3].copy_from_slice(d.as_slice());
        }
        largest
    }

    /// The reported relative residual: 0 for a load-free state at round-off
    /// (there is no load to be relative to).
    fn relative(&self, norm: f64, scale: f64) -> f64 {
        if scale <= self.force_floor && norm <= self.force_floor {
            0.0
        } else {
            norm / scale
        }
    }

    /// Whether `norm` is converged against `scale` (or at round-off).
    fn converged(&self, norm: f64, scale: f64) -> bool {
        norm <= self.settings.rel_tol * scale || norm <= self.force_floor
    }

    /// Solves for static equilibrium with the current constraints and loads.
    /// `context` names the step in errors (e.g. `frame 12`).
    pub fn solve_static(&mut self, context: &str) -> Result<NewtonStats> {
        self.solve_with(context, |_, _, _| false)
    }

    /// Solves for equilibrium while `update` may change the problem: it is
    /// called at the start of every Newton iteration, with the forces
    /// evaluated at the current positions, may set new filters, targets and
    /// loads, and returns whether it changed anything that decides the
    /// solution (a contact set, a stick/slip state); its third argument is
    /// then `false`. The solve converges on an iteration whose update
    /// changed nothing, whose residual is within tolerance and whose nodes
    /// sit on their targets (within 1e-7 of the mesh size). An iterate
    /// whose update changed nothing, whose nodes sit on their targets and
    /// whose residual is within [`REFINE_BELOW`] times the tolerance is
    /// offered to `update` once more with `true`: it may refine the
    /// constraints (re-project contact planes) and return `true`; the
    /// convergence test then applies to the refined problem (at most
    /// [`MAX_REFINEMENTS`] refinements per solve). Each Newton step moves
    /// the constrained directions onto their targets and solves the free
    /// ones with that move's coupling
    /// (`S K S y = S (r − K d)`), so a target that moves every iteration —
    /// a contact node re-projected onto a curved probe — costs no extra solve.
    pub fn solve_with<U>(&mut self, context: &str, mut update: U) -> Result<NewtonStats>
    where
        U: FnMut(&mut Simulation, usize, bool) -> bool,
    {
        self.evaluate_forces();
        let mut stats = NewtonStats::default();
        self.tangent_kind = TangentKind::Exact;
        self.coarse_stale = true;
        let mut refinements = 0;
        for it in 0..=self.settings.max_iterations {
            let changed = update(self, it, false);
            if changed {
                // A new contact problem: start again from the exact tangent.
                self.tangent_kind = TangentKind::Exact;
            }
            let (mut norm, mut scale) = self.residual();
            let mut violation = self.constraint_violation();
            stats.iterations = it;
            stats.rel_residual = self.relative(norm, scale);
            stats.scale = scale;
            if !stats.rel_residual.is_finite() || !violation.is_finite() {
                return Err(not_converged(context, it, stats.rel_residual));
            }
            let settled = !changed && violation <= self.position_tol;
            if settled
                && refinements < MAX_REFINEMENTS
                && stats.rel_residual <= REFINE_BELOW * self.settings.rel_tol
                && update(self, it, true)
            {
                refinements += 1;
                (norm, scale) = self.residual();
                violation = self.constraint_violation();
                stats.rel_residual = self.relative(norm, scale);
            }
            if settled && violation <= self.position_tol && self.converged(norm, scale) {
                return Ok(stats);
            }
            if it == self.settings.max_iterations {
                break;
            }
            self.r_free.clone_from(&self.rhs);
            self.assemble_tangent();
            let forcing = self.forcing(norm / scale);
            let (mut iterations, solved) = self.linear_solve(forcing);
            if !solved && self.tangent_kind == TangentKind::Exact {
                log::debug!(
                    "{context}: Newton {it}: exact tangent not positive definite; projecting"
                );
                self.tangent_kind = TangentKind::Projected;
                self.assemble_tangent();
                let (more, _) = self.linear_solve(forcing);
                iterations += more;
            }
            stats.cg_iterations += iterations;
            let (new_norm, new_scale, descended) = self.line_search(norm);
            if !descended && self.tangent_kind == TangentKind::Exact {
                // The exact step was no descent direction: project from now on.
                log::debug!(
                    "{context}: Newton {it}: no descent with the exact tangent; projecting"
                );
                self.tangent_kind = TangentKind::Projected;
            }
            log::debug!(
                "{context}: Newton {it}: {iterations} linear iterations, residual {:.3e} ({new_norm:.3e} N of {new_scale:.3e} N), constraints {violation:.2e} mm",
                new_norm / new_scale
            );
        }
        Err(not_converged(
            context,
            self.settings.max_iterations,
            stats.rel_residual,
        ))
    }

    /// Relative tolerance of the linear solve at relative residual `rel`
    /// (inexact Newton). Far from equilibrium a rough step does as well as an
    /// exact one; in the middle the tolerance follows the residual, which
    /// keeps the convergence quadratic; near the target it only has to bring
    /// the residual below the target. Bounded by `[cg.rel_tol, 0.1]`.
    fn forcing(&self, rel: f64) -> f64 {
        let target = self.settings.rel_tol;
        rel.max(0.5 * target / rel)
            .clamp(self.settings.cg.rel_tol, 0.1)
    }

    /// The right-hand side of the free directions, `S (r − K d)` plus the
    /// couplings' `g nᵀ (K d)_i`, from the filtered residual `r_free` and
    /// the prescribed move `d`.
    fn step_rhs(&mut self) {
        self.rhs.clone_from(&self.r_free);
        if self.prescribed.iter().all(|&d| d == 0.0) {
            return;
        }
        self.assembly.multiply(&self.prescribed, &mut self.kd);
        let kd = |k: &[f64], i: usize| Vec3::new(k[3 * i], k[3 * i + 1], k[3 * i + 2]);
        for (i, f) in self.filters.iter().enumerate() {
            let s = f.apply(&kd(&self.kd, i));
            for c in 0..3 {
                self.rhs[3 * i + c] -= s[c];
            }
        }
        for c in &self.couplings {
            let w = c.g * c.n.dot(&kd(&self.kd, c.node));
            for k in 0..3 {
                self.rhs[3 * c.node + k] += w[k];
            }
        }
    }

    /// Solves for the free part of the Newton step into `dx`; returns the
    /// linear iterations (1 for a direct solve) and whether the solve
    /// succeeded: a factorisation or a conjugate-gradient run that met no
    /// non-positive curvature and reached its tolerance.
    fn linear_solve(&mut self, forcing: f64) -> (usize, bool) {
        let start = std::time::Instant::now();
        self.step_rhs();
        let outcome = self.linear_solve_untimed(forcing);
        self.timings.linear_s += start.elapsed().as_secs_f64();
        outcome
    }

    fn linear_solve_untimed(&mut self, forcing: f64) -> (usize, bool) {
        if self.settings.linear == LinearSolver::Direct {
            if !self.couplings.is_empty() {
                // Not symmetric: BiCGStab preconditioned by this matrix's
                // symmetric part, factorised.
                if self.factor.factorize(&self.assembly, &self.filters) {
                    let st = self.pcg(forcing, self.settings.cg.max_iterations, true);
                    return (st.iterations, st.converged);
                }
            } else if self
                .factor
                .solve(&self.assembly, &self.filters, &self.rhs, &mut self.dx)
            {
                return (1, true);
            }
            if self.tangent_kind == TangentKind::Exact {
                // Not positive definite: the caller projects and retries.
                return (1, false);
            }
        }
        if self.settings.linear == LinearSolver::FactoredCg {
            if let Some(outcome) = self.factored_cg(forcing) {
                return outcome;
            }
        }
        if self.settings.linear == LinearSolver::TwoLevel && self.coarse_stale {
            let start = std::time::Instant::now();
            self.coarse.refresh(&self.assembly, &self.filters, &self.x);
            self.coarse_stale = false;
            self.timings.factor_s += start.elapsed().as_secs_f64();
        }
        let cg = self.pcg(forcing, self.settings.cg.max_iterations, false);
        (cg.iterations, cg.converged)
    }

    /// One conjugate-gradient solve of the step from zero, preconditioned by
    /// the kept factor or by block Jacobi.
    fn pcg(&mut self, rel_tol: f64, max_iterations: usize, factored: bool) -> solve::CgStats {
        self.dx.fill(0.0);
        let preconditioner = if factored {
            Preconditioner::Factor(&mut self.factor)
        } else if self.settings.linear == LinearSolver::TwoLevel && self.coarse.is_ready() {
            Preconditioner::TwoLevel(&self.coarse)
        } else {
            Preconditioner::BlockJacobi
        };
        solve::solve(
            solve::Operator {
                asm: &self.assembly,
                filters: &self.filters,
                couplings: &self.couplings,
            },
            &self.rhs,
            &mut self.dx,
            &CgSettings {
                rel_tol,
                max_iterations,
            },
            &mut self.cg,
            preconditioner,
        )
    }

    /// Conjugate gradients with the kept factor; a solve that stalls
    /// refactorises the current matrix and runs again. `None` when the
    /// current matrix cannot be factorised (block Jacobi takes over).
    fn factored_cg(&mut self, forcing: f64) -> Option<(usize, bool)> {
        let mut total = 0;
        for fresh in [false, true] {
            if fresh || !self.factor.is_factored() {
                let start = std::time::Instant::now();
                let factored = self.factor.factorize(&self.assembly, &self.filters);
                self.timings.factor_s += start.elapsed().as_secs_f64();
                if !factored {
                    return None;
                }
            }
            let limit = if fresh {
                self.settings.cg.max_iterations
            } else {
                REFACTOR_AFTER
            };
            let cg = self.pcg(forcing, limit, true);
            total += cg.iterations;
            if cg.converged {
                return Some((total, true));
            }
        }
        Some((total, false))
    }

    /// Positions `x_start + d + alpha·dx` (the prescribed move in full).
    fn set_trial(&mut self, alpha: f64) {
        for (i, x) in self.x.iter_mut().enumerate() {
            let k = 3 * i;
            let d = Vec3::new(
                self.prescribed[k],
                self.prescribed[k + 1],
                self.prescribed[k + 2],
            );
            let y = Vec3::new(self.dx[k], self.dx[k + 1], self.dx[k + 2]);
            *x = self.x_start[i] + d + y * alpha;
        }
    }

    /// Takes the step, halving its free part while the residual does not
    /// decrease (at most 6 times). When the step also moves constrained
    /// directions, descent after a failed full step is measured from the
    /// moved state (`alpha = 0`). Without descent the trial with the smallest
    /// residual is kept (the Newton loop decides). Returns the new
    /// (‖S r‖, scale) and whether the residual decreased.
    fn line_search(&mut self, old_norm: f64) -> (f64, f64, bool) {
        self.x_start.clone_from(&self.x);
        let moves = self.prescribed.iter().any(|&d| d != 0.0);
        let mut reference = old_norm;
        let mut best: Option<(f64, f64)> = None;
        let mut alpha = 1.0;
        for k in 0..7 {
            self.set_trial(alpha);
            self.evaluate_forces();
            let (norm, scale) = self.residual();
            if norm.is_finite() && norm < reference {
                return (norm, scale, true);
            }
            if norm.is_finite() && best.is_none_or(|(n, _)| norm < n) {
                best = Some((norm, alpha));
            }
            if k == 0 && moves {
                self.set_trial(0.0);
                self.evaluate_forces();
                let (norm, _) = self.residual();
                if norm.is_finite() {
                    reference = norm;
                    if best.is_none_or(|(n, _)| norm < n) {
                        best = Some((norm, 0.0));
                    }
                }
            }
            alpha *= 0.5;
        }
        // No decrease found: keep the best trial with some step (the
        // smallest step if none was finite).
        let alpha = best
            .filter(|&(_, a)| a > 0.0)
            .map_or(alpha * 2.0, |(_, a)| a);
        self.set_trial(alpha);
        self.evaluate_forces();
        let (norm, scale) = self.residual();
        (norm, scale, false)
    }
}

/// Lumped masses: each tet gives a quarter of ρV to each vertex.
fn lumped_mass(mesh: &TetMesh, tet_material: &[Material]) -> Vec<f64> {
    let mut mass = vec![0.0; mesh.num_vertices()];
    for (t, tet) in mesh.tets.iter().enumerate() {
        let m = tet_material[t].density_t_mm3 * mesh.tet_volume(t) / 4.0;
        for &v in tet {
            mass[v] += m;
        }
    }
    mass
}

fn not_converged(context: &str, iterations: usize, rel: f64) -> Error {
    Error::Solver(format!(
        "{context}: equilibrium not reached after {iterations} Newton iterations \
         (relative residual {rel:.3e})"
    ))
}
