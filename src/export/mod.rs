//! Writers for run outputs: per-frame VTU grids, the ParaView collection
//! file, the one-file VTKHDF alternative (feature `vtkhdf`) and the
//! metrics table.
//!
//! Every file is complete when it exists: grids are written atomically, and
//! `metrics.csv` is flushed row by row so an interrupted run keeps every
//! finished frame.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use crate::error::{Error, Result};
use crate::mesh::io::{self, Field, Grid};
use crate::mesh::{TetMesh, Vec3};
use crate::strain::{ElementStrains, SurfaceField};

pub mod frames;
pub mod outputs;
pub mod strain_images;
#[cfg(feature = "vtkhdf")]
pub mod vtkhdf;

/// One row of `metrics.csv`.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
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
    /// Smallest and largest r_s over the top-surface vertices.
    pub rs_range: [f64; 2],
    /// Smallest and largest r_t over the top-surface vertices.
    pub rt_range: [f64; 2],
    /// Top-surface vertices whose averaged T is folded (det T < 0).
    pub folded_vertices: usize,
    /// Tets with det F ≤ 0 (inverted elements).
    pub inverted_tets: usize,
    /// Smallest volume ratio J = det F over all tets.
    pub min_volume_ratio: f64,
    /// Largest penetration (mm).
    pub max_penetration_mm: f64,
    /// Newton iterations over the frame's substeps.
    pub newton_iterations: usize,
    /// Linear-solver iterations.
    pub linear_iterations: usize,
    /// Final relative residual.
    pub rel_residual: f64,
    /// `(W − E)/W`: the work `W` the probe and the supports did on the
    /// patch since the start (N·mm, over the load steps, at the nodes they
    /// hold; in a dynamic run, with inertia and damping, the work against
    /// the elastic forces at every node) less the elastic energy `E`
    /// stored in it, relative to the work; 0 before any work.
    pub energy_balance: f64,
    /// The largest net force on a node neither held nor in contact,
    /// relative to the probe force (to the largest held force without a
    /// probe force).
    pub free_node_force_ratio: f64,
    /// Wall-clock time of the frame (s); the only non-deterministic column.
    pub step_wall_s: f64,
}

const HEADER: &str = "frame,time_s,probe_force_x_n,probe_force_y_n,probe_force_z_n,\
contact_nodes,contact_area_mm2,max_penetration_mm,newton_iterations,linear_iterations,rel_residual,\
rs_min,rs_max,rt_min,rt_max,folded_vertices,inverted_tets,min_volume_ratio,energy_balance,\
free_node_force_ratio,step_wall_s";

/// A real number as every `metrics.csv` writes it: the shortest digits
/// that read back to the same bits, in plain decimal from 1e-4 up to 1e16
/// and in scientific notation (`1.5e-7`) outside that range, as spreadsheet
/// and data-frame readers parse both. (Wall times alone are fixed to
/// microseconds.)
pub fn csv_number(x: f64) -> String {
    let magnitude = x.abs();
    if x == 0.0 || !x.is_finite() || (1e-4..1e16).contains(&magnitude) {
        format!("{x}")
    } else {
        format!("{x:e}")
    }
}

/// A row type of `metrics.csv`: its header and how a row is written.
pub trait MetricsRow {
    /// The header line (column names, comma-separated, no newline).
    const HEADER: &'static str;
    /// One row, newline included.
    fn csv_row(&self) -> String;
}

impl MetricsRow for FrameMetrics {
    const HEADER: &'static str = HEADER;

    fn csv_row(&self) -> String {
        let m = self;
        let [fx, fy, fz] = m.probe_force_n;
        format!(
            "{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{:.6}\n",
            m.frame,
            csv_number(m.time_s),
            csv_number(fx),
            csv_number(fy),
            csv_number(fz),
            m.contact_nodes,
            csv_number(m.contact_area_mm2),
            csv_number(m.max_penetration_mm),
            m.newton_iterations,
            m.linear_iterations,
            csv_number(m.rel_residual),
            csv_number(m.rs_range[0]),
            csv_number(m.rs_range[1]),
            csv_number(m.rt_range[0]),
            csv_number(m.rt_range[1]),
            m.folded_vertices,
            m.inverted_tets,
            csv_number(m.min_volume_ratio),
            csv_number(m.energy_balance),
            csv_number(m.free_node_force_ratio),
            m.step_wall_s
        )
    }
}

/// One frame's row of an animated surface's `metrics.csv`.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct SurfaceMetrics {
    /// Frame index (0 is the first sample of the animation).
    pub frame: usize,
    /// Time (s).
    pub time_s: f64,
    /// Least and greatest r_s over the surface vertices.
    pub rs_range: [f64; 2],
    /// Least and greatest r_t over the surface vertices.
    pub rt_range: [f64; 2],
    /// Surface vertices whose averaged T folds (det T < 0).
    pub folded_vertices: usize,
    /// Triangles without area at rest, in UV or in this frame.
    pub degenerate_triangles: usize,
    /// Wall time of the frame's stages (s).
    pub wall_s: f64,
}

impl MetricsRow for SurfaceMetrics {
    const HEADER: &'static str =
        "frame,time_s,rs_min,rs_max,rt_min,rt_max,folded_vertices,degenerate_triangles,wall_s";

    fn csv_row(&self) -> String {
        let m = self;
        format!(
            "{},{},{},{},{},{},{},{},{:.6}\n",
            m.frame,
            csv_number(m.time_s),
            csv_number(m.rs_range[0]),
            csv_number(m.rs_range[1]),
            csv_number(m.rt_range[0]),
            csv_number(m.rt_range[1]),
            m.folded_vertices,
            m.degenerate_triangles,
            m.wall_s
        )
    }
}

/// `metrics.csv`, appended and flushed per frame through a [`CsvFile`]
/// (whole rows only, even on a full disk).
pub struct MetricsWriter<R: MetricsRow, W: Truncate = std::fs::File> {
    rows: std::marker::PhantomData<fn(&R)>,
    file: CsvFile<W>,
}

/// A CSV file appended and flushed line by line. Each line is formatted
/// first and written with one call; a write that fails (a full disk)
/// truncates the file back to its last whole line, so the file never ends
/// in half a row.
pub struct CsvFile<W: Truncate = std::fs::File> {
    path: PathBuf,
    file: W,
    /// Length of the file up to its last whole line (bytes).
    whole: u64,
}

/// A sink that can be cut back to a length (and continue writing there).
pub trait Truncate: std::io::Write {
    /// Cuts the data to `len` bytes; the next write continues at `len`.
    fn truncate_to(&mut self, len: u64) -> std::io::Result<()>;
}

impl Truncate for std::fs::File {
    fn truncate_to(&mut self, len: u64) -> std::io::Result<()> {
        use std::io::Seek;
        self.set_len(len)?;
        self.seek(std::io::SeekFrom::Start(len)).map(|_| ())
    }
}

impl<R: MetricsRow> MetricsWriter<R> {
    /// Creates (truncates) the file and writes the header.
    pub fn create(path: &Path) -> Result<MetricsWriter<R>> {
        let file = std::fs::File::create(path).map_err(|e| Error::io(path, e))?;
        MetricsWriter::new(path, file)
    }
}

impl<R: MetricsRow, W: Truncate> MetricsWriter<R, W> {
    /// Writes the header to `file` (reported as `path` in errors).
    pub fn new(path: &Path, file: W) -> Result<MetricsWriter<R, W>> {
        Ok(MetricsWriter {
            rows: std::marker::PhantomData,
            file: CsvFile::new(path, file, R::HEADER)?,
        })
    }

    /// Appends one row.
    pub fn push(&mut self, row: &R) -> Result<()> {
        self.file.write_line(&row.csv_row())
    }
}

impl CsvFile {
    /// Creates (truncates) the file at `path` and writes `header`.
    pub fn create(path: &Path, header: &str) -> Result<CsvFile> {
        let file = std::fs::File::create(path).map_err(|e| Error::io(path, e))?;
        CsvFile::new(path, file, header)
    }
}

impl<W: Truncate> CsvFile<W> {
    /// Writes `header` (no newline) to `file`, reported as `path` in errors.
    pub fn new(path: &Path, file: W, header: &str) -> Result<CsvFile<W>> {
        let mut csv = CsvFile {
            path: path.to_path_buf(),
            file,
            whole: 0,
        };
        csv.write_line(&format!("{header}\n"))?;
        Ok(csv)
    }

    /// Writes `line` (newline included) whole, or on failure cuts the file
    /// back to its last whole line and reports the error.
    pub fn write_line(&mut self, line: &str) -> Result<()> {
        match self
            .file
            .write_all(line.as_bytes())
            .and_then(|()| self.file.flush())
        {
            Ok(()) => {
                self.whole += line.len() as u64;
                Ok(())
            }
            Err(e) => {
                // Best effort: the write error is what gets reported.
                let _ = self.file.truncate_to(self.whole);
                Err(Error::io(&self.path, e))
            }
        }
    }
}

/// Component names of a 3-vector.
const XYZ: [&str; 3] = ["X", "Y", "Z"];

/// The deformed mesh of one frame at positions `x`.
///
/// Point data: `displacement_mm`; on top-surface vertices (NaN elsewhere)
/// `surface_stretch` (r_s, r_t) and the unit principal axes
/// `surface_axis_s`, `surface_axis_t` on the deformed surface; the probe's
/// `contact_force_n` on each node, `contact_pressure_n_mm2` and
/// `contact_shear_n_mm2` (zero off the contact). Cell data:
/// `region`, `principal_stretch` (λ1 ≥ λ2 ≥ λ3, sign-corrected),
/// `principal_biot_strain` (λ − 1), `principal_green_strain` ((λ² − 1)/2),
/// `volume_ratio` (J), the unit principal direction of each stretch
/// as a 3-vector, `principal_axis_K_rest` and `principal_axis_K_deformed`
/// (K = 1, 2, 3, matching λK), `cauchy_stress_n_mm2` (XX, YY, ZZ, XY, YZ,
/// XZ), `von_mises_stress_n_mm2` and `strain_energy_density_n_mm2` (per
/// rest volume). The points are the deformed positions.
/// Multi-component arrays carry component names (X, Y, Z for vectors).
pub fn frame_grid(
    mesh: &TetMesh,
    x: &[Vec3],
    strains: &ElementStrains,
    stresses: &[crate::strain::TetStress],
    contact: &crate::fem::contact::ContactForces,
    field: &SurfaceField,
) -> Grid {
    let displacement = x
        .iter()
        .zip(&mesh.positions)
        .flat_map(|(x, p)| (x - p).iter().copied().collect::<Vec<_>>())
        .collect();
    let n = mesh.num_tets();
    let (mut stretch, mut biot, mut green) = (
        Vec::with_capacity(3 * n),
        Vec::with_capacity(3 * n),
        Vec::with_capacity(3 * n),
    );
    let mut ratio = Vec::with_capacity(n);
    // Per stretch K, its direction in the rest and the deformed frame.
    let mut rest_axes: [Vec<f64>; 3] = std::array::from_fn(|_| Vec::with_capacity(3 * n));
    let mut deformed_axes: [Vec<f64>; 3] = std::array::from_fn(|_| Vec::with_capacity(3 * n));
    for s in &strains.tets {
        stretch.extend_from_slice(s.stretch.as_slice());
        biot.extend_from_slice(s.biot().as_slice());
        green.extend_from_slice(s.green().as_slice());
        ratio.push(s.volume_ratio());
        for k in 0..3 {
            rest_axes[k].extend(s.rest_axes.column(k).iter());
            deformed_axes[k].extend(s.deformed_axes.column(k).iter());
        }
    }
    let nv = mesh.num_vertices();
    let mut surface_stretch = vec![f64::NAN; 2 * nv];
    let mut axis_s = vec![f64::NAN; 3 * nv];
    let mut axis_t = vec![f64::NAN; 3 * nv];
    for (k, &v) in mesh.top.vertices.iter().enumerate() {
        let vs = &field.vertices[k];
        let svd = vs.strain().svd;
        surface_stretch[2 * v..2 * v + 2].copy_from_slice(&[svd.rs, svd.rt]);
        let [a, b] = vs.deformed_axes();
        axis_s[3 * v..3 * v + 3].copy_from_slice(a.as_slice());
        axis_t[3 * v..3 * v + 3].copy_from_slice(b.as_slice());
    }
    // Contact: zero force and traction off the contact.
    let (mut contact_force, mut pressure, mut shear) =
        (vec![0.0; 3 * nv], vec![0.0; nv], vec![0.0; nv]);
    for (k, &v) in contact.nodes.iter().enumerate() {
        contact_force[3 * v..3 * v + 3].copy_from_slice(contact.force_n[k].as_slice());
        pressure[v] = contact.pressure(k);
        shear[v] = contact.shear(k);
    }
    let (mut cauchy, mut von_mises, mut energy) = (
        Vec::with_capacity(6 * n),
        Vec::with_capacity(n),
        Vec::with_capacity(n),
    );
    for s in stresses {
        cauchy.extend_from_slice(&s.components());
        von_mises.push(s.von_mises());
        energy.push(s.energy_density);
    }
    Grid {
        points: x.to_vec(),
        tets: mesh.tets.clone(),
        triangles: Vec::new(),
        point_data: vec![
            Field::f64("displacement_mm", 3, displacement).named(&XYZ),
            Field::f64("surface_stretch", 2, surface_stretch).named(&["r_s", "r_t"]),
            Field::f64("surface_axis_s", 3, axis_s).named(&XYZ),
            Field::f64("surface_axis_t", 3, axis_t).named(&XYZ),
            Field::f64("contact_force_n", 3, contact_force).named(&XYZ),
            Field::f64("contact_pressure_n_mm2", 1, pressure),
            Field::f64("contact_shear_n_mm2", 1, shear),
        ],
        cell_data: {
            let mut cells = vec![
                Field::i32("region", 1, mesh.tet_region.clone()),
                Field::f64("principal_stretch", 3, stretch).named(&["λ1", "λ2", "λ3"]),
                Field::f64("principal_biot_strain", 3, biot).named(&["ε1", "ε2", "ε3"]),
                Field::f64("principal_green_strain", 3, green).named(&["E1", "E2", "E3"]),
                Field::f64("volume_ratio", 1, ratio),
                Field::f64("cauchy_stress_n_mm2", 6, cauchy)
                    .named(&["XX", "YY", "ZZ", "XY", "YZ", "XZ"]),
                Field::f64("von_mises_stress_n_mm2", 1, von_mises),
                Field::f64("strain_energy_density_n_mm2", 1, energy),
            ];
            for (frame, axes) in [("rest", rest_axes), ("deformed", deformed_axes)] {
                for (k, values) in axes.into_iter().enumerate() {
                    let name = format!("principal_axis_{}_{frame}", k + 1);
                    cells.push(Field::f64(&name, 3, values).named(&XYZ));
                }
            }
            cells
        },
    }
}

/// An animated surface's frame as a triangle grid: one point per surface
/// vertex (a UV seam has a point per chart) at its position in `x` (indexed
/// like `surface.positions`). Point data: `displacement_mm`, `uv`,
/// `surface_stretch` (r_s, r_t), `surface_axis_s`, `surface_axis_t` (unit
/// principal directions on the deformed surface). Cell data: the
/// triangle's own `triangle_stretch` (r_s, r_t of its T) and `degenerate`
/// (1 where it has no area at rest or in UV, or none now).
pub fn surface_grid(
    surface: &crate::surface::AnimatedSurface,
    x: &[Vec3],
    field: &SurfaceField,
) -> Grid {
    let top = &surface.top;
    let n = top.vertices.len();
    let (mut displacement, mut stretch) = (Vec::with_capacity(3 * n), Vec::with_capacity(2 * n));
    let (mut axis_s, mut axis_t) = (Vec::with_capacity(3 * n), Vec::with_capacity(3 * n));
    for (s, &v) in top.vertices.iter().enumerate() {
        displacement.extend((x[v] - surface.positions[v]).iter());
        let vs = &field.vertices[s];
        let svd = crate::strain::Svd2::of(&vs.t);
        stretch.extend([svd.rs, svd.rt]);
        let [a, b] = vs.deformed_axes();
        axis_s.extend(a.iter());
        axis_t.extend(b.iter());
    }
    let mut tri_stretch = Vec::with_capacity(2 * top.triangles.len());
    for t in &field.triangles {
        let svd = crate::strain::Svd2::of(&t.t);
        tri_stretch.extend([svd.rs, svd.rt]);
    }
    Grid {
        points: top.vertices.iter().map(|&v| x[v]).collect(),
        tets: Vec::new(),
        triangles: top.triangles.clone(),
        point_data: vec![
            Field::f64("displacement_mm", 3, displacement).named(&XYZ),
            Field::f64("uv", 2, top.uvs.iter().flatten().copied().collect()).named(&["u", "v"]),
            Field::f64("surface_stretch", 2, stretch).named(&["r_s", "r_t"]),
            Field::f64("surface_axis_s", 3, axis_s).named(&XYZ),
            Field::f64("surface_axis_t", 3, axis_t).named(&XYZ),
        ],
        cell_data: vec![
            Field::f64("triangle_stretch", 2, tri_stretch).named(&["r_s", "r_t"]),
            Field::i32(
                "degenerate",
                1,
                field
                    .triangles
                    .iter()
                    .map(|t| i32::from(t.weight == 0.0))
                    .collect(),
            ),
        ],
    }
}

/// Writes `frames/frame_NNNN.vtu` under `dir` in `format`; returns its path.
pub fn write_frame(
    dir: &Path,
    frame: usize,
    grid: &Grid,
    format: io::VtuFormat,
) -> Result<PathBuf> {
    let path = dir.join("frames").join(format!("frame_{frame:04}.vtu"));
    io::write_vtu_as(&path, grid, format)?;
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

#[cfg(test)]
mod tests {
    use super::*;

    /// Every real column reads back to its bits, and the FEM and surface
    /// rows write the same value the same way.
    #[test]
    fn metrics_numbers_round_trip_in_one_format() {
        let values = [
            0.0,
            1.0,
            0.25,
            1.0000000000000007,
            0.016666666666666666,
            -0.13623,
            1e-4,
            9.99e-5,
            -7.397313997013684e-5,
            6.2e-17,
            1e16,
            123456.789,
        ];
        for x in values {
            let text = csv_number(x);
            assert_eq!(
                text.parse::<f64>().unwrap().to_bits(),
                x.to_bits(),
                "{text}"
            );
        }
        assert_eq!(csv_number(0.016666666666666666), "0.016666666666666666");
        assert_eq!(csv_number(-7.397313997013684e-5), "-7.397313997013684e-5");
        assert_eq!(csv_number(1.0), "1");
        let fem = FrameMetrics {
            time_s: 0.1,
            rs_range: [0.98, 1.0000000000000007],
            ..FrameMetrics::default()
        };
        let surface = SurfaceMetrics {
            frame: 0,
            time_s: 0.1,
            rs_range: [0.98, 1.0000000000000007],
            rt_range: [0.0; 2],
            folded_vertices: 0,
            degenerate_triangles: 0,
            wall_s: 0.0,
        };
        let column = |header: &str, row: &str, name: &str| {
            let i = header.split(',').position(|c| c == name).unwrap();
            row.trim_end().split(',').nth(i).unwrap().to_string()
        };
        for name in ["time_s", "rs_min", "rs_max"] {
            assert_eq!(
                column(FrameMetrics::HEADER, &fem.csv_row(), name),
                column(SurfaceMetrics::HEADER, &surface.csv_row(), name),
                "{name}"
            );
        }
    }

    /// A sink that takes `room` bytes, then fails like a full disk (after a
    /// partial write).
    struct Full {
        data: Vec<u8>,
        room: usize,
    }

    impl std::io::Write for Full {
        fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
            let n = buf.len().min(self.room - self.data.len());
            if n == 0 && !buf.is_empty() {
                return Err(std::io::Error::new(
                    std::io::ErrorKind::StorageFull,
                    "disk full",
                ));
            }
            self.data.extend_from_slice(&buf[..n]);
            Ok(n)
        }
        fn flush(&mut self) -> std::io::Result<()> {
            Ok(())
        }
    }

    impl Truncate for Full {
        fn truncate_to(&mut self, len: u64) -> std::io::Result<()> {
            self.data.truncate(len as usize);
            Ok(())
        }
    }

    /// A row that does not fit is not left half written: the file ends
    /// with the last whole row, and the error names the file.
    #[test]
    fn a_full_disk_leaves_only_whole_rows() {
        full_disk_leaves_only_whole_rows(&FrameMetrics::default());
        full_disk_leaves_only_whole_rows(&SurfaceMetrics {
            frame: 12,
            time_s: 0.4,
            rs_range: [0.9, 1.2],
            rt_range: [0.8, 1.1],
            folded_vertices: 0,
            degenerate_triangles: 0,
            wall_s: 0.01,
        });
    }

    fn full_disk_leaves_only_whole_rows<R: MetricsRow>(row: &R) {
        let path = Path::new("out/metrics.csv");
        let header = R::HEADER;
        for room in [header.len() + 1 + 10, header.len() + 1 + 150, 2000] {
            let mut w = MetricsWriter::<R, _>::new(
                path,
                Full {
                    data: Vec::new(),
                    room,
                },
            )
            .unwrap();
            let mut written = 0;
            let err = loop {
                match w.push(row) {
                    Ok(()) => written += 1,
                    Err(e) => break e,
                }
                assert!(written < 100, "the sink never filled");
            };
            assert!(err.to_string().contains("out/metrics.csv"), "{err}");
            let text = String::from_utf8(w.file.file.data.clone()).unwrap();
            assert!(text.ends_with('\n'), "{text:?}");
            assert_eq!(text.lines().count(), 1 + written);
            assert!(
                text.lines()
                    .skip(1)
                    .all(|l| l.split(',').count() == header.split(',').count()),
                "{text}"
            );
        }
    }
}
