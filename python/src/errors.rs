//! The Python exceptions and how the library's errors become them.

use std::path::Path;

use std::sync::atomic::{AtomicU32, Ordering};

use pyo3::exceptions::{PyException, PyFileNotFoundError, PyOSError, PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use skinpatch::Error;

pyo3::create_exception!(
    skinpatch,
    SkinpatchError,
    PyException,
    "Base class of the errors skinpatch raises."
);
pyo3::create_exception!(
    skinpatch,
    ScenarioError,
    SkinpatchError,
    "A scenario that does not parse or validate. Attributes: `file` (the scenario \
     file), `line` (1-based, or None where the key is not in the file, e.g. an \
     override) and `key` (the dotted key at fault, or None)."
);
pyo3::create_exception!(
    skinpatch,
    MeshError,
    SkinpatchError,
    "A mesh file that does not parse, or a mesh the simulation cannot use."
);
pyo3::create_exception!(
    skinpatch,
    SolverError,
    SkinpatchError,
    "A frame whose equilibrium was not reached (the message names the frame and \
     residual); an in-memory run stays at its last good frame."
);
pyo3::create_exception!(
    skinpatch,
    GpuError,
    SkinpatchError,
    "A GPU stage that failed (or, with SKINPATCH_REQUIRE_GPU=1, no GPU adapter)."
);

/// The process whose skinpatch calls started the worker threads (0: none
/// has yet).
static WORKERS_PID: AtomicU32 = AtomicU32::new(0);

/// Called before any work that may use the worker threads (rayon's pool,
/// which the solver, strains and maps share). A process forked after they
/// started has none of them — only the thread that called `fork` is
/// copied — so work handed to them would wait forever: such a child gets
/// a `RuntimeError` that says what to do instead.
pub fn this_process() -> PyResult<()> {
    let pid = std::process::id();
    match WORKERS_PID.compare_exchange(0, pid, Ordering::SeqCst, Ordering::SeqCst) {
        Ok(_) => Ok(()),
        Err(owner) if owner == pid => Ok(()),
        Err(owner) => Err(PyRuntimeError::new_err(format!(
            "skinpatch's worker threads were started in process {owner}, and this process \
             ({pid}) was forked from it after that: a forked child has none of those threads, \
             so the work would wait forever. Start worker processes with the 'spawn' or \
             'forkserver' method (multiprocessing.get_context(\"spawn\"), or \
             concurrent.futures.ProcessPoolExecutor(mp_context=...)), or fork before the \
             first skinpatch call"
        ))),
    }
}

/// The scenario file an error came from, with its text (to find a key's
/// line) and the keys overrides set (whose values are not in the text).
pub struct Source<'a> {
    pub path: &'a Path,
    pub text: &'a str,
    pub overridden: &'a [String],
}

/// `e` as a Python exception. With `source`, a parameter error names its
/// scenario key and becomes a `ScenarioError` at that key's line.
pub fn to_py(py: Python<'_>, e: Error, source: Option<&Source<'_>>) -> PyErr {
    let message = e.to_string();
    match e {
        Error::Scenario {
            path, key, line, ..
        } => scenario_error(py, &message, &path, line, key),
        Error::Parameter { key, .. } => match source {
            Some(s) => {
                let line = if s.overridden.iter().any(|o| o == &key) {
                    None
                } else {
                    skinpatch::scenario::key_line(s.text, &key)
                };
                let message = match line {
                    Some(line) => format!("{}: line {line}: {message}", s.path.display()),
                    None => format!("{}: {message}", s.path.display()),
                };
                scenario_error(py, &message, s.path, line, Some(key))
            }
            None => PyValueError::new_err(message),
        },
        Error::Io { cause, .. } if cause.kind() == std::io::ErrorKind::NotFound => {
            PyFileNotFoundError::new_err(message)
        }
        Error::Io { .. } => PyOSError::new_err(message),
        Error::Parse { .. } | Error::InvalidMesh { .. } | Error::MeshGeneration(_) => {
            MeshError::new_err(message)
        }
        Error::Solver(_) => SolverError::new_err(message),
        Error::Gpu(_) => GpuError::new_err(message),
        _ => SkinpatchError::new_err(message),
    }
}

fn scenario_error(
    py: Python<'_>,
    message: &str,
    path: &Path,
    line: Option<usize>,
    key: Option<String>,
) -> PyErr {
    let err = ScenarioError::new_err(message.to_string());
    let value = err.value(py);
    // Setting attributes on a fresh exception object cannot fail short of
    // running out of memory, which the raise would report anyway.
    let _ = value.setattr("file", path.to_string_lossy().into_owned());
    let _ = value.setattr("line", line);
    let _ = value.setattr("key", key);
    err
}
