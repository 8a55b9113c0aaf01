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
    #[error("{path}: {}", clip(&.cause.to_string()))]
    Io {
        /// The file or folder being read or written.
        path: PathBuf,
        /// The underlying error (shown in the message, so not chained again).
        cause: std::io::Error,
    },

    /// A malformed input file, with the 1-based line where the problem was found.
    #[error("{path}{}: {}", at_line(*.line), clip(.message))]
    Parse {
        /// The file being parsed.
        path: PathBuf,
        /// 1-based line number (0 when the whole file is at fault, e.g. it is empty).
        line: usize,
        /// What is wrong there.
        message: String,
    },

    /// A scenario file that is not valid TOML or does not match the schema.
    #[error("{path}: {}", clip(.message))]
    Scenario {
        /// The scenario file.
        path: PathBuf,
        /// What is wrong, naming the key (and line where known).
        message: String,
        /// The dotted key at fault, where one is (also in `message`).
        key: Option<String>,
        /// Its 1-based line in the file, where known (also in `message`).
        line: Option<usize>,
    },

    /// A parameter outside its valid range, named by its scenario key or flag.
    #[error("{} {}", clip(.key), clip(.reason))]
    Parameter {
        /// Dotted scenario key, e.g. `mesh.top_layer_mm`.
        key: String,
        /// Why the value is rejected, e.g. `must be > 0, got -1`.
        reason: String,
    },

    /// A mesh that is structurally unusable (bad indices, degenerate or inverted
    /// tetrahedra, non-manifold surface, empty regions).
    #[error("{}: {}", clip(.origin), clip(.message))]
    InvalidMesh {
        /// Where the mesh came from (a file path or `generated mesh`).
        origin: String,
        /// What is wrong, naming the tetrahedron, face or vertex.
        message: String,
    },

    /// TetGen failed or produced a mesh that misses the requested quality.
    #[error("mesh generation failed: {}", clip(.0))]
    MeshGeneration(String),

    /// The simulation could not reach equilibrium (names the frame and residual).
    #[error("solver failed: {}", clip(.0))]
    Solver(String),

    /// A feature needed for the request was disabled at build time.
    #[error("{}", clip(.0))]
    FeatureDisabled(String),

    /// An external program the request needs is not installed.
    #[error("{}", clip(.0))]
    MissingTool(String),

    /// A stage produced a value that is not finite (NaN or infinity); its
    /// output is not written.
    #[error("{stage} produced a non-finite value at frame {frame} ({})", clip(.detail))]
    NonFinite {
        /// The stage, e.g. `microstructure (GPU)` or `render (dynamic)`.
        stage: String,
        /// The frame.
        frame: usize,
        /// Where (texel or pixel) and what.
        detail: String,
    },

    /// No usable GPU adapter, a limit a stage needs, or a failed GPU
    /// operation (what failed and on which adapter).
    #[error("GPU: {}", clip(.0))]
    Gpu(String),
}

/// Longest message part shown in full; a longer one (e.g. a bad value of a
/// megabyte echoed in its error) keeps its start and end.
const MAX_SHOWN: usize = 400;

/// `:line` after a file name, nothing for line 0 (the whole file).
fn at_line(line: usize) -> String {
    if line == 0 {
        String::new()
    } else {
        format!(":{line}")
    }
}

/// `text`, or for a longer one its first 300 and last 80 characters around
/// a note of how many were left out. The error keeps the full text.
fn clip(text: &str) -> std::borrow::Cow<'_, str> {
    let count = text.chars().count();
    if count <= MAX_SHOWN {
        return text.into();
    }
    let head: String = text.chars().take(300).collect();
    let tail: String = text.chars().skip(count - 80).collect();
    format!("{head} … [{} characters left out] … {tail}", count - 380).into()
}

/// A number as an error message shows it: plainly when moderate, in
/// exponent form when huge or tiny (`1e300`, not three hundred digits).
pub fn shown(v: f64) -> String {
    if v != 0.0 && v.is_finite() && !(1e-4..1e6).contains(&v.abs()) {
        format!("{v:e}")
    } else {
        format!("{v}")
    }
}

/// Shorthand for results with the library error type.
pub type Result<T, E = Error> = std::result::Result<T, E>;

/// The first non-finite value of `values` — `components` numbers per
/// element of a `width`-wide grid — as an error of `stage` at `frame`,
/// naming the element's column and row.
pub fn check_finite<'a, I>(
    stage: &str,
    frame: usize,
    width: usize,
    components: usize,
    values: I,
) -> Result<()>
where
    I: IntoIterator<Item = &'a f32>,
{
    let (width, components) = (width.max(1), components.max(1));
    match values.into_iter().position(|v| !v.is_finite()) {
        None => Ok(()),
        Some(k) => {
            let e = k / components;
            Err(Error::NonFinite {
                stage: stage.to_string(),
                frame,
                detail: format!("at column {}, row {}", e % width, e / width),
            })
        }
    }
}

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

#[cfg(test)]
mod tests {
    use super::*;

    /// A megabyte value echoed in an error is shown by its ends only; short
    /// messages are untouched.
    /// The error names the stage, the frame and the element.
    #[test]
    fn non_finite_values_are_located() {
        let ok = [1.0f32, 2.0, 3.0, 4.0];
        assert!(check_finite("s", 0, 2, 1, &ok).is_ok());
        let bad = [0.0f32, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, f32::NAN, 0.0];
        let e = check_finite("rendering (dynamic)", 7, 2, 3, &bad).unwrap_err();
        assert_eq!(
            e.to_string(),
            "rendering (dynamic) produced a non-finite value at frame 7 (at column 0, row 1)"
        );
    }

    #[test]
    fn long_messages_are_clipped_when_shown() {
        let value = "x".repeat(1 << 20);
        let e = Error::parameter("solver.linear", format!("must be \"cg\", got \"{value}\""));
        let shown = e.to_string();
        assert!(shown.len() < 600, "{} bytes", shown.len());
        assert!(
            shown.starts_with("solver.linear must be \"cg\", got \"xxx"),
            "{shown}"
        );
        assert!(shown.contains("characters left out"));
        assert!(shown.ends_with("xxx\""));
        let short = Error::parameter("mesh.top_layer_mm", "must be > 0, got -1");
        assert_eq!(short.to_string(), "mesh.top_layer_mm must be > 0, got -1");
        // Multi-byte characters are cut on character boundaries.
        let e = Error::Solver("é".repeat(1000));
        assert!(e.to_string().contains("characters left out"));
    }
}
