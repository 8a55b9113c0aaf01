//! `skinpatch view` end to end: a scripted session under a virtual X
//! display (xvfb-run) with the software Vulkan driver presses and drags
//! the probe, switches modes and overlays, takes screenshots and saves its
//! path, which `skinpatch run` then replays. Without xvfb-run the session
//! test is skipped with a note unless `SKINPATCH_REQUIRE_XVFB=1`.
#![cfg(feature = "viewer")]

use crate::common;

use std::path::Path;
use std::process::Command;

use skinpatch::render::camera::Camera;
use skinpatch::scenario::Setup;

use common::binary as skinpatch;

fn xvfb_run() -> Option<Command> {
    let found = Command::new("xvfb-run")
        .arg("--help")
        .output()
        .is_ok_and(|o| o.status.success() || !o.stdout.is_empty() || !o.stderr.is_empty());
    if found {
        let mut c = Command::new("xvfb-run");
        c.args(["-a", "-s", "-screen 0 1280x800x24"]);
        c.arg(env!("CARGO_BIN_EXE_skinpatch"));
        return Some(c);
    }
    let required = std::env::var("SKINPATCH_REQUIRE_XVFB").is_ok_and(|v| v == "1");
    assert!(
        !required,
        "SKINPATCH_REQUIRE_XVFB=1 but xvfb-run is not installed"
    );
    crate::common::skip("xvfb-run not found: viewer session (apt-get install xvfb)");
    None
}

fn read_rgb(path: &Path) -> (usize, usize, Vec<u8>) {
    let img = image::open(path)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
        .to_rgb8();
    (img.width() as usize, img.height() as usize, img.into_raw())
}

/// Mean absolute difference (8-bit levels, all channels) of two images
/// over the pixels `keep` selects.
fn mean_diff(a: &[u8], b: &[u8], w: usize, keep: impl Fn(usize, usize) -> bool) -> f64 {
    let (mut sum, mut n) = (0.0, 0usize);
    for (k, (pa, pb)) in a.chunks(3).zip(b.chunks(3)).enumerate() {
        if keep(k % w, k / w) {
            sum += pa
                .iter()
                .zip(pb)
                .map(|(x, y)| (*x as f64 - *y as f64).abs())
                .sum::<f64>()
                / 3.0;
            n += 1;
        }
    }
    assert!(n > 0, "no pixels selected");
    sum / n as f64
}

/// Fraction of the pixels `keep` selects whose largest channel change
/// exceeds `levels`.
fn changed_fraction(
    a: &[u8],
    b: &[u8],
    w: usize,
    levels: u8,
    keep: impl Fn(usize, usize) -> bool,
) -> f64 {
    let (mut changed, mut n) = (0usize, 0usize);
    for (k, (pa, pb)) in a.chunks(3).zip(b.chunks(3)).enumerate() {
        if keep(k % w, k / w) {
            n += 1;
            changed += pa.iter().zip(pb).any(|(x, y)| x.abs_diff(*y) > levels) as usize;
        }
    }
    changed as f64 / n.max(1) as f64
}

/// The probe force of every row of a metrics.csv.
fn final_force(path: &Path) -> Vec<[f64; 3]> {
    let text = std::fs::read_to_string(path).unwrap();
    text.lines()
        .skip(1)
        .map(|l| {
            let f: Vec<f64> = l
                .split(',')
                .skip(2)
                .take(3)
                .map(|v| v.parse().unwrap())
                .collect();
            [f[0], f[1], f[2]]
        })
        .collect()
}

#[test]
fn missing_display_is_a_clear_error() {
    let out = skinpatch()
        .args(["view", "tests/fixtures/render_small.toml"])
        .env_remove("DISPLAY")
        .env_remove("WAYLAND_DISPLAY")
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(stderr.contains("needs a display"), "{stderr}");
    assert!(stderr.contains("xvfb-run"), "{stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
}

#[test]
fn scripted_session_presses_drags_switches_and_replays() {
    let Some(mut viewer) = xvfb_run() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let shot = |name: &str| d.join(format!("{name}.png"));
    // The probe starts hovering over (0.5, 0); the press goes 0.7 mm deep.
    let script = format!(
        r#"
[[step]]
action = "mode"
mode = "none"
[[step]]
action = "screenshot"
file = "{before}"
[[step]]
action = "press"
at_mm = [0.5, 0.0]
depth_mm = 0.7
[[step]]
action = "screenshot"
file = "{pressed}"
[[step]]
action = "record_start"
[[step]]
action = "drag"
to_mm = [1.0, 0.0]
moves = 2
[[step]]
action = "record_stop"
[[step]]
action = "screenshot"
file = "{none}"
[[step]]
action = "mode"
mode = "static"
[[step]]
action = "screenshot"
file = "{stat}"
[[step]]
action = "overlay"
overlay = "rs"
[[step]]
action = "screenshot"
file = "{overlay}"
[[step]]
action = "screenshot"
file = "{window}"
window = true
[[step]]
action = "save_path"
file = "{recorded}"
[[step]]
action = "quit"
"#,
        before = shot("before").display(),
        pressed = shot("pressed").display(),
        none = shot("none").display(),
        stat = shot("static").display(),
        overlay = shot("overlay").display(),
        window = shot("window").display(),
        recorded = d.join("recorded.toml").display(),
    );
    let script_path = d.join("script.toml");
    std::fs::write(&script_path, script).unwrap();
    let record = d.join("view");
    let out = viewer
        .current_dir(common::root())
        .args([
            "view",
            "tests/fixtures/render_small.toml",
            "--width",
            "700",
            "--height",
            "400",
        ])
        .arg("--script")
        .arg(&script_path)
        .arg("--record-dir")
        .arg(&record)
        .args(["--exit-after", "600"])
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stdout}\n{stderr}");

    // The force rises as the probe presses in: frame 0 hovers, frame 1 is
    // the press, frames 2–3 the drag.
    let forces = final_force(&record.join("metrics.csv"));
    assert_eq!(forces.len(), 4, "{forces:?}");
    assert_eq!(forces[0][2], 0.0);
    assert!(forces[1][2] > 0.02, "the press pushes back: {forces:?}");
    // The drag is resisted along −x (friction).
    assert!(forces[3][0] < -0.01, "{forces:?}");

    // The press changes the image near the probe and not far from it.
    let (w, h, before) = read_rgb(&shot("before"));
    let (_, _, pressed) = read_rgb(&shot("pressed"));
    let setup = Setup::load(&common::root().join("tests/fixtures/render_small.toml")).unwrap();
    let camera: Camera = setup.outputs.render.as_ref().unwrap().camera;
    let m = camera.view_projection(w as f32 / h as f32, camera.target, 40.0);
    let ndc = m.project_point3(glam::Vec3::new(0.5, 0.0, 0.0));
    let (px, py) = (
        (ndc.x + 1.0) * 0.5 * w as f32,
        (1.0 - ndc.y) * 0.5 * h as f32,
    );
    let r = 0.12 * h as f32;
    let near = mean_diff(&before, &pressed, w, |x, y| {
        (x as f32 - px).hypot(y as f32 - py) < r
    });
    let far = mean_diff(&before, &pressed, w, |x, y| {
        (x as f32 - px).hypot(y as f32 - py) > 3.0 * r && y as f32 > py
    });
    assert!(near > 8.0, "near the probe: {near}");
    assert!(
        far < 0.1 * near && far < 2.0,
        "far from it: {far} (near {near})"
    );

    // Switching mode and overlay changes the skin's pixels.
    let (_, _, none) = read_rgb(&shot("none"));
    let (_, _, stat) = read_rgb(&shot("static"));
    let (_, _, overlay) = read_rgb(&shot("overlay"));
    let skin = |_: usize, y: usize| y as f32 > py + r;
    let modes = changed_fraction(&none, &stat, w, 3, skin);
    let coloured = mean_diff(&stat, &overlay, w, |x, y| {
        (x as f32 - px).hypot(y as f32 - py) < 2.0 * r
    });
    assert!(
        modes > 0.01,
        "none vs static: {modes} of the skin's pixels changed"
    );
    assert!(coloured > 5.0, "overlay: {coloured}");

    // The window capture has the window's size, the view on the left and
    // the panel (text on a flat background) on the right.
    let (ww, wh, window) = read_rgb(&shot("window"));
    assert_eq!((ww, wh), (700, 400));
    let view_part: Vec<u8> = window
        .chunks(3 * ww)
        .flat_map(|row| row[..3 * w].to_vec())
        .collect();
    // Encoded by the present shader instead of on the CPU: within a level.
    let same = mean_diff(&view_part, &overlay, w, |_, _| true);
    assert!(same < 0.5, "the window shows the view: {same}");
    let panel_levels: std::collections::BTreeSet<&[u8]> = window
        .chunks(3 * ww)
        .flat_map(|row| row[3 * w..].chunks(3))
        .collect();
    assert!(
        panel_levels.len() > 20,
        "the panel has text: {} colours",
        panel_levels.len()
    );

    // The recording holds the frames shown during the drag (one per new
    // state at least) and, with ffmpeg, their MP4.
    let frames = record.join("frames");
    let pngs = std::fs::read_dir(&frames)
        .unwrap()
        .filter(|e| {
            e.as_ref()
                .unwrap()
                .path()
                .extension()
                .is_some_and(|x| x == "png")
        })
        .count();
    assert!(pngs >= 2, "{pngs} recorded frames");
    let (rw, rh, _) = read_rgb(&frames.join("frame_0000.png"));
    assert_eq!((rw, rh), (w, h));
    let has_ffmpeg = Command::new("ffmpeg").arg("-version").output().is_ok();
    if has_ffmpeg {
        assert!(frames.join("frames.mp4").metadata().unwrap().len() > 0);
    }

    // The saved path replays to the viewer's final force.
    let replay = d.join("replay");
    let run = skinpatch()
        .current_dir(common::root())
        .arg("run")
        .arg(d.join("recorded.toml"))
        .arg("--output")
        .arg(&replay)
        .args(["--set", "render.modes=[\"none\"]", "-q"])
        .output()
        .unwrap();
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let replayed = final_force(&replay.join("metrics.csv"));
    assert_eq!(replayed.len(), forces.len());
    for (a, b) in replayed.iter().zip(&forces) {
        for c in 0..3 {
            let scale = b[0].hypot(b[1]).hypot(b[2]).max(1e-12);
            assert!(
                (a[c] - b[c]).abs() <= 1e-6 * scale,
                "{replayed:?} vs {forces:?}"
            );
        }
    }
}

/// A script that outlives `--exit-after` ends with an error naming the
/// flag and the step, not as a solver failure.
#[test]
fn exit_after_names_itself_not_the_solver() {
    let Some(mut viewer) = xvfb_run() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let script = dir.path().join("wait.toml");
    std::fs::write(
        &script,
        "[[step]]\naction = \"wait\"\nseconds = 600.0\n[[step]]\naction = \"quit\"\n",
    )
    .unwrap();
    let out = viewer
        .current_dir(common::root())
        .args(["view", "tests/fixtures/press_small.toml"])
        .args(["--width", "160", "--height", "120"])
        .arg("--script")
        .arg(&script)
        .arg("--record-dir")
        .arg(dir.path().join("view"))
        .args(["--exit-after", "2"])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{stderr}");
    assert!(
        stderr.contains("--exit-after 2 s ran out with the script still at step 1 of 2")
            && !stderr.contains("solver failed"),
        "{stderr}"
    );
}

/// The shipped viewer scripts parse and pass their checks.
#[test]
fn shipped_scripts_load() {
    let dir = common::root().join("examples/scripts");
    let mut count = 0;
    for entry in std::fs::read_dir(&dir).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_some_and(|e| e == "toml") {
            let scenario = common::root().join("examples/press.toml");
            let script = skinpatch::viewer::script::Script::load(&path, &scenario)
                .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
            assert!(!script.step.is_empty(), "{}", path.display());
            count += 1;
        }
    }
    assert!(count >= 1);
}

/// The viewer's loop without a window, as `skinpatch bench gpu` runs it,
/// on a scenario with a microstructure: it draws frames while the FEM
/// thread solves the playing path, runs the chain on each new state, and
/// presents the renderer's image, sRGB-encoded, to one 8-bit level. Bad
/// arguments are refused by name.
#[test]
fn offscreen_loop_runs_the_chain_and_presents_the_rendered_image() {
    use skinpatch::viewer::offscreen::bench_loop;
    let setup = Setup::load(&common::root().join("tests/fixtures/render_small.toml")).unwrap();
    let e = bench_loop(&setup, (96, 64), 0.0, None)
        .unwrap_err()
        .to_string();
    assert!(e.contains("viewer loop duration"), "{e}");
    let e = bench_loop(&setup, (4, 64), 1.0, None)
        .unwrap_err()
        .to_string();
    assert!(e.contains("viewer loop size"), "{e}");
    if common::context().is_none() {
        return;
    }
    let f = bench_loop(&setup, (96, 64), 1.5, None).unwrap();
    assert_eq!(f.size, (96, 64));
    assert_eq!(f.mode, "dynamic");
    assert!(f.seconds >= 1.5 && f.frames >= 2, "{f:?}");
    assert!(f.fem_frames >= 1, "{f:?}");
    assert!(f.chain_runs >= 1 && f.chain_ms.unwrap() > 0.0, "{f:?}");
    assert!(f.render_ms > 0.0 && f.present_ms > 0.0, "{f:?}");
    assert!(f.present_max_difference <= 1, "{f:?}");
}
