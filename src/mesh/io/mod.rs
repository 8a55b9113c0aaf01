//! Mesh files: TetGen `.node/.ele/.face`, Gmsh `.msh` (4.1 and 2.2, text or
//! binary), VTK `.vtu` and legacy `.vtk` unstructured grids.
//!
//! [`read_mesh`] picks the reader by extension. Every reader reports
//! malformed input as [`Error::Parse`] with the file and 1-based line, and
//! structural problems (bad indices, inverted tets, empty regions) through
//! [`crate::mesh::TetMesh::from_raw`]. Writers replace files atomically, so
//! an interrupted write never leaves a truncated file behind.

mod gmsh;
mod tetgen;
pub(crate) mod text;
mod vtk_data;
mod vtk_legacy;
mod vtk_mesh;
mod vtk_xml;
pub mod vtu;

use std::io::Write;
use std::path::{Path, PathBuf};

pub use gmsh::read_gmsh;
pub use tetgen::{read_tetgen, tetgen_paths, write_tetgen};
pub use vtk_mesh::{read_vtk_mesh, REGION_ARRAYS};
pub use vtu::{read_vtu, write_vtu, write_vtu_as, Field, Grid, Values, VtuFormat};

use crate::error::{Error, Result};
use crate::mesh::TetMesh;

/// Reads a mesh by extension: `.msh` (Gmsh 4.1 or 2.2, text or binary),
/// `.vtu` or `.vtk` (a VTK unstructured grid of tetrahedra), or a TetGen
/// mesh given as `base.node`, `base.ele` or the bare base name.
pub fn read_mesh(path: &Path) -> Result<TetMesh> {
    let extension = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_lowercase);
    match extension.as_deref() {
        Some("msh") => read_gmsh(path),
        Some("vtu" | "vtk") => read_vtk_mesh(path),
        Some("node" | "ele" | "face") => read_tetgen(&path.with_extension("")),
        _ if tetgen_paths(path)[0].exists() => read_tetgen(path),
        _ => Err(Error::parameter(
            "mesh file",
            format!(
                "{}: unknown mesh format; expected .msh, .vtu, .vtk, .node/.ele, or a TetGen base name",
                path.display()
            ),
        )),
    }
}

/// Checks that `path` is a regular file before it is opened: a FIFO would
/// block the read forever and a device could be endless, so both are
/// refused (a symlink to a regular file is fine).
pub fn regular_file(path: &Path) -> Result<()> {
    let meta = std::fs::metadata(path).map_err(|e| Error::io(path, e))?;
    if meta.is_file() {
        Ok(())
    } else {
        let kind = if meta.is_dir() {
            "a folder"
        } else {
            "not a regular file (a FIFO, socket or device)"
        };
        Err(Error::io(
            path,
            std::io::Error::new(
                std::io::ErrorKind::InvalidInput,
                format!("is {kind}; expected a file"),
            ),
        ))
    }
}

/// Reads a whole input file (refusing FIFOs and devices, see
/// [`regular_file`]).
pub fn read_input(path: &Path) -> Result<Vec<u8>> {
    regular_file(path)?;
    std::fs::read(path).map_err(|e| Error::io(path, e))
}

/// [`read_input`] as UTF-8 text.
pub fn read_input_text(path: &Path) -> Result<String> {
    String::from_utf8(read_input(path)?).map_err(|e| {
        Error::io(
            path,
            std::io::Error::new(std::io::ErrorKind::InvalidData, e.utf8_error()),
        )
    })
}

/// Writes `bytes` to `path` through a temporary file in the same folder and
/// a rename, so readers never see a partial file. A `path` that exists and
/// is not a regular file — a symlink, FIFO, device or folder — is refused:
/// the rename would replace it with a regular file (the link and what it
/// points to, the pipe, the device, all lost or bypassed).
pub fn write_atomically(path: &Path, bytes: &[u8]) -> Result<()> {
    if let Ok(meta) = std::fs::symlink_metadata(path) {
        let kind = meta.file_type();
        if !kind.is_file() {
            let what = if kind.is_symlink() {
                "a symbolic link"
            } else if kind.is_dir() {
                "a folder"
            } else {
                "not a regular file (a FIFO, socket or device)"
            };
            return Err(Error::io(
                path,
                std::io::Error::new(
                    std::io::ErrorKind::InvalidInput,
                    format!(
                        "is {what}; a file is written by replacing its target, which would \
                         lose it: write to a plain file path"
                    ),
                ),
            ));
        }
    }
    let dir = path.parent().filter(|d| !d.as_os_str().is_empty());
    let mut tmp_name = path.file_name().unwrap_or_default().to_os_string();
    tmp_name.push(format!(".tmp{}", std::process::id()));
    let tmp = dir.map_or_else(|| PathBuf::from(&tmp_name), |d| d.join(&tmp_name));
    let result = (|| {
        let mut f = std::fs::File::create(&tmp)?;
        f.write_all(bytes)?;
        f.sync_all()?;
        std::fs::rename(&tmp, path)
    })();
    result.map_err(|e| {
        let _ = std::fs::remove_file(&tmp);
        Error::io(path, e)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Replacing a symlink, FIFO or folder by a regular file lost what was
    /// there and reported success; each is refused and left as it was, and
    /// a regular file is still replaced whole.
    #[cfg(unix)]
    #[test]
    fn only_regular_files_are_replaced() {
        let dir = tempfile::tempdir().unwrap();
        let target = dir.path().join("target.vtu");
        std::fs::write(&target, b"kept").unwrap();
        let link = dir.path().join("link.vtu");
        std::os::unix::fs::symlink(&target, &link).unwrap();
        let fifo = dir.path().join("fifo.vtu");
        let made = std::process::Command::new("mkfifo").arg(&fifo).status();
        let folder = dir.path().join("folder.vtu");
        std::fs::create_dir(&folder).unwrap();
        let mut refused = vec![
            (link.clone(), "a symbolic link"),
            (folder.clone(), "a folder"),
        ];
        if made.is_ok_and(|s| s.success()) {
            refused.push((fifo.clone(), "not a regular file"));
        }
        for (path, what) in refused {
            let e = write_atomically(&path, b"new").unwrap_err().to_string();
            assert!(
                e.contains(&path.display().to_string()) && e.contains(what),
                "{e}"
            );
        }
        assert!(std::fs::symlink_metadata(&link)
            .unwrap()
            .file_type()
            .is_symlink());
        assert_eq!(std::fs::read(&target).unwrap(), b"kept");
        write_atomically(&target, b"new").unwrap();
        assert_eq!(std::fs::read(&target).unwrap(), b"new");
    }
}
