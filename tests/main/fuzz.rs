//! Bounded fuzzing of the input readers: mutated scenario files and mesh
//! files either load or fail with an error — never a panic, never a hang.
//! The seed and the case counts are fixed, so every CI run replays the
//! same corpus; a failure prints the input that caused it.

use crate::common;

use proptest::prelude::*;
use proptest::strategy::ValueTree;
use proptest::test_runner::{Config, RngSeed};

use common::{cube_tetgen, root, write_tetgen_text};

pub(crate) fn config(cases: u32) -> Config {
    Config {
        cases,
        rng_seed: RngSeed::Fixed(0x5eed_2026),
        failure_persistence: None,
        ..Config::default()
    }
}

/// A scenario with every section, on the small shipped mesh, with a 32²
/// microstructure map (larger maps would make each case slow).
fn base_scenario() -> String {
    format!(
        r#"[mesh]
file = {:?}

[material.dermis]
youngs_modulus_kpa = 150.0
poisson_ratio = 0.45

[boundary]
bottom = "fixed"
sides = "rollers"

[probe]
shape = "sphere"
radius_mm = 1.5
path_mm = [[0.0, 0.0, 0.0, 1.5], [0.5, 0.0, 0.0, 1.0], [1.0, 0.5, 0.0, 1.0]]
contact = "coulomb"
friction = 0.8

[solver]
rel_tol = 1e-6
linear = "two-level"
max_inverted_fraction = 0.01

[time]
duration_s = 1.0
frame_rate_hz = 6.0
substeps = 2

[output]
strain_images = true
strain_image_px = 64

[microstructure]
frame_stride = 2

[microstructure.procedural]
size_px = 32
groove_spacing_um = 250.0
groove_depth_um = 30.0
pore_radius_um = 25.0
noise_scale_um = 40.0

[render]
width_px = 64
height_px = 48
modes = ["none"]

[render.camera]
eye_mm = [0.0, -12.0, 9.0]
target_mm = [0.0, 0.5, -1.0]

[[render.lights]]
kind = "directional"
direction = [0.2, -0.75, -0.63]
intensity = 2.2
"#,
        root().join("meshes/patch_3k.node").to_str().unwrap()
    )
}

/// Values that break naive validation: extremes, wrong types, wrong shapes.
const NASTY: [&str; 16] = [
    "0",
    "-1",
    "1e308",
    "-1e308",
    "nan",
    "inf",
    "-inf",
    "1e-300",
    "0.5",
    "18446744073709551615",
    "\"text\"",
    "\"\"",
    "[]",
    "[1.0, 2.0, 3.0, 4.0, 5.0]",
    "true",
    "{ a = 1 }",
];

/// Keys a mutation may add (to any section), with a nasty value.
const KEYS: [&str; 12] = [
    "radius_mm",
    "substeps",
    "frame_rate_hz",
    "poisson_ratio",
    "intensity",
    "direction",
    "eye_mm",
    "texture_px",
    "supersample",
    "friction",
    "strain_image_px",
    "unknown_key",
];

/// One edit of a text, by line: replace a value, drop, duplicate or insert
/// a line, or cut the text short. The mesh `file` line is kept (without
/// it the scenario would generate a mesh with TetGen, too slow here).
#[derive(Clone, Debug)]
enum Edit {
    Value(usize, usize),
    Drop(usize),
    Duplicate(usize),
    Insert(usize, usize, usize),
    Truncate(usize),
}

fn edit() -> impl Strategy<Value = Edit> {
    // Mostly value edits: most others make the TOML itself invalid (a
    // duplicate or unknown key), which stops at the parser.
    prop_oneof![
        8 => (any::<usize>(), 0..NASTY.len()).prop_map(|(l, v)| Edit::Value(l, v)),
        1 => any::<usize>().prop_map(Edit::Drop),
        1 => any::<usize>().prop_map(Edit::Duplicate),
        1 => (any::<usize>(), 0..KEYS.len(), 0..NASTY.len())
            .prop_map(|(l, k, v)| Edit::Insert(l, k, v)),
        1 => any::<usize>().prop_map(Edit::Truncate),
    ]
}

fn apply(text: &str, edits: &[Edit]) -> String {
    let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
    for e in edits {
        if lines.is_empty() {
            break;
        }
        let at = |l: usize| l % lines.len();
        match *e {
            Edit::Value(l, v) => {
                // Among the key = value lines (not the mesh file).
                let values: Vec<usize> = (0..lines.len())
                    .filter(|&k| lines[k].contains(" = ") && !lines[k].starts_with("file"))
                    .collect();
                if let Some(&k) = values.get(l % values.len().max(1)) {
                    let key = lines[k].split_once(" = ").unwrap().0.to_string();
                    lines[k] = format!("{key} = {}", NASTY[v]);
                }
            }
            Edit::Drop(l) => {
                if !lines[at(l)].starts_with("file") {
                    lines.remove(at(l));
                }
            }
            Edit::Duplicate(l) => {
                let line = lines[at(l)].clone();
                lines.insert(at(l), line);
            }
            Edit::Insert(l, k, v) => lines.insert(at(l), format!("{} = {}", KEYS[k], NASTY[v])),
            Edit::Truncate(n) => {
                let joined = lines.join("\n");
                let keep: String = joined.chars().take(n % (joined.len() + 1)).collect();
                if keep.contains("file = ") {
                    lines = keep.lines().map(str::to_string).collect();
                }
            }
        }
    }
    lines.join("\n")
}

proptest! {
    #![proptest_config(config(4000))]

    /// A mutated scenario parses and validates, or is an error; when it
    /// validates, its output plan can be estimated.
    #[test]
    fn mutated_scenarios_never_panic(edits in prop::collection::vec(edit(), 1..3)) {
        let text = apply(&base_scenario(), &edits);
        let path = std::path::Path::new("fuzz.toml");
        if let Ok(scenario) = skinpatch::scenario::Scenario::parse(&text, path) {
            if let Ok(setup) = skinpatch::scenario::Setup::from_scenario(&scenario, path) {
                let _ = skinpatch::pipeline::plan::planned_bytes(&setup);
            }
        }
    }
}

/// Values for mesh-file fields: extremes and garbage.
const MESH_NASTY: [&str; 10] = [
    "0",
    "-1",
    "4000000000",
    "18446744073709551615",
    "nan",
    "1e308",
    "x",
    "",
    "1.5",
    "2 3 4 5 6 7 8 9",
];

/// Replaces field `f` of line `l` with `nasty[v]` (or, for `v` past the
/// list, drops or repeats the line).
pub(crate) fn mutate_lines(text: &str, edits: &[(usize, usize, usize)], nasty: &[&str]) -> String {
    let mut lines: Vec<Vec<String>> = text
        .lines()
        .map(|l| l.split_whitespace().map(str::to_string).collect())
        .collect();
    for &(l, f, v) in edits {
        if lines.is_empty() {
            break;
        }
        let l = l % lines.len();
        match v.checked_sub(nasty.len()) {
            None => {
                if !lines[l].is_empty() {
                    let f = f % lines[l].len();
                    lines[l][f] = nasty[v].to_string();
                }
            }
            Some(0) => {
                lines.remove(l);
            }
            Some(_) => {
                let line = lines[l].clone();
                lines.insert(l, line);
            }
        }
    }
    lines
        .iter()
        .map(|l| l.join(" "))
        .collect::<Vec<_>>()
        .join("\n")
}

fn mesh_edit() -> impl Strategy<Value = Vec<(usize, usize, usize)>> {
    prop::collection::vec(
        (any::<usize>(), any::<usize>(), 0..MESH_NASTY.len() + 2),
        1..4,
    )
}

proptest! {
    #![proptest_config(config(300))]

    /// A mutated TetGen mesh reads or is an error naming the file.
    #[test]
    fn mutated_tetgen_meshes_never_panic(node_edits in mesh_edit(), ele_edits in mesh_edit()) {
        let (node, ele) = cube_tetgen();
        let dir = tempfile::tempdir().unwrap();
        let base = write_tetgen_text(
            dir.path(),
            "cube",
            &mutate_lines(&node, &node_edits, &MESH_NASTY),
            &mutate_lines(&ele, &ele_edits, &MESH_NASTY),
        );
        if let Err(e) = skinpatch::mesh::io::read_tetgen(&base) {
            prop_assert!(e.to_string().contains("cube"), "{}", e);
        }
    }

    /// A mutated Gmsh mesh reads or is an error naming the file.
    #[test]
    fn mutated_gmsh_meshes_never_panic(edits in mesh_edit()) {
        static TEXT: std::sync::OnceLock<String> = std::sync::OnceLock::new();
        let text = TEXT.get_or_init(|| {
            std::fs::read_to_string(root().join("tests/fixtures/two_layer_box.msh")).unwrap()
        });
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("box.msh");
        std::fs::write(&path, mutate_lines(text, &edits, &MESH_NASTY)).unwrap();
        if let Err(e) = skinpatch::mesh::io::read_gmsh(&path) {
            prop_assert!(e.to_string().contains("box.msh"), "{}", e);
        }
    }
}

/// The corpus starts from a scenario that validates, and its mutations
/// reach validation (not just the TOML parser) often enough to matter.
#[test]
fn the_scenario_corpus_reaches_validation() {
    let path = std::path::Path::new("fuzz.toml");
    let scenario = skinpatch::scenario::Scenario::parse(&base_scenario(), path).unwrap();
    skinpatch::scenario::Setup::from_scenario(&scenario, path).unwrap();
    let mut runner = proptest::test_runner::TestRunner::new(config(160));
    let (mut parsed, mut valid) = (0, 0);
    for _ in 0..160 {
        let edits = prop::collection::vec(edit(), 1..3)
            .new_tree(&mut runner)
            .unwrap()
            .current();
        let text = apply(&base_scenario(), &edits);
        if let Ok(s) = skinpatch::scenario::Scenario::parse(&text, path) {
            parsed += 1;
            valid += usize::from(skinpatch::scenario::Setup::from_scenario(&s, path).is_ok());
        }
    }
    // Measured: 32 parse, 13 validate.
    assert!(
        parsed >= 20 && valid >= 8,
        "{parsed} parsed, {valid} valid of 160"
    );
    eprintln!("{parsed} parsed, {valid} valid of 160");
}
