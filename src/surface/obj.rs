//! OBJ animated surfaces: one file (a surface with one frame) or a sequence
//! `frame_%04d.obj` sharing topology (the same faces in the same objects),
//! read with `tobj`. UVs come from the rest mesh (a separate file, or the
//! first frame); later frames may omit them. OBJ has no unit, so the
//! scenario gives one. [`write_obj`] writes a frame with full f64 precision.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use super::{AnimatedSurface, ReadOptions, SplitSurface};
use crate::error::{Error, Result};
use crate::mesh::Vec3;

/// Reads an OBJ surface (see the module documentation).
pub fn read(path: &Path, options: &ReadOptions) -> Result<AnimatedSurface> {
    let mm = options.mm_per_unit.ok_or_else(|| {
        Error::parameter(
            "surface.units",
            format!(
                "is required for OBJ files ({} has no unit); e.g. \"m\" for Blender's default \
                 export, \"mm\" for skinpatch's own",
                path.display()
            ),
        )
    })?;
    let files = sequence(path)?;
    let rest_file = options.rest.clone().unwrap_or_else(|| files[0].clone());
    let rest = load(&rest_file)?;
    let mut split = SplitSurface {
        origin: rest_file.display().to_string(),
        ..SplitSurface::default()
    };
    // Split vertices: one per (object, position index, UV index).
    let mut corners: Vec<(usize, usize)> = Vec::new();
    for (m, model) in rest.iter().enumerate() {
        let mesh = &model.mesh;
        if mesh.texcoord_indices.len() != mesh.indices.len() || mesh.texcoords.is_empty() {
            return Err(Error::InvalidMesh {
                origin: rest_file.display().to_string(),
                message: format!(
                    "object '{}' has faces without texture coordinates (vt); unwrap the mesh \
                     before exporting it",
                    model.name
                ),
            });
        }
        let mut index = std::collections::HashMap::new();
        let mut tri = Vec::with_capacity(3);
        for (&p, &t) in mesh.indices.iter().zip(&mesh.texcoord_indices) {
            let s = *index.entry((p, t)).or_insert_with(|| {
                corners.push((m, p as usize));
                let uv = &mesh.texcoords[2 * t as usize..2 * t as usize + 2];
                split.uvs.push([uv[0], uv[1]]);
                split.labels.push(format!(
                    "object '{}' vertex {} (position {p})",
                    model.name,
                    corners.len() - 1
                ));
                corners.len() - 1
            });
            tri.push(s);
            if tri.len() == 3 {
                split.triangles.push([tri[0], tri[1], tri[2]]);
                tri.clear();
            }
        }
    }
    let positions = |models: &[tobj::Model]| -> Vec<Vec3> {
        corners
            .iter()
            .map(|&(m, p)| {
                let q = &models[m].mesh.positions[3 * p..3 * p + 3];
                Vec3::new(q[0], q[1], q[2])
            })
            .collect()
    };
    split.rest = positions(&rest);
    for file in &files {
        if *file == rest_file {
            split.frames.push(split.rest.clone());
            continue;
        }
        let frame = load(file)?;
        same_topology(&rest_file, &rest, file, &frame)?;
        split.frames.push(positions(&frame));
    }
    AnimatedSurface::from_split(split, mm, options.frame_rate_hz)
}

/// The files of a sequence: `path` itself, or every existing file matching
/// its `%d`/`%0Nd` pattern, in frame order and without gaps.
pub fn sequence(path: &Path) -> Result<Vec<PathBuf>> {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let Some(start) = name.find('%') else {
        if !path.exists() {
            return Err(Error::not_found(path));
        }
        return Ok(vec![path.to_path_buf()]);
    };
    let rest = &name[start + 1..];
    let end = rest.find('d').ok_or_else(|| {
        Error::parameter(
            "surface.file",
            format!("{name}: a sequence pattern is %d or %0Nd (e.g. frame_%04d.obj)"),
        )
    })?;
    let width: usize = if end == 0 {
        1
    } else {
        rest[..end].trim_start_matches('0').parse().map_err(|_| {
            Error::parameter(
                "surface.file",
                format!("{name}: a sequence pattern is %d or %0Nd (e.g. frame_%04d.obj)"),
            )
        })?
    };
    let (prefix, suffix) = (&name[..start], &rest[end + 1..]);
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let entries = std::fs::read_dir(&dir).map_err(|e| Error::io(&dir, e))?;
    let mut numbered: Vec<(u64, PathBuf)> = Vec::new();
    for entry in entries.flatten() {
        let file = entry.file_name().to_string_lossy().into_owned();
        let Some(digits) = file
            .strip_prefix(prefix)
            .and_then(|f| f.strip_suffix(suffix))
        else {
            continue;
        };
        if digits.len() >= width && digits.bytes().all(|b| b.is_ascii_digit()) {
            if let Ok(k) = digits.parse() {
                numbered.push((k, entry.path()));
            }
        }
    }
    numbered.sort();
    if numbered.is_empty() {
        return Err(Error::io(
            path,
            std::io::Error::new(
                std::io::ErrorKind::NotFound,
                format!("no file matches the pattern in {}", dir.display()),
            ),
        ));
    }
    for w in numbered.windows(2) {
        if w[1].0 != w[0].0 + 1 {
            let missing = format!("{prefix}{:0width$}{suffix}", w[0].0 + 1);
            return Err(Error::io(
                dir.join(&missing),
                std::io::Error::new(
                    std::io::ErrorKind::NotFound,
                    format!(
                        "the sequence has frames {} and {} but not the one between",
                        w[0].1.display(),
                        w[1].1.display()
                    ),
                ),
            ));
        }
    }
    Ok(numbered.into_iter().map(|(_, p)| p).collect())
}

fn load(path: &Path) -> Result<Vec<tobj::Model>> {
    if !path.exists() {
        return Err(Error::not_found(path));
    }
    let options = tobj::LoadOptions {
        single_index: false,
        triangulate: true,
        ignore_points: true,
        ignore_lines: true,
    };
    let (models, _materials) = tobj::load_obj(path, &options).map_err(|e| Error::Parse {
        path: path.to_path_buf(),
        line: bad_line(path).unwrap_or(0),
        message: format!("not a readable OBJ file: {e}"),
    })?;
    if models.is_empty() {
        return Err(Error::InvalidMesh {
            origin: path.display().to_string(),
            message: "has no faces".into(),
        });
    }
    Ok(models)
}

/// The first line whose numbers do not parse (the OBJ reader's errors name
/// no line).
fn bad_line(path: &Path) -> Option<usize> {
    let text = std::fs::read_to_string(path).ok()?;
    text.lines()
        .position(|line| {
            let mut words = line.split_whitespace();
            match words.next() {
                Some("v") | Some("vt") | Some("vn") => !words.all(|w| w.parse::<f64>().is_ok()),
                Some("f") => !words.all(|w| {
                    w.split('/')
                        .next()
                        .and_then(|i| i.parse::<i64>().ok())
                        .is_some_and(|i| i != 0)
                }),
                _ => false,
            }
        })
        .map(|k| k + 1)
}

/// A frame must have the rest mesh's objects, positions and faces.
fn same_topology(
    rest_file: &Path,
    rest: &[tobj::Model],
    file: &Path,
    frame: &[tobj::Model],
) -> Result<()> {
    let bad = |message: String| Error::InvalidMesh {
        origin: file.display().to_string(),
        message: format!("{message} (topology differs from {})", rest_file.display()),
    };
    if frame.len() != rest.len() {
        return Err(bad(format!(
            "has {} objects, not {}",
            frame.len(),
            rest.len()
        )));
    }
    for (a, b) in rest.iter().zip(frame) {
        if a.mesh.positions.len() != b.mesh.positions.len() {
            return Err(bad(format!(
                "object '{}' has {} positions, not {}",
                b.name,
                b.mesh.positions.len() / 3,
                a.mesh.positions.len() / 3
            )));
        }
        if let Some(k) = (0..a.mesh.indices.len().max(b.mesh.indices.len()))
            .find(|&k| a.mesh.indices.get(k) != b.mesh.indices.get(k))
        {
            let face = |m: &tobj::Model| {
                m.mesh
                    .indices
                    .get(3 * (k / 3)..3 * (k / 3) + 3)
                    .map(|f| f.to_vec())
            };
            return Err(bad(format!(
                "object '{}' triangle {} has positions {:?}, not {:?}",
                b.name,
                k / 3,
                face(b),
                face(a)
            )));
        }
    }
    Ok(())
}

/// Writes frame `frame` of `surface` (`None`: the rest) as an OBJ with
/// positions in millimetres and full precision, UVs per surface vertex.
pub fn write_obj(path: &Path, surface: &AnimatedSurface, frame: Option<usize>) -> Result<()> {
    let x = match frame {
        Some(f) => &surface.frames[f],
        None => &surface.positions,
    };
    let mut s = format!(
        "# skinpatch {}: {} (mm)\no surface\n",
        env!("CARGO_PKG_VERSION"),
        surface.origin
    );
    for p in x {
        let _ = writeln!(s, "v {} {} {}", p.x, p.y, p.z);
    }
    for w in &surface.top.uvs {
        let _ = writeln!(s, "vt {} {}", w[0], w[1]);
    }
    for tri in &surface.top.triangles {
        let [a, b, c] = tri.map(|v| (surface.top.vertices[v] + 1, v + 1));
        let _ = writeln!(s, "f {}/{} {}/{} {}/{}", a.0, a.1, b.0, b.1, c.0, c.1);
    }
    crate::mesh::io::write_atomically(path, s.as_bytes())
}
