//! A two-level preconditioner: block Jacobi plus a coarse correction on
//! the rigid-body modes of node aggregates.
//!
//! Block Jacobi removes the high-frequency error of a conjugate-gradient
//! solve quickly but the smooth, large-scale error only slowly: that error
//! looks locally like a rigid motion. The nodes are therefore grouped into
//! aggregates (cells of a regular grid over the rest positions), and each
//! aggregate gets the six rigid motions of its nodes — three translations
//! and three rotations about its centroid — as coarse basis vectors, the
//! columns of a prolongation `P` (three rows per node, six columns per
//! aggregate; each node's rows are filtered by its `S`, so the correction
//! stays in the free space). The coarse matrix `A_c = Pᵀ K P` is small and
//! dense and is factorised by Cholesky. The preconditioner is additive:
//!
//! `z = D⁻¹ r + P A_c⁻¹ Pᵀ r`,
//!
//! symmetric positive definite whenever `A_c` is, so it serves conjugate
//! gradients and BiCGStab alike. The coarse matrix may lag the Newton
//! matrix (it is rebuilt once per solve of a frame): a preconditioner only
//! has to be close, not exact.

use nalgebra::{DMatrix, DVector, Matrix3, Matrix3x6, Vector6};
use rayon::prelude::*;

use super::assembly::Assembly;
use super::nodal_pressure::NodalPressure;
use super::solve::Filter;
use crate::mesh::Vec3;

/// Aim for this many nodes per aggregate: ~50 aggregates (300 coarse
/// unknowns) on a 5,000-node patch, whose dense factorisation costs a few
/// milliseconds.
pub const NODES_PER_AGGREGATE: usize = 96;

/// A vector restricted to the coarse space, by aggregate: the few
/// aggregates it touches with their six entries.
type Restricted = Vec<(usize, Vector6<f64>)>;

/// The aggregates and, once built, the factorised coarse matrix.
#[derive(Clone, Debug, Default)]
pub struct Coarse {
    /// Aggregate of each node.
    aggregate: Vec<usize>,
    /// Nodes of each aggregate, ascending.
    members: Vec<Vec<usize>>,
    /// Per node its filtered 3×6 block of `P` (rows of the node, columns of
    /// its aggregate's six modes), at the last [`Coarse::refresh`].
    blocks: Vec<Matrix3x6<f64>>,
    /// Per node its offset from its aggregate's centroid at the last
    /// refresh: the unfiltered block of `P` is `[I | −[d]×]`.
    offsets: Vec<Vec3>,
    /// Per node the index of its filter in `projectors`, or `FREE`: the
    /// filtered block is `S [I | −[d]×]`.
    projector_of: Vec<u32>,
    /// The filters of the constrained nodes at the last refresh.
    projectors: Vec<Matrix3<f64>>,
    /// Cholesky factor of `A_c`; `None` before the first refresh or when
    /// the coarse matrix could not be factorised.
    factor: Option<nalgebra::Cholesky<f64, nalgebra::Dyn>>,
}

impl Coarse {
    /// Groups the nodes at `positions` into grid cells holding about
    /// [`NODES_PER_AGGREGATE`] nodes each (empty cells are dropped).
    pub fn new(positions: &[Vec3]) -> Coarse {
        let n = positions.len();
        if n == 0 {
            return Coarse::default();
        }
        let (mut lo, mut hi) = (positions[0], positions[0]);
        for p in positions {
            lo = lo.inf(p);
            hi = hi.sup(p);
        }
        let extent = (hi - lo).map(|e| e.max(1e-12));
        // A cube cell of volume V·k/n holds about k nodes on average.
        let volume = extent.x * extent.y * extent.z;
        let cell = (volume * NODES_PER_AGGREGATE as f64 / n as f64).cbrt();
        let cells = extent.map(|e| ((e / cell).round() as usize).max(1));
        let index = |p: &Vec3| {
            let c = |k: usize| {
                let t = (p[k] - lo[k]) / extent[k] * cells[k] as f64;
                (t.floor() as usize).min(cells[k] - 1)
            };
            (c(2) * cells.y + c(1)) * cells.x + c(0)
        };
        let mut renumber = vec![usize::MAX; cells.x * cells.y * cells.z];
        let mut members: Vec<Vec<usize>> = Vec::new();
        let mut aggregate = Vec::with_capacity(n);
        for (i, p) in positions.iter().enumerate() {
            let cell = index(p);
            if renumber[cell] == usize::MAX {
                renumber[cell] = members.len();
                members.push(Vec::new());
            }
            aggregate.push(renumber[cell]);
            members[renumber[cell]].push(i);
        }
        Coarse {
            aggregate,
            members,
            blocks: Vec::new(),
            offsets: Vec::new(),
            projector_of: Vec::new(),
            projectors: Vec::new(),
            factor: None,
        }
    }

    /// Number of aggregates.
    pub fn num_aggregates(&self) -> usize {
        self.members.len()
    }

    /// Whether a factorised coarse matrix is available.
    pub fn is_ready(&self) -> bool {
        self.factor.is_some()
    }

    /// Rebuilds `P` for the positions `x` and the filters, and `A_c = Pᵀ K P`
    /// from the assembled matrix and, where the matrix does not hold it,
    /// the nodal volume term's coupling, and factorises it. Returns whether
    /// the factorisation succeeded (a coarse mode that the filters remove
    /// entirely gets a unit diagonal).
    pub fn refresh(
        &mut self,
        asm: &Assembly,
        nodal: Option<&NodalPressure>,
        filters: &[Filter],
        x: &[Vec3],
    ) -> bool {
        let centroids: Vec<Vec3> = self
            .members
            .iter()
            .map(|m| m.iter().map(|&i| x[i]).sum::<Vec3>() / m.len() as f64)
            .collect();
        self.offsets = (0..x.len())
            .map(|i| x[i] - centroids[self.aggregate[i]])
            .collect();
        self.projectors.clear();
        self.projector_of = filters
            .iter()
            .map(|f| match f {
                Filter::Free => FREE,
                _ => {
                    self.projectors.push(f.matrix());
                    (self.projectors.len() - 1) as u32
                }
            })
            .collect();
        self.blocks = (0..x.len())
            .into_par_iter()
            .map(|i| {
                let d = self.offsets[i];
                // Translations, then rotations ω × d about the centroid.
                let mut p = Matrix3x6::zeros();
                p.fixed_view_mut::<3, 3>(0, 0)
                    .copy_from(&Matrix3::identity());
                p.fixed_view_mut::<3, 3>(0, 3).copy_from(&-d.cross_matrix());
                filters[i].matrix() * p
            })
            .collect();
        let m = 6 * self.members.len();
        // Rows of aggregate a: Σ_{i∈a} Σ_j P_iᵀ K_ij P_j, in parallel over
        // aggregates, each sum in node and neighbour order.
        let rows: Vec<Vec<f64>> = self
            .members
            .par_iter()
            .map(|nodes| {
                let mut row = vec![0.0; 6 * m];
                for &i in nodes {
                    let pi_t = self.blocks[i].transpose();
                    for (slot, &j) in asm.neighbours(i).iter().enumerate() {
                        let kp = asm.block(i, slot) * self.blocks[j];
                        let c = pi_t * kp;
                        let b = 6 * self.aggregate[j];
                        for r in 0..6 {
                            for col in 0..6 {
                                row[r * m + b + col] += c[(r, col)];
                            }
                        }
                    }
                }
                row
            })
            .collect();
        let mut a = DMatrix::<f64>::zeros(m, m);
        for (g, row) in rows.iter().enumerate() {
            for r in 0..6 {
                for col in 0..m {
                    a[(6 * g + r, col)] = row[r * m + col];
                }
            }
        }
        if let Some(nodal) = nodal {
            self.add_coupling(nodal, &mut a);
        }
        // Symmetrise (K is symmetric; round-off is not), and give modes the
        // filters removed a unit diagonal. A tiny shift keeps nearly
        // dependent modes of thin aggregates factorisable.
        let trace: f64 = (0..m).map(|k| a[(k, k)].abs()).sum::<f64>() / m.max(1) as f64;
        for r in 0..m {
            for c in 0..r {
                let v = 0.5 * (a[(r, c)] + a[(c, r)]);
                a[(r, c)] = v;
                a[(c, r)] = v;
            }
            if a[(r, r)] <= 1e-12 * trace {
                a[(r, r)] = trace.max(1.0);
            }
            a[(r, r)] += 1e-10 * trace;
        }
        self.factor = nalgebra::Cholesky::new(a);
        self.factor.is_some()
    }

    /// Adds `Pᵀ (Σ_a c_a γ_a γ_aᵀ) P = Σ_a c_a w_a w_aᵀ` with `w_a = Pᵀ γ_a`
    /// to the coarse matrix `a`: each `w_a` is non-zero only on the few
    /// aggregates its patch touches. The `w_a` in parallel, their sum in
    /// point order.
    fn add_coupling(&self, nodal: &NodalPressure, a: &mut DMatrix<f64>) {
        let terms: Vec<_> = nodal.coupling_terms().collect();
        let restricted: Vec<(f64, Restricted)> = terms
            .par_iter()
            .map(|&(weight, patch, gamma)| {
                let mut w: Restricted = Vec::new();
                for (&j, g) in patch.iter().zip(gamma) {
                    let (group, part) = (self.aggregate[j], self.blocks[j].transpose() * g);
                    match w.iter_mut().find(|(h, _)| *h == group) {
                        Some((_, sum)) => *sum += part,
                        None => w.push((group, part)),
                    }
                }
                (weight, w)
            })
            .collect();
        for (weight, w) in &restricted {
            for (ga, wa) in w {
                for (gb, wb) in w {
                    let outer = wa * wb.transpose() * *weight;
                    let mut view = a.fixed_view_mut::<6, 6>(6 * ga, 6 * gb);
                    view += outer;
                }
            }
        }
    }

    /// `z ← z + P A_c⁻¹ Pᵀ r` (nothing before a successful refresh). The
    /// products apply `P`'s blocks `S [I | −[d]×]` from each node's offset
    /// and, where it is constrained, its filter: 28 bytes a node read
    /// instead of a 144-byte block.
    pub fn correct(&self, r: &[f64], z: &mut [f64]) {
        let Some(factor) = &self.factor else {
            return;
        };
        // Restriction per aggregate, each sum in node order: the
        // translations' rows sum r_i, the rotations' rows d_i × r_i.
        let restricted: Vec<[f64; 6]> = self
            .members
            .par_iter()
            .with_min_len(self.members.len().div_ceil(4).max(1))
            .map(|nodes| {
                let (mut t, mut w) = (Vec3::zeros(), Vec3::zeros());
                for &i in nodes {
                    let ri = self.filtered(i, Vec3::new(r[3 * i], r[3 * i + 1], r[3 * i + 2]));
                    t += ri;
                    w += self.offsets[i].cross(&ri);
                }
                [t.x, t.y, t.z, w.x, w.y, w.z]
            })
            .collect();
        let mut rc = DVector::from_iterator(
            6 * self.members.len(),
            restricted.iter().flat_map(|s| s.iter().copied()),
        );
        factor.solve_mut(&mut rc);
        // Prolongation: each node moves with its aggregate, t + ω × d.
        z.par_chunks_mut(3 * PROLONG_GRAIN)
            .enumerate()
            .for_each(|(c, zc)| {
                for (k, zi) in zc.chunks_exact_mut(3).enumerate() {
                    let i = c * PROLONG_GRAIN + k;
                    let e = rc.fixed_rows::<6>(6 * self.aggregate[i]);
                    let t = Vec3::new(e[0], e[1], e[2]);
                    let w = Vec3::new(e[3], e[4], e[5]).cross(&self.offsets[i]);
                    let v = self.filtered(i, t + w);
                    zi[0] += v.x;
                    zi[1] += v.y;
                    zi[2] += v.z;
                }
            });
    }

    /// `S_i v` with node `i`'s filter at the last refresh.
    #[inline]
    fn filtered(&self, i: usize, v: Vec3) -> Vec3 {
        match self.projector_of[i] {
            FREE => v,
            k => self.projectors[k as usize] * v,
        }
    }
}

/// `Coarse::projector_of` of a free node.
const FREE: u32 = u32::MAX;

/// Nodes per task of the prolongation (a few tasks per thread on a
/// 5,000-node patch).
const PROLONG_GRAIN: usize = 1024;

#[cfg(test)]
mod tests {
    use super::*;

    /// Aggregates partition the nodes, and the coarse correction is exact
    /// on the coarse space: for `r = K P y` (a combination of the filtered
    /// rigid modes), `P A_c⁻¹ Pᵀ r = P y`.
    #[test]
    fn coarse_correction_inverts_the_coarse_space() {
        // A 3×3×3 block of nodes split into 2×2×2-ish cells by a large
        // aggregate size: an assembled elastic cube of 5 tets per cell.
        let (tets, rest, positions) = crate::fem::assembly::tests::cube_mesh(3);
        let mut asm = Assembly::new(positions.len(), &tets);
        asm.assemble_stiffness(|t, a, b| rest[t].k0(a, b));
        let mut coarse = Coarse::new(&positions);
        assert!(coarse.num_aggregates() >= 1);
        let mut seen = vec![0; positions.len()];
        for m in &coarse.members {
            for &i in m {
                seen[i] += 1;
            }
        }
        assert!(seen.iter().all(|&c| c == 1));
        // Fix the bottom layer so K is definite on the free space.
        let filters: Vec<Filter> = positions
            .iter()
            .map(|p| {
                if p.z < 1e-9 {
                    Filter::Fixed
                } else {
                    Filter::Free
                }
            })
            .collect();
        assert!(coarse.refresh(&asm, None, &filters, &positions));
        let m = 6 * coarse.num_aggregates();
        let y: Vec<f64> = (0..m).map(|k| ((k * 5 + 1) as f64).sin()).collect();
        let mut py = vec![0.0; 3 * positions.len()];
        for (i, b) in coarse.blocks.iter().enumerate() {
            let g = coarse.aggregate[i];
            let w = b * nalgebra::Vector6::from_fn(|k, _| y[6 * g + k]);
            py[3 * i..3 * i + 3].copy_from_slice(w.as_slice());
        }
        // S K P y: the residual of a filtered solve is in the free space,
        // and the solve filters the correction.
        let mut r = vec![0.0; py.len()];
        asm.multiply(&py, &mut r);
        let filter = |v: &mut [f64]| {
            for (c, f) in v.chunks_exact_mut(3).zip(&filters) {
                let w = f.apply(&Vec3::new(c[0], c[1], c[2]));
                c.copy_from_slice(w.as_slice());
            }
        };
        filter(&mut r);
        let mut z = vec![0.0; py.len()];
        coarse.correct(&r, &mut z);
        filter(&mut z);
        let err: f64 = z
            .iter()
            .zip(&py)
            .map(|(a, b)| (a - b).powi(2))
            .sum::<f64>()
            .sqrt();
        let norm: f64 = py.iter().map(|v| v * v).sum::<f64>().sqrt();
        assert!(err < 1e-6 * norm, "error {err} of {norm}");
    }
}
