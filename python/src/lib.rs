//! The Python face of skinpatch (the extension module `skinpatch._native`,
//! re-exported by the `skinpatch` package): scenarios, runs stepped from
//! Python, each frame's fields as numpy arrays, the microstructure maps,
//! kernel fitting and mesh I/O. Long work (loading, solving, deforming maps, writing) runs
//! without the GIL.

mod arrays;
mod errors;
mod fit;
mod mesh;
mod run;
mod scenario;

use pyo3::prelude::*;

use errors::{to_py, GpuError, MeshError, ScenarioError, SkinpatchError, SolverError};

/// The scenario's neutral microstructure map: `(height, width)` float32
/// heights in µm. The scenario needs a `[microstructure]` with a whole map.
#[pyfunction]
fn neutral_map<'py>(
    py: Python<'py>,
    scenario: &scenario::Scenario,
) -> PyResult<Bound<'py, numpy::PyArray2<f32>>> {
    errors::this_process()?;
    let micro = scenario
        .setup
        .outputs
        .micro
        .as_ref()
        .ok_or_else(|| SkinpatchError::new_err("the scenario has no [microstructure]"))?;
    let map = micro
        .neutral
        .whole("neutral_map")
        .map_err(|e| to_py(py, e, Some(&scenario.source())))?;
    run::heights_um(py, map)
}

#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add("SkinpatchError", py.get_type::<SkinpatchError>())?;
    m.add("ScenarioError", py.get_type::<ScenarioError>())?;
    m.add("MeshError", py.get_type::<MeshError>())?;
    m.add("SolverError", py.get_type::<SolverError>())?;
    m.add("GpuError", py.get_type::<GpuError>())?;
    m.add_class::<scenario::Scenario>()?;
    m.add_class::<run::Run>()?;
    m.add_class::<run::Frame>()?;
    m.add_class::<mesh::Mesh>()?;
    m.add_function(wrap_pyfunction!(neutral_map, m)?)?;
    m.add_function(wrap_pyfunction!(fit::fit, m)?)?;
    m.add_function(wrap_pyfunction!(mesh::read_mesh, m)?)?;
    m.add_function(wrap_pyfunction!(mesh::write_vtu, m)?)?;
    Ok(())
}
