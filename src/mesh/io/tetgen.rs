//! TetGen `.node` / `.ele` / `.face` files.
//!
//! * `.node`: header `<points> <dim = 3> <attributes> <markers 0|1>`, then
//!   `<index> <x> <y> <z> [attributes…] [marker]`.
//! * `.ele`: header `<tets> <nodes per tet: 4 | 10> <attributes>`, then
//!   `<index> <n0> … [attributes…]`. The first attribute is the region id
//!   (it must be integral); without attributes every tet is region 1.
//!   Corner nodes of 10-node tets are used; mid-edge nodes are dropped.
//! * `.face` (optional): header `<faces> <markers 0|1>`, then
//!   `<index> <n0> <n1> <n2> [marker]`.
//!
//! `#` starts a comment anywhere. Numbering is 0- or 1-based, taken from the
//! first point's index (TetGen's rule), and must then run consecutively.
//! Region names, which TetGen has no place for, are kept in `.ele` comment
//! lines of the form `# region <id> <name>`; the writer emits them and the
//! reader honours them.

use std::collections::{BTreeMap, HashMap};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use super::text::{read_text, Lines, Record};
use super::write_atomically;
use crate::error::{Error, Result};
use crate::mesh::{face_key, RawMesh, TetMesh, Vec3};

/// The three file paths of a TetGen mesh with base name `base` (`base.node`, …).
pub fn tetgen_paths(base: &Path) -> [PathBuf; 3] {
    ["node", "ele", "face"].map(|ext| {
        let mut name = base.as_os_str().to_owned();
        name.push(".");
        name.push(ext);
        PathBuf::from(name)
    })
}

/// Reads `base.node`, `base.ele` and, if present, `base.face`.
pub fn read_tetgen(base: &Path) -> Result<TetMesh> {
    let [node_path, ele_path, face_path] = tetgen_paths(base);
    let (positions, offset) = read_node(&node_path)?;
    let (tets, tet_region, region_names) = read_ele(&ele_path, positions.len(), offset)?;
    let face_markers = if face_path.exists() {
        read_face(&face_path, positions.len(), offset)?
    } else {
        HashMap::new()
    };
    let raw = RawMesh {
        positions,
        tets,
        tet_region,
        region_names,
        face_markers,
    };
    TetMesh::from_raw(&ele_path.display().to_string(), raw)
}

fn count(r: &Record, i: usize, what: &str) -> Result<usize> {
    r.get::<usize>(i, what)
}

fn flag(r: &Record, i: usize, what: &str) -> Result<bool> {
    match r.fields.get(i).copied() {
        None | Some("0") => Ok(false),
        Some("1") => Ok(true),
        Some(other) => Err(r.error(format!("{what} must be 0 or 1, got '{other}'"))),
    }
}

/// Checks the running index of record `k` and returns nothing on success.
fn check_index(r: &Record, k: usize, offset: usize, what: &str) -> Result<()> {
    let index: i64 = r.get(0, &format!("{what} index"))?;
    if index != (k + offset) as i64 {
        return Err(r.error(format!(
            "{what} index {index} out of sequence: expected {} ({}-based numbering)",
            k + offset,
            offset
        )));
    }
    Ok(())
}

/// Converts a file vertex number to a 0-based index, checking its range.
fn vertex(r: &Record, i: usize, num_vertices: usize, offset: usize) -> Result<usize> {
    let n: i64 = r.get(i, "vertex index")?;
    let k = n - offset as i64;
    if k < 0 || k >= num_vertices as i64 {
        return Err(r.error(format!(
            "vertex index {n} out of range: {num_vertices} vertices numbered from {offset}"
        )));
    }
    Ok(k as usize)
}

fn read_node(path: &Path) -> Result<(Vec<Vec3>, usize)> {
    let text = read_text(path)?;
    let mut lines = Lines::new(path, &text, Some('#'));
    let head = lines.next_record("the .node header")?;
    let n = count(&head, 0, "number of points")?;
    let dim = head.fields.get(1).copied().unwrap_or("3");
    if dim != "3" {
        return Err(head.error(format!("dimension must be 3, got {dim}")));
    }
    let attributes = match head.fields.get(2) {
        Some(_) => count(&head, 2, "number of attributes")?,
        None => 0,
    };
    let marker_column = flag(&head, 3, "boundary marker flag")?;
    let width = attributes.saturating_add(4 + usize::from(marker_column));
    let mut positions = Vec::with_capacity(lines.capacity(n));
    let mut offset = 0;
    for k in 0..n {
        let r = lines.next_record(&format!("point {} of {n}", k + 1))?;
        r.expect_len(width, "a point line")?;
        if k == 0 {
            offset = match r.get::<i64>(0, "point index")? {
                0 => 0,
                1 => 1,
                other => {
                    return Err(r.error(format!(
                        "the first point must be numbered 0 or 1, got {other}"
                    )))
                }
            };
        }
        check_index(&r, k, offset, "point")?;
        positions.push(Vec3::new(
            r.float(1, "x")?,
            r.float(2, "y")?,
            r.float(3, "z")?,
        ));
    }
    if let Some(extra) = lines.next() {
        return Err(extra.error(format!("unexpected data after the {n} points")));
    }
    Ok((positions, offset))
}

type EleData = (Vec<[usize; 4]>, Vec<i32>, BTreeMap<i32, String>);

fn read_ele(path: &Path, num_vertices: usize, offset: usize) -> Result<EleData> {
    let text = read_text(path)?;
    let region_names = region_name_comments(path, &text)?;
    let mut lines = Lines::new(path, &text, Some('#'));
    let head = lines.next_record("the .ele header")?;
    let n = count(&head, 0, "number of tetrahedra")?;
    let per_tet = match head.fields.get(1) {
        Some(_) => count(&head, 1, "nodes per tetrahedron")?,
        None => 4,
    };
    if per_tet != 4 && per_tet != 10 {
        return Err(head.error(format!(
            "nodes per tetrahedron must be 4 or 10, got {per_tet}"
        )));
    }
    if per_tet == 10 {
        log::warn!(
            "{}: 10-node tets; using their corner nodes only",
            path.display()
        );
    }
    let attributes = match head.fields.get(2) {
        Some(_) => count(&head, 2, "number of attributes")?,
        None => 0,
    };
    let mut tets = Vec::with_capacity(lines.capacity(n));
    let mut regions = Vec::with_capacity(lines.capacity(n));
    for k in 0..n {
        let r = lines.next_record(&format!("tetrahedron {} of {n}", k + 1))?;
        r.expect_len(attributes.saturating_add(1 + per_tet), "a tetrahedron line")?;
        check_index(&r, k, offset, "tetrahedron")?;
        let mut tet = [0; 4];
        for (i, v) in tet.iter_mut().enumerate() {
            *v = vertex(&r, 1 + i, num_vertices, offset)?;
        }
        tets.push(tet);
        let region = if attributes > 0 {
            let a = r.float(1 + per_tet, "region attribute")?;
            if a.fract() != 0.0 || a.abs() > i32::MAX as f64 {
                return Err(r.error(format!("region attribute must be an integer, got {a}")));
            }
            a as i32
        } else {
            1
        };
        regions.push(region);
    }
    if let Some(extra) = lines.next() {
        return Err(extra.error(format!("unexpected data after the {n} tetrahedra")));
    }
    Ok((tets, regions, region_names))
}

/// Collects `# region <id> <name>` comment lines.
fn region_name_comments(path: &Path, text: &str) -> Result<BTreeMap<i32, String>> {
    let mut names = BTreeMap::new();
    for (i, line) in text.lines().enumerate() {
        let Some(rest) = line.trim_start().strip_prefix('#') else {
            continue;
        };
        let fields: Vec<&str> = rest.split_whitespace().collect();
        if let ["region", id, name] = fields[..] {
            let id: i32 = id.parse().map_err(|_| Error::Parse {
                path: path.to_path_buf(),
                line: i + 1,
                message: format!("region comment: cannot parse id '{id}'"),
            })?;
            names.insert(id, name.to_string());
        }
    }
    Ok(names)
}

fn read_face(path: &Path, num_vertices: usize, offset: usize) -> Result<HashMap<[usize; 3], i32>> {
    let text = read_text(path)?;
    let mut lines = Lines::new(path, &text, Some('#'));
    let head = lines.next_record("the .face header")?;
    let n = count(&head, 0, "number of faces")?;
    let marker_column = flag(&head, 1, "boundary marker flag")?;
    let mut markers = HashMap::with_capacity(lines.capacity(n));
    for k in 0..n {
        let r = lines.next_record(&format!("face {} of {n}", k + 1))?;
        r.expect_len(4 + usize::from(marker_column), "a face line")?;
        check_index(&r, k, offset, "face")?;
        let mut f = [0; 3];
        for (i, v) in f.iter_mut().enumerate() {
            *v = vertex(&r, 1 + i, num_vertices, offset)?;
        }
        if f[0] == f[1] || f[1] == f[2] || f[0] == f[2] {
            return Err(r.error(format!("face repeats a vertex: {f:?}")));
        }
        let marker = if marker_column {
            r.get(4, "boundary marker")?
        } else {
            1
        };
        if markers.insert(face_key(f), marker).is_some() {
            return Err(r.error("the same face is listed twice"));
        }
    }
    if let Some(extra) = lines.next() {
        return Err(extra.error(format!("unexpected data after the {n} faces")));
    }
    Ok(markers)
}

/// Writes `base.node`, `base.ele` (region id as attribute, names as
/// comments) and `base.face` (boundary faces with markers), 0-based.
/// Coordinates are written in shortest round-trip form, so a read gives the
/// same bits back.
pub fn write_tetgen(mesh: &TetMesh, base: &Path) -> Result<()> {
    let [node_path, ele_path, face_path] = tetgen_paths(base);
    let mut s = String::new();
    let _ = writeln!(
        s,
        "# skinpatch mesh: positions in mm\n{} 3 0 0",
        mesh.num_vertices()
    );
    for (i, p) in mesh.positions.iter().enumerate() {
        let _ = writeln!(s, "{i} {:?} {:?} {:?}", p.x, p.y, p.z);
    }
    write_atomically(&node_path, s.as_bytes())?;

    let mut s = String::new();
    for r in &mesh.regions {
        let _ = writeln!(s, "# region {} {}", r.id, r.name);
    }
    let _ = writeln!(s, "{} 4 1", mesh.num_tets());
    for (t, tet) in mesh.tets.iter().enumerate() {
        let _ = writeln!(
            s,
            "{t} {} {} {} {} {}",
            tet[0], tet[1], tet[2], tet[3], mesh.tet_region[t]
        );
    }
    write_atomically(&ele_path, s.as_bytes())?;

    let mut s = String::new();
    let _ = writeln!(s, "{} 1", mesh.boundary.len());
    for (i, f) in mesh.boundary.iter().enumerate() {
        let [a, b, c] = f.nodes;
        let _ = writeln!(s, "{i} {a} {b} {c} {}", f.marker);
    }
    write_atomically(&face_path, s.as_bytes())
}
