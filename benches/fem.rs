//! Criterion benchmarks of the FEM stages on the press scenario
//! (`examples/press.toml`, patch_25k): the element loop (rotations and
//! forces; at one state and alternating between two), tangent assembly,
//! and whole press frames with contact.
//!
//! Run: `cargo bench --bench fem`. The figures and their ratios are kept in
//! docs/PERFORMANCE.md beside those of `skinpatch bench fem`.

use std::path::Path;

use criterion::{criterion_group, criterion_main, BatchSize, Criterion};
use skinpatch::fem::contact::{solve_with_contact, ContactState};
use skinpatch::fem::simulation::{LinearSolver, Simulation};
use skinpatch::fem::TangentKind;
use skinpatch::mesh::Vec3;
use skinpatch::scenario::Setup;

/// The press scenario's simulation after its first frame (probe 1/24 mm
/// deep), with what a frame needs to run again.
struct Pressed {
    setup: Setup,
    sim: Simulation,
    contact: ContactState,
}

fn pressed() -> Pressed {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/press.toml");
    let setup = Setup::load(&path).expect("examples/press.toml loads");
    let s = &setup.simulation;
    let mut sim = Simulation::new(&setup.mesh, &s.tet_material);
    sim.settings = s.newton;
    let sides: Vec<usize> = s.sets.sides.iter().flatten().copied().collect();
    let mut contact = ContactState::new(&setup.mesh, &sides);
    frame(&setup, &mut sim, &mut contact, 1);
    Pressed {
        setup,
        sim,
        contact,
    }
}

/// Solves press frame `k` (quasi-static, with contact).
fn frame(setup: &Setup, sim: &mut Simulation, contact: &mut ContactState, k: usize) {
    let s = &setup.simulation;
    let t = k as f64 * s.frame_dt;
    let (filters, targets) = s.boundary.constraints(&s.sets, &setup.mesh.positions, t);
    let loads = vec![Vec3::zeros(); setup.mesh.num_vertices()];
    let probe = s.probe.as_ref().expect("the press scenario has a probe");
    solve_with_contact(
        sim,
        (&filters, &targets, &loads),
        &probe.pose(t),
        probe.mode,
        contact,
        "bench",
    )
    .expect("press frame converges");
}

fn fem(c: &mut Criterion) {
    let base = pressed();
    let mut group = c.benchmark_group("fem_patch_25k");
    group.sample_size(10);

    let mut sim = base.sim.clone();
    group.bench_function("element_loop", |b| b.iter(|| sim.evaluate_forces()));
    // Between the states of two frames, as Newton iterations move: each
    // tet's rotation starts from the other state's (the warm start sees a
    // real change, where evaluating one state again would see none).
    let states = {
        let mut next = base.sim.clone();
        let mut contact = base.contact.clone();
        frame(&base.setup, &mut next, &mut contact, 2);
        [base.sim.positions().to_vec(), next.positions().to_vec()]
    };
    let mut which = 0;
    group.bench_function("element_loop_moving", |b| {
        b.iter(|| {
            which = 1 - which;
            sim.positions_mut().copy_from_slice(&states[which]);
            sim.evaluate_forces();
        })
    });
    group.bench_function("forces_and_tangent_assembly", |b| {
        b.iter(|| {
            sim.stiffness(TangentKind::Exact);
        })
    });

    for (name, linear) in [
        ("press_frame_cg", LinearSolver::Cg),
        ("press_frame_direct", LinearSolver::Direct),
    ] {
        group.bench_function(name, |b| {
            b.iter_batched(
                || {
                    let mut sim = base.sim.clone();
                    sim.settings.linear = linear;
                    (sim, base.contact.clone())
                },
                |(mut sim, mut contact)| frame(&base.setup, &mut sim, &mut contact, 2),
                BatchSize::LargeInput,
            )
        });
    }
    group.finish();
}

criterion_group!(benches, fem);
criterion_main!(benches);
