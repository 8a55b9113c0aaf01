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

use std::time::Instant;

use crate::error::Result;
use crate::gpu::micro::{GpuMicro, StageTimes};
use crate::mesh::{TetMesh, Vec3};
use crate::micro::procedural::{generate, SkinParams};
use crate::micro::{DisplacementMap, Edge, KernelModel};
use crate::strain::raster::DILATE_TEXELS;
use crate::strain::SurfaceField;

/// Figures at one map size.
#[derive(Clone, Debug, PartialEq)]
pub struct MicroRow {
    /// Map side (texels).
    pub size: usize,
    /// CPU reference frame (ms).
    pub cpu_ms: f64,
    /// GPU frame without read-back, mean over the repetitions (ms).
    pub gpu_ms: Option<f64>,
    /// GPU frame with read-back of D′ and normals (ms).
    pub gpu_readback_ms: Option<f64>,
    /// Largest |GPU − CPU| of D′ relative to the height range.
    pub max_difference: Option<f64>,
    /// Each stage of a GPU frame submitted alone and waited for: wall
    /// time and, where the adapter has timestamp queries, GPU time (ms).
    pub stages: Option<StageTimes>,
}

/// What the bench ran on.
#[derive(Clone, Debug)]
pub struct MicroBench {
    /// The GPU adapter, if any.
    pub adapter: Option<String>,
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

/// Runs the bench over `sizes` with `repetitions` timed GPU frames each;
/// `on_row` sees each row as it is done.
pub fn bench_micro(
    mesh: &TetMesh,
    model: &KernelModel,
    sizes: &[usize],
    repetitions: usize,
    mut on_row: impl FnMut(&MicroRow),
) -> Result<MicroBench> {
    let field = SurfaceField::new(&mesh.top, &mesh.positions, &bench_deformation(mesh));
    let (lo, hi) = mesh.bounds();
    let mut ctx = crate::gpu::acquire()?;
    let adapter = ctx.as_ref().map(|c| c.describe());
    let mut rows = Vec::new();
    for &size in sizes {
        let neutral = bench_map(size, hi.x - lo.x)?;
        let start = Instant::now();
        let cpu = crate::micro::convolve::deform(&neutral, model, &field);
        let cpu_normals = crate::micro::normals::normal_map(&cpu);
        let cpu_ms = start.elapsed().as_secs_f64() * 1e3;
        drop(cpu_normals);
        let mut row = MicroRow {
            size,
            cpu_ms,
            gpu_ms: None,
            gpu_readback_ms: None,
            max_difference: None,
            stages: None,
        };
        if let Some(c) = ctx.take() {
            let mut chain = GpuMicro::new(c, &neutral, model, DILATE_TEXELS)?;
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
            row.max_difference = Some(cpu.max_difference(&frame.map));
            row.stages = Some(chain.time_stages(&field)?);
            ctx = Some(chain.into_context());
        }
        on_row(&row);
        rows.push(row);
    }
    Ok(MicroBench { adapter, rows })
}
