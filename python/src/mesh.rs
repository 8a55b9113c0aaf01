//! Tet meshes: `read_mesh`, the `Mesh` class and `write_vtu`.

use std::path::PathBuf;
use std::sync::Arc;

use numpy::{PyArray1, PyArray2, PyReadonlyArrayDyn, PyUntypedArrayMethods};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use skinpatch::mesh::io::vtu::{Field, Grid};
use skinpatch::mesh::TetMesh;

use crate::arrays;
use crate::errors::{this_process, to_py};

/// A tetrahedral mesh in millimetres: rest positions, tets, their regions
/// and the top surface the microstructure maps onto.
#[pyclass(module = "skinpatch", frozen)]
pub struct Mesh {
    pub(crate) mesh: Arc<TetMesh>,
}

#[pymethods]
impl Mesh {
    /// Vertex positions, `(n_vertices, 3)` float64, mm.
    #[getter]
    fn positions<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        arrays::vec3s(py, &self.mesh.positions)
    }

    /// Tets as vertex indices, `(n_tets, 4)` int64, positively oriented.
    #[getter]
    fn tets<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<i64>>> {
        let flat = self.mesh.tets.iter().flatten().map(|&v| v as i64).collect();
        arrays::rows(py, flat, 4)
    }

    /// Region id of every tet, `(n_tets,)` int32.
    #[getter]
    fn tet_region<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<i32>> {
        PyArray1::from_vec(py, self.mesh.tet_region.clone())
    }

    /// Region names by id, `{id: name}`.
    #[getter]
    fn regions<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        for r in &self.mesh.regions {
            d.set_item(r.id, &r.name)?;
        }
        Ok(d)
    }

    /// The mesh vertices on the top (skin) surface, `(n_top,)` int64; row
    /// k of `top_uvs` belongs to vertex `top_vertices[k]`.
    #[getter]
    fn top_vertices<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<i64>> {
        arrays::indices(py, self.mesh.top.vertices.iter().copied())
    }

    /// Top-surface triangles as mesh vertex indices, `(n_triangles, 3)`
    /// int64, counter-clockwise seen from above.
    #[getter]
    fn top_triangles<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<i64>>> {
        let top = &self.mesh.top;
        let flat = top
            .triangles
            .iter()
            .flatten()
            .map(|&s| top.vertices[s] as i64)
            .collect();
        arrays::rows(py, flat, 3)
    }

    /// Texture coordinates of the top vertices, `(n_top, 2)` float64.
    #[getter]
    fn top_uvs<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let flat = self.mesh.top.uvs.iter().flatten().copied().collect();
        arrays::rows(py, flat, 2)
    }

    /// Number of vertices.
    #[getter]
    fn num_vertices(&self) -> usize {
        self.mesh.num_vertices()
    }

    /// Number of tets.
    #[getter]
    fn num_tets(&self) -> usize {
        self.mesh.num_tets()
    }

    /// Writes the mesh as a VTU file with optional extra arrays (see
    /// `skinpatch.write_vtu`).
    #[pyo3(signature = (path, point_data=None, cell_data=None))]
    fn write_vtu(
        &self,
        py: Python<'_>,
        path: PathBuf,
        point_data: Option<&Bound<'_, PyDict>>,
        cell_data: Option<&Bound<'_, PyDict>>,
    ) -> PyResult<()> {
        write_vtu(py, path, self, point_data, cell_data)
    }

    fn __repr__(&self) -> String {
        format!(
            "Mesh({} vertices, {} tets, regions {:?})",
            self.mesh.num_vertices(),
            self.mesh.num_tets(),
            self.mesh
                .regions
                .iter()
                .map(|r| &r.name)
                .collect::<Vec<_>>()
        )
    }
}

/// Reads a tet mesh: TetGen `.node` (with its `.ele`), Gmsh `.msh` (2.2 or
/// 4.1, text or binary), VTK `.vtu` or legacy `.vtk` — the formats
/// `[mesh] file` accepts. Raises `MeshError` naming the file and line.
#[pyfunction]
pub fn read_mesh(py: Python<'_>, path: PathBuf) -> PyResult<Mesh> {
    this_process()?;
    let mesh = py
        .detach(|| skinpatch::mesh::io::read_mesh(&path))
        .map_err(|e| to_py(py, e, None))?;
    Ok(Mesh {
        mesh: Arc::new(mesh),
    })
}

/// Writes `mesh` (its rest positions) as a VTU file with the rest mesh's
/// arrays (`region`, `volume_mm3`, `on_top`, `uv`) and the extra arrays
/// given: `point_data` maps names to arrays of `n_vertices` rows,
/// `cell_data` to arrays of `n_tets` rows; each a float or int array of 1
/// or 2 dimensions (the second its components).
#[pyfunction]
#[pyo3(signature = (path, mesh, point_data=None, cell_data=None))]
pub fn write_vtu(
    py: Python<'_>,
    path: PathBuf,
    mesh: &Mesh,
    point_data: Option<&Bound<'_, PyDict>>,
    cell_data: Option<&Bound<'_, PyDict>>,
) -> PyResult<()> {
    let mut grid = Grid::from_mesh(&mesh.mesh);
    for (arrays, rows, kind, out) in [
        (
            point_data,
            mesh.mesh.num_vertices(),
            "point",
            &mut grid.point_data,
        ),
        (cell_data, mesh.mesh.num_tets(), "cell", &mut grid.cell_data),
    ] {
        let Some(arrays) = arrays else { continue };
        for (name, value) in arrays.iter() {
            let name: String = name.extract()?;
            out.push(field(&name, &value, rows, kind)?);
        }
    }
    this_process()?;
    py.detach(|| skinpatch::mesh::io::vtu::write_vtu(&path, &grid))
        .map_err(|e| to_py(py, e, None))
}

/// One named array as a VTU field of `rows` rows.
fn field(name: &str, value: &Bound<'_, PyAny>, rows: usize, kind: &str) -> PyResult<Field> {
    let bad = |why: String| PyValueError::new_err(format!("{kind} array '{name}': {why}"));
    let shape_of = |shape: &[usize]| -> PyResult<usize> {
        match shape {
            [n] if *n == rows => Ok(1),
            [n, k] if *n == rows && *k > 0 => Ok(*k),
            _ => Err(bad(format!(
                "shape {shape:?}; expected ({rows},) or ({rows}, k)"
            ))),
        }
    };
    if let Ok(a) = value.extract::<PyReadonlyArrayDyn<'_, i32>>() {
        let k = shape_of(a.shape())?;
        return Ok(Field::i32(name, k, a.as_array().iter().copied().collect()));
    }
    if let Ok(a) = value.extract::<PyReadonlyArrayDyn<'_, i64>>() {
        let k = shape_of(a.shape())?;
        let values = a
            .as_array()
            .iter()
            .map(|&v| {
                i32::try_from(v).map_err(|_| bad(format!("{v} does not fit a 32-bit integer")))
            })
            .collect::<PyResult<Vec<i32>>>()?;
        return Ok(Field::i32(name, k, values));
    }
    let np = value.py().import("numpy")?;
    let array = np
        .call_method1("asarray", (value,))
        .map_err(|e| bad(format!("not an array ({e})")))?;
    // numpy would cast complex values to real with only a warning.
    let kind: String = array.getattr("dtype")?.getattr("kind")?.extract()?;
    if kind == "c" {
        return Err(bad(
            "complex values; VTU arrays hold real numbers (pass .real or abs())".into(),
        ));
    }
    let as_f64 = array
        .call_method1("astype", ("float64",))
        .map_err(|e| bad(format!("not a numeric array ({e})")))?;
    let a: PyReadonlyArrayDyn<'_, f64> = as_f64
        .extract()
        .map_err(|_| bad("not a numeric array".into()))?;
    let k = shape_of(a.shape())?;
    Ok(Field::f64(name, k, a.as_array().iter().copied().collect()))
}
