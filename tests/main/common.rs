//! Helpers shared by the integration tests.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use skinpatch::mesh::generate::{LayerSpec, PatchSpec, RefineZone, ZoneShape};

/// The `skinpatch` binary as a command, started in the crate's folder.
pub fn binary() -> Command {
    let mut command = Command::new(env!("CARGO_BIN_EXE_skinpatch"));
    command.current_dir(root());
    command
}

/// Runs the binary with `args` in the crate's folder.
pub fn skinpatch(args: &[&str]) -> Output {
    binary()
        .args(args)
        .output()
        .expect("the skinpatch binary runs")
}

/// Runs the binary with `args` in `dir`.
pub fn skinpatch_in(dir: &Path, args: &[&str]) -> Output {
    binary()
        .args(args)
        .current_dir(dir)
        .output()
        .expect("the skinpatch binary runs")
}

/// A command's output bytes as text.
pub fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

/// Folder of the crate, for shipped meshes and fixtures.
pub fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// The shipped ~3k-tet two-layer patch (`meshes/patch_3k`).
pub fn patch_3k() -> skinpatch::mesh::TetMesh {
    skinpatch::mesh::io::read_tetgen(&root().join("meshes/patch_3k")).unwrap()
}

/// Records that the running test skipped its check (a tool or an adapter
/// this machine lacks), prints `why` now, and — once per test binary — has
/// the process print the list of skips after libtest's summary, so a run
/// that skipped checks does not read as a clean pass.
pub fn skip(why: &str) {
    use std::sync::{Mutex, Once};
    static SKIPS: Mutex<Vec<String>> = Mutex::new(Vec::new());
    static AT_EXIT: Once = Once::new();
    extern "C" {
        fn atexit(callback: extern "C" fn()) -> std::os::raw::c_int;
    }
    extern "C" fn report() {
        let skips = SKIPS.lock().map(|s| s.clone()).unwrap_or_default();
        eprintln!(
            "\n{} check(s) skipped (the tool or adapter is missing here; CI requires them):",
            skips.len()
        );
        for s in &skips {
            eprintln!("  skipped: {s}");
        }
    }
    let test = std::thread::current()
        .name()
        .unwrap_or("a test")
        .to_string();
    eprintln!("skipped: {why}");
    if let Ok(mut skips) = SKIPS.lock() {
        skips.push(format!("{test}: {why}"));
    }
    // SAFETY: `report` is a plain function that only reads a static; the C
    // library calls it once when the test process exits.
    AT_EXIT.call_once(|| unsafe {
        atexit(report);
    });
}

/// The GPU adapter, or `None` (test skipped with a note) when there is
/// none and a GPU is not required (`SKINPATCH_REQUIRE_GPU=1` makes a
/// missing adapter a failure).
pub fn context() -> Option<skinpatch::gpu::Context> {
    match skinpatch::gpu::acquire() {
        Ok(Some(ctx)) => Some(ctx),
        Ok(None) => {
            skip("no GPU adapter (set SKINPATCH_REQUIRE_GPU=1 to fail instead)");
            None
        }
        Err(e) => panic!("{e}"),
    }
}

/// A two-layer patch spec with small limits so tests stay fast.
pub fn small_patch(refine: Option<RefineZone>) -> PatchSpec {
    PatchSpec {
        width_mm: 4.0,
        depth_mm: 3.0,
        layers: vec![
            LayerSpec {
                name: "dermis".into(),
                id: 1,
                thickness_mm: 1.0,
                max_volume_mm3: 0.05,
            },
            LayerSpec {
                name: "hypodermis".into(),
                id: 2,
                thickness_mm: 1.5,
                max_volume_mm3: 0.2,
            },
        ],
        refine,
        radius_edge_max: 1.5,
        min_dihedral_deg: 0.0,
        target_tets: None,
        target_tolerance: 0.05,
    }
}

/// A refinement zone reaching through the layer interface.
pub fn deep_zone() -> RefineZone {
    RefineZone {
        shape: ZoneShape::Box {
            center_mm: [0.5, -0.25],
            size_mm: [1.5, 1.0, 1.6],
        },
        max_volume_mm3: 0.005,
    }
}

/// The unit cube as six positively oriented tets around the main diagonal, in
/// TetGen text: (.node, .ele) with 1-based numbering and a region attribute.
pub fn cube_tetgen() -> (String, String) {
    let node = "\
# unit cube
8 3 0 0
1 0 0 0
2 1 0 0
3 1 1 0
4 0 1 0
5 0 0 1
6 1 0 1
7 1 1 1
8 0 1 1
";
    let ele = "\
6 4 1
1 1 2 3 7 5
2 1 3 4 7 5
3 1 4 8 7 5
4 1 8 5 7 5
5 1 5 6 7 5
6 1 6 2 7 5
";
    (node.to_string(), ele.to_string())
}

/// Writes `base.node` and `base.ele` into `dir` and returns the base path.
pub fn write_tetgen_text(dir: &Path, name: &str, node: &str, ele: &str) -> PathBuf {
    let base = dir.join(name);
    std::fs::write(dir.join(format!("{name}.node")), node).unwrap();
    std::fs::write(dir.join(format!("{name}.ele")), ele).unwrap();
    base
}

/// Loads the fixture scenario `tests/fixtures/<name>`, edits its text, runs
/// it into a temporary folder and returns the summary with that folder.
pub fn run_fixture(
    name: &str,
    edit: impl Fn(String) -> String,
) -> (skinpatch::pipeline::FemRunSummary, tempfile::TempDir) {
    let fixture = root().join("tests/fixtures").join(name);
    let text = edit(std::fs::read_to_string(&fixture).unwrap());
    let scenario = skinpatch::scenario::Scenario::parse(&text, &fixture).unwrap();
    let mut setup = skinpatch::scenario::Setup::from_scenario(&scenario, &fixture).unwrap();
    let dir = tempfile::tempdir().unwrap();
    setup.outputs.dir = dir.path().to_path_buf();
    (skinpatch::pipeline::run(&setup, |_| {}).unwrap(), dir)
}

/// One tet with its top face at z = 0 (a mesh needs a top surface) and its
/// apex at (0, 0, −1).
pub fn one_tet() -> skinpatch::mesh::TetMesh {
    use skinpatch::mesh::{RawMesh, Vec3};
    let raw = RawMesh {
        positions: vec![Vec3::zeros(), Vec3::y(), Vec3::x(), -Vec3::z()],
        tets: vec![[0, 1, 2, 3]],
        tet_region: vec![1],
        ..Default::default()
    };
    skinpatch::mesh::TetMesh::from_raw("one tet", raw).unwrap()
}

/// Runs the Python `script` (with `args` as `sys.argv[1:]`) that checks
/// our output with an independent reader from the Python package
/// `package`, and returns what it printed. When the package is not
/// installed the check is skipped with a note and `None` returned, unless
/// the environment variable `require_var` is `1` (`.ci/run` sets it): then,
/// as for any failure of the script, the test fails.
pub fn python_check(
    package: &str,
    require_var: &str,
    script: &str,
    args: &[&str],
) -> Option<String> {
    let required = std::env::var(require_var).is_ok_and(|v| v == "1");
    let skip = |why: String| {
        assert!(
            !required,
            "{package} check required ({require_var}=1): {why}"
        );
        skip(&format!(
            "{package} check ({why}; set {require_var}=1 to fail instead)"
        ));
        None
    };
    match std::process::Command::new("python3")
        .arg("-c")
        .arg(script)
        .args(args)
        .output()
    {
        Ok(o) if o.status.success() => Some(String::from_utf8_lossy(&o.stdout).into_owned()),
        Ok(o) => {
            let stderr = String::from_utf8_lossy(&o.stderr).into_owned();
            if stderr.contains("ModuleNotFoundError") {
                skip(format!("the Python package {package} is not installed"))
            } else {
                panic!("{package} disagrees with our output:\n{stderr}")
            }
        }
        Err(e) => skip(format!("python3 does not run: {e}")),
    }
}

/// Writes tests/fixtures/press_small.toml with `extra` appended (mesh path
/// made absolute) into `dir` and runs it with output `dir/out`, after
/// `configure` has adjusted the command (environment).
pub fn run_press_small_configured(
    dir: &Path,
    extra: &str,
    configure: impl FnOnce(&mut Command),
) -> (std::path::PathBuf, Output) {
    let scenario = std::fs::read_to_string(root().join("tests/fixtures/press_small.toml")).unwrap();
    let scenario =
        scenario.replace("../../meshes", root().join("meshes").to_str().unwrap()) + extra;
    let path = dir.join("scenario.toml");
    std::fs::write(&path, scenario).unwrap();
    let out = dir.join("out");
    let mut cmd = binary();
    cmd.args([
        "run",
        path.to_str().unwrap(),
        "--output",
        out.to_str().unwrap(),
    ])
    .current_dir(root());
    configure(&mut cmd);
    (out, cmd.output().expect("the skinpatch binary runs"))
}

/// A deterministic generator (SplitMix64): one sequence per seed on every
/// run and machine (mutation corpora, kill moments).
pub struct Rng(pub u64);

impl Rng {
    pub fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }

    pub fn below(&mut self, n: usize) -> usize {
        (self.next() % n.max(1) as u64) as usize
    }
}
