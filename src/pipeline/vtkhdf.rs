//! The run's `frames.vtkhdf`, when the build has the `vtkhdf` feature
//! (scenario validation refuses `output.frames_vtkhdf` without it, so the
//! stand-ins below are never asked to write).

use std::path::Path;

use crate::error::Result;
use crate::mesh::io::Grid;
use crate::scenario::Setup;

#[cfg(feature = "vtkhdf")]
pub(super) type Writer = crate::export::vtkhdf::VtkHdfWriter;

/// Without the feature there is no writer; `Option<Writer>` stays `None`.
#[cfg(not(feature = "vtkhdf"))]
pub(super) enum Writer {}

/// Appends `grid` as the step at `time`, creating `dir/frames.vtkhdf` on
/// the first call.
#[cfg(feature = "vtkhdf")]
pub(super) fn push(
    writer: &mut Option<Writer>,
    dir: &Path,
    setup: &Setup,
    time: f64,
    grid: &Grid,
) -> Result<()> {
    if writer.is_none() {
        *writer = Some(Writer::create(
            &dir.join("frames.vtkhdf"),
            grid,
            setup.outputs.vtu_format,
        )?);
    }
    writer
        .as_mut()
        .expect("created just above")
        .push(time, grid)
}

#[cfg(not(feature = "vtkhdf"))]
pub(super) fn push(
    _writer: &mut Option<Writer>,
    _dir: &Path,
    _setup: &Setup,
    _time: f64,
    _grid: &Grid,
) -> Result<()> {
    Err(crate::error::Error::parameter(
        "output.frames_vtkhdf",
        "needs skinpatch built with the `vtkhdf` feature",
    ))
}

/// Closes the file, if one was written.
pub(super) fn finish(writer: Option<Writer>) -> Result<()> {
    #[cfg(feature = "vtkhdf")]
    return writer.map(Writer::finish).transpose().map(drop);
    #[cfg(not(feature = "vtkhdf"))]
    match writer {
        None => Ok(()),
        Some(never) => match never {},
    }
}
