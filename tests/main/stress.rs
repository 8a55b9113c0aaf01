//! Stress and contact traction, as a biomechanics user reads them: nodal
//! contact pressure against Hertz's profile and the probe force, element
//! stress and strain energy against the work the probe did.

use crate::common;

use skinpatch::scenario::Setup;

/// One frame's contact and energy, as the run's callback saw them.
struct Seen {
    delta: f64,
    force: [f64; 3],
    /// Per contact node: distance from the probe axis (mm), pressure
    /// (N/mm²), area (mm²), pressure × area × normal (N).
    nodes: Vec<(f64, f64, f64, [f64; 3])>,
    /// Σ ψ V over the tets (N·mm).
    energy: f64,
}

fn hertz_frames(poisson: f64) -> Vec<Seen> {
    let fixture = common::root().join("tests/fixtures/hertz.toml");
    let text = std::fs::read_to_string(&fixture)
        .unwrap()
        .replace("poisson_ratio = 0.3", &format!("poisson_ratio = {poisson}"));
    let scenario = skinpatch::scenario::Scenario::parse(&text, &fixture).unwrap();
    let mut setup = Setup::from_scenario(&scenario, &fixture).unwrap();
    let dir = tempfile::tempdir().unwrap();
    setup.outputs.dir = dir.path().to_path_buf();
    let mut seen = Vec::new();
    skinpatch::pipeline::run(&setup, |frame| {
        let c = frame.contact;
        let volumes: Vec<f64> = (0..frame.mesh.num_tets())
            .map(|t| frame.mesh.tet_volume(t))
            .collect();
        let energy = frame
            .stresses()
            .iter()
            .zip(&volumes)
            .map(|(s, v)| s.energy_density * v)
            .sum();
        seen.push(Seen {
            delta: 0.2 * frame.metrics.time_s,
            force: frame.metrics.probe_force_n,
            nodes: (0..c.nodes.len())
                .map(|k| {
                    let x = frame.positions[c.nodes[k]];
                    let t = c.normal[k] * (c.pressure(k) * c.area_mm2[k]);
                    (
                        x.x.hypot(x.y),
                        c.pressure(k),
                        c.area_mm2[k],
                        [t.x, t.y, t.z],
                    )
                })
                .collect(),
            energy,
        });
    })
    .unwrap();
    seen
}

/// Hertz (frictionless sphere, R = 2 mm, on the E = 100 kPa, ν = 0.3
/// block of `tests/fixtures/hertz.toml`) at δ = 0.05 … 0.2 mm:
///
/// - the nodal tractions (pressure × area × contact normal) sum to the
///   probe force within 1e-6 relative;
/// - the pressure profile, as the contact force over the contact area in
///   rings 0.1a wide, follows p(r) = p0 √(1 − r²/a²) with a = √(Rδ) and
///   p0 = 3F/(2πa²) (F the computed force) within 5% inside 0.8a (the
///   outer ring straddles the edge of the contact and is left out);
/// - the strain energy Σ ψ V equals the probe's work, which for Hertz's
///   F ∝ δ^{3/2} is 0.4 F δ, within 2%.
#[test]
fn hertz_pressure_profile_and_energy() {
    let frames = hertz_frames(0.3);
    let r = 2.0f64;
    let mut report = String::new();
    for f in &frames[1..] {
        let fz = f.force[2];
        let sum: [f64; 3] = [0, 1, 2].map(|c| f.nodes.iter().map(|n| n.3[c]).sum());
        let balance = (0..3)
            .map(|c| (sum[c] + f.force[c]).abs())
            .fold(0.0, f64::max)
            / fz;
        assert!(
            balance < 1e-6,
            "δ {}: tractions {sum:?} vs force {:?}",
            f.delta,
            f.force
        );
        let a = (r * f.delta).sqrt();
        let p0 = 3.0 * fz / (2.0 * std::f64::consts::PI * a * a);
        for ring in 0..8 {
            let (lo, hi) = (ring as f64 * 0.1 * a, (ring + 1) as f64 * 0.1 * a);
            let inside: Vec<_> = f.nodes.iter().filter(|n| n.0 >= lo && n.0 < hi).collect();
            assert!(!inside.is_empty(), "δ {}: no node in ring {ring}", f.delta);
            let force: f64 = inside.iter().map(|n| n.1 * n.2).sum();
            let area: f64 = inside.iter().map(|n| n.2).sum();
            let mid = 0.5 * (lo + hi) / a;
            let hertz = p0 * (1.0 - mid * mid).sqrt();
            let err = force / area / hertz - 1.0;
            report += &format!(
                "δ {:.2} ring {ring}: {:.5} vs {hertz:.5} N/mm² ({:+.1}%)\n",
                f.delta,
                force / area,
                100.0 * err
            );
            assert!(err.abs() < 0.05, "{report}");
        }
        let work = 0.4 * fz * f.delta;
        let err = f.energy / work - 1.0;
        report += &format!(
            "δ {:.2}: energy {:.4e} vs {work:.4e} N·mm ({:+.2}%)\n",
            f.delta,
            f.energy,
            100.0 * err
        );
        assert!(err.abs() < 0.02, "{report}");
    }
    println!("{report}");
}

/// Under Coulomb friction (μ = 0.8, `tests/fixtures/press_small.toml`) the
/// nodal forces sum to minus the probe force, every node's shear traction
/// stays within the cone (μ(1 + 1e-3) times its pressure), the drag shears,
/// and the frame's VTU carries the stress and contact arrays: the von Mises
/// stress of the pressed skin is positive, the cells' energy density too.
#[test]
fn coulomb_tractions_balance_and_stay_in_the_cone() {
    let fixture = common::root().join("tests/fixtures/press_small.toml");
    let mut setup = Setup::load(&fixture).unwrap();
    let dir = tempfile::tempdir().unwrap();
    setup.outputs.dir = dir.path().to_path_buf();
    let mut sheared = 0.0f64;
    skinpatch::pipeline::run(&setup, |frame| {
        let c = frame.contact;
        let total = c.total();
        let force = frame.metrics.probe_force_n;
        let scale = force[2].abs().max(1e-12);
        for k in 0..3 {
            assert!(
                (total[k] + force[k]).abs() <= 1e-9 * scale.max(1e-3),
                "{total:?} vs {force:?}"
            );
        }
        for k in 0..c.nodes.len() {
            assert!(c.pressure(k) > 0.0 && c.area_mm2[k] > 0.0);
            assert!(
                c.shear(k) <= 0.8 * (1.0 + 1e-3) * c.pressure(k),
                "node {}",
                c.nodes[k]
            );
            sheared = sheared.max(c.shear(k));
        }
    })
    .unwrap();
    assert!(sheared > 0.0, "the drag shears the skin");
    let grid = skinpatch::mesh::io::read_vtu(&dir.path().join("frames/frame_0006.vtu")).unwrap();
    let cell = |name: &str| -> Vec<f64> {
        let f = grid
            .cell_data
            .iter()
            .find(|f| f.name == name)
            .unwrap_or_else(|| panic!("{name}"));
        match &f.values {
            skinpatch::mesh::io::Values::F64(v) => v.clone(),
            _ => panic!("{name} is f64"),
        }
    };
    assert_eq!(cell("cauchy_stress_n_mm2").len(), 6 * grid.tets.len());
    assert!(
        cell("von_mises_stress_n_mm2")
            .iter()
            .fold(0.0f64, |m, &v| m.max(v))
            > 1e-3
    );
    assert!(cell("strain_energy_density_n_mm2")
        .iter()
        .all(|&v| v >= 0.0));
    let point = |name: &str| grid.point_data.iter().any(|f| f.name == name);
    assert!(
        point("contact_force_n") && point("contact_pressure_n_mm2") && point("contact_shear_n_mm2")
    );
}

/// The press of `solved_state_checks`: patch_3k, both layers of `model`
/// with `volumetric` and Poisson's ratio `nu`, a frictionless sphere
/// (R 1.5 mm) pressed 0.5 mm in 10 quasi-static frames, solved to 1e-10.
fn solved_state_press(model: &str, volumetric: &str, nu: f64) -> String {
    let mesh = common::root().join("meshes/patch_3k.node");
    let layer = |name: &str, kpa: f64| {
        format!(
            "[material.{name}]\nyoungs_modulus_kpa = {kpa}\npoisson_ratio = {nu}\n\
             model = \"{model}\"\nvolumetric = \"{volumetric}\"\n"
        )
    };
    format!(
        "[mesh]\nfile = {mesh:?}\n{}{}\
         [boundary]\nbottom = \"fixed\"\nsides = \"rollers\"\n\
         [probe]\nshape = \"sphere\"\nradius_mm = 1.5\n\
         path_mm = [[0.0, 0.0, 0.0, 1.5], [1.0, 0.0, 0.0, 1.0]]\ncontact = \"frictionless\"\n\
         [solver]\nrel_tol = 1e-10\n\
         [time]\nduration_s = 1.0\nframe_rate_hz = 10.0\n\
         [output]\nmesh_vtu = false\nframes_vtu = false\n",
        layer("dermis", 150.0),
        layer("hypodermis", 15.0)
    )
}

/// The stress and energy outputs are the state the solver found, for every
/// material model and volume measure at the Poisson's ratios each accepts
/// (0.45 and 0.49; 0.499 locking-free), on a quasi-static frictionless
/// press (`solved_state_press`). From the per-tet Cauchy stresses alone the
/// test rebuilds each node's elastic force `−Σ_e V_e J_e σ_e F_e⁻ᵀ g_b`:
///
/// - summed over the contact nodes it is the probe force, to 1e-6;
/// - at every free node (not in contact, not on the bottom or the sides)
///   it vanishes, to 1e-6 of the probe force;
/// - the strain energy `Σ ψ_e V_e` is the probe's work `∫F dδ`
///   (trapezoids over the 10 frames, whose own error is about 0.3% for
///   F ∝ δ^{3/2}) within 2%;
/// - the run's own checks in `metrics.csv` say the same: its
///   `free_node_force_ratio` is at most 1e-6 and at least half the one
///   rebuilt here, and its `energy_balance` is `1 − Σψ V/W` within 1% (its
///   trapezoids follow each held node, these the probe).
///
/// Before the locking-free tets carried their nodal pressure in the
/// outputs, their stresses implied 17% too little probe force at ν 0.49
/// and the wrong sign at 0.499 on the Hertz block, and their energy was
/// 1.16 to 26 times the work.
#[test]
fn stress_and_energy_outputs_are_the_solved_state() {
    use skinpatch::fem::boundary::{NodeSet, NodeSets};
    let dir = tempfile::tempdir().unwrap();
    let mut report = String::new();
    for (model, volumetric, nu) in [
        ("corotational", "standard", 0.45),
        ("corotational", "standard", 0.49),
        ("corotational", "locking-free", 0.45),
        ("corotational", "locking-free", 0.49),
        ("corotational", "locking-free", 0.499),
        ("stable-neo-hookean", "standard", 0.45),
        ("stable-neo-hookean", "standard", 0.49),
        ("stable-neo-hookean", "locking-free", 0.45),
        ("stable-neo-hookean", "locking-free", 0.49),
        ("stable-neo-hookean", "locking-free", 0.499),
    ] {
        let case = format!("{model}, {volumetric}, ν {nu}");
        let path = dir.path().join("press.toml");
        std::fs::write(&path, solved_state_press(model, volumetric, nu)).unwrap();
        let scenario = skinpatch::scenario::Scenario::load(&path).unwrap();
        let setup = Setup::from_scenario(&scenario, &path).unwrap();
        let (mesh, materials) = (&setup.mesh, &setup.simulation.tet_material);
        let sets = NodeSets::of(mesh);
        let mut supported = vec![false; mesh.num_vertices()];
        for set in [
            NodeSet::Bottom,
            NodeSet::XMin,
            NodeSet::XMax,
            NodeSet::YMin,
            NodeSet::YMax,
        ] {
            for &v in sets.get(set) {
                supported[v] = true;
            }
        }
        let elements = skinpatch::fem::simulation::rest_elements(mesh, materials);
        let mut run = skinpatch::pipeline::Run::new(&setup);
        let (mut work, mut last) = (0.0, (0.0, 0.0));
        let (mut worst_balance, mut worst_free, mut worst_energy) = (0.0f64, 0.0f64, 0.0f64);
        for _ in 0..run.scenario_frames() {
            let frame = run.step().unwrap();
            let (x, m) = (frame.positions, frame.metrics);
            let (delta, fz) = (0.5 * m.time_s, m.probe_force_n[2]);
            work += 0.5 * (fz + last.1) * (delta - last.0);
            last = (delta, fz);
            if fz < 1e-4 {
                continue;
            }
            let mut force = vec![nalgebra::Vector3::zeros(); mesh.num_vertices()];
            for (t, (stress, e)) in frame.stresses().iter().zip(&elements).enumerate() {
                let tet = mesh.tets[t];
                let f = e.deformation_gradient(&tet.map(|v| x[v]));
                let j = f.determinant();
                let piola = stress.cauchy * j * f.try_inverse().unwrap().transpose();
                for (&v, g) in tet.iter().zip(&e.grads) {
                    force[v] -= piola * g * e.volume;
                }
            }
            let mut in_contact = vec![false; mesh.num_vertices()];
            let mut on_probe = nalgebra::Vector3::zeros();
            for &v in &frame.contact.nodes {
                in_contact[v] = true;
                on_probe += force[v];
            }
            let probe = nalgebra::Vector3::from(m.probe_force_n);
            let balance = (on_probe - probe).norm() / fz;
            let free = (0..mesh.num_vertices())
                .filter(|&v| !in_contact[v] && !supported[v])
                .map(|v| force[v].norm())
                .fold(0.0, f64::max)
                / fz;
            let energy: f64 = frame
                .stresses()
                .iter()
                .zip(&elements)
                .map(|(s, e)| s.energy_density * e.volume)
                .sum();
            worst_balance = worst_balance.max(balance);
            worst_free = worst_free.max(free);
            worst_energy = worst_energy.max((energy / work - 1.0).abs());
            // The run's own checks agree.
            assert!(m.free_node_force_ratio <= 1e-6, "{case}: {m:?}");
            assert!(
                m.free_node_force_ratio >= 0.5 * free,
                "{case}: {m:?} vs {free}"
            );
            assert!(
                (m.energy_balance - (1.0 - energy / work)).abs() < 1e-2,
                "{case}: {m:?} vs {}",
                1.0 - energy / work
            );
        }
        report += &format!(
            "{case}: contact tractions {worst_balance:.1e} of F, free nodes {worst_free:.1e} of F, \
             energy/work within {:.2}%\n",
            100.0 * worst_energy
        );
        assert!(worst_balance < 1e-6, "{report}");
        assert!(worst_free < 1e-6, "{report}");
        assert!(worst_energy < 0.02, "{report}");
    }
    println!("{report}");
}
