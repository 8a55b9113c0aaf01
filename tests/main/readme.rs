//! Every command in the shell blocks of the README and the docs
//! ([`DOCS`]), kept in sync with a list here: each is run as written (in a
//! scratch folder holding copies of the examples, fixtures and meshes it
//! reads), run with arguments that make it small (stated), or named with
//! the reason it is not run and the test that covers it. A command added to
//! a page without a line here fails the test, and so does a line here that
//! no page has any more.

use std::path::{Path, PathBuf};
use std::process::Command;

use crate::common::root;

/// What this test does with a README command.
enum How {
    /// Run it as written.
    AsWritten,
    /// Run it with these arguments appended (a smaller case of the same).
    Smaller(&'static [&'static str]),
    /// Not run, for this reason.
    Skip(&'static str),
}

/// Every command of the README's `sh` blocks (continuation lines joined,
/// comments dropped), in order, with what the test does with it.
const COMMANDS: &[(&str, How)] = &[
    (
        "cargo run --release -- run examples/press.toml",
        How::Smaller(&["--set", "time.duration_s=0.05"]),
    ),
    (
        "apt-get install g++ mesa-vulkan-drivers",
        How::Skip("system packages (.ci/run installs them)"),
    ),
    ("cargo test --release", How::Skip("the command that runs this test")),
    (
        "cargo install --path .",
        How::Skip("installs the binary this suite runs from target/ (a full release build)"),
    ),
    (
        "python3 -m pip install ./python pytest && python3 -m pytest python/tests",
        How::Skip("the Python tests: .ci/run runs them after this suite (python/tests/test_readme.py runs the README's Python example)"),
    ),
    (
        "python3 -m pip install ./python",
        How::Skip("builds and installs the wheel, as .ci/run does before the Python tests"),
    ),
    (
        "pip install ./python",
        How::Skip("python/README.md's form of the install above"),
    ),
    (
        "skinpatch run examples/press.toml --set output.surface_glb=true",
        How::Skip("the main job with one more output; dcc_outputs::* write and check surface.glb"),
    ),
    (
        "blender --python examples/python/blender_load.py -- out/press",
        How::Skip("needs Blender; python/tests run the loader outside Blender"),
    ),
    (
        "skinpatch synth benches/synth_1024.toml -o /tmp/s",
        How::Skip("a synthesis benchmark (PERFORMANCE.md); synth::* run synthesis files"),
    ),
    (
        "skinpatch synth benches/synth_1024.toml -o /tmp/s --set synthesis.pca_dims=0",
        How::Skip("a synthesis benchmark (PERFORMANCE.md)"),
    ),
    (
        "skinpatch synth benches/synth_1024.toml -o /tmp/s --set synthesis.mesostructure_generated.extent_mm=10.24 --set synthesis.mesostructure_generated.skin.size_px=2048",
        How::Skip("a synthesis benchmark (PERFORMANCE.md)"),
    ),
    (
        "skinpatch synth benches/synth_1024.toml -o /tmp/s --set synthesis.mesostructure_generated.extent_mm=20.48 --set synthesis.mesostructure_generated.skin.size_px=4096",
        How::Skip("a synthesis benchmark (PERFORMANCE.md)"),
    ),
    (
        "xvfb-run -a -s \"-screen 0 1920x1080x24\" skinpatch view examples/press.toml --script examples/scripts/press_session.toml --width 1920 --height 1080",
        How::Skip("a viewer benchmark (PERFORMANCE.md); viewer::* run scripted sessions"),
    ),
    (
        "cargo run --release --example step_timing -- examples/press.toml",
        How::Skip("the Python layer's benchmark, the main job (PERFORMANCE.md)"),
    ),
    (
        "python3 examples/python/step_timing.py examples/press.toml",
        How::Skip("the same benchmark from Python; python/tests run the examples"),
    ),
    (
        "skinpatch run <scenario.toml> [--output DIR] [--force] [--set KEY=VALUE]… [--quiet]",
        How::Skip("usage line"),
    ),
    (
        "skinpatch mesh [--scenario FILE] [flags] [--out BASE]",
        How::Skip("usage line"),
    ),
    ("skinpatch mesh --input FILE", How::Skip("usage line")),
    (
        "skinpatch mesh --input FILE --renumber --out BASE",
        How::Skip("usage line"),
    ),
    (
        "skinpatch bench fem [--scenario FILE] [--frames N]",
        How::Skip("usage line; cli::bench_fem_compares_solvers runs it"),
    ),
    (
        "skinpatch bench micro [--sizes 1024,2048,4096] [--frames N] [--texel-um 10 [--tile 4096]] [--bandwidth-gbs B] [--raster-step N]",
        How::Skip("usage line; gpu::bench_micro_profiles_every_stage runs it"),
    ),
    (
        "skinpatch tiles split <map.exr|png> -o DIR [--tile 4096] | tiles join DIR -o <map.exr|png>",
        How::Skip("usage line; cli::tiles_split_and_join_round_trip runs both"),
    ),
    (
        "skinpatch bench render [--width 1920 --height 1080] [--frames N]",
        How::Skip("usage line; render::bench_render_reports_timings runs it"),
    ),
    (
        "skinpatch bench gpu [--quick] [--report gpu-report.json]",
        How::Skip("usage line; cli::bench_gpu_quick_writes_every_part_of_the_report runs it"),
    ),
    (
        "skinpatch view <scenario.toml> [--script FILE] [--exit-after S] [--record-dir DIR] [--width PX --height PX]",
        How::Skip("usage line"),
    ),
    (
        "skinpatch fit <samples.toml>",
        How::Skip("usage line; doors::fit_never_writes_over_its_inputs runs it"),
    ),
    (
        "skinpatch synth <synth.toml> [--output DIR] [--set KEY=VALUE]…",
        How::Skip("usage line; synth::a_synthesis_file_writes_maps_preview_and_report runs it"),
    ),
    ("skinpatch gpu-info", How::AsWritten),
    ("skinpatch --help", How::AsWritten),
    ("skinpatch mesh --help", How::AsWritten),
    (
        "cargo run --release -- view examples/press.toml",
        How::Skip("an interactive window; viewer::* drive it by script under a virtual display"),
    ),
    (
        "xvfb-run -a skinpatch view examples/press.toml --script examples/scripts/press_session.toml --width 1920 --height 1080",
        How::Skip("a 1920 × 1080 session on a software GPU takes minutes; viewer::* run scripted sessions, fuzz_doors loads this script"),
    ),
    (
        "for mu in 0.1 0.2 0.4 0.8; do echo \"$mu\"; done | xargs -P 4 -I{} skinpatch run examples/press.toml --quiet --set probe.friction={} --output out/sweep/mu_{}",
        How::Skip("four main jobs; the same `run` with --set and --output runs above"),
    ),
    (
        "skinpatch mesh --scenario meshes/patch_25k.toml --out meshes/patch_25k",
        How::AsWritten,
    ),
    (
        "skinpatch mesh --width-mm 6 --depth-mm 6 --top-layer-mm 1 --bottom-layer-mm 2 --refine-sphere 0.5,0,0.8 --refine-max-volume-mm3 0.0005 --out my_patch",
        How::AsWritten,
    ),
    (
        "skinpatch mesh --input meshes/hertz_block.node --edges-within 0,0,0,0.7",
        How::AsWritten,
    ),
    (
        "skinpatch mesh --input my_mesh.msh --renumber --out my_mesh_banded",
        How::Skip("the user's own mesh; cli::mesh_renumbers_a_loaded_file renumbers one"),
    ),
    (
        "apt-get install libhdf5-dev pkg-config",
        How::Skip("a system package (CI installs it)"),
    ),
    (
        "cargo run --release --features vtkhdf -- run examples/press.toml --set output.frames_vtkhdf=true",
        How::Skip("needs the vtkhdf build; tests/vtkhdf.rs runs it in CI"),
    ),
    (
        "cargo run --release -- run examples/surface.toml",
        How::Skip("25 rendered frames (~45 s); surface::animated_gltf_surface_renders_with_dynamic_microstructure runs the same surface"),
    ),
    (
        "cargo run --release --example press_api",
        How::Skip("the full main job; the line below runs the example on patch_3k"),
    ),
    (
        "cargo run --release --example press_api -- --dermis-kpa 75 --mesh meshes/patch_3k.node",
        How::AsWritten,
    ),
    ("cargo run --release --example probe_control", How::AsWritten),
    (
        "cargo run --release -- run examples/closeup.toml",
        How::Smaller(&["--set", "time.duration_s=0.1"]),
    ),
    ("skinpatch fit examples/fit/samples.toml", How::AsWritten),
    ("cargo run --release --example fit_samples", How::AsWritten),
    (
        "cargo run --release --example probe_control -- --force-n 0.02 --mesh meshes/patch_3k.node --out out/probe_control",
        How::AsWritten,
    ),
];

/// The pages whose `sh` blocks hold commands a reader types.
pub(crate) const DOCS: &[&str] = &[
    "README.md",
    "ARCHITECTURE.md",
    "docs/API.md",
    "docs/GUIDE.md",
    "docs/PERFORMANCE.md",
    "docs/REFERENCES.md",
    "docs/SCENARIO.md",
    "docs/SYNTHESIS.md",
    "docs/VERIFICATION.md",
    "meshes/README.md",
    "python/README.md",
];

/// The commands of every page's `sh` blocks, page by page.
fn readme_commands() -> Vec<String> {
    DOCS.iter()
        .flat_map(|page| {
            let text = std::fs::read_to_string(root().join(page))
                .unwrap_or_else(|e| panic!("{page}: {e}"));
            sh_commands(&text)
        })
        .collect()
}

/// The commands of `text`'s `sh` blocks: continuation lines joined,
/// comments and blank lines dropped, several commands on one line (`a, b`
/// in the synopsis) split.
fn sh_commands(text: &str) -> Vec<String> {
    let mut commands = Vec::new();
    let mut in_sh = false;
    let mut pending = String::new();
    for line in text.lines() {
        if let Some(tag) = line.strip_prefix("```") {
            in_sh = !in_sh && tag.trim() == "sh";
            continue;
        }
        if !in_sh {
            continue;
        }
        let code = match line.find(" #") {
            Some(i) => &line[..i],
            None if line.trim_start().starts_with('#') => "",
            None => line,
        };
        let code = code.trim();
        if let Some(start) = code.strip_suffix('\\') {
            pending.push_str(start.trim());
            pending.push(' ');
            continue;
        }
        if code.ends_with('|') {
            // A pipe continues on the next line.
            pending.push_str(code);
            pending.push(' ');
            continue;
        }
        pending.push_str(code);
        let whole = std::mem::take(&mut pending);
        let whole = whole.trim();
        if whole.is_empty() {
            continue;
        }
        if whole.starts_with("skinpatch --help, ") {
            commands.extend(whole.split(", ").map(str::to_string));
        } else {
            commands.push(whole.split_whitespace().collect::<Vec<_>>().join(" "));
        }
    }
    commands
}

/// The pages and the list above name the same commands.
#[test]
fn the_list_matches_the_readme() {
    let readme = readme_commands();
    let listed: Vec<&str> = COMMANDS.iter().map(|(c, _)| *c).collect();
    for c in &readme {
        assert!(
            listed.contains(&c.as_str()),
            "a command of the docs is not in tests/main/readme.rs: {c:?}"
        );
    }
    for c in &listed {
        assert!(
            readme.iter().any(|r| r == c),
            "tests/main/readme.rs lists a command no page has any more: {c:?}"
        );
    }
}

/// A scratch copy of what the commands read: `examples/`, `tests/fixtures/`
/// and `meshes/` (copied, so that a command writing into them leaves the
/// repository alone).
fn scratch() -> tempfile::TempDir {
    fn copy_dir(from: &Path, to: &Path) {
        std::fs::create_dir_all(to).unwrap();
        for entry in std::fs::read_dir(from).unwrap() {
            let entry = entry.unwrap();
            let target = to.join(entry.file_name());
            if entry.file_type().unwrap().is_dir() {
                copy_dir(&entry.path(), &target);
            } else {
                std::fs::copy(entry.path(), target).unwrap();
            }
        }
    }
    let dir = tempfile::tempdir().unwrap();
    for sub in ["examples", "tests/fixtures", "meshes"] {
        copy_dir(&root().join(sub), &dir.path().join(sub));
    }
    dir
}

/// The program and arguments of a command: `cargo run --release [--example
/// E] -- args` runs the binary (or example) that `cargo test` built.
pub(crate) fn program(command: &str) -> (PathBuf, Vec<String>) {
    let words: Vec<String> = command.split_whitespace().map(str::to_string).collect();
    let built = |name: &str, sub: &str| {
        // target/<profile>/deps/main-… → target/<profile>/[examples/]name
        let exe = std::env::current_exe().unwrap();
        let profile = exe.parent().and_then(Path::parent).unwrap().to_path_buf();
        let dir = if sub.is_empty() {
            profile
        } else {
            profile.join(sub)
        };
        dir.join(format!("{name}{}", std::env::consts::EXE_SUFFIX))
    };
    match words.first().map(String::as_str) {
        Some("skinpatch") => (
            PathBuf::from(env!("CARGO_BIN_EXE_skinpatch")),
            words[1..].to_vec(),
        ),
        Some("cargo") => {
            let dashes = words.iter().position(|w| w == "--");
            let args = dashes.map_or(Vec::new(), |i| words[i + 1..].to_vec());
            match words.iter().position(|w| w == "--example") {
                Some(i) => (built(&words[i + 1], "examples"), args),
                None => (PathBuf::from(env!("CARGO_BIN_EXE_skinpatch")), args),
            }
        }
        _ => panic!("no runner for {command:?}"),
    }
}

/// Every command marked to run runs and exits 0.
#[test]
fn readme_commands_run() {
    let dir = scratch();
    let mut ran = 0;
    let mut no_gpu: Vec<&str> = Vec::new();
    let gpu_required = skinpatch::gpu::gpu_required();
    for (command, how) in COMMANDS {
        let extra: &[&str] = match how {
            How::AsWritten => &[],
            How::Smaller(extra) => extra,
            How::Skip(why) => {
                assert!(!why.is_empty(), "{command}: a skip says why");
                eprintln!("not run: {command} ({why})");
                continue;
            }
        };
        let (exe, mut args) = program(command);
        args.extend(extra.iter().map(|s| s.to_string()));
        let o = Command::new(&exe)
            .args(&args)
            .current_dir(dir.path())
            .env("XDG_RUNTIME_DIR", std::env::temp_dir())
            .output()
            .unwrap_or_else(|e| panic!("{command}: {} does not run: {e}", exe.display()));
        let stderr = String::from_utf8_lossy(&o.stderr);
        if !o.status.success() && !gpu_required && stderr.contains("no Vulkan adapter") {
            // A command that renders (or lists adapters) on a machine
            // without a Vulkan driver: it stopped before any work with the
            // error that says what to install.
            crate::common::skip(&format!("{command}: no Vulkan adapter here"));
            no_gpu.push(*command);
            continue;
        }
        assert!(
            o.status.success(),
            "README command failed: {command} {extra:?}\nstdout: {}\nstderr: {stderr}",
            String::from_utf8_lossy(&o.stdout),
        );
        ran += 1;
    }
    assert_eq!(ran + no_gpu.len(), 13);
    // What the commands promise to leave behind, and the command that writes it.
    for (file, by) in [
        ("out/press/metrics.csv", "examples/press.toml"),
        ("meshes/patch_25k.node", "meshes/patch_25k"),
        ("my_patch.node", "my_patch"),
        ("my_patch.vtu", "my_patch"),
        ("out/probe_control/metrics.csv", "out/probe_control"),
        (
            "out/closeup/render/comparison/frame_0003.png",
            "examples/closeup.toml",
        ),
        ("out/fit/kernel.toml", "examples/fit/samples.toml"),
    ] {
        if no_gpu.iter().any(|c| c.ends_with(by)) {
            continue;
        }
        assert!(dir.path().join(file).exists(), "{file}");
    }
    // The sample maps regenerate to the shipped bytes.
    for name in ["neutral.png", "stretched_115.png", "compressed_085.png"] {
        let made = std::fs::read(dir.path().join("examples/fit").join(name)).unwrap();
        let shipped = std::fs::read(root().join("examples/fit").join(name)).unwrap();
        assert!(
            made == shipped,
            "examples/fit/{name} regenerates differently"
        );
    }
}
