//! Stress of the element, for output: the state the solver found.
//!
//! A tet's energy density is its law's `Ψ(σ̂)` of the principal stretches
//! ([`crate::fem::hyperelastic::Law`]), whose first Piola–Kirchhoff
//! stress is `P = U diag(Ψ_i) Vᵀ` (`F = U Σ̂ Vᵀ`, the sign-corrected SVD
//! the forces use) and whose Cauchy stress is `σ = P Fᵀ / J`:
//!
//! - corotational (the default): `ψ = μ ε:ε + λ/2 (tr ε)²` with the
//!   corotated strain `ε = S − I`, `F = R S`, so `σ = R s S Rᵀ / J` with
//!   `s = 2μ ε + λ tr(ε) I`;
//! - stable Neo-Hookean: `σ = (μ/J) F Fᵀ + (κ(J − 1) − μ) I`;
//! - Neo-Hookean (logarithmic volume term): `σ = (μ/J)(F Fᵀ − I) +
//!   (λ ln J / J) I`.
//!
//! A tet of a locking-free material carries only a share of the volume
//! term itself (its law's λ is [`Material::element_lambda`]); the rest
//! sits on the nodes ([`crate::fem::nodal_pressure`]), and the tet adds
//! the pressure `p̄_e` of its points to its stress (`p̄_e I`) and a quarter
//! of each point's energy density to its own. Summed over the tets with
//! their rest volumes, the energy densities are the solver's energy, and
//! the stresses are in balance with the forces it balanced.
//! Units: N and mm, so stresses and energy densities are N/mm² (MPa,
//! mJ/mm³).

use nalgebra::Matrix3;
use rayon::prelude::*;

use crate::fem::hyperelastic::Law;
use crate::fem::nodal_pressure::{NodalPressure, TetShare};
use crate::fem::{Corotation, Material, Volumetric};
use crate::mesh::{TetMesh, Vec3};

/// The stress state of one tet.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TetStress {
    /// Cauchy stress (N/mm², deformed frame). For an inverted tet (J ≤ 0),
    /// where it has no meaning, the Kirchhoff stress `P Fᵀ` is given.
    pub cauchy: Matrix3<f64>,
    /// Strain energy per rest volume (N/mm² = mJ/mm³).
    pub energy_density: f64,
}

impl TetStress {
    /// The stress of a tet of `material` under a deformation gradient `f`
    /// that the tet shares with its neighbours (a uniform deformation):
    /// a locking-free material's nodal points then have the tet's own
    /// volume ratio.
    pub fn of(f: &Matrix3<f64>, material: &Material) -> TetStress {
        let share = (material.volumetric == Volumetric::LockingFree).then(|| {
            let (kappa, j) = (material.nodal_bulk(), f.determinant());
            TetShare {
                pressure: kappa * (j - 1.0),
                energy_density: 0.5 * kappa * (j - 1.0).powi(2),
            }
        });
        TetStress::solved(f, &material.element_law(), share)
    }

    /// The stress of a tet whose own energy density is `law`, with its
    /// `share` of the nodal volume term where it has one.
    pub fn solved(f: &Matrix3<f64>, law: &Law, share: Option<TetShare>) -> TetStress {
        let c = Corotation::of(f);
        let p = c.u * Matrix3::from_diagonal(&law.gradient(&c.sigma)) * c.v.transpose();
        let j = c.sigma.product();
        let mut kirchhoff = p * f.transpose();
        let mut energy_density = law.energy(&c.sigma);
        if let Some(share) = share {
            // P = p̄ cof F, so P Fᵀ = p̄ J I.
            kirchhoff += Matrix3::identity() * (share.pressure * j);
            energy_density += share.energy_density;
        }
        let cauchy = if j > 0.0 { kirchhoff / j } else { kirchhoff };
        TetStress {
            // Symmetric to round-off; made exactly so.
            cauchy: (cauchy + cauchy.transpose()) * 0.5,
            energy_density,
        }
    }

    /// The six components `[xx, yy, zz, xy, yz, xz]` (the order ParaView
    /// reads as a symmetric tensor).
    pub fn components(&self) -> [f64; 6] {
        let s = &self.cauchy;
        [
            s[(0, 0)],
            s[(1, 1)],
            s[(2, 2)],
            s[(0, 1)],
            s[(1, 2)],
            s[(0, 2)],
        ]
    }

    /// Von Mises equivalent stress `√(3/2 dev σ : dev σ)` (N/mm²).
    pub fn von_mises(&self) -> f64 {
        let dev = self.cauchy - Matrix3::identity() * (self.cauchy.trace() / 3.0);
        (1.5 * dev.norm_squared()).sqrt()
    }

    /// Mean normal stress `tr σ / 3` (N/mm²; negative in compression).
    pub fn mean(&self) -> f64 {
        self.cauchy.trace() / 3.0
    }
}

/// The stress of every tet of `mesh` at positions `x`, with each tet's
/// material: the state the solver found at `x` — the rest elements and
/// the nodal volume term built as the solver builds them, so locking-free
/// tets carry their points' pressure (parallel over tets, each entry
/// computed in a fixed order).
pub fn element_stresses(mesh: &TetMesh, x: &[Vec3], materials: &[Material]) -> Vec<TetStress> {
    let elements = crate::fem::simulation::rest_elements(mesh, materials);
    let shares = match NodalPressure::new(&mesh.tets, &elements, materials, mesh.num_vertices()) {
        Some(mut nodal) => {
            nodal.evaluate(&mesh.tets, &elements, x);
            nodal.shares()
        }
        None => vec![None; mesh.num_tets()],
    };
    elements
        .par_iter()
        .zip(&mesh.tets)
        .zip(shares)
        .map(|((e, tet), share)| {
            TetStress::solved(&e.deformation_gradient(&tet.map(|v| x[v])), &e.law(), share)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Checks a Neo-Hookean material's stress against the closed forms both
    /// energies share: simple shear `F = I + γ e_x e_yᵀ` (J = 1) gives
    /// `σ = μ(F Fᵀ − I)` and `ψ = μγ²/2`; uniaxial stretch `s` with the
    /// lateral stretch `t = lateral(s)` that zeroes the lateral stress gives
    /// `σ_xx = μ(s² − t²)/J`, the rest 0 (to `tol` of σ_xx).
    fn assert_neo_hookean_closed_forms(m: &Material, lateral: impl Fn(f64) -> f64, tol: f64) {
        let mu = m.mu();
        for gamma in [0.1, 0.5, 1.0] {
            let f = Matrix3::new(1.0, gamma, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0);
            let expected = (f * f.transpose() - Matrix3::identity()) * mu;
            let st = TetStress::of(&f, m);
            assert!(
                (st.cauchy - expected).norm() <= 1e-12 * expected.norm(),
                "γ {gamma}: {} vs {expected}",
                st.cauchy
            );
            let psi = 0.5 * mu * gamma * gamma;
            assert!((st.energy_density - psi).abs() <= 1e-12 * psi);
        }
        for s in [0.6, 0.9, 1.2, 2.0] {
            let t = lateral(s);
            let f = Matrix3::from_diagonal(&nalgebra::Vector3::new(s, t, t));
            let sxx = mu * (s * s - t * t) / (s * t * t);
            let st = TetStress::of(&f, m);
            let expected = Matrix3::from_diagonal(&nalgebra::Vector3::new(sxx, 0.0, 0.0));
            assert!(
                (st.cauchy - expected).norm() <= tol * sxx.abs(),
                "stretch {s}: {} vs {expected}",
                st.cauchy
            );
        }
    }

    /// The stable Neo-Hookean stress against the closed forms; its free
    /// lateral stretch solves `s t² = 1 + μ(1 − 1/s)/κ`.
    #[test]
    fn neo_hookean_matches_its_closed_forms() {
        let m = material().with_model(crate::fem::Model::StableNeoHookean);
        let (mu, kappa) = (m.mu(), m.lambda() + m.mu());
        let lateral = |s: f64| ((1.0 + mu * (1.0 - 1.0 / s) / kappa) / s).sqrt();
        assert_neo_hookean_closed_forms(&m, lateral, 1e-12);
    }

    fn material() -> Material {
        Material::from_scenario_units("test", 150.0, 0.45, 1100.0).unwrap()
    }

    /// The Neo-Hookean stress with the logarithmic volume term against the
    /// same closed forms; its free lateral stretch solves
    /// `μ(t² − 1) + λ ln(s t²) = 0` (bisection).
    #[test]
    fn log_neo_hookean_matches_its_closed_forms() {
        let m = material().with_model(crate::fem::Model::NeoHookean);
        let (mu, lambda) = (m.mu(), m.lambda());
        let lateral = |s: f64| {
            let stress = |t: f64| mu * (t * t - 1.0) + lambda * (s * t * t).ln();
            let (mut lo, mut hi) = (0.1, 3.0);
            for _ in 0..200 {
                let mid = 0.5 * (lo + hi);
                if stress(mid) > 0.0 {
                    hi = mid;
                } else {
                    lo = mid;
                }
            }
            0.5 * (lo + hi)
        };
        assert_neo_hookean_closed_forms(&m, lateral, 1e-10);
    }

    /// `P` is the derivative of the energy density: `σ J F⁻ᵀ` against
    /// central differences of ψ, for a general and a rotated deformation.
    #[test]
    fn stress_is_the_energy_gradient() {
        let turn = nalgebra::Rotation3::from_euler_angles(0.3, -0.5, 1.1).into_inner();
        let f0 = Matrix3::new(1.1, 0.2, -0.1, 0.05, 0.9, 0.15, -0.2, 0.1, 1.2);
        let snh = material().with_model(crate::fem::Model::StableNeoHookean);
        for (m, f) in [
            (material(), f0),
            (material(), turn * f0),
            (snh, f0),
            (snh, turn * f0),
        ] {
            let st = TetStress::of(&f, &m);
            let p = st.cauchy * f.determinant() * f.try_inverse().unwrap().transpose();
            let h = 1e-6;
            for i in 0..3 {
                for k in 0..3 {
                    let (mut fp, mut fm) = (f, f);
                    fp[(i, k)] += h;
                    fm[(i, k)] -= h;
                    let d = (TetStress::of(&fp, &m).energy_density
                        - TetStress::of(&fm, &m).energy_density)
                        / (2.0 * h);
                    assert!(
                        (p[(i, k)] - d).abs() < 1e-7,
                        "P[{i}{k}] {} vs {d}",
                        p[(i, k)]
                    );
                }
            }
            assert_eq!(st.cauchy, st.cauchy.transpose());
        }
    }

    /// Small strains give linear elasticity; a pure rotation gives none; the
    /// von Mises stress of uniaxial tension is the tension.
    #[test]
    fn small_strain_limit_and_invariants() {
        let m = material();
        let (mu, lambda) = (m.mu(), m.lambda());
        let e = Matrix3::new(2.0, 0.5, 0.0, 0.5, -1.0, 0.3, 0.0, 0.3, 0.5) * 1e-6;
        let linear = e * (2.0 * mu) + Matrix3::identity() * (lambda * e.trace());
        let st = TetStress::of(&(Matrix3::identity() + e), &m);
        assert!((st.cauchy - linear).norm() < 1e-4 * linear.norm());
        let turn = nalgebra::Rotation3::from_euler_angles(0.7, 0.2, -1.3).into_inner();
        let rigid = TetStress::of(&turn, &m);
        assert!(rigid.cauchy.norm() < 1e-15 && rigid.energy_density.abs() < 1e-30);
        let uniaxial = TetStress {
            cauchy: Matrix3::from_diagonal(&nalgebra::Vector3::new(0.2, 0.0, 0.0)),
            energy_density: 0.0,
        };
        assert!((uniaxial.von_mises() - 0.2).abs() < 1e-15);
        assert_eq!(st.components()[3], st.cauchy[(0, 1)]);
    }

    /// Under a uniform deformation a locking-free tet's own share and its
    /// nodal share add up to the whole volume term: for the stable
    /// Neo-Hookean energy, whose volume term is `(λ + μ)/2 (J − 1)²`
    /// whichever part of λ a tet keeps, exactly the standard tet's stress
    /// and energy; for the corotational one, to first order in the strain.
    /// Below its volume limit the locking-free tet adds the limit's energy.
    #[test]
    fn a_locking_free_tet_adds_its_nodal_share() {
        use crate::fem::{Model, Volumetric};
        // J = 0.94, above the limit of both ν.
        let f = Matrix3::new(1.1, 0.2, -0.1, 0.05, 0.95, 0.15, -0.2, 0.1, 0.95);
        let squeezed = Matrix3::new(1.1, 0.2, -0.1, 0.05, 0.9, 0.15, -0.2, 0.1, 0.85);
        for nu in [0.45, 0.49] {
            let standard =
                Material::with_volumetric("t", 150.0, nu, 1100.0, Volumetric::Standard).unwrap();
            let lf = Material {
                volumetric: Volumetric::LockingFree,
                ..standard
            };
            assert!(lf.nodal_bulk() > 0.0);
            let (snh, snh_lf) = (
                standard.with_model(Model::StableNeoHookean),
                lf.with_model(Model::StableNeoHookean),
            );
            let (a, b) = (TetStress::of(&f, &snh), TetStress::of(&f, &snh_lf));
            assert!(
                (a.cauchy - b.cauchy).norm() < 1e-12 * a.cauchy.norm(),
                "ν {nu}"
            );
            assert!((a.energy_density - b.energy_density).abs() < 1e-12 * a.energy_density);
            let j = squeezed.determinant();
            let limit = snh_lf.element_limit();
            let added = limit.terms(j).0;
            let (a, b) = (
                TetStress::of(&squeezed, &snh),
                TetStress::of(&squeezed, &snh_lf),
            );
            assert_eq!(
                j < limit.ratio,
                nu == 0.49,
                "ν {nu}: J {j}, limit {limit:?}"
            );
            assert!(
                (b.energy_density - a.energy_density - added).abs() < 1e-12 * a.energy_density,
                "ν {nu}"
            );
            let small = Matrix3::identity() + (squeezed - Matrix3::identity()) * 1e-5;
            let (a, b) = (TetStress::of(&small, &standard), TetStress::of(&small, &lf));
            assert!(
                (a.cauchy - b.cauchy).norm() < 1e-4 * a.cauchy.norm(),
                "ν {nu}"
            );
            // Without the nodal share the pressure would be that of λ = 2μ.
            let own = TetStress::solved(&small, &lf.element_law(), None);
            assert!(
                (own.mean() - a.mean()).abs() > 0.5 * a.mean().abs(),
                "ν {nu}"
            );
        }
    }
}
