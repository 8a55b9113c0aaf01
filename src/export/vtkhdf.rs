//! `frames.vtkhdf`: every frame of a run in one file, in VTK's HDF5 format
//! (VTKHDF 2.x, a transient `UnstructuredGrid`; ParaView 5.12 or newer and
//! VTK 9.3 or newer read it with `vtkHDFReader`).
//!
//! The file holds the same grid and arrays as the per-frame VTUs. What
//! does not change between frames is stored once: the connectivity, cell
//! offsets and types are written at creation and every step points at
//! them (`Steps/CellOffsets` and `Steps/ConnectivityIdOffsets` stay 0), and
//! an array whose values equal the previous step's (the region ids, say)
//! is not appended again — its step offset repeats the previous one. The
//! deformed points and the other arrays grow by one block per step.
//!
//! Layout under `/VTKHDF` (attributes `Version` = [2, 0] and `Type` =
//! `UnstructuredGrid`):
//!
//! * `NumberOfPoints`, `NumberOfCells`, `NumberOfConnectivityIds`: one entry
//!   (one partition, shared by every step), `Types`, `Connectivity`,
//!   `Offsets`;
//! * `Points` (`steps · points` × 3) and `PointData/<name>`,
//!   `CellData/<name>` (`blocks · entries` × components, one-dimensional
//!   for scalars);
//! * `Steps` (attribute `NSteps`): `Values` (the frame times), `PartOffsets`
//!   and `NumberOfParts` (0 and 1), `PointOffsets`, `CellOffsets`,
//!   `ConnectivityIdOffsets`, and `PointDataOffsets/<name>`,
//!   `CellDataOffsets/<name>` (in entries).
//!
//! Arrays are chunked one block per chunk and, when asked, compressed by
//! HDF5's shuffle and deflate filters (level 1). Floats are stored as f64
//! or f32 like the VTUs. Component names have no place in VTKHDF; they are
//! in the VTUs only.
//!
//! The file is flushed after every step and `NSteps` is raised last, so a
//! reader of a run still going (or of one stopped between frames) sees the
//! steps completed so far.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use hdf5_metno as hdf5;

use crate::error::{Error, Result};
use crate::mesh::io::{Field, Grid, Values, VtuFormat};

/// VTK's cell type of a linear tetrahedron.
const VTK_TETRA: u8 = 10;
/// Format version written (major, minor).
const VERSION: [i64; 2] = [2, 0];
/// Rows per chunk of a growing array at most (a step's block is one chunk
/// up to this size).
const MAX_CHUNK_ROWS: usize = 1 << 16;

/// One array of the point or cell data, as appended so far.
struct Series {
    data: hdf5::Dataset,
    offsets: hdf5::Dataset,
    components: usize,
    /// Entries per block (points or cells).
    entries: usize,
    /// Rows written (entries).
    rows: usize,
    /// The last block written, its first row and its values, to store an
    /// unchanged block once.
    last: Option<(usize, Values)>,
}

/// Writes the frames of one run into a VTKHDF file, one step per frame.
pub struct VtkHdfWriter {
    path: PathBuf,
    file: hdf5::File,
    steps_group: hdf5::Group,
    points: Series,
    point_data: BTreeMap<String, Series>,
    cell_data: BTreeMap<String, Series>,
    /// The per-step bookkeeping arrays of `Steps`.
    step_arrays: StepArrays,
    f32: bool,
    steps: usize,
}

/// `Steps/Values`, `PartOffsets`, `NumberOfParts`, `CellOffsets`,
/// `ConnectivityIdOffsets`.
struct StepArrays {
    values: hdf5::Dataset,
    part_offsets: hdf5::Dataset,
    parts: hdf5::Dataset,
    cell_offsets: hdf5::Dataset,
    connectivity_offsets: hdf5::Dataset,
}

impl VtkHdfWriter {
    /// Creates `path` (replacing a file there) with the connectivity and
    /// array layout of `grid`; the steps follow with [`VtkHdfWriter::push`].
    pub fn create(path: &Path, grid: &Grid, format: VtuFormat) -> Result<VtkHdfWriter> {
        let failed = |e: hdf5::Error| h5_error(path, e);
        // Strong close: closing the file closes every handle into it.
        // No file lock: HDF5 opens the file without close-on-exec, so a
        // process started meanwhile (ffmpeg, a caller's tool) would inherit
        // the descriptor and keep the lock after we close; a lock would also
        // keep ParaView from reading a run in progress, and fails on some
        // cluster file systems. Only this writer ever writes the file.
        let file = hdf5::File::with_options()
            .with_fapl(|fapl| {
                fapl.fclose_degree(hdf5::file::FileCloseDegree::Strong)
                    .file_locking(false)
            })
            .create(path)
            .map_err(failed)?;
        let root = file.create_group("VTKHDF").map_err(failed)?;
        root.new_attr::<i64>()
            .shape(2)
            .create("Version")
            .and_then(|a| a.write(&VERSION))
            .map_err(failed)?;
        let kind = hdf5::types::FixedAscii::<16>::from_ascii("UnstructuredGrid")
            .expect("the type name is ASCII and 16 bytes");
        root.new_attr::<hdf5::types::FixedAscii<16>>()
            .create("Type")
            .and_then(|a| a.write_scalar(&kind))
            .map_err(failed)?;

        let (n_points, n_cells) = (grid.points.len(), grid.tets.len());
        let writer = Writer {
            path,
            group: &root,
            compress: format.compress,
        };
        writer.constant("NumberOfPoints", &[n_points as i64])?;
        writer.constant("NumberOfCells", &[n_cells as i64])?;
        writer.constant("NumberOfConnectivityIds", &[4 * n_cells as i64])?;
        writer.constant("Types", &vec![VTK_TETRA; n_cells])?;
        let connectivity: Vec<i64> = grid.tets.iter().flatten().map(|&v| v as i64).collect();
        writer.constant("Connectivity", &connectivity)?;
        let offsets: Vec<i64> = (0..=n_cells as i64).map(|c| 4 * c).collect();
        writer.constant("Offsets", &offsets)?;

        let float = |f32: bool| if f32 { Kind::F32 } else { Kind::F64 };
        let kind_of = |values: &Values| match values {
            Values::F64(_) => float(format.f32),
            Values::I32(_) => Kind::I32,
        };
        let steps_group = root.create_group("Steps").map_err(failed)?;
        let points = writer.series(
            "Points",
            "Steps/PointOffsets",
            3,
            n_points,
            float(format.f32),
        )?;
        let data = |group: &str, fields: &[Field], entries: usize| -> Result<BTreeMap<_, _>> {
            fields
                .iter()
                .map(|field| {
                    let series = writer.series(
                        &format!("{group}Data/{}", field.name),
                        &format!("Steps/{group}DataOffsets/{}", field.name),
                        field.components,
                        entries,
                        kind_of(&field.values),
                    )?;
                    Ok((field.name.clone(), series))
                })
                .collect()
        };
        let point_data = data("Point", &grid.point_data, n_points)?;
        let cell_data = data("Cell", &grid.cell_data, n_cells)?;
        let step_arrays = StepArrays {
            values: writer.growing("Steps/Values", false, Kind::F64)?,
            part_offsets: writer.growing("Steps/PartOffsets", false, Kind::I64)?,
            parts: writer.growing("Steps/NumberOfParts", false, Kind::I64)?,
            cell_offsets: writer.growing("Steps/CellOffsets", true, Kind::I64)?,
            connectivity_offsets: writer.growing("Steps/ConnectivityIdOffsets", true, Kind::I64)?,
        };
        let mut out = VtkHdfWriter {
            path: path.to_path_buf(),
            file,
            steps_group,
            points,
            point_data,
            cell_data,
            step_arrays,
            f32: format.f32,
            steps: 0,
        };
        out.set_steps(0)?;
        Ok(out)
    }

    /// Appends `grid` (the same mesh and arrays as at creation) as the step
    /// at time `time`, then flushes the file.
    pub fn push(&mut self, time: f64, grid: &Grid) -> Result<()> {
        let path = self.path.clone();
        let flat: Vec<f64> = grid.points.iter().flat_map(|p| [p.x, p.y, p.z]).collect();
        if grid.points.len() != self.points.entries {
            return Err(Error::io(
                &path,
                std::io::Error::other(format!(
                    "a step with {} points in a file of {}",
                    grid.points.len(),
                    self.points.entries
                )),
            ));
        }
        self.points
            .append(&path, &Values::F64(flat), self.f32, false)?;
        for (fields, series) in [
            (&grid.point_data, &mut self.point_data),
            (&grid.cell_data, &mut self.cell_data),
        ] {
            if fields.len() != series.len() {
                return Err(layout_changed(&path, fields));
            }
            for field in fields {
                let s = series
                    .get_mut(&field.name)
                    .ok_or_else(|| layout_changed(&path, fields))?;
                s.append(&path, &field.values, self.f32, true)?;
            }
        }
        let k = self.steps;
        let a = &self.step_arrays;
        append(&path, &a.values, &[time], k)?;
        append(&path, &a.part_offsets, &[0i64], k)?;
        append(&path, &a.parts, &[1i64], k)?;
        append(&path, &a.cell_offsets, &[0i64], k)?;
        append(&path, &a.connectivity_offsets, &[0i64], k)?;
        // Raised last: a reader sees a step only once all of it is there.
        self.set_steps(k + 1)?;
        self.file.flush().map_err(|e| h5_error(&path, e))
    }

    /// Steps written so far.
    pub fn steps(&self) -> usize {
        self.steps
    }

    /// Closes the file and returns its path.
    pub fn finish(self) -> Result<PathBuf> {
        let VtkHdfWriter {
            path,
            file,
            steps_group,
            points,
            point_data,
            cell_data,
            step_arrays,
            ..
        } = self;
        drop((steps_group, points, point_data, cell_data, step_arrays));
        file.close().map_err(|e| h5_error(&path, e))?;
        Ok(path)
    }

    fn set_steps(&mut self, n: usize) -> Result<()> {
        let failed = |e: hdf5::Error| h5_error(&self.path, e);
        let attr = match self.steps_group.attr("NSteps") {
            Ok(attr) => attr,
            Err(_) => self
                .steps_group
                .new_attr::<i64>()
                .create("NSteps")
                .map_err(failed)?,
        };
        attr.write_scalar(&(n as i64)).map_err(failed)?;
        self.steps = n;
        Ok(())
    }
}

fn layout_changed(path: &Path, fields: &[Field]) -> Error {
    let names: Vec<&str> = fields.iter().map(|f| f.name.as_str()).collect();
    Error::io(
        path,
        std::io::Error::other(format!(
            "a step's arrays ({}) differ from the file's",
            names.join(", ")
        )),
    )
}

fn h5_error(path: &Path, e: hdf5::Error) -> Error {
    Error::io(path, std::io::Error::other(format!("HDF5: {e}")))
}

/// Element types of the datasets.
#[derive(Clone, Copy)]
enum Kind {
    F64,
    F32,
    I32,
    I64,
}

/// Creates datasets under one group.
struct Writer<'a> {
    path: &'a Path,
    group: &'a hdf5::Group,
    compress: bool,
}

impl Writer<'_> {
    /// A one-dimensional dataset written once.
    fn constant<T: hdf5::H5Type>(&self, name: &str, values: &[T]) -> Result<()> {
        let mut builder = self.group.new_dataset_builder();
        if self.compress && values.len() > 1 {
            builder = builder
                .shuffle()
                .deflate(1)
                .chunk(values.len().min(MAX_CHUNK_ROWS));
        }
        builder
            .with_data(values)
            .create(name)
            .map(|_| ())
            .map_err(|e| h5_error(self.path, e))
    }

    /// An empty dataset of `columns` per row (1: one-dimensional) that
    /// grows by rows, chunked by `chunk_rows`.
    fn extensible(
        &self,
        name: &str,
        columns: usize,
        chunk_rows: usize,
        kind: Kind,
    ) -> Result<hdf5::Dataset> {
        let chunk_rows = chunk_rows.clamp(1, MAX_CHUNK_ROWS);
        let compress = self.compress && chunk_rows > 1;
        macro_rules! build {
            ($t:ty) => {{
                let mut b = self.group.new_dataset::<$t>();
                if compress {
                    b = b.shuffle().deflate(1);
                }
                if columns == 1 {
                    b.chunk(chunk_rows).shape(0..).create(name)
                } else {
                    b.chunk((chunk_rows, columns))
                        .shape((0.., columns))
                        .create(name)
                }
            }};
        }
        let made = match kind {
            Kind::F64 => build!(f64),
            Kind::F32 => build!(f32),
            Kind::I32 => build!(i32),
            Kind::I64 => build!(i64),
        };
        made.map_err(|e| h5_error(self.path, e))
    }

    /// A per-step bookkeeping array: one entry per step, as a vector or
    /// (`column`) as a steps × 1 matrix like `CellOffsets`.
    fn growing(&self, name: &str, column: bool, kind: Kind) -> Result<hdf5::Dataset> {
        const CHUNK: usize = 64;
        macro_rules! build {
            ($t:ty) => {{
                let b = self.group.new_dataset::<$t>();
                if column {
                    b.chunk((CHUNK, 1)).shape((0.., 1)).create(name)
                } else {
                    b.chunk(CHUNK).shape(0..).create(name)
                }
            }};
        }
        let made = match kind {
            Kind::F64 => build!(f64),
            _ => build!(i64),
        };
        made.map_err(|e| h5_error(self.path, e))
    }

    /// A growing data array with its per-step offsets.
    fn series(
        &self,
        name: &str,
        offsets: &str,
        components: usize,
        entries: usize,
        kind: Kind,
    ) -> Result<Series> {
        Ok(Series {
            data: self.extensible(name, components, entries, kind)?,
            offsets: self.growing(offsets, false, Kind::I64)?,
            components,
            entries,
            rows: 0,
            last: None,
        })
    }
}

impl Series {
    /// Appends one block (`entries × components` values) and its offset;
    /// with `dedup`, a block equal to the last one is not stored again and
    /// its offset repeats the last one's.
    fn append(&mut self, path: &Path, values: &Values, f32: bool, dedup: bool) -> Result<()> {
        let expected = self.entries * self.components;
        let len = values.len();
        if len != expected {
            return Err(Error::io(
                path,
                std::io::Error::other(format!("a block of {len} values where {expected} belong")),
            ));
        }
        let step = self.offsets.shape()[0];
        if dedup {
            if let Some((first, last)) = &self.last {
                if last == values {
                    return append(path, &self.offsets, &[*first as i64], step);
                }
            }
        }
        let first = self.rows;
        match values {
            Values::F64(v) if f32 => {
                let v: Vec<f32> = v.iter().map(|&x| x as f32).collect();
                append(path, &self.data, &v, first)?
            }
            Values::F64(v) => append(path, &self.data, v, first)?,
            Values::I32(v) => append(path, &self.data, v, first)?,
        }
        self.rows += self.entries;
        append(path, &self.offsets, &[first as i64], step)?;
        if dedup {
            self.last = Some((first, values.clone()));
        }
        Ok(())
    }
}

/// Grows `data` (a vector, or a matrix of whole rows) to hold `values`
/// from row `at` and writes them there.
fn append<T: hdf5::H5Type>(
    path: &Path,
    data: &hdf5::Dataset,
    values: &[T],
    at: usize,
) -> Result<()> {
    let failed = |e: hdf5::Error| h5_error(path, e);
    let shape = data.shape();
    if shape.len() == 1 {
        let rows = values.len();
        data.resize(at + rows).map_err(failed)?;
        data.write_slice(values, at..at + rows).map_err(failed)
    } else {
        let width = shape[1];
        let rows = values.len() / width;
        data.resize((at + rows, width)).map_err(failed)?;
        let view = ndarray::ArrayView2::from_shape((rows, width), values)
            .expect("the block holds whole rows");
        data.write_slice(view, (at..at + rows, ..)).map_err(failed)
    }
}
