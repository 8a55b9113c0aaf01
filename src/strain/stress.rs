//! Stress of the element, for output.
//!
//! Corotational (the default): the energy per rest volume is
//! `ψ = μ ε:ε + λ/2 (tr ε)²` with
//! the corotated strain `ε = S − I`, `F = R S` (the sign-corrected polar
//! decomposition the forces use). Its first Piola–Kirchhoff stress is
//! `P = R s` with `s = 2μ ε + λ tr(ε) I`, and the Cauchy stress
//! `σ = P Fᵀ / J = R s S Rᵀ / J` (symmetric: `s` is a polynomial in `S`).
//! Any other energy density ([`crate::fem::hyperelastic`]) gives
//! `P = U diag(Ψ_i) Vᵀ` from its principal derivatives, and `σ = P Fᵀ / J`
//! the same way (for the stable Neo-Hookean energy,
//! `σ = (μ/J)(F Fᵀ − I) + κ(J − 1) I`).
//! Units: N and mm, so stresses and energy densities are N/mm² (MPa,
//! mJ/mm³).

use nalgebra::Matrix3;
use rayon::prelude::*;

use super::element::deformation_gradient;
use crate::fem::{Corotation, Material};
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
    /// The stress of a tet of `material` under the deformation gradient `f`.
    pub fn of(f: &Matrix3<f64>, material: &Material) -> TetStress {
        if material.model != crate::fem::Model::Corotational {
            return TetStress::hyperelastic(f, material);
        }
        let c = Corotation::of(f);
        let stretch = c.v * Matrix3::from_diagonal(&c.sigma) * c.v.transpose();
        let strain = stretch - Matrix3::identity();
        let (mu, lambda) = (material.mu(), material.lambda());
        let trace = strain.trace();
        let s = strain * (2.0 * mu) + Matrix3::identity() * (lambda * trace);
        let kirchhoff = c.r * s * stretch * c.r.transpose();
        let j = c.sigma.product();
        let cauchy = if j > 0.0 { kirchhoff / j } else { kirchhoff };
        TetStress {
            // Symmetric to round-off; made exactly so.
            cauchy: (cauchy + cauchy.transpose()) * 0.5,
            energy_density: mu * strain.norm_squared() + 0.5 * lambda * trace * trace,
        }
    }

    /// The stress of a material whose energy is not the corotational one.
    fn hyperelastic(f: &Matrix3<f64>, material: &Material) -> TetStress {
        let c = Corotation::of(f);
        let law = material.law();
        let p = c.u * Matrix3::from_diagonal(&law.gradient(&c.sigma)) * c.v.transpose();
        let kirchhoff = p * f.transpose();
        let j = c.sigma.product();
        let cauchy = if j > 0.0 { kirchhoff / j } else { kirchhoff };
        TetStress {
            cauchy: (cauchy + cauchy.transpose()) * 0.5,
            energy_density: law.energy(&c.sigma),
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
/// material (parallel over tets; each entry depends on its tet only).
pub fn element_stresses(mesh: &TetMesh, x: &[Vec3], materials: &[Material]) -> Vec<TetStress> {
    mesh.tets
        .par_iter()
        .zip(materials)
        .map(|(tet, m)| TetStress::of(&deformation_gradient(&mesh.positions, x, tet), m))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The stable Neo-Hookean stress against its closed forms: simple shear
    /// `F = I + γ e_x e_yᵀ` (J = 1) gives `σ = μ(F Fᵀ − I)`; uniaxial stretch
    /// `s` with the free lateral stretch `t` that zeroes the lateral stress
    /// (`s t² = 1 + μ(1 − 1/s)/κ`) gives `σ_xx = μ(s² − t²)/J`, the rest 0.
    #[test]
    fn neo_hookean_matches_its_closed_forms() {
        let m = material().with_model(crate::fem::Model::StableNeoHookean);
        let (mu, kappa) = (m.mu(), m.lambda() + m.mu());
        for gamma in [0.1, 0.5, 1.0] {
            let f = Matrix3::new(1.0, gamma, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0);
            let expected = (f * f.transpose() - Matrix3::identity()) * mu;
            let st = TetStress::of(&f, &m);
            assert!(
                (st.cauchy - expected).norm() <= 1e-12 * expected.norm(),
                "γ {gamma}: {} vs {expected}",
                st.cauchy
            );
            let psi = 0.5 * mu * gamma * gamma;
            assert!((st.energy_density - psi).abs() <= 1e-12 * psi);
        }
        for s in [0.6, 0.9, 1.2, 2.0] {
            let t = ((1.0 + mu * (1.0 - 1.0 / s) / kappa) / s).sqrt();
            let f = Matrix3::from_diagonal(&nalgebra::Vector3::new(s, t, t));
            let j = s * t * t;
            let sxx = mu * (s * s - t * t) / j;
            let st = TetStress::of(&f, &m);
            let expected = Matrix3::from_diagonal(&nalgebra::Vector3::new(sxx, 0.0, 0.0));
            assert!(
                (st.cauchy - expected).norm() <= 1e-12 * sxx.abs(),
                "stretch {s}: {} vs {expected}",
                st.cauchy
            );
        }
    }

    fn material() -> Material {
        Material::from_scenario_units("test", 150.0, 0.45, 1100.0).unwrap()
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
}
