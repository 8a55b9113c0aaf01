//! FEM verification: patch test, rigid motion, caliper stretch (exact
//! homogeneous solution), inversion recovery, determinism.

use crate::common;
use crate::common::patch_3k;

use nalgebra::{Matrix3, Rotation3, Vector3};
use skinpatch::fem::boundary::{
    BottomCondition, BoundaryConditions, Caliper, Keyframes, NodeSets, SideCondition,
};
use skinpatch::fem::simulation::Simulation;
use skinpatch::fem::solve::Filter;
use skinpatch::fem::{Corotation, Material, Model, TangentKind, Volumetric};
use skinpatch::mesh::Vec3;

fn skin(region: i32) -> Material {
    let kpa = if region == 1 { 150.0 } else { 15.0 };
    Material::from_scenario_units("test", kpa, 0.45, 1100.0).unwrap()
}

fn tight(sim: &mut Simulation) {
    sim.settings.rel_tol = 1e-11;
    sim.settings.cg.rel_tol = 1e-12;
    sim.settings.max_iterations = 30;
}

/// Prescribes `x = A X + c` on every boundary node and checks that every tet
/// ends with F = A, for each energy density and volume measure (the
/// locking-free one at ν = 0.48 and 0.4999).
fn patch_test(a: Matrix3<f64>) {
    for model in [
        Model::Corotational,
        Model::StableNeoHookean,
        Model::NeoHookean,
    ] {
        for (volumetric, nu) in [
            (Volumetric::Standard, 0.45),
            (Volumetric::LockingFree, 0.48),
            (Volumetric::LockingFree, 0.4999),
        ] {
            let m = Material::with_volumetric("test", 150.0, nu, 1100.0, volumetric).unwrap();
            patch_test_with(a, m.with_model(model));
        }
    }
}

fn patch_test_with(a: Matrix3<f64>, material: Material) {
    let _ = env_logger::builder().is_test(true).try_init();
    let mesh = patch_3k();
    let model = (material.model, material.volumetric, material.poisson);
    let material = vec![material; mesh.num_tets()];
    let mut sim = Simulation::new(&mesh, &material);
    tight(&mut sim);
    let c = Vec3::new(0.3, -0.2, 0.1);
    for f in &mesh.boundary {
        for &v in &f.nodes {
            sim.loads_mut().filters[v] = Filter::Fixed;
            sim.loads_mut().targets[v] = a * mesh.positions[v] + c;
        }
    }
    let stats = sim.solve_static("patch test").unwrap();
    let mut worst: f64 = 0.0;
    for t in 0..mesh.num_tets() {
        worst = worst.max((sim.deformation_gradient(t) - a).abs().max());
    }
    // The solve stops at a residual relative to forces that grow with λ,
    // so the error in F grows with λ/μ (about 5000 at ν = 0.4999).
    let bound = 1e-9 * (material[0].lambda() / (1000.0 * material[0].mu())).max(1.0);
    assert!(
        worst < bound,
        "{model:?}: max |F − A| = {worst:e} after {stats:?}"
    );
}

#[test]
fn patch_test_small_strain() {
    patch_test(Matrix3::new(
        1.01, 0.002, 0.0, -0.003, 0.995, 0.004, 0.001, 0.0, 1.006,
    ));
}

#[test]
fn patch_test_large_strain_with_rotation() {
    let rot = Rotation3::from_euler_angles(0.2, -0.1, 0.4).into_inner();
    patch_test(rot * Matrix3::new(1.2, 0.05, 0.0, 0.0, 0.85, 0.03, 0.02, 0.0, 1.1));
}

#[test]
fn rigid_rotation_by_ninety_degrees_has_no_force_or_strain() {
    let mesh = patch_3k();
    let material: Vec<Material> = mesh.tet_region.iter().map(|&r| skin(r)).collect();
    let mut sim = Simulation::new(&mesh, &material);
    let rot = Rotation3::from_axis_angle(&Vector3::y_axis(), std::f64::consts::FRAC_PI_2);
    for (x, p) in sim.positions_mut().iter_mut().zip(&mesh.positions) {
        *x = rot * p + Vec3::new(1.0, 2.0, 3.0);
    }
    sim.evaluate_forces();
    let fmax = sim
        .internal_forces()
        .iter()
        .map(|f| f.norm())
        .fold(0.0, f64::max);
    assert!(fmax < 1e-14, "max force {fmax:e} N");
    for t in 0..mesh.num_tets() {
        let c = Corotation::of(&sim.deformation_gradient(t));
        for s in c.sigma.iter() {
            assert!((s - 1.0).abs() < 1e-12, "tet {t} stretch {s}");
        }
    }
}

#[test]
fn global_stiffness_is_symmetric_and_forces_balance() {
    let mesh = patch_3k();
    let material: Vec<Material> = mesh.tet_region.iter().map(|&r| skin(r)).collect();
    let mut sim = Simulation::new(&mesh, &material);
    // A smooth, large deformation.
    for (x, p) in sim.positions_mut().iter_mut().zip(&mesh.positions) {
        *x = p + Vec3::new(
            0.2 * (p.y * 0.5).sin(),
            0.1 * p.z * p.x * 0.1,
            -0.3 * (p.x * 0.3).cos(),
        );
    }
    sim.evaluate_forces();
    // Internal forces of a free body sum to zero (no net force).
    let net: Vec3 = sim.internal_forces().iter().sum();
    let scale: f64 = sim.internal_forces().iter().map(|f| f.norm()).sum();
    assert!(net.norm() < 1e-12 * scale, "net force {net}");
    // K equals its transpose entry by entry.
    let k = sim.stiffness(TangentKind::Exact).clone();
    let kt = k.transpose();
    assert_eq!(k.col_indices(), kt.col_indices());
    let biggest = k.values().iter().fold(0.0f64, |m, v| m.max(v.abs()));
    for (a, b) in k.values().iter().zip(kt.values()) {
        assert!((a - b).abs() <= 1e-12 * biggest, "{a} vs {b}");
    }
}

/// Stretches the patch along x to `s` between frictionless jaws, the
/// bottom and the y sides on rollers and the top free, in `steps` equal
/// load steps solved to equilibrium.
fn caliper_stretch(sim: &mut Simulation, mesh: &skinpatch::mesh::TetMesh, s: f64, steps: usize) {
    let bc = BoundaryConditions {
        bottom: BottomCondition::Rollers,
        sides: SideCondition::Rollers,
        caliper: Some(Caliper {
            axis: 0,
            stretch: Keyframes {
                points: vec![(0.0, 1.0), (1.0, s)],
            },
        }),
        prescribed: vec![],
    };
    let sets = NodeSets::of(mesh);
    for step in 1..=steps {
        let (filters, targets) = bc.constraints(&sets, &mesh.positions, step as f64 / steps as f64);
        sim.set_constraints(filters, targets);
        sim.solve_static("caliper").unwrap();
    }
}

/// Caliper stretch 1.2 with a free top, bottom on rollers and the y sides on
/// rollers: F = diag(1.2, 1, λ_z) exactly, so every tet's largest principal
/// stretch is 1.2 along x.
#[test]
fn caliper_stretch_is_homogeneous() {
    let mesh = patch_3k();
    let material: Vec<Material> = mesh.tet_region.iter().map(|&r| skin(r)).collect();
    let mut sim = Simulation::new(&mesh, &material);
    tight(&mut sim);
    caliper_stretch(&mut sim, &mesh, 1.2, 1);
    for (t, m) in material.iter().enumerate() {
        let c = Corotation::of(&sim.deformation_gradient(t));
        let k = c.sigma.imax();
        assert!(
            (c.sigma[k] - 1.2).abs() < 1e-6,
            "tet {t}: largest stretch {}",
            c.sigma[k]
        );
        let dir = c.v.column(k);
        assert!(dir.x.abs() > 1.0 - 1e-6, "tet {t}: direction {dir}");
        // Lateral stretches: 1 across y, λ_z = 1 − λ(s − 1)/(λ + 2μ) through the thickness.
        let lz = 1.0 - m.lambda() * 0.2 / (m.lambda() + 2.0 * m.mu());
        let f = sim.deformation_gradient(t);
        assert!(
            (f[(1, 1)] - 1.0).abs() < 1e-6 && (f[(2, 2)] - lz).abs() < 1e-6,
            "tet {t}: F = {f}"
        );
    }
}

/// The same caliper with the stable Neo-Hookean energy, to 1.5: F =
/// diag(s, 1, t) with the through-thickness stretch that frees the top,
/// `t = (κ + μ)/(κ s + μ/s)`, and the Cauchy stress `σ_xx = (μ s + c t) s/J`
/// (`c = κ(J − 1) − μ`, `J = s t`), the other normal stresses `σ_zz = 0`
/// and `σ_yy = (μ + c s t)/J`, in every tet to 1e-6.
#[test]
fn neo_hookean_caliper_stretch_matches_the_closed_form() {
    let mesh = patch_3k();
    let material: Vec<Material> = mesh
        .tet_region
        .iter()
        .map(|&r| skin(r).with_model(Model::StableNeoHookean))
        .collect();
    let mut sim = Simulation::new(&mesh, &material);
    tight(&mut sim);
    let s = 1.5;
    // In load steps, as a run would: 1.5 in one step is beyond Newton's reach
    // from rest.
    caliper_stretch(&mut sim, &mesh, s, 5);
    let x = sim.positions().to_vec();
    let stresses = skinpatch::strain::element_stresses(&mesh, &x, &material);
    for (t, m) in material.iter().enumerate() {
        let (mu, kappa) = (m.mu(), m.lambda() + m.mu());
        let lz = (kappa + mu) / (kappa * s + mu / s);
        let j = s * lz;
        let c = kappa * (j - 1.0) - mu;
        let f = sim.deformation_gradient(t);
        let expected_f = Matrix3::from_diagonal(&Vector3::new(s, 1.0, lz));
        assert!((f - expected_f).abs().max() < 1e-6, "tet {t}: F = {f}");
        let sigma = stresses[t].cauchy;
        let sxx = (mu * s + c * lz) * s / j;
        let syy = (mu + c * s * lz) / j;
        assert!(
            (sigma[(0, 0)] - sxx).abs() < 1e-6 * sxx,
            "tet {t}: {sigma} vs {sxx}"
        );
        assert!(
            (sigma[(1, 1)] - syy).abs() < 1e-6 * sxx,
            "tet {t}: {sigma} vs {syy}"
        );
        assert!(sigma[(2, 2)].abs() < 1e-6 * sxx, "tet {t}: {sigma}");
    }
    // Beyond small strain the two laws part: the linear law's thickness.
    let linear =
        1.0 - material[0].lambda() * (s - 1.0) / (material[0].lambda() + 2.0 * material[0].mu());
    let m = &material[0];
    let lz = (m.lambda() + 2.0 * m.mu()) / ((m.lambda() + m.mu()) * s + m.mu() / s);
    assert!((lz - linear).abs() > 0.05, "{lz} vs {linear}");
}

/// A caliper stretch of 1.2 at ν = 0.499 with the locking-free corotational
/// tet: F = diag(s, 1, t) in every tet with the thickness of its energy,
/// `μ Σ(σ − 1)² + λ_e/2 (Σσ − 3)² + λ_n/2 (J − 1)²` (λ_e the element's
/// share of λ, λ_n the nodes'), `t = (2μ + λ_e(2 − s) + λ_n s)/(2μ + λ_e +
/// λ_n s²)`, to 1e-6, and the volume ratio J = s t within 1e-3 of an
/// incompressible material's 1.
#[test]
fn locking_free_caliper_keeps_the_volume_at_0_499() {
    let mesh = patch_3k();
    let material: Vec<Material> = mesh
        .tet_region
        .iter()
        .map(|&r| {
            let kpa = if r == 1 { 150.0 } else { 15.0 };
            Material::with_volumetric("test", kpa, 0.499, 1100.0, Volumetric::LockingFree).unwrap()
        })
        .collect();
    let mut sim = Simulation::new(&mesh, &material);
    tight(&mut sim);
    let s = 1.2;
    caliper_stretch(&mut sim, &mesh, s, 2);
    for (t, m) in material.iter().enumerate() {
        let (mu, le, ln) = (m.mu(), m.element_lambda(), m.nodal_bulk());
        let lz = (2.0 * mu + le * (2.0 - s) + ln * s) / (2.0 * mu + le + ln * s * s);
        let f = sim.deformation_gradient(t);
        let expected = Matrix3::from_diagonal(&Vector3::new(s, 1.0, lz));
        assert!((f - expected).abs().max() < 1e-6, "tet {t}: F = {f}");
        assert!(
            (f.determinant() - 1.0).abs() < 1e-3,
            "tet {t}: J = {}",
            f.determinant()
        );
    }
}

/// Simple shear `x = X + γ Z e_x` prescribed on the whole boundary of the
/// patch, raised to γ = 1 in five steps, with the stable Neo-Hookean energy
/// (standard at ν = 0.45 and locking-free at 0.499): J = 1, so the pressure
/// term vanishes and the Cauchy stress is `μ(B − I)` — shear `σ_xz = μγ`,
/// normal `σ_xx = μγ²` (the Poynting effect the linear law lacks), every
/// other component 0 — in every tet to 1e-6 of μγ.
#[test]
fn neo_hookean_simple_shear_matches_the_closed_form() {
    let mesh = patch_3k();
    let (lo, _) = mesh.bounds();
    for (volumetric, nu) in [
        (Volumetric::Standard, 0.45),
        (Volumetric::LockingFree, 0.499),
    ] {
        let m = Material::with_volumetric("test", 150.0, nu, 1100.0, volumetric)
            .unwrap()
            .with_model(Model::StableNeoHookean);
        let material = vec![m; mesh.num_tets()];
        let mut sim = Simulation::new(&mesh, &material);
        tight(&mut sim);
        for step in 1..=5 {
            let gamma = 0.2 * step as f64;
            let a = Matrix3::new(1.0, 0.0, gamma, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0);
            for f in &mesh.boundary {
                for &v in &f.nodes {
                    sim.loads_mut().filters[v] = Filter::Fixed;
                    sim.loads_mut().targets[v] = a * (mesh.positions[v] - lo) + lo;
                }
            }
            sim.solve_static("simple shear").unwrap();
            let x = sim.positions().to_vec();
            let stresses = skinpatch::strain::element_stresses(&mesh, &x, &material);
            let mu = m.mu();
            let expected = mu * (a * a.transpose() - Matrix3::identity());
            assert!((expected[(0, 2)] - mu * gamma).abs() < 1e-12 * mu);
            assert!((expected[(0, 0)] - mu * gamma * gamma).abs() < 1e-12 * mu);
            for (t, stress) in stresses.iter().enumerate() {
                let f = sim.deformation_gradient(t);
                assert!(
                    (f - a).abs().max() < 1e-6,
                    "{volumetric:?}, γ {gamma}: tet {t}: F = {f}"
                );
                let sigma = stress.cauchy;
                assert!(
                    (sigma - expected).abs().max() < 1e-6 * mu * gamma,
                    "{volumetric:?}, γ {gamma}: tet {t}: σ = {sigma}, expected {expected}"
                );
            }
        }
    }
}

/// Confined compression at ν = 0.499 with the locking-free tet, both
/// models: the bottom fixed, the sides on rollers and the top pressed 5%
/// down as a bonded plate. The exact solution is homogeneous, F =
/// diag(1, 1, s), J = s = 0.95 in every tet (to 1e-9, well inside the 1e-3
/// asked of an incompressible material's volume), with the axial stress of
/// the whole bulk modulus `σ_zz = (λ + 2μ)(s − 1)` to 1e-6 — 500 times the
/// shear modulus, which no locking-free split may lose.
#[test]
fn locking_free_confined_compression_is_exact_at_0_499() {
    use skinpatch::fem::boundary::{NodeSet, Prescribed};
    let mesh = patch_3k();
    let sets = NodeSets::of(&mesh);
    let (lo, hi) = mesh.bounds();
    let s = 0.95;
    let bc = BoundaryConditions {
        bottom: BottomCondition::Fixed,
        sides: SideCondition::Rollers,
        caliper: None,
        prescribed: vec![Prescribed {
            name: "top".into(),
            nodes: sets.get(NodeSet::Top).to_vec(),
            displacement: Keyframes {
                points: vec![
                    (0.0, Vector3::zeros()),
                    (1.0, Vector3::new(0.0, 0.0, (s - 1.0) * (hi.z - lo.z))),
                ],
            },
        }],
    };
    for model in [Model::Corotational, Model::StableNeoHookean] {
        let m = Material::with_volumetric("test", 150.0, 0.499, 1100.0, Volumetric::LockingFree)
            .unwrap()
            .with_model(model);
        let material = vec![m; mesh.num_tets()];
        let mut sim = Simulation::new(&mesh, &material);
        tight(&mut sim);
        for step in 1..=2 {
            let (filters, targets) = bc.constraints(&sets, &mesh.positions, step as f64 / 2.0);
            sim.set_constraints(filters, targets);
            sim.solve_static("confined compression").unwrap();
        }
        let x = sim.positions().to_vec();
        let stresses = skinpatch::strain::element_stresses(&mesh, &x, &material);
        let expected = Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, s));
        let szz = (m.lambda() + 2.0 * m.mu()) * (s - 1.0);
        assert!(szz.abs() > 25.0 * m.mu());
        for (t, stress) in stresses.iter().enumerate() {
            let f = sim.deformation_gradient(t);
            assert!(
                (f - expected).abs().max() < 1e-9,
                "{model:?}: tet {t}: F = {f}"
            );
            assert!((f.determinant() - s).abs() < 1e-9);
            let sigma = stress.cauchy;
            assert!(
                (sigma[(2, 2)] - szz).abs() < 1e-6 * szz.abs(),
                "{model:?}: tet {t}: σ = {sigma}, expected σ_zz {szz}"
            );
        }
    }
}

/// One tet with three vertices fixed and the fourth pushed through the
/// opposite face (inverted, and counted as such) returns to rest when
/// released.
#[test]
fn inverted_element_recovers() {
    let _ = env_logger::builder().is_test(true).try_init();
    let mesh = common::one_tet();
    let rest = mesh.positions.clone();
    let mut sim = Simulation::new(&mesh, &[skin(1)]);
    tight(&mut sim);
    for v in 0..3 {
        sim.loads_mut().filters[v] = Filter::Fixed;
    }
    sim.positions_mut()[3] = Vec3::new(0.2, 0.1, 0.6);
    let j = sim.deformation_gradient(0).determinant();
    assert!(j < 0.0);
    let inversion = sim.inversion();
    assert_eq!((inversion.inverted, inversion.min_volume_ratio), (1, j));
    sim.solve_static("release").unwrap();
    let inversion = sim.inversion();
    assert_eq!(inversion.inverted, 0);
    assert!((inversion.min_volume_ratio - 1.0).abs() < 1e-9);
    assert!(
        (sim.positions()[3] - rest[3]).norm() < 1e-9,
        "vertex ended at {}",
        sim.positions()[3]
    );
}

#[test]
fn static_solves_are_deterministic() {
    let mesh = patch_3k();
    let material: Vec<Material> = mesh.tet_region.iter().map(|&r| skin(r)).collect();
    let run = || {
        let mut sim = Simulation::new(&mesh, &material);
        let bc = BoundaryConditions {
            bottom: BottomCondition::Fixed,
            sides: SideCondition::Free,
            caliper: Some(Caliper {
                axis: 1,
                stretch: Keyframes {
                    points: vec![(0.0, 0.85)],
                },
            }),
            prescribed: vec![],
        };
        let (f, t) = bc.constraints(&NodeSets::of(&mesh), &mesh.positions, 0.0);
        sim.set_constraints(f, t);
        sim.solve_static("compress").unwrap();
        sim.positions()
            .iter()
            .flat_map(|p| p.iter().map(|c| c.to_bits()).collect::<Vec<_>>())
            .collect::<Vec<u64>>()
    };
    let a = run();
    let b = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap()
        .install(run);
    assert_eq!(a, b);
}

/// Backward Euler on one tet: released from a stretched state, the free
/// apex overshoots its rest position (inertia) when undamped, and creeps back
/// without overshoot when heavily mass-damped.
#[test]
fn implicit_euler_has_inertia_and_damping() {
    use skinpatch::fem::simulation::Dynamics;
    let mesh = common::one_tet();
    let run = |alpha: f64| -> (f64, f64) {
        let mut sim = Simulation::new(&mesh, &[skin(1)]);
        tight(&mut sim);
        for v in 0..3 {
            sim.loads_mut().filters[v] = Filter::Fixed;
        }
        let apex = (0..4).find(|&v| mesh.positions[v].z < 0.0).unwrap();
        // Period of the apex's vertical oscillation: 2π √(m/k).
        let k = sim.stiffness(TangentKind::Exact).clone();
        let kzz = nalgebra::DMatrix::from(&k)[(3 * apex + 2, 3 * apex + 2)];
        let period = 2.0 * std::f64::consts::PI * (sim.body().mass[apex] / kzz).sqrt();
        sim.dynamics = Some(Dynamics {
            dt: period / 100.0,
            alpha,
            beta: 0.0,
        });
        sim.positions_mut()[apex].z = -1.2;
        let (mut highest, mut lowest_after) = (f64::NEG_INFINITY, f64::INFINITY);
        for step in 0..100 {
            sim.begin_step();
            sim.solve_static("step").unwrap();
            sim.end_step();
            highest = highest.max(sim.positions()[apex].z);
            if step > 50 {
                lowest_after = lowest_after.min(sim.positions()[apex].z);
            }
        }
        (highest, lowest_after)
    };
    let (undamped_top, _) = run(0.0);
    assert!(
        undamped_top > -0.9,
        "undamped apex reached {undamped_top}, expected past rest (−1)"
    );
    let (damped_top, _) = run(1e5);
    assert!(damped_top < -1.0 + 1e-9, "damped apex reached {damped_top}");
}

/// Slow loading: backward-Euler frames agree with quasi-static ones.
#[test]
fn implicit_euler_approaches_quasi_static_for_slow_loading() {
    let run = |extra: &str| {
        let (summary, _dir) = common::run_fixture("press_small.toml", |t| {
            t.replace("[time]", &format!("[time]\n{extra}"))
                .replace("[time]", "[output]\nframes_vtu = false\n\n[time]")
        });
        summary.frames
    };
    let quasi = run("");
    let dynamic = run("integrator = \"implicit-euler\"\ndamping_alpha_per_s = 10.0");
    for (q, d) in quasi.iter().zip(&dynamic).skip(1) {
        let (fq, fd) = (q.probe_force_n[2], d.probe_force_n[2]);
        assert!(
            (fq - fd).abs() < 0.02 * fq,
            "frame {}: {fq} vs {fd}",
            q.frame
        );
    }
}
