//! VTK XML unstructured grids (`.vtu`) read by hand: every layout VTK,
//! ParaView and meshio write — `ascii`, inline `binary` (base64) and
//! `appended` arrays, the appended block `raw` (VTK's default) or base64,
//! uncompressed or zlib-compressed, UInt32 or UInt64 headers, either byte
//! order.
//!
//! Every size the file states (header words, block tables, offsets) is
//! checked against the bytes that are there before anything is sliced or
//! allocated, and every error names the file, the line of the element at
//! fault and, inside appended data, the byte.

use std::io::Read;
use std::path::Path;

use base64::engine::{DecodePaddingMode, GeneralPurpose, GeneralPurposeConfig};
use roxmltree::{Document, Node};

use super::vtk_data::{Num, RawGrid, Scalar};
use crate::error::{Error, Result};

/// Reads the one piece of a `.vtu` file's unstructured grid.
pub(super) fn read_xml(path: &Path, bytes: &[u8]) -> Result<RawGrid> {
    let (head, appended) = split_appended(path, bytes)?;
    let doc = Document::parse(&head).map_err(|e| Error::Parse {
        path: path.to_path_buf(),
        line: e.pos().row as usize,
        message: format!("not well-formed XML: {e}"),
    })?;
    let root = doc.root_element();
    let r = Reader::new(path, &doc, root, appended)?;
    let kind = root.attribute("type").unwrap_or("");
    if kind != "UnstructuredGrid" {
        return Err(r.error(
            root,
            format!("the file holds a {kind:?} data set; only an UnstructuredGrid is read"),
        ));
    }
    let grid = r.child(root, "UnstructuredGrid")?;
    let pieces: Vec<Node> = grid
        .children()
        .filter(|n| n.has_tag_name("Piece"))
        .collect();
    let [piece] = pieces[..] else {
        return Err(r.error(
            grid,
            format!("expected one <Piece>, found {}", pieces.len()),
        ));
    };
    let points = r.count(piece, "NumberOfPoints")?;
    let cells = r.count(piece, "NumberOfCells")?;

    let point_array = r.child(r.child(piece, "Points")?, "DataArray")?;
    let (coords, components) = r.array(point_array, Some(points))?;
    if components != 3 {
        return Err(r.error(
            point_array,
            format!("points have {components} components, expected 3"),
        ));
    }
    let cell_node = r.child(piece, "Cells")?;
    let named = |name: &str| {
        cell_node
            .children()
            .find(|n| n.has_tag_name("DataArray") && n.attribute("Name") == Some(name))
            .ok_or_else(|| {
                r.error(
                    cell_node,
                    format!("<Cells> has no DataArray named '{name}'"),
                )
            })
    };
    let integers = |node: Node, count: Option<usize>| -> Result<Vec<i64>> {
        let (values, _) = r.array(node, count)?;
        values.into_i64().ok_or_else(|| {
            r.error(
                node,
                format!(
                    "DataArray '{}' holds floats or values beyond 64 bits; expected integers",
                    node.attribute("Name").unwrap_or("")
                ),
            )
        })
    };
    let ends = integers(named("offsets")?, Some(cells))?;
    let links = ends
        .last()
        .map_or(0, |&e| usize::try_from(e).unwrap_or(usize::MAX));
    let connectivity_node = named("connectivity")?;
    let connectivity = integers(connectivity_node, None)?;
    if connectivity.len() < links {
        return Err(r.error(
            connectivity_node,
            format!(
                "connectivity has {} point ids; the last offset needs {links}",
                connectivity.len()
            ),
        ));
    }
    let types_node = named("types")?;
    let types = integers(types_node, Some(cells))?
        .into_iter()
        .map(|t| u8::try_from(t).ok())
        .collect::<Option<Vec<u8>>>()
        .ok_or_else(|| {
            r.error(
                types_node,
                "DataArray 'types' holds a cell type beyond 0 … 255",
            )
        })?;

    let fields = |section: &str, count: usize| -> Result<Vec<_>> {
        let Some(node) = piece.children().find(|n| n.has_tag_name(section)) else {
            return Ok(Vec::new());
        };
        node.children()
            .filter(|n| n.has_tag_name("DataArray"))
            .map(|a| {
                let (values, components) = r.array(a, Some(count))?;
                Ok(values.into_field(a.attribute("Name").unwrap_or(""), components))
            })
            .collect()
    };
    Ok(RawGrid {
        coords: coords.into_f64(),
        connectivity,
        ends,
        types,
        point_data: fields("PointData", points)?,
        cell_data: fields("CellData", cells)?,
    })
}

/// The `<AppendedData>` block: its payload after the `_` marker.
struct Appended<'a> {
    raw: bool,
    data: &'a [u8],
    /// File offset of `data[0]`, for messages.
    at: usize,
}

/// The appended payload's bytes after the `_` marker and their file
/// offset.
type Payload<'a> = (&'a [u8], usize);

/// Splits the file into the XML text and the appended payload, which in
/// the `raw` encoding is not text: the XML is cut at `<AppendedData …>` and
/// closed there, so the parser sees the tag and its attributes only.
fn split_appended<'a>(path: &Path, bytes: &'a [u8]) -> Result<(String, Option<Payload<'a>>)> {
    let find = |needle: &[u8], from: usize| {
        bytes[from..]
            .windows(needle.len())
            .position(|w| w == needle)
            .map(|k| k + from)
    };
    let utf8 = |b: &[u8]| {
        std::str::from_utf8(b).map(str::to_owned).map_err(|e| {
            Error::malformed(
                path,
                format!(
                    "byte {}: not text (invalid UTF-8) before any appended data",
                    e.valid_up_to()
                ),
            )
        })
    };
    let Some(tag) = find(b"<AppendedData", 0) else {
        return Ok((utf8(bytes)?, None));
    };
    let Some(close) = find(b">", tag) else {
        return Err(Error::malformed(
            path,
            "the <AppendedData> tag is not closed",
        ));
    };
    let mut head = utf8(&bytes[..close])?;
    let self_closed = head.ends_with('/');
    head.truncate(head.trim_end_matches('/').len());
    head.push_str("/></VTKFile>");
    if self_closed {
        return Ok((head, None));
    }
    let mut at = close + 1;
    while bytes.get(at).is_some_and(u8::is_ascii_whitespace) {
        at += 1;
    }
    if bytes.get(at) != Some(&b'_') {
        return Err(Error::malformed(
            path,
            format!("byte {at}: appended data must start with '_'"),
        ));
    }
    let start = at + 1;
    Ok((head, Some((&bytes[start..], start))))
}

/// The file-wide settings every array is read with.
struct Reader<'a, 'd> {
    path: &'a Path,
    doc: &'d Document<'d>,
    big_endian: bool,
    /// The type of block-header words (UInt32 or UInt64).
    header: Scalar,
    zlib: bool,
    appended: Option<Appended<'a>>,
}

impl<'a, 'd> Reader<'a, 'd> {
    fn new(
        path: &'a Path,
        doc: &'d Document<'d>,
        root: Node,
        payload: Option<Payload<'a>>,
    ) -> Result<Self> {
        let mut r = Reader {
            path,
            doc,
            big_endian: false,
            header: Scalar::U32,
            zlib: false,
            appended: None,
        };
        if !root.has_tag_name("VTKFile") {
            return Err(r.error(root, "the root element is not <VTKFile>"));
        }
        if let Some((data, at)) = payload {
            let node = r.child(root, "AppendedData")?;
            let raw = match node.attribute("encoding").unwrap_or("") {
                "raw" => true,
                "base64" => false,
                other => {
                    return Err(r.error(
                        node,
                        format!(
                            "AppendedData encoding {other:?} is neither \"raw\" nor \"base64\""
                        ),
                    ))
                }
            };
            r.appended = Some(Appended { raw, data, at });
        }
        r.big_endian = match root.attribute("byte_order").unwrap_or("LittleEndian") {
            "LittleEndian" => false,
            "BigEndian" => true,
            other => {
                return Err(r.error(
                    root,
                    format!("byte_order {other:?} is neither LittleEndian nor BigEndian"),
                ))
            }
        };
        r.header = match root.attribute("header_type").unwrap_or("UInt32") {
            "UInt32" => Scalar::U32,
            "UInt64" => Scalar::U64,
            other => {
                return Err(r.error(
                    root,
                    format!("header_type {other:?} is neither UInt32 nor UInt64"),
                ))
            }
        };
        r.zlib = match root.attribute("compressor") {
            None | Some("") => false,
            Some("vtkZLibDataCompressor") => true,
            Some(other) => {
                return Err(r.error(
                    root,
                    format!(
                        "compressor {other:?} is not supported: save the file with \
                         vtkZLibDataCompressor or without compression"
                    ),
                ))
            }
        };
        Ok(r)
    }

    /// An error at the line where `node` starts.
    fn error(&self, node: Node, message: impl Into<String>) -> Error {
        Error::Parse {
            path: self.path.to_path_buf(),
            line: self.doc.text_pos_at(node.range().start).row as usize,
            message: message.into(),
        }
    }

    fn child<'n>(&self, parent: Node<'n, 'd>, tag: &str) -> Result<Node<'n, 'd>> {
        parent
            .children()
            .find(|n| n.has_tag_name(tag))
            .ok_or_else(|| {
                self.error(
                    parent,
                    format!("<{}> has no <{tag}>", parent.tag_name().name()),
                )
            })
    }

    /// A non-negative count attribute.
    fn count(&self, node: Node, name: &str) -> Result<usize> {
        let text = node
            .attribute(name)
            .ok_or_else(|| self.error(node, format!("missing attribute {name}")))?;
        text.trim()
            .parse()
            .map_err(|_| self.error(node, format!("{name}=\"{text}\" is not a count")))
    }

    /// One `<DataArray>`: its values and components per entry, with
    /// `entries × components` values when `entries` is given.
    fn array(&self, node: Node, entries: Option<usize>) -> Result<(Num, usize)> {
        let name = node.attribute("Name").unwrap_or("");
        let bad = |message: String| self.error(node, format!("DataArray '{name}': {message}"));
        let type_name = node.attribute("type").unwrap_or("");
        let scalar = Scalar::from_xml(type_name).ok_or_else(|| {
            bad(format!(
                "type {type_name:?} is not a VTK numeric type (Int8 … UInt64, Float32, Float64)"
            ))
        })?;
        let components = match node.attribute("NumberOfComponents") {
            None => 1,
            Some(text) => text
                .trim()
                .parse::<usize>()
                .ok()
                .filter(|&c| c > 0)
                .ok_or_else(|| {
                    bad(format!(
                        "NumberOfComponents=\"{text}\" is not a positive count"
                    ))
                })?,
        };
        let values = match node.attribute("format").unwrap_or("ascii") {
            "ascii" => self.ascii(node, scalar)?,
            "binary" => {
                let text: Vec<u8> = node
                    .children()
                    .filter(|n| n.is_text())
                    .flat_map(|n| n.text().unwrap_or("").bytes())
                    .filter(|b| !b.is_ascii_whitespace())
                    .collect();
                let raw = self.base64_block(&text).map_err(&bad)?;
                scalar.decode(&self.payload(&raw, scalar).map_err(&bad)?, self.big_endian)
            }
            "appended" => {
                let offset = self.count(node, "offset")?;
                let Some(app) = &self.appended else {
                    return Err(bad(
                        "format is appended but the file has no <AppendedData>".into()
                    ));
                };
                let block = app.data.get(offset..).ok_or_else(|| {
                    bad(format!(
                        "offset {offset} is past the end of the appended data ({} bytes)",
                        app.data.len()
                    ))
                })?;
                let at = |m: String| bad(format!("appended data at byte {}: {m}", app.at + offset));
                let bytes = if app.raw {
                    self.payload(block, scalar).map_err(at)?
                } else {
                    let raw = self.base64_block(block).map_err(at)?;
                    self.payload(&raw, scalar).map_err(at)?
                };
                scalar.decode(&bytes, self.big_endian)
            }
            other => {
                return Err(bad(format!(
                    "format {other:?} is not ascii, binary or appended"
                )))
            }
        };
        if values.len() % components != 0 {
            return Err(bad(format!(
                "{} values are not a whole number of {components}-component entries",
                values.len()
            )));
        }
        if let Some(n) = entries {
            if values.len() / components != n {
                return Err(bad(format!(
                    "{} entries of {components} values; expected {n}",
                    values.len() / components
                )));
            }
        }
        Ok((values, components))
    }

    /// An `ascii` array: whitespace-separated numbers, an error naming the
    /// line of the first that does not parse.
    fn ascii(&self, node: Node, scalar: Scalar) -> Result<Num> {
        // Each token with its offset in the document (for the line).
        let mut tokens = Vec::new();
        for text in node.children().filter(|n| n.is_text()) {
            let body = text.text().unwrap_or("");
            let mut from = 0;
            for token in body.split_ascii_whitespace() {
                let offset = from + body[from..].find(token).unwrap_or(0);
                from = offset + token.len();
                tokens.push((text.range().start + offset, token));
            }
        }
        scalar
            .parse_text(tokens.iter().map(|t| t.1))
            .map_err(|k| Error::Parse {
                path: self.path.to_path_buf(),
                line: self.doc.text_pos_at(tokens[k].0).row as usize,
                message: format!(
                    "DataArray '{}': value {} ('{}') is not {}",
                    node.attribute("Name").unwrap_or(""),
                    k + 1,
                    tokens[k].1,
                    scalar.describe()
                ),
            })
    }

    /// Reads `n` header words from `raw` at word `first`.
    fn words(&self, raw: &[u8], first: usize, n: usize) -> std::result::Result<Vec<u64>, String> {
        let size = self.header.size();
        let bytes = first
            .checked_add(n)
            .and_then(|k| k.checked_mul(size))
            .and_then(|end| raw.get(first * size..end))
            .ok_or_else(|| {
                format!(
                    "the block header needs {} {} words; {} bytes are there",
                    first.saturating_add(n),
                    self.header.name(),
                    raw.len()
                )
            })?;
        Ok(match self.header.decode(bytes, self.big_endian) {
            Num::Ints(v) => v.into_iter().map(|w| w as u64).collect(),
            Num::Floats(_) => unreachable!("header types are integers"),
        })
    }

    /// The header's length in bytes and the data bytes after it, from the
    /// first words of a binary block.
    fn block_sizes(&self, raw: &[u8]) -> std::result::Result<(usize, usize), String> {
        let size = self.header.size();
        let first = self.words(raw, 0, 1)?[0];
        if !self.zlib {
            let n = usize::try_from(first).map_err(|_| format!("a byte count of {first}"))?;
            return Ok((size, n));
        }
        // [blocks, block size, last block size, compressed sizes…]
        let blocks = usize::try_from(first)
            .ok()
            .filter(|&b| b <= raw.len() / size)
            .ok_or_else(|| {
                format!(
                    "the zlib header claims {first} blocks, more than its {} bytes can list",
                    raw.len()
                )
            })?;
        let header = (3 + blocks) * size;
        let sizes = self.words(raw, 3, blocks)?;
        let data = sizes
            .iter()
            .try_fold(0usize, |sum, &c| {
                usize::try_from(c).ok().and_then(|c| sum.checked_add(c))
            })
            .ok_or("the compressed block sizes overflow")?;
        Ok((header, data))
    }

    /// The header and data bytes of a base64 block, which VTK encodes
    /// either as one stream or header and data apart (each padded): a
    /// header whose encoding ends in `=` was encoded apart.
    fn base64_block(&self, text: &[u8]) -> std::result::Result<Vec<u8>, String> {
        let engine = GeneralPurpose::new(
            &base64::alphabet::STANDARD,
            GeneralPurposeConfig::new()
                .with_decode_padding_mode(DecodePaddingMode::Indifferent)
                .with_decode_allow_trailing_bits(true),
        );
        let decode = |from: usize, bytes: usize| -> std::result::Result<Vec<u8>, String> {
            let chars = bytes.div_ceil(3) * 4;
            let end = from
                .checked_add(chars)
                .filter(|&e| e <= text.len())
                .ok_or_else(|| {
                    format!(
                        "the base64 text ends after {} characters; {} more were needed",
                        text.len(),
                        chars
                    )
                })?;
            let mut out = base64::Engine::decode(&engine, &text[from..end])
                .map_err(|e| base64_error(e, from))?;
            if out.len() < bytes {
                return Err(format!(
                    "the base64 text holds {} bytes, {bytes} were needed",
                    out.len()
                ));
            }
            out.truncate(bytes);
            Ok(out)
        };
        let size = self.header.size();
        let first = decode(0, size)?;
        let header_len = if self.zlib {
            let blocks = self.words(&first, 0, 1)?[0];
            usize::try_from(blocks)
                .ok()
                .and_then(|b| b.checked_add(3))
                .and_then(|w| w.checked_mul(size))
                .filter(|&h| h / 3 * 4 <= text.len())
                .ok_or_else(|| {
                    format!("the zlib header claims {blocks} blocks, more than the text holds")
                })?
        } else {
            size
        };
        let header = decode(0, header_len)?;
        let (_, data_len) = self.block_sizes(&header)?;
        let header_chars = header_len.div_ceil(3) * 4;
        let apart = !header_len.is_multiple_of(3) && text.get(header_chars - 1) == Some(&b'=');
        if apart {
            let mut raw = header;
            raw.extend(decode(header_chars, data_len)?);
            Ok(raw)
        } else {
            let total = header_len
                .checked_add(data_len)
                .ok_or("the block sizes overflow")?;
            decode(0, total)
        }
    }

    /// The data bytes of a binary block (`raw`: header words, then data):
    /// checked against the bytes present, zlib blocks inflated to exactly
    /// their stated sizes.
    fn payload(&self, raw: &[u8], scalar: Scalar) -> std::result::Result<Vec<u8>, String> {
        let (header, data_len) = self.block_sizes(raw)?;
        let data = header
            .checked_add(data_len)
            .and_then(|end| raw.get(header..end))
            .ok_or_else(|| {
                format!(
                    "the header announces {data_len} data bytes; {} are there",
                    raw.len().saturating_sub(header)
                )
            })?;
        let bytes = if self.zlib {
            let words = self.words(raw, 0, 3)?;
            let (blocks, block, last) = (words[0] as usize, words[1], words[2]);
            let sizes = self.words(raw, 3, blocks)?;
            let mut out = Vec::new();
            let mut at = 0usize;
            for (k, &c) in sizes.iter().enumerate() {
                let want = if k + 1 == blocks && last != 0 {
                    last
                } else {
                    block
                };
                let c = c as usize; // fits: the sum was checked in block_sizes
                let mut inflated = Vec::new();
                flate2::read::ZlibDecoder::new(&data[at..at + c])
                    .take(want.saturating_add(1))
                    .read_to_end(&mut inflated)
                    .map_err(|e| format!("zlib block {k} does not inflate ({e})"))?;
                if inflated.len() as u64 != want {
                    return Err(format!(
                        "zlib block {k} inflates to {}{} bytes; the header says {want}",
                        inflated.len(),
                        if inflated.len() as u64 > want {
                            "+"
                        } else {
                            ""
                        }
                    ));
                }
                out.extend_from_slice(&inflated);
                at += c;
            }
            out
        } else {
            data.to_vec()
        };
        if !bytes.len().is_multiple_of(scalar.size()) {
            return Err(format!(
                "{} bytes are not a whole number of {} values",
                bytes.len(),
                scalar.name()
            ));
        }
        Ok(bytes)
    }
}

/// A base64 decoding error in the reader's words, positions counted from
/// the start of the array's text.
fn base64_error(e: base64::DecodeError, from: usize) -> String {
    use base64::DecodeError as D;
    match e {
        D::InvalidByte(at, byte) => format!(
            "invalid base64: character {} is {:?}",
            from + at,
            char::from(byte)
        ),
        D::InvalidLength(n) => format!("invalid base64: {n} characters cannot end a block"),
        D::InvalidLastSymbol(at, byte) => format!(
            "invalid base64: the last character ({:?}, character {}) has bits set past the data",
            char::from(byte),
            from + at
        ),
        D::InvalidPadding => "invalid base64 padding".to_string(),
    }
}
