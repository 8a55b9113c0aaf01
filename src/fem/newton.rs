//! The Newton solve of a [`Simulation`] step: residual and convergence
//! test, the linear solve of each iteration (conjugate gradients with the
//! configured preconditioner, a factored matrix, or both) and the
//! backtracking line search. The equations and the convergence rule are in
//! [`super::simulation`]'s documentation.

use super::corotation::TangentKind;
use super::simulation::{
    LinearSolver, NewtonStats, Simulation, MAX_REFINEMENTS, REFACTOR_AFTER, REFINE_BELOW,
};
use super::solve::{self, CgSettings, Filter, Preconditioner};
use crate::error::{Error, Result};
use crate::mesh::Vec3;

impl Simulation {
    /// Residual norms after [`Simulation::evaluate_forces`]: (‖S r‖, scale).
    /// Leaves `S r` in `rhs`.
    fn residual(&mut self) -> (f64, f64) {
        let mut free = 0.0;
        let mut reaction = 0.0;
        let mut external = 0.0;
        self.work.f_slip.iter_mut().for_each(|f| *f = Vec3::zeros());
        self.work.f_slip.resize(self.num_nodes(), Vec3::zeros());
        for load in &mut self.loads.slip_loads {
            // Coulomb: the magnitude follows the current normal reaction.
            let i = load.node;
            let reaction = -(self.work.f_int[i] + self.loads.f_ext[i]);
            load.follow(&reaction);
            self.work.f_slip[i] += load.force(&self.state.x[i], &reaction);
        }
        for i in 0..self.num_nodes() {
            let r = self.work.f_int[i] + self.loads.f_ext[i] + self.work.f_slip[i];
            let s = self.loads.filters[i].apply(&r);
            self.work.rhs[3 * i..3 * i + 3].copy_from_slice(s.as_slice());
            free += s.norm_squared();
            reaction += (self.work.f_int[i] - self.loads.filters[i].apply(&self.work.f_int[i]))
                .norm_squared();
            external += (self.loads.f_ext[i] + self.work.f_slip[i]).norm_squared();
        }
        let scale = reaction.sqrt().max(external.sqrt()).max(self.force_floor());
        (free.sqrt(), scale)
    }

    /// Fills `prescribed` with each node's move onto its targets along its
    /// constrained directions, `(I − S)(target − x)`, and returns the
    /// largest such distance (mm).
    fn constraint_violation(&mut self) -> f64 {
        let mut largest: f64 = 0.0;
        for i in 0..self.num_nodes() {
            let f = &self.loads.filters[i];
            let d = if *f == Filter::Free {
                Vec3::zeros()
            } else {
                let gap = self.loads.targets[i] - self.state.x[i];
                gap - f.apply(&gap)
            };
            largest = largest.max(d.norm());
            self.work.prescribed[3 * i..3 * i + 3].copy_from_slice(d.as_slice());
        }
        largest
    }

    /// The residual (N) below which a step counts as converged whatever
    /// its load: the round-off of the forces at rest
    /// ([`super::simulation::Floors`]).
    pub fn force_floor(&self) -> f64 {
        self.body.floors.of(self.dynamics.as_ref())
    }

    /// The reported relative residual: 0 for a load-free state at round-off
    /// (there is no load to be relative to).
    fn relative(&self, norm: f64, scale: f64) -> f64 {
        if scale <= self.force_floor() && norm <= self.force_floor() {
            0.0
        } else {
            norm / scale
        }
    }

    /// Whether `norm` is converged against `scale` (or at round-off).
    fn converged(&self, norm: f64, scale: f64) -> bool {
        norm <= self.settings.rel_tol * scale || norm <= self.force_floor()
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
    /// A step the line search cuts to 1/8 or less leaves the
    /// friction couplings (`G` of [`super::simulation::SlipLoad`]) out of
    /// the matrix for the rest of the solve: the friction then follows the
    /// reaction an iteration late, which converges linearly but surely where
    /// a stiff normal reaction made the coupled step overshoot.
    ///
    /// The whole loop runs on a thread of rayon's pool (the caller's
    /// thread waits): the element pass, the assembly and every vector
    /// operation of the linear solves fork and join there, where a
    /// parallel loop costs a few microseconds. Called from outside the
    /// pool, each of those loops would first be handed to the pool and
    /// waited for, which costs tens of microseconds each, and a BiCGStab
    /// iteration on patch_25k runs about thirty of them.
    pub fn solve_with<U>(&mut self, context: &str, update: U) -> Result<NewtonStats>
    where
        U: FnMut(&mut Simulation, usize, bool) -> bool + Send,
    {
        rayon::scope(|_| self.newton_loop(context, update))
    }

    /// [`Simulation::solve_with`]'s loop, on the calling thread.
    fn newton_loop<U>(&mut self, context: &str, mut update: U) -> Result<NewtonStats>
    where
        U: FnMut(&mut Simulation, usize, bool) -> bool,
    {
        self.evaluate_forces();
        let mut stats = NewtonStats::default();
        self.work.tangent_kind = TangentKind::Exact;
        self.work.coarse_stale = true;
        self.work.friction_lagged = false;
        self.work.element_tangent_kind = None;
        let mut refinements = 0;
        let mut trace = Trace::default();
        for it in 0..=self.settings.max_iterations {
            let changed = update(self, it, false);
            if changed {
                // A new contact problem: start again from the exact tangent.
                self.work.tangent_kind = TangentKind::Exact;
            }
            let (mut norm, mut scale) = self.residual();
            let mut violation = self.constraint_violation();
            stats.iterations = it;
            stats.rel_residual = self.relative(norm, scale);
            stats.scale = scale;
            if !stats.rel_residual.is_finite() || !violation.is_finite() {
                return Err(self.not_converged(context, it, stats.rel_residual, &trace));
            }
            trace.residual(stats.rel_residual);
            let settled = !changed && violation <= self.body.position_tol;
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
            if settled && violation <= self.body.position_tol && self.converged(norm, scale) {
                return Ok(stats);
            }
            if it == self.settings.max_iterations {
                break;
            }
            self.work.r_free.clone_from(&self.work.rhs);
            // Near the solution the last step was small and so is the
            // element tangent's change: the last one, with the current
            // contact terms, still gives a step that lands within the
            // tolerance, and the assembly is skipped.
            let lagged = !changed
                && it > 0
                && stats.rel_residual <= LAG_TANGENT_BELOW
                && self.reuse_element_tangent();
            if !lagged {
                self.assemble_tangent();
            }
            let forcing = self.forcing(norm / scale);
            // The first step may move constrained nodes (a predicted start,
            // a probe that moved): its right-hand side then carries that
            // move's `K·d`, often several times the load, and the forcing
            // alone would leave a remainder of the load's size.
            let remainder = (it == 0).then_some(MAX_FIRST_REMAINDER * scale);
            let (mut iterations, mut solved) = self.linear_solve(forcing, remainder);
            if !solved && self.work.tangent_kind == TangentKind::Exact {
                log::debug!(
                    "{context}: Newton {it}: exact tangent not positive definite; projecting"
                );
                self.work.tangent_kind = TangentKind::Projected;
                self.assemble_tangent();
                let more;
                (more, solved) = self.linear_solve(forcing, remainder);
                iterations += more;
            }
            stats.cg_iterations += iterations;
            let (new_norm, new_scale, descended, length) = self.line_search(norm);
            trace.step(changed, solved, descended);
            if !descended && self.work.tangent_kind == TangentKind::Exact {
                // The exact step was no descent direction: project from now on.
                log::debug!(
                    "{context}: Newton {it}: no descent with the exact tangent; projecting"
                );
                self.work.tangent_kind = TangentKind::Projected;
            }
            if length <= SHORT_STEP && !self.work.couplings.is_empty() {
                // The friction couplings made the step overshoot: a sliding
                // node's friction follows a normal reaction that a squeezed
                // tet makes very stiff. Without them the friction is
                // lagged by an iteration, which converges more slowly but
                // surely.
                log::debug!(
                    "{context}: Newton {it}: step cut to {length}; friction lagged from now on"
                );
                self.work.friction_lagged = true;
            }
            log::debug!(
                "{context}: Newton {it}: {iterations} linear iterations, residual {:.3e} ({new_norm:.3e} N of {new_scale:.3e} N), constraints {violation:.2e} mm",
                new_norm / new_scale
            );
        }
        Err(self.not_converged(
            context,
            self.settings.max_iterations,
            stats.rel_residual,
            &trace,
        ))
    }

    /// The error of a solve that stopped at `rel` after `iterations`: what
    /// stopped it, read from its `trace`, and what to try.
    fn not_converged(&self, context: &str, iterations: usize, rel: f64, trace: &Trace) -> Error {
        let cause = trace.cause(
            rel,
            self.body.largest_poisson,
            self.body.largest_standard_poisson,
        );
        Error::Solver(format!(
            "{context}: equilibrium not reached after {iterations} Newton iterations \
             (relative residual {rel:.3e}, tolerance {:.0e}): {cause}",
            self.settings.rel_tol
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
    /// couplings' `G (K d)_i`, from the filtered residual `r_free` and
    /// the prescribed move `d`.
    fn step_rhs(&mut self) {
        self.work.rhs.clone_from(&self.work.r_free);
        if self.work.prescribed.iter().all(|&d| d == 0.0) {
            return;
        }
        let mut kd = std::mem::take(&mut self.work.kd);
        self.multiply_tangent(&self.work.prescribed, &mut kd);
        self.work.kd = kd;
        let kd = |k: &[f64], i: usize| Vec3::new(k[3 * i], k[3 * i + 1], k[3 * i + 2]);
        for (i, f) in self.loads.filters.iter().enumerate() {
            let s = f.apply(&kd(&self.work.kd, i));
            for c in 0..3 {
                self.work.rhs[3 * i + c] -= s[c];
            }
        }
        for c in &self.work.couplings {
            let d = kd(&self.work.prescribed, c.node);
            let w = c.apply(&kd(&self.work.kd, c.node), &d);
            for k in 0..3 {
                self.work.rhs[3 * c.node + k] += w[k];
            }
        }
    }

    /// Solves for the free part of the Newton step into `dx`; returns the
    /// linear iterations (1 for a direct solve) and whether the solve
    /// succeeded: a factorisation or a conjugate-gradient run that met no
    /// non-positive curvature and reached its tolerance. `remainder`, when
    /// given, bounds the linear residual left (N): the tolerance is
    /// tightened when the right-hand side is large.
    fn linear_solve(&mut self, forcing: f64, remainder: Option<f64>) -> (usize, bool) {
        let start = std::time::Instant::now();
        self.step_rhs();
        let forcing = match remainder {
            Some(bound) => {
                let rhs = self.work.rhs.iter().map(|v| v * v).sum::<f64>().sqrt();
                if rhs * forcing > bound {
                    (bound / rhs).max(self.settings.cg.rel_tol)
                } else {
                    forcing
                }
            }
            None => forcing,
        };
        let outcome = self.linear_solve_untimed(forcing);
        self.timings.linear_s += start.elapsed().as_secs_f64();
        outcome
    }

    fn linear_solve_untimed(&mut self, forcing: f64) -> (usize, bool) {
        if self.settings.linear == LinearSolver::Direct {
            if !self.work.couplings.is_empty() {
                // Not symmetric: BiCGStab preconditioned by this matrix's
                // symmetric part, factorised.
                if self
                    .work
                    .factor
                    .factorize(&self.work.assembly, &self.loads.filters)
                {
                    let st = self.pcg(forcing, self.settings.cg.max_iterations, true);
                    return (st.iterations, st.converged);
                }
            } else if self.work.factor.solve(
                &self.work.assembly,
                &self.loads.filters,
                &self.work.rhs,
                &mut self.work.dx,
            ) {
                return (1, true);
            }
            if self.work.tangent_kind == TangentKind::Exact {
                // Not positive definite: the caller projects and retries.
                return (1, false);
            }
        }
        if self.settings.linear == LinearSolver::FactoredCg {
            if let Some(outcome) = self.factored_cg(forcing) {
                return outcome;
            }
        }
        if self.settings.linear == LinearSolver::TwoLevel && self.work.coarse_stale {
            let start = std::time::Instant::now();
            let nodal = self.body.pressure.as_ref().filter(|_| !self.work.patched);
            self.work.coarse.refresh(
                &self.work.assembly,
                nodal,
                &self.loads.filters,
                &self.state.x,
            );
            self.work.coarse_stale = false;
            self.timings.factor_s += start.elapsed().as_secs_f64();
        }
        let cg = self.pcg(forcing, self.settings.cg.max_iterations, false);
        (cg.iterations, cg.converged)
    }

    /// One conjugate-gradient solve of the step from zero, preconditioned by
    /// the kept factor or by block Jacobi.
    fn pcg(&mut self, rel_tol: f64, max_iterations: usize, factored: bool) -> solve::CgStats {
        self.work.dx.fill(0.0);
        let preconditioner = if factored {
            Preconditioner::Factor(&mut self.work.factor)
        } else if self.settings.linear == LinearSolver::TwoLevel && self.work.coarse.is_ready() {
            Preconditioner::TwoLevel(&self.work.coarse)
        } else {
            Preconditioner::BlockJacobi
        };
        solve::solve(
            solve::Operator {
                asm: &self.work.assembly,
                filters: &self.loads.filters,
                couplings: &self.work.couplings,
                nodal: self.body.pressure.as_ref().filter(|_| !self.work.patched),
            },
            &self.work.rhs,
            &mut self.work.dx,
            &CgSettings {
                rel_tol,
                max_iterations,
            },
            &mut self.work.cg,
            preconditioner,
        )
    }

    /// Conjugate gradients with the kept factor; a solve that stalls
    /// refactorises the current matrix and runs again. `None` when the
    /// current matrix cannot be factorised (block Jacobi takes over).
    fn factored_cg(&mut self, forcing: f64) -> Option<(usize, bool)> {
        let mut total = 0;
        for fresh in [false, true] {
            if fresh || !self.work.factor.is_factored() {
                let start = std::time::Instant::now();
                let factored = self
                    .work
                    .factor
                    .factorize(&self.work.assembly, &self.loads.filters);
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
        for (i, x) in self.state.x.iter_mut().enumerate() {
            let k = 3 * i;
            let d = Vec3::new(
                self.work.prescribed[k],
                self.work.prescribed[k + 1],
                self.work.prescribed[k + 2],
            );
            let y = Vec3::new(self.work.dx[k], self.work.dx[k + 1], self.work.dx[k + 2]);
            *x = self.work.x_start[i] + d + y * alpha;
        }
    }

    /// Takes the step, halving its free part while the residual does not
    /// decrease (at most 6 times). When the step also moves constrained
    /// directions, descent after a failed full step is measured from the
    /// moved state (`alpha = 0`), and a full step below that is taken.
    /// Without descent the trial with the smallest residual is kept (the
    /// Newton loop decides). Returns the new (‖S r‖, scale), whether the
    /// residual decreased and the step length taken.
    fn line_search(&mut self, old_norm: f64) -> (f64, f64, bool, f64) {
        self.work.x_start.clone_from(&self.state.x);
        let moves = self.work.prescribed.iter().any(|&d| d != 0.0);
        let mut reference = old_norm;
        let mut best: Option<(f64, f64)> = None;
        let mut alpha = 1.0;
        for k in 0..7 {
            self.set_trial(alpha);
            self.evaluate_forces();
            let (norm, scale) = self.residual();
            if norm.is_finite() && norm < reference {
                return (norm, scale, true, alpha);
            }
            if norm.is_finite() && best.is_none_or(|(n, _)| norm < n) {
                best = Some((norm, alpha));
            }
            if k == 0 && moves {
                self.set_trial(0.0);
                self.evaluate_forces();
                let (moved, _) = self.residual();
                if moved.is_finite() {
                    reference = moved;
                    if norm.is_finite() && norm < moved {
                        // The full step descends from the moved state: take
                        // it whole (a shortened one would cost Newton its
                        // quadratic convergence).
                        self.set_trial(1.0);
                        self.evaluate_forces();
                        let (norm, scale) = self.residual();
                        return (norm, scale, true, 1.0);
                    }
                    if best.is_none_or(|(n, _)| moved < n) {
                        best = Some((moved, 0.0));
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
        (norm, scale, false, alpha)
    }
}

/// Step length at or below which a Newton step counts as cut short: the
/// friction couplings are then left out of the matrix for the rest of the
/// solve.
const SHORT_STEP: f64 = 0.125;

/// The ν of a standard tet from which a stalled solve suggests the
/// locking-free volume measure (docs/SCENARIO.md recommends it from 0.48).
const MIN_LOCKING_FREE_ADVICE: f64 = 0.48;

/// Relative residual below which a Newton iteration reuses the last
/// element tangent of its solve.
const LAG_TANGENT_BELOW: f64 = 1e-4;

/// Largest linear remainder a solve's first step leaves, relative to the
/// load scale.
const MAX_FIRST_REMAINDER: f64 = 1e-2;

/// The Newton iterations a failure's diagnosis looks back on.
const RECENT: usize = 10;

/// What the iterations of one Newton solve did, for the diagnosis of a
/// failure.
#[derive(Debug, Default)]
struct Trace {
    /// The relative residual at the start of each iteration.
    residuals: Vec<f64>,
    /// Per step taken: (contact set changed, linear solve converged,
    /// residual decreased).
    steps: Vec<(bool, bool, bool)>,
}

/// What stopped a Newton solve.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Cause {
    /// Non-finite forces or positions.
    NotFinite,
    /// Fewer iterations allowed than a diagnosis needs ([`RECENT`]).
    TooFew(usize),
    /// The contact set kept changing: (changes, of iterations).
    Contact(usize, usize),
    /// The linear solves stopped at their limit: (failures, of recent).
    LinearSolve(usize, usize),
    /// The residual stopped falling over the recent iterations: (its
    /// smallest there, the largest Poisson's ratio when near incompressible).
    Stalled(f64, Option<f64>),
    /// The residual fell, too slowly: from the largest to the smallest.
    Slow(f64, f64),
}

impl Trace {
    fn residual(&mut self, rel: f64) {
        self.residuals.push(rel);
    }

    fn step(&mut self, contact_changed: bool, solved: bool, descended: bool) {
        self.steps.push((contact_changed, solved, descended));
    }

    /// Which [`Cause`] the iterations show, first match in the order of
    /// the enum: the contact set over the whole solve (after a while the
    /// contact solve only lets it grow, which changes it less often), the
    /// linear solves and the residual over the last
    /// [`RECENT`]; ν counts as near incompressible from 0.49.
    fn classify(&self, rel: f64, poisson: f64) -> Cause {
        if !rel.is_finite() {
            return Cause::NotFinite;
        }
        let all = self.steps.len();
        if all < RECENT {
            return Cause::TooFew(all);
        }
        let changes = self.steps.iter().filter(|s| s.0).count();
        let recent = &self.steps[all.saturating_sub(RECENT)..];
        let failed = recent.iter().filter(|s| !s.1).count();
        let residuals = &self.residuals[self.residuals.len().saturating_sub(RECENT + 1)..];
        let smallest = |r: &[f64]| r.iter().copied().fold(rel, f64::min);
        let opening = residuals.first().copied().unwrap_or(rel);
        if all > 0 && 10 * changes >= 3 * all {
            Cause::Contact(changes, all)
        } else if !recent.is_empty() && 2 * failed >= recent.len() {
            Cause::LinearSolve(failed, recent.len())
        } else if residuals.len() > RECENT && smallest(residuals) > 0.1 * opening {
            Cause::Stalled(smallest(residuals), (poisson >= 0.49).then_some(poisson))
        } else {
            let largest = self.residuals.iter().copied().fold(rel, f64::max);
            Cause::Slow(largest, smallest(&self.residuals))
        }
    }

    /// The diagnosis in words, with what to try (scenario keys); `standard`
    /// is the largest ν of the tets with the standard volume measure (the
    /// locking-free one is suggested only while some nearly incompressible
    /// region lacks it).
    fn cause(&self, rel: f64, poisson: f64, standard: f64) -> String {
        match self.classify(rel, poisson) {
            Cause::NotFinite => "the forces became non-finite (a tet collapsed under a load step \
                 too large for it); raise time.substeps"
                .into(),
            Cause::TooFew(n) => format!(
                "solver.max_newton_iterations = {n} is fewer than a solve with contact or a \
                 large load step may need; raise it (default {})",
                super::simulation::NewtonSettings::default().max_iterations
            ),
            Cause::Contact(k, n) => format!(
                "the contact set did not settle (it changed in {k} of {n} iterations: nodes \
                 kept switching between touching and free, or sticking and slipping); raise \
                 time.substeps so the probe moves less a step, or lower probe.friction"
            ),
            Cause::LinearSolve(k, n) => format!(
                "the linear solves stopped at solver.max_linear_iterations before \
                 converging ({k} of the last {n}); set solver.linear = \"direct\" or raise \
                 solver.max_linear_iterations"
            ),
            Cause::Stalled(at, Some(nu)) => format!(
                "the residual stopped falling (at best {at:.1e} over the last {RECENT} \
                 iterations); with ν up to {nu} the volume stiffness is {:.0} times the shear \
                 stiffness, which the load step cannot follow: raise time.substeps, {}or lower \
                 poisson_ratio",
                lambda_over_mu(nu),
                if standard >= MIN_LOCKING_FREE_ADVICE {
                    "use volumetric = \"locking-free\" where a region with ν ≥ 0.48 does not, "
                } else {
                    ""
                }
            ),
            Cause::Stalled(at, None) => format!(
                "the residual stopped falling (at best {at:.1e} over the last {RECENT} \
                 iterations): the load step is too large for the Newton solve to follow; raise \
                 time.substeps"
            ),
            Cause::Slow(largest, smallest) => format!(
                "the residual fell from {largest:.1e} to {smallest:.1e}, too slowly; raise \
                 solver.max_newton_iterations or time.substeps"
            ),
        }
    }
}

/// λ/μ at Poisson's ratio `nu`: `2ν / (1 − 2ν)`.
fn lambda_over_mu(nu: f64) -> f64 {
    2.0 * nu / (1.0 - 2.0 * nu)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn trace(steps: &[(bool, bool, bool)], residuals: &[f64]) -> Trace {
        let mut t = Trace::default();
        for &r in residuals {
            t.residual(r);
        }
        for &(c, s, d) in steps {
            t.step(c, s, d);
        }
        t
    }

    /// Each cause is named from the iterations, in the order non-finite,
    /// contact, linear solve, stall, slow.
    #[test]
    fn a_failure_names_what_stopped_it() {
        let ok = (false, true, true);
        let falling: Vec<f64> = (0..30).map(|k| 0.5f64.powi(k)).collect();
        let steps = vec![ok; 29];
        let t = trace(&steps, &falling);
        assert_eq!(t.classify(falling[29], 0.45), Cause::Slow(1.0, falling[29]));
        assert_eq!(t.classify(f64::NAN, 0.45), Cause::NotFinite);

        // Contact changes early on count (the set only grows later).
        let mut contact = vec![(true, true, true); 10];
        contact.extend([ok; 20]);
        assert_eq!(
            trace(&contact, &falling).classify(0.1, 0.45),
            Cause::Contact(10, 30)
        );

        let mut linear = vec![ok; 5];
        linear.extend([(false, false, true); 10]);
        assert_eq!(
            trace(&linear, &falling[..16]).classify(0.1, 0.45),
            Cause::LinearSolve(10, 10)
        );
        assert_eq!(
            trace(&linear[..4], &falling[..5]).classify(0.1, 0.45),
            Cause::TooFew(4)
        );

        let flat: Vec<f64> = (0..20).map(|k| 2.0 - 0.01 * k as f64).collect();
        let t = trace(&[ok; 19], &flat);
        let at = flat[19];
        assert_eq!(t.classify(at, 0.4999), Cause::Stalled(at, Some(0.4999)));
        assert_eq!(t.classify(at, 0.45), Cause::Stalled(at, None));
        let text = t.cause(at, 0.4999, 0.4999);
        assert!(
            text.contains("4999 times the shear")
                && text.contains("time.substeps")
                && text.contains("locking-free"),
            "{text}"
        );
        // Every nearly incompressible region already locking-free: not
        // suggested again.
        let text = t.cause(at, 0.4999, 0.45);
        assert!(
            text.contains("4999 times the shear") && !text.contains("locking-free"),
            "{text}"
        );
    }
}
