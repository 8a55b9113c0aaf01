//! The microstructure room of a run: where the per-frame stages run (the
//! GPU chain, the chains of a tiled map, or the CPU references) and the
//! files they write under `micro/` — the neutral map with its normals and
//! roughness table, and each frame's deformed map.
//!
//! The GPU and CPU engines write the same files; the stages themselves live
//! in [`crate::micro`] (CPU references) and [`crate::gpu`].

use std::path::{Path, PathBuf};

use crate::error::{Error, Result};
use crate::gpu::tiled::TileFrame;
use crate::mesh::io;
use crate::micro::tiled::TiledMap;
use crate::micro::DisplacementMap;
use crate::scenario::{MicroSetup, NeutralMap};
use crate::strain::SurfaceField;

/// The GPU chain of a scenario's microstructure: its neutral map and kernel
/// model, the standard raster dilation, incremental frames when the
/// scenario asks for them.
pub fn gpu_chain(
    ctx: crate::gpu::Context,
    micro: &MicroSetup,
) -> Result<crate::gpu::micro::GpuMicro> {
    let mut chain = crate::gpu::micro::GpuMicro::new(
        ctx,
        micro.neutral.whole("the untiled GPU chain")?,
        &micro.model,
        crate::strain::raster::DILATE_TEXELS,
    )?;
    chain.set_incremental(micro.incremental_tolerance);
    chain.set_raster_step(micro.raster_step);
    Ok(chain)
}

/// Where the per-frame microstructure stages run.
pub(crate) enum MicroEngine {
    /// The GPU chain with the neutral map resident.
    Gpu(Box<crate::gpu::micro::GpuMicro>),
    /// The GPU chains of a tiled map, one per tile within the surface's reach.
    Tiled(Box<crate::gpu::tiled::TiledMicro>),
    /// The CPU references.
    Cpu,
}

impl MicroEngine {
    /// The GPU chain when an adapter is usable, else the CPU (an error
    /// instead when `SKINPATCH_REQUIRE_GPU=1`). A tiled map needs the GPU;
    /// so does a run that renders (`renders`: the renderer reads the
    /// chain's normals on the device). Otherwise a software adapter gives
    /// way to the faster CPU path ([`crate::gpu::worth_using`]).
    pub(crate) fn new(micro: &MicroSetup, renders: bool) -> Result<MicroEngine> {
        if let NeutralMap::Tiled(map) = &micro.neutral {
            let ctx = crate::gpu::acquire()?.ok_or_else(|| {
                Error::Gpu(format!(
                    "microstructure.map {} is a tiled map, which only the GPU chain \
                     convolves, and there is no usable GPU adapter",
                    map.dir.display()
                ))
            })?;
            let mut chains = crate::gpu::tiled::TiledMicro::new(
                ctx,
                map.clone(),
                &micro.model,
                crate::strain::raster::DILATE_TEXELS,
            );
            chains.set_incremental(micro.incremental_tolerance);
            chains.set_raster_step(micro.raster_step)?;
            return Ok(MicroEngine::Tiled(Box::new(chains)));
        }
        let Some(ctx) = crate::gpu::acquire()? else {
            return Ok(MicroEngine::Cpu);
        };
        let name = ctx.describe();
        if !renders && !crate::gpu::worth_using(&ctx) {
            log::info!(
                "microstructure stages on the CPU: {name} is a software adapter, slower than \
                 the CPU path (SKINPATCH_REQUIRE_GPU=1 uses it)"
            );
            return Ok(MicroEngine::Cpu);
        }
        let built = gpu_chain(ctx, micro);
        Ok(match crate::gpu::or_cpu(built)? {
            Some(chain) => {
                log::info!("microstructure stages on the GPU: {name}");
                MicroEngine::Gpu(Box::new(chain))
            }
            None => MicroEngine::Cpu,
        })
    }

    /// Where the stages ran and, for a coarse strain raster, its step (the
    /// run's report).
    pub(crate) fn summary(&self, micro: &MicroSetup) -> String {
        let mut text = self.describe();
        if micro.raster_step > 1 {
            text += &format!(
                "; strain raster: one texel per {0} × {0} map texels",
                micro.raster_step
            );
        }
        text
    }

    pub(crate) fn describe(&self) -> String {
        match self {
            MicroEngine::Gpu(chain) => {
                let mut text = format!("GPU: {}", chain.context().describe());
                if let Some(share) = chain.pass_tile_share() {
                    text += &format!(
                        "; convolution passes ran on {:.1}% of the map's tiles",
                        100.0 * share
                    );
                    if let Some(t) = chain.incremental() {
                        text += &format!(
                            " (incremental frames, tolerance {})",
                            crate::error::shown(t)
                        );
                    }
                }
                text
            }
            MicroEngine::Tiled(chains) => {
                let (cols, rows) = chains.source().grid();
                format!(
                    "GPU, tiled map of {cols} × {rows} tiles, {} within the surface's reach",
                    chains.active_tiles().len()
                )
            }
            MicroEngine::Cpu => "CPU reference stages".into(),
        }
    }

    /// Deforms the map for one frame and writes it under `folder`: a tiled
    /// map's frame as the tiled map `height_[TAG]NNNN.tiles`, otherwise
    /// `height_[TAG]NNNN.*` with its normals, checked for NaN first.
    pub(crate) fn write_frame(
        &mut self,
        micro: &MicroSetup,
        field: &SurfaceField,
        folder: &Path,
        tag: &str,
        frame: usize,
    ) -> Result<()> {
        let stage = format!("the microstructure ({})", self.describe());
        if let MicroEngine::Tiled(chains) = self {
            return write_tiled_frame(chains, micro, field, folder, tag, frame);
        }
        let (deformed, normals) = self.deform_whole(micro, field, micro.normal_maps)?;
        crate::error::check_finite(&stage, frame, deformed.width, 1, &deformed.data)?;
        if let Some(n) = &normals {
            crate::error::check_finite(
                &format!("{stage}, normals"),
                frame,
                deformed.width,
                3,
                n.iter().flatten(),
            )?;
        }
        write_micro_frame(
            folder,
            &format!("{tag}{frame:04}"),
            micro,
            &deformed,
            normals,
        )?;
        Ok(())
    }
}

impl MicroEngine {
    /// One frame's deformed map (and its normals when asked for) from an
    /// engine of a whole map.
    fn deform_whole(
        &mut self,
        micro: &MicroSetup,
        field: &SurfaceField,
        normals: bool,
    ) -> Result<(DisplacementMap, Option<Vec<[f32; 3]>>)> {
        Ok(match self {
            MicroEngine::Tiled(_) => {
                return Err(Error::parameter(
                    "microstructure.map",
                    "a tiled map is deformed tile by tile into files: run the scenario \
                     with its outputs to get its frames",
                ))
            }
            MicroEngine::Gpu(chain) => {
                let frame = chain.deform(field, normals)?;
                (frame.map, frame.normals)
            }
            MicroEngine::Cpu => (
                crate::micro::convolve::deform_stepped(
                    micro.neutral.whole("the CPU microstructure stages")?,
                    &micro.model,
                    field,
                    micro.raster_step,
                ),
                None,
            ),
        })
    }
}

/// A scenario's microstructure stages for callers that want each frame's
/// deformed map in memory rather than in files (the Python package's
/// `Frame.deformed_map`): the GPU chain when an adapter is usable, the CPU
/// references otherwise — the engine a run picks. A tiled map is refused:
/// its frames only exist as files.
pub struct MapDeformer {
    engine: MicroEngine,
}

impl MapDeformer {
    /// The engine for `micro` (its neutral map must be whole).
    pub fn new(micro: &MicroSetup) -> Result<MapDeformer> {
        if let NeutralMap::Tiled(map) = &micro.neutral {
            return Err(Error::parameter(
                "microstructure.map",
                format!(
                    "{} is a tiled map, deformed tile by tile into files: run the \
                     scenario with its outputs to get its frames",
                    map.dir.display()
                ),
            ));
        }
        Ok(MapDeformer {
            engine: MicroEngine::new(micro, false)?,
        })
    }

    /// Where the stages run (`GPU: <adapter>` or `CPU reference stages`).
    pub fn describe(&self) -> String {
        self.engine.describe()
    }

    /// The neutral map deformed by frame `frame`'s surface field, checked
    /// for NaN (an error names the frame); heights in the neutral map's
    /// units.
    pub fn deform(
        &mut self,
        micro: &MicroSetup,
        field: &SurfaceField,
        frame: usize,
    ) -> Result<DisplacementMap> {
        let stage = format!("the microstructure ({})", self.engine.describe());
        let (map, _) = self.engine.deform_whole(micro, field, false)?;
        crate::error::check_finite(&stage, frame, map.width, 1, &map.data)?;
        Ok(map)
    }
}

/// A frame of a tiled map written as the tiled map
/// `micro/height_[TAG]NNNN.tiles`: the tiles within the surface's reach
/// deformed (with their normals, checked for NaN), the others linked to the
/// neutral tiles.
fn write_tiled_frame(
    chains: &mut crate::gpu::tiled::TiledMicro,
    micro: &MicroSetup,
    field: &SurfaceField,
    folder: &Path,
    tag: &str,
    frame: usize,
) -> Result<()> {
    let neutral = TiledMap::open(&folder.join("height_neutral.tiles"))?;
    let out_dir = folder.join(format!("height_{tag}{frame:04}.tiles"));
    let out = TiledMap::create(
        &out_dir,
        &neutral.metadata(neutral.width, neutral.height),
        neutral.tile,
    )?;
    chains.deform(field, micro.normal_maps, |col, row, tile| match tile {
        TileFrame::Deformed { map, normals } => {
            let stage = format!("the microstructure (GPU, tiled map, tile ({col}, {row}))");
            crate::error::check_finite(&stage, frame, map.width, 1, &map.data)?;
            if let Some(n) = &normals {
                crate::error::check_finite(&stage, frame, map.width, 3, n.iter().flatten())?;
            }
            out.write_tile(col, row, &map, normals.as_deref())
        }
        TileFrame::Neutral => {
            link_or_copy(&neutral.tile_path(col, row), &out.tile_path(col, row))?;
            if micro.normal_maps {
                link_or_copy(&neutral.normal_path(col, row), &out.normal_path(col, row))?;
            }
            Ok(())
        }
    })?;
    Ok(())
}

/// `dst` as a hard link to `src` (no space taken), or a copy where the
/// file system has no links. An existing `dst` is removed first: copying
/// onto a link to `src` would truncate `src` itself.
fn link_or_copy(src: &Path, dst: &Path) -> Result<()> {
    match std::fs::remove_file(dst) {
        Err(e) if e.kind() != std::io::ErrorKind::NotFound => return Err(Error::io(dst, e)),
        _ => {}
    }
    if std::fs::hard_link(src, dst).is_ok() {
        return Ok(());
    }
    std::fs::copy(src, dst).map_err(|e| Error::io(dst, e))?;
    Ok(())
}

/// Writes the neutral map (and its normals) under `micro/`; warns when the
/// map's texel size disagrees with the patch it is stretched over.
pub(crate) fn write_neutral(dir: &Path, patch_width_mm: f64, micro: &MicroSetup) -> Result<()> {
    let folder = dir.join("micro");
    std::fs::create_dir_all(&folder).map_err(|e| Error::io(&folder, e))?;
    let map = match &micro.neutral {
        NeutralMap::Whole(map) => map,
        NeutralMap::Tiled(tiled) => return write_neutral_tiles(&folder, micro, tiled),
    };
    let patch_texel_um = patch_width_mm * 1000.0 / map.width as f64;
    if (map.texel_um / patch_texel_um - 1.0).abs() > 0.01 {
        log::warn!(
            "the microstructure map has {:.3} µm texels but spans the {:.1} mm patch at {:.3} µm per texel; \
             kernel widths follow the patch",
            map.texel_um,
            patch_width_mm,
            patch_texel_um
        );
    }
    write_micro_frame(&folder, "neutral", micro, map, None)?;
    if micro.roughness_table {
        let ratios: Vec<f64> = (0..=14).map(|k| 0.7 + 0.05 * k as f64).collect();
        let table = crate::micro::roughness::tabulate(map, &micro.model, &ratios);
        let mut csv = String::from("stretch_ratio,beckmann_m\n");
        for (r, m) in &table.points {
            csv.push_str(&format!("{r:.2},{m:e}\n"));
        }
        let path = folder.join("roughness.csv");
        io::write_atomically(&path, csv.as_bytes())?;
    }
    Ok(())
}

/// The neutral tiled map as `micro/height_neutral.tiles`: its tiles linked
/// (or copied) from the input and, when asked, each tile's normals (from the
/// tile and the one-texel ring of its neighbours around it, so they equal
/// the whole map's).
fn write_neutral_tiles(folder: &Path, micro: &MicroSetup, tiled: &TiledMap) -> Result<()> {
    let dir = folder.join("height_neutral.tiles");
    let out = TiledMap::create(&dir, &tiled.metadata(tiled.width, tiled.height), tiled.tile)?;
    let (cols, rows) = tiled.grid();
    for row in 0..rows {
        for col in 0..cols {
            link_or_copy(&tiled.tile_path(col, row), &out.tile_path(col, row))?;
            if micro.normal_maps {
                let [x0, y0, w, h] = tiled.tile_rect(col, row);
                let ring = tiled.read_window([x0 as isize - 1, y0 as isize - 1], [w + 2, h + 2])?;
                let normals = crate::micro::normals::normal_map(&ring);
                let inner = crate::micro::tiled::crop_values(&normals, w + 2, [1, 1, w, h]);
                let meta = tiled.metadata(w, h);
                crate::micro::io::write_normal_exr(&out.normal_path(col, row), &inner, &meta)?;
            }
        }
    }
    Ok(())
}

/// Writes a map as `height_TAG.{png,exr}` and, when asked, its normals as
/// `normal_TAG.{png,exr}` (`normals` if already computed, else from the map).
pub(crate) fn write_micro_frame(
    folder: &Path,
    tag: &str,
    micro: &MicroSetup,
    map: &DisplacementMap,
    normals: Option<Vec<[f32; 3]>>,
) -> Result<Vec<PathBuf>> {
    use crate::micro::io;
    let mut written = Vec::new();
    if micro.png16 {
        let path = folder.join(format!("height_{tag}.png"));
        let clipped = io::write_png16_in(&path, map, micro.png_range)?;
        if clipped > 0 {
            let [lo, hi] = micro
                .png_range
                .unwrap_or_default()
                .map(|h| h * map.height_unit_um);
            log::warn!(
                "{}: {clipped} texels ({:.3} %) lie outside the run's PNG height range \
                 [{lo:.2}, {hi:.2}] µm and were clipped; widen [microstructure] height_range_um \
                 (or read the .exr maps, which are not clipped)",
                path.display(),
                100.0 * clipped as f64 / map.data.len() as f64
            );
        }
        written.push(path);
    }
    if micro.exr {
        let path = folder.join(format!("height_{tag}.exr"));
        io::write_exr(&path, map)?;
        written.push(path);
    }
    if micro.normal_maps {
        let path = folder.join(format!("normal_{tag}.png"));
        let normals = normals.unwrap_or_else(|| crate::micro::normals::normal_map(map));
        io::write_normal_png16(&path, &normals, map)?;
        written.push(path);
        if micro.exr {
            let path = folder.join(format!("normal_{tag}.exr"));
            io::write_normal_exr(&path, &normals, map)?;
            written.push(path);
        }
    }
    Ok(written)
}
