//! Probe contact: penetration bound, force balance, friction behaviour.

mod common;

use nalgebra::Vector3;
use skinpatch::fem::boundary::{
    BottomCondition, BoundaryConditions, Keyframes, NodeSets, SideCondition,
};
use skinpatch::fem::contact::{solve_with_contact, ContactMode, ContactState, Probe, ProbeShape};
use skinpatch::fem::integrate::Simulation;
use skinpatch::fem::Material;
use skinpatch::mesh::{io, TetMesh, Vec3};

fn patch_25k() -> TetMesh {
    io::read_tetgen(&common::root().join("meshes/patch_25k")).unwrap()
}

struct Rig {
    mesh: TetMesh,
    sim: Simulation,
    base: (Vec<skinpatch::fem::solve::Filter>, Vec<Vec3>, Vec<Vec3>),
    state: ContactState,
}

fn rig(mesh: TetMesh, bottom: BottomCondition, sides: SideCondition) -> Rig {
    let material: Vec<Material> = mesh
        .tet_region
        .iter()
        .map(|&r| {
            Material::from_scenario_units("t", if r == 1 { 150.0 } else { 15.0 }, 0.45, 1100.0)
                .unwrap()
        })
        .collect();
    let sim = Simulation::new(&mesh, &material);
    let sets = NodeSets::of(&mesh);
    let bc = BoundaryConditions {
        bottom,
        sides,
        caliper: None,
        prescribed: vec![],
    };
    let (f, t) = bc.constraints(&sets, &mesh.positions, 0.0);
    let sides_all: Vec<usize> = sets.sides.iter().flatten().copied().collect();
    let state = ContactState::new(&mesh, &sides_all);
    let n = mesh.num_vertices();
    Rig {
        mesh,
        sim,
        base: (f, t, vec![Vec3::zeros(); n]),
        state,
    }
}

fn sphere(path: Vec<(f64, Vector3<f64>)>, mode: ContactMode) -> Probe {
    Probe {
        shape: ProbeShape::Sphere { radius_mm: 1.5 },
        path: Keyframes { points: path },
        axis: Keyframes {
            points: vec![(0.0, Vector3::x())],
        },
        mode,
    }
}

#[test]
fn press_balances_forces_and_respects_penetration_bound() {
    let _ = env_logger::builder().is_test(true).try_init();
    let mut r = rig(patch_25k(), BottomCondition::Fixed, SideCondition::Rollers);
    let probe = sphere(
        vec![
            (0.0, Vector3::new(0.0, 0.0, 1.5)),
            (1.0, Vector3::new(0.0, 0.0, 1.0)),
        ],
        ContactMode::Frictionless,
    );
    let mut last = None;
    for k in 1..=4 {
        let t = k as f64 / 4.0;
        let pose = probe.pose(t);
        let rep = solve_with_contact(
            &mut r.sim,
            (&r.base.0, &r.base.1, &r.base.2),
            &pose,
            probe.mode,
            &mut r.state,
            &format!("step {k}"),
        )
        .unwrap();
        assert!(rep.max_penetration_ratio <= 0.01, "{rep:?}");
        last = Some(rep);
    }
    let rep = last.unwrap();
    assert!(rep.contact_nodes >= 3, "{rep:?}");
    // The probe is pushed up; frictionless and centred: no tangential force.
    assert!(rep.probe_force.z > 0.0);
    let tangential = (rep.probe_force.x.powi(2) + rep.probe_force.y.powi(2)).sqrt();
    assert!(tangential < 0.02 * rep.probe_force.z, "{rep:?}");
    // Probe force equals the total support reaction.
    let contact: std::collections::HashSet<usize> = r.state.active.keys().copied().collect();
    let support: Vec3 = (0..r.mesh.num_vertices())
        .filter(|v| !contact.contains(v))
        .map(|v| -r.sim.internal_forces()[v])
        .sum();
    assert!(
        (support - rep.probe_force).norm() < 1e-4 * rep.probe_force.norm(),
        "{support} vs {}",
        rep.probe_force
    );
    println!("{rep:?}");
}

/// A probe pushed to 60% of the patch thickness: no NaN, no crash, a force
/// that grows with depth, and penetration within 1.5% of the local size.
#[test]
fn deep_press_is_robust() {
    let path = common::root().join("tests/fixtures/deep_press.toml");
    let mut setup = skinpatch::scenario::Setup::load(&path).unwrap();
    let dir = tempfile::tempdir().unwrap();
    setup.output_dir = dir.path().to_path_buf();
    let summary = skinpatch::pipeline::run(&setup, |_, _| {}).unwrap();
    let forces: Vec<f64> = summary.frames.iter().map(|m| m.probe_force_n[2]).collect();
    assert_eq!(forces.len(), 11);
    for w in forces.windows(2) {
        assert!(w[1].is_finite() && w[1] > w[0], "{forces:?}");
    }
    for m in &summary.frames {
        assert!(m.max_penetration_mm <= 0.015, "{m:?}");
    }
}
