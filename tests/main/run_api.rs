//! The step-by-step run API (`pipeline::Run`): probe targets set from code
//! reproduce the scripted path, in-memory runs write nothing, a failed frame
//! leaves an in-memory run at its last good state, a writing run stops at
//! its error and at the scenario's end, and the probe_control example stops
//! at its force threshold.

use skinpatch::mesh::Vec3;
use skinpatch::pipeline::{self, Run};
use skinpatch::scenario::Setup;

use crate::common::root;

fn press_small() -> Setup {
    Setup::load(&root().join("tests/fixtures/press_small.toml")).unwrap()
}

/// (probe force, positions) of every frame of `run` stepped `frames` times,
/// with `aim` called before each step.
fn states(
    run: &mut Run<'_>,
    frames: usize,
    mut aim: impl FnMut(&mut Run<'_>, usize),
) -> Vec<([f64; 3], Vec<Vec3>)> {
    (0..frames)
        .map(|k| {
            aim(run, k);
            let frame = run.step().unwrap();
            (frame.metrics.probe_force_n, frame.positions.to_vec())
        })
        .collect()
}

/// Targets at the scenario path's poses, one a frame, solve to the frames
/// of the scripted run: the keyframes (0, 0.5 and 1 s) fall on frame times,
/// so only the interpolation's rounding differs. And the in-memory run is
/// the writing run of `pipeline::run`, bit for bit.
#[test]
fn driven_targets_reproduce_the_scripted_path() {
    let mut setup = press_small();
    let dir = tempfile::tempdir().unwrap();
    setup.outputs.dir = dir.path().join("out");
    let frames = setup.simulation.frames + 1;
    let probe = setup.simulation.probe.clone().unwrap();
    let scripted = states(&mut Run::new(&setup), frames, |_, _| {});
    let dt = setup.simulation.frame_dt;
    let driven = states(&mut Run::new(&setup), frames, |run, k| {
        run.set_probe_target(probe.pose(k as f64 * dt).centre)
            .unwrap()
    });
    let scale = scripted
        .iter()
        .flat_map(|(_, x)| {
            x.iter()
                .zip(&setup.mesh.positions)
                .map(|(p, q)| (p - q).norm())
        })
        .fold(0.0, f64::max);
    assert!(scale > 0.3, "the probe deforms the patch: {scale} mm");
    for (k, (a, b)) in scripted.iter().zip(&driven).enumerate() {
        let dx =
            a.1.iter()
                .zip(&b.1)
                .map(|(p, q)| (p - q).norm())
                .fold(0.0, f64::max);
        assert!(
            dx <= 1e-9 * scale,
            "frame {k}: positions differ by {dx:e} mm"
        );
        for i in 0..3 {
            assert!(
                (a.0[i] - b.0[i]).abs() <= 1e-8 * a.0[2].abs().max(1e-3),
                "frame {k}: force {:?} against {:?}",
                a.0,
                b.0
            );
        }
    }
    let mut written = Vec::new();
    pipeline::run(&setup, |f| {
        written.push((f.metrics.probe_force_n, f.positions.to_vec()))
    })
    .unwrap();
    assert!(
        written == scripted,
        "the writing run differs from the in-memory one"
    );
}

/// An in-memory run writes nothing; its summary holds every frame.
#[test]
fn an_in_memory_run_writes_nothing() {
    let mut setup = press_small();
    let dir = tempfile::tempdir().unwrap();
    setup.outputs.dir = dir.path().join("out");
    let mut run = Run::new(&setup);
    for _ in 0..3 {
        run.step().unwrap();
    }
    let summary = run.finish().unwrap();
    assert_eq!(summary.frames.len(), 3);
    assert!(summary.written.is_empty());
    assert!(!setup.outputs.dir.exists());
}

/// A target the probe cannot reach in one frame fails the step; the
/// in-memory run stays at its last good frame, and stepping on from there
/// gives the frames of a run that never tried it.
#[test]
fn a_failed_frame_leaves_an_in_memory_run_at_its_last_good_state() {
    let setup = press_small();
    let start = setup.simulation.probe.as_ref().unwrap().pose(0.0).centre;
    let press = |run: &mut Run<'_>, k: usize| {
        run.set_probe_target(start - Vec3::z() * (0.2 * k as f64))
            .unwrap()
    };
    let clean = states(&mut Run::new(&setup), 4, press);
    let mut run = Run::new(&setup);
    let mut tried = states(&mut run, 2, press);
    run.set_probe_target(start + Vec3::x() * 1e7).unwrap();
    let err = run.step().err().expect("a 10 km move fails").to_string();
    assert!(err.contains("load steps"), "{err}");
    assert_eq!(run.next_frame(), 2);
    assert_eq!(run.probe_pose().unwrap().centre, start - Vec3::z() * 0.2);
    tried.extend(states(&mut run, 2, |run, k| press(run, k + 2)));
    assert!(tried == clean, "the failed try left a trace");
    // Bad targets are refused when set.
    let err = run
        .set_probe_target(Vec3::new(f64::NAN, 0.0, 0.0))
        .unwrap_err();
    assert!(err.to_string().contains("must be finite"), "{err}");
}

/// A writing run stops at its first failure (what it wrote stays) and
/// writes no more frames than the scenario planned.
#[test]
fn a_writing_run_stops_at_an_error_and_at_the_scenarios_end() {
    let mut setup = press_small();
    let dir = tempfile::tempdir().unwrap();
    setup.outputs.dir = dir.path().join("out");
    let mut run = Run::writing(&setup).unwrap();
    run.step().unwrap();
    run.set_probe_target(Vec3::new(1e7, 0.0, 0.0)).unwrap();
    assert!(run.step().is_err());
    let err = run.step().err().unwrap().to_string();
    assert!(err.contains("stopped at an earlier error"), "{err}");
    run.close_after_error();
    let csv = std::fs::read_to_string(setup.outputs.dir.join("metrics.csv")).unwrap();
    assert_eq!(csv.lines().count(), 2, "header and frame 0:\n{csv}");

    let mut run = Run::writing(&setup).unwrap();
    for _ in 0..=setup.simulation.frames {
        run.step().unwrap();
    }
    let err = run.step().err().unwrap().to_string();
    assert!(err.contains("time.duration_s"), "{err}");
    let summary = run.finish().unwrap();
    assert_eq!(summary.frames.len(), setup.simulation.frames + 1);
    assert!(summary
        .written
        .contains(&setup.outputs.dir.join("metrics.csv")));
}

/// The example presses until the force reaches the threshold and stops
/// there: the last row reaches it, the one before does not; with `--out`
/// it writes a metrics row per frame solved, with the forces it printed.
#[test]
fn probe_control_stops_at_its_force_threshold() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let command = format!(
        "cargo run --release --example probe_control -- --force-n 0.02 --step-mm 0.04 \
         --mesh meshes/patch_3k.node --out {}",
        out.display()
    );
    let (program, args) = crate::readme::program(&command);
    let o = std::process::Command::new(program)
        .args(&args)
        .current_dir(root())
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(
        o.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&o.stderr)
    );
    // Table rows: six numbers, the force third.
    let forces: Vec<f64> = stdout
        .lines()
        .filter_map(|l| {
            let v: Vec<f64> = l
                .split_whitespace()
                .filter_map(|w| w.parse().ok())
                .collect();
            (v.len() == 6 && l.split_whitespace().count() == 6).then(|| v[2])
        })
        .collect();
    let (last, before) = (forces[forces.len() - 1], forces[forces.len() - 2]);
    assert!(last >= 0.02 && before < 0.02, "{forces:?}");
    assert!(stdout.contains("reached"), "{stdout}");
    let csv = std::fs::read_to_string(out.join("metrics.csv")).unwrap();
    assert_eq!(csv.lines().count(), forces.len() + 1, "{csv}");
}

/// Each frame's region volumes are the sums of the tets' volumes `J V₀`
/// (from the frame's strains), with the smallest `J` and the tets below
/// `solver.warn_volume_ratio`; a writing run's `volume.csv` holds the same
/// numbers, bit for bit, one row a frame.
#[test]
fn region_volumes_are_reported_per_frame() {
    let mut setup = press_small();
    setup.simulation.warn_volume_ratio = 0.98;
    let dir = tempfile::tempdir().unwrap();
    setup.outputs.dir = dir.path().join("out");
    let mesh = &setup.mesh;
    let rest: Vec<f64> = mesh
        .tets
        .iter()
        .map(|t| {
            let [a, b, c, d] = t.map(|v| mesh.positions[v]);
            skinpatch::mesh::signed_volume(&a, &b, &c, &d)
        })
        .collect();
    let mut expected = Vec::new();
    let mut counted = 0;
    pipeline::run(&setup, |frame| {
        let strains = frame.strains();
        let mut row = Vec::new();
        for (k, region) in mesh.regions.iter().enumerate() {
            let tets: Vec<usize> = (0..mesh.num_tets())
                .filter(|&t| mesh.tet_region[t] == region.id)
                .collect();
            let v0: f64 = tets.iter().map(|&t| rest[t]).sum();
            let v: f64 = tets
                .iter()
                .map(|&t| strains.tets[t].volume_ratio() * rest[t])
                .sum();
            let j_min = tets
                .iter()
                .map(|&t| strains.tets[t].volume_ratio())
                .fold(f64::INFINITY, f64::min);
            let below = tets
                .iter()
                .filter(|&&t| strains.tets[t].volume_ratio() < 0.98)
                .count();
            let got = &frame.volumes[k];
            assert_eq!(got.name, region.name);
            assert!((got.rest_mm3 - v0).abs() <= 1e-12 * v0);
            assert!(
                (got.change() - (v / v0 - 1.0)).abs() <= 1e-12,
                "frame {}: {} against {}",
                frame.metrics.frame,
                got.change(),
                v / v0 - 1.0
            );
            assert!((got.min_volume_ratio - j_min).abs() <= 1e-12);
            assert_eq!(got.tets_below, below);
            counted += below;
            row.push((got.change(), got.min_volume_ratio, got.tets_below));
        }
        expected.push(row);
    })
    .unwrap();
    assert!(counted > 0, "the press squeezes some tets below 0.98");
    let csv = std::fs::read_to_string(setup.outputs.dir.join("volume.csv")).unwrap();
    let mut lines = csv.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    assert_eq!(header.len(), 2 + 3 * mesh.regions.len());
    assert_eq!(header[2], format!("{}_volume_change", mesh.regions[0].name));
    let rows: Vec<&str> = lines.collect();
    assert_eq!(rows.len(), expected.len());
    for (k, (line, row)) in rows.iter().zip(&expected).enumerate() {
        let cells: Vec<&str> = line.split(',').collect();
        assert_eq!(cells[0], k.to_string());
        for (r, (change, j, below)) in row.iter().enumerate() {
            assert_eq!(cells[2 + 3 * r].parse::<f64>().unwrap(), *change);
            assert_eq!(cells[3 + 3 * r].parse::<f64>().unwrap(), *j);
            assert_eq!(cells[4 + 3 * r].parse::<usize>().unwrap(), *below);
        }
    }
}
