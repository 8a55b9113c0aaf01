//! Probe contact: penetration bound, force balance, friction behaviour.

use crate::common;

use nalgebra::Vector3;
use skinpatch::fem::boundary::{
    BottomCondition, BoundaryConditions, Keyframes, NodeSets, SideCondition,
};
use skinpatch::fem::contact::{solve_with_contact, ContactMode, ContactState, Probe, ProbeShape};
use skinpatch::fem::simulation::Simulation;
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

/// Solves the probe at times k/steps, k = 1 … steps, checking the
/// penetration bound at each; returns the last report.
fn press(r: &mut Rig, probe: &Probe, steps: usize) -> skinpatch::fem::contact::ContactReport {
    let mut last = None;
    for k in 1..=steps {
        let rep = solve_with_contact(
            &mut r.sim,
            (&r.base.0, &r.base.1, &r.base.2),
            &probe.pose(k as f64 / steps as f64),
            probe.mode,
            &mut r.state,
            &format!("step {k}"),
        )
        .unwrap();
        assert!(rep.max_penetration_ratio <= 0.01, "{rep:?}");
        last = Some(rep);
    }
    last.unwrap()
}

/// The probe force equals the total support reaction (within 1e-4).
fn assert_force_balance(r: &Rig, rep: &skinpatch::fem::contact::ContactReport) {
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
    let rep = press(&mut r, &probe, 4);
    assert!(rep.contact_nodes >= 3, "{rep:?}");
    // The probe is pushed up; frictionless and centred: no tangential force.
    assert!(rep.probe_force.z > 0.0);
    let tangential = (rep.probe_force.x.powi(2) + rep.probe_force.y.powi(2)).sqrt();
    assert!(tangential < 0.02 * rep.probe_force.z, "{rep:?}");
    assert_force_balance(&r, &rep);
    println!("{rep:?}");
}

/// A probe pushed to 60% of the patch thickness: no NaN, no crash, a force
/// that grows with depth, and penetration within 1.5% of the local size.
#[test]
fn deep_press_is_robust() {
    let path = common::root().join("tests/fixtures/deep_press.toml");
    let mut setup = skinpatch::scenario::Setup::load(&path).unwrap();
    let dir = tempfile::tempdir().unwrap();
    setup.outputs.dir = dir.path().to_path_buf();
    let summary = skinpatch::pipeline::run(&setup, |_| {}).unwrap();
    let forces: Vec<f64> = summary.frames.iter().map(|m| m.probe_force_n[2]).collect();
    assert_eq!(forces.len(), 11);
    for w in forces.windows(2) {
        assert!(w[1].is_finite() && w[1] > w[0], "{forces:?}");
    }
    for m in &summary.frames {
        assert!(m.max_penetration_mm <= 0.015, "{m:?}");
    }
}

/// A sphere driven from touching to 3.5 mm below the 5 mm patch's bottom
/// face over 10 frames used to slip between the surface nodes at frame 8
/// (0.62 N at frame 7, then no contact, the mesh back at rest and exit 0).
/// Now the run stops with an error naming the first frame it cannot solve
/// — the probe through the skin, or no equilibrium with the skin wrapped
/// around it (frame 7 or 8) — and the frames before it stay written, the
/// force rising to the last.
#[test]
fn a_probe_through_the_skin_stops_the_run() {
    let path = common::root().join("tests/fixtures/deep_press.toml");
    let text = std::fs::read_to_string(&path)
        .unwrap()
        .replace("[1.0, 0.0, 0.0, -1.5]", "[1.0, 0.0, 0.0, -3.5]");
    let scenario = skinpatch::scenario::Scenario::parse(&text, &path).unwrap();
    let mut setup = skinpatch::scenario::Setup::from_scenario(&scenario, &path).unwrap();
    let dir = tempfile::tempdir().unwrap();
    setup.outputs.dir = dir.path().to_path_buf();
    let err = skinpatch::pipeline::run(&setup, |_| {})
        .unwrap_err()
        .to_string();
    let metrics = std::fs::read_to_string(dir.path().join("metrics.csv")).unwrap();
    let forces: Vec<f64> = metrics
        .lines()
        .skip(1)
        .map(|row| row.split(',').nth(4).unwrap().parse().unwrap())
        .collect();
    let failed = forces.len();
    assert!((7..=8).contains(&failed), "{err}\n{metrics}");
    assert!(err.contains(&format!("frame {failed} ")), "{err}");
    assert!(
        err.contains("passed through the skin") || err.contains("equilibrium not reached"),
        "{err}"
    );
    for w in forces.windows(2) {
        assert!(w[1] > w[0], "{metrics}");
    }
    assert!(forces[failed - 1] > 0.4, "{metrics}");
}

/// Coulomb friction bounds every node's force, not only the sum: after
/// each step of a press and drag on patch_3k, each contact node's
/// tangential force (against the probe's normal at the node) is at most
/// μ(1 + 1e-3) times its normal force, for μ = 0.8 (as press_small) and
/// μ = 0.3. Kept constraint planes tilted away from the probe's normal
/// gave 0.8023 and 0.3015. The six steps take at most 35 Newton
/// iterations.
#[test]
fn coulomb_forces_stay_in_the_cone_node_by_node() {
    let _ = env_logger::builder().is_test(true).try_init();
    for mu in [0.8, 0.3] {
        let mut r = rig(
            common::patch_3k(),
            BottomCondition::Fixed,
            SideCondition::Rollers,
        );
        let probe = sphere(
            vec![
                (0.0, Vector3::new(0.0, 0.0, 1.5)),
                (0.5, Vector3::new(0.0, 0.0, 1.0)),
                (1.0, Vector3::new(0.5, 0.0, 1.0)),
            ],
            ContactMode::Coulomb(mu),
        );
        let steps = 6;
        let mut worst: f64 = 0.0;
        let mut sliding = 0;
        let mut newton = 0;
        for k in 1..=steps {
            let pose = probe.pose(k as f64 / steps as f64);
            newton += solve_with_contact(
                &mut r.sim,
                (&r.base.0, &r.base.1, &r.base.2),
                &pose,
                probe.mode,
                &mut r.state,
                &format!("μ {mu}, step {k}"),
            )
            .unwrap()
            .newton_iterations;
            let largest = r
                .state
                .active
                .keys()
                .map(|&v| r.sim.internal_forces()[v].norm())
                .fold(0.0, f64::max);
            for &v in r.state.active.keys() {
                let f = -r.sim.internal_forces()[v];
                let (_, n) = pose.distance(&r.sim.positions()[v]);
                let normal = f.dot(&n);
                let tangential = (f - n * normal).norm();
                if normal > 1e-6 * largest {
                    worst = worst.max(tangential / normal);
                }
                if tangential > 0.99 * mu * normal {
                    sliding += 1;
                }
            }
        }
        println!(
            "μ {mu}: largest |f_t|/f_n {worst:.6}, {sliding} sliding node-steps, \
             {newton} Newton iterations"
        );
        assert!(sliding > 0, "the drag makes nodes slide");
        // Friction along the trial force settles the stick–slip boundary
        // without creeping iterations: 34 for μ = 0.8 (39 with friction
        // along the slip direction).
        assert!(newton <= 35, "μ {mu}: {newton} Newton iterations");
        assert!(
            worst <= mu * (1.0 + 1e-3),
            "μ {mu}: |f_t|/f_n reaches {worst}"
        );
    }
}

/// Runs tests/fixtures/drag.toml with the given `[probe]` contact lines.
fn drag(contact: &str) -> (skinpatch::pipeline::FemRunSummary, tempfile::TempDir) {
    common::run_fixture("drag.toml", |t| {
        t.replace("[time]", &format!("{contact}\n[time]"))
    })
}

/// A flat punch pressed 0.1 mm and dragged 0.5 mm with μ = 0.3 slides over
/// the skin: once sliding, the tangential / normal probe force ratio is μ
/// within 2% (measured 0.3000). Nodes the punch reaches during a step slip
/// relative to the moving punch, so their friction drags the skin along.
#[test]
fn sliding_punch_force_ratio_is_mu() {
    let (summary, _dir) = common::run_fixture("drag.toml", |t| {
        let t = t
            .replace("shape = \"sphere\"", "shape = \"punch\"")
            .replace("radius_mm = 1.5", "radius_mm = 1.0")
            .replace(
                "path_mm = [[0.0, -0.25, 0.0, 1.5], [0.5, -0.25, 0.0, 1.0], [1.0, 0.25, 0.0, 1.0]]",
                "path_mm = [[0.0, -0.25, 0.0, 0.0], [0.5, -0.25, 0.0, -0.1], [1.0, 0.25, 0.0, -0.1]]",
            )
            .replace("[time]", "contact = \"coulomb\"\nfriction = 0.3\n[time]");
        assert!(t.contains("punch") && t.contains("-0.1]]"));
        t
    });
    for m in &summary.frames[5..] {
        let [fx, fy, fz] = m.probe_force_n;
        let ratio = fx.hypot(fy) / fz;
        assert!((ratio / 0.3 - 1.0).abs() < 0.02, "ratio {ratio}: {m:?}");
        assert!(fx < 0.0, "the skin resists the drag along +x: {m:?}");
    }
}

/// With μ = 0 a dragged probe carries no tangential force, up to the
/// faceting of the mesh: the contact nodes sit unevenly around the probe's
/// lowest point, and the node-by-node normal reactions of the exact discrete
/// solution add up to a small tangential force that changes as the probe
/// passes nodes. With the 3 mm sphere of this test (about 82 nodes in
/// contact) it stays under 0.5% of the normal force (measured ≤ 0.14% once
/// dragging); with the fixture's 1.5 mm sphere (about 37 nodes) under 1%
/// (measured ≤ 0.53%).
#[test]
fn frictionless_drag_has_no_tangential_force() {
    let (summary, _dir) = common::run_fixture("drag.toml", |t| {
        let t = t
            .replace("radius_mm = 1.5", "radius_mm = 3.0")
            .replace(
                "path_mm = [[0.0, -0.25, 0.0, 1.5], [0.5, -0.25, 0.0, 1.0], [1.0, 0.25, 0.0, 1.0]]",
                "path_mm = [[0.0, -0.25, 0.0, 3.0], [0.5, -0.25, 0.0, 2.5], [1.0, 0.25, 0.0, 2.5]]",
            )
            .replace("[time]", "contact = \"frictionless\"\n[time]");
        assert!(t.contains("3.0]") && t.contains("2.5]]"));
        t
    });
    for m in &summary.frames[4..] {
        let [fx, fy, fz] = m.probe_force_n;
        assert!(fx.hypot(fy) < 0.005 * fz, "{m:?}");
    }
    let (summary, _dir) = drag("contact = \"frictionless\"");
    for m in &summary.frames[4..] {
        let [fx, fy, fz] = m.probe_force_n;
        assert!(fx.hypot(fy) < 0.01 * fz, "{m:?}");
    }
}

/// Frictionless contact forces are normal to the probe node by node, and
/// the loaded nodes lie on the sphere: the constraint of every sliding node
/// is its closest point's tangent plane at convergence, not one left from an
/// earlier iterate. A 3 mm press (60% of the patch) into patch_3k: every
/// node carrying at least 1% of the largest nodal force has a tangential /
/// normal ratio ≤ 1e-3 (measured 4.4e-4; planes tilted by more than 2e-4
/// rad are re-projected near convergence, and without that it is 1.3e-3)
/// and sits within 1e-5 mm of the sphere.
#[test]
fn frictionless_forces_are_normal_node_by_node() {
    let mesh = io::read_tetgen(&common::root().join("meshes/patch_3k")).unwrap();
    let mut r = rig(mesh, BottomCondition::Fixed, SideCondition::Rollers);
    let probe = sphere(
        vec![
            (0.0, Vector3::new(0.0, 0.0, 1.5)),
            (1.0, Vector3::new(0.0, 0.0, -1.5)),
        ],
        ContactMode::Frictionless,
    );
    press(&mut r, &probe, 10);
    let pose = probe.pose(1.0);
    let forces: Vec<(usize, Vec3)> = r
        .state
        .active
        .keys()
        .map(|&v| (v, -r.sim.internal_forces()[v]))
        .collect();
    let largest = forces.iter().map(|(_, f)| f.norm()).fold(0.0, f64::max);
    let (mut worst_ratio, mut worst_gap, mut loaded) = (0.0f64, 0.0f64, 0);
    for (v, f) in forces {
        if f.norm() < 0.01 * largest {
            continue;
        }
        let (gap, n) = pose.distance(&r.sim.positions()[v]);
        let normal = f.dot(&n);
        worst_ratio = worst_ratio.max((f - n * normal).norm() / normal);
        worst_gap = worst_gap.max(gap.abs());
        loaded += 1;
    }
    println!(
        "{loaded} loaded nodes: tangential/normal ≤ {worst_ratio:.2e}, |gap| ≤ {worst_gap:.2e} mm"
    );
    assert!(loaded >= 10, "{loaded} loaded nodes");
    assert!(worst_ratio <= 1e-3, "tangential/normal {worst_ratio:.3e}");
    assert!(worst_gap <= 1e-5, "gap {worst_gap:.3e} mm");
}

/// With a large μ the surface under the probe moves with it: the nodes in
/// contact at the end travelled the full 0.5 mm of the drag.
#[test]
fn sticky_drag_carries_the_surface() {
    let (summary, dir) = drag("contact = \"coulomb\"\nfriction = 5.0");
    let last = summary.frames.last().unwrap();
    assert!(
        last.probe_force_n[0] < -0.5 * last.probe_force_n[2],
        "{last:?}"
    );
    let read =
        |k: usize| io::read_vtu(&dir.path().join(format!("frames/frame_{k:04}.vtu"))).unwrap();
    let (end, pressed) = (read(6), read(3));
    let disp = |g: &skinpatch::mesh::io::Grid| match &g.point_data[0].values {
        skinpatch::mesh::io::Values::F64(v) => v.clone(),
        _ => panic!("float displacement"),
    };
    let (d_end, d_pressed) = (disp(&end), disp(&pressed));
    let mut checked = 0;
    for (v, p) in end.points.iter().enumerate() {
        // Nodes under the sphere's lowest point (0.25, 0, −0.5) at the end.
        if (p.x - 0.25).hypot(p.y) < 0.3 && p.z > -0.6 && p.z < -0.3 {
            let moved = d_end[3 * v] - d_pressed[3 * v];
            assert!((moved - 0.5).abs() < 0.02, "node {v} moved {moved} mm");
            checked += 1;
        }
    }
    assert!(checked >= 3, "{checked} nodes under the probe");
}

/// A bonded probe pressed 0.3 mm and lifted 0.3 mm above the surface pulls
/// the skin up with it: the probe force turns downward and the node under it
/// rises about 0.3 mm.
#[test]
fn bonded_probe_pulls_the_surface() {
    let (summary, dir) = common::run_fixture("press_small.toml", |t| {
        let t = t
            .replace(
                "path_mm = [[0.0, 0.0, 0.0, 1.5], [0.5, 0.0, 0.0, 1.0], [1.0, 0.5, 0.0, 1.0]]",
                "path_mm = [[0.0, 0.0, 0.0, 1.5], [0.5, 0.0, 0.0, 1.2], [1.0, 0.0, 0.0, 1.8]]",
            )
            .replace(
                "contact = \"coulomb\"\nfriction = 0.8",
                "contact = \"bonded\"",
            );
        assert!(t.contains("bonded") && t.contains("1.8]]"));
        t
    });
    let last = summary.frames.last().unwrap();
    assert!(last.probe_force_n[2] < 0.0, "{last:?}");
    assert!(last.contact_nodes > 0);
    let grid = io::read_vtu(&dir.path().join("frames/frame_0006.vtu")).unwrap();
    let skinpatch::mesh::io::Values::F64(d) = &grid.point_data[0].values else {
        panic!()
    };
    // The rest-top node closest to the probe axis.
    let top = (0..grid.points.len())
        .filter(|&v| (grid.points[v].z - d[3 * v + 2]).abs() < 1e-9)
        .min_by(|&a, &b| {
            let r = |v: usize| (grid.points[v].x - d[3 * v]).hypot(grid.points[v].y - d[3 * v + 1]);
            r(a).total_cmp(&r(b))
        })
        .unwrap();
    assert!(
        (d[3 * top + 2] - 0.3).abs() < 0.05,
        "top centre rose {} mm",
        d[3 * top + 2]
    );
}

/// Hertz: a frictionless rigid sphere (R = 2 mm) on the E = 100 kPa,
/// ν = 0.3 block. Theory for a half-space: F = (4/3)·E/(1−ν²)·√R·δ^{3/2}
/// and contact radius a = √(Rδ). At δ = 0.05 and 0.1 mm the force is within
/// 5% and the radius (of the contact area, a = √(A/π)) within 10%; at
/// δ = 0.2 mm finite-size and large-deformation effects are allowed 10%.
/// Hertz's force (N) and contact radius (mm) of the fixture's sphere
/// (R = 2 mm) pressed `delta` mm into a half-space of E = 100 kPa and
/// Poisson's ratio `nu`.
fn hertz(nu: f64, delta: f64) -> (f64, f64) {
    let (e_mpa, r): (f64, f64) = (0.1, 2.0);
    let force = (4.0 / 3.0) * e_mpa / (1.0 - nu * nu) * r.sqrt() * delta.powf(1.5);
    (force, (r * delta).sqrt())
}

#[test]
fn hertz_indentation_matches_theory() {
    let (summary, _dir) = common::run_fixture("hertz.toml", |t| t);
    let nu = 0.3;
    let mut report = String::new();
    for m in &summary.frames[1..] {
        let delta = 0.2 * m.time_s;
        let (force, a) = hertz(nu, delta);
        let a_fem = (m.contact_area_mm2 / std::f64::consts::PI).sqrt();
        let force_err = m.probe_force_n[2] / force - 1.0;
        let radius_err = a_fem / a - 1.0;
        report += &format!(
            "δ {delta:.2} mm: force {:.4e} N vs {force:.4e} ({:+.2}%), radius {a_fem:.4} mm vs {a:.4} ({:+.2}%)\n",
            m.probe_force_n[2],
            100.0 * force_err,
            100.0 * radius_err
        );
        let (force_bound, radius_bound) = if delta < 0.11 {
            (0.05, 0.10)
        } else {
            (0.10, 0.10)
        };
        assert!(force_err.abs() < force_bound, "{report}");
        assert!(radius_err.abs() < radius_bound, "{report}");
        // Frictionless and centred: no tangential force.
        let [fx, fy, fz] = m.probe_force_n;
        assert!(fx.hypot(fy) < 1e-3 * fz, "{m:?}");
    }
    assert_eq!(summary.frames.len(), 5);
    println!("{report}");
}

/// The Hertz block's bottom is on rollers and its sides are free, so only
/// the frictionless sphere holds it sideways — a neutral mode in which
/// Newton used to stall once the contact planes followed the nodes (ν =
/// 0.45 stopped at frame 1 with a residual of 6e-5). With the rigid
/// motions pinned it converges to the tolerance at every ν, in few
/// iterations, with the force within the Hertz bounds of the ν = 0.3 test
/// at ν = 0.45; at ν = 0.49 the linear tet locks and the force is ~8–10%
/// stiff, allowed 12% here.
#[test]
fn hertz_converges_for_nearly_incompressible_blocks() {
    let _ = env_logger::builder().is_test(true).try_init();
    let mut report = String::new();
    for (nu, bound_shallow, bound_deep) in [(0.45, 0.05, 0.10), (0.49, 0.12, 0.12)] {
        let (summary, _dir) = common::run_fixture("hertz.toml", |t| {
            t.replace("poisson_ratio = 0.3", &format!("poisson_ratio = {nu}"))
                .replace("frame_rate_hz = 4.0", "frame_rate_hz = 2.0")
        });
        assert_eq!(summary.frames.len(), 3);
        for m in &summary.frames[1..] {
            let delta = 0.2 * m.time_s;
            let (force, _) = hertz(nu, delta);
            let err = m.probe_force_n[2] / force - 1.0;
            report += &format!(
                "ν {nu}, δ {delta:.2} mm: force {:+.2}% of Hertz, {} Newton iterations, residual {:.1e}\n",
                100.0 * err,
                m.newton_iterations,
                m.rel_residual
            );
            assert!(m.rel_residual <= 1e-6, "{report}");
            assert!(m.newton_iterations <= 15, "{report}");
            let bound = if delta < 0.11 {
                bound_shallow
            } else {
                bound_deep
            };
            assert!(err.abs() < bound, "{report}");
            let [fx, fy, fz] = m.probe_force_n;
            assert!(fx.hypot(fy) < 1e-3 * fz, "{m:?}");
        }
    }
    println!("{report}");
}

/// Contact radii (mm) of a Hertz frame: `(√(A/π), √(5/2 · Σ f r² / Σ f))`.
/// The first is the radius of the contact nodes' lumped area, which counts
/// half of the ring of triangles outside the rim and so runs high by a
/// fraction of the surface spacing over the radius. The second is the
/// radius of the Hertz pressure `p₀√(1 − r²/a²)` with the second moment of
/// the nodal contact forces about the probe axis (for that profile
/// `∫p r² dA / ∫p dA = 2a²/5`): it uses the forces the solve balances, not
/// the areas, and reads wrong where the pressure is not Hertz-shaped.
fn contact_radii(frame: &skinpatch::pipeline::Frame<'_>) -> (f64, f64) {
    let area = (frame.metrics.contact_area_mm2 / std::f64::consts::PI).sqrt();
    let (mut f0, mut f2) = (0.0, 0.0);
    for (k, &v) in frame.contact.nodes.iter().enumerate() {
        let (p, fz) = (frame.positions[v], frame.contact.force_n[k].z);
        f0 += fz;
        f2 += fz * (p.x * p.x + p.y * p.y);
    }
    (area, (2.5 * f2 / f0).sqrt())
}

/// The locking-free tet (`volumetric = "locking-free"`, average nodal
/// pressure) on the Hertz block at ν = 0.49 and 0.499, where the standard
/// tet is 8% and 72% too stiff: the force within 3% of Hertz's half-space
/// value, the contact radius of the force distribution within 2% and that
/// of the lumped contact area within 3% (see `contact_radii`), converged to
/// rel_tol 1e-6 in few Newton iterations. (Measured at δ = 0.1 / 0.2 mm:
/// force +1.5% / +1.3% at 0.49, +1.8% / +1.7% at 0.499; radius of the
/// forces +1.0% / +1.2%, of the area +0.8% to +2.4%. The ν = 0.3 block
/// reads +0.7% / +1.2% and +0.4% / +1.8%.)
#[test]
fn locking_free_hertz_matches_theory_near_incompressibility() {
    let _ = env_logger::builder().is_test(true).try_init();
    let fixture = common::root().join("tests/fixtures/hertz.toml");
    let text = std::fs::read_to_string(&fixture).unwrap();
    let mut report = String::new();
    for nu in [0.49, 0.499] {
        let text = text
            .replace(
                "poisson_ratio = 0.3",
                &format!("poisson_ratio = {nu}\nvolumetric = \"locking-free\""),
            )
            .replace("frame_rate_hz = 4.0", "frame_rate_hz = 2.0");
        let scenario = skinpatch::scenario::Scenario::parse(&text, &fixture).unwrap();
        let setup = skinpatch::scenario::Setup::from_scenario(&scenario, &fixture).unwrap();
        let mut run = skinpatch::pipeline::Run::new(&setup);
        assert_eq!(run.scenario_frames(), 3);
        run.step().unwrap();
        for _ in 1..3 {
            let frame = run.step().unwrap();
            let m = frame.metrics;
            let delta = 0.2 * m.time_s;
            let (force, a) = hertz(nu, delta);
            let (a_area, a_force) = contact_radii(&frame);
            let force_err = m.probe_force_n[2] / force - 1.0;
            let (area_err, radius_err) = (a_area / a - 1.0, a_force / a - 1.0);
            report += &format!(
                "ν {nu}, δ {delta:.2} mm: force {:+.2}%, radius {:+.2}% (forces) {:+.2}% (area) of Hertz, {} Newton iterations, residual {:.1e}\n",
                100.0 * force_err,
                100.0 * radius_err,
                100.0 * area_err,
                m.newton_iterations,
                m.rel_residual
            );
            assert!(m.rel_residual <= 1e-6, "{report}");
            assert!(m.newton_iterations <= 15, "{report}");
            assert!(force_err.abs() < 0.03, "{report}");
            assert!(radius_err.abs() < 0.02, "{report}");
            assert!(area_err.abs() < 0.03, "{report}");
        }
    }
    println!("{report}");
}

/// Flat cylindrical punch (radius 0.5 mm) pressed 0.02 mm into the Hertz
/// block: Sneddon's half-space solution F = 2·a·E/(1−ν²)·δ, within 10% (the
/// rim is a stress singularity resolved by one ring of nodes); the nodes under
/// the face are all in contact, so the contact area is about πa².
#[test]
fn punch_indentation_matches_sneddon() {
    let (summary, _dir) = common::run_fixture("hertz.toml", |t| {
        t.replace("shape = \"sphere\"", "shape = \"punch\"")
            .replace("radius_mm = 2.0", "radius_mm = 0.5")
            .replace(
                "[[0.0, 0.0, 0.0, 2.0], [1.0, 0.0, 0.0, 1.8]]",
                "[[0.0, 0.0, 0.0, 0.0], [1.0, 0.0, 0.0, -0.04]]",
            )
            .replace("frame_rate_hz = 4.0", "frame_rate_hz = 2.0")
    });
    let (e_mpa, nu, a): (f64, f64, f64) = (0.1, 0.3, 0.5);
    let mut report = String::new();
    for m in &summary.frames[1..] {
        let delta = 0.04 * m.time_s;
        let force = 2.0 * a * e_mpa / (1.0 - nu * nu) * delta;
        let area = std::f64::consts::PI * a * a;
        report += &format!(
            "δ {delta:.3} mm: force {:.4e} N vs {force:.4e} ({:+.2}%), area {:.4} mm² vs {area:.4} ({:+.2}%), penetration {:.1e} mm\n",
            m.probe_force_n[2],
            100.0 * (m.probe_force_n[2] / force - 1.0),
            m.contact_area_mm2,
            100.0 * (m.contact_area_mm2 / area - 1.0),
            m.max_penetration_mm,
        );
        assert!((m.probe_force_n[2] / force - 1.0).abs() < 0.10, "{report}");
        assert!((m.contact_area_mm2 / area - 1.0).abs() < 0.15, "{report}");
        assert!(m.max_penetration_mm < 0.01 * 0.11, "{report}");
    }
    println!("{report}");
}

/// Presses a capsule (radius 0.5 mm, 2 mm between end centres) 0.3 mm into
/// patch_25k with its axis along `axis`; returns the last report and the
/// extents (x, y) of the contact nodes (mm).
fn press_capsule(axis: Vector3<f64>) -> (skinpatch::fem::contact::ContactReport, [f64; 2]) {
    let mut r = rig(patch_25k(), BottomCondition::Fixed, SideCondition::Rollers);
    let probe = Probe {
        shape: ProbeShape::Capsule {
            radius_mm: 0.5,
            length_mm: 2.0,
        },
        path: Keyframes {
            points: vec![
                (0.0, Vector3::new(0.0, 0.0, 0.5)),
                (1.0, Vector3::new(0.0, 0.0, 0.2)),
            ],
        },
        axis: Keyframes {
            points: vec![(0.0, axis)],
        },
        mode: ContactMode::Frictionless,
    };
    let rep = press(&mut r, &probe, 3);
    assert_force_balance(&r, &rep);
    let contact: Vec<usize> = r.state.active.keys().copied().collect();
    let extent = |k: usize| {
        let values = contact.iter().map(|&v| r.sim.positions()[v][k]);
        values.clone().fold(f64::MIN, f64::max) - values.fold(f64::MAX, f64::min)
    };
    (rep, [extent(0), extent(1)])
}

/// A capsule's contact patch is elongated along its axis and turns with it;
/// the force does not depend on the axis direction beyond the mesh's
/// asymmetry, and balances the supports.
#[test]
fn capsule_contact_follows_its_axis() {
    let (along_x, [x1, y1]) = press_capsule(Vector3::x());
    let (along_y, [x2, y2]) = press_capsule(Vector3::y());
    // The straight part (2 mm) plus the caps' contact, against a width of
    // about 2·√(Rδ) ≈ 0.8 mm across.
    assert!(x1 > 2.0 && x1 > 1.8 * y1, "extents {x1} × {y1}");
    assert!(y2 > 2.0 && y2 > 1.8 * x2, "extents {x2} × {y2}");
    let (f1, f2) = (along_x.probe_force.z, along_y.probe_force.z);
    assert!(f1 > 0.0 && (f1 / f2 - 1.0).abs() < 0.05, "{f1} vs {f2}");
    for rep in [along_x, along_y] {
        // Frictionless: tangential force only from the faceting of the
        // ~30-node contact patch (the sphere's ~100-node patch stays under 2%).
        let tangential = rep.probe_force.x.hypot(rep.probe_force.y);
        assert!(tangential < 0.04 * rep.probe_force.z, "{rep:?}");
    }
    println!("axis x: {along_x:?}, extents {x1:.3} × {y1:.3} mm");
    println!("axis y: {along_y:?}, extents {x2:.3} × {y2:.3} mm");
}

/// Load steps follow the probe's motion, not the frame's length: a 0.5 mm
/// press of a 1.5 mm sphere takes 2 steps of at most a quarter radius
/// whether the frame lasts 1 ms, 1000 s or 10⁶ s (the slow frames once
/// needed 2048 steps, and failed beyond 10000), also when the press takes
/// only the first second of a 10⁶ s frame, and a probe at rest takes the
/// configured count.
#[test]
fn load_steps_follow_the_probe_not_the_clock() {
    use skinpatch::fem::load_steps::load_steps;
    for seconds in [1e-3, 1e3, 1e6] {
        let probe = sphere(
            vec![
                (0.0, Vector3::new(0.0, 0.0, 1.5)),
                (seconds, Vector3::new(0.0, 0.0, 1.0)),
            ],
            ContactMode::Coulomb(0.8),
        );
        assert_eq!(
            load_steps(Some(&probe), 1, 0.0, seconds, 1).unwrap().len(),
            2
        );
        assert_eq!(
            load_steps(Some(&probe), 3, 0.0, seconds, 1).unwrap().len(),
            3
        );
        // The same press in the first second of a long frame (a frame rate
        // of 1e-6 Hz): equal steps would need millions; steps that follow
        // the path need the press's 2 and one for the rest.
        let early = sphere(
            vec![
                (0.0, Vector3::new(0.0, 0.0, 1.5)),
                (1.0, Vector3::new(0.0, 0.0, 1.05)),
            ],
            ContactMode::Coulomb(0.8),
        );
        let t = load_steps(Some(&early), 1, 0.0, 1e6, 1).unwrap();
        assert_eq!(t, vec![0.5, 1.0, 1e6]);
        let resting = sphere(
            vec![(0.0, Vector3::new(0.0, 0.0, 1.5))],
            ContactMode::Coulomb(0.8),
        );
        assert_eq!(
            load_steps(Some(&resting), 1, seconds, 2.0 * seconds, 2)
                .unwrap()
                .len(),
            1
        );
    }
}

/// The press-and-drag fixture with both layers locking-free at ν = 0.499:
/// every frame converges to rel_tol 1e-6 with frictionless, Coulomb and
/// bonded contact; with frictionless contact every linear solver gives the
/// same probe force (to the solve tolerance), and backward-Euler dynamics
/// runs too.
#[test]
fn locking_free_layers_converge_with_every_contact_mode_and_solver() {
    let _ = env_logger::builder().is_test(true).try_init();
    let layers = "[material.dermis]\nyoungs_modulus_kpa = 150.0\npoisson_ratio = 0.499\n\
                  volumetric = \"locking-free\"\n[material.hypodermis]\nyoungs_modulus_kpa = 15.0\n\
                  poisson_ratio = 0.499\nvolumetric = \"locking-free\"\n";
    // `extra` goes at the end (a `[solver]` section) or, starting with
    // "integrator", into the fixture's `[time]`.
    let run = |contact: &str, extra: &str| {
        let (summary, _dir) = common::run_fixture("press_small.toml", |t| {
            let t = t
                .replace("contact = \"coulomb\"", &format!("contact = \"{contact}\""))
                .replace("frame_rate_hz = 6.0", "frame_rate_hz = 3.0");
            let (t, extra) = if extra.starts_with("integrator") {
                (t.replace("[time]\n", &format!("[time]\n{extra}")), "")
            } else {
                (t, extra)
            };
            let t = if contact == "coulomb" {
                t
            } else {
                t.replace("friction = 0.8", "")
            };
            format!("{t}\n{layers}{extra}")
        });
        for m in &summary.frames {
            assert!(
                m.rel_residual <= 1e-6,
                "{contact} {extra}: frame {} residual {:e}",
                m.frame,
                m.rel_residual
            );
        }
        summary.frames.last().unwrap().probe_force_n
    };
    for contact in ["coulomb", "bonded"] {
        let f = run(contact, "");
        assert!(f[2] > 0.0, "{contact}: {f:?}");
    }
    let reference = run("frictionless", "[solver]\nlinear = \"direct\"\n");
    for solver in ["two-level", "cg", "factored-cg"] {
        let f = run(
            "frictionless",
            &format!("[solver]\nlinear = \"{solver}\"\n"),
        );
        assert!(
            (f[2] - reference[2]).abs() <= 1e-4 * reference[2],
            "{solver}: {f:?} against direct {reference:?}"
        );
    }
    let f = run("frictionless", "integrator = \"implicit-euler\"\n");
    assert!(f[2] > 0.0, "implicit Euler: {f:?}");
}

/// Nearly incompressible skin (locking-free, ν 0.4999 in both layers of
/// patch_25k) under a frictionless sphere (R 1.5 mm) pressed 0.25 and
/// 0.5 mm: the contact set still changes after 30 Newton iterations (the
/// rim nodes bulge into the probe as the nodes inside are pushed out), and
/// from then on it only takes nodes in. Both frames converge with no node
/// inside the probe by more than its tolerance (1% of the edge length
/// there) nor by more than 3 µm, 0.6% of the press (2.69 µm measured; 0.08
/// µm before the volume limit changed the path) — the set frozen instead
/// accepted them with nodes 4.1 and 22 µm inside.
#[test]
fn a_contact_set_that_keeps_changing_leaves_no_node_inside_the_probe() {
    let mesh = common::root().join("meshes/patch_25k.node");
    let layer = |name: &str| {
        format!("[material.{name}]\npoisson_ratio = 0.4999\nvolumetric = \"locking-free\"\n")
    };
    let text = format!(
        "[mesh]\nfile = {mesh:?}\n{}{}\
         [boundary]\nbottom = \"fixed\"\nsides = \"rollers\"\n\
         [probe]\nshape = \"sphere\"\nradius_mm = 1.5\n\
         path_mm = [[0.0, 0.0, 0.0, 1.5], [0.5, 0.0, 0.0, 1.0]]\ncontact = \"frictionless\"\n\
         [time]\nduration_s = 0.5\nframe_rate_hz = 4.0\n",
        layer("dermis"),
        layer("hypodermis")
    );
    let path = common::root().join("tests/fixtures/press_small.toml");
    let scenario = skinpatch::scenario::Scenario::parse(&text, &path).unwrap();
    let setup = skinpatch::scenario::Setup::from_scenario(&scenario, &path).unwrap();
    let mut run = skinpatch::pipeline::Run::new(&setup);
    let mut report = String::new();
    for _ in 0..run.scenario_frames() {
        let m = *run.step().unwrap().metrics;
        report += &format!(
            "frame {}: force {:.5} N, {} contact nodes, deepest {:.2e} mm, {} Newton iterations\n",
            m.frame, m.probe_force_n[2], m.contact_nodes, m.max_penetration_mm, m.newton_iterations
        );
        // A node deeper than its tolerance fails the solve itself.
        assert!(m.max_penetration_mm < 3e-3, "{report}");
        assert!(m.rel_residual <= 1e-6, "{report}");
    }
    println!("{report}");
}

/// The README's coarse drag (`press_api -- --dermis-kpa 75 --mesh
/// meshes/patch_3k.node`): the main job's locking-free ν = 0.49 layers with
/// their volume limit, a softer dermis, patch_3k. At frame 38 a node turns
/// from stick to slip beside a tet under the limit, whose stiff normal
/// reaction made every coupled Newton step overshoot (cut to 1/32 and
/// worse, the frame failed after four halvings of its load step). A step
/// cut to 1/8 or less now lags the friction for the rest of the solve:
/// every frame converges, frame 38 in 31 Newton iterations and without a
/// halving of its load step (docs/VERIFICATION.md, "Friction beside a
/// squeezed tet").
#[test]
fn a_step_cut_short_lags_the_friction() {
    use skinpatch::scenario::{Scenario, Setup};
    let path = common::root().join("examples/press.toml");
    let mut scenario = Scenario::load(&path).unwrap();
    scenario
        .material
        .entry("dermis".into())
        .or_default()
        .youngs_modulus_kpa = Some(75.0);
    scenario.mesh.file = Some(common::root().join("meshes/patch_3k.node"));
    scenario.render = None;
    scenario.microstructure = None;
    scenario.output.strain_images = false;
    let setup = Setup::from_scenario(&scenario, &path).unwrap();
    let mut run = skinpatch::pipeline::Run::new(&setup);
    let mut most = 0;
    for _ in 0..run.scenario_frames() {
        let m = *run.step().unwrap_or_else(|e| panic!("{e}")).metrics;
        assert!(m.rel_residual <= 1e-6, "frame {}: {m:?}", m.frame);
        most = most.max(m.newton_iterations);
    }
    // The lagged friction converges linearly: 31 iterations at frame 38.
    assert!(most <= 40, "{most} Newton iterations in a frame");
}
