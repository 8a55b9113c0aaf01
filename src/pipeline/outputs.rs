//! The output stage both kinds of run share: a frame source (the FEM
//! [`Stepper`](super::Stepper) or an animated surface's frames) hands it each
//! frame, and it writes what the scenario asks for — the frame's VTU and the
//! ParaView collection, per map the strain images and the deformed
//! microstructure (NaN-checked, normals too), the rendered frames — and then
//! the frame's `metrics.csv` row through [`MetricsWriter`] (whole rows only,
//! even on a full disk), and last the frame's entry in `frames.pvd`. A row
//! in `metrics.csv` therefore means that the frame's files (and its
//! `volume.csv` row) are complete, and an entry in `frames.pvd` that its row
//! is there too.
//!
//! Setting up is ordered so that everything that can fail before the first
//! frame (the adapters, ffmpeg) is checked before an earlier run's files are
//! removed from the output folder.

use std::path::{Path, PathBuf};

use super::micro::{write_neutral, MicroEngine};
use super::render::RenderEngine;
use crate::error::{Error, Result};
use crate::export::{self, MetricsRow, MetricsWriter};
use crate::mesh::io::Grid;
use crate::render::scene::FrameGeometry;
use crate::scenario::OutputSetup;
use crate::strain::{StrainRaster, SurfaceField};

/// What every kind of run writes per frame, borrowed from its setup.
pub(super) struct OutputSpec<'a> {
    /// What the scenario asks to write.
    pub outputs: &'a OutputSetup,
    /// Width of the surface's UV square (mm) and of a render texel (mm).
    pub extent_mm: (f64, f64),
    /// Frame rate of the MP4 files (Hz).
    pub frame_rate_hz: f64,
}

/// One map of the surface: the unit square (tag `""`), or a UDIM tile with
/// its triangles (tag `"1001_"`).
pub(super) struct MapPiece<'a> {
    /// Text before the frame number in the map's file names.
    pub tag: String,
    /// The triangles of the piece, moved into the unit square; `None`: every
    /// triangle in place.
    pub triangles: Option<&'a [(usize, [f64; 2])]>,
}

/// One frame as a source hands it to the output stage.
pub(super) struct FrameInput<'a> {
    /// Frame index.
    pub frame: usize,
    /// Time (s).
    pub time_s: f64,
    /// The surface's deformation in texture space.
    pub field: &'a SurfaceField,
    /// The frame's VTU grid (built by the source when frames are written).
    pub grid: Option<&'a Grid>,
    /// The render geometry at a tessellation (called on rendered frames).
    pub geometry: &'a dyn Fn(usize) -> FrameGeometry,
}

/// The output stage of a run: set up once, then fed frame by frame.
pub(super) struct FrameOutputs<'a, R: MetricsRow> {
    spec: OutputSpec<'a>,
    pieces: Vec<MapPiece<'a>>,
    /// One microstructure engine per piece.
    engines: Vec<MicroEngine>,
    renderer: Option<RenderEngine>,
    metrics: Option<MetricsWriter<R>>,
    collection: Vec<(f64, PathBuf)>,
    /// The frame written but not yet listed in `frames.pvd`.
    unlisted: Option<(f64, PathBuf)>,
    /// Every frame's row, in order.
    pub rows: Vec<R>,
}

impl<'a, R: MetricsRow + Copy> FrameOutputs<'a, R> {
    /// Acquires the engines and the renderer (the checks that can fail
    /// before the folder is touched), then clears an earlier run's files
    /// from the folder. The run writes its own rest files next, then calls
    /// [`FrameOutputs::start`].
    pub fn open(spec: OutputSpec<'a>, pieces: Vec<MapPiece<'a>>) -> Result<FrameOutputs<'a, R>> {
        refuse_inputs_in_outputs(spec.outputs)?;
        let mut engines = Vec::new();
        if let Some(micro) = spec.outputs.micro.as_ref() {
            for _ in &pieces {
                engines.push(MicroEngine::new(micro, spec.outputs.render.is_some())?);
            }
        }
        let dir = spec.outputs.dir.as_path();
        // The renderer first: a run refused for lack of a GPU creates no
        // folder.
        let renderer = match spec.outputs.render.as_ref() {
            Some(r) => Some(RenderEngine::new(
                dir,
                r,
                spec.outputs.micro.as_ref(),
                engines.first(),
                spec.extent_mm,
            )?),
            None => None,
        };
        export::outputs::create_output_dir(dir)?;
        // Then the previous run's files go, so the folder holds one run.
        clear_previous_run(dir)?;
        for (folder, wanted) in [
            ("frames", spec.outputs.write_frames),
            ("strain", spec.outputs.strain_images.is_some()),
        ] {
            if wanted {
                let path = dir.join(folder);
                std::fs::create_dir_all(&path).map_err(|e| Error::io(&path, e))?;
            }
        }
        Ok(FrameOutputs {
            spec,
            pieces,
            engines,
            renderer,
            metrics: None,
            collection: Vec::new(),
            unlisted: None,
            rows: Vec::new(),
        })
    }

    /// Writes the neutral microstructure and the header of `metrics.csv`.
    pub fn start(&mut self) -> Result<()> {
        if let Some(micro) = self.spec.outputs.micro.as_ref() {
            write_neutral(
                self.spec.outputs.dir.as_path(),
                self.spec.extent_mm.0,
                micro,
            )?;
        }
        let path = self.spec.outputs.dir.as_path().join("metrics.csv");
        self.metrics = Some(MetricsWriter::create(&path)?);
        Ok(())
    }

    /// Whether frames need their VTU grid.
    pub fn wants_grid(&self) -> bool {
        self.spec.outputs.write_frames
    }

    /// Writes one frame's files: VTU, strain images and microstructure per
    /// map, rendered frames. The frame's row follows with [`Self::row`].
    pub fn frame(&mut self, input: &FrameInput<'_>) -> Result<()> {
        let (dir, f) = (self.spec.outputs.dir.as_path(), input.frame);
        if let (true, Some(grid)) = (self.spec.outputs.write_frames, input.grid) {
            let path = export::write_frame(dir, f, grid, self.spec.outputs.vtu_format)?;
            // Listed in frames.pvd by `row`, once the frame is whole.
            self.unlisted = Some((input.time_s, path));
        }
        let mut fresh_normals = false;
        for (k, piece) in self.pieces.iter().enumerate() {
            let view;
            let field = match piece.triangles {
                None => input.field,
                Some(triangles) => {
                    view = input.field.view(triangles);
                    &view
                }
            };
            if let Some(images) = self.spec.outputs.strain_images {
                if images.previews {
                    let raster = StrainRaster::new(field, images.px, images.px);
                    export::strain_images::StrainImages::new(&raster, images.range)
                        .write_tagged(dir, &piece.tag, f)?;
                }
                if let Some([w, h]) = images.data {
                    let raster = StrainRaster::new(field, w, h);
                    export::strain_images::write_strain_data(&raster, dir, &piece.tag, f)?;
                }
            }
            if let (Some(micro), Some(engine)) =
                (self.spec.outputs.micro.as_ref(), self.engines.get_mut(k))
            {
                if f % micro.frame_stride == 0 {
                    engine.write_frame(micro, field, &dir.join("micro"), &piece.tag, f)?;
                    fresh_normals = micro.normal_maps;
                }
            }
        }
        if let (Some(r), Some(renderer)) =
            (self.spec.outputs.render.as_ref(), self.renderer.as_mut())
        {
            if f % r.frame_stride == 0 {
                let geometry = (input.geometry)(r.tessellate);
                renderer.frame(
                    &geometry,
                    input.field,
                    self.engines.first_mut(),
                    f,
                    fresh_normals,
                )?;
            }
        }
        Ok(())
    }

    /// Commits the frame: its row in `metrics.csv` (after its files and
    /// any other row of the run's), then its entry in `frames.pvd`
    /// (rewritten atomically, so a killed run's frames open in ParaView
    /// too). After a kill, a listed frame has every file and row.
    pub fn row(&mut self, row: R) -> Result<()> {
        self.metrics
            .as_mut()
            .expect("FrameOutputs::start opens metrics.csv before the frames")
            .push(&row)?;
        self.rows.push(row);
        if let Some(entry) = self.unlisted.take() {
            self.collection.push(entry);
            export::write_collection(self.spec.outputs.dir.as_path(), &self.collection)?;
        }
        Ok(())
    }

    /// After the last frame: the MP4 files encoded, and where the
    /// microstructure ran.
    pub fn finish(self) -> Result<Finished<R>> {
        if let (Some(r), Some(renderer)) = (self.spec.outputs.render.as_ref(), &self.renderer) {
            renderer.finish(r, self.spec.frame_rate_hz)?;
        }
        let micro_device = self
            .engines
            .first()
            .zip(self.spec.outputs.micro.as_ref())
            .map(|(e, m)| e.summary(m));
        Ok(Finished {
            rows: self.rows,
            micro_device,
        })
    }
}

/// Which kind of run a summary is of.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum RunKind {
    /// The FEM patch (`pipeline::run`).
    Fem,
    /// An animated surface (`pipeline::surface::run`).
    Surface,
}

/// What a run produced, for either kind of run: `R` is its row type
/// ([`crate::export::FrameMetrics`] or [`crate::export::SurfaceMetrics`]).
#[derive(Clone, Debug, serde::Serialize)]
pub struct RunSummary<R> {
    /// The kind of run.
    pub kind: RunKind,
    /// Every file the run wrote, sorted by path (see
    /// [`crate::export::outputs::run_files`]; `summary.json` follows).
    pub written: Vec<PathBuf>,
    /// Quality of the mesh (the FEM run; `None` for a surface).
    pub quality: Option<crate::mesh::QualityReport>,
    /// Metrics of every frame.
    pub frames: Vec<R>,
    /// Where the microstructure stages ran (`None` without microstructure).
    pub micro_device: Option<String>,
}

/// What the output stage wrote, for the run's summary.
pub(super) struct Finished<R> {
    /// Every frame's row.
    pub rows: Vec<R>,
    /// Where the microstructure stages ran.
    pub micro_device: Option<String>,
}

/// Refuses a run one of whose inputs is a file the run owns in its output
/// folder (`out/x/micro/height_0000.png` as the neutral map of a run
/// writing `out/x`, a scenario file named `metrics.csv` there): the run
/// clears and rewrites those, so the input would be lost. Files are
/// compared by device and inode, so links and symlinks count.
fn refuse_inputs_in_outputs(outputs: &OutputSetup) -> Result<()> {
    if outputs.dir.as_os_str().is_empty() {
        // An empty path is the working directory, whose files named like a
        // run's (metrics.csv, frames/, mesh.vtu) the run would clear.
        return Err(Error::parameter(
            "output.dir",
            "is empty; name the output folder (\".\" for the working directory)",
        ));
    }
    let owned = export::outputs::run_files(&outputs.dir);
    for (key, input) in &outputs.inputs {
        if let Some(out) = owned.iter().find(|o| export::outputs::same_file(o, input)) {
            return Err(Error::parameter(
                key.as_str(),
                format!(
                    "{} is a file the run writes in its output folder ({}): the run clears \
                     and rewrites it, and the input would be lost; move it out of the folder \
                     or choose another output.dir",
                    input.display(),
                    out.display()
                ),
            ));
        }
    }
    Ok(())
}

/// Removes an earlier run's files from the output folder (and says so).
fn clear_previous_run(dir: &Path) -> Result<()> {
    let cleared = export::outputs::clear_previous_run(dir)?;
    if cleared > 0 {
        log::info!(
            "removed {cleared} files of an earlier run from {}",
            dir.display()
        );
    }
    Ok(())
}
