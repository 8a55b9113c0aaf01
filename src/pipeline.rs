//! Runs a validated [`Setup`] and writes its outputs.
//!
//! For now the pipeline writes the rest mesh (VTU and optionally TetGen
//! files) into the output folder; the simulation stages hook in here as they
//! land.

use std::path::PathBuf;

use crate::error::{Error, Result};
use crate::mesh::{io, QualityReport};
use crate::scenario::Setup;

/// What a run produced.
#[derive(Clone, Debug)]
pub struct RunSummary {
    /// Files written, in order.
    pub written: Vec<PathBuf>,
    /// Quality of the mesh used.
    pub quality: QualityReport,
}

/// Runs the scenario: creates the output folder and writes the outputs.
pub fn run(setup: &Setup) -> Result<RunSummary> {
    let dir = &setup.output_dir;
    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    let mut written = Vec::new();
    if setup.write_mesh_vtu {
        let path = dir.join("mesh.vtu");
        io::write_vtu(&path, &io::Grid::from_mesh(&setup.mesh))?;
        log::info!("wrote {}", path.display());
        written.push(path);
    }
    if setup.write_mesh_tetgen {
        let base = dir.join("mesh");
        io::write_tetgen(&setup.mesh, &base)?;
        log::info!("wrote {}.node/.ele/.face", base.display());
        written.extend(io::tetgen_paths(&base));
    }
    Ok(RunSummary {
        written,
        quality: QualityReport::of(&setup.mesh),
    })
}
