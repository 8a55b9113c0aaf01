//! `Scenario.load` and the scenario's face in Python.

use std::path::PathBuf;
use std::sync::Arc;

use pyo3::exceptions::PyTypeError;
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyDict, PyFloat, PyInt, PyList, PyString, PyTuple};
use skinpatch::scenario::Setup;

use crate::errors::{this_process, to_py, Source};
use crate::mesh::Mesh;

/// A validated scenario with its mesh, ready to run.
#[pyclass(module = "skinpatch", frozen)]
pub struct Scenario {
    pub(crate) path: PathBuf,
    pub(crate) text: String,
    /// The keys the overrides set.
    pub(crate) overridden: Vec<String>,
    pub(crate) setup: Arc<Setup>,
}

impl Scenario {
    /// The scenario file as an error source.
    pub(crate) fn source(&self) -> Source<'_> {
        Source {
            path: &self.path,
            text: &self.text,
            overridden: &self.overridden,
        }
    }
}

#[pymethods]
impl Scenario {
    /// Reads, validates and sets up the scenario at `path` (loading its
    /// mesh) with `overrides` applied: `{"material.dermis.youngs_modulus_kpa":
    /// 200, "probe.contact": "frictionless"}`, the keys and values
    /// `skinpatch run --set` takes. Raises `ScenarioError` (with `file`,
    /// `line`, `key`) on a malformed or invalid scenario, `MeshError` on a
    /// bad mesh file, `FileNotFoundError` when a file is missing.
    #[staticmethod]
    #[pyo3(signature = (path, overrides=None))]
    fn load(
        py: Python<'_>,
        path: PathBuf,
        overrides: Option<&Bound<'_, PyDict>>,
    ) -> PyResult<Scenario> {
        let (mut sets, mut overridden) = (Vec::new(), Vec::new());
        if let Some(overrides) = overrides {
            for (key, value) in overrides.iter() {
                let key: String = key
                    .extract()
                    .map_err(|_| PyTypeError::new_err("override keys must be strings"))?;
                let value = toml_value(&value)
                    .map_err(|why| PyTypeError::new_err(format!("override {key}: {why}")))?;
                sets.push(format!("{key}={value}"));
                overridden.push(key);
            }
        }
        // For error messages only; a FIFO or device is not read here (it
        // would block), the load below refuses it by name.
        let text = skinpatch::mesh::io::read_input_text(&path).unwrap_or_default();
        let source = Source {
            path: &path,
            text: &text,
            overridden: &overridden,
        };
        this_process()?;
        let loaded = py.detach(|| {
            let scenario = skinpatch::scenario::Scenario::load_with(&path, &sets)?;
            Setup::from_scenario(&scenario, &path)
        });
        let setup = loaded.map_err(|e| to_py(py, e, Some(&source)))?;
        Ok(Scenario {
            path,
            text,
            overridden,
            setup: Arc::new(setup),
        })
    }

    /// The scenario's name (its file stem).
    #[getter]
    fn name(&self) -> &str {
        &self.setup.name
    }

    /// The scenario file.
    #[getter]
    fn path(&self) -> PathBuf {
        self.path.clone()
    }

    /// Frames the scenario runs, the rest frame (0) included.
    #[getter]
    fn frames(&self) -> usize {
        self.setup.simulation.frames + 1
    }

    /// Time between frames (s).
    #[getter]
    fn frame_dt(&self) -> f64 {
        self.setup.simulation.frame_dt
    }

    /// Where a run with outputs writes (`[output] dir`, else `out/<name>`).
    #[getter]
    fn output_dir(&self) -> PathBuf {
        self.setup.outputs.dir.clone()
    }

    /// Whether the scenario has a probe (`[probe]`).
    #[getter]
    fn has_probe(&self) -> bool {
        self.setup.simulation.probe.is_some()
    }

    /// Whether the scenario has a microstructure (`[microstructure]`).
    #[getter]
    fn has_microstructure(&self) -> bool {
        self.setup.outputs.micro.is_some()
    }

    /// The patch mesh (rest state).
    #[getter]
    fn mesh(&self) -> Mesh {
        Mesh {
            mesh: Arc::new(self.setup.mesh.clone()),
        }
    }

    fn __repr__(&self) -> String {
        format!(
            "Scenario('{}', {} frames, {} tets)",
            self.path.display(),
            self.setup.simulation.frames + 1,
            self.setup.mesh.num_tets()
        )
    }
}

/// A Python value as TOML (for an override's right-hand side).
fn toml_value(v: &Bound<'_, PyAny>) -> Result<toml::Value, String> {
    if v.is_instance_of::<PyBool>() {
        return Ok(toml::Value::Boolean(
            v.extract::<bool>().map_err(|e| e.to_string())?,
        ));
    }
    if v.is_instance_of::<PyInt>() {
        return Ok(toml::Value::Integer(
            v.extract::<i64>().map_err(|e| e.to_string())?,
        ));
    }
    if v.is_instance_of::<PyFloat>() {
        return Ok(toml::Value::Float(
            v.extract::<f64>().map_err(|e| e.to_string())?,
        ));
    }
    if v.is_instance_of::<PyString>() {
        return Ok(toml::Value::String(
            v.extract::<String>().map_err(|e| e.to_string())?,
        ));
    }
    if v.is_instance_of::<PyList>() || v.is_instance_of::<PyTuple>() {
        let items = v
            .try_iter()
            .map_err(|e| e.to_string())?
            .map(|item| toml_value(&item.map_err(|e| e.to_string())?))
            .collect::<Result<Vec<_>, _>>()?;
        return Ok(toml::Value::Array(items));
    }
    if let Ok(d) = v.cast::<PyDict>() {
        let mut table = toml::Table::new();
        for (k, item) in d.iter() {
            let k: String = k.extract().map_err(|_| "table keys must be strings")?;
            table.insert(k, toml_value(&item)?);
        }
        return Ok(toml::Value::Table(table));
    }
    // numpy integers (not `int` subclasses) and other integer-like objects:
    // `__index__` says they are whole (a usize key refuses a float).
    if let Ok(i) = v.call_method0("__index__").and_then(|i| i.extract::<i64>()) {
        return Ok(toml::Value::Integer(i));
    }
    // numpy floats and other numbers.
    if let Ok(x) = v.extract::<f64>() {
        return Ok(toml::Value::Float(x));
    }
    Err(format!(
        "{} is not a TOML value (bool, int, float, str, list or dict)",
        v.get_type()
            .name()
            .map(|n| n.to_string())
            .unwrap_or_default()
    ))
}
