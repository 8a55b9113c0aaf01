//! The Newton matrix of a [`Simulation`]: the elements' tangent blocks
//! gathered per node, the nodal volume term's coupling (stored in the
//! matrix for the solvers that factorise it, applied as a product for the
//! iterative ones) and the contact terms on the diagonal with their
//! friction couplings.

use rayon::prelude::*;

use super::{LinearSolver, Simulation};
use crate::fem::assembly::Assembly;
use crate::fem::corotation::{TangentKind, UPPER};
use crate::fem::nodal_pressure::NodalPressure;
use crate::fem::solve::{Coupling, Factor};

/// The matrix pattern of `tets` over `num_nodes` nodes, with the patches
/// of `pressure`'s nodal volume term when the matrix is to hold its
/// coupling.
pub(super) fn pattern(
    num_nodes: usize,
    tets: &[[usize; 4]],
    pressure: Option<&NodalPressure>,
) -> Assembly {
    let assembly = match pressure {
        Some(p) => Assembly::with_patches(num_nodes, tets, &p.patches()),
        None => Assembly::new(num_nodes, tets),
    };
    log::debug!(
        "stiffness pattern: {num_nodes} nodes, {} blocks{}",
        assembly.matrix.nnz() / 9,
        if pressure.is_some() {
            " (with the nodal volume term's patches)"
        } else {
            ""
        }
    );
    assembly
}

impl Simulation {
    /// The tangent stiffness of `kind` at the current positions (evaluates
    /// forces first), the nodal volume term's coupling included whatever
    /// the linear solver.
    pub fn stiffness(&mut self, kind: TangentKind) -> &nalgebra_sparse::CsrMatrix<f64> {
        self.evaluate_forces();
        self.work.tangent_kind = kind;
        self.assemble_tangent_with(self.body.pressure.is_some());
        &self.work.assembly.matrix
    }

    /// Assembles the tangent stiffness (of `self.work.tangent_kind`) at the last
    /// evaluation, with the nodal coupling in the matrix only for the
    /// solvers that factorise it.
    pub(in crate::fem) fn assemble_tangent(&mut self) {
        let factorised = matches!(
            self.settings.linear,
            LinearSolver::Direct | LinearSolver::FactoredCg
        );
        self.assemble_tangent_with(factorised && self.body.pressure.is_some());
    }

    /// Assembles the tangent, with the nodal coupling in the matrix when
    /// `patched` (its pattern is rebuilt when that changes) and as the
    /// product's data otherwise.
    fn assemble_tangent_with(&mut self, patched: bool) {
        let start = std::time::Instant::now();
        let (elements, corotations, kind) = (
            &self.body.elements,
            &self.work.corotations,
            self.work.tangent_kind,
        );
        let k = self.dynamics.map_or(1.0, |d| 1.0 + d.beta / d.dt);
        // Each tet's 10 distinct blocks once, then the per-node gather
        // (the lower ones as transposes: the matrix is symmetric to the bit).
        self.work
            .tet_blocks
            .par_iter_mut()
            .enumerate()
            .for_each(|(t, out)| *out = elements[t].tangent(&corotations[t], kind).upper_blocks(k));
        if let (Some(p), TangentKind::Exact) = (&self.body.pressure, kind) {
            p.add_geometric_blocks(elements, k, &mut self.work.tet_blocks);
        }
        if patched != self.work.patched {
            let n = self.state.x.len();
            let pressure = self.body.pressure.as_ref().filter(|_| patched);
            self.work.assembly = pattern(n, &self.body.tets, pressure);
            self.work.patched = patched;
            self.work.element_tangent_kind = None;
            self.work.factor = Factor::default();
        }
        let blocks = &self.work.tet_blocks;
        self.work.assembly.assemble_stiffness(|t, a, b| {
            if a <= b {
                blocks[t][UPPER[a][b]]
            } else {
                blocks[t][UPPER[b][a]].transpose()
            }
        });
        if let Some(p) = self.body.pressure.as_mut() {
            if patched {
                p.add_coupling(
                    &self.body.tets,
                    &self.body.elements,
                    &mut self.work.assembly,
                    k,
                );
            } else {
                p.update_coupling(&self.body.tets, &self.body.elements, k);
            }
        }
        if let Some(d) = self.dynamics {
            let c = 1.0 / (d.dt * d.dt) + d.alpha / d.dt;
            let diagonal: Vec<f64> = self.body.mass.iter().map(|m| m * c).collect();
            self.work.assembly.add_to_diagonal(&diagonal);
        }
        self.work.element_tangent.clear();
        self.work
            .element_tangent
            .extend_from_slice(self.work.assembly.matrix.values());
        self.work.element_tangent_kind = Some(kind);
        self.add_contact_tangent();
        self.timings.assembly_s += start.elapsed().as_secs_f64();
    }

    /// The nodal volume term's coupling where the matrix does not hold it:
    /// what the linear solve applies besides the matrix.
    pub(in crate::fem) fn nodal_coupling(&self) -> Option<&NodalPressure> {
        self.body.pressure.as_ref().filter(|_| !self.work.patched)
    }

    /// `y = K x` with the Newton matrix of the last assembly, the nodal
    /// coupling included.
    pub(in crate::fem) fn multiply_tangent(&self, x: &[f64], y: &mut [f64]) {
        self.work.assembly.multiply(x, y);
        if let Some(p) = self.nodal_coupling() {
            p.add_product(x, y);
        }
    }

    /// The matrix of the last [`Simulation::assemble_tangent`] in this solve
    /// again (its element part, not re-evaluated), with the current contact
    /// terms. Returns `false`, changing nothing, when there is none of the
    /// current kind.
    pub(in crate::fem) fn reuse_element_tangent(&mut self) -> bool {
        if self.work.element_tangent_kind != Some(self.work.tangent_kind) {
            return false;
        }
        let start = std::time::Instant::now();
        self.work
            .assembly
            .matrix
            .values_mut()
            .copy_from_slice(&self.work.element_tangent);
        self.add_contact_tangent();
        self.timings.assembly_s += start.elapsed().as_secs_f64();
        true
    }

    /// Adds the contact terms to the element tangent: the probe's curvature
    /// and the sliding nodes' friction, with its couplings.
    fn add_contact_tangent(&mut self) {
        for (node, k) in &self.loads.curvature {
            self.work.assembly.add_to_diagonal_block(*node, k);
        }
        self.work.couplings.clear();
        for load in &self.loads.slip_loads {
            let i = load.node;
            let reaction = -(self.work.f_int[i] + self.loads.f_ext[i]);
            if let Some((k, g)) = load.linearisation(&self.state.x[i], &reaction) {
                self.work.assembly.add_to_diagonal_block(i, &k);
                if self.work.friction_lagged {
                    continue;
                }
                // The reaction changes with the elements' stiffness alone,
                // not with the terms added on this node's diagonal.
                let own = self
                    .loads
                    .curvature
                    .iter()
                    .filter(|(node, _)| *node == i)
                    .fold(k, |sum, (_, c)| sum + c);
                self.work.couplings.push(Coupling {
                    node: i,
                    g: self.loads.filters[i].matrix() * g,
                    own,
                });
            }
        }
    }
}
