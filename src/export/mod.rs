//! Writers for run outputs: per-frame VTU grids, the ParaView collection
//! file and the metrics table.
//!
//! Every file is complete when it exists: grids are written atomically, and
//! `metrics.csv` is flushed row by row so an interrupted run keeps every
//! finished frame.

use std::fmt::Write as _;
use std::io::Write as _;
use std::path::{Path, PathBuf};

use crate::error::{Error, Result};
use crate::fem::integrate::Simulation;
use crate::mesh::io::{self, Field, Grid};
use crate::mesh::TetMesh;

/// One row of `metrics.csv`.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FrameMetrics {
    /// Frame number (0 is t = 0).
    pub frame: usize,
    /// Simulated time (s).
    pub time_s: f64,
    /// Force the skin exerts on the probe (N).
    pub probe_force_n: [f64; 3],
    /// Nodes in contact.
    pub contact_nodes: usize,
    /// Skin area in contact (mm², lumped nodal areas of the contact nodes).
    pub contact_area_mm2: f64,
    /// Largest penetration (mm).
    pub max_penetration_mm: f64,
    /// Newton iterations over the frame's substeps and contact rounds.
    pub newton_iterations: usize,
    /// Linear-solver iterations.
    pub linear_iterations: usize,
    /// Final relative residual.
    pub rel_residual: f64,
    /// Wall-clock time of the frame (s); the only non-deterministic column.
    pub step_wall_s: f64,
}

const HEADER: &str = "frame,time_s,probe_force_x_n,probe_force_y_n,probe_force_z_n,\
contact_nodes,contact_area_mm2,max_penetration_mm,newton_iterations,linear_iterations,rel_residual,step_wall_s";

/// `metrics.csv`, appended and flushed per frame.
pub struct MetricsWriter {
    path: PathBuf,
    file: std::fs::File,
}

impl MetricsWriter {
    /// Creates (truncates) the file and writes the header.
    pub fn create(path: &Path) -> Result<MetricsWriter> {
        let mut file = std::fs::File::create(path).map_err(|e| Error::io(path, e))?;
        writeln!(file, "{HEADER}").map_err(|e| Error::io(path, e))?;
        Ok(MetricsWriter {
            path: path.to_path_buf(),
            file,
        })
    }

    /// Appends one row.
    pub fn push(&mut self, m: &FrameMetrics) -> Result<()> {
        let [fx, fy, fz] = m.probe_force_n;
        writeln!(
            self.file,
            "{},{},{fx:e},{fy:e},{fz:e},{},{:e},{:e},{},{},{:e},{:.6}",
            m.frame,
            m.time_s,
            m.contact_nodes,
            m.contact_area_mm2,
            m.max_penetration_mm,
            m.newton_iterations,
            m.linear_iterations,
            m.rel_residual,
            m.step_wall_s
        )
        .and_then(|()| self.file.flush())
        .map_err(|e| Error::io(&self.path, e))
    }
}

/// The deformed mesh of one frame: positions, displacement (point data),
/// region, principal stretches λ1 ≥ λ2 ≥ λ3 (sign-corrected) and volume
/// ratio J (cell data).
pub fn frame_grid(mesh: &TetMesh, sim: &Simulation) -> Grid {
    let displacement = sim
        .x
        .iter()
        .zip(&mesh.positions)
        .flat_map(|(x, p)| (x - p).iter().copied().collect::<Vec<_>>())
        .collect();
    let mut stretches = Vec::with_capacity(3 * mesh.num_tets());
    let mut ratio = Vec::with_capacity(mesh.num_tets());
    for c in sim.corotations() {
        stretches.extend_from_slice(c.sigma.as_slice());
        ratio.push(c.sigma.product());
    }
    Grid {
        points: sim.x.clone(),
        tets: mesh.tets.clone(),
        point_data: vec![Field::f64("displacement_mm", 3, displacement)],
        cell_data: vec![
            Field::i32("region", 1, mesh.tet_region.clone()),
            Field::f64("principal_stretch", 3, stretches),
            Field::f64("volume_ratio", 1, ratio),
        ],
    }
}

/// Writes `frames/frame_NNNN.vtu` under `dir`; returns its path.
pub fn write_frame(dir: &Path, frame: usize, grid: &Grid) -> Result<PathBuf> {
    let path = dir.join("frames").join(format!("frame_{frame:04}.vtu"));
    io::write_vtu(&path, grid)?;
    Ok(path)
}

/// Writes `frames.pvd`, a ParaView collection of the frame files with times.
pub fn write_collection(dir: &Path, frames: &[(f64, PathBuf)]) -> Result<PathBuf> {
    let mut s = String::from(
        "<?xml version=\"1.0\"?>\n<VTKFile type=\"Collection\" version=\"0.1\">\n  <Collection>\n",
    );
    for (t, path) in frames {
        let rel = path.strip_prefix(dir).unwrap_or(path);
        let _ = writeln!(
            s,
            "    <DataSet timestep=\"{t}\" group=\"\" part=\"0\" file=\"{}\"/>",
            rel.display()
        );
    }
    s.push_str("  </Collection>\n</VTKFile>\n");
    let path = dir.join("frames.pvd");
    io::write_atomically(&path, s.as_bytes())?;
    Ok(path)
}
