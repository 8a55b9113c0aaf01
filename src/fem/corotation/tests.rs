//! Unit tests of the element: forces, energy, tangents, rotations.

use super::*;
use nalgebra::Rotation3;

fn material() -> Material {
    Material {
        youngs_mpa: 0.15,
        poisson: 0.45,
        density_t_mm3: 1.1e-9,
        model: Default::default(),
        volumetric: Default::default(),
    }
}

fn rest_tet() -> [Vec3; 4] {
    [
        Vec3::new(0.1, -0.2, 0.0),
        Vec3::new(1.3, 0.1, -0.1),
        Vec3::new(0.2, 0.9, 0.2),
        Vec3::new(0.3, 0.2, 1.1),
    ]
}

fn element() -> RestElement {
    RestElement::new(rest_tet(), &material())
}

fn deform(f: &Matrix3<f64>, t: Vec3) -> [Vec3; 4] {
    rest_tet().map(|p| f * p + t)
}

#[test]
fn rest_stiffness_is_symmetric_and_kills_rigid_translation() {
    let e = element();
    for a in 0..4 {
        let mut row = Matrix3::zeros();
        for b in 0..4 {
            assert!((e.k0(a, b) - e.k0(b, a).transpose()).norm() < 1e-15);
            row += e.k0(a, b);
        }
        assert!(row.norm() < 1e-14, "row {a} sums to {row}");
    }
}

#[test]
fn rigid_rotation_gives_zero_force_and_unit_stretches() {
    let e = element();
    let rot = Rotation3::from_euler_angles(0.0, 0.0, std::f64::consts::FRAC_PI_2);
    let x = deform(rot.matrix(), Vec3::new(3.0, -1.0, 2.0));
    let c = Corotation::of(&e.deformation_gradient(&x));
    assert!((c.r - rot.matrix()).norm() < 1e-12);
    for s in c.sigma.iter() {
        assert!((s - 1.0).abs() < 1e-12);
    }
    for f in e.forces(&x, &c.r) {
        assert!(f.norm() < 1e-14, "force {f}");
    }
    assert!(e.energy(&x).abs() < 1e-28);
}

/// The stress form of the forces equals the rest-stiffness form to
/// round-off, stretched, sheared, rotated and inverted.
#[test]
fn stress_forces_match_the_rest_stiffness_forces() {
    let e = element();
    let rot = Rotation3::from_euler_angles(0.3, -0.7, 1.1);
    let cases = [
        Matrix3::new(1.1, 0.2, -0.1, 0.05, 0.9, 0.15, -0.2, 0.1, 1.2),
        rot.matrix() * Matrix3::new(0.6, 0.1, 0.0, 0.0, 1.3, 0.2, 0.1, 0.0, 0.8),
        Matrix3::new(1.0, 0.1, 0.0, 0.0, 1.0, 0.2, 0.1, 0.0, -0.4),
    ];
    for f in cases {
        let x = deform(&f, Vec3::new(0.3, 0.1, -0.2));
        let c = Corotation::of(&e.deformation_gradient(&x));
        let a = e.forces(&x, &c.r);
        let b = e.forces_from(&c);
        let scale = a.iter().map(|v| v.norm()).fold(0.0, f64::max);
        for (fa, fb) in a.iter().zip(&b) {
            assert!((fa - fb).norm() <= 1e-12 * scale, "{fa} vs {fb}");
        }
    }
}

/// Started from a nearby rotation (or a poor one), the decomposition
/// is the cold start's to round-off.
#[test]
fn warm_started_rotation_matches_the_cold_start() {
    let rot = Rotation3::from_euler_angles(0.3, -0.7, 1.1);
    let cases = [
        Matrix3::new(1.1, 0.2, -0.1, 0.05, 0.9, 0.15, -0.2, 0.1, 1.2),
        rot.matrix() * Matrix3::new(0.6, 0.1, 0.0, 0.0, 1.3, 0.2, 0.1, 0.0, 0.8),
        Matrix3::new(1.0, 0.1, 0.0, 0.0, 1.0, 0.2, 0.1, 0.0, -0.4),
        Matrix3::identity(),
    ];
    for f in cases {
        let cold = Corotation::of(&f);
        let nudged =
            Corotation::of(&(f * Matrix3::new(1.0, 1e-3, 0.0, 0.0, 1.0, -2e-3, 0.0, 0.0, 1.0)));
        for guess in [nudged.v, *rot.matrix(), Matrix3::identity() * 1.0000001] {
            let warm = Corotation::near(&f, &guess);
            assert!((warm.r - cold.r).norm() < 1e-12, "{f}");
            assert!((warm.sigma - cold.sigma).norm() < 1e-12, "{f}");
            assert!(
                (warm.u * Matrix3::from_diagonal(&warm.sigma) * warm.v.transpose() - f).norm()
                    < 1e-12
            );
        }
    }
}

/// The 10 upper blocks are the blocks, and the lower ones their
/// transposes to round-off (the tangent is symmetric).
#[test]
fn upper_blocks_hold_the_whole_symmetric_tangent() {
    let e = element();
    let f = Matrix3::new(0.8, 0.2, -0.1, 0.05, 0.7, 0.15, -0.2, 0.1, 0.9);
    let x = deform(&f, Vec3::zeros());
    for kind in [TangentKind::Exact, TangentKind::Projected] {
        let t = e.tangent(&Corotation::of(&e.deformation_gradient(&x)), kind);
        let upper = t.upper_blocks(2.0);
        for a in 0..4 {
            for b in 0..4 {
                let k = t.block(a, b) * 2.0;
                let (lo, hi) = (a.min(b), a.max(b));
                let stored = if a <= b {
                    upper[UPPER[lo][hi]]
                } else {
                    upper[UPPER[lo][hi]].transpose()
                };
                assert!(
                    (k - stored).norm() <= 1e-13 * k.norm().max(1e-300),
                    "{a}{b}"
                );
            }
        }
    }
}

fn neo_hookean() -> RestElement {
    RestElement::new(
        rest_tet(),
        &material().with_model(super::super::hyperelastic::Model::StableNeoHookean),
    )
}

/// The stable Neo-Hookean element: at rest its tangent is the
/// corotational rest stiffness (the same small-strain limit); stretched,
/// compressed or inverted its exact tangent is the force derivative; its
/// projected tangent is positive semi-definite, finite, and the exact one
/// where no mode needs clamping (a mild deformation).
#[test]
fn neo_hookean_element_tangent() {
    let e = neo_hookean();
    assert_rest_tangent_is_k0(&e);
    let stretched = Matrix3::new(1.3, 0.1, 0.0, 0.05, 1.1, 0.1, 0.0, -0.1, 1.2);
    let compressed = Matrix3::new(0.5, 0.1, 0.0, 0.0, 0.6, 0.1, 0.1, 0.0, 0.4);
    let inverted = Matrix3::new(1.0, 0.1, 0.0, 0.0, 1.0, 0.2, 0.1, 0.0, -0.4);
    for f in [stretched, compressed, inverted] {
        assert_element_tangent_is_force_derivative(&e, f, TangentKind::Exact);
        let k = stiffness(&e, &deform(&f, Vec3::zeros()), TangentKind::Projected);
        assert!(k.iter().all(|v| v.is_finite()));
        assert!(k.symmetric_eigenvalues().min() > -1e-10 * k.norm());
        // Each of these has a mode the projection clamps.
        let exact = stiffness(&e, &deform(&f, Vec3::zeros()), TangentKind::Exact);
        assert!(
            exact.symmetric_eigenvalues().min() < -1e-6 * exact.norm(),
            "{f}"
        );
    }
    let mild = Matrix3::new(1.02, 0.01, 0.0, 0.0, 0.99, 0.01, 0.01, 0.0, 1.01);
    assert_element_tangent_is_force_derivative(&e, mild, TangentKind::Projected);
}

/// The exact tangent at rest is the corotational rest stiffness `K0` (the
/// same small-strain limit).
fn assert_rest_tangent_is_k0(e: &RestElement) {
    let t = e.tangent(&Corotation::of(&Matrix3::identity()), TangentKind::Exact);
    for a in 0..4 {
        for b in 0..4 {
            assert!((t.block(a, b) - e.k0(a, b)).norm() < 1e-14 * e.k0(a, b).norm().max(1e-3));
        }
    }
}

/// The Neo-Hookean element with the logarithmic volume term: at rest the
/// corotational rest stiffness, stretched or compressed its exact tangent
/// the force derivative (it is not defined inverted).
#[test]
fn log_neo_hookean_element_tangent() {
    let e = RestElement::new(
        rest_tet(),
        &material().with_model(super::super::hyperelastic::Model::NeoHookean),
    );
    assert_rest_tangent_is_k0(&e);
    let stretched = Matrix3::new(1.3, 0.1, 0.0, 0.05, 1.1, 0.1, 0.0, -0.1, 1.2);
    let compressed = Matrix3::new(0.5, 0.1, 0.0, 0.0, 0.6, 0.1, 0.1, 0.0, 0.4);
    for f in [stretched, compressed] {
        assert_element_tangent_is_force_derivative(&e, f, TangentKind::Exact);
    }
}

#[test]
fn forces_are_minus_the_energy_gradient() {
    for e in [element(), neo_hookean()] {
        assert_forces_are_minus_the_energy_gradient(&e);
    }
}

fn assert_forces_are_minus_the_energy_gradient(e: &RestElement) {
    let f = Matrix3::new(1.1, 0.2, -0.1, 0.05, 0.9, 0.15, -0.2, 0.1, 1.2);
    // Also an inverted configuration (det F < 0).
    let inverted = Matrix3::new(1.0, 0.1, 0.0, 0.0, 1.0, 0.2, 0.1, 0.0, -0.4);
    for f in [f, inverted] {
        let x = deform(&f, Vec3::new(0.3, 0.1, -0.2));
        let c = Corotation::of(&e.deformation_gradient(&x));
        let forces = e.forces(&x, &c.r);
        let h = 1e-6;
        for a in 0..4 {
            for k in 0..3 {
                let (mut xp, mut xm) = (x, x);
                xp[a][k] += h;
                xm[a][k] -= h;
                let grad = (e.energy(&xp) - e.energy(&xm)) / (2.0 * h);
                let scale = forces.iter().map(|v| v.norm()).fold(0.0, f64::max);
                assert!(
                    (forces[a][k] + grad).abs() < 1e-7 * scale,
                    "vertex {a} axis {k}: force {} vs −∂Ψ {}",
                    forces[a][k],
                    -grad
                );
            }
        }
    }
}

fn stiffness(e: &RestElement, x: &[Vec3; 4], kind: TangentKind) -> nalgebra::SMatrix<f64, 12, 12> {
    let t = e.tangent(&Corotation::of(&e.deformation_gradient(x)), kind);
    let mut k = nalgebra::SMatrix::<f64, 12, 12>::zeros();
    for a in 0..4 {
        for b in 0..4 {
            k.fixed_view_mut::<3, 3>(3 * a, 3 * b)
                .copy_from(&t.block(a, b));
        }
    }
    k
}

#[test]
fn tangent_at_rest_is_the_rest_stiffness() {
    let e = element();
    for kind in [TangentKind::Exact, TangentKind::Projected] {
        let t = e.tangent(&Corotation::of(&Matrix3::identity()), kind);
        for a in 0..4 {
            for b in 0..4 {
                assert!((t.block(a, b) - e.k0(a, b)).norm() < 1e-14, "block {a}{b}");
            }
        }
    }
}

/// Compares the tangent at `F = rot · f` with central differences of the forces.
fn assert_tangent_is_force_derivative(f: Matrix3<f64>, kind: TangentKind) {
    assert_element_tangent_is_force_derivative(&element(), f, kind);
}

fn assert_element_tangent_is_force_derivative(e: &RestElement, f: Matrix3<f64>, kind: TangentKind) {
    let rot = Rotation3::from_euler_angles(0.4, -0.3, 0.9).into_inner();
    let x = deform(&(rot * f), Vec3::new(0.1, 0.2, 0.3));
    let k = stiffness(e, &x, kind);
    let h = 1e-6;
    for b in 0..4 {
        for l in 0..3 {
            let (mut xp, mut xm) = (x, x);
            xp[b][l] += h;
            xm[b][l] -= h;
            let fp = e.forces(&xp, &Corotation::of(&e.deformation_gradient(&xp)).r);
            let fm = e.forces(&xm, &Corotation::of(&e.deformation_gradient(&xm)).r);
            for a in 0..4 {
                for i in 0..3 {
                    let fd = -(fp[a][i] - fm[a][i]) / (2.0 * h);
                    let kv = k[(3 * a + i, 3 * b + l)];
                    assert!(
                        (fd - kv).abs() < 1e-6 * k.norm(),
                        "K[{a}{i},{b}{l}] {kv} vs {fd}"
                    );
                }
            }
        }
    }
    assert!((k - k.transpose()).norm() < 1e-14 * k.norm());
}

#[test]
fn tangent_is_the_force_derivative_under_stretch() {
    // No twist clamping is active when every σ̂_i + σ̂_j is large enough.
    let f = Matrix3::new(1.3, 0.1, 0.0, 0.05, 1.1, 0.1, 0.0, -0.1, 1.2);
    assert_tangent_is_force_derivative(f, TangentKind::Exact);
    assert_tangent_is_force_derivative(f, TangentKind::Projected);
}

#[test]
fn exact_tangent_is_the_force_derivative_under_compression() {
    // Strong compression: the twist eigenvalues are negative here.
    let f = Matrix3::new(0.5, 0.1, 0.0, 0.0, 0.6, 0.1, 0.1, 0.0, 0.4);
    assert_tangent_is_force_derivative(f, TangentKind::Exact);
    let e = element();
    let k = stiffness(&e, &deform(&f, Vec3::zeros()), TangentKind::Exact);
    assert!(
        k.symmetric_eigenvalues().min() < -1e-6 * k.norm(),
        "the exact tangent is indefinite here"
    );
}

#[test]
fn tangent_is_positive_semidefinite_when_compressed_or_inverted() {
    let e = element();
    for f in [
        Matrix3::new(0.5, 0.1, 0.0, 0.0, 0.6, 0.1, 0.1, 0.0, 0.4),
        Matrix3::new(1.0, 0.1, 0.0, 0.0, 1.0, 0.2, 0.1, 0.0, -0.4),
    ] {
        let k = stiffness(&e, &deform(&f, Vec3::zeros()), TangentKind::Projected);
        let eig = k.symmetric_eigenvalues();
        assert!(eig.min() > -1e-12 * k.norm(), "eigenvalues {eig}");
    }
}

#[test]
fn inverted_tet_has_one_negative_stretch_and_rotations() {
    let f = Matrix3::new(1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, -0.5);
    let c = Corotation::of(&f);
    assert!((c.u.determinant() - 1.0).abs() < 1e-12);
    assert!((c.v.determinant() - 1.0).abs() < 1e-12);
    let mut s: Vec<f64> = c.sigma.iter().copied().collect();
    s.sort_by(f64::total_cmp);
    assert_eq!(s.iter().filter(|v| **v < 0.0).count(), 1);
    assert!((s[0] + 0.5).abs() < 1e-12 && (s[1] - 1.0).abs() < 1e-12);
    let back = c.u * nalgebra::Matrix3::from_diagonal(&c.sigma) * c.v.transpose();
    assert!((back - f).norm() < 1e-12);
}

/// The Jacobi SVD against nalgebra's on matrices that stress it: random,
/// rotations, repeated and zero singular values, near-singular,
/// inverted, rank one: `U`, `V` rotations, `U Σ̂ Vᵀ = F`, the same
/// singular values, `σ̂₁ ≥ σ̂₂ ≥ |σ̂₃|` with `σ̂₃` of the sign of `det F`,
/// and for an invertible `F` the polar rotation of `F`.
#[test]
fn jacobi_svd_matches_a_reference_svd() {
    let mut seed = 0x2545_f491_4f6c_dd1d_u64;
    let mut random = || {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        (seed >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
    };
    let rot = Rotation3::from_euler_angles(0.4, -1.1, 2.3).into_inner();
    let mut cases = vec![
        Matrix3::identity(),
        Matrix3::zeros(),
        rot,
        rot * Matrix3::from_diagonal(&Vector3::new(1.2, 1.2, 0.7)) * rot.transpose(),
        Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, -0.5)),
        rot * Matrix3::from_diagonal(&Vector3::new(2.0, 1e-9, 1e-12)),
        Vector3::new(1.0, 2.0, -0.5) * Vector3::new(0.3, -0.1, 0.9).transpose(),
        Matrix3::new(1.0, 0.1, 0.0, 0.0, 1.0, 0.2, 0.1, 0.0, -0.4),
        Matrix3::identity() + Matrix3::from_fn(|i, j| 1e-9 * (i as f64 - j as f64 * 0.7)),
        // Entries of `FᵀF` whose squares overflow and underflow.
        Matrix3::new(1.0, 0.1, 0.0, 0.3, 1.0, 0.2, 0.1, -0.6, 0.4) * 1e80,
        Matrix3::new(1.0, 0.1, 0.0, 0.3, 1.0, 0.2, 0.1, -0.6, 0.4) * 1e-100,
    ];
    for _ in 0..500 {
        cases.push(Matrix3::from_fn(|_, _| random()));
    }
    for f in cases {
        let c = Corotation::of(&f);
        let scale = f.norm().max(1e-300);
        let ortho = |m: &Matrix3<f64>| (m.transpose() * m - Matrix3::identity()).norm();
        assert!(ortho(&c.u) < 1e-12 && ortho(&c.v) < 1e-12, "{f}");
        assert!((c.u.determinant() - 1.0).abs() < 1e-12, "{f}");
        assert!((c.v.determinant() - 1.0).abs() < 1e-12, "{f}");
        let back = c.u * Matrix3::from_diagonal(&c.sigma) * c.v.transpose();
        assert!(
            (back - f).norm() <= 1e-13 * scale,
            "{f}: {}",
            (back - f).norm()
        );
        let s = c.sigma;
        assert!(
            s[0] >= s[1] - 1e-13 * scale && s[1] >= s[2].abs() - 1e-13 * scale,
            "{s}"
        );
        let mut reference: Vec<f64> = f.singular_values().iter().copied().collect();
        reference.sort_by(|a, b| b.total_cmp(a));
        for k in 0..3 {
            assert!(
                (s[k].abs() - reference[k]).abs() <= 1e-12 * scale,
                "{s} vs {reference:?}"
            );
        }
        let det = f.determinant();
        if det.abs() > 1e-6 * scale.powi(3) {
            assert_eq!(s[2] < 0.0, det < 0.0, "{f}");
            if det > 0.0 {
                // Polar rotation: F = R S with S symmetric positive definite.
                let stretch = c.r.transpose() * f;
                assert!(
                    (stretch - stretch.transpose()).norm() < 1e-12 * scale,
                    "{f}"
                );
                assert!(stretch.symmetric_eigenvalues().min() > 0.0, "{f}");
            }
        }
    }
}

/// The size ARCHITECTURE.md states: the force loop streams these, so a
/// field added here is a measured decision, not an accident.
#[test]
fn a_rest_element_is_304_bytes() {
    assert_eq!(std::mem::size_of::<RestElement>(), 304);
}
