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
//! when `‖S r‖` reaches the round-off of the forces at rest, [`Floors`]:
//! `1e-15·(λ + 2μ)·L²` with L the mesh diagonal, and in a backward-Euler
//! step that weighted as the step weights the elastic and inertial terms.

use nalgebra::Matrix3;
use rayon::prelude::*;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use super::assembly::Assembly;
use super::coarse::Coarse;
use super::corotation::{Corotation, RestElement, TangentKind};
use super::material::Material;
use super::nodal_pressure::NodalPressure;
use super::solve::{CgSettings, CgWorkspace, Coupling, Factor, Filter};

mod tangent;
use tangent::pattern;

use crate::mesh::{TetMesh, Vec3};

/// Which linear solver Newton steps use (`solver.linear`: `cg`, `direct`,
/// `factored-cg`, `two-level`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Deserialize, Serialize, JsonSchema)]
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

/// The round-off of the forces of a body at rest, below which a residual
/// counts as zero.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Floors {
    /// Of the elastic forces (N): `1e-15·(λ + 2μ)·L²` with the largest
    /// modulus and L the mesh diagonal.
    pub elastic: f64,
    /// Of the inertial forces per unit acceleration (t·mm): `1e-15·M·L`
    /// with M the total mass.
    pub inertial: f64,
}

impl Floors {
    /// The floor of a step's residual (N). Backward Euler scales the
    /// elastic forces by `1 + β/h` and adds the inertia and mass damping
    /// of position changes, `M (1/h² + α/h) Δx`: the round-off of both
    /// grows with them (with β = 1000 s at 60 Hz the elastic forces are
    /// weighted 60,000 times, and a floor on the static forces alone left
    /// the load-free frame 0 unconverged).
    pub fn of(&self, dynamics: Option<&Dynamics>) -> f64 {
        match dynamics {
            None => self.elastic,
            Some(d) => {
                self.elastic * (1.0 + d.beta / d.dt)
                    + self.inertial * (1.0 / (d.dt * d.dt) + d.alpha / d.dt)
            }
        }
    }
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

/// A Coulomb sliding-friction load on one node, in the semi-smooth form of
/// Alart & Curnier (1991): the force has magnitude `m = μ F_n` (the node's
/// normal reaction) along the trial force `ξ = λ_t − c·s`, where `λ_t` is
/// the node's tangential reaction, `s = (I − n nᵀ)(x − reference)` its
/// slip and `c` its complementarity constant: `f = m·ξ/|ξ|`. At a solution
/// `f = λ_t`, so `ξ = −(m + c|s|)·ŝ` and the force opposes the slip. Unlike
/// the slip direction `ŝ`, the trial direction stays well defined where a
/// node barely slips (`|ξ| ≥ m` once `λ_t = f`), so a node near the
/// stick–slip boundary costs no extra Newton iterations. The force's
/// derivative, with `δλ = (K δx)_node`, is
/// `δf = G δλ − a·c·Q δx`, `G = μ ξ̂ nᵀ + a·Q`, `Q = I − n nᵀ − ξ̂ ξ̂ᵀ`,
/// `a = m/|ξ| ≤ 1`: the Newton matrix gains `a·c·Q` on the node's diagonal
/// block and the non-symmetric row [`Coupling`] `G` (solved by BiCGStab).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SlipLoad {
    /// The node.
    pub node: usize,
    /// Where slip is measured from (mm).
    pub reference: Vec3,
    /// Unit normal of the contact surface.
    pub normal: Vec3,
    /// Force magnitude `μ·F_n` (N), recomputed from the normal reaction at
    /// every residual evaluation.
    pub magnitude: f64,
    /// The friction coefficient μ.
    pub mu: f64,
    /// Complementarity constant `c` (N/mm): turns slip into force.
    pub stiffness: f64,
}

impl SlipLoad {
    /// The tangential slip at `x`.
    fn slip(&self, x: &Vec3) -> Vec3 {
        let d = x - self.reference;
        d - self.normal * d.dot(&self.normal)
    }

    /// The trial force `ξ = λ_t − c·s` at `x` with the node's contact
    /// reaction `reaction` (`−(f_int + f_ext)`).
    pub fn trial(&self, x: &Vec3, reaction: &Vec3) -> Vec3 {
        let n = self.normal;
        reaction - n * reaction.dot(&n) - self.slip(x) * self.stiffness
    }

    /// Recomputes the magnitude `μ·max(F_n, 0)` from `reaction`.
    pub fn follow(&mut self, reaction: &Vec3) {
        self.magnitude = self.mu * reaction.dot(&self.normal).max(0.0);
    }

    /// The friction force on the node at `x` (N); zero where the trial
    /// force vanishes.
    pub fn force(&self, x: &Vec3, reaction: &Vec3) -> Vec3 {
        let xi = self.trial(x, reaction);
        let len = xi.norm();
        if len > 0.0 {
            xi * (self.magnitude / len)
        } else {
            Vec3::zeros()
        }
    }

    /// The force's linearisation: (its diagonal stiffness block `a·c·Q`,
    /// the row coupling `G`), see the type's documentation. `None` while
    /// the force vanishes.
    fn linearisation(&self, x: &Vec3, reaction: &Vec3) -> Option<(Matrix3<f64>, Matrix3<f64>)> {
        let xi = self.trial(x, reaction);
        let len = xi.norm();
        if self.magnitude <= 0.0 || len <= 0.0 {
            return None;
        }
        let dir = xi / len;
        let n = self.normal;
        let q = Matrix3::identity() - n * n.transpose() - dir * dir.transpose();
        let a = self.magnitude / len;
        Some((
            q * (a * self.stiffness),
            dir * n.transpose() * self.mu + q * a,
        ))
    }
}

/// The simulated patch: the body (rest data), the state, the loads and
/// constraints, and the solver's workspace, each a group of its own; the
/// pipeline reads through accessors and writes through methods.
#[derive(Clone, Debug)]
pub struct Simulation {
    /// Newton settings.
    pub settings: NewtonSettings,
    /// Accumulated solver timings (reset by the caller).
    pub timings: Timings,
    /// Implicit-Euler dynamics; `None` for quasi-static solves.
    pub dynamics: Option<Dynamics>,
    pub(super) body: Body,
    pub(super) state: State,
    pub(super) loads: Loads,
    pub(super) work: Workspace,
}

/// What the mesh and the materials fix: the discretised body.
#[derive(Clone, Debug)]
pub struct Body {
    /// Tets (positively oriented at rest).
    pub tets: Vec<[usize; 4]>,
    /// Per-tet rest data.
    pub elements: Vec<RestElement>,
    /// Lumped nodal masses (t).
    pub mass: Vec<f64>,
    /// Round-off of the forces at rest: residuals below it are zero.
    pub(super) floors: Floors,
    /// The largest Poisson's ratio of any tet (for the diagnosis of a
    /// Newton failure).
    pub(super) largest_poisson: f64,
    /// The largest Poisson's ratio of a tet with the standard volume
    /// measure (the same diagnosis suggests the locking-free one).
    pub(super) largest_standard_poisson: f64,
    /// How close (mm) a constrained node must be to its target.
    pub(super) position_tol: f64,
    /// The nodal volume term of the locking-free materials, if any.
    pub(super) pressure: Option<NodalPressure>,
}

/// A simulation's state kept to go back to ([`Simulation::snapshot`]).
#[derive(Clone, Debug)]
pub struct Snapshot {
    state: State,
    corotations: Vec<Corotation>,
}

/// The deformed state.
#[derive(Clone, Debug)]
pub struct State {
    /// Current positions (mm).
    pub x: Vec<Vec3>,
    /// Nodal velocities (mm/s), updated by [`Simulation::end_step`].
    pub v: Vec<Vec3>,
    /// Positions at the start of the step (dynamics).
    pub(super) x_n: Vec<Vec3>,
    /// Elastic forces at the start of the step (dynamics).
    pub(super) f_elastic_n: Vec<Vec3>,
}

/// What holds and loads the patch: per-node constraints and their target
/// positions, external loads and sliding-friction loads.
#[derive(Clone, Debug)]
pub struct Loads {
    /// Per-node constraint filters.
    pub filters: Vec<Filter>,
    /// Positions imposed on each node's constrained directions.
    pub targets: Vec<Vec3>,
    /// External nodal loads (N).
    pub f_ext: Vec<Vec3>,
    /// Sliding-friction loads, which depend on the positions (see [`SlipLoad`]).
    pub slip_loads: Vec<SlipLoad>,
    /// Stiffness the constraints' curvature adds to nodes' diagonal blocks
    /// (N/mm): a node held on a curved surface by a reaction λ along its
    /// normal gains `−λ ∇²g` (g the distance to the surface), the term that
    /// makes Newton's method on the curved constraint quadratic when the
    /// constraint plane is re-projected at every iteration.
    pub curvature: Vec<(usize, Matrix3<f64>)>,
}

/// The solver's buffers, kept between solves.
#[derive(Clone, Debug)]
pub(super) struct Workspace {
    pub(super) f_elastic: Vec<Vec3>,
    pub(super) assembly: Assembly,
    pub(super) corotations: Vec<Corotation>,
    pub(super) x_start: Vec<Vec3>,
    pub(super) tet_forces: Vec<[Vec3; 4]>,
    /// Per tet its 10 distinct tangent blocks (see [`super::corotation::UPPER`]).
    pub(super) tet_blocks: Vec<[Matrix3<f64>; 10]>,
    pub(super) f_int: Vec<Vec3>,
    pub(super) cg: CgWorkspace,
    pub(super) coarse: Coarse,
    /// Whether the coarse matrix must be rebuilt before the next solve.
    pub(super) coarse_stale: bool,
    pub(super) factor: Factor,
    /// The friction couplings of the current Newton matrix.
    pub(super) couplings: Vec<Coupling>,
    /// Whether the Newton matrix leaves the friction couplings out for
    /// the rest of the solve (after a step cut short, see
    /// [`Simulation::solve_with`]).
    pub(super) friction_lagged: bool,
    pub(super) dx: Vec<f64>,
    pub(super) rhs: Vec<f64>,
    pub(super) r_free: Vec<f64>,
    pub(super) f_slip: Vec<Vec3>,
    pub(super) prescribed: Vec<f64>,
    pub(super) kd: Vec<f64>,
    pub(super) tangent_kind: TangentKind,
    /// The matrix values of the solve's last element tangent, before any
    /// contact term, and its kind (`None`: none yet in this solve).
    pub(super) element_tangent: Vec<f64>,
    pub(super) element_tangent_kind: Option<TangentKind>,
    /// Whether `assembly`'s matrix holds the nodal volume term's coupling
    /// (its pattern then holds every patch): only for the solvers that
    /// factorise it. The iterative ones apply the coupling as a product
    /// ([`Simulation::nodal_coupling`]) on the tets' own pattern.
    pub(super) patched: bool,
}

/// The rest data of every tet of `mesh` with its material, as a
/// simulation builds it.
pub fn rest_elements(mesh: &TetMesh, tet_material: &[Material]) -> Vec<RestElement> {
    (0..mesh.num_tets())
        .into_par_iter()
        .map(|t| RestElement::new(mesh.tet_points(t), &tet_material[t]))
        .collect()
}

/// What depends on the materials: the rest elements, the lumped nodal
/// masses and the floors of the forces at rest (see [`Floors`]).
fn material_data(
    mesh: &TetMesh,
    tet_material: &[Material],
) -> (Vec<RestElement>, Vec<f64>, Floors) {
    let elements = rest_elements(mesh, tet_material);
    let (lo, hi) = mesh.bounds();
    let size = (hi - lo).norm();
    // The largest modulus an element has: λ + 2μ (uniaxial strain),
    // which grows without bound as ν → 0.5, and with it the round-off
    // of the forces at rest.
    let stiffest = tet_material
        .iter()
        .map(|m| m.lambda() + 2.0 * m.mu())
        .fold(0.0, f64::max);
    let mass = lumped_mass(mesh, tet_material);
    let floors = Floors {
        elastic: 1e-15 * stiffest * size * size,
        inertial: 1e-15 * mass.iter().sum::<f64>() * size,
    };
    (elements, mass, floors)
}

impl Simulation {
    /// Sets up a simulation of `mesh` with one material per tet.
    pub fn new(mesh: &TetMesh, tet_material: &[Material]) -> Simulation {
        let (elements, mass, floors) = material_data(mesh, tet_material);
        let (n, m) = (mesh.num_vertices(), elements.len());
        let pressure = NodalPressure::new(&mesh.tets, &elements, tet_material, n);
        let assembly = pattern(n, &mesh.tets, None);
        let (lo, hi) = mesh.bounds();
        let size = (hi - lo).norm();
        Simulation {
            settings: NewtonSettings::default(),
            timings: Timings::default(),
            dynamics: None,
            body: Body {
                tets: mesh.tets.clone(),
                elements,
                mass,
                floors,
                largest_poisson: largest_poisson(tet_material.iter()),
                largest_standard_poisson: largest_poisson(standard(tet_material)),
                position_tol: 1e-7 * size,
                pressure,
            },
            state: State {
                x: mesh.positions.clone(),
                v: vec![Vec3::zeros(); n],
                x_n: mesh.positions.clone(),
                f_elastic_n: vec![Vec3::zeros(); n],
            },
            loads: Loads {
                filters: vec![Filter::Free; n],
                targets: mesh.positions.clone(),
                f_ext: vec![Vec3::zeros(); n],
                slip_loads: Vec::new(),
                curvature: Vec::new(),
            },
            work: Workspace {
                f_elastic: vec![Vec3::zeros(); n],
                assembly,
                patched: false,
                corotations: vec![Corotation::of(&Matrix3::identity()); m],
                x_start: Vec::new(),
                tet_forces: vec![[Vec3::zeros(); 4]; m],
                tet_blocks: vec![[Matrix3::zeros(); 10]; m],
                f_int: vec![Vec3::zeros(); n],
                cg: CgWorkspace::default(),
                coarse: Coarse::new(&mesh.positions),
                coarse_stale: true,
                factor: Factor::default(),
                couplings: Vec::new(),
                friction_lagged: false,
                dx: vec![0.0; 3 * n],
                rhs: vec![0.0; 3 * n],
                r_free: vec![0.0; 3 * n],
                f_slip: vec![Vec3::zeros(); n],
                prescribed: vec![0.0; 3 * n],
                kd: vec![0.0; 3 * n],
                tangent_kind: TangentKind::Exact,
                element_tangent: Vec::new(),
                element_tangent_kind: None,
            },
        }
    }

    /// Replaces the materials (one per tet of `mesh`, the mesh this
    /// simulation was built on) and keeps the deformed state: the rest
    /// elements, the lumped masses and the force floor follow the new
    /// moduli, and the preconditioners are rebuilt at the next solve.
    pub fn set_materials(&mut self, mesh: &TetMesh, tet_material: &[Material]) {
        (self.body.elements, self.body.mass, self.body.floors) = material_data(mesh, tet_material);
        self.body.largest_poisson = largest_poisson(tet_material.iter());
        self.body.largest_standard_poisson = largest_poisson(standard(tet_material));
        let had_pressure = self.body.pressure.is_some();
        self.body.pressure = NodalPressure::new(
            &mesh.tets,
            &self.body.elements,
            tet_material,
            mesh.num_vertices(),
        );
        if had_pressure || self.body.pressure.is_some() {
            self.work.assembly = pattern(mesh.num_vertices(), &mesh.tets, None);
            self.work.patched = false;
            self.work.element_tangent_kind = None;
        }
        self.work.factor = Factor::default();
        self.work.coarse_stale = true;
    }

    /// Current positions (mm).
    pub fn positions(&self) -> &[Vec3] {
        &self.state.x
    }

    /// The deformed state and the rotations that start the next polar
    /// decompositions: what [`Simulation::restore`] needs to take a step
    /// again from here.
    pub fn snapshot(&self) -> Snapshot {
        Snapshot {
            state: self.state.clone(),
            corotations: self.work.corotations.clone(),
        }
    }

    /// Goes back to a [`Simulation::snapshot`] of this simulation: the
    /// same positions, velocities and step start, so that solving the same
    /// step again gives the same bits.
    pub fn restore(&mut self, snapshot: &Snapshot) {
        self.state.clone_from(&snapshot.state);
        self.work.corotations.clone_from(&snapshot.corotations);
    }

    /// Positions to move nodes to before a solve (its start state).
    pub fn positions_mut(&mut self) -> &mut [Vec3] {
        &mut self.state.x
    }

    /// Nodal velocities (mm/s).
    pub fn velocities(&self) -> &[Vec3] {
        &self.state.v
    }

    /// The discretised body: tets, rest elements and lumped masses.
    pub fn body(&self) -> &Body {
        &self.body
    }

    /// Constraints and loads.
    pub fn loads(&self) -> &Loads {
        &self.loads
    }

    /// Constraints and loads, to change before the next solve.
    pub fn loads_mut(&mut self) -> &mut Loads {
        &mut self.loads
    }

    /// Sets every node's constraint filter and target position.
    pub fn set_constraints(&mut self, filters: Vec<Filter>, targets: Vec<Vec3>) {
        self.loads.filters = filters;
        self.loads.targets = targets;
    }

    /// Number of nodes.
    pub fn num_nodes(&self) -> usize {
        self.state.x.len()
    }

    /// How close (mm) a constrained node must be to its target for a solve
    /// to converge: 1e-7 of the mesh diagonal.
    pub fn position_tol(&self) -> f64 {
        self.body.position_tol
    }

    /// Internal elastic forces at the last evaluation (N).
    pub fn internal_forces(&self) -> &[Vec3] {
        &self.work.f_int
    }

    /// Per-tet rotation data (R, U, V, σ̂) at the last evaluation.
    pub fn corotations(&self) -> &[Corotation] {
        &self.work.corotations
    }

    /// Deformation gradient of tet `t` at the current positions.
    pub fn deformation_gradient(&self, t: usize) -> Matrix3<f64> {
        let x = self.body.tets[t].map(|v| self.state.x[v]);
        self.body.elements[t].deformation_gradient(&x)
    }

    /// Inverted tets at the current positions (det F ≤ 0, or not finite)
    /// and the smallest volume ratio J = det F over all tets (NaN when a
    /// position is not finite). Exact for any thread count: the count is an
    /// integer sum and the minimum does not depend on the order.
    pub fn inversion(&self) -> Inversion {
        let (x, tets, elements) = (&self.state.x, &self.body.tets, &self.body.elements);
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

    /// The elastic energy at the current positions (N·mm): the tets' own
    /// and the nodal volume term's, summed in a fixed order.
    pub fn elastic_energy(&mut self) -> f64 {
        let (x, tets, elements) = (&self.state.x, &self.body.tets, &self.body.elements);
        let per_tet: Vec<f64> = elements
            .par_iter()
            .zip(tets)
            .map(|(e, t)| e.energy(&t.map(|v| x[v])))
            .collect();
        let nodal = self.body.pressure.as_mut().map_or(0.0, |p| {
            p.evaluate(tets, elements, x);
            p.energy()
        });
        per_tet.iter().sum::<f64>() + nodal
    }

    /// Per node the force that works against the elastic forces at the
    /// last force evaluation (N). Quasi-static: what the supports and the
    /// probe apply, minus the internal force where one holds the node and
    /// zero at a free node (whose force is the residual, not a load). In a
    /// backward-Euler step, minus the elastic force at every node: what
    /// the supports, the probe, inertia and damping apply together.
    pub fn held_forces(&self) -> Vec<Vec3> {
        if self.dynamics.is_some() {
            return self.work.f_elastic.iter().map(|f| -f).collect();
        }
        self.loads
            .filters
            .iter()
            .zip(&self.work.f_int)
            .map(|(filter, f)| match filter {
                Filter::Free => Vec3::zeros(),
                _ => -f,
            })
            .collect()
    }

    /// The largest net force on a free node at the last force evaluation
    /// (N): what equilibrium leaves there.
    pub fn largest_free_force(&self) -> f64 {
        self.loads
            .filters
            .iter()
            .zip(&self.work.f_int)
            .filter(|(filter, _)| matches!(filter, Filter::Free))
            .map(|(_, f)| f.norm())
            .fold(0.0, f64::max)
    }

    /// Evaluates rotations and internal forces at the current positions.
    pub fn evaluate_forces(&mut self) {
        let start = std::time::Instant::now();
        let (x, tets, elements) = (&self.state.x, &self.body.tets, &self.body.elements);
        self.work
            .corotations
            .par_iter_mut()
            .zip(self.work.tet_forces.par_iter_mut())
            .enumerate()
            .for_each(|(t, (c, f))| {
                let xe = tets[t].map(|v| x[v]);
                let e = &elements[t];
                *c = Corotation::near(&e.deformation_gradient(&xe), &c.v);
                *f = e.forces_from(c);
            });
        if let Some(p) = self.body.pressure.as_mut() {
            p.add_forces(
                &self.body.tets,
                &self.body.elements,
                &self.state.x,
                &mut self.work.tet_forces,
            );
        }
        self.work
            .assembly
            .gather_forces(&self.work.tet_forces, &mut self.work.f_int);
        if let Some(d) = self.dynamics {
            // f_int becomes the effective force: elastic, damping and inertia.
            let (h, k) = (d.dt, d.beta / d.dt);
            self.work.f_elastic.copy_from_slice(&self.work.f_int);
            for i in 0..self.work.f_int.len() {
                let dx = self.state.x[i] - self.state.x_n[i];
                let inertia = (dx - self.state.v[i] * h) * (self.body.mass[i] / (h * h))
                    + dx * (d.alpha * self.body.mass[i] / h);
                self.work.f_int[i] =
                    self.work.f_elastic[i] * (1.0 + k) - self.state.f_elastic_n[i] * k - inertia;
            }
        }
        self.timings.forces_s += start.elapsed().as_secs_f64();
    }

    /// Starts a backward-Euler step from the current state.
    pub fn begin_step(&mut self) {
        let dynamics = self.dynamics.take();
        self.evaluate_forces();
        self.dynamics = dynamics;
        self.state.x_n.copy_from_slice(&self.state.x);
        self.state.f_elastic_n.copy_from_slice(&self.work.f_int);
    }

    /// Moves every node on by `ratio` times its change since `previous`: a
    /// constant-velocity prediction of the next solve's start. Constraints
    /// and contact are imposed by the solve as usual.
    pub fn predict(&mut self, previous: &[Vec3], ratio: f64) {
        self.state
            .x
            .par_iter_mut()
            .zip(previous)
            .for_each(|(x, p)| *x += (*x - p) * ratio);
    }

    /// Ends a backward-Euler step: velocities from the position change.
    pub fn end_step(&mut self) {
        if let Some(d) = self.dynamics {
            for ((v, x), xn) in self
                .state
                .v
                .iter_mut()
                .zip(&self.state.x)
                .zip(&self.state.x_n)
            {
                *v = (x - xn) / d.dt;
            }
        }
    }

    /// Per node the stiffness of its rest diagonal block, `tr(K0_ii)/3`
    /// (N/mm): the force it takes to move the node alone by 1 mm.
    pub fn rest_node_stiffness(&self) -> Vec<f64> {
        let mut k = vec![0.0; self.num_nodes()];
        for (tet, e) in self.body.tets.iter().zip(&self.body.elements) {
            for (a, &v) in tet.iter().enumerate() {
                k[v] += e.k0(a, a).trace() / 3.0;
            }
        }
        k
    }
}

/// The largest Poisson's ratio of `materials` (0 for none).
fn largest_poisson<'a>(materials: impl Iterator<Item = &'a Material>) -> f64 {
    materials.map(|m| m.poisson).fold(0.0, f64::max)
}

/// The materials of `tet_material` with the standard volume measure.
fn standard(tet_material: &[Material]) -> impl Iterator<Item = &Material> {
    tet_material
        .iter()
        .filter(|m| m.volumetric == super::material::Volumetric::Standard)
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
