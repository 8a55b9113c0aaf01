//! Linear solves for Newton steps: preconditioned conjugate gradients on the
//! filtered system.
//!
//! Constraints are handled with per-node filters `S_i` (orthogonal projectors
//! onto the node's free directions; Baraff & Witkin 1998). The solved system
//! is `(S K S + (I − S)) Δx = S b`: on free directions it is the stiffness,
//! on constrained ones the identity, so `Δx` has no constrained component.
//! The preconditioner inverts each node's filtered diagonal block
//! (block Jacobi). Dot products reduce over fixed-size chunks in a fixed
//! order, so results do not depend on the thread count.
//!
//! The direct solver ([`crate::fem::simulation::LinearSolver::Direct`])
//! solves the same filtered system with a sparse Cholesky factorisation
//! (faer, AMD ordering); its symbolic analysis is done once for the fixed
//! pattern and reused for every numeric factorisation.

use nalgebra::{Matrix3, Vector3};
use rayon::prelude::*;

use super::assembly::Assembly;
use super::coarse::Coarse;
use super::nodal_pressure::NodalPressure;

/// Per-node projector onto the free directions.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Filter {
    /// No constraint (`S = I`).
    Free,
    /// All three directions prescribed (`S = 0`).
    Fixed,
    /// Some directions prescribed: `S` is the projector onto the rest.
    Partial(Matrix3<f64>),
}

impl Filter {
    /// `S v`.
    #[inline]
    pub fn apply(&self, v: &Vector3<f64>) -> Vector3<f64> {
        match self {
            Filter::Free => *v,
            Filter::Fixed => Vector3::zeros(),
            Filter::Partial(s) => s * v,
        }
    }

    /// `S` as a matrix.
    pub fn matrix(&self) -> Matrix3<f64> {
        match self {
            Filter::Free => Matrix3::identity(),
            Filter::Fixed => Matrix3::zeros(),
            Filter::Partial(s) => *s,
        }
    }

    /// The filter whose free space is this one's minus the direction `n` (unit).
    pub fn constrain(&self, n: &Vector3<f64>) -> Filter {
        let s = self.matrix();
        // Remove the part of n already constrained, then project it out.
        let free_part = s * n;
        let len = free_part.norm();
        if len < 1e-9 {
            return *self;
        }
        let e = free_part / len;
        let s = s - e * e.transpose();
        if s.norm() < 1e-9 {
            Filter::Fixed
        } else {
            Filter::Partial(s)
        }
    }
}

/// Stopping rule of the conjugate-gradient solve.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CgSettings {
    /// Stop when `‖r‖ ≤ rel_tol · ‖b‖`.
    pub rel_tol: f64,
    /// Give up after this many iterations.
    pub max_iterations: usize,
}

/// What a solve did.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct CgStats {
    /// Iterations taken.
    pub iterations: usize,
    /// Final `‖r‖ / ‖b‖`.
    pub rel_residual: f64,
    /// Whether `rel_tol` was reached.
    pub converged: bool,
}

/// Scratch vectors reused across solves.
#[derive(Clone, Debug, Default)]
pub struct CgWorkspace {
    r: Vec<f64>,
    z: Vec<f64>,
    p: Vec<f64>,
    q: Vec<f64>,
    // BiCGStab only.
    r0: Vec<f64>,
    s: Vec<f64>,
    t: Vec<f64>,
    y: Vec<f64>,
}

/// A non-symmetric coupling of one node's equations to its own reaction:
/// the node's row of the operator gains `−G δλ`, the reaction's change
/// `δλ = (K S x)_node − own (S x)_node`. A Coulomb
/// friction force that follows the node's reaction `λ` changes by `G δλ`
/// when the positions move, and `δλ = (K δx)_node` (see
/// [`super::simulation::SlipLoad`]); with it the Newton matrix is the full
/// semi-smooth one.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Coupling {
    /// The node.
    pub node: usize,
    /// The reaction's change mapped onto the node's free space (filtered
    /// on the left).
    pub g: Matrix3<f64>,
    /// The part of the node's assembled diagonal block that is not the
    /// elements' (constraint curvature, friction stiffness): the reaction
    /// is `(K S x)_node − own (S x)_node`.
    pub own: Matrix3<f64>,
}

impl Coupling {
    /// `G δλ` for the assembled product `k = (K v)_node` of `v = v_node`.
    pub fn apply(&self, k: &Vector3<f64>, v: &Vector3<f64>) -> Vector3<f64> {
        self.g * (k - self.own * v)
    }
}

/// Entries per chunk of the deterministic reductions (a multiple of 3, so
/// chunks hold whole nodes).
const CHUNK: usize = 3 * 1024;

/// Deterministic dot product: fixed chunks, partial sums added in order.
pub fn dot(a: &[f64], b: &[f64]) -> f64 {
    let partial: Vec<f64> = a
        .par_chunks(CHUNK)
        .zip(b.par_chunks(CHUNK))
        .map(|(x, y)| x.iter().zip(y).map(|(u, v)| u * v).sum::<f64>())
        .collect();
    partial.iter().sum()
}

/// The nodes whose filter is not [`Filter::Free`], ascending.
fn constrained_nodes(filters: &[Filter]) -> Vec<usize> {
    (0..filters.len())
        .filter(|&i| filters[i] != Filter::Free)
        .collect()
}

fn filter_in_place(filters: &[Filter], v: &mut [f64]) {
    v.par_chunks_mut(3).zip(filters).for_each(|(c, f)| {
        if *f != Filter::Free {
            let w = f.apply(&Vector3::new(c[0], c[1], c[2]));
            c.copy_from_slice(w.as_slice());
        }
    });
}

/// `v ← S v` on the listed (constrained) nodes only.
fn filter_nodes(filters: &[Filter], nodes: &[usize], v: &mut [f64]) {
    for &i in nodes {
        let c = &mut v[3 * i..3 * i + 3];
        let w = filters[i].apply(&Vector3::new(c[0], c[1], c[2]));
        c.copy_from_slice(w.as_slice());
    }
}

/// The linear system of a Newton step: the assembled matrix `K`, the
/// per-node filters `S` and the friction couplings.
#[derive(Clone, Copy)]
pub struct Operator<'a> {
    /// The assembled Newton matrix.
    pub asm: &'a Assembly,
    /// Per-node projectors onto the free directions.
    pub filters: &'a [Filter],
    /// Non-symmetric row couplings (empty: the operator is symmetric).
    pub couplings: &'a [Coupling],
    /// The nodal volume term's coupling where the matrix does not hold it
    /// (applied as its product, [`NodalPressure::add_product`]).
    pub nodal: Option<&'a NodalPressure>,
}

impl Operator<'_> {
    /// `y = K x`, the nodal coupling included.
    pub fn multiply(&self, x: &[f64], y: &mut [f64]) {
        self.asm.multiply(x, y);
        if let Some(nodal) = self.nodal {
            nodal.add_product(x, y);
        }
    }

    /// Node `i`'s diagonal block of `K`, the nodal coupling included.
    pub fn diagonal_block(&self, i: usize) -> Matrix3<f64> {
        let block = self.asm.diagonal_block(i);
        match self.nodal {
            Some(nodal) => block + nodal.diagonal_block(i),
            None => block,
        }
    }
}

/// `y = (S K S + I − S) x`, minus the couplings' `G δλ_i`;
/// `constrained` lists the nodes whose filter is not free.
fn apply_operator(op: Operator, constrained: &[usize], x: &[f64], sx: &mut [f64], y: &mut [f64]) {
    let Operator {
        filters, couplings, ..
    } = op;
    sx.copy_from_slice(x);
    filter_nodes(filters, constrained, sx);
    op.multiply(sx, y);
    let changes: Vec<Vector3<f64>> = couplings
        .iter()
        .map(|c| {
            let k = 3 * c.node;
            c.apply(
                &Vector3::new(y[k], y[k + 1], y[k + 2]),
                &Vector3::new(sx[k], sx[k + 1], sx[k + 2]),
            )
        })
        .collect();
    for &i in constrained {
        let f = &filters[i];
        let k = 3 * i;
        let xv = Vector3::new(x[k], x[k + 1], x[k + 2]);
        let w = f.apply(&Vector3::new(y[k], y[k + 1], y[k + 2])) + (xv - f.apply(&xv));
        y[k..k + 3].copy_from_slice(w.as_slice());
    }
    for (c, change) in couplings.iter().zip(changes) {
        let k = 3 * c.node;
        for (yk, ck) in y[k..k + 3].iter_mut().zip(change.iter()) {
            *yk -= ck;
        }
    }
}

/// The preconditioner of a conjugate-gradient or BiCGStab solve.
pub enum Preconditioner<'a> {
    /// Each node's filtered diagonal block, inverted.
    BlockJacobi,
    /// A Cholesky factor of the filtered matrix of an earlier Newton step
    /// (possibly with other filters), followed by the current filter: exact
    /// when neither the matrix nor the filters have changed since.
    Factor(&'a mut Factor),
    /// Block Jacobi plus the coarse correction of [`Coarse`] (additive).
    TwoLevel(&'a Coarse),
}

/// Solves `(S K S + I − S) x = S b` by preconditioned conjugate gradients,
/// starting from `x` (a warm start; its constrained part is removed first);
/// with `couplings` the operator is not symmetric and the solve is
/// preconditioned BiCGStab (van der Vorst 1992) instead. Every iterate stays
/// in the free space of the filters.
pub fn solve(
    op: Operator,
    b: &[f64],
    x: &mut [f64],
    settings: &CgSettings,
    ws: &mut CgWorkspace,
    mut preconditioner: Preconditioner,
) -> CgStats {
    let Operator {
        asm,
        filters,
        couplings,
        ..
    } = op;
    let n = b.len();
    for v in [&mut ws.r, &mut ws.z, &mut ws.p, &mut ws.q] {
        v.resize(n, 0.0);
    }
    if !couplings.is_empty() {
        for v in [&mut ws.r0, &mut ws.s, &mut ws.t, &mut ws.y] {
            v.resize(n, 0.0);
        }
    }
    let mut blocks = Vec::new();
    if let Preconditioner::BlockJacobi | Preconditioner::TwoLevel(_) = preconditioner {
        blocks = (0..asm.num_nodes())
            .into_par_iter()
            .map(|i| {
                let s = filters[i].matrix();
                let d = s * op.diagonal_block(i) * s + (Matrix3::identity() - s);
                d.try_inverse().unwrap_or_else(Matrix3::identity)
            })
            .collect();
    }
    let constrained = constrained_nodes(filters);
    // z = M⁻¹ r; returns r·z.
    let mut precondition = |r: &[f64], z: &mut [f64]| match &mut preconditioner {
        Preconditioner::BlockJacobi => precondition_blocks(&blocks, r, z),
        Preconditioner::TwoLevel(coarse) => {
            precondition_blocks(&blocks, r, z);
            coarse.correct(r, z);
            // The coarse modes were filtered when the coarse matrix was
            // built; the filters may have changed since.
            filter_nodes(filters, &constrained, z);
            dot(r, z)
        }
        Preconditioner::Factor(factor) => {
            z.copy_from_slice(r);
            factor.solve_in_place(z);
            filter_nodes(filters, &constrained, z);
            dot(r, z)
        }
    };
    filter_nodes(filters, &constrained, x);
    // r = S b − A x
    ws.r.copy_from_slice(b);
    filter_nodes(filters, &constrained, &mut ws.r);
    let b_norm = dot(&ws.r, &ws.r).sqrt();
    if b_norm == 0.0 {
        x.fill(0.0);
        return CgStats {
            iterations: 0,
            rel_residual: 0.0,
            converged: true,
        };
    }
    apply_operator(op, &constrained, x, &mut ws.z, &mut ws.q);
    ws.r.par_iter_mut().zip(&ws.q).for_each(|(r, q)| *r -= q);
    if !couplings.is_empty() {
        return bicgstab(op, &constrained, x, b_norm, settings, ws, precondition);
    }
    let mut rz = precondition(&ws.r, &mut ws.z);
    ws.p.copy_from_slice(&ws.z);
    let mut r_norm = dot(&ws.r, &ws.r).sqrt();
    for k in 0..settings.max_iterations {
        let stats = CgStats {
            iterations: k,
            rel_residual: r_norm / b_norm,
            converged: r_norm <= settings.rel_tol * b_norm,
        };
        if stats.converged || !r_norm.is_finite() {
            return stats;
        }
        let (p, q) = (&ws.p, &mut ws.q);
        let mut sp = std::mem::take(&mut ws.z);
        apply_operator(op, &constrained, p, &mut sp, q);
        ws.z = sp;
        let pq = dot(&ws.p, &ws.q);
        if pq <= 0.0 {
            // Not positive definite along p: stop with what we have.
            return stats;
        }
        let alpha = rz / pq;
        r_norm = cg_update(x, &mut ws.r, &ws.p, &ws.q, alpha).sqrt();
        let rz_new = precondition(&ws.r, &mut ws.z);
        let beta = rz_new / rz;
        rz = rz_new;
        ws.p.par_iter_mut()
            .zip(&ws.z)
            .for_each(|(p, z)| *p = z + beta * *p);
    }
    CgStats {
        iterations: settings.max_iterations,
        rel_residual: r_norm / b_norm,
        converged: r_norm <= settings.rel_tol * b_norm,
    }
}

/// The conjugate-gradient update `x ← x + α p`, `r ← r − α q` in one pass;
/// returns the new `r·r` (fixed chunks, partial sums added in order).
fn cg_update(x: &mut [f64], r: &mut [f64], p: &[f64], q: &[f64], alpha: f64) -> f64 {
    let partial: Vec<f64> = x
        .par_chunks_mut(CHUNK)
        .zip(r.par_chunks_mut(CHUNK))
        .zip(p.par_chunks(CHUNK).zip(q.par_chunks(CHUNK)))
        .map(|((x, r), (p, q))| {
            let mut rr = 0.0;
            for k in 0..x.len() {
                x[k] += alpha * p[k];
                r[k] -= alpha * q[k];
                rr += r[k] * r[k];
            }
            rr
        })
        .collect();
    partial.iter().sum()
}

/// `a ← a + α b`.
fn axpy(a: &mut [f64], alpha: f64, b: &[f64]) {
    a.par_iter_mut().zip(b).for_each(|(a, b)| *a += alpha * b);
}

/// Right-preconditioned BiCGStab from the residual in `ws.r` of `x`.
fn bicgstab(
    op: Operator,
    constrained: &[usize],
    x: &mut [f64],
    b_norm: f64,
    settings: &CgSettings,
    ws: &mut CgWorkspace,
    mut precondition: impl FnMut(&[f64], &mut [f64]) -> f64,
) -> CgStats {
    let mut sx = vec![0.0; x.len()];
    ws.r0.copy_from_slice(&ws.r);
    ws.p.fill(0.0);
    ws.q.fill(0.0); // v
    let (mut rho, mut alpha, mut omega) = (1.0, 1.0, 1.0);
    let stats = |k: usize, r_norm: f64| CgStats {
        iterations: k,
        rel_residual: r_norm / b_norm,
        converged: r_norm <= settings.rel_tol * b_norm,
    };
    for k in 0..settings.max_iterations {
        let r_norm = dot(&ws.r, &ws.r).sqrt();
        let st = stats(k, r_norm);
        if st.converged || !r_norm.is_finite() {
            return st;
        }
        let rho_new = dot(&ws.r0, &ws.r);
        if rho_new == 0.0 || omega == 0.0 {
            return st; // breakdown: stop with what we have
        }
        let beta = (rho_new / rho) * (alpha / omega);
        rho = rho_new;
        ws.p.par_iter_mut()
            .zip(&ws.r)
            .zip(&ws.q)
            .for_each(|((p, r), v)| *p = r + beta * (*p - omega * v));
        precondition(&ws.p, &mut ws.z); // z = M⁻¹ p (r·z unused)
        apply_operator(op, constrained, &ws.z, &mut sx, &mut ws.q); // v = A z
        let r0v = dot(&ws.r0, &ws.q);
        if r0v == 0.0 || !r0v.is_finite() {
            return st;
        }
        alpha = rho / r0v;
        ws.s.copy_from_slice(&ws.r);
        axpy(&mut ws.s, -alpha, &ws.q);
        axpy(x, alpha, &ws.z);
        let s_norm = dot(&ws.s, &ws.s).sqrt();
        if s_norm <= settings.rel_tol * b_norm {
            ws.r.copy_from_slice(&ws.s);
            return stats(k + 1, s_norm);
        }
        precondition(&ws.s, &mut ws.y); // y = M⁻¹ s
        apply_operator(op, constrained, &ws.y, &mut sx, &mut ws.t); // t = A y
        let tt = dot(&ws.t, &ws.t);
        omega = if tt > 0.0 {
            dot(&ws.t, &ws.s) / tt
        } else {
            0.0
        };
        axpy(x, omega, &ws.y);
        ws.r.copy_from_slice(&ws.s);
        axpy(&mut ws.r, -omega, &ws.t);
    }
    let r_norm = dot(&ws.r, &ws.r).sqrt();
    stats(settings.max_iterations, r_norm)
}

/// `z = M⁻¹ r` with the inverted diagonal blocks; returns `r·z` (fixed
/// chunks, partial sums added in order).
fn precondition_blocks(blocks: &[Matrix3<f64>], r: &[f64], z: &mut [f64]) -> f64 {
    let partial: Vec<f64> = z
        .par_chunks_mut(CHUNK)
        .zip(r.par_chunks(CHUNK))
        .zip(blocks.par_chunks(CHUNK / 3))
        .map(|((z, r), blocks)| {
            let mut rz = 0.0;
            for ((zc, rc), m) in z.chunks_exact_mut(3).zip(r.chunks_exact(3)).zip(blocks) {
                let rv = Vector3::new(rc[0], rc[1], rc[2]);
                let w = m * rv;
                zc.copy_from_slice(w.as_slice());
                rz += rv.dot(&w);
            }
            rz
        })
        .collect();
    partial.iter().sum()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn constraining_directions_builds_projectors() {
        let f = Filter::Free.constrain(&Vector3::x());
        let s = f.matrix();
        assert!((s - Matrix3::from_diagonal(&Vector3::new(0.0, 1.0, 1.0))).norm() < 1e-15);
        // A direction already constrained changes nothing.
        assert_eq!(f.constrain(&Vector3::x()), f);
        // An oblique normal removes only its free part.
        let n = Vector3::new(1.0, 1.0, 0.0).normalize();
        let s2 = f.constrain(&n).matrix();
        assert!((s2 - Matrix3::from_diagonal(&Vector3::new(0.0, 0.0, 1.0))).norm() < 1e-12);
        assert_eq!(
            f.constrain(&Vector3::y()).constrain(&Vector3::z()),
            Filter::Fixed
        );
    }

    /// BiCGStab on a coupled (non-symmetric) filtered system, with block
    /// Jacobi and with a Cholesky factor of its symmetric part, matches a
    /// dense solve of the same operator; without couplings CG with the
    /// factor matches the direct solve.
    #[test]
    fn coupled_solves_match_a_dense_reference() {
        let (tets, rest) = crate::fem::assembly::tests::two_tets();
        let mut asm = Assembly::new(5, &tets);
        asm.assemble_stiffness(|t, a, b| rest[t].k0(a, b));
        let normal = Vector3::new(1.0, 1.0, 1.0).normalize();
        let mut filters = vec![Filter::Free; 5];
        // No rigid-body mode left free.
        filters[0] = Filter::Fixed;
        filters[1] = Filter::Fixed;
        filters[2] = Filter::Free.constrain(&Vector3::z());
        filters[4] = Filter::Free.constrain(&normal);
        // A tangential coupling vector at node 4 (|g| ≤ μ = 0.8).
        let g = filters[4].apply(&Vector3::new(0.8, -0.3, 0.1));
        let couplings = [Coupling {
            node: 4,
            g: g * normal.transpose(),
            own: Matrix3::zeros(),
        }];
        let b: Vec<f64> = (0..15).map(|k| ((k * 7 + 3) as f64).sin()).collect();
        // Dense A = S K S + I − S − E K S, E = g nᵀ at node 4.
        let k = nalgebra::DMatrix::from(&asm.matrix);
        let mut sm = nalgebra::DMatrix::<f64>::zeros(15, 15);
        let mut e = nalgebra::DMatrix::<f64>::zeros(15, 15);
        for (i, f) in filters.iter().enumerate() {
            sm.view_mut((3 * i, 3 * i), (3, 3)).copy_from(&f.matrix());
        }
        e.view_mut((12, 12), (3, 3))
            .copy_from(&(g * normal.transpose()));
        let eye = nalgebra::DMatrix::<f64>::identity(15, 15);
        let solve_dense = |a: nalgebra::DMatrix<f64>| {
            let sb = &sm * nalgebra::DVector::from_column_slice(&b);
            a.lu().solve(&sb).unwrap()
        };
        let coupled = solve_dense(&sm * &k * &sm + &eye - &sm - &e * &k * &sm);
        let symmetric = solve_dense(&sm * &k * &sm + &eye - &sm);
        let settings = CgSettings {
            rel_tol: 1e-13,
            max_iterations: 200,
        };
        let mut factor = Factor::default();
        assert!(factor.factorize(&asm, &filters));
        for (couplings, reference) in [(&couplings[..], &coupled), (&[][..], &symmetric)] {
            let op = Operator {
                asm: &asm,
                filters: &filters,
                couplings,
                nodal: None,
            };
            for with_factor in [false, true] {
                let mut x = vec![0.0; 15];
                let pre = if with_factor {
                    Preconditioner::Factor(&mut factor)
                } else {
                    Preconditioner::BlockJacobi
                };
                let stats = solve(op, &b, &mut x, &settings, &mut CgWorkspace::default(), pre);
                assert!(stats.converged, "{stats:?}");
                let err = (nalgebra::DVector::from_vec(x) - reference).norm();
                assert!(err < 1e-10 * reference.norm(), "error {err}");
            }
        }
        assert!(
            (&coupled - &symmetric).norm() > 1e-3,
            "the coupling matters"
        );
        let mut x = vec![0.0; 15];
        assert!(factor.solve(&asm, &filters, &b, &mut x));
        assert!((nalgebra::DVector::from_vec(x) - &symmetric).norm() < 1e-12);
    }

    /// On an elastic cube fixed at its bottom (8³ cells), conjugate
    /// gradients with the two-level preconditioner reach the block-Jacobi
    /// solution, also with partial filters, in under half the iterations.
    #[test]
    fn two_level_solves_match_block_jacobi_in_fewer_iterations() {
        let (tets, rest, positions) = crate::fem::assembly::tests::cube_mesh(8);
        let mut asm = Assembly::new(positions.len(), &tets);
        asm.assemble_stiffness(|t, a, b| rest[t].k0(a, b));
        let filters: Vec<Filter> = positions
            .iter()
            .map(|p| {
                if p.z < 1e-9 {
                    Filter::Fixed
                } else if p.x < 1e-9 {
                    Filter::Free.constrain(&Vector3::x())
                } else {
                    Filter::Free
                }
            })
            .collect();
        let b: Vec<f64> = (0..3 * positions.len())
            .map(|k| ((k * 13 + 5) as f64 * 0.37).sin())
            .collect();
        let mut coarse = Coarse::new(&positions);
        assert!(coarse.num_aggregates() > 1);
        assert!(coarse.refresh(&asm, None, &filters, &positions));
        let settings = CgSettings {
            rel_tol: 1e-10,
            max_iterations: 2000,
        };
        let op = Operator {
            asm: &asm,
            filters: &filters,
            couplings: &[],
            nodal: None,
        };
        let mut ws = CgWorkspace::default();
        let mut x_jacobi = vec![0.0; b.len()];
        let jacobi = solve(
            op,
            &b,
            &mut x_jacobi,
            &settings,
            &mut ws,
            Preconditioner::BlockJacobi,
        );
        let mut x_two = vec![0.0; b.len()];
        let two = solve(
            op,
            &b,
            &mut x_two,
            &settings,
            &mut ws,
            Preconditioner::TwoLevel(&coarse),
        );
        assert!(jacobi.converged && two.converged, "{jacobi:?} {two:?}");
        assert!(
            2 * two.iterations < jacobi.iterations,
            "{two:?} vs {jacobi:?}"
        );
        let diff: f64 = x_two
            .iter()
            .zip(&x_jacobi)
            .map(|(a, b)| (a - b).powi(2))
            .sum::<f64>()
            .sqrt();
        let norm: f64 = x_jacobi.iter().map(|v| v * v).sum::<f64>().sqrt();
        assert!(diff < 1e-7 * norm, "difference {diff} of {norm}");
        // The constrained directions stay untouched.
        for (i, f) in filters.iter().enumerate() {
            let xi = Vector3::new(x_two[3 * i], x_two[3 * i + 1], x_two[3 * i + 2]);
            assert!((xi - f.apply(&xi)).norm() < 1e-14);
        }
    }

    #[test]
    fn dot_is_independent_of_thread_count() {
        let a: Vec<f64> = (0..100_000)
            .map(|k| ((k * 7919) % 1000) as f64 * 1e-3 - 0.5)
            .collect();
        let b: Vec<f64> = (0..100_000)
            .map(|k| ((k * 104729) % 997) as f64 * 1e-2)
            .collect();
        let reference = dot(&a, &b);
        for threads in [1, 2, 3] {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            assert_eq!(pool.install(|| dot(&a, &b)).to_bits(), reference.to_bits());
        }
    }
}

/// A sparse Cholesky factor of the filtered matrix `S K S + I − S` (see the
/// module docs). The symbolic analysis (AMD ordering, supernodes) is done
/// once for the fixed pattern; factorisation and solves run on one thread,
/// so their results do not depend on the thread count.
#[derive(Default)]
pub struct Factor {
    symbolic: Option<faer::sparse::linalg::cholesky::SymbolicCholesky<usize>>,
    /// The filtered matrix (the pattern of the assembly).
    values: Vec<f64>,
    /// The factor's values; empty until a factorisation succeeded.
    l_values: Vec<f64>,
    scratch: Option<faer::dyn_stack::MemBuffer>,
}

impl std::fmt::Debug for Factor {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Factor")
            .field("analysed", &self.symbolic.is_some())
            .field("factored", &self.is_factored())
            .finish()
    }
}

impl Clone for Factor {
    /// A clone shares nothing and must factorise again.
    fn clone(&self) -> Self {
        Factor::default()
    }
}

impl Factor {
    /// Whether a factorisation is held.
    pub fn is_factored(&self) -> bool {
        !self.l_values.is_empty()
    }

    /// Factorises the filtered matrix of `asm`. Returns `false`, holding no
    /// factor, if the matrix is not positive definite.
    pub fn factorize(&mut self, asm: &Assembly, filters: &[Filter]) -> bool {
        use faer::dyn_stack::{MemBuffer, MemStack, StackReq};
        use faer::linalg::cholesky::llt::factor::LltRegularization;
        use faer::sparse::linalg::cholesky::factorize_symbolic_cholesky;
        use faer::sparse::{SparseColMatRef, SymbolicSparseColMatRef};
        self.l_values.clear();
        let m = &asm.matrix;
        let n = m.nrows();
        self.values.resize(m.values().len(), 0.0);
        asm.map_blocks(&mut self.values, |i, j, k| {
            let (si, sj) = (filters[i].matrix(), filters[j].matrix());
            let mut out = si * k * sj;
            if i == j {
                out += Matrix3::identity() - si;
            }
            out
        });
        // The matrix is symmetric, so its CSR arrays are also its CSC arrays.
        let pattern =
            SymbolicSparseColMatRef::new_checked(n, n, m.row_offsets(), None, m.col_indices());
        if self.symbolic.is_none() {
            let Ok(symbolic) = factorize_symbolic_cholesky(
                pattern,
                faer::Side::Lower,
                Default::default(),
                Default::default(),
            ) else {
                return false;
            };
            let req = StackReq::any_of(&[
                symbolic.factorize_numeric_llt_scratch::<f64>(faer::Par::Seq, Default::default()),
                symbolic.solve_in_place_scratch::<f64>(1, faer::Par::Seq),
            ]);
            self.scratch = Some(MemBuffer::new(req));
            self.symbolic = Some(symbolic);
        }
        let symbolic = self.symbolic.as_ref().expect("analysed above");
        let mut l_values = vec![0.0; symbolic.len_val()];
        let factored = symbolic
            .factorize_numeric_llt(
                &mut l_values,
                SparseColMatRef::new(pattern, &self.values),
                faer::Side::Lower,
                LltRegularization::default(),
                faer::Par::Seq,
                MemStack::new(self.scratch.as_mut().expect("allocated with the analysis")),
                Default::default(),
            )
            .is_ok();
        if factored && l_values.iter().all(|v| v.is_finite()) {
            self.l_values = l_values;
            true
        } else {
            false
        }
    }

    /// Overwrites `x` with the factor's solve of `x` (needs a factor).
    pub fn solve_in_place(&mut self, x: &mut [f64]) {
        use faer::sparse::linalg::cholesky::LltRef;
        let symbolic = self.symbolic.as_ref().expect("factorised before solving");
        let llt = LltRef::new(symbolic, &self.l_values);
        let n = x.len();
        llt.solve_in_place_with_conj(
            faer::Conj::No,
            faer::MatMut::from_column_major_slice_mut(x, n, 1),
            faer::Par::Seq,
            faer::dyn_stack::MemStack::new(
                self.scratch.as_mut().expect("allocated with the analysis"),
            ),
        );
    }

    /// Solves `(S K S + I − S) x = S b` exactly with a new factorisation;
    /// `x` is overwritten. Returns `false` if the factorisation failed or
    /// the solution is not finite.
    pub fn solve(&mut self, asm: &Assembly, filters: &[Filter], b: &[f64], x: &mut [f64]) -> bool {
        if !self.factorize(asm, filters) {
            return false;
        }
        x.copy_from_slice(b);
        filter_in_place(filters, x);
        self.solve_in_place(x);
        x.iter().all(|v| v.is_finite())
    }
}
