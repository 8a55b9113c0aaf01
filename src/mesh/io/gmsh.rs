//! Gmsh MSH 4.1 (ASCII) reader for linear tetrahedra.
//!
//! Reads `$MeshFormat`, `$PhysicalNames`, `$Entities`, `$Nodes` and
//! `$Elements`; other sections are skipped. Node tags may be sparse and in any
//! order across blocks. Tetrahedra (element type 4) become the mesh; every
//! tet takes the first physical tag of its volume entity as region id (the
//! entity tag when the volume has no physical group), named from
//! `$PhysicalNames` where a 3-D name exists. Lower-dimensional elements are
//! ignored. Binary files are rejected with a hint to save as ASCII.
//!
//! Written by hand rather than through a crate: the MSH crate at hand drops
//! the node tags of dense blocks (assuming they run in block order), skips
//! `$PhysicalNames`, and reports errors without line numbers.

use std::collections::{BTreeMap, HashMap};
use std::path::Path;

use super::text::{read_text, Lines, Record};
use crate::error::{Error, Result};
use crate::mesh::{RawMesh, TetMesh, Vec3};

const TET4: i32 = 4;

/// Reads a Gmsh MSH 4.1 ASCII file.
pub fn read_gmsh(path: &Path) -> Result<TetMesh> {
    let text = read_text(path)?;
    let mut lines = Lines::new(path, &text, None);
    let mut state = State::default();
    let mut saw_format = false;
    while let Some(r) = lines.next() {
        let section = r.fields[0];
        let Some(name) = section.strip_prefix('$') else {
            return Err(r.error(format!(
                "expected a section header like $Nodes, got '{section}'"
            )));
        };
        match name {
            "MeshFormat" => {
                read_format(&mut lines)?;
                saw_format = true;
            }
            _ if !saw_format => return Err(r.error("the file must start with $MeshFormat")),
            "PhysicalNames" => read_physical_names(&mut lines, &mut state)?,
            "Entities" => read_entities(&mut lines, &mut state)?,
            "Nodes" => read_nodes(&mut lines, &mut state)?,
            "Elements" => read_elements(&mut lines, &mut state)?,
            other => {
                log::debug!("{}: skipping section ${other}", path.display());
                skip_section(&mut lines, other)?;
                continue;
            }
        }
        let end = lines.next_record(&format!("$End{name}"))?;
        if end.fields[0] != format!("$End{name}") {
            return Err(end.error(format!("expected $End{name}, got '{}'", end.fields[0])));
        }
    }
    if !saw_format {
        return Err(Error::malformed(path, "empty file: no $MeshFormat section"));
    }
    state.finish(path)
}

#[derive(Default)]
struct State {
    /// 3-D physical names by tag.
    names: BTreeMap<i32, String>,
    /// Volume entity tag → region id.
    volume_region: HashMap<i32, i32>,
    /// Node tag → index in `positions`.
    node_index: HashMap<u64, usize>,
    positions: Vec<Vec3>,
    /// (element tag, node tags, region id, line)
    tets: Vec<(u64, [u64; 4], i32, usize)>,
}

impl State {
    fn finish(self, path: &Path) -> Result<TetMesh> {
        let mut tets = Vec::with_capacity(self.tets.len());
        let mut tet_region = Vec::with_capacity(self.tets.len());
        for (tag, nodes, region, line) in &self.tets {
            let mut tet = [0; 4];
            for (slot, node) in tet.iter_mut().zip(nodes) {
                *slot = *self.node_index.get(node).ok_or_else(|| Error::Parse {
                    path: path.to_path_buf(),
                    line: *line,
                    message: format!("element {tag} refers to node {node}, which is not defined"),
                })?;
            }
            tets.push(tet);
            tet_region.push(*region);
        }
        let raw = RawMesh {
            positions: self.positions,
            tets,
            tet_region,
            region_names: self.names,
            face_markers: HashMap::new(),
        };
        TetMesh::from_raw(&path.display().to_string(), raw)
    }
}

fn read_format(lines: &mut Lines) -> Result<()> {
    let r = lines.next_record("the format line 'version file-type data-size'")?;
    r.expect_len(3, "the format line")?;
    if r.fields[0] != "4.1" {
        return Err(r.error(format!(
            "MSH version {} is not supported; save as 4.1",
            r.fields[0]
        )));
    }
    if r.fields[1] != "0" {
        return Err(r.error("binary MSH is not supported; save as ASCII (Mesh.Binary = 0)"));
    }
    Ok(())
}

fn skip_section(lines: &mut Lines, name: &str) -> Result<()> {
    let end = format!("$End{name}");
    loop {
        let (_, text) = lines.next_text(&end)?;
        if text == end {
            return Ok(());
        }
    }
}

fn count(r: &Record, i: usize, what: &str) -> Result<usize> {
    r.get(i, what)
}

fn read_physical_names(lines: &mut Lines, state: &mut State) -> Result<()> {
    let r = lines.next_record("the number of physical names")?;
    let n = count(&r, 0, "number of physical names")?;
    for _ in 0..n {
        let (line, text) = lines.next_text("a physical name line")?;
        let bad = |m: &str| Error::Parse {
            path: lines.path().to_path_buf(),
            line,
            message: m.to_string(),
        };
        let mut parts = text.splitn(3, char::is_whitespace);
        let dim: i32 = parts
            .next()
            .and_then(|s| s.parse().ok())
            .ok_or_else(|| bad("physical name: bad dimension"))?;
        let tag: i32 = parts
            .next()
            .and_then(|s| s.parse().ok())
            .ok_or_else(|| bad("physical name: bad tag"))?;
        let name = parts
            .next()
            .map(|s| s.trim().trim_matches('"').to_string())
            .filter(|s| !s.is_empty())
            .ok_or_else(|| bad("physical name: missing quoted name"))?;
        if dim == 3 {
            state
                .names
                .insert(tag, name.replace(char::is_whitespace, "_"));
        }
    }
    Ok(())
}

fn read_entities(lines: &mut Lines, state: &mut State) -> Result<()> {
    let r = lines.next_record("entity counts")?;
    r.expect_len(4, "the entity counts line")?;
    let counts: Vec<usize> = (0..4)
        .map(|i| count(&r, i, "entity count"))
        .collect::<Result<_>>()?;
    // Points: tag x y z nPhys phys…; curves, surfaces, volumes:
    // tag minX minY minZ maxX maxY maxZ nPhys phys… nBound bound…
    for (dim, &n) in counts.iter().enumerate() {
        for _ in 0..n {
            let r = lines.next_record(&format!("a {dim}-D entity"))?;
            let phys_at = if dim == 0 { 4 } else { 7 };
            let tag: i32 = r.get(0, "entity tag")?;
            let nphys = count(&r, phys_at, "number of physical tags")?;
            r.expect_len(phys_at + 1 + nphys, "an entity line")?;
            if dim == 3 {
                let region = if nphys > 0 {
                    r.get(phys_at + 1, "physical tag")?
                } else {
                    tag
                };
                state.volume_region.insert(tag, region);
            }
        }
    }
    Ok(())
}

fn read_nodes(lines: &mut Lines, state: &mut State) -> Result<()> {
    let head = lines.next_record("the $Nodes header")?;
    head.expect_len(4, "the $Nodes header")?;
    let blocks = count(&head, 0, "number of node blocks")?;
    let total = count(&head, 1, "number of nodes")?;
    for _ in 0..blocks {
        let r = lines.next_record("a node block header")?;
        r.expect_len(4, "a node block header")?;
        let dim: usize = r.get(0, "entity dimension")?;
        let parametric: u8 = r.get(2, "parametric flag")?;
        let n = count(&r, 3, "number of nodes in block")?;
        let mut tags = Vec::with_capacity(lines.capacity(n));
        for _ in 0..n {
            let t = lines.next_record("a node tag")?;
            tags.push((t.get::<u64>(0, "node tag")?, t.line));
        }
        let width = 3 + if parametric == 1 { dim } else { 0 };
        for (tag, tag_line) in tags {
            let c = lines.next_record("node coordinates")?;
            c.expect_len(width, "a node coordinate line")?;
            let p = Vec3::new(c.float(0, "x")?, c.float(1, "y")?, c.float(2, "z")?);
            if state
                .node_index
                .insert(tag, state.positions.len())
                .is_some()
            {
                return Err(c.error(format!("node tag {tag} (line {tag_line}) is defined twice")));
            }
            state.positions.push(p);
        }
    }
    if state.positions.len() != total {
        return Err(head.error(format!(
            "header announces {total} nodes, the blocks hold {}",
            state.positions.len()
        )));
    }
    Ok(())
}

fn read_elements(lines: &mut Lines, state: &mut State) -> Result<()> {
    let head = lines.next_record("the $Elements header")?;
    head.expect_len(4, "the $Elements header")?;
    let blocks = count(&head, 0, "number of element blocks")?;
    let total = count(&head, 1, "number of elements")?;
    let mut seen = 0;
    for _ in 0..blocks {
        let r = lines.next_record("an element block header")?;
        r.expect_len(4, "an element block header")?;
        let dim: i32 = r.get(0, "entity dimension")?;
        let entity: i32 = r.get(1, "entity tag")?;
        let kind: i32 = r.get(2, "element type")?;
        let n = count(&r, 3, "number of elements in block")?;
        let region = if dim == 3 {
            *state.volume_region.get(&entity).unwrap_or(&entity)
        } else {
            0
        };
        if dim == 3 && kind != TET4 {
            return Err(r.error(format!(
                "3-D element type {kind} is not supported; only linear tetrahedra (type 4)"
            )));
        }
        for _ in 0..n {
            let e = lines.next_record("an element line")?;
            seen += 1;
            if dim != 3 {
                continue;
            }
            e.expect_len(5, "a tetrahedron line")?;
            let tag: u64 = e.get(0, "element tag")?;
            let mut nodes = [0u64; 4];
            for (i, node) in nodes.iter_mut().enumerate() {
                *node = e.get(1 + i, "node tag")?;
            }
            state.tets.push((tag, nodes, region, e.line));
        }
    }
    if seen != total {
        return Err(head.error(format!(
            "header announces {total} elements, the blocks hold {seen}"
        )));
    }
    Ok(())
}
