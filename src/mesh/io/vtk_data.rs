//! What the two VTK readers share: the grid as read, before any index is
//! checked, and the numeric types VTK files name.
//!
//! [`super::vtk_xml`] (`.vtu`) and [`super::vtk_legacy`] (`.vtk`) both fill
//! a [`RawGrid`]; [`super::vtu::load_unstructured`] checks its indices and
//! hands it on.

use super::vtu::{Field, Values};

/// A single-piece unstructured grid as a file states it.
#[derive(Default)]
pub(super) struct RawGrid {
    /// Point coordinates, three per point.
    pub coords: Vec<f64>,
    /// Point ids of every cell, back to back.
    pub connectivity: Vec<i64>,
    /// Where each cell's ids end in `connectivity` (one per cell).
    pub ends: Vec<i64>,
    /// VTK cell type of each cell.
    pub types: Vec<u8>,
    pub point_data: Vec<Field>,
    pub cell_data: Vec<Field>,
}

/// The VTK cell types a reader may meet, by their numbers in VTK's
/// `vtkCellType.h`.
pub(super) mod cell {
    pub const VERTEX: u8 = 1;
    pub const POLY_VERTEX: u8 = 2;
    pub const LINE: u8 = 3;
    pub const POLY_LINE: u8 = 4;
    pub const TRIANGLE: u8 = 5;
    pub const TRIANGLE_STRIP: u8 = 6;
    pub const POLYGON: u8 = 7;
    pub const PIXEL: u8 = 8;
    pub const QUAD: u8 = 9;
    pub const TETRA: u8 = 10;
    pub const QUADRATIC_EDGE: u8 = 21;
    pub const QUADRATIC_TRIANGLE: u8 = 22;
    pub const QUADRATIC_QUAD: u8 = 23;
    pub const QUADRATIC_TETRA: u8 = 24;

    /// A cell type's name in messages.
    pub fn name(kind: u8) -> String {
        let name = match kind {
            VERTEX => "vertex",
            POLY_VERTEX => "poly-vertex",
            LINE => "line",
            POLY_LINE => "poly-line",
            TRIANGLE => "triangle",
            TRIANGLE_STRIP => "triangle strip",
            POLYGON => "polygon",
            PIXEL => "pixel",
            QUAD => "quad",
            TETRA => "tetrahedron",
            11 => "voxel",
            12 => "hexahedron",
            13 => "wedge",
            14 => "pyramid",
            15 => "pentagonal prism",
            16 => "hexagonal prism",
            QUADRATIC_EDGE => "quadratic edge",
            QUADRATIC_TRIANGLE => "quadratic triangle",
            QUADRATIC_QUAD => "quadratic quad",
            QUADRATIC_TETRA => "quadratic tetrahedron",
            25 => "quadratic hexahedron",
            26 => "quadratic wedge",
            27 => "quadratic pyramid",
            42 => "polyhedron",
            _ => return format!("cell of VTK type {kind}"),
        };
        format!("{name} (VTK type {kind})")
    }

    /// Whether a type is a point, curve or surface cell (skipped by the
    /// mesh reader, which wants volume cells).
    pub fn below_volume(kind: u8) -> bool {
        matches!(
            kind,
            VERTEX
                | POLY_VERTEX
                | LINE
                | POLY_LINE
                | TRIANGLE
                | TRIANGLE_STRIP
                | POLYGON
                | PIXEL
                | QUAD
                | QUADRATIC_EDGE
                | QUADRATIC_TRIANGLE
                | QUADRATIC_QUAD
        ) || (34..=37).contains(&kind) // biquadratic and cubic surface cells
            || (68..=70).contains(&kind) // Lagrange curve, triangle, quad
            || (75..=77).contains(&kind) // Bézier curve, triangle, quad
    }

    /// The point count a type fixes; `None` for the variable ones.
    pub fn fixed_points(kind: u8) -> Option<usize> {
        match kind {
            VERTEX => Some(1),
            LINE => Some(2),
            TRIANGLE | QUADRATIC_EDGE => Some(3),
            PIXEL | QUAD | TETRA => Some(4),
            QUADRATIC_TRIANGLE => Some(6),
            QUADRATIC_QUAD => Some(8),
            QUADRATIC_TETRA => Some(10),
            _ => None,
        }
    }
}

/// A numeric type as VTK files name it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Scalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    I64,
    U64,
    F32,
    F64,
}

impl Scalar {
    /// The XML names (`Int32`, `Float64`, …).
    pub fn from_xml(name: &str) -> Option<Scalar> {
        Some(match name {
            "Int8" | "Char" => Scalar::I8,
            "UInt8" | "UChar" => Scalar::U8,
            "Int16" => Scalar::I16,
            "UInt16" => Scalar::U16,
            "Int32" => Scalar::I32,
            "UInt32" => Scalar::U32,
            "Int64" => Scalar::I64,
            "UInt64" => Scalar::U64,
            "Float32" => Scalar::F32,
            "Float64" => Scalar::F64,
            _ => return None,
        })
    }

    /// The legacy names (`int`, `double`, `vtktypeint64`, …). `long` is
    /// taken as 8 bytes, as VTK writes it on 64-bit systems.
    pub fn from_legacy(name: &str) -> Option<Scalar> {
        Some(match name.to_ascii_lowercase().as_str() {
            "char" | "signed_char" | "vtktypeint8" => Scalar::I8,
            "bit" => return None,
            "unsigned_char" | "vtktypeuint8" => Scalar::U8,
            "short" | "vtktypeint16" => Scalar::I16,
            "unsigned_short" | "vtktypeuint16" => Scalar::U16,
            "int" | "vtktypeint32" => Scalar::I32,
            "unsigned_int" | "vtktypeuint32" => Scalar::U32,
            "long" | "vtktypeint64" | "long_long" | "vtkidtype" => Scalar::I64,
            "unsigned_long" | "vtktypeuint64" | "unsigned_long_long" => Scalar::U64,
            "float" | "vtktypefloat32" => Scalar::F32,
            "double" | "vtktypefloat64" => Scalar::F64,
            _ => return None,
        })
    }

    /// The XML name, used in messages.
    pub fn name(self) -> &'static str {
        match self {
            Scalar::I8 => "Int8",
            Scalar::U8 => "UInt8",
            Scalar::I16 => "Int16",
            Scalar::U16 => "UInt16",
            Scalar::I32 => "Int32",
            Scalar::U32 => "UInt32",
            Scalar::I64 => "Int64",
            Scalar::U64 => "UInt64",
            Scalar::F32 => "Float32",
            Scalar::F64 => "Float64",
        }
    }

    /// Bytes per value.
    pub fn size(self) -> usize {
        match self {
            Scalar::I8 | Scalar::U8 => 1,
            Scalar::I16 | Scalar::U16 => 2,
            Scalar::I32 | Scalar::U32 | Scalar::F32 => 4,
            Scalar::I64 | Scalar::U64 | Scalar::F64 => 8,
        }
    }

    pub fn is_float(self) -> bool {
        matches!(self, Scalar::F32 | Scalar::F64)
    }

    /// Decodes `bytes` (a whole number of values) in the given byte order.
    pub fn decode(self, bytes: &[u8], big_endian: bool) -> Num {
        macro_rules! each {
            ($t:ty, $wrap:ident, $as:ty) => {
                Num::$wrap(
                    bytes
                        .chunks_exact(std::mem::size_of::<$t>())
                        .map(|c| {
                            let b = c.try_into().expect("chunk of the type's size");
                            (if big_endian {
                                <$t>::from_be_bytes(b)
                            } else {
                                <$t>::from_le_bytes(b)
                            }) as $as
                        })
                        .collect(),
                )
            };
        }
        match self {
            Scalar::I8 => each!(i8, Ints, i128),
            Scalar::U8 => each!(u8, Ints, i128),
            Scalar::I16 => each!(i16, Ints, i128),
            Scalar::U16 => each!(u16, Ints, i128),
            Scalar::I32 => each!(i32, Ints, i128),
            Scalar::U32 => each!(u32, Ints, i128),
            Scalar::I64 => each!(i64, Ints, i128),
            Scalar::U64 => each!(u64, Ints, i128),
            Scalar::F32 => each!(f32, Floats, f64),
            Scalar::F64 => each!(f64, Floats, f64),
        }
    }

    /// Parses text values (ASCII data) of this type; `Err(k)`: value k
    /// does not parse.
    pub fn parse_text<'t>(self, tokens: impl IntoIterator<Item = &'t str>) -> Result<Num, usize> {
        let tokens = tokens.into_iter().enumerate();
        if self.is_float() {
            // VTK writes non-finite values as `nan`, `inf`, `-inf`.
            tokens
                .map(|(k, t)| t.parse::<f64>().map_err(|_| k))
                .collect::<Result<_, _>>()
                .map(Num::Floats)
        } else {
            tokens
                .map(|(k, t)| t.parse::<i128>().map_err(|_| k))
                .collect::<Result<_, _>>()
                .map(Num::Ints)
        }
    }

    /// "an Int32 integer", "a Float64 number" (in messages).
    pub fn describe(self) -> String {
        if self.is_float() {
            format!("a {} number", self.name())
        } else {
            format!("an {} integer", self.name())
        }
    }
}

/// Decoded values: integers exactly (any width), floats as f64.
pub(super) enum Num {
    Ints(Vec<i128>),
    Floats(Vec<f64>),
}

impl Num {
    pub fn len(&self) -> usize {
        match self {
            Num::Ints(v) => v.len(),
            Num::Floats(v) => v.len(),
        }
    }

    /// As floats (point coordinates).
    pub fn into_f64(self) -> Vec<f64> {
        match self {
            Num::Ints(v) => v.into_iter().map(|i| i as f64).collect(),
            Num::Floats(v) => v,
        }
    }

    /// As 64-bit integers (connectivity, offsets); `None` for floats or a
    /// value beyond i64.
    pub fn into_i64(self) -> Option<Vec<i64>> {
        match self {
            Num::Ints(v) => v.into_iter().map(|i| i64::try_from(i).ok()).collect(),
            Num::Floats(_) => None,
        }
    }

    /// As array values: integers as [`Values::I32`] where every one fits,
    /// as floats otherwise (a region reader then names the value that does
    /// not fit).
    pub fn into_values(self) -> Values {
        match self {
            Num::Ints(v) => match v.iter().map(|&i| i32::try_from(i).ok()).collect() {
                Some(ints) => Values::I32(ints),
                None => Values::F64(v.into_iter().map(|i| i as f64).collect()),
            },
            Num::Floats(v) => Values::F64(v),
        }
    }

    /// A named array of `components` per entry.
    pub fn into_field(self, name: &str, components: usize) -> Field {
        Field {
            name: name.to_string(),
            components,
            values: self.into_values(),
            component_names: Vec::new(),
        }
    }
}
