//! Fixed-seed fuzz corpora for the doors beside the scenario path: glTF
//! surfaces (mutations of the shipped GLB's JSON and of its bytes), OBJ
//! sequences, displacement maps (PNG and EXR), tiled-map indexes and
//! viewer scripts, read through the library; and the `synth`, `fit` and
//! `tiles join` commands on mutated inputs, with a pre-filled output
//! folder. Every case either reads or fails with an error that names the
//! file — never a panic, an abort or a hang — and a command leaves its
//! inputs and the files already in its output folder as they were. The
//! seed and the counts are fixed, so every CI run replays the same corpus;
//! a failure prints the case.

use std::path::{Path, PathBuf};

use proptest::prelude::*;
use skinpatch::micro::{DisplacementMap, Edge};

use crate::common::root;
use crate::fuzz::{config, mutate_lines};

/// The shipped animated surface.
fn forehead() -> &'static [u8] {
    static BYTES: std::sync::OnceLock<Vec<u8>> = std::sync::OnceLock::new();
    BYTES.get_or_init(|| std::fs::read(root().join("examples/surfaces/forehead.glb")).unwrap())
}

/// The JSON and binary chunks of a GLB file.
fn glb_chunks(glb: &[u8]) -> (Vec<u8>, Vec<u8>) {
    let word = |at: usize| u32::from_le_bytes(glb[at..at + 4].try_into().unwrap()) as usize;
    let json_len = word(12);
    let json = glb[20..20 + json_len].to_vec();
    let bin_at = 20 + json_len;
    let bin_len = word(bin_at);
    (json, glb[bin_at + 8..bin_at + 8 + bin_len].to_vec())
}

/// A GLB file of a JSON and a binary chunk, each padded to four bytes.
fn glb(json: &[u8], bin: &[u8]) -> Vec<u8> {
    let pad = |n: usize| n.div_ceil(4) * 4;
    let (jl, bl) = (pad(json.len()), pad(bin.len()));
    let mut out = Vec::with_capacity(28 + jl + bl);
    out.extend(b"glTF");
    out.extend(2u32.to_le_bytes());
    out.extend(((28 + jl + bl) as u32).to_le_bytes());
    out.extend((jl as u32).to_le_bytes());
    out.extend(b"JSON");
    out.extend(json);
    out.resize(20 + jl, b' ');
    out.extend((bl as u32).to_le_bytes());
    out.extend(b"BIN\0");
    out.extend(bin);
    out.resize(28 + jl + bl, 0);
    out
}

/// Every value's JSON pointer in `v`, depth first.
fn pointers(v: &serde_json::Value, at: String, out: &mut Vec<String>) {
    match v {
        serde_json::Value::Object(map) => {
            for (k, child) in map {
                pointers(
                    child,
                    format!("{at}/{}", k.replace('~', "~0").replace('/', "~1")),
                    out,
                );
            }
        }
        serde_json::Value::Array(list) => {
            for (k, child) in list.iter().enumerate() {
                pointers(child, format!("{at}/{k}"), out);
            }
        }
        _ => {}
    }
    out.push(at);
}

/// Values that break naive glTF readers: indices past every array,
/// counts past every buffer, wrong types.
const JSON_NASTY: [&str; 20] = [
    "0",
    "-1",
    "1",
    "3",
    "99",
    "5121",
    "5126",
    "4294967295",
    "1e300",
    "-1e300",
    "0.5",
    "\"\"",
    "\"SCALAR\"",
    "\"VEC2\"",
    "\"/dev/zero\"",
    "null",
    "true",
    "[]",
    "{}",
    "[0, 0, 0]",
];

/// One edit of the glTF JSON: value `v` at the `p`-th pointer, or (`v`
/// past the list) that value removed.
fn mutate_json(json: &[u8], edits: &[(usize, usize)]) -> Vec<u8> {
    let mut doc: serde_json::Value = serde_json::from_slice(json).unwrap();
    for &(p, v) in edits {
        let mut all = Vec::new();
        pointers(&doc, String::new(), &mut all);
        let at = &all[p % all.len()];
        if at.is_empty() {
            continue;
        }
        if let Some(&nasty) = JSON_NASTY.get(v) {
            *doc.pointer_mut(at).unwrap() = serde_json::from_str(nasty).unwrap();
        } else {
            let (parent, key) = at.rsplit_once('/').unwrap();
            match doc.pointer_mut(parent).unwrap() {
                serde_json::Value::Object(map) => {
                    map.remove(&key.replace("~1", "/").replace("~0", "~"));
                }
                serde_json::Value::Array(list) => {
                    list.remove(key.parse::<usize>().unwrap());
                }
                _ => {}
            }
        }
    }
    serde_json::to_vec(&doc).unwrap()
}

/// Reads the glTF surface `path` (default options): it reads, or the
/// error names the file.
fn read_surface(path: &Path) {
    if let Err(e) = skinpatch::surface::AnimatedSurface::read(path, &Default::default()) {
        let name = path.file_name().unwrap().to_string_lossy();
        let message = e.to_string();
        assert!(
            message.contains(name.as_ref()),
            "the error does not name {name}: {message}"
        );
    }
}

/// Bytes `(position, value)` written over `bytes`; a position past the
/// end is taken modulo the first `head` bytes (the header and the start of
/// the JSON), where most of a file's structure is.
fn mutate_bytes(bytes: &[u8], edits: &[(usize, u8)], head: usize) -> Vec<u8> {
    let mut out = bytes.to_vec();
    for &(p, v) in edits {
        let at = if p % 3 == 0 {
            p % head.min(out.len())
        } else {
            p % out.len()
        };
        out[at] = v;
    }
    out
}

proptest! {
    #![proptest_config(config(120))]

    /// A GLB whose JSON has one or two values replaced or removed reads,
    /// or is an error naming the file.
    #[test]
    fn mutated_gltf_json_never_panics(
        edits in prop::collection::vec((any::<usize>(), 0..JSON_NASTY.len() + 1), 1..3)
    ) {
        let (json, bin) = glb_chunks(forehead());
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("forehead.glb");
        std::fs::write(&path, glb(&mutate_json(&json, &edits), &bin)).unwrap();
        read_surface(&path);
    }

    /// A GLB with a few bytes overwritten anywhere (a third of them in the
    /// header and the JSON's start) reads, or is an error naming the file.
    #[test]
    fn mutated_glb_bytes_never_panic(
        edits in prop::collection::vec((any::<usize>(), any::<u8>()), 1..5)
    ) {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("forehead.glb");
        std::fs::write(&path, mutate_bytes(forehead(), &edits, 64)).unwrap();
        read_surface(&path);
    }
}

/// Frame `k` of a small OBJ sequence: a 4 × 4 vertex sheet with texture
/// coordinates, bulging by `k` (0.1 unit a frame).
fn obj_frame(k: usize) -> String {
    let mut text = String::from("o sheet\n");
    for j in 0..4 {
        for i in 0..4 {
            let bump = 0.1 * k as f64 * ((i % 3) * (j % 3)) as f64;
            text += &format!("v {i}.0 {j}.0 {bump}\n");
        }
    }
    for j in 0..4 {
        for i in 0..4 {
            text += &format!("vt {} {}\n", i as f64 / 3.0, j as f64 / 3.0);
        }
    }
    for j in 0..3 {
        for i in 0..3 {
            let a = j * 4 + i + 1;
            let (b, c, d) = (a + 1, a + 5, a + 4);
            text += &format!("f {a}/{a} {b}/{b} {c}/{c}\nf {a}/{a} {c}/{c} {d}/{d}\n");
        }
    }
    text
}

/// Values for OBJ fields: extremes, garbage and indices past the lists.
const OBJ_NASTY: [&str; 12] = [
    "0",
    "-1",
    "-99",
    "17",
    "99999999999",
    "nan",
    "inf",
    "1e308",
    "x",
    "",
    "1/2/3/4",
    "2//",
];

proptest! {
    #![proptest_config(config(150))]

    /// A three-frame OBJ sequence with one frame mutated reads, or is an
    /// error naming a frame's file.
    #[test]
    fn mutated_obj_sequences_never_panic(
        frame in 0..3usize,
        edits in prop::collection::vec((any::<usize>(), any::<usize>(), 0..OBJ_NASTY.len() + 2), 1..4)
    ) {
        let dir = tempfile::tempdir().unwrap();
        for k in 0..3 {
            let mut text = obj_frame(k);
            if k == frame {
                text = mutate_lines(&text, &edits, &OBJ_NASTY);
            }
            std::fs::write(dir.path().join(format!("frame_{:04}.obj", k + 1)), text).unwrap();
        }
        let options = skinpatch::surface::ReadOptions {
            mm_per_unit: Some(1.0),
            ..Default::default()
        };
        if let Err(e) = skinpatch::surface::AnimatedSurface::read(&dir.path().join("frame_%04d.obj"), &options) {
            let message = e.to_string();
            prop_assert!(message.contains("frame_000"), "the error names no frame: {}", message);
        }
    }
}

/// A 24 × 16 map with a ramp and a ridge, 5 µm texels.
fn small_map() -> DisplacementMap {
    DisplacementMap::from_fn(24, 16, 5.0, Edge::Wrap, |i, j| {
        (i as f32 * 0.5 - j as f32 * 0.25) + if i % 6 == 0 { 3.0 } else { 0.0 }
    })
}

fn map_defaults() -> skinpatch::micro::io::MapDefaults {
    skinpatch::micro::io::MapDefaults {
        texel: skinpatch::micro::io::TexelSize::Um(5.0),
        height_unit_um: 1.0,
        edge: Edge::Wrap,
    }
}

/// Reads a map; a map read must be whole, an error must name the file.
fn read_map(path: &Path) -> Result<(), String> {
    match skinpatch::micro::io::read_map(path, &map_defaults()) {
        Ok(map) => {
            assert_eq!(map.data.len(), map.width * map.height, "{}", path.display());
            Ok(())
        }
        Err(e) => {
            let name = path.file_name().unwrap().to_string_lossy();
            let message = e.to_string();
            assert!(
                message.contains(name.as_ref()),
                "the error does not name {name}: {message}"
            );
            Err(message)
        }
    }
}

/// CRC-32 of a PNG chunk's type and data, bit by bit.
fn crc32(bytes: &[u8]) -> u32 {
    let mut crc = !0u32;
    for &b in bytes {
        crc ^= u32::from(b);
        for _ in 0..8 {
            crc = if crc & 1 == 1 {
                (crc >> 1) ^ 0xedb8_8320
            } else {
                crc >> 1
            };
        }
    }
    !crc
}

/// Sets every PNG chunk's CRC to match its (mutated) contents, so the
/// mutation reaches the decoder instead of the checksum test.
fn fix_png_crcs(png: &mut [u8]) {
    let mut at = 8;
    while at + 12 <= png.len() {
        let len = u32::from_be_bytes(png[at..at + 4].try_into().unwrap()) as usize;
        let Some(end) = (at + 8).checked_add(len).filter(|&e| e + 4 <= png.len()) else {
            break;
        };
        let crc = crc32(&png[at + 4..end]);
        png[end..end + 4].copy_from_slice(&crc.to_be_bytes());
        at = end + 4;
    }
}

proptest! {
    #![proptest_config(config(200))]

    /// A 16-bit PNG map with bytes overwritten (a third of them in the
    /// signature, the header and the metadata), checksums made to match
    /// or not, reads whole or is an error naming the file.
    #[test]
    fn mutated_png_maps_never_panic(
        edits in prop::collection::vec((any::<usize>(), any::<u8>()), 1..4),
        fix_crcs in any::<bool>(),
    ) {
        static PNG: std::sync::OnceLock<Vec<u8>> = std::sync::OnceLock::new();
        let png = PNG.get_or_init(|| {
            let dir = tempfile::tempdir().unwrap();
            let path = dir.path().join("map.png");
            skinpatch::micro::io::write_png16(&path, &small_map()).unwrap();
            std::fs::read(path).unwrap()
        });
        let mut bytes = mutate_bytes(png, &edits, 200);
        if fix_crcs {
            fix_png_crcs(&mut bytes);
        }
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("map.png");
        std::fs::write(&path, bytes).unwrap();
        let _ = read_map(&path);
    }

    /// An EXR map with bytes overwritten (a third of them in its header)
    /// reads whole or is an error naming the file.
    #[test]
    fn mutated_exr_maps_never_panic(
        edits in prop::collection::vec((any::<usize>(), any::<u8>()), 1..4)
    ) {
        static EXR: std::sync::OnceLock<Vec<u8>> = std::sync::OnceLock::new();
        let exr = EXR.get_or_init(|| {
            let dir = tempfile::tempdir().unwrap();
            let path = dir.path().join("map.exr");
            skinpatch::micro::io::write_exr(&path, &small_map()).unwrap();
            std::fs::read(path).unwrap()
        });
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("map.exr");
        std::fs::write(&path, mutate_bytes(exr, &edits, 400)).unwrap();
        let _ = read_map(&path);
    }
}

/// An EXR whose data window claims a million texels a side (its pixels
/// a few hundred bytes) is refused before anything is allocated, naming
/// the size.
#[test]
fn an_exr_header_claiming_terabytes_is_refused_before_allocating() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("huge.exr");
    skinpatch::micro::io::write_exr(&path, &small_map()).unwrap();
    let mut bytes = std::fs::read(&path).unwrap();
    // The attribute: name, type, size 16, then x_min, y_min, x_max, y_max.
    let key = b"dataWindow\0box2i\0";
    let at = bytes
        .windows(key.len())
        .position(|w| w == key)
        .expect("an EXR has a data window")
        + key.len()
        + 4;
    for (k, v) in [0i32, 0, 999_999, 999_999].into_iter().enumerate() {
        bytes[at + 4 * k..at + 4 * k + 4].copy_from_slice(&v.to_le_bytes());
    }
    std::fs::write(&path, bytes).unwrap();
    let e = read_map(&path).unwrap_err();
    assert!(e.contains("1000000 × 1000000"), "{e}");
}

/// Edits of the `key = value` lines of a TOML text (values only: an
/// edited key or table header stops at the parser as an unknown key).
/// Edit `(l, v)` takes the `l`-th such line (modulo their count) and
/// gives it value `nasty[v]`, or (`v` past the list) empties it, or
/// repeats it.
fn edit_values(text: &str, edits: &[(usize, usize)], nasty: &[&str]) -> String {
    let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
    for &(l, v) in edits {
        let values: Vec<usize> = (0..lines.len())
            .filter(|&k| lines[k].contains(" = "))
            .collect();
        let Some(&k) = values.get(l % values.len().max(1)) else {
            break;
        };
        match v.checked_sub(nasty.len()) {
            None => {
                let key = lines[k].split_once(" = ").unwrap().0.to_string();
                lines[k] = format!("{key} = {}", nasty[v]);
            }
            Some(0) => lines[k].clear(),
            Some(_) => {
                let line = lines[k].clone();
                lines.insert(k, line);
            }
        }
    }
    lines.join("\n")
}

/// Values for tile-index keys.
const INDEX_NASTY: [&str; 14] = [
    "0",
    "-1",
    "1",
    "1000000000",
    "18446744073709551615",
    "1e308",
    "nan",
    "-inf",
    "0.5",
    "\"\"",
    "\"../map\"",
    "\"wrap\"",
    "[]",
    "true",
];

proptest! {
    #![proptest_config(config(200))]

    /// A tiled map's `index.toml` with one or two values replaced, or a
    /// line dropped or repeated, opens and its tiles read whole, or is an
    /// error naming the index or the tile.
    #[test]
    fn mutated_tile_indexes_never_panic(
        edits in prop::collection::vec((any::<usize>(), 0..INDEX_NASTY.len() + 2), 1..3)
    ) {
        let dir = tempfile::tempdir().unwrap();
        let tiles = dir.path().join("tiles");
        let map = small_map();
        skinpatch::micro::tiled::TiledMap::write(&tiles, &map, 16).unwrap();
        let index = tiles.join("index.toml");
        let text = std::fs::read_to_string(&index).unwrap();
        let mutated = edit_values(&text, &edits, &INDEX_NASTY);
        std::fs::write(&index, &mutated).unwrap();
        let named = |message: &str| message.contains("index.toml") || message.contains("tiles");
        match skinpatch::micro::tiled::TiledMap::open(&tiles) {
            Ok(tiled) => {
                // The first tiles of each row and column (a valid index
                // may claim thousands of tiles that are not there).
                let (cols, rows) = tiled.grid();
                for row in 0..rows.min(3) {
                    for col in 0..cols.min(3) {
                        match tiled.read_tile(col, row) {
                            Ok(tile) => prop_assert_eq!(tile.data.len(), tile.width * tile.height),
                            Err(e) => prop_assert!(named(&e.to_string()), "{}", e),
                        }
                    }
                }
            }
            Err(e) => prop_assert!(named(&e.to_string()), "{}", e),
        }
    }
}

/// Values for viewer-script keys.
#[cfg(feature = "viewer")]
const SCRIPT_NASTY: [&str; 16] = [
    "0",
    "-1",
    "1e308",
    "nan",
    "inf",
    "-inf",
    "1e-300",
    "18446744073709551615",
    "\"\"",
    "\"examples/press.toml\"",
    "\"press_session.toml\"",
    "[nan, 0.0]",
    "[1.0]",
    "[1e308, -1e308]",
    "true",
    "\"rs\"",
];

#[cfg(feature = "viewer")]
proptest! {
    #![proptest_config(config(300))]

    /// The shipped viewer script with one or two values replaced, or a
    /// line dropped or repeated, loads and every step gives its commands,
    /// or is an error naming the script.
    #[test]
    fn mutated_viewer_scripts_never_panic(
        edits in prop::collection::vec((any::<usize>(), 0..SCRIPT_NASTY.len() + 2), 1..3)
    ) {
        static TEXT: std::sync::OnceLock<String> = std::sync::OnceLock::new();
        let text = TEXT.get_or_init(|| {
            std::fs::read_to_string(root().join("examples/scripts/press_session.toml")).unwrap()
        });
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("press_session.toml");
        std::fs::write(&path, edit_values(text, &edits, &SCRIPT_NASTY)).unwrap();
        match skinpatch::viewer::script::Script::load(&path, &root().join("examples/press.toml")) {
            Ok(script) => {
                for step in &script.step {
                    let _ = step.commands();
                }
            }
            Err(e) => {
                let message = e.to_string();
                prop_assert!(message.contains("press_session.toml"), "{}", message);
            }
        }
    }
}

use crate::common::skinpatch_in;

/// Every file under `base` outside its `out` folder, with its bytes.
fn snapshot(base: &Path) -> std::collections::BTreeMap<PathBuf, Vec<u8>> {
    let mut files = std::collections::BTreeMap::new();
    let mut folders = vec![base.to_path_buf()];
    while let Some(folder) = folders.pop() {
        for entry in std::fs::read_dir(&folder).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                if path != base.join("out") {
                    folders.push(path);
                }
            } else {
                files.insert(path.clone(), std::fs::read(&path).unwrap());
            }
        }
    }
    files
}

/// What a command on a mutated input must leave: exit 0 or 1 (an error,
/// not a panic or an abort) with an error naming `file`, every file that
/// was there before (`before`) unchanged but the one it was told to write
/// (`target`, when that is not one of its inputs), and the sentinel file
/// of the pre-filled output folder. (Files a command made in an earlier
/// case are its own outputs: not in `before`.)
fn check_command(
    case: &str,
    output: &std::process::Output,
    (base, before): (&Path, &std::collections::BTreeMap<PathBuf, Vec<u8>>),
    target: Option<&Path>,
    file: &str,
) {
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(
        matches!(output.status.code(), Some(0 | 1)) && !stderr.contains("panicked"),
        "{case}: exit {:?}\n{stderr}",
        output.status.code()
    );
    assert!(
        output.status.success() || stderr.contains(file),
        "{case}: the error does not name {file}:\n{stderr}"
    );
    for (path, bytes) in before {
        if target.is_some_and(|t| base.join(t) == *path) {
            continue;
        }
        assert!(
            std::fs::read(path).ok().as_ref() == Some(bytes),
            "{case}: {} changed\n{stderr}",
            path.display()
        );
    }
    assert_eq!(
        std::fs::read_to_string(base.join("out/mine.txt"))
            .ok()
            .as_deref(),
        Some("kept"),
        "{case}: the output folder's own file was lost\n{stderr}"
    );
}

/// A small xorshift generator: the command corpora choose their edits
/// with it (each case runs the binary, so they are few and listed).
struct Xorshift(u64);

impl Xorshift {
    fn next(&mut self) -> usize {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        (self.0 >> 11) as usize
    }
}

/// One random edit of a `key = value` line of `text`: a nasty value of
/// the same kind (number, string or list) five times in six, of another
/// kind otherwise, or the line dropped or repeated.
fn edit_toml(text: &str, rng: &mut Xorshift) -> String {
    let lines: Vec<&str> = text.lines().filter(|l| l.contains(" = ")).collect();
    let line = rng.next() % lines.len();
    let value = lines[line].split_once(" = ").unwrap().1;
    let kinds = [&NUMBERS[..], &STRINGS[..], &LISTS[..]];
    let kind = match value.chars().next() {
        _ if rng.next().is_multiple_of(6) => kinds[rng.next() % 3],
        Some('"') => &STRINGS[..],
        Some('[') => &LISTS[..],
        _ => &NUMBERS[..],
    };
    let edit = (line, rng.next() % (kind.len() + 2));
    edit_values(text, &[edit], kind)
}

/// Numbers for the commands' files.
const NUMBERS: [&str; 11] = [
    "0",
    "-1",
    "1e308",
    "nan",
    "inf",
    "1e-300",
    "0.5",
    "3",
    "1000000000",
    "18446744073709551615",
    "true",
];

/// Strings for the commands' files: paths onto their own inputs among
/// them.
const STRINGS: [&str; 9] = [
    "\"\"",
    "\"neutral.png\"",
    "\"input.toml\"",
    "\"meso.exr\"",
    "\"tiles/index.toml\"",
    "\"out\"",
    "\"x\"",
    "\"/dev/zero\"",
    "\"mirror\"",
];

/// Lists for the commands' files.
const LISTS: [&str; 4] = ["[]", "[\"png16\"]", "[\"exr\", \"exr\"]", "[\"tiff\"]"];

/// `synth`, `fit` and `tiles join` on small mutated inputs whose output
/// folder already holds a file: an error or a result, inputs unchanged,
/// the folder's file kept. 24 cases each.
#[test]
fn commands_on_mutated_inputs_keep_inputs_and_outputs() {
    use skinpatch::micro::io::{write_exr, write_png16};
    let dir = tempfile::tempdir().unwrap();
    let base = dir.path();
    let neutral = DisplacementMap::from_fn(32, 32, 5.0, Edge::Wrap, |i, j| {
        ((i * 7 + j * 3) % 11) as f32
    });
    write_png16(&base.join("neutral.png"), &neutral).unwrap();
    let stretched = DisplacementMap::from_fn(32, 32, 5.0, Edge::Wrap, |i, j| {
        ((i * 5 + j * 3) % 11) as f32 * 0.8
    });
    write_png16(&base.join("stretched.png"), &stretched).unwrap();
    let meso = DisplacementMap::from_fn(16, 16, 20.0, Edge::Wrap, |i, j| {
        ((i as f32) * 0.4).sin() + (j as f32 * 0.3).cos()
    });
    write_exr(&base.join("meso.exr"), &meso).unwrap();
    skinpatch::micro::tiled::TiledMap::write(&base.join("tiles"), &small_map(), 16).unwrap();
    std::fs::create_dir_all(base.join("out")).unwrap();
    std::fs::write(base.join("out/mine.txt"), "kept").unwrap();
    std::fs::write(base.join("input.toml"), "").unwrap();
    // The inputs: what the commands' files name, and what they are.
    let inputs: Vec<PathBuf> = snapshot(base).into_keys().collect();
    let before = || -> std::collections::BTreeMap<PathBuf, Vec<u8>> {
        inputs
            .iter()
            .map(|p| (p.clone(), std::fs::read(p).unwrap()))
            .collect()
    };

    let synth = "[synthesis]\nexemplar = \"neutral.png\"\nmesostructure = \"meso.exr\"\n\
                 mesostructure_sigma_um = 20.0\nalpha = 0.5\nseed = 1\n\n\
                 [output]\ndir = \"out\"\nformats = [\"exr\"]\npreview_px = 32\n";
    let fit = "neutral = \"neutral.png\"\noutput = \"out/kernel.toml\"\n\n\
               [[sample]]\nmap = \"stretched.png\"\nr = 1.2\naxis = \"u\"\n\n\
               [[point]]\nr = 0.8\nsigma_um = 4.0\nalpha = 0.6\n";
    // Where fit was told to write, unless that is one of its inputs.
    let fit_target = |text: &str| -> Option<PathBuf> {
        let doc: toml::Value = toml::from_str(text).ok()?;
        let output = doc.get("output")?.as_str()?;
        let mut inputs = vec!["input.toml"];
        inputs.extend(doc.get("neutral").and_then(|v| v.as_str()));
        for sample in doc
            .get("sample")
            .and_then(|s| s.as_array())
            .into_iter()
            .flatten()
        {
            inputs.extend(sample.get("map").and_then(|v| v.as_str()));
        }
        (!inputs.contains(&output)).then(|| PathBuf::from(output))
    };
    let mut rng = Xorshift(0x5eed_2026);
    let mut outcomes = [0usize; 2];
    for (name, text) in [("synth", synth), ("fit", fit)] {
        // Unmutated, the input runs.
        std::fs::write(base.join("input.toml"), text).unwrap();
        let output = skinpatch_in(base, &[name, "input.toml"]);
        assert!(
            output.status.success(),
            "{name}: {}",
            String::from_utf8_lossy(&output.stderr)
        );
        for case in 0..24 {
            let mutated = edit_toml(text, &mut rng);
            std::fs::write(base.join("input.toml"), &mutated).unwrap();
            let before = before();
            let output = skinpatch_in(base, &[name, "input.toml"]);
            let target = if name == "fit" {
                fit_target(&mutated)
            } else {
                None
            };
            check_command(
                &format!("{name} case {case}:\n{mutated}"),
                &output,
                (base, &before),
                target.as_deref(),
                "input.toml",
            );
            outcomes[usize::from(output.status.success())] += 1;
        }
    }
    // tiles join of a mutated index, onto a file beside the sentinel and
    // onto its own inputs (the index, a tile).
    let index = base.join("tiles/index.toml");
    let index_text = std::fs::read_to_string(&index).unwrap();
    for case in 0..24 {
        let mutated = edit_toml(&index_text, &mut rng);
        std::fs::write(&index, &mutated).unwrap();
        let target = [
            "out/joined.exr",
            "tiles/index.toml",
            "tiles/tile_0000_0000.exr",
            "out/joined.png",
        ][case % 4];
        let before = before();
        let output = skinpatch_in(base, &["tiles", "join", "tiles", "--output", target]);
        check_command(
            &format!("tiles join case {case} → {target}:\n{mutated}"),
            &output,
            (base, &before),
            None,
            "tiles",
        );
        outcomes[usize::from(output.status.success())] += 1;
    }
    // The corpora reach past the parsers: some cases run to the end
    // (measured: 20 of 72).
    eprintln!("{} succeeded, {} refused", outcomes[1], outcomes[0]);
    assert!(
        outcomes[1] >= 12,
        "{} succeeded, {} refused",
        outcomes[1],
        outcomes[0]
    );
}

/// The Gmsh fixture as a mesh, for the binary mesh corpora.
fn gmsh_fixture() -> &'static skinpatch::mesh::TetMesh {
    static MESH: std::sync::OnceLock<skinpatch::mesh::TetMesh> = std::sync::OnceLock::new();
    MESH.get_or_init(|| {
        skinpatch::mesh::io::read_mesh(&root().join("tests/fixtures/two_layer_box.msh")).unwrap()
    })
}

/// Reads a mutated mesh file: it reads, or the error names the file.
fn read_mutated_mesh(name: &str, bytes: &[u8]) -> Result<(), TestCaseError> {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join(name);
    std::fs::write(&path, bytes).unwrap();
    if let Err(e) = skinpatch::mesh::io::read_mesh(&path) {
        prop_assert!(e.to_string().contains(name), "{}", e);
    }
    Ok(())
}

proptest! {
    #![proptest_config(config(150))]

    /// Binary Gmsh meshes (4.1 and 2.2, either byte order) with a few bytes
    /// overwritten (a third of them in the first 400 bytes: format,
    /// names, entities and headers) read, or fail naming the file.
    #[test]
    fn mutated_binary_gmsh_meshes_never_panic(
        layout in 0..4usize,
        edits in prop::collection::vec((any::<usize>(), any::<u8>()), 1..4)
    ) {
        let bytes = crate::mesh_io::encode_msh(gmsh_fixture(), layout < 2, true, layout % 2 == 1);
        read_mutated_mesh("box.msh", &mutate_bytes(&bytes, &edits, 400))?;
    }

    /// VTU meshes, uncompressed binary, with bytes overwritten: read, or
    /// fail naming the file.
    #[test]
    fn mutated_vtu_meshes_never_panic(
        edits in prop::collection::vec((any::<usize>(), any::<u8>()), 1..4)
    ) {
        static BYTES: std::sync::OnceLock<Vec<u8>> = std::sync::OnceLock::new();
        let bytes = BYTES.get_or_init(|| {
            let dir = tempfile::tempdir().unwrap();
            let path = dir.path().join("box.vtu");
            let grid = skinpatch::mesh::io::Grid::from_mesh(gmsh_fixture());
            skinpatch::mesh::io::write_vtu_as(&path, &grid, skinpatch::mesh::io::VtuFormat { compress: false, f32: false })
                .unwrap();
            std::fs::read(&path).unwrap()
        });
        read_mutated_mesh("box.vtu", &mutate_bytes(bytes, &edits, 1200))?;
    }
}
