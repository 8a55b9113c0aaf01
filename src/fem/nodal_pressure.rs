//! The volume term of locking-free materials on nodal volume ratios: the
//! average nodal pressure tetrahedron of Bonet & Burton 1998 ("A simple
//! average nodal pressure tetrahedral element for incompressible and nearly
//! incompressible dynamic explicit applications").
//!
//! A linear tet that carries its own volume term imposes one
//! near-constraint per tet, and a tet mesh has about five tets per node:
//! more constraints than the three displacements per node can meet, so the
//! mesh locks as ν → 0.5. Here the tets of a locking-free material keep
//! the rest of their energy and a share of the volume term too small to
//! lock ([`super::material::Material::element_lambda`]), and the rest of
//! the volume term sits on the nodes:
//!
//! - each node has one *point* `a` per locking-free material among its
//!   tets (a node on the interface of two such materials has two, so that
//!   neither material's pressure leaks into the other: across an interface
//!   the normal stress is continuous, the pressure is not);
//! - a point has a rest volume `V_a = Σ_e V_e/4` and a deformed one
//!   `v_a = Σ_e v_e/4` over the node's tets `e` of its material, with
//!   `v_e = V_e det F_e`, and the volume ratio `J̄_a = v_a/V_a`;
//! - the energy is `Σ_a V_a κ_a/2 (J̄_a − 1)²` (κ_a the material's
//!   [`nodal_bulk`](super::material::Material::nodal_bulk)), one
//!   near-constraint per point;
//! - its forces are those of a pressure `p̄_e = Σ_{a∈e} p_a/4`,
//!   over the tet's points, `p_a = κ_a (J̄_a − 1)`, uniform in each tet: `f_b = −p̄_e V_e cof(F_e) g_b`;
//! - its Hessian is `Σ_a (κ_a/V_a) γ_a γ_aᵀ` with `γ_a = ∂v_a/∂x`
//!   (positive semi-definite, coupling every two nodes of a point's patch,
//!   the nodes of its tets: the matrix pattern grows to those pairs,
//!   [`NodalPressure::patches`])
//!   plus `Σ_e p̄_e V_e ∂²J_e/∂x²`, whose block `(b, c)` is
//!   `−p̄_e V_e [F_e (g_b × g_c)]×` (indefinite; left out of the projected
//!   tangent).
//!
//! A uniform deformation gives every point the tets' common J, so the
//! patch tests hold to round-off; at small strain the energy is the
//! material's linear elasticity. Every sum runs in a fixed order.

use nalgebra::{Matrix3, Vector3};
use rayon::prelude::*;

use super::assembly::Assembly;
use super::corotation::{RestElement, UPPER};
use super::material::{Material, Volumetric};
use crate::mesh::Vec3;

/// Marks a node or tet without a locking-free material.
const NONE: u32 = u32::MAX;

/// The nodal volume term of a mesh's locking-free tets, with the state of
/// its last evaluation.
#[derive(Clone, Debug)]
pub struct NodalPressure {
    /// Mesh tets of locking-free materials, ascending.
    tets: Vec<usize>,
    /// Per mesh tet its index in `tets`, or [`NONE`].
    tet_slot: Vec<u32>,
    /// The points: (mesh node, material group), ascending.
    points: Vec<(usize, u16)>,
    /// Per mesh node `node_points[v]..node_points[v + 1]` indexes its points.
    node_points: Vec<u32>,
    /// Per locking-free tet the points of its vertices.
    tet_points: Vec<[u32; 4]>,
    /// Per point `incident_start[a]..incident_start[a + 1]` indexes its
    /// (tet index in `tets`, local vertex) pairs, ascending.
    incident_start: Vec<usize>,
    incident: Vec<(u32, u8)>,
    /// Per point its patch: the mesh nodes of its tets, ascending, its own
    /// included (`patch_start` indexes `patch`).
    patch_start: Vec<usize>,
    patch: Vec<usize>,
    /// Per point `V_a` (mm³) and `κ_a` (MPa).
    rest_volume: Vec<f64>,
    bulk: Vec<f64>,
    /// Per point the volume ratio `J̄_a` and the pressure `p_a` (MPa) of the
    /// last evaluation.
    ratio: Vec<f64>,
    pressure: Vec<f64>,
    /// Per tet `p̄_e` (MPa), `V_e cof(F_e)` and `F_e` of the last evaluation.
    tet_pressure: Vec<f64>,
    cofactor: Vec<Matrix3<f64>>,
    deformation: Vec<Matrix3<f64>>,
    /// Per point `γ_a` on its patch (aligned with `patch`): `∂v_a/∂x_j`.
    gamma: Vec<Vec3>,
    /// Per mesh node `column_start[v]..column_start[v + 1]` indexes the
    /// patch entries of node `v` (`column`), by ascending point: the
    /// points whose `γ_a` reach the node; `column_point` holds their
    /// points and `column_gamma` their `γ_{a,v}` (copied at
    /// [`NodalPressure::update_coupling`], so that the products read them
    /// in order).
    column_start: Vec<usize>,
    column: Vec<u32>,
    column_point: Vec<u32>,
    column_gamma: Vec<Vec3>,
    /// The factor the tangent's coupling carries (`1 + β/h` in
    /// implicit-Euler runs) at the last [`NodalPressure::update_coupling`].
    scale: f64,
}

/// A locking-free tet's part of the nodal volume term.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TetShare {
    /// `p̄_e` (MPa), the mean pressure of its points: the term adds
    /// `p̄_e I` to its Cauchy stress (`p̄_e cof F` to the first Piola).
    pub pressure: f64,
    /// `Σ_{a∈e} κ_a/8 (J̄_a − 1)²` (N/mm² per rest volume): a quarter of
    /// each of its points' energy densities, so that `Σ_e V_e ψ_e` over
    /// the tets is the term's energy `Σ_a V_a κ_a/2 (J̄_a − 1)²`.
    pub energy_density: f64,
}

/// `cof(F)`: the columns `f₁×f₂, f₂×f₀, f₀×f₁`, so that `∂ det F/∂F = cof F`
/// (defined for any F, inverted or flat included).
fn cofactor(f: &Matrix3<f64>) -> Matrix3<f64> {
    let (c0, c1, c2) = (f.column(0), f.column(1), f.column(2));
    Matrix3::from_columns(&[c1.cross(&c2), c2.cross(&c0), c0.cross(&c1)])
}

/// `[w]×`, the matrix of `v ↦ w × v`.
fn skew(w: &Vector3<f64>) -> Matrix3<f64> {
    Matrix3::new(0.0, -w.z, w.y, w.z, 0.0, -w.x, -w.y, w.x, 0.0)
}

impl NodalPressure {
    /// The nodal term of the locking-free tets of a mesh (`tets`, their
    /// rest `elements`, one material per tet, `num_nodes` nodes); `None`
    /// where no material is locking-free with a nodal share of its volume
    /// term (ν above 1/3).
    pub fn new(
        tets: &[[usize; 4]],
        elements: &[RestElement],
        materials: &[Material],
        num_nodes: usize,
    ) -> Option<NodalPressure> {
        let lf: Vec<usize> = (0..tets.len())
            .filter(|&t| {
                materials[t].volumetric == Volumetric::LockingFree
                    && materials[t].nodal_bulk() > 0.0
            })
            .collect();
        if lf.is_empty() {
            return None;
        }
        let mut tet_slot = vec![NONE; tets.len()];
        for (k, &t) in lf.iter().enumerate() {
            tet_slot[t] = k as u32;
        }
        // Material groups: tets of equal materials share nodal points.
        let mut groups: Vec<Material> = Vec::new();
        let tet_group: Vec<u16> = lf
            .iter()
            .map(|&t| {
                let g = groups
                    .iter()
                    .position(|m| *m == materials[t])
                    .unwrap_or_else(|| {
                        groups.push(materials[t]);
                        groups.len() - 1
                    });
                g as u16
            })
            .collect();
        let mut points: Vec<(usize, u16)> = lf
            .iter()
            .zip(&tet_group)
            .flat_map(|(&t, &g)| tets[t].map(|v| (v, g)))
            .collect();
        points.sort_unstable();
        points.dedup();
        let mut node_points = vec![0u32; num_nodes + 1];
        for &(v, _) in &points {
            node_points[v + 1] += 1;
        }
        for v in 0..num_nodes {
            node_points[v + 1] += node_points[v];
        }
        let find = |v: usize, g: u16| -> u32 {
            let range = node_points[v] as usize..node_points[v + 1] as usize;
            let k = points[range.clone()]
                .iter()
                .position(|&(_, h)| h == g)
                .expect("every vertex of a locking-free tet has its point");
            (range.start + k) as u32
        };
        let tet_points: Vec<[u32; 4]> = lf
            .iter()
            .zip(&tet_group)
            .map(|(&t, &g)| tets[t].map(|v| find(v, g)))
            .collect();
        let mut incident: Vec<Vec<(u32, u8)>> = vec![Vec::new(); points.len()];
        for (k, corners) in tet_points.iter().enumerate() {
            for (a, &p) in corners.iter().enumerate() {
                incident[p as usize].push((k as u32, a as u8));
            }
        }
        let (mut incident_start, mut flat) = (vec![0], Vec::new());
        let (mut patch_start, mut patch) = (vec![0], Vec::new());
        let (mut rest_volume, mut bulk) = (Vec::new(), Vec::new());
        for (point, list) in points.iter().zip(&incident) {
            let mut volume = 0.0;
            let mut members = Vec::new();
            for &(k, _) in list {
                let t = lf[k as usize];
                volume += elements[t].volume / 4.0;
                members.extend_from_slice(&tets[t]);
            }
            members.sort_unstable();
            members.dedup();
            patch.extend_from_slice(&members);
            patch_start.push(patch.len());
            flat.extend_from_slice(list);
            incident_start.push(flat.len());
            rest_volume.push(volume);
            bulk.push(groups[point.1 as usize].nodal_bulk());
        }
        let mut entry_point = vec![0u32; patch.len()];
        let mut column_start = vec![0usize; num_nodes + 1];
        for (a, w) in patch_start.windows(2).enumerate() {
            entry_point[w[0]..w[1]].fill(a as u32);
        }
        for &v in &patch {
            column_start[v + 1] += 1;
        }
        for v in 0..num_nodes {
            column_start[v + 1] += column_start[v];
        }
        let mut column = vec![0u32; patch.len()];
        let mut fill = column_start.clone();
        // Entries in ascending order, so each node's list is by point.
        for (e, &v) in patch.iter().enumerate() {
            column[fill[v]] = e as u32;
            fill[v] += 1;
        }
        let column_point = column.iter().map(|&e| entry_point[e as usize]).collect();
        let (n_tets, n_points, n_patch) = (lf.len(), points.len(), patch.len());
        Some(NodalPressure {
            tets: lf,
            tet_slot,
            points,
            node_points,
            tet_points,
            incident_start,
            incident: flat,
            patch_start,
            patch,
            rest_volume,
            bulk,
            ratio: vec![1.0; n_points],
            pressure: vec![0.0; n_points],
            tet_pressure: vec![0.0; n_tets],
            cofactor: vec![Matrix3::identity(); n_tets],
            deformation: vec![Matrix3::identity(); n_tets],
            gamma: vec![Vec3::zeros(); n_patch],
            column_start,
            column,
            column_point,
            column_gamma: vec![Vec3::zeros(); n_patch],
            scale: 1.0,
        })
    }

    /// Every point's patch (the nodes its term couples), for the matrix
    /// pattern ([`Assembly::with_patches`]).
    pub fn patches(&self) -> Vec<Vec<usize>> {
        (0..self.points.len())
            .map(|a| self.patch_of(a).to_vec())
            .collect()
    }

    fn patch_of(&self, a: usize) -> &[usize] {
        &self.patch[self.patch_start[a]..self.patch_start[a + 1]]
    }

    fn incident_of(&self, a: usize) -> &[(u32, u8)] {
        &self.incident[self.incident_start[a]..self.incident_start[a + 1]]
    }

    /// Evaluates the nodal volume ratios at positions `x` and adds the
    /// pressure forces to the tets' vertex forces.
    pub fn add_forces(
        &mut self,
        tets: &[[usize; 4]],
        elements: &[RestElement],
        x: &[Vec3],
        tet_forces: &mut [[Vec3; 4]],
    ) {
        self.evaluate(tets, elements, x);
        let (tet_slot, tet_pressure, cofactor) =
            (&self.tet_slot, &self.tet_pressure, &self.cofactor);
        tet_forces.par_iter_mut().enumerate().for_each(|(t, f)| {
            let k = tet_slot[t];
            if k != NONE {
                let k = k as usize;
                let pc = cofactor[k] * tet_pressure[k];
                for (fb, g) in f.iter_mut().zip(&elements[t].grads) {
                    *fb -= pc * g;
                }
            }
        });
    }

    /// Evaluates the nodal volume ratios, the points' pressures and the
    /// tets' `p̄_e` at positions `x`.
    pub fn evaluate(&mut self, tets: &[[usize; 4]], elements: &[RestElement], x: &[Vec3]) {
        let lf = &self.tets;
        let volumes: Vec<f64> = self
            .cofactor
            .par_iter_mut()
            .zip(self.deformation.par_iter_mut())
            .enumerate()
            .map(|(k, (cof, f))| {
                let (t, e) = (lf[k], &elements[lf[k]]);
                *f = e.deformation_gradient(&tets[t].map(|v| x[v]));
                *cof = cofactor(f) * e.volume;
                e.volume * f.determinant()
            })
            .collect();
        let (rest, bulk) = (&self.rest_volume, &self.bulk);
        let (starts, incident) = (&self.incident_start, &self.incident);
        self.ratio
            .par_iter_mut()
            .zip(self.pressure.par_iter_mut())
            .enumerate()
            .for_each(|(a, (j, p))| {
                let v: f64 = incident[starts[a]..starts[a + 1]]
                    .iter()
                    .map(|&(k, _)| volumes[k as usize] / 4.0)
                    .sum();
                *j = v / rest[a];
                *p = bulk[a] * (*j - 1.0);
            });
        let (pressure, tet_points) = (&self.pressure, &self.tet_points);
        self.tet_pressure
            .par_iter_mut()
            .enumerate()
            .for_each(|(k, p)| {
                *p = tet_points[k]
                    .iter()
                    .map(|&a| pressure[a as usize])
                    .sum::<f64>()
                    / 4.0;
            });
    }

    /// Per mesh tet its share of the term at the last evaluation, `None`
    /// for a tet without a locking-free material: what its stress and
    /// energy outputs add to its own (reduced) volume term to be the state
    /// the solver found.
    pub fn shares(&self) -> Vec<Option<TetShare>> {
        self.tet_slot
            .iter()
            .map(|&k| {
                (k != NONE).then(|| {
                    let points = &self.tet_points[k as usize];
                    TetShare {
                        pressure: self.tet_pressure[k as usize],
                        energy_density: points
                            .iter()
                            .map(|&a| {
                                let a = a as usize;
                                self.bulk[a] / 8.0 * (self.ratio[a] - 1.0).powi(2)
                            })
                            .sum(),
                    }
                })
            })
            .collect()
    }

    /// `γ_a` on each node's patch: `Σ_e V_e cof(F_e) g_b / 4` over the
    /// node's tets `e`, at the patch position of each vertex `b`.
    fn update_gamma(&mut self, tets: &[[usize; 4]], elements: &[RestElement]) {
        let mut gamma = std::mem::take(&mut self.gamma);
        let rows = split_rows(&self.patch_start, &mut gamma);
        rows.into_par_iter().enumerate().for_each(|(a, out)| {
            out.fill(Vec3::zeros());
            let patch = self.patch_of(a);
            for &(k, _) in self.incident_of(a) {
                let t = self.tets[k as usize];
                let c = self.cofactor[k as usize] / 4.0;
                for (&v, g) in tets[t].iter().zip(&elements[t].grads) {
                    let q = patch
                        .binary_search(&v)
                        .expect("a tet's node is in its patch");
                    out[q] += c * g;
                }
            }
        });
        self.gamma = gamma;
    }

    /// Adds the pressure term `p̄_e V_e ∂²J_e/∂x²` (times `scale`) to the
    /// 10 upper blocks of each locking-free tet (the exact tangent).
    pub fn add_geometric_blocks(
        &self,
        elements: &[RestElement],
        scale: f64,
        blocks: &mut [[Matrix3<f64>; 10]],
    ) {
        blocks.par_iter_mut().enumerate().for_each(|(t, out)| {
            let k = self.tet_slot[t];
            if k == NONE {
                return;
            }
            let k = k as usize;
            let (f, g) = (&self.deformation[k], &elements[t].grads);
            let c = -self.tet_pressure[k] * elements[t].volume * scale;
            for a in 0..4 {
                for b in a + 1..4 {
                    out[UPPER[a][b]] += skew(&(f * g[a].cross(&g[b]))) * c;
                }
            }
        });
    }

    /// Adds `scale · Σ_a (κ_a/V_a) γ_a γ_aᵀ` at the last evaluation of the
    /// forces to the matrix of `asm` (whose pattern holds every point's
    /// patch). The `γ_a` are computed here, not with the forces, which the
    /// line search evaluates more often than the tangent is assembled.
    pub fn add_coupling(
        &mut self,
        tets: &[[usize; 4]],
        elements: &[RestElement],
        asm: &mut Assembly,
        scale: f64,
    ) {
        self.update_coupling(tets, elements, scale);
        asm.add_row_blocks(|i, add| {
            // The points whose patch holds node i: for each point of i, the
            // points of its material at the nodes of its patch.
            for own in self.node_points[i]..self.node_points[i + 1] {
                let group = self.points[own as usize].1;
                for &v in self.patch_of(own as usize) {
                    let a = self.point(v, group);
                    let patch = self.patch_of(a);
                    let gamma = &self.gamma[self.patch_start[a]..self.patch_start[a + 1]];
                    let q = patch.binary_search(&i).expect("patches are symmetric");
                    let gi = gamma[q] * (scale * self.bulk[a] / self.rest_volume[a]);
                    for (&j, gj) in patch.iter().zip(gamma) {
                        add(j, &(gi * gj.transpose()));
                    }
                }
            }
        });
    }

    /// Computes the `γ_a` at the last evaluation of the forces for the
    /// coupling `scale · Σ_a (κ_a/V_a) γ_a γ_aᵀ` that
    /// [`NodalPressure::add_product`], [`NodalPressure::diagonal_block`] and
    /// [`NodalPressure::coupling_terms`] then apply without a matrix.
    pub fn update_coupling(&mut self, tets: &[[usize; 4]], elements: &[RestElement], scale: f64) {
        self.update_gamma(tets, elements);
        let (gamma, column) = (&self.gamma, &self.column);
        self.column_gamma
            .par_iter_mut()
            .zip(column)
            .for_each(|(g, &e)| *g = gamma[e as usize]);
        self.scale = scale;
    }

    /// `c_a = scale · κ_a/V_a`, the weight of point `a`'s `γ_a γ_aᵀ`.
    fn weight(&self, a: usize) -> f64 {
        self.scale * self.bulk[a] / self.rest_volume[a]
    }

    /// Adds the coupling's product to `y`: `y += Σ_a c_a γ_a (γ_a · x)`
    /// (`x`, `y` of three entries a node). Each point's dot product runs
    /// over its patch, then each node gathers its points in ascending order:
    /// the same bits for any number of threads. It costs two passes over
    /// the patches where the assembled coupling would hold every pair of a
    /// patch's nodes: about four times the tets' own blocks.
    pub fn add_product(&self, x: &[f64], y: &mut [f64]) {
        let amount: Vec<f64> = (0..self.points.len())
            .into_par_iter()
            .map(|a| {
                let range = self.patch_start[a]..self.patch_start[a + 1];
                let dot: f64 = self.patch[range.clone()]
                    .iter()
                    .zip(&self.gamma[range])
                    .map(|(&v, g)| g.x * x[3 * v] + g.y * x[3 * v + 1] + g.z * x[3 * v + 2])
                    .sum();
                self.weight(a) * dot
            })
            .collect();
        y.par_chunks_mut(3).enumerate().for_each(|(v, yv)| {
            let range = self.column_start[v]..self.column_start[v + 1];
            if range.is_empty() {
                return;
            }
            let mut sum = Vec3::zeros();
            for (g, &a) in self.column_gamma[range.clone()]
                .iter()
                .zip(&self.column_point[range])
            {
                sum += g * amount[a as usize];
            }
            yv[0] += sum.x;
            yv[1] += sum.y;
            yv[2] += sum.z;
        });
    }

    /// The coupling's diagonal block of node `v`: `Σ_a c_a γ_{a,v} γ_{a,v}ᵀ`.
    pub fn diagonal_block(&self, v: usize) -> Matrix3<f64> {
        let range = self.column_start[v]..self.column_start[v + 1];
        self.column_gamma[range.clone()]
            .iter()
            .zip(&self.column_point[range])
            .fold(Matrix3::zeros(), |sum, (g, &a)| {
                sum + g * g.transpose() * self.weight(a as usize)
            })
    }

    /// Per point its weight `c_a`, its patch and `γ_a` on it: the coupling
    /// as a sum of `c_a γ_a γ_aᵀ` (for the coarse matrix, [`super::coarse`]).
    pub fn coupling_terms(&self) -> impl Iterator<Item = (f64, &[usize], &[Vec3])> + '_ {
        (0..self.points.len()).map(|a| {
            let range = self.patch_start[a]..self.patch_start[a + 1];
            (
                self.weight(a),
                &self.patch[range.clone()],
                &self.gamma[range],
            )
        })
    }

    /// The point of node `v` in material group `group`.
    fn point(&self, v: usize, group: u16) -> usize {
        let start = self.node_points[v] as usize;
        let end = self.node_points[v + 1] as usize;
        start
            + self.points[start..end]
                .iter()
                .position(|&(_, g)| g == group)
                .expect("a patch's nodes have points of its material")
    }

    /// The nodal volume energy `Σ_a V_a κ_a/2 (J̄_a − 1)²` (N·mm) at the last
    /// evaluation.
    pub fn energy(&self) -> f64 {
        self.rest_volume
            .iter()
            .zip(&self.bulk)
            .zip(&self.ratio)
            .map(|((v, k), j)| 0.5 * v * k * (j - 1.0).powi(2))
            .sum()
    }

    /// Each point of the term (its mesh node) with its volume ratio `J̄_a`
    /// at the last evaluation.
    pub fn volume_ratios(&self) -> impl Iterator<Item = (usize, f64)> + '_ {
        self.points
            .iter()
            .zip(&self.ratio)
            .map(|(&(v, _), &j)| (v, j))
    }
}

/// `values` cut into the consecutive rows `starts[i]..starts[i + 1]`.
fn split_rows<'a, T>(starts: &[usize], mut values: &'a mut [T]) -> Vec<&'a mut [T]> {
    let mut rows = Vec::with_capacity(starts.len() - 1);
    for w in starts.windows(2) {
        let (row, rest) = values.split_at_mut(w[1] - w[0]);
        rows.push(row);
        values = rest;
    }
    rows
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fem::assembly::tests::cube_mesh;
    use crate::fem::coarse::Coarse;
    use crate::fem::corotation::TangentKind;
    use crate::fem::hyperelastic::Model;
    use crate::fem::simulation::{LinearSolver, Simulation};
    use crate::fem::solve::Filter;
    use crate::mesh::{Region, TetMesh};

    /// A 2×2×2-cell cube whose lower half is locking-free with Poisson's
    /// ratio `nu`, in two materials (E = 100 kPa at x < 1, 30 kPa beyond,
    /// so the nodes between them have a point in each); the upper half is
    /// standard with ν = 0.45, so nodes on that interface average over part
    /// of their tets. Deformed by a smooth non-uniform map.
    fn deformed(model: Model, nu: f64) -> (Simulation, TetMesh) {
        let (tets, _, positions) = cube_mesh(2);
        let mesh = TetMesh {
            tet_region: vec![1; tets.len()],
            positions,
            tets,
            regions: vec![Region {
                id: 1,
                name: "cube".into(),
            }],
            boundary: Vec::new(),
            top: Default::default(),
        };
        let materials: Vec<Material> = (0..mesh.num_tets())
            .map(|t| {
                let c = mesh.tet_centroid(t);
                let (volumetric, nu) = if c.z < 1.0 {
                    (Volumetric::LockingFree, nu)
                } else {
                    (Volumetric::Standard, 0.45)
                };
                let kpa = if c.x < 1.0 { 100.0 } else { 30.0 };
                Material::with_volumetric("cube", kpa, nu, 1000.0, volumetric)
                    .unwrap()
                    .with_model(model)
            })
            .collect();
        let mut sim = Simulation::new(&mesh, &materials);
        for p in sim.positions_mut() {
            let (x, y, z) = (p.x, p.y, p.z);
            *p = Vec3::new(
                x + 0.12 * (y * z).sin() - 0.05 * z * z,
                0.93 * y + 0.08 * (x * z).cos(),
                1.08 * z - 0.1 * x * y + 0.03 * x * x,
            );
        }
        (sim, mesh)
    }

    fn total_energy(sim: &mut Simulation) -> f64 {
        sim.evaluate_forces();
        let x = sim.positions().to_vec();
        let elastic: f64 = (sim.body.tets.iter().zip(&sim.body.elements))
            .map(|(t, e)| e.energy(&t.map(|v| x[v])))
            .sum();
        elastic + sim.body.pressure.as_ref().unwrap().energy()
    }

    /// The forces are minus the gradient of the total energy, and the exact
    /// tangent is their derivative, by central differences, for both
    /// energy densities at ν = 0.48 and 0.4999.
    #[test]
    fn forces_and_tangent_are_the_energy_derivatives() {
        for model in [Model::Corotational, Model::StableNeoHookean] {
            for nu in [0.48, 0.4999] {
                let (mut sim, _) = deformed(model, nu);
                sim.evaluate_forces();
                let f = sim.work.f_int.clone();
                let scale = f.iter().map(|v| v.norm()).fold(0.0, f64::max);
                assert!(scale > 0.0);
                let h = 1e-6;
                for v in [0, 5, 13, 22, 26] {
                    for (k, fk) in f[v].iter().enumerate() {
                        let x0 = sim.positions()[v][k];
                        sim.positions_mut()[v][k] = x0 + h;
                        let ep = total_energy(&mut sim);
                        sim.positions_mut()[v][k] = x0 - h;
                        let em = total_energy(&mut sim);
                        sim.positions_mut()[v][k] = x0;
                        let grad = (ep - em) / (2.0 * h);
                        assert!(
                            (fk + grad).abs() <= 1e-6 * scale,
                            "{model:?} ν {nu} node {v} axis {k}: {fk} vs {}",
                            -grad
                        );
                    }
                }
                // K d against −(f(x + h d) − f(x − h d))/2h along a direction d.
                let n = sim.num_nodes();
                let d: Vec<f64> = (0..3 * n)
                    .map(|i| ((i * 7919) % 13) as f64 / 13.0 - 0.5)
                    .collect();
                sim.evaluate_forces();
                sim.work.tangent_kind = TangentKind::Exact;
                sim.assemble_tangent();
                let mut kd = vec![0.0; 3 * n];
                sim.multiply_tangent(&d, &mut kd);
                let x0 = sim.positions().to_vec();
                let at = |sign: f64, sim: &mut Simulation| {
                    for (i, p) in sim.positions_mut().iter_mut().enumerate() {
                        *p = x0[i] + Vec3::new(d[3 * i], d[3 * i + 1], d[3 * i + 2]) * (sign * h);
                    }
                    sim.evaluate_forces();
                    sim.work.f_int.clone()
                };
                let fp = at(1.0, &mut sim);
                let fm = at(-1.0, &mut sim);
                let kscale = kd.iter().fold(0.0f64, |m, v| m.max(v.abs()));
                for i in 0..n {
                    for k in 0..3 {
                        let fd = -(fp[i][k] - fm[i][k]) / (2.0 * h);
                        assert!(
                            (fd - kd[3 * i + k]).abs() <= 1e-5 * kscale,
                            "{model:?} ν {nu} node {i} axis {k}: K d {} vs {fd}",
                            kd[3 * i + k]
                        );
                    }
                }
            }
        }
    }

    /// A uniform deformation gives every point the tets' J.
    #[test]
    fn a_uniform_deformation_gives_every_node_its_volume_ratio() {
        let (mut sim, mesh) = deformed(Model::Corotational, 0.49);
        let a = Matrix3::new(1.1, 0.05, 0.0, -0.02, 0.95, 0.03, 0.0, 0.04, 0.9);
        for (p, q) in sim.positions_mut().iter_mut().zip(&mesh.positions) {
            *p = a * q;
        }
        sim.evaluate_forces();
        let j = a.determinant();
        let p = sim.body.pressure.as_ref().unwrap();
        let mut count = 0;
        for (_, r) in p.volume_ratios() {
            assert!((r - j).abs() < 1e-14, "{r} vs {j}");
            count += 1;
        }
        // The 18 nodes of the lower half, 6 of them (at x = 1) twice.
        assert_eq!(count, 24);
    }

    /// The iterative solvers apply the coupling as a product on the tets'
    /// own pattern; the factorising ones assemble it. Both give the same
    /// `K d`, the same diagonal blocks and the same coarse correction, and
    /// the public stiffness matrix holds the coupling either way.
    #[test]
    fn the_coupling_applied_as_a_product_is_the_assembled_one() {
        let (mut sim, mesh) = deformed(Model::StableNeoHookean, 0.49);
        let n = sim.num_nodes();
        let d: Vec<f64> = (0..3 * n)
            .map(|i| ((i * 7919) % 13) as f64 / 13.0 - 0.5)
            .collect();
        // The bottom held, so that the coarse matrix is definite.
        let filters: Vec<Filter> = mesh
            .positions
            .iter()
            .map(|p| {
                if p.z == 0.0 {
                    Filter::Fixed
                } else {
                    Filter::Free
                }
            })
            .collect();
        let mut seen = Vec::new();
        for linear in [LinearSolver::Direct, LinearSolver::TwoLevel] {
            sim.settings.linear = linear;
            sim.evaluate_forces();
            sim.work.tangent_kind = TangentKind::Exact;
            sim.assemble_tangent();
            assert_eq!(sim.work.patched, linear == LinearSolver::Direct);
            let mut kd = vec![0.0; 3 * n];
            sim.multiply_tangent(&d, &mut kd);
            let nodal = sim.nodal_coupling();
            let diagonal: Vec<Matrix3<f64>> = (0..n)
                .map(|i| {
                    sim.work.assembly.diagonal_block(i)
                        + nodal.map_or(Matrix3::zeros(), |p| p.diagonal_block(i))
                })
                .collect();
            let mut coarse = Coarse::new(&mesh.positions);
            assert!(coarse.refresh(&sim.work.assembly, nodal, &filters, sim.positions()));
            let mut z = vec![0.0; 3 * n];
            coarse.correct(&d, &mut z);
            seen.push((kd, diagonal, z, sim.work.assembly.matrix.nnz()));
        }
        let (assembled, product) = (&seen[0], &seen[1]);
        assert!(
            product.3 < assembled.3,
            "the product keeps the tets' own pattern"
        );
        let close = |a: &[f64], b: &[f64]| {
            let scale = a.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            a.iter().zip(b).all(|(x, y)| (x - y).abs() <= 1e-12 * scale)
        };
        assert!(close(&assembled.0, &product.0), "K d");
        let flat =
            |m: &[Matrix3<f64>]| m.iter().flat_map(|b| b.iter().copied()).collect::<Vec<_>>();
        assert!(
            close(&flat(&assembled.1), &flat(&product.1)),
            "diagonal blocks"
        );
        assert!(close(&assembled.2, &product.2), "coarse correction");
        // `Simulation::stiffness` is the whole tangent under any solver.
        assert_eq!(sim.settings.linear, LinearSolver::TwoLevel);
        sim.stiffness(TangentKind::Exact);
        let mut kd = vec![0.0; 3 * n];
        sim.work.assembly.multiply(&d, &mut kd);
        assert!(close(&assembled.0, &kd), "the stiffness matrix");
    }
}
