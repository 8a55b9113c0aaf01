//! The library's error type.
//!
//! Every variant names *what* went wrong and *where*: a file and line, a
//! scenario key, or an element index. The binary adds context on top with
//! `anyhow`; the library never panics on bad input.

use std::path::PathBuf;

/// Errors returned by the `skinpatch` library.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// An operating-system I/O failure on a named file.
    #[error("{path}: {cause}")]
    Io {
        /// The file or folder being read or written.
        path: PathBuf,
        /// The underlying error (shown in the message, so not chained again).
        cause: std::io::Error,
    },

    /// A malformed input file, with the 1-based line where the problem was found.
    #[error("{path}:{line}: {message}")]
    Parse {
        /// The file being parsed.
        path: PathBuf,
        /// 1-based line number (0 when the whole file is at fault, e.g. it is empty).
        line: usize,
        /// What is wrong there.
        message: String,
    },

    /// A scenario file that is not valid TOML or does not match the schema.
    #[error("{path}: {message}")]
    Scenario {
        /// The scenario file.
        path: PathBuf,
        /// What is wrong, naming the key (and line where known).
        message: String,
    },

    /// A parameter outside its valid range, named by its scenario key or flag.
    #[error("{key} {reason}")]
    Parameter {
        /// Dotted scenario key, e.g. `mesh.top_layer_mm`.
        key: String,
        /// Why the value is rejected, e.g. `must be > 0, got -1`.
        reason: String,
    },

    /// A mesh that is structurally unusable (bad indices, degenerate or inverted
    /// tetrahedra, non-manifold surface, empty regions).
    #[error("{origin}: {message}")]
    InvalidMesh {
        /// Where the mesh came from (a file path or `generated mesh`).
        origin: String,
        /// What is wrong, naming the tetrahedron, face or vertex.
        message: String,
    },

    /// TetGen failed or produced a mesh that misses the requested quality.
    #[error("mesh generation failed: {0}")]
    MeshGeneration(String),

    /// The simulation could not reach equilibrium (names the frame and residual).
    #[error("solver failed: {0}")]
    Solver(String),

    /// A feature needed for the request was disabled at build time.
    #[error("{0}")]
    FeatureDisabled(String),

    /// An external program the request needs is not installed.
    #[error("{0}")]
    MissingTool(String),

    /// No usable GPU adapter, a limit a stage needs, or a failed GPU
    /// operation (what failed and on which adapter).
    #[error("GPU: {0}")]
    Gpu(String),
}

/// Shorthand for results with the library error type.
pub type Result<T, E = Error> = std::result::Result<T, E>;

impl Error {
    /// Wraps an I/O error with the path it concerns.
    pub fn io(path: impl Into<PathBuf>, cause: std::io::Error) -> Self {
        Error::Io {
            path: path.into(),
            cause,
        }
    }

    /// A file that is malformed as a whole (no line to point at, e.g. a
    /// binary format).
    pub fn malformed(path: &std::path::Path, message: impl Into<String>) -> Self {
        Error::Parse {
            path: path.to_path_buf(),
            line: 0,
            message: message.into(),
        }
    }

    /// A missing file.
    pub fn not_found(path: &std::path::Path) -> Self {
        Error::io(
            path,
            std::io::Error::new(std::io::ErrorKind::NotFound, "no such file"),
        )
    }

    /// A range error for the scenario key `key`.
    pub fn parameter(key: impl Into<String>, reason: impl Into<String>) -> Self {
        Error::Parameter {
            key: key.into(),
            reason: reason.into(),
        }
    }
}
