//! Every documented range holds at its ends: each numeric scenario key
//! with an accepted range (docs/SCENARIO.md's "accepted" column, made from
//! the same schema the validation reads) is run at each end the range
//! includes, all other keys as in a small scenario. A run at an end must
//! finish with finite metrics, or be refused with the message listed here
//! for it; the few ends too large for a test run (a 16384² map, 10,000
//! load steps a frame) are listed with their reason and must pass the
//! validation. A key added with a range is run at its ends without being
//! listed anywhere. `SKINPATCH_RANGES=text` runs only the keys containing
//! it; `SKINPATCH_RANGES_PRINT=1` prints each case's scenario.

use std::path::Path;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;

use skinpatch::scenario::{reference, Scenario};

use crate::common::{self, root, text};

/// What an end must do when it is not simply run.
enum Expect {
    /// Refused by the run with an error containing this text.
    Refused(&'static str),
    /// Validated only: a run would take minutes or gigabytes (the reason).
    Heavy(&'static str),
}

/// The ends that do not simply run: (dotted key, `<region>` for a
/// material, end, expectation).
const EXCEPTIONS: &[(&str, f64, Expect)] = &[
    (
        "mesh.target_tets",
        1.0,
        Expect::Refused("could not reach 1 ± 5% tets (mesh.target_tets"),
    ),
    // With the small generated inputs here, the other limits of synthesis
    // speak first; each message names what to change.
    (
        "microstructure.synthesis.levels",
        8.0,
        Expect::Refused(
            "at pyramid level 0 it has 1 × 1 texels, the window is 5 × 5; use fewer levels",
        ),
    ),
    (
        "microstructure.synthesis.exemplar_generated.skin.size_px",
        1.0,
        Expect::Refused("synthesis.exemplar is too small"),
    ),
    (
        "microstructure.synthesis.mesostructure_generated.skin.size_px",
        1.0,
        Expect::Refused("wider than the largest map"),
    ),
    (
        "microstructure.synthesis.mesostructure_generated.extent_mm",
        1000.0,
        Expect::Refused(
            "each side must be in 1 … 32768; the output covers the mesostructure map: use a smaller map",
        ),
    ),
    (
        "solver.max_linear_iterations",
        1.0,
        Expect::Refused("solver.max_linear_iterations"),
    ),
    (
        "solver.max_newton_iterations",
        1.0,
        Expect::Refused("solver.max_newton_iterations = 1 is fewer than"),
    ),
    (
        "time.substeps",
        10000.0,
        Expect::Heavy("20,000 Newton solves (40 s on two cores)"),
    ),
    (
        "output.strain_image_px",
        8192.0,
        Expect::Heavy("three 8192² strain images a frame (45 s)"),
    ),
    (
        "render.texture_px",
        8192.0,
        Expect::Heavy("an 8192² texture-space render a frame (25 s on lavapipe)"),
    ),
    (
        "microstructure.procedural.size_px",
        16384.0,
        Expect::Heavy("a 16384² map, 1 GiB a copy (over 2 min on lavapipe)"),
    ),
    (
        "microstructure.synthesis.size_px",
        32768.0,
        Expect::Heavy("a 32768² synthesized map (hours of synthesis)"),
    ),
    (
        "microstructure.synthesis.exemplar_generated.skin.size_px",
        16384.0,
        Expect::Heavy("a 16384² exemplar to synthesize from"),
    ),
    (
        "microstructure.synthesis.mesostructure_generated.skin.size_px",
        16384.0,
        Expect::Heavy("a 16384² mesostructure map"),
    ),
];

/// The FEM and microstructure keys run on this: patch_3k pressed 0.5 mm
/// in two frames, a 64² procedural map, strain images.
const BASE: &str = r#"
[mesh]
file = "MESH"
[boundary]
bottom = "fixed"
sides = "rollers"
[probe]
shape = "sphere"
radius_mm = 1.5
path_mm = [[0.0, 0.0, 0.0, 1.5], [1.0, 0.0, 0.0, 1.0]]
[time]
duration_s = 1.0
frame_rate_hz = 2.0
[output]
frames_vtu = false
strain_images = true
strain_image_px = 64
[microstructure]
formats = ["png16"]
[microstructure.procedural]
size_px = 64
"#;

/// Added for the `[render]` keys: a 32² render with one light.
const RENDER: &str = r#"
[render]
width_px = 32
height_px = 32
texture_px = 64
shadow_map_px = 64
[render.camera]
[render.environment]
[[render.lights]]
kind = "directional"
direction = [0.5, 0.6, -0.62]
intensity = 2.5
"#;

/// Replaces `[microstructure.procedural]` for the synthesis keys: a 64²
/// map synthesized from a small generated exemplar.
const SYNTHESIS: &str = r#"
[microstructure.synthesis]
size_px = 64
levels = 2
[microstructure.synthesis.exemplar_generated]
extent_mm = 0.64
[microstructure.synthesis.exemplar_generated.skin]
size_px = 64
"#;

/// For the mesostructure keys, in place of the synthesis' `size_px` (the
/// output then covers the mesostructure map).
const MESOSTRUCTURE: &str = r#"
[microstructure.synthesis.mesostructure_generated]
extent_mm = 0.8
[microstructure.synthesis.mesostructure_generated.skin]
size_px = 64
"#;

/// Replaces the mesh file for the `[mesh]` generation keys: a 4 × 4 mm
/// patch of two thin layers.
const GENERATED_MESH: &str = r#"
width_mm = 4.0
depth_mm = 4.0
top_layer_mm = 0.5
bottom_layer_mm = 1.0
top_max_volume_mm3 = 0.05
bottom_max_volume_mm3 = 0.2
"#;

/// Other keys an end needs to take effect (or to be accepted at all).
fn companions(key: &str) -> &'static [(&'static str, &'static str)] {
    match key {
        "material.dermis.poisson_ratio" => &[("material.dermis.volumetric", "\"locking-free\"")],
        "material.dermis.density_kg_m3" | "time.damping_alpha_per_s" | "time.damping_beta_s" => {
            &[("time.integrator", "\"implicit-euler\"")]
        }
        "probe.friction" => &[("probe.contact", "\"coulomb\"")],
        "probe.length_mm" => &[("probe.shape", "\"capsule\"")],
        // The largest sphere, touching the skin at the start.
        "probe.radius_mm" => &[(
            "probe.path_mm",
            "[[0.0, 0.0, 0.0, 100000.0], [1.0, 0.0, 0.0, 99999.5]]",
        )],
        "microstructure.synthesis.window_coarse" => {
            &[("microstructure.synthesis.window_fine", "31")]
        }
        "microstructure.synthesis.window_fine" => {
            &[("microstructure.synthesis.window_coarse", "3")]
        }
        "render.camera.height_mm" => &[("render.camera.projection", "\"orthographic\"")],
        _ => &[],
    }
}

/// One case: a key at one end of its range.
struct Case {
    key: String,
    end: f64,
    integer: bool,
    /// An array value (a colour): every element at the end.
    array: bool,
}

/// The ends a range text includes: `[a, b]`, `[a, b)`, `(a, b]`, `a … b`,
/// `≥ a`, `each …` (arrays, every element at the end).
fn closed_ends(range: &str) -> Vec<f64> {
    let range = range.trim_start_matches("each ").trim();
    let number = |s: &str| {
        s.trim()
            .parse::<f64>()
            .unwrap_or_else(|_| panic!("{range}"))
    };
    if let Some(lo) = range.strip_prefix("≥ ") {
        return vec![number(lo)];
    }
    if range.starts_with('>') || range.starts_with('<') || range.starts_with('≤') {
        return match range.strip_prefix("≤ ") {
            Some(hi) => vec![number(hi)],
            None => Vec::new(),
        };
    }
    if let Some((lo, hi)) = range.split_once(" … ") {
        return vec![number(lo), number(hi)];
    }
    let (lo, hi) = range[1..range.len() - 1].split_once(',').unwrap();
    let mut ends = Vec::new();
    if range.starts_with('[') {
        ends.push(number(lo));
    }
    if range.ends_with(']') {
        ends.push(number(hi));
    }
    ends
}

/// Every closed end of every ranged scenario key.
fn cases() -> Vec<Case> {
    let mut out = Vec::new();
    for table in reference::tables::<Scenario>() {
        let section = table
            .section
            .trim_matches(|c| c == '[' || c == ']')
            .replace("<region>", "dermis")
            .replace("<name>", "dermis");
        for row in &table.rows {
            if row.range.is_empty() || !row.range.chars().any(|c| c.is_ascii_digit()) {
                continue;
            }
            let key = if section.is_empty() {
                row.key.clone()
            } else {
                format!("{section}.{}", row.key)
            };
            for end in closed_ends(&row.range) {
                out.push(Case {
                    key: key.clone(),
                    end,
                    integer: row.kind == "integer",
                    array: row.kind.starts_with('['),
                });
            }
        }
    }
    out
}

/// `value` under the dotted `key` of `doc`, creating tables on the way;
/// in an array of tables, in each of them.
fn set(doc: &mut toml::Table, key: &str, value: toml::Value) {
    let (head, last) = match key.split_once('.') {
        Some((head, rest)) => (head, Some(rest)),
        None => (key, None),
    };
    match last {
        None => {
            doc.insert(head.to_string(), value);
        }
        Some(rest) => match doc
            .entry(head.to_string())
            .or_insert_with(|| toml::Value::Table(toml::Table::new()))
        {
            toml::Value::Table(t) => set(t, rest, value),
            toml::Value::Array(items) => {
                for item in items {
                    if let toml::Value::Table(t) = item {
                        set(t, rest, value.clone());
                    }
                }
            }
            other => panic!("{key}: {other:?} is not a table"),
        },
    }
}

/// The scenario of `case` as TOML.
fn scenario(case: &Case) -> String {
    let mut base = BASE.replace(
        "MESH",
        root().join("meshes/patch_3k.node").to_str().unwrap(),
    );
    if case.key.starts_with("render.") {
        base.push_str(RENDER);
    }
    if case.key.starts_with("microstructure.synthesis.") {
        base = base.replace("[microstructure.procedural]\nsize_px = 64\n", SYNTHESIS);
        if case.key.contains("mesostructure_generated") {
            base = base.replace("size_px = 64\nlevels = 2", "levels = 2") + MESOSTRUCTURE;
        }
    }
    if case.key.starts_with("mesh.") {
        let file = format!("file = {:?}\n", root().join("meshes/patch_3k.node"));
        base = base.replace(&file, GENERATED_MESH);
    }
    let mut doc: toml::Table = toml::from_str(&base).unwrap();
    for (key, value) in companions(&case.key) {
        set(
            &mut doc,
            key,
            toml::from_str(&format!("v = {value}")).map_or_else(
                |e: toml::de::Error| panic!("{e}"),
                |t: toml::Table| t["v"].clone(),
            ),
        );
    }
    let number = if case.integer {
        toml::Value::Integer(case.end as i64)
    } else {
        toml::Value::Float(case.end)
    };
    let value = if case.array {
        // Every element of an array key (a colour) at the end.
        toml::Value::Array(vec![number; 3])
    } else {
        number
    };
    set(&mut doc, &case.key, value);
    toml::to_string(&doc).unwrap()
}

/// Runs `case` in `dir`; `None` when it did what it must, else what it did.
fn check(case: &Case, dir: &Path) -> Option<String> {
    let path = dir.join("scenario.toml");
    std::fs::write(&path, scenario(case)).unwrap();
    let expect = EXCEPTIONS
        .iter()
        .find(|(k, e, _)| *k == case.key && *e == case.end)
        .map(|(_, _, x)| x);
    if let Some(Expect::Heavy(why)) = expect {
        // The file's validation (Setup would build the mesh and the map).
        return Scenario::load(&path)
            .and_then(|s| skinpatch::scenario::bounds::check(&s))
            .err()
            .map(|e| format!("refused by the validation ({why}): {e}"));
    }
    let out = dir.join("out");
    if std::env::var_os("SKINPATCH_RANGES_PRINT").is_some() {
        eprintln!(
            "{}:\n{}",
            path.display(),
            std::fs::read_to_string(&path).unwrap()
        );
    }
    let o = common::binary()
        .args([
            "run",
            "-q",
            path.to_str().unwrap(),
            "-o",
            out.to_str().unwrap(),
        ])
        .output()
        .expect("the skinpatch binary runs");
    let stderr = text(&o.stderr);
    match expect {
        Some(Expect::Refused(message)) => (o.status.success()
            || !stderr.contains(message)
            || stderr.contains("panicked"))
        .then(|| {
            format!(
                "exit {:?}, expected an error with {message:?}: {stderr}",
                o.status.code()
            )
        }),
        _ if !o.status.success() => Some(format!("exit {:?}: {stderr}", o.status.code())),
        _ => {
            let metrics = std::fs::read_to_string(out.join("metrics.csv")).unwrap_or_default();
            let bad = metrics.to_ascii_lowercase();
            (metrics.lines().count() < 2 || bad.contains("nan") || bad.contains("inf"))
                .then(|| format!("metrics not finite:\n{metrics}"))
        }
    }
}

#[test]
fn every_documented_range_holds_at_its_ends() {
    let cases = cases();
    // Keys from every part of the scenario, at both ends.
    for key in [
        "material.dermis.poisson_ratio",
        "time.damping_beta_s",
        "render.width_px",
        "mesh.target_tets",
        "microstructure.synthesis.window_fine",
    ] {
        assert!(cases.iter().any(|c| c.key == key), "{key} has no case");
    }
    for (key, end, _) in EXCEPTIONS {
        assert!(
            cases.iter().any(|c| c.key == *key && c.end == *end),
            "{key} = {end} is listed but is no end of a documented range"
        );
    }
    // `SKINPATCH_RANGES=text` runs only the keys containing it.
    let only = std::env::var("SKINPATCH_RANGES").unwrap_or_default();
    let cases: Vec<Case> = cases
        .into_iter()
        .filter(|c| c.key.contains(&only))
        .collect();
    let next = AtomicUsize::new(0);
    let failures = Mutex::new(Vec::new());
    let dir = tempfile::tempdir().unwrap();
    std::thread::scope(|scope| {
        for _ in 0..2 {
            scope.spawn(|| loop {
                let i = next.fetch_add(1, Ordering::Relaxed);
                let Some(case) = cases.get(i) else { break };
                let case_dir = dir.path().join(i.to_string());
                std::fs::create_dir_all(&case_dir).unwrap();
                if let Some(why) = check(case, &case_dir) {
                    failures
                        .lock()
                        .unwrap()
                        .push(format!("{} = {}: {why}", case.key, case.end));
                }
            });
        }
    });
    let failures = failures.into_inner().unwrap();
    assert!(
        failures.is_empty(),
        "{} of {} ends fail:\n{}",
        failures.len(),
        cases.len(),
        failures.join("\n\n")
    );
}
