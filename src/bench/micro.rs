//! `skinpatch bench micro`: the per-frame microstructure stages on the GPU
//! and on their CPU references, in one run, at several map sizes.
//!
//! The surface is the scenario's mesh under a fixed smooth deformation
//! (stretch, compression, shear and a dimple, so every texel gets a
//! non-trivial kernel); the neutral map is a generated skin tile repeated
//! to the size, spanning the patch. One frame is raster → SVD and kernel
//! parameters → pass along s → pass along t → normals (on the GPU the SVD
//! runs inside each pass). The GPU time covers the upload of the vertex
//! data, the four dispatches and the wait for them;
//! read-back of D′ and the normals is timed separately. The CPU reference
//! runs once per size (it takes seconds at 4096²).
//!
//! Two layouts of the map ([`MapLayout`]): the fixed patch (the map spans
//! the patch, so its texels shrink as the size grows and the kernels widen
//! in texels) and the fixed texel (a real user's case: the texel stays at
//! the measurement resolution, e.g. 10 µm, and the map covers a growing
//! area with the patch's strain field mapped onto its centre; outside it
//! the skin is at rest).

use std::time::Instant;

use crate::error::{Error, Result};
use crate::gpu::micro::{GpuMicro, StageTimes};
use crate::mesh::{TetMesh, Vec3};
use crate::micro::procedural::{generate, SkinParams};
use crate::micro::{DisplacementMap, Edge, KernelModel};
use crate::strain::raster::DILATE_TEXELS;
use crate::strain::SurfaceField;

/// How the bench's map relates to the patch.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum MapLayout {
    /// The map spans the patch at every size.
    FixedPatch,
    /// Texels of `texel_um`; the map spans `size × texel_um` with the
    /// patch at its centre. The CPU reference runs up to `cpu_up_to`
    /// texels a side (it takes minutes beyond a few thousand).
    FixedTexel {
        /// Texel size (µm).
        texel_um: f64,
        /// Largest side the CPU reference runs at.
        cpu_up_to: usize,
        /// Also hold the map as tiles of this side and convolve it tile by
        /// tile ([`crate::gpu::tiled::TiledMicro`]).
        tile: Option<usize>,
    },
}

/// Figures of the tiled chain at one size.
#[derive(Clone, Debug, PartialEq)]
pub struct TiledRow {
    /// Tile side (texels).
    pub tile: usize,
    /// Tiles with a chain (within the surface's reach).
    pub active: usize,
    /// Tiles in the map.
    pub total: usize,
    /// Halo around each tile (texels).
    pub halo: usize,
    /// Frame over every chain, no read-back, mean over the repetitions (ms).
    pub gpu_ms: f64,
    /// Largest |tiled − untiled| of D′ relative to the height range, where
    /// the untiled chain ran.
    pub max_difference: Option<f64>,
}

/// Figures at one map size.
#[derive(Clone, Debug, PartialEq)]
pub struct MicroRow {
    /// Map side (texels).
    pub size: usize,
    /// Texel size (µm).
    pub texel_um: f64,
    /// CPU reference frame (ms), where it ran.
    pub cpu_ms: Option<f64>,
    /// GPU frame without read-back, mean over the repetitions (ms).
    pub gpu_ms: Option<f64>,
    /// GPU frame with read-back of D′ and normals (ms).
    pub gpu_readback_ms: Option<f64>,
    /// Largest |GPU − CPU| of D′ relative to the height range.
    pub max_difference: Option<f64>,
    /// Share of the map's tiles the GPU passes ran on (the rest lies
    /// beyond the surface's reach and keeps the neutral map).
    pub pass_tile_share: Option<f64>,
    /// Each stage of a GPU frame submitted alone and waited for: wall
    /// time and, where the adapter has timestamp queries, GPU time (ms).
    pub stages: Option<StageTimes>,
    /// The map held as tiles, where asked for.
    pub tiled: Option<TiledRow>,
    /// Why the untiled GPU chain did not run (the map exceeds the
    /// adapter's limits), where it did not.
    pub untiled_skipped: Option<String>,
}

/// What the bench ran on.
#[derive(Clone, Debug)]
pub struct MicroBench {
    /// The GPU adapter, if any.
    pub adapter: Option<String>,
    /// The adapter's peak memory bandwidth (GB/s) where
    /// [`peak_bandwidth_gbs`] knows it.
    pub peak_bandwidth_gbs: Option<f64>,
    /// One row per size.
    pub rows: Vec<MicroRow>,
}

/// The fixed deformation applied to the rest positions.
pub fn bench_deformation(mesh: &TetMesh) -> Vec<Vec3> {
    let (lo, hi) = mesh.bounds();
    let scale = 10.0 / (hi.x - lo.x).max(1e-9);
    mesh.positions
        .iter()
        .map(|p| {
            let (x, y) = ((p.x - lo.x) * scale - 5.0, (p.y - lo.y) * scale - 5.0);
            p + Vec3::new(
                (0.08 * x + 0.35 * (0.6 * x).sin() + 0.05 * y) / scale,
                (-0.06 * y + 0.2 * (0.5 * x + 0.3 * y).cos()) / scale,
                0.3 * (-(x * x + y * y) / 4.0).exp() / scale,
            )
        })
        .collect()
}

/// A generated 256² skin tile repeated to `size²`, spanning `extent_mm`.
pub fn bench_map(size: usize, extent_mm: f64) -> Result<DisplacementMap> {
    let tile = generate(&SkinParams {
        size_px: 256,
        extent_mm: 1.28,
        seed: 5,
        groove_spacing_um: 150.0,
        ..SkinParams::default()
    })?;
    let mut map = DisplacementMap::from_fn(
        size,
        size,
        extent_mm * 1000.0 / size as f64,
        Edge::Wrap,
        |i, j| tile.data[(j % 256) * 256 + i % 256],
    );
    map.height_unit_um = tile.height_unit_um;
    Ok(map)
}

/// Largest map side `bench micro` runs (texels).
pub const MAX_BENCH_SIDE: usize = 65536;

/// Bytes a texel of a benchmarked map takes in host memory at least: the
/// neutral and deformed heights, the normals and the CPU reference's
/// copies (f32 each).
const BYTES_PER_TEXEL: u64 = 32;

/// Every side in 1 ..= [`MAX_BENCH_SIDE`] and within the memory available.
fn check_sizes(sizes: &[usize]) -> Result<()> {
    if sizes.is_empty() {
        return Err(Error::parameter("--sizes", "names no map side"));
    }
    for &size in sizes {
        if size == 0 || size > MAX_BENCH_SIDE {
            return Err(Error::parameter(
                "--sizes",
                format!("{size} texels: each side must be in 1 … {MAX_BENCH_SIDE}"),
            ));
        }
        let needed = (size as u64).pow(2) * BYTES_PER_TEXEL;
        if let Some((needed, have)) = crate::memory::shortfall_gb(needed) {
            return Err(Error::parameter(
                "--sizes",
                format!(
                    "a map of {size}² texels needs about {needed:.1} GB, {have:.1} GB are \
                     available"
                ),
            ));
        }
    }
    Ok(())
}

/// Runs the bench over `sizes` with `repetitions` timed GPU frames each,
/// the strain rasterised at one texel per `raster_step²` map texels (1: the
/// exact raster; see [`GpuMicro::set_raster_step`]), GPU and CPU alike;
/// `on_row` sees each row as it is done.
pub fn bench_micro(
    mesh: &TetMesh,
    model: &KernelModel,
    sizes: &[usize],
    repetitions: usize,
    (layout, raster_step): (MapLayout, usize),
    mut on_row: impl FnMut(&MicroRow),
) -> Result<MicroBench> {
    check_sizes(sizes)?;
    let deformed = bench_deformation(mesh);
    let (lo, hi) = mesh.bounds();
    let patch_mm = hi.x - lo.x;
    let mut ctx = crate::gpu::acquire()?;
    let adapter = ctx.as_ref().map(|c| c.describe());
    let peak_bandwidth_gbs = ctx.as_ref().and_then(|c| peak_bandwidth_gbs(&c.info.name));
    let mut rows = Vec::new();
    for &size in sizes {
        let (extent_mm, run_cpu) = match layout {
            MapLayout::FixedPatch => (patch_mm, true),
            MapLayout::FixedTexel {
                texel_um,
                cpu_up_to,
                ..
            } => (size as f64 * texel_um / 1000.0, size <= cpu_up_to),
        };
        let tile = match layout {
            MapLayout::FixedTexel { tile, .. } => tile,
            MapLayout::FixedPatch => None,
        };
        let field = centred_field(mesh, &deformed, patch_mm / extent_mm)?;
        let neutral = bench_map(size, extent_mm)?;
        let mut cpu = None;
        let mut cpu_ms = None;
        if run_cpu {
            let start = Instant::now();
            let map = crate::micro::convolve::deform_stepped(&neutral, model, &field, raster_step);
            let normals = crate::micro::normals::normal_map(&map);
            cpu_ms = Some(start.elapsed().as_secs_f64() * 1e3);
            drop(normals);
            cpu = Some(map);
        }
        let mut row = MicroRow {
            size,
            texel_um: neutral.texel_um,
            cpu_ms,
            gpu_ms: None,
            gpu_readback_ms: None,
            max_difference: None,
            pass_tile_share: None,
            stages: None,
            tiled: None,
            untiled_skipped: None,
        };
        let mut untiled = None;
        let fits = ctx
            .as_ref()
            .map(|c| c.check_map(size, size, crate::gpu::micro::LARGEST_BYTES_PER_TEXEL));
        if let (Some(Err(e)), Some(_)) = (&fits, tile) {
            // The tiled chain is the one that can run this size.
            row.untiled_skipped = Some(e.to_string());
        } else if let Some(c) = ctx.take() {
            let mut chain = GpuMicro::new(c, &neutral, model, DILATE_TEXELS)?;
            chain.set_raster_step(raster_step);
            chain.run(&field)?; // warm-up: first use of the pipelines
            let start = Instant::now();
            for _ in 0..repetitions.max(1) {
                chain.run(&field)?;
            }
            row.gpu_ms = Some(start.elapsed().as_secs_f64() * 1e3 / repetitions.max(1) as f64);
            // Normals are read back only where one buffer can hold them
            // (16 B a texel: 4 GiB at 16384², over most drivers' limit).
            let normals = (size * size * 16) as u64 <= chain.context().limits.max_buffer_size;
            let start = Instant::now();
            let frame = chain.deform(&field, normals)?;
            row.gpu_readback_ms = Some(start.elapsed().as_secs_f64() * 1e3);
            row.max_difference = cpu.as_ref().map(|c| c.max_difference(&frame.map));
            let tiles = chain.last_tiles();
            row.pass_tile_share =
                Some((tiles.pass_s + tiles.pass_t) as f64 / (2 * tiles.total) as f64);
            row.stages = Some(chain.time_stages(&field)?);
            untiled = Some(frame.map);
            ctx = Some(chain.into_context());
        }
        if let (Some(tile), Some(c)) = (tile, &ctx) {
            row.tiled = Some(bench_tiled(
                c,
                &neutral,
                model,
                &field,
                (tile, raster_step),
                repetitions,
                untiled.as_ref(),
            )?);
        }
        on_row(&row);
        rows.push(row);
    }
    Ok(MicroBench {
        adapter,
        peak_bandwidth_gbs,
        rows,
    })
}

/// Published peak memory bandwidth (GB/s) of the GPUs the targets are set
/// on and a few common ones, by the adapter name the Vulkan driver reports
/// (e.g. `NVIDIA H100 80GB HBM3`); `None` for others (software adapters
/// included), where `bench micro --bandwidth-gbs` gives it.
pub fn peak_bandwidth_gbs(adapter_name: &str) -> Option<f64> {
    let name = adapter_name.to_ascii_uppercase();
    let has = |part: &str| name.contains(part);
    let gbs = if has("H200") {
        4800.0
    } else if has("H100") && has("PCIE") {
        2000.0
    } else if has("H100") && has("NVL") {
        3900.0
    } else if has("H100") {
        3350.0
    } else if has("A100") && has("80GB") && has("PCIE") {
        1935.0
    } else if has("A100") && has("80GB") {
        2039.0
    } else if has("A100") {
        1555.0
    } else if has("L40") {
        864.0
    } else if has("RTX 4090") {
        1008.0
    } else if has("RTX 3090") {
        936.0
    } else if has("V100") {
        900.0
    } else {
        return None;
    };
    Some(gbs)
}

/// The tiled chain over `neutral` held as tiles of `tile` texels (in a
/// scratch folder, removed after), timed like the untiled one and compared
/// with its output `untiled` where given.
fn bench_tiled(
    ctx: &crate::gpu::Context,
    neutral: &DisplacementMap,
    model: &KernelModel,
    field: &SurfaceField,
    (tile, raster_step): (usize, usize),
    repetitions: usize,
    untiled: Option<&DisplacementMap>,
) -> Result<TiledRow> {
    use crate::gpu::tiled::{TileFrame, TiledMicro};
    use crate::micro::tiled::{crop, TiledMap};
    let dir = std::env::temp_dir().join(format!("skinpatch-bench-tiles-{}", std::process::id()));
    let result = (|| {
        let tiled = TiledMap::write(&dir, neutral, tile)?;
        let (cols, rows) = tiled.grid();
        let mut chains = TiledMicro::new(ctx.clone(), tiled.clone(), model, DILATE_TEXELS);
        chains.set_raster_step(raster_step)?;
        chains.run(field)?; // builds the chains; first use of the pipelines
        let start = Instant::now();
        for _ in 0..repetitions.max(1) {
            chains.run(field)?;
        }
        let gpu_ms = start.elapsed().as_secs_f64() * 1e3 / repetitions.max(1) as f64;
        let mut max_difference = None;
        if let Some(reference) = untiled {
            let (lo, hi) = neutral.range();
            let mut worst = 0.0f32;
            chains.deform(field, false, |col, row, frame| {
                let rect = tiled.tile_rect(col, row);
                let got = match frame {
                    TileFrame::Deformed { map, .. } => map,
                    TileFrame::Neutral => crop(neutral, rect),
                };
                for (a, b) in got.data.iter().zip(&crop(reference, rect).data) {
                    worst = worst.max((a - b).abs());
                }
                Ok(())
            })?;
            max_difference = Some(f64::from(worst) / f64::from(hi - lo));
        }
        Ok(TiledRow {
            tile,
            active: chains.active_tiles().len(),
            total: cols * rows,
            halo: chains.halo(),
            gpu_ms,
            max_difference,
        })
    })();
    // Best effort: the scratch tiles are no output of the bench.
    let _ = std::fs::remove_dir_all(&dir);
    result
}

/// The field of `mesh` deformed to `deformed` with its UVs shrunk by
/// `scale` (≤ 1) about the centre of the map: the patch on the centre of a
/// larger map.
fn centred_field(mesh: &TetMesh, deformed: &[Vec3], scale: f64) -> Result<SurfaceField> {
    if !(scale.is_finite() && scale > 0.0 && scale <= 1.0 + 1e-12) {
        return Err(crate::error::Error::parameter(
            "bench micro --texel-um",
            format!(
                "the map must be at least as large as the patch: at this texel size it is {:.3} of \
                 the patch's width; use larger sizes or a larger texel",
                1.0 / scale
            ),
        ));
    }
    if scale == 1.0 {
        return Ok(SurfaceField::new(&mesh.top, &mesh.positions, deformed));
    }
    let mut top = mesh.top.clone();
    for uv in &mut top.uvs {
        *uv = uv.map(|c| 0.5 + (c - 0.5) * scale);
    }
    Ok(SurfaceField::new(&top, &mesh.positions, deformed))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn peak_bandwidths_by_adapter_name() {
        assert_eq!(peak_bandwidth_gbs("NVIDIA H100 80GB HBM3"), Some(3350.0));
        assert_eq!(peak_bandwidth_gbs("NVIDIA H100 PCIe"), Some(2000.0));
        assert_eq!(peak_bandwidth_gbs("NVIDIA H200"), Some(4800.0));
        assert_eq!(peak_bandwidth_gbs("NVIDIA A100-SXM4-80GB"), Some(2039.0));
        assert_eq!(peak_bandwidth_gbs("NVIDIA A100-PCIE-40GB"), Some(1555.0));
        assert_eq!(peak_bandwidth_gbs("llvmpipe (LLVM 19.1.7, 256 bits)"), None);
    }

    #[test]
    fn a_centred_field_has_the_same_strain_and_leaves_the_rest_of_the_map_at_rest() {
        let mesh =
            crate::mesh::io::read_mesh(std::path::Path::new("meshes/patch_3k.node")).unwrap();
        let deformed = bench_deformation(&mesh);
        let plain = SurfaceField::new(&mesh.top, &mesh.positions, &deformed);
        let centred = centred_field(&mesh, &deformed, 0.5).unwrap();
        // Shrinking the UVs does not change the stretch ratios.
        let (a, b) = (plain.extremes(), centred.extremes());
        assert!((a.0 .0 - b.0 .0).abs() < 1e-12 && (a.0 .1 - b.0 .1).abs() < 1e-12);
        assert!((a.1 .0 - b.1 .0).abs() < 1e-12 && (a.1 .1 - b.1 .1).abs() < 1e-12);
        // Outside the centre half (and its dilation) the map is unchanged.
        let (lo, hi) = mesh.bounds();
        let neutral = bench_map(128, 2.0 * (hi.x - lo.x)).unwrap();
        let out = crate::micro::convolve::deform(&neutral, &KernelModel::forehead(), &centred);
        for j in 0..128 {
            for i in 0..128 {
                let border = !(24..104).contains(&i) || !(24..104).contains(&j);
                if border {
                    let k = j * 128 + i;
                    assert_eq!(out.data[k], neutral.data[k], "texel ({i}, {j})");
                }
            }
        }
        assert!(centred_field(&mesh, &deformed, 1.5).is_err());
    }
}
