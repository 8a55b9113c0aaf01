//! numpy arrays from the library's vectors: each array owns a buffer made
//! for it (a Vec moved into numpy, no second copy).

use nalgebra::{Matrix3, Vector3};
use numpy::{PyArray1, PyArray2, PyArray3, PyArrayMethods};
use pyo3::prelude::*;

/// `(n, 3)` float64 from 3-vectors.
pub fn vec3s<'py>(py: Python<'py>, v: &[Vector3<f64>]) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let flat: Vec<f64> = v.iter().flat_map(|p| [p.x, p.y, p.z]).collect();
    PyArray1::from_vec(py, flat).reshape([v.len(), 3])
}

/// `(n, k)` from a row-major buffer of `n × k` values.
pub fn rows<'py, T: numpy::Element>(
    py: Python<'py>,
    flat: Vec<T>,
    k: usize,
) -> PyResult<Bound<'py, PyArray2<T>>> {
    let n = flat.len() / k.max(1);
    PyArray1::from_vec(py, flat).reshape([n, k])
}

/// `(n, 3, 3)` float64 from 3 × 3 matrices (row-major per matrix).
pub fn mat3s<'py>(py: Python<'py>, m: &[Matrix3<f64>]) -> PyResult<Bound<'py, PyArray3<f64>>> {
    let flat: Vec<f64> = m
        .iter()
        .flat_map(|a| (0..3).flat_map(move |i| (0..3).map(move |j| a[(i, j)])))
        .collect();
    PyArray1::from_vec(py, flat).reshape([m.len(), 3, 3])
}

/// `(n,)` int64 from indices.
pub fn indices<'py>(py: Python<'py>, v: impl Iterator<Item = usize>) -> Bound<'py, PyArray1<i64>> {
    PyArray1::from_vec(py, v.map(|i| i as i64).collect())
}
