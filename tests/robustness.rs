//! Reliability by class (see README, "What a failed run leaves behind"):
//! wrong physics is an error, not a success; every case asserts the exit
//! status, that the message names the key or frame, and what is left of
//! the outputs.

mod common;

use std::path::Path;
use std::process::{Command, Output};

use common::root;

fn skinpatch(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_skinpatch"))
        .args(args)
        .current_dir(root())
        .output()
        .expect("the skinpatch binary runs")
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

/// Writes `body` (with an `[output]` section pointing at `out`) to a
/// scenario file in `dir` and runs it.
fn run_scenario(dir: &Path, body: &str, out: &Path) -> Output {
    let scenario = dir.join("scenario.toml");
    std::fs::write(
        &scenario,
        format!("{body}\n[output]\ndir = {:?}\n", out.to_str().unwrap()),
    )
    .unwrap();
    skinpatch(&["run", scenario.to_str().unwrap()])
}

/// The column `name` of every row of a metrics file.
fn column(metrics: &str, name: &str) -> Vec<f64> {
    let mut lines = metrics.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let k = header.iter().position(|h| *h == name).unwrap();
    lines
        .map(|l| l.split(',').nth(k).unwrap().parse().unwrap())
        .collect()
}

/// A caliper stretch to 3 with the bottom on rollers squeezes the
/// corotational (linear-in-stretch) patch through itself: with y held and
/// z free, ε_zz = −ν/(1 − ν)·(λ − 1), so the volume ratio
/// J = λ·(1 − ν/(1 − ν)·(λ − 1)) passes 0 at λ = 1/ν (2.22 for ν = 0.45). The run stops at the first frame over
/// `solver.max_inverted_fraction` with an error naming frame and key, and
/// keeps the rows before it; with the limit at 1 it runs on and reports
/// every tet inverted.
fn caliper_stretch(extra_solver: &str) -> String {
    format!(
        "[mesh]\nfile = {:?}\n[boundary]\nbottom = \"rollers\"\nsides = \"rollers\"\n\
         [boundary.caliper]\naxis = \"x\"\nstretch = [[0.0, 1.0], [1.0, 3.0]]\n\
         [solver]\nrel_tol = 1e-4\nmax_newton_iterations = 100\n{extra_solver}\n\
         [time]\nduration_s = 1.0\nframe_rate_hz = 10.0\n",
        root().join("meshes/patch_3k.node").to_str().unwrap()
    )
}

#[test]
fn an_inverted_patch_stops_the_run() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let o = run_scenario(dir.path(), &caliper_stretch(""), &out);
    let stderr = text(&o.stderr);
    assert!(!o.status.success(), "{stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
    for part in [
        "frame 7 ",
        "tets (100.00%) are inverted",
        "solver.max_inverted_fraction",
    ] {
        assert!(stderr.contains(part), "{stderr:?} should contain {part:?}");
    }
    let metrics = std::fs::read_to_string(out.join("metrics.csv")).unwrap();
    let j = column(&metrics, "min_volume_ratio");
    assert_eq!(j.len(), 7, "frames 0–6 are kept: {metrics}");
    assert!(column(&metrics, "inverted_tets").iter().all(|&n| n == 0.0));
    // J of the confined column with ν = 0.45 (both layers) at frame 6
    // (λ = 2.2); the state is homogeneous, so only round-off separates them.
    let expected = 2.2 * (1.0 - 0.45 / 0.55 * 1.2);
    assert!((j[6] - expected).abs() < 1e-3, "J {} vs {expected}", j[6]);

    let out = dir.path().join("on");
    let o = run_scenario(
        dir.path(),
        &caliper_stretch("max_inverted_fraction = 1.0"),
        &out,
    );
    assert!(o.status.success(), "{}", text(&o.stderr));
    assert!(text(&o.stderr).contains("tets are inverted"));
    let metrics = std::fs::read_to_string(out.join("metrics.csv")).unwrap();
    let inverted = column(&metrics, "inverted_tets");
    assert_eq!(inverted.len(), 11);
    assert_eq!(inverted[10], 3085.0, "{metrics}");
    assert!(column(&metrics, "min_volume_ratio")[10] < 0.0);
}

/// The limit is a fraction.
#[test]
fn max_inverted_fraction_is_validated() {
    let dir = tempfile::tempdir().unwrap();
    for bad in ["-0.1", "1.5", "nan"] {
        let out = dir.path().join("out");
        let o = run_scenario(
            dir.path(),
            &format!("[solver]\nmax_inverted_fraction = {bad}\n"),
            &out,
        );
        let stderr = text(&o.stderr);
        assert!(!o.status.success());
        assert!(
            stderr.contains("solver.max_inverted_fraction must be in [0, 1]"),
            "{stderr}"
        );
    }
}
