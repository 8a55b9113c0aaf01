//! VTK XML unstructured grids (`.vtu`): written here; read by
//! `vtk_xml.rs` (and legacy `.vtk` by `vtk_legacy.rs`).
//!
//! Files are written with inline base64 ("binary") arrays, zlib-compressed
//! by default ([`VtuFormat`]), which ParaView and the Python package meshio
//! read. The writer takes any points, tets and
//! named point/cell arrays, so later stages (per-frame displacement, strains)
//! export through the same function. The reader returns the raw arrays; it is
//! used to check round trips.

use std::path::Path;

use super::vtk_data::cell;
use super::write_atomically;
use crate::error::{Error, Result};
use crate::mesh::{TetMesh, Vec3};

/// Values of one named array.
#[derive(Clone, Debug, PartialEq)]
pub enum Values {
    /// Floating-point data.
    F64(Vec<f64>),
    /// Integer data (ids, markers, flags).
    I32(Vec<i32>),
}

impl Values {
    /// Number of values.
    pub(crate) fn len(&self) -> usize {
        match self {
            Values::F64(v) => v.len(),
            Values::I32(v) => v.len(),
        }
    }
}

/// A named point or cell array with `components` values per entry.
#[derive(Clone, Debug, PartialEq)]
pub struct Field {
    /// Array name as shown in ParaView.
    pub name: String,
    /// Components per point or cell (1 scalar, 3 vector, 9 tensor …).
    pub components: usize,
    /// `components × count` values, entry-major.
    pub values: Values,
    /// Names of the components (written as `ComponentName0…`; empty: none,
    /// and ParaView shows X, Y, Z or 0, 1, 2). Not read back.
    pub component_names: Vec<String>,
}

impl Field {
    /// A float field.
    pub fn f64(name: &str, components: usize, values: Vec<f64>) -> Field {
        Field {
            name: name.into(),
            components,
            values: Values::F64(values),
            component_names: Vec::new(),
        }
    }

    /// An integer field.
    pub fn i32(name: &str, components: usize, values: Vec<i32>) -> Field {
        Field {
            name: name.into(),
            components,
            values: Values::I32(values),
            component_names: Vec::new(),
        }
    }

    /// The same field with named components (one name per component).
    pub fn named(mut self, names: &[&str]) -> Field {
        debug_assert_eq!(names.len(), self.components);
        self.component_names = names.iter().map(|n| n.to_string()).collect();
        self
    }
}

/// An unstructured grid of tetrahedra and triangles with point and cell
/// data (cells are the tets, then the triangles).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Grid {
    /// Point positions.
    pub points: Vec<Vec3>,
    /// Tets as point indices.
    pub tets: Vec<[usize; 4]>,
    /// Triangles as point indices (a surface grid).
    pub triangles: Vec<[usize; 3]>,
    /// Arrays with one entry per point.
    pub point_data: Vec<Field>,
    /// Arrays with one entry per cell.
    pub cell_data: Vec<Field>,
}

impl Grid {
    /// The rest mesh with its region ids, tet volumes, top-surface flag and UVs
    /// (−1 off the top surface).
    pub fn from_mesh(mesh: &TetMesh) -> Grid {
        let n = mesh.num_vertices();
        let mut on_top = vec![0; n];
        let mut uv = vec![-1.0; 2 * n];
        for (s, &v) in mesh.top.vertices.iter().enumerate() {
            on_top[v] = 1;
            uv[2 * v..2 * v + 2].copy_from_slice(&mesh.top.uvs[s]);
        }
        Grid {
            points: mesh.positions.clone(),
            tets: mesh.tets.clone(),
            triangles: Vec::new(),
            point_data: vec![
                Field::i32("on_top", 1, on_top),
                Field::f64("uv", 2, uv).named(&["u", "v"]),
            ],
            cell_data: vec![
                Field::i32("region", 1, mesh.tet_region.clone()),
                Field::f64(
                    "volume_mm3",
                    1,
                    (0..mesh.num_tets()).map(|t| mesh.tet_volume(t)).collect(),
                ),
            ],
        }
    }

    /// Tets plus triangles.
    pub fn num_cells(&self) -> usize {
        self.tets.len() + self.triangles.len()
    }

    /// Checks that every array has `components × count` values.
    fn check(&self) -> Result<()> {
        for (fields, count, kind) in [
            (&self.point_data, self.points.len(), "point"),
            (&self.cell_data, self.num_cells(), "cell"),
        ] {
            for f in fields {
                if f.values.len() != f.components * count {
                    return Err(Error::parameter(
                        format!("{kind} array '{}'", f.name),
                        format!(
                            "has {} values, expected {} × {count}",
                            f.values.len(),
                            f.components
                        ),
                    ));
                }
            }
        }
        Ok(())
    }
}

/// Escapes a name for an XML attribute value.
fn xml_attr(text: &str) -> String {
    text.replace('&', "&amp;")
        .replace('"', "&quot;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}

/// How [`write_vtu_as`] stores the arrays.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct VtuFormat {
    /// zlib-compress each array in blocks of [`BLOCK`] bytes
    /// (`vtkZLibDataCompressor`, lossless; zlib's fastest level, which on a
    /// frame is 0.5% larger than the default level in half the time).
    pub compress: bool,
    /// Points and float arrays as Float32 (7 significant digits) instead of
    /// Float64.
    pub f32: bool,
}

impl Default for VtuFormat {
    /// Compressed, Float64.
    fn default() -> Self {
        VtuFormat {
            compress: true,
            f32: false,
        }
    }
}

/// Uncompressed bytes per compressed block (VTK's default).
pub const BLOCK: usize = 1 << 15;

/// One `<DataArray>` in the VTK XML "binary" format: base64 of a UInt64
/// byte count and the little-endian values, or, compressed, base64 of the
/// block header `[blocks, block size, last partial block size, compressed
/// sizes…]` followed by base64 of the zlib blocks.
fn data_array(
    out: &mut String,
    format: VtuFormat,
    (type_name, name, components): (&str, &str, usize),
    names: &[String],
    bytes: &[u8],
) {
    use base64::Engine;
    use std::fmt::Write;
    let b64 = &base64::engine::general_purpose::STANDARD;
    let _ = write!(
        out,
        r#"<DataArray type="{type_name}" Name="{}""#,
        xml_attr(name)
    );
    if components != 1 {
        let _ = write!(out, r#" NumberOfComponents="{components}""#);
    }
    for (k, n) in names.iter().enumerate() {
        let _ = write!(out, r#" ComponentName{k}="{}""#, xml_attr(n));
    }
    out.push_str(r#" format="binary">"#);
    if format.compress {
        // Blocks compress independently, in parallel, and are concatenated in
        // order (the same bytes on any thread count).
        use rayon::prelude::*;
        let blocks: Vec<Vec<u8>> = bytes
            .par_chunks(BLOCK)
            .map(|chunk| {
                let mut z =
                    flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::fast());
                std::io::Write::write_all(&mut z, chunk).expect("writing to memory");
                z.finish().expect("writing to memory")
            })
            .collect();
        let mut header: Vec<u64> = vec![
            blocks.len() as u64,
            BLOCK as u64,
            (bytes.len() % BLOCK) as u64,
        ];
        header.extend(blocks.iter().map(|b| b.len() as u64));
        out.push_str(&b64.encode(le_bytes(&header, |x| x.to_le_bytes())));
        out.push_str(&b64.encode(blocks.concat()));
    } else {
        let mut payload = Vec::with_capacity(8 + bytes.len());
        payload.extend_from_slice(&(bytes.len() as u64).to_le_bytes());
        payload.extend_from_slice(bytes);
        out.push_str(&b64.encode(&payload));
    }
    out.push_str("</DataArray>\n");
}

/// A float array as Float64 or, with `format.f32`, Float32.
fn float_array(
    out: &mut String,
    format: VtuFormat,
    name: &str,
    components: usize,
    names: &[String],
    v: &[f64],
) {
    if format.f32 {
        let bytes = le_bytes(v, |x| (x as f32).to_le_bytes());
        data_array(out, format, ("Float32", name, components), names, &bytes);
    } else {
        let bytes = le_bytes(v, |x| x.to_le_bytes());
        data_array(out, format, ("Float64", name, components), names, &bytes);
    }
}

fn field_array(out: &mut String, format: VtuFormat, f: &Field) {
    match &f.values {
        Values::F64(v) => float_array(out, format, &f.name, f.components, &f.component_names, v),
        Values::I32(v) => data_array(
            out,
            format,
            ("Int32", &f.name, f.components),
            &f.component_names,
            &le_bytes(v, |x| x.to_le_bytes()),
        ),
    }
}

fn le_bytes<T: Copy, const N: usize>(values: &[T], f: impl Fn(T) -> [u8; N]) -> Vec<u8> {
    values.iter().flat_map(|&v| f(v)).collect()
}

/// Writes a `.vtu` file atomically in the default [`VtuFormat`]
/// (compressed, Float64).
pub fn write_vtu(path: &Path, grid: &Grid) -> Result<()> {
    write_vtu_as(path, grid, VtuFormat::default())
}

/// Writes a `.vtu` file atomically (temporary file, then rename): VTK XML,
/// inline base64 binary arrays with UInt64 headers as `format` says,
/// connectivity and offsets as Int64 (as VTK writes them; meshio reads
/// unsigned ones back as floats), cell types UInt8, component names where
/// the fields have them.
pub fn write_vtu_as(path: &Path, grid: &Grid, format: VtuFormat) -> Result<()> {
    grid.check()?;
    let mut out = String::new();
    out.push_str(
        "<?xml version=\"1.0\"?>\n<VTKFile type=\"UnstructuredGrid\" version=\"1.0\" \
         byte_order=\"LittleEndian\" header_type=\"UInt64\"",
    );
    if format.compress {
        out.push_str(" compressor=\"vtkZLibDataCompressor\"");
    }
    out.push_str(">\n<UnstructuredGrid>\n");
    out.push_str(&format!(
        "<Piece NumberOfPoints=\"{}\" NumberOfCells=\"{}\">\n<PointData>\n",
        grid.points.len(),
        grid.num_cells()
    ));
    grid.point_data
        .iter()
        .for_each(|f| field_array(&mut out, format, f));
    out.push_str("</PointData>\n<CellData>\n");
    grid.cell_data
        .iter()
        .for_each(|f| field_array(&mut out, format, f));
    out.push_str("</CellData>\n<Points>\n");
    let points: Vec<f64> = grid.points.iter().flat_map(|p| [p.x, p.y, p.z]).collect();
    float_array(&mut out, format, "Points", 3, &[], &points);
    out.push_str("</Points>\n<Cells>\n");
    let connectivity: Vec<i64> = grid
        .tets
        .iter()
        .flat_map(|t| t.map(|v| v as i64))
        .chain(grid.triangles.iter().flat_map(|t| t.map(|v| v as i64)))
        .collect();
    let tet_end = 4 * grid.tets.len() as i64;
    let offsets: Vec<i64> = (1..=grid.tets.len() as i64)
        .map(|k| 4 * k)
        .chain((1..=grid.triangles.len() as i64).map(|k| tet_end + 3 * k))
        .collect();
    for (name, values) in [("connectivity", connectivity), ("offsets", offsets)] {
        let bytes = le_bytes(&values, |x| x.to_le_bytes());
        data_array(&mut out, format, ("Int64", name, 1), &[], &bytes);
    }
    // VTK_TETRA, then VTK_TRIANGLE.
    let mut types = vec![10u8; grid.tets.len()];
    types.resize(grid.num_cells(), 5);
    data_array(&mut out, format, ("UInt8", "types", 1), &[], &types);
    out.push_str("</Cells>\n</Piece>\n</UnstructuredGrid>\n</VTKFile>\n");
    write_atomically(path, out.as_bytes())
}

/// Reads a `.vtu` file written by [`write_vtu`] (or any single-piece
/// unstructured grid of tetrahedra and triangles, tets first).
pub fn read_vtu(path: &Path) -> Result<Grid> {
    let bad = |message: String| Error::malformed(path, message);
    let loaded = load_unstructured(path)?;
    let (mut tets, mut triangles) = (Vec::with_capacity(loaded.cells.len()), Vec::new());
    for (k, cell) in loaded.cells.iter().enumerate() {
        let nodes = loaded.nodes(cell);
        match (cell.kind, nodes.len()) {
            (cell::TETRA, 4) => {
                if !triangles.is_empty() {
                    return Err(bad(format!(
                        "cell {k}: tetrahedra after triangles are not supported"
                    )));
                }
                tets.push(std::array::from_fn(|i| nodes[i]));
            }
            (cell::TRIANGLE, 3) => triangles.push(std::array::from_fn(|i| nodes[i])),
            (cell::TETRA | cell::TRIANGLE, n) => {
                return Err(bad(format!("cell {k} has {n} nodes, not as its type says")))
            }
            (other, _) => {
                return Err(bad(format!(
                    "cell {k} is a {}; only tetrahedra and triangles are supported",
                    cell::name(other)
                )))
            }
        }
    }
    Ok(Grid {
        points: loaded.points,
        tets,
        triangles,
        point_data: loaded.point_data,
        cell_data: loaded.cell_data,
    })
}

/// One cell of a loaded grid: its VTK type and its range in the
/// connectivity.
pub(super) struct Cell {
    pub kind: u8,
    pub range: std::ops::Range<usize>,
}

/// A single-piece unstructured grid as read, any cell types.
pub(super) struct Unstructured {
    pub points: Vec<Vec3>,
    pub connectivity: Vec<usize>,
    pub cells: Vec<Cell>,
    pub point_data: Vec<Field>,
    pub cell_data: Vec<Field>,
}

impl Unstructured {
    /// The point indices of `cell`.
    pub fn nodes(&self, cell: &Cell) -> &[usize] {
        &self.connectivity[cell.range.clone()]
    }
}

/// Reads a single-piece unstructured grid from VTK XML (`.vtu`) or legacy
/// VTK (`.vtk`, versions 2 to 5.1, text or binary), checking every cell's
/// point indices. Legacy field data (`FIELD`) arrays become ordinary arrays.
pub(super) fn load_unstructured(path: &Path) -> Result<Unstructured> {
    let bad = |message: String| Error::malformed(path, message);
    let bytes = super::read_input(path)?;
    let legacy = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("vtk"));
    let raw = if legacy {
        super::vtk_legacy::read_legacy(path, &bytes)?
    } else {
        super::vtk_xml::read_xml(path, &bytes)?
    };
    if !raw.coords.len().is_multiple_of(3) {
        return Err(bad(format!(
            "{} point coordinates, not a multiple of 3",
            raw.coords.len()
        )));
    }
    if let Some(i) = raw.coords.iter().position(|x| !x.is_finite()) {
        return Err(bad(format!(
            "point {} has a non-finite coordinate ({})",
            i / 3,
            raw.coords[i]
        )));
    }
    let points: Vec<Vec3> = raw
        .coords
        .chunks_exact(3)
        .map(|c| Vec3::new(c[0], c[1], c[2]))
        .collect();
    if raw.types.len() != raw.ends.len() {
        return Err(bad(format!(
            "{} cell types for {} cells",
            raw.types.len(),
            raw.ends.len()
        )));
    }
    let mut connectivity = Vec::with_capacity(raw.connectivity.len());
    let mut cells = Vec::with_capacity(raw.types.len());
    let mut start = 0usize;
    for (k, (&end, &kind)) in raw.ends.iter().zip(&raw.types).enumerate() {
        let end = usize::try_from(end).unwrap_or(usize::MAX);
        if end < start || end > raw.connectivity.len() {
            return Err(bad(format!(
                "cell {k}: offset {end} is out of order or beyond the {} point ids",
                raw.connectivity.len()
            )));
        }
        for &v in &raw.connectivity[start..end] {
            let index = usize::try_from(v).ok().filter(|&i| i < points.len());
            connectivity.push(index.ok_or_else(|| {
                bad(format!(
                    "cell {k} refers to point {v}; there are {}",
                    points.len()
                ))
            })?);
        }
        cells.push(Cell {
            kind,
            range: start..end,
        });
        start = end;
    }
    Ok(Unstructured {
        points,
        connectivity,
        cells,
        point_data: raw.point_data,
        cell_data: raw.cell_data,
    })
}
