//! Per-tet principal strains.
//!
//! For each tet the deformation gradient `F = Ds·Dm⁻¹` is decomposed by the
//! sign-corrected SVD of the FEM ([`crate::fem::Corotation`]):
//! `F = U Σ̂ Vᵀ` with `U`, `V` rotations and an inverted tet carrying its one
//! negative stretch last. The principal stretches `λ1 ≥ λ2 ≥ λ3` (λ3 < 0 for
//! an inverted tet), the principal directions in the rest frame (columns of
//! `V`) and in the deformed frame (columns of `U`), Biot strains `λ − 1`,
//! Green strains `(λ² − 1)/2` and the volume ratio `J = λ1 λ2 λ3 = det F`
//! follow from it.

use nalgebra::{Matrix3, Vector3};
use rayon::prelude::*;

use crate::fem::Corotation;
use crate::mesh::{TetMesh, Vec3};

/// Principal strains of one tet.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PrincipalStrain {
    /// Deformation gradient.
    pub f: Matrix3<f64>,
    /// Principal stretches λ1 ≥ λ2 ≥ λ3 (λ3 negative when inverted).
    pub stretch: Vector3<f64>,
    /// Principal directions in the rest frame (columns, matching `stretch`).
    pub rest_axes: Matrix3<f64>,
    /// Principal directions in the deformed frame (columns).
    pub deformed_axes: Matrix3<f64>,
}

impl PrincipalStrain {
    /// Decomposes `f`.
    pub fn of(f: Matrix3<f64>) -> PrincipalStrain {
        let c = Corotation::of(&f);
        PrincipalStrain {
            f,
            stretch: c.sigma,
            rest_axes: c.v,
            deformed_axes: c.u,
        }
    }

    /// Biot strains `λ − 1`.
    pub fn biot(&self) -> Vector3<f64> {
        self.stretch.map(|l| l - 1.0)
    }

    /// Green strains `(λ² − 1)/2`.
    pub fn green(&self) -> Vector3<f64> {
        self.stretch.map(|l| 0.5 * (l * l - 1.0))
    }

    /// Volume ratio `J = det F`.
    pub fn volume_ratio(&self) -> f64 {
        self.stretch.product()
    }

    /// Whether the tet is inverted.
    pub fn inverted(&self) -> bool {
        self.stretch[2] < 0.0
    }
}

/// Principal strains of every tet of a deformed mesh.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ElementStrains {
    /// One entry per tet, in mesh order.
    pub tets: Vec<PrincipalStrain>,
}

impl ElementStrains {
    /// Strains of every tet of `mesh` (rest positions) at positions `x`
    /// (parallel over tets; each entry depends on its tet only, so the
    /// result is the same for any thread count).
    pub fn compute(mesh: &TetMesh, x: &[Vec3]) -> ElementStrains {
        let tets = mesh
            .tets
            .par_iter()
            .map(|tet| PrincipalStrain::of(deformation_gradient(&mesh.positions, x, tet)))
            .collect();
        ElementStrains { tets }
    }

    /// Number of inverted tets.
    pub fn inverted(&self) -> usize {
        self.tets.iter().filter(|s| s.inverted()).count()
    }
}

/// `F = Ds·Dm⁻¹` of `tet` from rest positions `rest` to `x` (the rest tet is
/// non-degenerate: the mesh validation guarantees it).
pub fn deformation_gradient(rest: &[Vec3], x: &[Vec3], tet: &[usize; 4]) -> Matrix3<f64> {
    let edges = |p: &[Vec3]| {
        Matrix3::from_columns(&[
            p[tet[1]] - p[tet[0]],
            p[tet[2]] - p[tet[0]],
            p[tet[3]] - p[tet[0]],
        ])
    };
    let dm_inv = edges(rest).try_inverse().unwrap_or_else(Matrix3::zeros);
    edges(x) * dm_inv
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Rotation3;

    #[test]
    fn stretch_along_rotated_axes() {
        let axes = Rotation3::from_euler_angles(0.3, -0.2, 0.7).into_inner();
        let spin = Rotation3::from_euler_angles(-0.5, 0.1, 0.2).into_inner();
        let stretch = Vector3::new(1.4, 1.1, 0.7);
        let f = spin * axes * Matrix3::from_diagonal(&stretch) * axes.transpose();
        let s = PrincipalStrain::of(f);
        assert!((s.stretch - stretch).norm() < 1e-12, "{}", s.stretch);
        for k in 0..3 {
            // Directions up to sign.
            let rest = s.rest_axes.column(k).dot(&axes.column(k)).abs();
            let deformed = s
                .deformed_axes
                .column(k)
                .dot(&(spin * axes).column(k))
                .abs();
            assert!((rest - 1.0).abs() < 1e-12 && (deformed - 1.0).abs() < 1e-12);
        }
        assert!((s.biot() - Vector3::new(0.4, 0.1, -0.3)).norm() < 1e-12);
        assert!((s.green()[0] - 0.48).abs() < 1e-12);
        assert!((s.volume_ratio() - f.determinant()).abs() < 1e-12);
        assert!(!s.inverted());
        let inverted = PrincipalStrain::of(Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, -0.2)));
        assert!(inverted.inverted() && (inverted.volume_ratio() + 0.2).abs() < 1e-15);
    }
}
