//! Gmsh MSH reader for linear tetrahedra: versions 4.1 and 2.2, each ASCII
//! or binary (little- or big-endian).
//!
//! Reads `$MeshFormat`, `$PhysicalNames`, `$Entities` (4.1), `$Nodes` and
//! `$Elements`; other sections are skipped. Node tags may be sparse and in any
//! order. Tetrahedra (element type 4) become the mesh; lower-dimensional
//! elements are skipped and other 3-D elements refused.
//!
//! Region ids: in 4.1 a tet takes the first physical tag of its volume
//! entity (the entity tag when the volume has no physical group); in 2.2 its
//! own first tag, the physical group (the elementary tag when that is 0).
//! Regions are named from `$PhysicalNames` where a 3-D name exists.
//!
//! Errors name the file and, in text, the 1-based line; inside binary data
//! they name the byte offset instead.
//!
//! Written by hand rather than through a crate: the MSH crate at hand drops
//! the node tags of dense blocks (assuming they run in block order), skips
//! `$PhysicalNames`, reads neither 2.2 nor big-endian files, and reports
//! errors without positions.

use std::collections::{BTreeMap, HashMap};
use std::path::Path;

use super::text::{Binary, Cursor};
use crate::error::{Error, Result};
use crate::mesh::{RawMesh, TetMesh, Vec3};

const TET4: i32 = 4;
const TET10: i32 = 11;

/// Reads a Gmsh MSH file, version 4.1 or 2.2, ASCII or binary.
pub fn read_gmsh(path: &Path) -> Result<TetMesh> {
    let data = super::read_input(path)?;
    let mut c = Cursor {
        path,
        data: &data,
        pos: 0,
        binary: None,
    };
    let Some((at, first)) = c.token_opt()? else {
        return Err(Error::malformed(path, "empty file: no $MeshFormat section"));
    };
    if first != "$MeshFormat" {
        return Err(c.error_at(at, "the file must start with $MeshFormat"));
    }
    let version = read_format(&mut c)?;
    c.expect_end("MeshFormat")?;
    let mut state = State::default();
    while let Some((at, section)) = c.token_opt()? {
        let Some(name) = section.strip_prefix('$') else {
            return Err(c.error_at(
                at,
                format!("expected a section header like $Nodes, got '{section}'"),
            ));
        };
        match (name, version) {
            ("PhysicalNames", _) => read_physical_names(&mut c, &mut state)?,
            ("Entities", Version::V41) => {
                read_entities(&mut c, &mut state)?;
                state.entities = true;
            }
            ("Nodes", Version::V41) => read_nodes_41(&mut c, &mut state)?,
            ("Elements", Version::V41) => read_elements_41(&mut c, &mut state)?,
            ("Nodes", Version::V22) => read_nodes_22(&mut c, &mut state)?,
            ("Elements", Version::V22) => read_elements_22(&mut c, &mut state)?,
            (other, _) => {
                log::debug!("{}: skipping section ${other}", path.display());
                c.skip_section(at, other)?;
                continue;
            }
        }
        c.expect_end(name)?;
    }
    if version == Version::V41 && !state.entities && !state.names.is_empty() {
        // meshio's 4.1 writer keeps $PhysicalNames but not the $Entities
        // that tie physical groups to elements: the element blocks' entity
        // tags are all the file says.
        let names: Vec<&str> = state.names.values().map(String::as_str).collect();
        log::warn!(
            "{}: the file has no $Entities section, so its physical groups ({}) cannot be \
             tied to elements; regions are the element blocks' entity tags, named \
             region_<tag>. To keep the groups, save the mesh from Gmsh itself, from \
             meshio as MSH 2.2 (file_format=\"gmsh22\"), or as VTU",
            path.display(),
            names.join(", ")
        );
        state.names.clear();
    }
    state.finish(&c)
}

#[derive(Clone, Copy, PartialEq, Eq, Debug)]
enum Version {
    V41,
    V22,
}

/// Reads the line after `$MeshFormat`: version, file type and data size,
/// then in binary files the endianness marker (the integer 1).
fn read_format(c: &mut Cursor) -> Result<Version> {
    let (at, version) = c.token("the format line 'version file-type data-size'")?;
    let version = match version {
        "4.1" => Version::V41,
        "2.2" | "2.1" | "2.0" | "2" => Version::V22,
        other => {
            return Err(c.error_at(
                at,
                format!("MSH version {other} is not supported; save as 4.1 or 2.2"),
            ))
        }
    };
    let (at, kind) = c.token("the file type (0 text, 1 binary)")?;
    let binary = match kind {
        "0" => false,
        "1" => true,
        other => return Err(c.error_at(at, format!("file type '{other}' is neither 0 nor 1"))),
    };
    let (at, size) = c.token("the data size")?;
    if size != "8" {
        return Err(c.error_at(
            at,
            format!("data size {size} is not supported; only 8-byte numbers (the Gmsh default)"),
        ));
    }
    if binary {
        c.end_of_line();
        let at = c.mark();
        let marker: [u8; 4] = c.bytes("the endianness marker")?;
        let big_endian = match (i32::from_le_bytes(marker), i32::from_be_bytes(marker)) {
            (1, _) => false,
            (_, 1) => true,
            _ => {
                return Err(c.binary_error(
                    at,
                    "the endianness marker is not the integer 1 in either byte order",
                ))
            }
        };
        c.binary = Some(Binary { big_endian });
    }
    Ok(version)
}

/// Node count of each Gmsh element type up to 31 (lines, triangles,
/// quadrangles, tetrahedra, hexahedra, prisms, pyramids, points and their
/// higher-order forms), so that blocks of other elements can be skipped.
fn nodes_of(kind: i32) -> Option<usize> {
    const NODES: [usize; 31] = [
        2, 3, 4, 4, 8, 6, 5, 3, 6, 9, 10, 27, 18, 14, 1, 8, 20, 15, 13, 9, 10, 12, 15, 15, 21, 4,
        5, 6, 20, 35, 56,
    ];
    usize::try_from(kind)
        .ok()
        .and_then(|k| k.checked_sub(1))
        .and_then(|k| NODES.get(k).copied())
}

/// Dimension of element types 1…31 (the ones [`nodes_of`] knows).
fn dim_of(kind: i32) -> usize {
    match kind {
        15 => 0,
        1 | 8 | 26 | 27 | 28 => 1,
        2 | 3 | 9 | 10 | 16 | 20..=25 => 2,
        _ => 3,
    }
}

/// What to say after an error at an element block's header when a block
/// (header offset, declared count) came before it: a count too small
/// leaves that block's last elements to be read as this header.
fn short_block_hint(c: &Cursor, previous: Option<(usize, u64)>) -> String {
    match previous {
        Some((at, count)) => format!(
            "; if this is an element, the block before it ({}) holds more than the {count} \
             elements it declares",
            c.site(at).place()
        ),
        None => String::new(),
    }
}

/// Checks an element type of a 3-D block or element: linear tets only.
fn check_volume_type(kind: i32) -> std::result::Result<(), String> {
    match kind {
        TET4 => Ok(()),
        TET10 => Err(
            "second-order tetrahedra (type 11) are not supported; mesh with Mesh.ElementOrder = 1"
                .into(),
        ),
        other => Err(format!(
            "3-D element type {other} is not supported; only linear tetrahedra (type 4)"
        )),
    }
}

#[derive(Default)]
struct State {
    /// Whether a 4.1 file had `$Entities`.
    entities: bool,
    /// 3-D physical names by tag.
    names: BTreeMap<i32, String>,
    /// Volume entity tag → region id (4.1).
    volume_region: HashMap<i32, i32>,
    /// Node tag → index in `positions`.
    node_index: HashMap<u64, usize>,
    positions: Vec<Vec3>,
    /// (element tag, node tags, region id, byte offset of the element)
    tets: Vec<(u64, [u64; 4], i32, usize)>,
}

impl State {
    fn add_node(&mut self, c: &Cursor, at: usize, tag: u64, p: Vec3) -> Result<()> {
        if self.node_index.insert(tag, self.positions.len()).is_some() {
            return Err(c.error_at(at, format!("node tag {tag} is defined twice")));
        }
        self.positions.push(p);
        Ok(())
    }

    fn finish(self, c: &Cursor) -> Result<TetMesh> {
        let mut tets = Vec::with_capacity(self.tets.len());
        let mut tet_region = Vec::with_capacity(self.tets.len());
        for (tag, nodes, region, at) in &self.tets {
            let mut tet = [0; 4];
            for (slot, node) in tet.iter_mut().zip(nodes) {
                *slot = *self.node_index.get(node).ok_or_else(|| {
                    c.error_at(
                        *at,
                        format!("element {tag} refers to node {node}, which is not defined"),
                    )
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
        TetMesh::from_raw(&c.path.display().to_string(), raw)
    }
}

fn read_physical_names(c: &mut Cursor, state: &mut State) -> Result<()> {
    let n: usize = c.parse("the number of physical names")?;
    for _ in 0..n {
        let dim: i32 = c.parse("a physical name's dimension")?;
        let tag: i32 = c.parse("a physical name's tag")?;
        let (at, rest) = c.rest_of_line();
        let name = rest.trim().trim_matches('"').trim();
        if name.is_empty() {
            return Err(c.error_at(at, "physical name: missing quoted name"));
        }
        if dim == 3 {
            state
                .names
                .insert(tag, name.replace(char::is_whitespace, "_"));
        }
    }
    Ok(())
}

fn read_entities(c: &mut Cursor, state: &mut State) -> Result<()> {
    c.start_binary_block();
    let mut counts = [0u64; 4];
    for n in &mut counts {
        *n = c.size("an entity count")?;
    }
    // Points: tag x y z nPhys phys…; curves, surfaces, volumes:
    // tag minX minY minZ maxX maxY maxZ nPhys phys… nBound bound…
    for (dim, &n) in counts.iter().enumerate() {
        for _ in 0..n {
            let tag = c.int("an entity tag")?;
            for _ in 0..if dim == 0 { 3 } else { 6 } {
                c.real("an entity coordinate")?;
            }
            let nphys = c.size("the number of physical tags")?;
            let mut region = tag;
            for k in 0..nphys {
                let phys = c.int("a physical tag")?;
                if k == 0 {
                    region = phys;
                }
            }
            if dim > 0 {
                let nbound = c.size("the number of bounding entities")?;
                for _ in 0..nbound {
                    c.int("a bounding entity")?;
                }
            }
            if dim == 3 {
                state.volume_region.insert(tag, region);
            }
        }
    }
    Ok(())
}

fn read_nodes_41(c: &mut Cursor, state: &mut State) -> Result<()> {
    c.start_binary_block();
    let head = c.mark();
    let blocks = c.size("the number of node blocks")?;
    let total = c.size("the number of nodes")?;
    c.size("the smallest node tag")?;
    c.size("the largest node tag")?;
    let before = state.positions.len();
    for _ in 0..blocks {
        let dim = c.int("a node block's entity dimension")?;
        c.int("a node block's entity tag")?;
        let parametric = c.int("a node block's parametric flag")?;
        let n = c.size("the number of nodes in a block")?;
        let mut tags = Vec::with_capacity(c.capacity(n));
        for _ in 0..n {
            tags.push(c.size("a node tag")?);
        }
        let extra = if parametric == 1 {
            usize::try_from(dim.clamp(0, 3)).unwrap_or(0)
        } else {
            0
        };
        for tag in tags {
            let at = c.mark();
            let p = Vec3::new(c.real("x")?, c.real("y")?, c.real("z")?);
            for _ in 0..extra {
                c.real("a parametric coordinate")?;
            }
            state.add_node(c, at, tag, p)?;
        }
    }
    let read = state.positions.len() - before;
    if read as u64 != total {
        return Err(c.error_at(
            head,
            format!("header announces {total} nodes, the blocks hold {read}"),
        ));
    }
    Ok(())
}

fn read_elements_41(c: &mut Cursor, state: &mut State) -> Result<()> {
    c.start_binary_block();
    let head = c.mark();
    let blocks = c.size("the number of element blocks")?;
    let total = c.size("the number of elements")?;
    c.size("the smallest element tag")?;
    c.size("the largest element tag")?;
    let mut seen = 0u64;
    // The block before (its header's offset and count): a count that is
    // too small leaves its last elements to be read as the next header,
    // which is then what the error names.
    let mut previous: Option<(usize, u64)> = None;
    for _ in 0..blocks {
        let at = c.mark();
        let dim = c.int("an element block's entity dimension")?;
        let entity = c.int("an element block's entity tag")?;
        let kind = c.int("an element type")?;
        let n = c.size("the number of elements in a block")?;
        let header_error = |c: &Cursor, message: String| {
            let hint = short_block_hint(c, previous);
            c.error_at(at, format!("element block header: {message}{hint}"))
        };
        if c.binary.is_none() {
            // A header is one line of four numbers; an element line is
            // longer (its tag and node tags).
            let (_, rest) = c.rest_of_line();
            let extra = rest.split_whitespace().count();
            if extra > 0 {
                return Err(header_error(
                    c,
                    format!("{} values on the line, where a header has 4", 4 + extra),
                ));
            }
        }
        if seen.saturating_add(n) > total {
            return Err(c.error_at(
                at,
                format!(
                    "element block header: {n} elements here and {seen} in the blocks before \
                     exceed the {total} the section header ({}) announces",
                    c.site(head).place()
                ),
            ));
        }
        if dim == 3 {
            check_volume_type(kind).map_err(|m| header_error(c, m))?;
        }
        let nodes = nodes_of(kind)
            .ok_or_else(|| header_error(c, format!("unknown element type {kind}")))?;
        if i32::try_from(dim_of(kind)) != Ok(dim) {
            return Err(header_error(
                c,
                format!(
                    "entity dimension {dim} does not match element type {kind} (dimension {})",
                    dim_of(kind)
                ),
            ));
        }
        previous = Some((at, n));
        let block_at = at;
        let region = *state.volume_region.get(&entity).unwrap_or(&entity);
        for _ in 0..n {
            let at = c.mark();
            let tag = c.size("an element tag")?;
            let mut tet = [0u64; 4];
            for k in 0..nodes {
                let node = c.size("an element's node tag")?;
                if let Some(slot) = tet.get_mut(k) {
                    *slot = node;
                }
            }
            if c.binary.is_none() {
                // One element a line, its tag and `nodes` node tags: a
                // line short of them, or a longer one, means the block's
                // count does not match its lines.
                let spans_lines = c.data[at..c.pos].contains(&b'\n');
                let (_, rest) = c.rest_of_line();
                if spans_lines || !rest.trim().is_empty() {
                    return Err(c.error_at(
                        at,
                        format!(
                            "an element of type {kind} is a line of {} values (its tag and \
                             {nodes} node tags), this one is not; the block ({}) declares {n} \
                             elements: is that its number of lines?",
                            1 + nodes,
                            c.site(block_at).place()
                        ),
                    ));
                }
            }
            seen += 1;
            if dim == 3 {
                state.tets.push((tag, tet, region, at));
            }
        }
    }
    if seen != total {
        return Err(c.error_at(
            head,
            format!("header announces {total} elements, the blocks hold {seen}"),
        ));
    }
    Ok(())
}

fn read_nodes_22(c: &mut Cursor, state: &mut State) -> Result<()> {
    let n: u64 = c.parse("the number of nodes")?;
    c.start_binary_block();
    for _ in 0..n {
        let at = c.mark();
        let tag = if c.binary.is_some() {
            u64::try_from(c.int("a node tag")?)
                .map_err(|_| c.binary_error(at, "negative node tag"))?
        } else {
            c.parse("a node tag")?
        };
        let p = Vec3::new(c.real("x")?, c.real("y")?, c.real("z")?);
        state.add_node(c, at, tag, p)?;
    }
    Ok(())
}

fn read_elements_22(c: &mut Cursor, state: &mut State) -> Result<()> {
    let total: u64 = c.parse("the number of elements")?;
    c.start_binary_block();
    let mut seen = 0u64;
    let mut previous: Option<(usize, u64)> = None;
    while seen < total {
        // Binary data comes in blocks (type, count, tag count) of like
        // elements; text has one element a line with its own type.
        let at = c.mark();
        let (text_tag, kind, count, ntags) = if c.binary.is_some() {
            let kind = c.int("an element block's type")?;
            let count = c.int("an element block's count")?;
            let ntags = c.int("an element block's tag count")?;
            let count =
                u64::try_from(count).map_err(|_| c.binary_error(at, "negative element count"))?;
            (None, kind, count, ntags)
        } else {
            let tag = c.parse::<u64>("an element tag")?;
            let kind = c.parse("an element type")?;
            let ntags = c.parse("an element's tag count")?;
            (Some(tag), kind, 1, ntags)
        };
        // In binary data a block's count that is too small leaves its last
        // elements to be read as the next block's header.
        let header_error = |c: &Cursor, message: String| {
            c.error_at(at, format!("{message}{}", short_block_hint(c, previous)))
        };
        let nodes = nodes_of(kind)
            .ok_or_else(|| header_error(c, format!("unknown element type {kind}")))?;
        let volume = dim_of(kind) == 3;
        if volume {
            check_volume_type(kind).map_err(|m| header_error(c, m))?;
        }
        if c.binary.is_some() {
            previous = Some((at, count));
        }
        if ntags < 0 {
            return Err(c.error_at(at, format!("negative tag count {ntags}")));
        }
        for k in 0..count {
            let at = if k == 0 { at } else { c.mark() };
            let tag = match text_tag {
                Some(tag) => tag,
                None => {
                    let at = c.mark();
                    u64::try_from(c.int("an element tag")?)
                        .map_err(|_| c.binary_error(at, "negative element tag"))?
                }
            };
            let mut tags = [0i32; 2];
            for t in 0..ntags as usize {
                let v = c.int("an element tag value")?;
                if let Some(slot) = tags.get_mut(t) {
                    *slot = v;
                }
            }
            let mut tet = [0u64; 4];
            for n in 0..nodes {
                let at = c.mark();
                let node = c.int("an element's node tag")?;
                let node = u64::try_from(node).map_err(|_| c.error_at(at, "negative node tag"))?;
                if let Some(slot) = tet.get_mut(n) {
                    *slot = node;
                }
            }
            seen += 1;
            if seen > total {
                return Err(c.error_at(
                    at,
                    format!("header announces {total} elements, the blocks hold more"),
                ));
            }
            if volume {
                let region = if tags[0] != 0 { tags[0] } else { tags[1] };
                state.tets.push((tag, tet, region, at));
            }
        }
    }
    Ok(())
}

impl Cursor<'_> {
    /// A 4-byte integer in binary files, a text token otherwise.
    fn int(&mut self, what: &str) -> Result<i32> {
        if self.binary.is_none() {
            return self.parse(what);
        }
        let b = self.bytes::<4>(what)?;
        Ok(if self.big_endian() {
            i32::from_be_bytes(b)
        } else {
            i32::from_le_bytes(b)
        })
    }

    /// An 8-byte unsigned size in binary files, a text token otherwise.
    fn size(&mut self, what: &str) -> Result<u64> {
        if self.binary.is_none() {
            return self.parse(what);
        }
        let b = self.bytes::<8>(what)?;
        Ok(if self.big_endian() {
            u64::from_be_bytes(b)
        } else {
            u64::from_le_bytes(b)
        })
    }

    /// A finite 8-byte float in binary files, a text token otherwise.
    fn real(&mut self, what: &str) -> Result<f64> {
        let at = self.pos;
        let v = if self.binary.is_none() {
            self.parse(what)?
        } else {
            let b = self.bytes::<8>(what)?;
            if self.big_endian() {
                f64::from_be_bytes(b)
            } else {
                f64::from_le_bytes(b)
            }
        };
        if v.is_finite() {
            Ok(v)
        } else {
            Err(self.error_at(at, format!("{what} is not finite ({v})")))
        }
    }

    /// Requires the token `$End<name>`.
    fn expect_end(&mut self, name: &str) -> Result<()> {
        let end = format!("$End{name}");
        let (at, token) = self.token(&end)?;
        if token == end {
            Ok(())
        } else {
            Err(self.error_at(
                at,
                format!(
                    "expected {end}, got '{token}': the section holds more than its header \
                     announces, or a value is missing before this"
                ),
            ))
        }
    }

    /// Moves past `$End<name>` of a section this reader does not use.
    fn skip_section(&mut self, at: usize, name: &str) -> Result<()> {
        let end = format!("$End{name}");
        let found = self.data[self.pos..]
            .windows(end.len())
            .position(|w| w == end.as_bytes());
        match found {
            Some(k) => {
                self.pos += k + end.len();
                Ok(())
            }
            None => Err(self.error_at(at, format!("section ${name} has no {end}"))),
        }
    }
}
