//! Mesh files written by other tools (Gmsh, meshio, VTK; see
//! tests/fixtures/tools/README.md): each reads to the mesher's own counts,
//! and a corpus of mutations of each is read without a panic or a hang,
//! every failure an error that names the file.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use crate::common::{root, Rng};
use skinpatch::mesh::io;

fn tools_dir() -> PathBuf {
    root().join("tests/fixtures/tools")
}

/// The counts Gmsh reported for the mesh (counts.txt).
fn counts() -> BTreeMap<String, usize> {
    std::fs::read_to_string(tools_dir().join("counts.txt"))
        .unwrap()
        .lines()
        .map(|l| {
            let (k, v) = l.split_once(' ').unwrap();
            (k.to_string(), v.parse().unwrap())
        })
        .collect()
}

/// Every mesh file in the folder, sorted.
fn seeds() -> Vec<PathBuf> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(tools_dir())
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| {
            p.extension()
                .is_some_and(|e| e == "msh" || e == "vtu" || e == "vtk")
        })
        .collect();
    files.sort();
    files
}

/// Each tool's file reads to the tets and region sizes Gmsh made; the one
/// that cannot hold the regions (meshio's Gmsh 4.1, without `$Entities`)
/// reads as one region; VTK's LZ4 compression is refused by name.
#[test]
fn tool_files_read_with_the_mesher_counts() {
    let c = counts();
    let files = seeds();
    assert!(files.len() >= 20, "{} files", files.len());
    for path in files {
        let name = path.file_name().unwrap().to_str().unwrap();
        if name == "vtk_lz4.vtu" {
            let err = io::read_mesh(&path).unwrap_err().to_string();
            assert!(
                err.contains(name) && err.contains("vtkLZ4DataCompressor"),
                "{err}"
            );
            continue;
        }
        let mesh = io::read_mesh(&path).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!(mesh.num_tets(), c["tets"], "{name}");
        assert_eq!(mesh.num_vertices(), c["points_in_tets"], "{name}");
        let mut sizes: BTreeMap<i32, usize> = BTreeMap::new();
        for &r in &mesh.tet_region {
            *sizes.entry(r).or_default() += 1;
        }
        if name == "meshio.msh" {
            assert_eq!(sizes.len(), 1, "{name}: {sizes:?}");
            continue;
        }
        assert_eq!(
            sizes,
            BTreeMap::from([(1, c["region_1"]), (2, c["region_2"])]),
            "{name}"
        );
        if name.starts_with("gmsh") {
            let names: Vec<&str> = mesh.regions.iter().map(|r| r.name.as_str()).collect();
            assert_eq!(names, ["dermis", "hypodermis"], "{name}");
        }
    }
}

/// Numbers a careless edit or a broken writer puts in a count or a value.
const NASTY: [&str; 12] = [
    "0",
    "-1",
    "4294967296",
    "18446744073709551615",
    "3000000000",
    "1e308",
    "nan",
    "-0",
    "7",
    "x",
    "",
    "999999999999",
];

/// One mutation of `bytes`: flipped bytes, a cut, a dropped or repeated
/// run, a number replaced, or an XML attribute given a nasty value.
fn mutate(bytes: &[u8], rng: &mut Rng) -> (String, Vec<u8>) {
    let mut out = bytes.to_vec();
    let n = out.len();
    let kind = rng.below(6);
    let what = match kind {
        0 => {
            let k = 1 + rng.below(8);
            for _ in 0..k {
                let at = rng.below(n);
                out[at] ^= 1 << rng.below(8);
            }
            format!("{k} bits flipped")
        }
        1 => {
            let at = rng.below(n);
            out.truncate(at);
            format!("cut at byte {at}")
        }
        2 => {
            let at = rng.below(n);
            let len = 1 + rng.below(64).min(n - at - 1);
            out.drain(at..at + len);
            format!("{len} bytes dropped at {at}")
        }
        3 => {
            let at = rng.below(n);
            let len = 1 + rng.below(64).min(n - at - 1);
            let run = out[at..at + len].to_vec();
            out.splice(at..at, run);
            format!("{len} bytes repeated at {at}")
        }
        _ => {
            // A run of ASCII digits (a count, an id, an offset, a size)
            // replaced by a nasty number.
            let starts: Vec<usize> = (0..n)
                .filter(|&i| {
                    out[i].is_ascii_digit() && (i == 0 || !out[i - 1].is_ascii_alphanumeric())
                })
                .collect();
            if starts.is_empty() {
                return ("unchanged".into(), out);
            }
            let at = starts[rng.below(starts.len())];
            let end = (at..n).find(|&i| !out[i].is_ascii_digit()).unwrap_or(n);
            let nasty = NASTY[rng.below(NASTY.len())];
            out.splice(at..end, nasty.bytes());
            format!("number at byte {at} set to '{nasty}'")
        }
    };
    (what, out)
}

/// How one case ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
enum Outcome {
    Read,
    Clear,
    Unclear,
    Panic,
    Hang,
}

fn outcome(path: &Path) -> (Outcome, String) {
    let name = path.file_name().unwrap().to_str().unwrap().to_string();
    let start = Instant::now();
    let result = std::panic::catch_unwind(|| io::read_mesh(path));
    let slow = start.elapsed() > Duration::from_secs(5);
    match result {
        Err(_) => (Outcome::Panic, "panicked".into()),
        _ if slow => (Outcome::Hang, format!("took {:?}", start.elapsed())),
        Ok(Ok(_)) => (Outcome::Read, String::new()),
        Ok(Err(e)) => {
            let text = e.to_string();
            if clear(&text, &name) {
                (Outcome::Clear, text)
            } else {
                (Outcome::Unclear, text)
            }
        }
    }
}

/// Whether an error message is one a user can act on: it names the file
/// and a place in it — a line (`file:12:`), a byte, or the cell, point,
/// array, element or section at fault — and shows no dependency's debug
/// value (`Foo { .. }`, `Bar(Baz(..))`).
fn clear(text: &str, name: &str) -> bool {
    let Some(at) = text.find(name) else {
        return false;
    };
    let after = &text[at + name.len()..];
    let line = after.starts_with(':') && after[1..].starts_with(|c: char| c.is_ascii_digit());
    let place = [
        "byte ",
        "cell ",
        "point",
        "tet ",
        "element",
        "node ",
        "array '",
        "DataArray '",
        "region",
        "section",
        "keyword",
        "<",
        "Points",
        "CELLS",
        "POINTS",
        "tetrahedr",
        "triangle",
        "tets",
    ]
    .iter()
    .any(|w| after.contains(w));
    let debug = text.contains(" { ") || text.contains("((") || text.contains("error: ");
    (line || place) && !debug
}

/// Mutations per seed file (22 seeds: Gmsh 4.1/2.2 text and binary from
/// Gmsh and meshio, VTU appended raw/base64, inline, ASCII, zlib or not,
/// UInt32/UInt64 headers, legacy VTK 4.2/5.1 ASCII and binary).
const CASES_PER_SEED: usize = 60;

/// Every case reads or fails with an error naming the file, in its own
/// words; none panics or takes over 5 s. The table is printed for the
/// record.
#[test]
fn mutated_tool_files_never_panic_or_hang() {
    let dir = tempfile::tempdir().unwrap();
    let mut rng = Rng(0x5eed_0058);
    let mut table: BTreeMap<String, BTreeMap<Outcome, usize>> = BTreeMap::new();
    let mut bad = Vec::new();
    // SKINPATCH_CORPUS_LOG=file: every case's outcome and message, one a
    // line, for the record.
    let log = std::env::var_os("SKINPATCH_CORPUS_LOG").map(|p| std::fs::File::create(p).unwrap());
    for seed in seeds() {
        let bytes = std::fs::read(&seed).unwrap();
        let ext = seed.extension().unwrap().to_str().unwrap().to_string();
        let stem = seed
            .file_name()
            .unwrap()
            .to_str()
            .unwrap()
            .replace('.', "_");
        for k in 0..CASES_PER_SEED {
            let (what, mutated) = mutate(&bytes, &mut rng);
            let path = dir.path().join(format!("{stem}_{k}.{ext}"));
            std::fs::write(&path, &mutated).unwrap();
            let (o, text) = outcome(&path);
            *table.entry(stem.clone()).or_default().entry(o).or_default() += 1;
            if let Some(log) = &log {
                use std::io::Write;
                let text = text.replace(dir.path().to_str().unwrap(), "");
                writeln!(&*log, "{stem}\t{k}\t{o:?}\t{what}\t{text}").unwrap();
            }
            if o >= Outcome::Unclear {
                bad.push(format!("{stem} case {k} ({what}): {o:?}: {text}"));
            }
            std::fs::remove_file(&path).unwrap();
        }
    }
    let mut total: BTreeMap<Outcome, usize> = BTreeMap::new();
    eprintln!("{:<36} read clear unclear panic hang", "seed");
    for (seed, row) in &table {
        let get = |o| row.get(&o).copied().unwrap_or(0);
        eprintln!(
            "{seed:<36} {:>4} {:>5} {:>7} {:>5} {:>4}",
            get(Outcome::Read),
            get(Outcome::Clear),
            get(Outcome::Unclear),
            get(Outcome::Panic),
            get(Outcome::Hang)
        );
        for (o, n) in row {
            *total.entry(*o).or_default() += n;
        }
    }
    eprintln!("total {total:?}");
    assert!(
        bad.is_empty(),
        "{} bad cases:\n{}",
        bad.len(),
        bad.join("\n")
    );
}
