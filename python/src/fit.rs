//! `skinpatch.fit`: `skinpatch fit` from Python, its report as plain data.

use std::path::PathBuf;

use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};
use skinpatch::micro::PiecewiseLinear;
use skinpatch::pipeline::fit::{fit_file, FitReport};

use crate::errors::{this_process, to_py, Source};

/// Fits kernel parameters (α, σ) to the deformed maps of a samples file and
/// a kernel model to them, as `skinpatch fit <samples.toml>` does (the same
/// validation, search and kernel file, written when the file names an
/// `output`). Returns a dict: `rows` (per sample, then per point: `source`,
/// `r`, `alpha`, `sigma_um`, and for fitted samples `axis`, `range`,
/// `distance`, `alpha_valley`, `sigma_valley_um`, `seconds`), `model`
/// (`alpha`, `sigma_compression_um`, `sigma_stretch_um`: lists of `(r,
/// value)` knots, as in `[microstructure.kernel]`), `written` (the kernel
/// file's path or None) and `device` (where candidates were counted, or
/// None without map samples). Raises `ScenarioError` naming the key of a
/// value out of range, `FileNotFoundError` for a missing file.
#[pyfunction]
pub fn fit<'py>(py: Python<'py>, samples_path: PathBuf) -> PyResult<Bound<'py, PyDict>> {
    this_process()?;
    let report = py
        .detach(|| fit_file(&samples_path, |_, _, _| {}))
        .map_err(|e| {
            let text = skinpatch::mesh::io::read_input_text(&samples_path).unwrap_or_default();
            let source = Source {
                path: &samples_path,
                text: &text,
                overridden: &[],
            };
            to_py(py, e, Some(&source))
        })?;
    report_dict(py, &report)
}

fn knots<'py>(py: Python<'py>, table: &PiecewiseLinear) -> PyResult<Bound<'py, PyList>> {
    PyList::new(py, table.points.iter().copied())
}

fn report_dict<'py>(py: Python<'py>, report: &FitReport) -> PyResult<Bound<'py, PyDict>> {
    let rows = PyList::empty(py);
    for row in &report.rows {
        let d = PyDict::new(py);
        d.set_item("source", &row.source)?;
        d.set_item("r", row.r)?;
        d.set_item("alpha", row.alpha)?;
        d.set_item("sigma_um", row.sigma_um)?;
        if let Some(f) = &row.fit {
            d.set_item("axis", format!("{:?}", f.axis).to_lowercase())?;
            d.set_item("range", f.range)?;
            d.set_item("distance", f.result.distance)?;
            d.set_item("alpha_valley", f.result.alpha_range)?;
            d.set_item("sigma_valley_um", f.result.sigma_range_um)?;
            d.set_item("seconds", f.seconds)?;
        }
        rows.append(d)?;
    }
    let model = PyDict::new(py);
    model.set_item("alpha", knots(py, &report.model.alpha)?)?;
    model.set_item(
        "sigma_compression_um",
        knots(py, &report.model.sigma_compression_um)?,
    )?;
    model.set_item(
        "sigma_stretch_um",
        knots(py, &report.model.sigma_stretch_um)?,
    )?;
    let out = PyDict::new(py);
    out.set_item("rows", rows)?;
    out.set_item("model", model)?;
    out.set_item(
        "written",
        report.written.as_ref().map(|p| p.display().to_string()),
    )?;
    out.set_item("device", report.device.as_deref())?;
    Ok(out)
}
