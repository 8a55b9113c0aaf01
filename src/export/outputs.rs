//! The output folder as one set: before a run writes anything, the files a
//! previous run left there — its outputs and the temporaries of a killed
//! run — are removed, so the folder never mixes two runs (a shorter rerun
//! used to leave the old run's later frames beside its own metrics).
//!
//! Only names this crate writes are touched (see [`is_run_output`]); any
//! other file in the folder is left alone.

use std::path::{Path, PathBuf};

use crate::error::{Error, Result};

/// Subfolders a run writes into, with the names it writes there.
const SUBFOLDERS: [&str; 5] = ["frames", "strain", "micro", "render", "surface"];

/// Whether `name`, found in `folder` (relative to the output folder: `""`,
/// `frames`, `strain`, `micro`, `surface` or `render/<mode>`), is a file a
/// run writes. Frame numbers may carry a UDIM tile (`rs_1001_0004.png`).
pub fn is_run_output(folder: &str, name: &str) -> bool {
    if is_temporary(name) {
        return true;
    }
    let numbered = |prefix: &str, extensions: &[&str]| {
        name.strip_prefix(prefix).is_some_and(|rest| {
            extensions.iter().any(|ext| {
                rest.strip_suffix(ext).is_some_and(|n| {
                    let n = match n.split_once('_') {
                        Some((tile, n)) if tile.len() == 4 && all_digits(tile) => n,
                        _ => n,
                    };
                    all_digits(n)
                })
            })
        })
    };
    match folder {
        "" => matches!(
            name,
            "mesh.vtu"
                | "mesh.node"
                | "mesh.ele"
                | "mesh.face"
                | "metrics.csv"
                | "volume.csv"
                | "frames.pvd"
                | "frames.vtkhdf"
                | "summary.json"
                | "surface.glb"
                | "surface.vtu"
        ),
        "surface" => numbered("frame_", &[".obj"]),
        "frames" => numbered("frame_", &[".vtu"]),
        "strain" => ["rs_", "rt_", "axes_"]
            .iter()
            .any(|p| numbered(p, &[".png"])),
        "micro" => {
            name == "roughness.csv"
                || ["height_", "normal_"].iter().any(|p| {
                    numbered(p, &[".png", ".exr"])
                        || name == format!("{p}neutral.png")
                        || name == format!("{p}neutral.exr")
                })
        }
        "render" => name.ends_with(".mp4"),
        _ if folder.starts_with("render/") => numbered("frame_", &[".png", ".exr"]),
        _ => false,
    }
}

/// Whether `name` in `micro/` is a frame folder a run writes for a tiled
/// map (`height_NNNN.tiles`, `height_neutral.tiles`).
fn is_tiled_frame(name: &str) -> bool {
    name.strip_prefix("height_")
        .and_then(|r| r.strip_suffix(".tiles"))
        .is_some_and(|n| n == "neutral" || all_digits(n))
}

/// Whether `name` inside a tiled frame folder is a file a run writes: the
/// index, `tile_C_R.exr`, `normal_C_R.exr`, temporaries.
fn is_tile_file(name: &str) -> bool {
    if name == crate::micro::tiled::INDEX_FILE || is_temporary(name) {
        return true;
    }
    ["tile_", "normal_"].iter().any(|p| {
        name.strip_prefix(p)
            .and_then(|r| r.strip_suffix(".exr"))
            .and_then(|r| r.split_once('_'))
            .is_some_and(|(c, r)| all_digits(c) && all_digits(r))
    })
}

fn all_digits(s: &str) -> bool {
    !s.is_empty() && s.bytes().all(|b| b.is_ascii_digit())
}

/// A temporary of an atomic write (`<name>.tmp<pid>`), complete or not:
/// finished files are only ever renamed into place, so one that is still
/// there belongs to a run that was killed.
fn is_temporary(name: &str) -> bool {
    name.rsplit_once(".tmp")
        .is_some_and(|(_, pid)| !pid.is_empty() && pid.bytes().all(|b| b.is_ascii_digit()))
}

/// Every file in `dir` with a name a run writes (see [`is_run_output`]),
/// the files of tiled frame folders and the temporaries of a killed run
/// included, sorted by path: after a finished run, the files it wrote;
/// before one, the files it will remove. Folders that do not exist are
/// skipped.
pub fn run_files(dir: &Path) -> Vec<PathBuf> {
    let mut folders: Vec<(String, PathBuf)> = vec![(String::new(), dir.to_path_buf())];
    folders.extend(SUBFOLDERS.iter().map(|f| (f.to_string(), dir.join(f))));
    if let Ok(entries) = std::fs::read_dir(dir.join("render")) {
        for entry in entries.flatten() {
            if entry.file_type().is_ok_and(|t| t.is_dir()) {
                let name = entry.file_name().to_string_lossy().into_owned();
                folders.push((format!("render/{name}"), entry.path()));
            }
        }
    }
    let mut files = Vec::new();
    for (label, folder) in folders {
        let Ok(entries) = std::fs::read_dir(&folder) else {
            continue;
        };
        for entry in entries.flatten() {
            let name = entry.file_name().to_string_lossy().into_owned();
            let kind = entry.file_type();
            if kind.as_ref().is_ok_and(|t| t.is_file()) && is_run_output(&label, &name) {
                files.push(entry.path());
            } else if label == "micro" && kind.is_ok_and(|t| t.is_dir()) && is_tiled_frame(&name) {
                let Ok(tiles) = std::fs::read_dir(entry.path()) else {
                    continue;
                };
                files.extend(tiles.flatten().filter_map(|tile| {
                    let name = tile.file_name().to_string_lossy().into_owned();
                    (tile.file_type().is_ok_and(|t| t.is_file()) && is_tile_file(&name))
                        .then(|| tile.path())
                }));
            }
        }
    }
    files.sort();
    files
}

/// Bytes the files of [`run_files`] take: the space a run in `dir` frees
/// before it writes.
pub fn run_files_bytes(dir: &Path) -> u64 {
    run_files(dir)
        .iter()
        .filter_map(|f| std::fs::metadata(f).ok())
        .map(|m| m.len())
        .sum()
}

/// The index files of a run, in the reverse of the order a frame commits
/// to them (files → `volume.csv` → `metrics.csv` → `frames.pvd`).
const INDEXES_LAST_WRITTEN_FIRST: [&str; 3] = ["frames.pvd", "metrics.csv", "volume.csv"];

/// Removes every earlier run's file from `dir` (see [`run_files`]), and
/// tiled frame folders left empty; returns how many files.
///
/// The indexes go first, in the reverse of their commit order, and the
/// frames' own files after them: a run killed while it clears leaves no
/// listed frame without its rows and no row without its files.
pub fn clear_previous_run(dir: &Path) -> Result<usize> {
    let files = clearing_order(dir);
    for path in &files {
        std::fs::remove_file(path).map_err(|e| Error::io(path, e))?;
    }
    if let Ok(entries) = std::fs::read_dir(dir.join("micro")) {
        for entry in entries.flatten() {
            let name = entry.file_name().to_string_lossy().into_owned();
            if entry.file_type().is_ok_and(|t| t.is_dir()) && is_tiled_frame(&name) {
                // Kept when the user put files of their own there.
                let _ = std::fs::remove_dir(entry.path());
            }
        }
    }
    Ok(files.len())
}

/// [`run_files`] in the order [`clear_previous_run`] removes them.
fn clearing_order(dir: &Path) -> Vec<PathBuf> {
    let mut files = run_files(dir);
    let rank = |path: &PathBuf| {
        INDEXES_LAST_WRITTEN_FIRST
            .iter()
            .position(|name| path.parent() == Some(dir) && path.file_name() == Some(name.as_ref()))
            .unwrap_or(INDEXES_LAST_WRITTEN_FIRST.len())
    };
    files.sort_by_key(rank);
    files
}

/// Whether `a` and `b` name the same existing file (after following links
/// and `..`; on Unix also two hard links of one file).
pub fn same_file(a: &Path, b: &Path) -> bool {
    let (Ok(ma), Ok(mb)) = (std::fs::metadata(a), std::fs::metadata(b)) else {
        return false;
    };
    #[cfg(unix)]
    {
        use std::os::unix::fs::MetadataExt;
        if (ma.dev(), ma.ino()) == (mb.dev(), mb.ino()) {
            return true;
        }
    }
    let _ = (ma, mb);
    matches!(
        (std::fs::canonicalize(a), std::fs::canonicalize(b)),
        (Ok(x), Ok(y)) if x == y
    )
}

/// Creates the output folder `dir` (and its parents). Where `dir` or a
/// folder above it is a file, the error says so and names that file,
/// rather than the system's "File exists".
pub fn create_output_dir(dir: &Path) -> Result<()> {
    std::fs::create_dir_all(dir).map_err(|e| {
        let blocking = dir
            .ancestors()
            .filter(|a| !a.as_os_str().is_empty())
            .find(|a| std::fs::metadata(a).is_ok_and(|m| !m.is_dir()));
        match blocking {
            Some(file) => Error::parameter(
                "output.dir",
                format!(
                    "{} cannot be created: {} is a file, not a folder; choose another output \
                     folder (output.dir, or -o)",
                    dir.display(),
                    file.display()
                ),
            ),
            None => Error::io(dir, e),
        }
    })
}

/// The rule every command follows: an output file is never one of the
/// run's inputs. `key` names the output's setting; `inputs` are (what,
/// path) pairs. The error names both.
pub fn refuse_input_overwrite(key: &str, output: &Path, inputs: &[(&str, &Path)]) -> Result<()> {
    match inputs.iter().find(|(_, input)| same_file(output, input)) {
        Some((what, input)) => Err(Error::parameter(
            key,
            format!(
                "{} is the run's {what} ({}); writing it would overwrite an input: choose \
                 another file",
                output.display(),
                input.display()
            ),
        )),
        None => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn run_outputs_are_recognised_by_name_and_folder() {
        for (folder, name) in [
            ("", "metrics.csv"),
            ("", "frames.pvd"),
            ("", "frames.vtkhdf"),
            ("", "metrics.csv.tmp4242"),
            ("frames", "frame_0007.vtu"),
            ("frames", "frame_0007.vtu.tmp17"),
            ("strain", "axes_0012.png"),
            ("micro", "height_neutral.exr"),
            ("micro", "normal_0003.png"),
            ("micro", "roughness.csv"),
            ("render", "dynamic.mp4"),
            ("render/dynamic", "frame_0060.png"),
        ] {
            assert!(is_run_output(folder, name), "{folder}/{name}");
        }
        for (folder, name) in [
            ("", "notes.txt"),
            ("", "press.toml"),
            ("frames", "frame_.vtu"),
            ("frames", "frame_12a.vtu"),
            ("strain", "rs_0001.jpg"),
            ("micro", "height_mine.png"),
            ("render/dynamic", "poster.png"),
            ("", "data.tmp"),
            ("elsewhere", "frame_0001.vtu"),
        ] {
            assert!(!is_run_output(folder, name), "{folder}/{name}");
        }
    }

    /// Old outputs and temporaries go, the user's own files stay.
    #[test]
    fn clearing_keeps_what_the_run_did_not_write() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        for f in ["frames", "micro", "render/static"] {
            std::fs::create_dir_all(d.join(f)).unwrap();
        }
        let old = [
            "metrics.csv",
            "frames.pvd.tmp99",
            "frames/frame_0060.vtu",
            "frames/frame_0061.vtu.tmp99",
            "micro/height_0003.exr",
            "render/static/frame_0001.png",
            "render/static.mp4",
        ];
        let mine = ["notes.txt", "frames/readme.md", "render/static/cover.png"];
        for f in old.iter().chain(&mine) {
            std::fs::write(d.join(f), "x").unwrap();
        }
        assert_eq!(clear_previous_run(d).unwrap(), old.len());
        for f in old {
            assert!(!d.join(f).exists(), "{f}");
        }
        for f in mine {
            assert!(d.join(f).exists(), "{f}");
        }
        // Tiled frames: the run's tiles go, a folder left empty too.
        for f in ["micro/height_0006.tiles", "micro/height_neutral.tiles"] {
            std::fs::create_dir_all(d.join(f)).unwrap();
            for tile in ["index.toml", "tile_0000_0001.exr", "normal_0002_0000.exr"] {
                std::fs::write(d.join(f).join(tile), "x").unwrap();
            }
        }
        std::fs::write(d.join("micro/height_0006.tiles/notes.txt"), "x").unwrap();
        std::fs::create_dir_all(d.join("micro/height_mine.tiles")).unwrap();
        std::fs::write(d.join("micro/height_mine.tiles/index.toml"), "x").unwrap();
        assert_eq!(clear_previous_run(d).unwrap(), 6);
        assert!(!d.join("micro/height_neutral.tiles").exists());
        assert!(d.join("micro/height_0006.tiles/notes.txt").exists());
        assert!(!d
            .join("micro/height_0006.tiles/tile_0000_0001.exr")
            .exists());
        assert!(d.join("micro/height_mine.tiles/index.toml").exists());
        // A folder that does not exist yet is nothing to clear.
        assert_eq!(clear_previous_run(&d.join("new")).unwrap(), 0);
    }

    /// A kill while a rerun clears must leave the commit order's promise
    /// intact: `frames.pvd`, then `metrics.csv`, then `volume.csv` go
    /// before any frame's files (sorted by path, `frames/` would come
    /// before `metrics.csv` and `volume.csv` last).
    #[test]
    fn clearing_removes_the_indexes_before_the_frames() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        std::fs::create_dir_all(d.join("frames")).unwrap();
        std::fs::create_dir_all(d.join("strain")).unwrap();
        for f in [
            "volume.csv",
            "summary.json",
            "metrics.csv",
            "frames/frame_0000.vtu",
            "frames.pvd",
            "strain/axes_0000.png",
        ] {
            std::fs::write(d.join(f), "x").unwrap();
        }
        let order: Vec<String> = clearing_order(d)
            .iter()
            .map(|p| p.strip_prefix(d).unwrap().to_string_lossy().into_owned())
            .collect();
        assert_eq!(
            order,
            [
                "frames.pvd",
                "metrics.csv",
                "volume.csv",
                "frames/frame_0000.vtu",
                "strain/axes_0000.png",
                "summary.json"
            ]
        );
    }
}
