//! Legacy VTK unstructured grids (`.vtk`), read by hand: versions 2 to 5.1,
//! `ASCII` or `BINARY` (big-endian), every array type VTK and meshio write
//! (`int`, `unsigned_char`, `vtktypeint64`, …) in `SCALARS`, `VECTORS`,
//! `FIELD` and the other attribute blocks, with `METADATA` skipped.
//!
//! Errors name the file and the line of the keyword or value at fault; in
//! binary data they name the byte.

use std::path::Path;

use super::text::{Binary, Cursor};
use super::vtk_data::{Num, RawGrid, Scalar};
use super::vtu::Field;
use crate::error::{Error, Result};

/// Reads the unstructured grid of a legacy `.vtk` file.
pub(super) fn read_legacy(path: &Path, bytes: &[u8]) -> Result<RawGrid> {
    let mut r = Legacy {
        c: Cursor {
            path,
            data: bytes,
            pos: 0,
            binary: None,
        },
        binary: false,
        version: (0, 0),
        section: None,
    };
    r.header()?;
    let mut grid = RawGrid::default();
    let mut have_points = false;
    while let Some((at, words)) = r.keyword_line()? {
        let keyword = words[0].to_ascii_uppercase();
        let here = r.c.site(at);
        let word = |k: usize, what: &str| -> Result<&str> {
            words
                .get(k)
                .copied()
                .ok_or_else(|| here.error(format!("{keyword}: missing {what}")))
        };
        let count = |k: usize, what: &str| -> Result<usize> {
            let w = word(k, what)?;
            w.parse()
                .map_err(|_| here.error(format!("{keyword}: {what} '{w}' is not a count")))
        };
        let scalar = |k: usize| -> Result<Scalar> {
            let w = word(k, "the data type")?;
            Scalar::from_legacy(w)
                .ok_or_else(|| here.error(format!("{keyword}: unknown data type '{w}'")))
        };
        match keyword.as_str() {
            "POINTS" => {
                let (n, t) = (count(1, "the point count")?, scalar(2)?);
                grid.coords = r.values(at, n, 3, t, "point coordinates")?.into_f64();
                have_points = true;
            }
            "CELLS" => {
                let (a, b) = (count(1, "the first size")?, count(2, "the second size")?);
                if r.version.0 >= 5 {
                    let offsets = r.typed_block("OFFSETS", a)?;
                    let connectivity = r.typed_block("CONNECTIVITY", b)?;
                    match offsets.split_first() {
                        Some((0, ends)) => grid.ends = ends.to_vec(),
                        _ if a == 0 => {}
                        _ => return Err(here.error("OFFSETS must start at 0")),
                    }
                    grid.connectivity = connectivity;
                } else {
                    let list = r.integers(b, Scalar::I32, "the cell list")?;
                    let (ends, connectivity) =
                        cell_list(&list, a).map_err(|m| here.error(format!("CELLS: {m}")))?;
                    grid.ends = ends;
                    grid.connectivity = connectivity;
                }
            }
            "CELL_TYPES" => {
                let n = count(1, "the cell count")?;
                let types = r.integers(n, Scalar::I32, "cell types")?;
                grid.types = types
                    .into_iter()
                    .map(|t| u8::try_from(t).ok())
                    .collect::<Option<_>>()
                    .ok_or_else(|| here.error("CELL_TYPES holds a type beyond 0 … 255"))?;
            }
            "CELL_DATA" => r.section = Some((false, count(1, "the cell count")?)),
            "POINT_DATA" => r.section = Some((true, count(1, "the point count")?)),
            "METADATA" => r.skip_metadata(),
            "FIELD" => {
                let n = count(2, "the array count")?;
                for _ in 0..n {
                    let Some((at, w)) = r.keyword_line()? else {
                        return Err(r.c.ends_early("a FIELD array"));
                    };
                    let name = decode_name(w[0]);
                    let here = r.c.site(at);
                    if name == "NULL_ARRAY" {
                        continue;
                    }
                    if w.len() < 4 {
                        return Err(here.error(format!(
                            "FIELD array '{name}': expected 'name components tuples type'"
                        )));
                    }
                    let num = |s: &str, what: &str| {
                        s.parse::<usize>().map_err(|_| {
                            here.error(format!("FIELD array '{name}': {what} '{s}' is not a count"))
                        })
                    };
                    let (comps, tuples) = (num(w[1], "components")?, num(w[2], "tuples")?);
                    let t = Scalar::from_legacy(w[3]).ok_or_else(|| {
                        here.error(format!(
                            "FIELD array '{name}': unknown data type '{}'",
                            w[3]
                        ))
                    })?;
                    let values = r.values(at, tuples, comps, t, &format!("array '{name}'"))?;
                    r.attach(
                        &mut grid,
                        at,
                        values.into_field(&name, comps.max(1)),
                        tuples,
                    )?;
                }
            }
            "SCALARS"
            | "VECTORS"
            | "NORMALS"
            | "TENSORS"
            | "TENSORS6"
            | "GLOBAL_IDS"
            | "PEDIGREE_IDS"
            | "TEXTURE_COORDINATES" => {
                let name = decode_name(word(1, "the array name")?);
                let (comps, t) = match keyword.as_str() {
                    "SCALARS" => (
                        if words.len() > 3 {
                            count(3, "the component count")?
                        } else {
                            1
                        },
                        scalar(2)?,
                    ),
                    "VECTORS" | "NORMALS" => (3, scalar(2)?),
                    "TENSORS" => (9, scalar(2)?),
                    "TENSORS6" => (6, scalar(2)?),
                    "TEXTURE_COORDINATES" => (count(2, "the dimension")?, scalar(3)?),
                    _ => (1, scalar(2)?),
                };
                if keyword == "SCALARS" {
                    r.lookup_table_line();
                }
                let entries = r.entries(at, &keyword)?;
                let values = r.values(at, entries, comps, t, &format!("array '{name}'"))?;
                r.attach(
                    &mut grid,
                    at,
                    values.into_field(&name, comps.max(1)),
                    entries,
                )?;
            }
            "COLOR_SCALARS" | "LOOKUP_TABLE" => {
                // Colours for display only: read past them.
                let per = count(2, "the value count")?;
                let entries = if keyword == "LOOKUP_TABLE" {
                    per
                } else {
                    r.entries(at, &keyword)?
                };
                let comps = if keyword == "LOOKUP_TABLE" { 4 } else { per };
                let t = if r.binary { Scalar::U8 } else { Scalar::F32 };
                r.values(at, entries, comps, t, &keyword)?;
            }
            _ => {
                return Err(here.error(format!(
                    "unknown keyword '{}' in an unstructured grid (or a count before \
                         it is wrong)",
                    words[0]
                )))
            }
        }
    }
    if !have_points {
        return Err(Error::malformed(path, "the grid has no POINTS"));
    }
    Ok(grid)
}

/// Legacy (before 5.0) `CELLS` lists: `n id…` per cell.
fn cell_list(list: &[i64], cells: usize) -> std::result::Result<(Vec<i64>, Vec<i64>), String> {
    let mut ends = Vec::with_capacity(cells.min(list.len()));
    let mut connectivity = Vec::with_capacity(list.len());
    let mut at = 0usize;
    for k in 0..cells {
        let n = *list
            .get(at)
            .ok_or_else(|| format!("the list ends before cell {k}"))?;
        let ids = usize::try_from(n)
            .ok()
            .and_then(|n| list.get(at + 1..at + 1 + n))
            .ok_or_else(|| format!("cell {k} lists {n} points past the list's end"))?;
        connectivity.extend_from_slice(ids);
        ends.push(connectivity.len() as i64);
        at += 1 + ids.len();
    }
    if at != list.len() {
        return Err(format!(
            "{} values follow the {cells} cells the header announces",
            list.len() - at
        ));
    }
    Ok((ends, connectivity))
}

/// VTK 5 writes spaces in names as `%20` (any byte as `%XX`).
fn decode_name(name: &str) -> String {
    let bytes = name.as_bytes();
    let mut out = Vec::with_capacity(bytes.len());
    let mut i = 0;
    while i < bytes.len() {
        let hex = bytes
            .get(i + 1..i + 3)
            .and_then(|h| std::str::from_utf8(h).ok())
            .and_then(|h| u8::from_str_radix(h, 16).ok());
        match (bytes[i], hex) {
            (b'%', Some(b)) => {
                out.push(b);
                i += 3;
            }
            (b, _) => {
                out.push(b);
                i += 1;
            }
        }
    }
    String::from_utf8_lossy(&out).into_owned()
}

struct Legacy<'a> {
    c: Cursor<'a>,
    binary: bool,
    version: (u32, u32),
    /// The section attribute blocks belong to (points or not) with its
    /// entry count.
    section: Option<(bool, usize)>,
}

impl<'a> Legacy<'a> {
    /// The whole current line (without its newline), moving past it.
    fn line(&mut self) -> (usize, &'a str) {
        let (at, text) = self.c.rest_of_line();
        self.c.pos = (self.c.pos + 1).min(self.c.data.len());
        (at, text.trim_end_matches('\r'))
    }

    /// The version line, title, `ASCII`/`BINARY` and `DATASET` lines.
    fn header(&mut self) -> Result<()> {
        let (at, first) = self.line();
        let version = first
            .strip_prefix("# vtk DataFile Version ")
            .ok_or_else(|| {
                self.c.error_at(
                    at,
                    "not a legacy VTK file: the first line must be '# vtk DataFile Version …'",
                )
            })?
            .trim();
        let mut parts = version.split('.').map(|p| p.parse::<u32>());
        self.version = match (parts.next(), parts.next().unwrap_or(Ok(0))) {
            (Some(Ok(major)), Ok(minor)) if (2..=5).contains(&major) => (major, minor),
            _ => {
                return Err(self.c.error_at(
                    at,
                    format!("legacy VTK version '{version}' is not supported (2.0 … 5.1 are)"),
                ))
            }
        };
        self.line(); // title
        let (at, mode) = self.line();
        self.binary = match mode.trim().to_ascii_uppercase().as_str() {
            "ASCII" => false,
            "BINARY" => true,
            other => {
                return Err(self.c.error_at(
                    at,
                    format!("line 3 must say ASCII or BINARY, not '{other}'"),
                ))
            }
        };
        if self.binary {
            // Past line 3, newline bytes inside the data make line numbers
            // meaningless: errors name bytes.
            self.c.binary = Some(Binary { big_endian: true });
        }
        let Some((at, words)) = self.keyword_line()? else {
            return Err(self.c.ends_early("DATASET UNSTRUCTURED_GRID"));
        };
        match words[..] {
            [d, kind, ..] if d.eq_ignore_ascii_case("DATASET") => {
                if kind.eq_ignore_ascii_case("UNSTRUCTURED_GRID") {
                    Ok(())
                } else {
                    Err(self.c.error_at(
                        at,
                        format!("the file holds a {kind} data set; only UNSTRUCTURED_GRID is read"),
                    ))
                }
            }
            _ => Err(self.c.error_at(at, "expected 'DATASET UNSTRUCTURED_GRID'")),
        }
    }

    /// The next non-blank line split into words, or `None` at the end.
    fn keyword_line(&mut self) -> Result<Option<(usize, Vec<&'a str>)>> {
        loop {
            while self
                .c
                .data
                .get(self.c.pos)
                .is_some_and(u8::is_ascii_whitespace)
            {
                self.c.pos += 1;
            }
            let at = self.c.pos;
            if at >= self.c.data.len() {
                return Ok(None);
            }
            let (_, text) = self.line();
            let words: Vec<&str> = text.split_whitespace().collect();
            if words.is_empty() {
                if std::str::from_utf8(&self.c.data[at..self.c.pos]).is_err() {
                    return Err(self.c.error_at(
                        at,
                        "expected a keyword line, found binary data (the counts before it \
                         may be wrong)",
                    ));
                }
                continue;
            }
            return Ok(Some((at, words)));
        }
    }

    /// Skips `METADATA` lines up to the blank line that ends them.
    fn skip_metadata(&mut self) {
        while self.c.pos < self.c.data.len() {
            let (_, text) = self.line();
            if text.trim().is_empty() {
                break;
            }
        }
    }

    /// Moves past an optional `LOOKUP_TABLE name` line after `SCALARS`.
    fn lookup_table_line(&mut self) {
        let mut at = self.c.pos;
        while self
            .c
            .data
            .get(at)
            .is_some_and(|&b| b == b' ' || b == b'\t' || b == b'\r')
        {
            at += 1;
        }
        if self.c.data[at..].starts_with(b"LOOKUP_TABLE") {
            self.c.pos = at;
            self.line();
        }
    }

    /// The entry count of the current section.
    fn entries(&self, at: usize, keyword: &str) -> Result<usize> {
        self.section.map(|(_, n)| n).ok_or_else(|| {
            self.c
                .error_at(at, format!("{keyword} before CELL_DATA or POINT_DATA"))
        })
    }

    /// `entries × comps` values of type `t` (the block announced at `at`).
    fn values(
        &mut self,
        at: usize,
        entries: usize,
        comps: usize,
        t: Scalar,
        what: &str,
    ) -> Result<Num> {
        let total = entries
            .checked_mul(comps)
            .ok_or_else(|| self.c.error_at(at, format!("{what}: too many values")))?;
        self.data(total, t, what)
    }

    /// Adds an array to the current section after checking its length;
    /// field data outside a section (the data set's own) is dropped.
    fn attach(&self, grid: &mut RawGrid, at: usize, field: Field, tuples: usize) -> Result<()> {
        let Some((points, n)) = self.section else {
            return Ok(());
        };
        if tuples != n {
            return Err(self.c.error_at(
                at,
                format!(
                    "array '{}' has {tuples} entries; the {} holds {n}",
                    field.name,
                    if points {
                        "POINT_DATA section"
                    } else {
                        "CELL_DATA section"
                    }
                ),
            ));
        }
        if points {
            grid.point_data.push(field);
        } else {
            grid.cell_data.push(field);
        }
        Ok(())
    }

    /// `OFFSETS type` or `CONNECTIVITY type`, then `n` integers.
    fn typed_block(&mut self, keyword: &str, n: usize) -> Result<Vec<i64>> {
        let Some((at, words)) = self.keyword_line()? else {
            return Err(self.c.ends_early(keyword));
        };
        if !words[0].eq_ignore_ascii_case(keyword) {
            return Err(self
                .c
                .error_at(at, format!("expected {keyword}, found '{}'", words[0])));
        }
        let t = words
            .get(1)
            .and_then(|w| Scalar::from_legacy(w))
            .filter(|t| !t.is_float())
            .ok_or_else(|| {
                self.c
                    .error_at(at, format!("{keyword}: expected an integer type"))
            })?;
        self.integers(n, t, keyword)
    }

    /// `n` integers of type `t`.
    fn integers(&mut self, n: usize, t: Scalar, what: &str) -> Result<Vec<i64>> {
        let at = self.c.pos;
        self.data(n, t, what)?.into_i64().ok_or_else(|| {
            self.c
                .error_at(at, format!("{what}: expected integers within 64 bits"))
        })
    }

    /// `n` values of type `t`: big-endian bytes in a binary file,
    /// whitespace-separated numbers otherwise.
    fn data(&mut self, n: usize, t: Scalar, what: &str) -> Result<Num> {
        if self.binary {
            let at = self.c.pos;
            let left = self.c.data.len() - at;
            let bytes = n
                .checked_mul(t.size())
                .filter(|&b| b <= left)
                .ok_or_else(|| {
                    self.c.binary_error(
                        at,
                        format!(
                            "{what}: {n} {} values need more than the {left} bytes left",
                            t.name()
                        ),
                    )
                })?;
            self.c.pos += bytes;
            return Ok(t.decode(&self.c.data[at..at + bytes], true));
        }
        let mut tokens = Vec::with_capacity(self.c.capacity(n as u64));
        for _ in 0..n {
            tokens.push(self.c.token(what)?);
        }
        t.parse_text(tokens.iter().map(|t| t.1)).map_err(|k| {
            self.c.error_at(
                tokens[k].0,
                format!(
                    "{what}: value {} of {n} is '{}', not {}",
                    k + 1,
                    tokens[k].1,
                    t.describe()
                ),
            )
        })
    }
}
