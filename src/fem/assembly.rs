//! Deterministic, parallel assembly of nodal forces and the global stiffness.
//!
//! The sparsity pattern is built once: every node's neighbours (nodes sharing
//! a tet, itself included) in ascending order. Row `3i + r` of the CSR matrix
//! holds, for each neighbour `j`, the three columns `3j..3j+3`; the nine
//! values of block `(i, j)` therefore sit at fixed offsets, and the three
//! rows of node `i` are contiguous in the value array.
//!
//! Assembly is a *gather* per node: node `i` visits its incidences
//! `(tet, local vertex a)` in ascending tet order and adds the tet's
//! contributions. Nodes are processed in parallel, each writing only its own
//! rows, and every sum runs in a fixed order — the result is bit-identical
//! for any number of threads.

use nalgebra::Matrix3;
use nalgebra_sparse::CsrMatrix;
use rayon::prelude::*;

use crate::mesh::Vec3;

/// One tet touching a node: the tet, the node's local index in it, and for
/// each local vertex `b` the slot of `tets[tet][b]` in the node's neighbour list.
#[derive(Clone, Copy, Debug)]
struct Incidence {
    tet: u32,
    local: u8,
    slots: [u32; 4],
}

/// Sparsity pattern, incidence lists and the stiffness matrix.
#[derive(Clone, Debug)]
pub struct Assembly {
    /// `neighbour_start[i]..neighbour_start[i+1]` indexes node i's neighbours.
    neighbour_start: Vec<usize>,
    neighbours: Vec<usize>,
    incidence_start: Vec<usize>,
    incidences: Vec<Incidence>,
    /// Slot of each node in its own neighbour list (its diagonal block).
    diagonal_slot: Vec<usize>,
    /// The global stiffness `K` (3n × 3n), values refilled by [`Assembly::assemble_stiffness`].
    pub matrix: CsrMatrix<f64>,
}

impl Assembly {
    /// Builds the pattern for `num_nodes` nodes and the given tets.
    pub fn new(num_nodes: usize, tets: &[[usize; 4]]) -> Assembly {
        Assembly::with_patches(num_nodes, tets, &[])
    }

    /// Builds the pattern of the tets plus every pair of nodes that share
    /// one of `patches` (the nodal volume term of locking-free materials
    /// couples the nodes of each node's patch, [`super::nodal_pressure`]).
    pub fn with_patches(num_nodes: usize, tets: &[[usize; 4]], patches: &[Vec<usize>]) -> Assembly {
        let mut lists: Vec<Vec<usize>> = vec![Vec::new(); num_nodes];
        let mut incident: Vec<Vec<(u32, u8)>> = vec![Vec::new(); num_nodes];
        for (t, tet) in tets.iter().enumerate() {
            for (a, &i) in tet.iter().enumerate() {
                lists[i].extend_from_slice(tet);
                incident[i].push((t as u32, a as u8));
            }
        }
        for patch in patches {
            for &i in patch {
                lists[i].extend_from_slice(patch);
            }
        }
        let mut neighbour_start = Vec::with_capacity(num_nodes + 1);
        let mut neighbours = Vec::new();
        let mut diagonal_slot = Vec::with_capacity(num_nodes);
        neighbour_start.push(0);
        for (i, list) in lists.iter_mut().enumerate() {
            list.push(i);
            list.sort_unstable();
            list.dedup();
            diagonal_slot.push(list.binary_search(&i).expect("node is its own neighbour"));
            neighbours.extend_from_slice(list);
            neighbour_start.push(neighbours.len());
        }
        let mut incidence_start = Vec::with_capacity(num_nodes + 1);
        let mut incidences = Vec::new();
        incidence_start.push(0);
        for (i, inc) in incident.iter().enumerate() {
            let nb = &neighbours[neighbour_start[i]..neighbour_start[i + 1]];
            for &(t, a) in inc {
                let tet = &tets[t as usize];
                let slots =
                    tet.map(|j| nb.binary_search(&j).expect("tet vertex is a neighbour") as u32);
                incidences.push(Incidence {
                    tet: t,
                    local: a,
                    slots,
                });
            }
            incidence_start.push(incidences.len());
        }
        let matrix = csr_pattern(num_nodes, &neighbour_start, &neighbours);
        Assembly {
            neighbour_start,
            neighbours,
            incidence_start,
            incidences,
            diagonal_slot,
            matrix,
        }
    }

    /// Number of nodes.
    pub fn num_nodes(&self) -> usize {
        self.neighbour_start.len() - 1
    }

    /// Sums per-tet vertex forces into per-node forces (`out` is overwritten).
    pub fn gather_forces(&self, tet_forces: &[[Vec3; 4]], out: &mut [Vec3]) {
        out.par_iter_mut().enumerate().for_each(|(i, f)| {
            let mut sum = Vec3::zeros();
            for inc in self.node_incidences(i) {
                sum += tet_forces[inc.tet as usize][inc.local as usize];
            }
            *f = sum;
        });
    }

    fn node_incidences(&self, i: usize) -> &[Incidence] {
        &self.incidences[self.incidence_start[i]..self.incidence_start[i + 1]]
    }

    /// Refills the stiffness values from per-tet blocks: `block(tet, a, b)`
    /// is the 3×3 coupling of the tet's local vertices `a` and `b`.
    pub fn assemble_stiffness<B>(&mut self, block: B)
    where
        B: Fn(usize, usize, usize) -> Matrix3<f64> + Sync,
    {
        let rows = node_rows(&self.neighbour_start, self.matrix.values_mut());
        let incidences = &self.incidences;
        let incidence_start = &self.incidence_start;
        rows.into_par_iter().enumerate().for_each(|(i, values)| {
            values.fill(0.0);
            let n = values.len() / 9;
            for inc in &incidences[incidence_start[i]..incidence_start[i + 1]] {
                let a = inc.local as usize;
                for (b, &slot) in inc.slots.iter().enumerate() {
                    let block = block(inc.tet as usize, a, b);
                    let k = slot as usize;
                    for row in 0..3 {
                        let base = 3 * n * row + 3 * k;
                        for col in 0..3 {
                            values[base + col] += block[(row, col)];
                        }
                    }
                }
            }
        });
    }

    /// Adds blocks row by row, in parallel over rows: `f(i, add)` calls
    /// `add(j, K)` to add `K` to block `(i, j)`, `j` a neighbour of `i` in
    /// the pattern. Each row's additions run in the order `f` makes them.
    pub fn add_row_blocks<F>(&mut self, f: F)
    where
        F: Fn(usize, &mut dyn FnMut(usize, &Matrix3<f64>)) + Sync,
    {
        let rows = node_rows(&self.neighbour_start, self.matrix.values_mut());
        let (starts, neighbours) = (&self.neighbour_start, &self.neighbours);
        rows.into_par_iter().enumerate().for_each(|(i, values)| {
            let nb = &neighbours[starts[i]..starts[i + 1]];
            let n = nb.len();
            f(i, &mut |j, block| {
                let k = nb
                    .binary_search(&j)
                    .expect("a coupled node is in the pattern");
                for row in 0..3 {
                    let base = 3 * n * row + 3 * k;
                    for col in 0..3 {
                        values[base + col] += block[(row, col)];
                    }
                }
            });
        });
    }

    /// Writes `f(i, j, K_ij)` for every block of the current matrix into
    /// `out` (same layout as the matrix values), in parallel over nodes.
    pub fn map_blocks<F>(&self, out: &mut [f64], f: F)
    where
        F: Fn(usize, usize, &Matrix3<f64>) -> Matrix3<f64> + Sync,
    {
        let rows = node_rows(&self.neighbour_start, out);
        rows.into_par_iter().enumerate().for_each(|(i, values)| {
            let nb = self.neighbours(i);
            let n = nb.len();
            for (k, &j) in nb.iter().enumerate() {
                let b = f(i, j, &self.block(i, k));
                for row in 0..3 {
                    values[3 * n * row + 3 * k..3 * n * row + 3 * k + 3].copy_from_slice(&[
                        b[(row, 0)],
                        b[(row, 1)],
                        b[(row, 2)],
                    ]);
                }
            }
        });
    }

    /// Adds `d[i]·I` to each node's diagonal block.
    pub fn add_to_diagonal(&mut self, d: &[f64]) {
        for (i, &di) in d.iter().enumerate() {
            let n = self.neighbour_start[i + 1] - self.neighbour_start[i];
            let base = 9 * self.neighbour_start[i] + 3 * self.diagonal_slot[i];
            let values = self.matrix.values_mut();
            for row in 0..3 {
                values[base + 3 * n * row + row] += di;
            }
        }
    }

    /// Adds `k` to node `i`'s diagonal block.
    pub fn add_to_diagonal_block(&mut self, i: usize, k: &Matrix3<f64>) {
        let n = self.neighbour_start[i + 1] - self.neighbour_start[i];
        let base = 9 * self.neighbour_start[i] + 3 * self.diagonal_slot[i];
        let values = self.matrix.values_mut();
        for row in 0..3 {
            for col in 0..3 {
                values[base + 3 * n * row + col] += k[(row, col)];
            }
        }
    }

    /// The diagonal 3×3 block of node `i`.
    pub fn diagonal_block(&self, i: usize) -> Matrix3<f64> {
        self.block(i, self.diagonal_slot[i])
    }

    /// Block `(i, neighbours(i)[slot])` of the current matrix.
    pub fn block(&self, i: usize, slot: usize) -> Matrix3<f64> {
        let n = self.neighbour_start[i + 1] - self.neighbour_start[i];
        let base = 9 * self.neighbour_start[i];
        let v = &self.matrix.values()[base..base + 9 * n];
        Matrix3::from_fn(|row, col| v[3 * n * row + 3 * slot + col])
    }

    /// The neighbours of node `i`, ascending.
    pub fn neighbours(&self, i: usize) -> &[usize] {
        &self.neighbours[self.neighbour_start[i]..self.neighbour_start[i + 1]]
    }
}

/// Splits a value array into the (contiguous) three rows of each node.
fn node_rows<'a>(starts: &[usize], mut values: &'a mut [f64]) -> Vec<&'a mut [f64]> {
    let mut rows = Vec::with_capacity(starts.len() - 1);
    for w in starts.windows(2) {
        let (head, tail) = values.split_at_mut(9 * (w[1] - w[0]));
        rows.push(head);
        values = tail;
    }
    rows
}

/// The CSR structure with zero values.
fn csr_pattern(num_nodes: usize, start: &[usize], neighbours: &[usize]) -> CsrMatrix<f64> {
    let mut row_offsets = Vec::with_capacity(3 * num_nodes + 1);
    let mut cols = Vec::with_capacity(9 * neighbours.len());
    row_offsets.push(0);
    for i in 0..num_nodes {
        let nb = &neighbours[start[i]..start[i + 1]];
        for _ in 0..3 {
            for &j in nb {
                cols.extend_from_slice(&[3 * j, 3 * j + 1, 3 * j + 2]);
            }
            row_offsets.push(cols.len());
        }
    }
    let values = vec![0.0; cols.len()];
    CsrMatrix::try_from_csr_data(3 * num_nodes, 3 * num_nodes, row_offsets, cols, values)
        .expect("pattern rows are sorted and in range")
}

/// Nodes per parallel task of the block product: enough work (≈ 0.1 ms)
/// per task that scheduling does not show.
const MULTIPLY_GRAIN: usize = 256;

impl Assembly {
    /// `y = K x` for the assembled matrix, by 3×3 blocks: per node, each
    /// neighbour's three entries of `x` are loaded once and multiplied into
    /// the node's three rows, so the product reads one index per block
    /// instead of one per entry (the CSR column indices are only kept for
    /// the factorisation). Parallel over nodes; every sum runs in the fixed
    /// order of the neighbour list.
    pub fn multiply(&self, x: &[f64], y: &mut [f64]) {
        y.par_chunks_mut(3 * MULTIPLY_GRAIN)
            .enumerate()
            .for_each(|(c, out)| self.multiply_rows(c * MULTIPLY_GRAIN, x, out));
    }

    /// Rows of nodes `first..` of `y = K x` into `out` (three per node),
    /// with the widest vector unit the processor has: the same operations
    /// in the same order whatever it is (no fused multiply-add), so the
    /// same bits.
    fn multiply_rows(&self, first: usize, x: &[f64], out: &mut [f64]) {
        #[cfg(target_arch = "x86_64")]
        if std::is_x86_feature_detected!("avx2") {
            // SAFETY: the processor has AVX2 (checked above).
            return unsafe { self.multiply_rows_avx2(first, x, out) };
        }
        self.multiply_rows_portable(first, x, out);
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn multiply_rows_avx2(&self, first: usize, x: &[f64], out: &mut [f64]) {
        self.multiply_rows_portable(first, x, out);
    }

    #[inline(always)]
    fn multiply_rows_portable(&self, first: usize, x: &[f64], out: &mut [f64]) {
        let values = self.matrix.values();
        for (k, row) in out.chunks_exact_mut(3).enumerate() {
            let i = first + k;
            let (start, end) = (self.neighbour_start[i], self.neighbour_start[i + 1]);
            let n = end - start;
            let rows = &values[9 * start..9 * end];
            let (r0, rest) = rows.split_at(3 * n);
            let (r1, r2) = rest.split_at(3 * n);
            let mut s = [0.0f64; 3];
            for (k, &j) in self.neighbours[start..end].iter().enumerate() {
                let xj = &x[3 * j..3 * j + 3];
                let b = 3 * k;
                s[0] += r0[b] * xj[0] + r0[b + 1] * xj[1] + r0[b + 2] * xj[2];
                s[1] += r1[b] * xj[0] + r1[b + 1] * xj[1] + r1[b + 2] * xj[2];
                s[2] += r2[b] * xj[0] + r2[b + 1] * xj[1] + r2[b + 2] * xj[2];
            }
            row.copy_from_slice(&s);
        }
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::fem::{Material, RestElement};

    /// `y = K x` for a general CSR matrix, parallel over rows (each row serial):
    /// the reference for [`Assembly::multiply`].
    fn multiply_csr(matrix: &CsrMatrix<f64>, x: &[f64], y: &mut [f64]) {
        let offsets = matrix.row_offsets();
        let cols = matrix.col_indices();
        let values = matrix.values();
        y.par_iter_mut().enumerate().for_each(|(row, out)| {
            let mut s = 0.0;
            for k in offsets[row]..offsets[row + 1] {
                s += values[k] * x[cols[k]];
            }
            *out = s;
        });
    }

    /// Two positively oriented tets sharing a face, with their rest data
    /// (E = 1 MPa, ν = 0.3).
    pub(crate) fn two_tets() -> (Vec<[usize; 4]>, Vec<RestElement>) {
        let p = [
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(1.0, 0.0, 0.0),
            Vec3::new(0.0, 1.0, 0.0),
            Vec3::new(0.0, 0.0, 1.0),
            Vec3::new(1.0, 1.0, 1.0),
        ];
        let tets = vec![[0, 1, 2, 3], [1, 2, 3, 4]];
        let rest = rest_elements(&tets, &p);
        (tets, rest)
    }

    /// Rest data of `tets` over `positions` with E = 1 MPa, ν = 0.3.
    fn rest_elements(tets: &[[usize; 4]], positions: &[Vec3]) -> Vec<RestElement> {
        let m = Material {
            youngs_mpa: 1.0,
            poisson: 0.3,
            density_t_mm3: 1e-9,
            model: Default::default(),
            volumetric: Default::default(),
        };
        tets.iter()
            .map(|t| RestElement::new(t.map(|v| positions[v]), &m))
            .collect()
    }

    /// A cube of `n³` unit cells (`(n+1)³` nodes, z = 0 at the bottom),
    /// each cut into six positively oriented tets (E = 1 MPa, ν = 0.3):
    /// tets, rest data and node positions.
    pub(crate) fn cube_mesh(n: usize) -> (Vec<[usize; 4]>, Vec<RestElement>, Vec<Vec3>) {
        let id = |i: usize, j: usize, k: usize| (k * (n + 1) + j) * (n + 1) + i;
        let mut positions = Vec::new();
        for k in 0..=n {
            for j in 0..=n {
                for i in 0..=n {
                    positions.push(Vec3::new(i as f64, j as f64, k as f64));
                }
            }
        }
        let mut tets = Vec::new();
        for k in 0..n {
            for j in 0..n {
                for i in 0..n {
                    let c = |d: usize| id(i + (d & 1), j + ((d >> 1) & 1), k + (d >> 2));
                    // Kuhn split along the diagonal 0–7.
                    for path in [[1, 3], [1, 5], [2, 3], [2, 6], [4, 5], [4, 6]] {
                        let mut t = [c(0), c(path[0]), c(path[1]), c(7)];
                        let p = t.map(|v| positions[v]);
                        let vol = (p[1] - p[0]).cross(&(p[2] - p[0])).dot(&(p[3] - p[0]));
                        if vol < 0.0 {
                            t.swap(1, 2);
                        }
                        tets.push(t);
                    }
                }
            }
        }
        let rest = rest_elements(&tets, &positions);
        (tets, rest, positions)
    }

    #[test]
    fn assembled_matrix_matches_dense_sum() {
        let (tets, rest) = two_tets();
        let rot = nalgebra::Rotation3::from_euler_angles(0.3, -0.2, 0.7).into_inner();
        let mut asm = Assembly::new(5, &tets);
        let rotations = [rot, Matrix3::identity()];
        asm.assemble_stiffness(|t, a, b| {
            rotations[t] * rest[t].k0(a, b) * rotations[t].transpose()
        });
        let mut dense = nalgebra::DMatrix::<f64>::zeros(15, 15);
        for (t, tet) in tets.iter().enumerate() {
            let r = if t == 0 { rot } else { Matrix3::identity() };
            for a in 0..4 {
                for b in 0..4 {
                    let block = r * rest[t].k0(a, b) * r.transpose();
                    let (i, j) = (tet[a], tet[b]);
                    for x in 0..3 {
                        for y in 0..3 {
                            dense[(3 * i + x, 3 * j + y)] += block[(x, y)];
                        }
                    }
                }
            }
        }
        let csr_dense = nalgebra::DMatrix::from(&asm.matrix);
        assert!((csr_dense.clone() - &dense).norm() < 1e-14);
        assert!((csr_dense.clone() - csr_dense.transpose()).norm() < 1e-14);
        // Multiply agrees with the dense product.
        let x: Vec<f64> = (0..15).map(|k| (k as f64 * 0.37).sin()).collect();
        let (mut y, mut y_csr) = (vec![0.0; 15], vec![0.0; 15]);
        asm.multiply(&x, &mut y);
        multiply_csr(&asm.matrix, &x, &mut y_csr);
        let yd = &dense * nalgebra::DVector::from_vec(x);
        for k in 0..15 {
            assert!((y[k] - yd[k]).abs() < 1e-13);
            assert!((y_csr[k] - yd[k]).abs() < 1e-13);
        }
        assert_eq!(asm.neighbours(4), &[1, 2, 3, 4]);
        assert!((asm.diagonal_block(0) - dense.fixed_view::<3, 3>(0, 0)).norm() < 1e-15);
    }

    /// The product on the processor's vector unit has the portable code's
    /// bits, node by node (a mesh of several product tasks).
    #[test]
    fn vector_product_has_the_portable_bits() {
        let (tets, rest, positions) = cube_mesh(9);
        let n = positions.len();
        assert!(n > 2 * MULTIPLY_GRAIN, "{n} nodes");
        let mut asm = Assembly::new(n, &tets);
        asm.assemble_stiffness(|t, a, b| rest[t].k0(a, b));
        let x: Vec<f64> = (0..3 * n).map(|k| (k as f64 * 0.731).sin()).collect();
        let mut y = vec![0.0; 3 * n];
        asm.multiply(&x, &mut y);
        let mut portable = vec![0.0; 3 * n];
        asm.multiply_rows_portable(0, &x, &mut portable);
        for (a, b) in y.iter().zip(&portable) {
            assert_eq!(a.to_bits(), b.to_bits());
        }
    }
}
