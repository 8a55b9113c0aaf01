//! `skinpatch bench`: `fem`, `micro` and `render` figures, each printed as a
//! table, and `gpu`, every GPU figure in one report (the measurements are
//! the library's `skinpatch::bench`).

use std::path::{Path, PathBuf};

use anyhow::{bail, Context};
use clap::{Args, Subcommand};
use skinpatch::scenario::Setup;

use super::print_stdout;

/// The stage to benchmark.
#[derive(Subcommand)]
pub enum BenchCommand {
    /// Time the FEM frames with each linear solver.
    ///
    /// Simulates the first frames of a scenario (default the press-and-drag
    /// example) with each linear solver in one run and prints frames/s,
    /// iterations, the time split and the ratio between solvers.
    Fem(FemArgs),
    /// Time one microstructure frame on the GPU and on the CPU references.
    ///
    /// Runs one microstructure frame (raster, SVD, two convolution passes,
    /// normals) on the GPU and on the CPU references at each map size, on
    /// the scenario's mesh under a fixed deformation, and prints both times,
    /// their ratio and the largest difference; then per stage its time, the
    /// bytes it must move and the GB/s achieved, and the frame against the
    /// GPU's peak bandwidth where known.
    Micro(MicroArgs),
    /// Time the whole frame: FEM step, microstructure, geometry, render.
    ///
    /// Simulates the first frames of the scenario and times per frame the
    /// FEM step, the microstructure chain, the geometry and the render at
    /// `--width × --height` (dynamic mode), and prints frames per second for
    /// rendering alone and for the whole frame.
    Render(RenderArgs),
    /// Every GPU figure in one run, written as a JSON report and Markdown.
    ///
    /// Records the adapters (as `gpu-info`), the microstructure chain at
    /// fixed 10 µm texels from 1024² to 16384² (tiles where one binding
    /// cannot hold the map) for strain-raster steps 1, 2 and 4, per stage
    /// with bytes and GB/s and with the CPU reference's parity up to 2048²;
    /// the renderer at 1920 × 1080 with and without the moment filter and
    /// MSAA; the whole frame (FEM, chain, geometry, render) of the
    /// scenario's first frames; the GPU fit counter against the CPU one;
    /// and the viewer's render loop without a window (10 s at 1920 × 1080,
    /// the probe's path played while the FEM thread solves). `--quick`
    /// sizes everything for a software adapter.
    Gpu(GpuArgs),
}

/// `bench gpu`.
#[derive(Args)]
pub struct GpuArgs {
    /// Scenario (its mesh, kernel model, render settings and first frames)
    /// [default: examples/press.toml of the working directory or of the
    /// source tree this binary was built from].
    #[arg(long)]
    scenario: Option<PathBuf>,
    /// Small sizes for a software adapter (CI): the same parts, in a few
    /// minutes on lavapipe (about 3 on 2 cores).
    #[arg(long)]
    quick: bool,
    /// The JSON report; the Markdown is written beside it (`.md`).
    #[arg(long, value_name = "FILE", default_value = "gpu-report.json")]
    report: PathBuf,
}

/// Options every stage takes.
#[derive(Args)]
pub struct Common {
    /// Scenario (its mesh and, for `micro`, its kernel model) [default:
    /// examples/press.toml of the working directory or of the source tree
    /// this binary was built from].
    #[arg(long)]
    scenario: Option<PathBuf>,
    /// Frames to simulate (`fem`, `render`) or timed GPU frames per size
    /// (`micro`).
    #[arg(long, default_value_t = 10)]
    frames: usize,
}

/// `bench fem`.
#[derive(Args)]
pub struct FemArgs {
    #[command(flatten)]
    common: Common,
}

/// `bench micro`.
#[derive(Args)]
pub struct MicroArgs {
    #[command(flatten)]
    common: Common,
    /// Map sides (texels).
    #[arg(long, value_delimiter = ',', default_value = "1024,2048,4096")]
    sizes: Vec<usize>,
    /// Fixed texels of this size (µm, e.g. 10): the map covers size × texel
    /// with the patch's strain on its centre, instead of spanning the patch
    /// at every size.
    #[arg(long, value_name = "UM")]
    texel_um: Option<f64>,
    /// With --texel-um, the largest side the CPU reference runs at.
    #[arg(long, default_value_t = 2048)]
    cpu_up_to: usize,
    /// With --texel-um, also hold the map as tiles of this side and
    /// convolve it tile by tile (maps beyond one GPU binding run only this
    /// way).
    #[arg(long, value_name = "TEXELS")]
    tile: Option<usize>,
    /// The GPU's peak memory bandwidth (GB/s) the per-stage traffic is
    /// compared with, for adapters the bench does not know by name.
    #[arg(long, value_name = "GBS")]
    bandwidth_gbs: Option<f64>,
    /// Map texels per strain-raster texel along each side (as
    /// `[microstructure] strain_raster_step`; 1 is the exact raster).
    #[arg(long, default_value_t = 1, value_name = "N")]
    raster_step: usize,
}

/// `bench render`.
#[derive(Args)]
pub struct RenderArgs {
    #[command(flatten)]
    common: Common,
    /// Image width (px).
    #[arg(long, default_value_t = 1920)]
    width: usize,
    /// Image height (px).
    #[arg(long, default_value_t = 1080)]
    height: usize,
}

/// Runs one stage's benchmark and prints its figures.
pub fn run(command: BenchCommand) -> anyhow::Result<()> {
    match command {
        BenchCommand::Fem(a) => bench_fem(&scenario_path(&a.common.scenario)?, a.common.frames),
        BenchCommand::Micro(a) => bench_micro(
            &scenario_path(&a.common.scenario)?,
            a.common.frames,
            &a.sizes,
            (a.texel_um, a.cpu_up_to, a.tile),
            (a.bandwidth_gbs, a.raster_step),
        ),
        BenchCommand::Render(a) => bench_render(
            &scenario_path(&a.common.scenario)?,
            a.common.frames,
            a.width,
            a.height,
        ),
        BenchCommand::Gpu(a) => bench_gpu(&a),
    }
}

/// The scenario a benchmark runs: the one given, else the press example,
/// looked for in the working directory and then in the source tree the
/// binary was built from (so that `bench` runs from any folder on the
/// machine that built it).
fn scenario_path(given: &Option<PathBuf>) -> anyhow::Result<PathBuf> {
    if let Some(path) = given {
        return Ok(path.clone());
    }
    let relative = Path::new("examples/press.toml");
    let built_from = Path::new(env!("CARGO_MANIFEST_DIR")).join(relative);
    for candidate in [relative.to_path_buf(), built_from.clone()] {
        if candidate.is_file() {
            return Ok(candidate);
        }
    }
    bail!(
        "no --scenario given, and the default {} is neither in the working directory nor at {}; \
         pass --scenario FILE (examples/press.toml of the repository, or any scenario)",
        relative.display(),
        built_from.display()
    )
}

/// `bench gpu`: the report, then its Markdown on stdout.
fn bench_gpu(args: &GpuArgs) -> anyhow::Result<()> {
    use skinpatch::bench::gpu::{bench_gpu, write_report, GpuBenchSizes};
    let path = &scenario_path(&args.scenario)?;
    let setup = Setup::load(path).with_context(|| format!("scenario {}", path.display()))?;
    let sizes = if args.quick {
        GpuBenchSizes::quick()
    } else {
        GpuBenchSizes::full()
    };
    let start = std::time::Instant::now();
    let progress = |part: &str| eprintln!("[{:7.1} s] {part}", start.elapsed().as_secs_f64());
    #[allow(unused_mut)]
    let mut report = bench_gpu(&setup, &sizes, progress)?;
    // The viewer is a layer above the benchmarks: its loop is run here.
    #[cfg(feature = "viewer")]
    {
        let (w, h) = sizes.image;
        progress(&format!(
            "viewer loop offscreen, {w} × {h} px, {} s",
            sizes.viewer_s
        ));
        let figures = skinpatch::viewer::offscreen::bench_loop(
            &setup,
            sizes.image,
            sizes.viewer_s,
            sizes.texture_px,
        )
        .context("the viewer's loop")?;
        report.viewer = Some(figures);
    }
    let md = write_report(&report, &args.report)?;
    print_stdout(&format!(
        "{}\nwritten: {} and {} ({:.1} s)\n",
        report.markdown(),
        args.report.display(),
        md.display(),
        start.elapsed().as_secs_f64()
    ))
}

/// `bench fem`: the first frames with each linear solver, in one run.
fn bench_fem(path: &Path, frames: usize) -> anyhow::Result<()> {
    use skinpatch::fem::simulation::LinearSolver;
    let mut setup = Setup::load(path).with_context(|| format!("scenario {}", path.display()))?;
    let mut report = format!(
        "bench fem: {} ({} tets), first {} frames\n\
         {:<9} {:>9} {:>9} {:>8} {:>10} {:>9} {:>9} {:>9} {:>9} {:>9}\n",
        path.display(),
        setup.mesh.num_tets(),
        frames,
        "solver",
        "frames/s",
        "wall s",
        "Newton",
        "linear it",
        "forces s",
        "assemb s",
        "linear s",
        "factor s",
        "other s"
    );
    let mut walls = Vec::new();
    for (name, solver) in [
        ("cg", LinearSolver::Cg),
        ("factored", LinearSolver::FactoredCg),
        ("direct", LinearSolver::Direct),
        ("two-level", LinearSolver::TwoLevel),
    ] {
        setup.simulation.newton.linear = solver;
        let f = skinpatch::bench::bench_fem(&setup, frames)?;
        let t = f.timings;
        let other = f.wall_s - t.forces_s - t.assembly_s - t.linear_s;
        report += &format!(
            "{name:<9} {:>9.3} {:>9.2} {:>8} {:>10} {:>9.2} {:>9.2} {:>9.2} {:>9.2} {:>9.2}\n",
            f.frames as f64 / f.wall_s,
            f.wall_s,
            f.newton_iterations,
            f.linear_iterations,
            t.forces_s,
            t.assembly_s,
            t.linear_s,
            t.factor_s,
            other
        );
        walls.push(f.wall_s);
    }
    report += &format!(
        "wall-time ratios: cg / factored {:.2}, direct / factored {:.2}, cg / two-level {:.2}\n",
        walls[0] / walls[1],
        walls[2] / walls[1],
        walls[0] / walls[3]
    );
    print_stdout(&report)
}

/// `bench micro`; `fixed_texel` is (--texel-um, --cpu-up-to, --tile).
fn bench_micro(
    path: &Path,
    frames: usize,
    sizes: &[usize],
    (texel_um, cpu_up_to, tile): (Option<f64>, usize, Option<usize>),
    (bandwidth_gbs, raster_step): (Option<f64>, usize),
) -> anyhow::Result<()> {
    let layout = micro_layout(
        sizes,
        (texel_um, cpu_up_to, tile),
        (bandwidth_gbs, raster_step),
    )?;
    let setup = Setup::load(path).with_context(|| format!("scenario {}", path.display()))?;
    let model = setup
        .outputs
        .micro
        .as_ref()
        .map_or_else(skinpatch::micro::KernelModel::forehead, |m| m.model.clone());
    println!(
        "bench micro: one frame (raster, SVD, two passes, normals) on {} ({} top triangles)",
        path.display(),
        setup.mesh.top.triangles.len()
    );
    match layout {
        skinpatch::bench::MapLayout::FixedPatch => {
            println!("map spans the patch at every size (texels shrink as the size grows)")
        }
        skinpatch::bench::MapLayout::FixedTexel { texel_um, .. } => println!(
            "fixed {texel_um} µm texels: the map covers size × {texel_um} µm, the patch's strain on its centre"
        ),
    }
    println!(
        "{:>6} {:>9} {:>12} {:>12} {:>16} {:>10} {:>12} {:>8}",
        "size", "texel µm", "CPU ms", "GPU ms", "GPU+readback ms", "CPU/GPU", "max |Δ|", "tiles %"
    );
    if raster_step > 1 {
        println!(
            "strain raster: one texel per {raster_step} × {raster_step} map texels, read bilinearly"
        );
    }
    let stepped = (layout, raster_step);
    let bench = skinpatch::bench::bench_micro(
        &setup.mesh,
        &model,
        sizes,
        frames,
        stepped,
        print_micro_row,
    )?;
    println!(
        "tiles %: share of the map's tiles the GPU passes ran on (the others keep the neutral map)"
    );
    match &bench.adapter {
        Some(a) => println!("GPU: {a}; GPU ms is the mean of {} frames", frames.max(1)),
        None => println!("no GPU adapter: CPU figures only"),
    }
    print_stage_tables(&bench, bandwidth_gbs);
    Ok(())
}

/// The map layout of `bench micro`'s flags, each checked.
fn micro_layout(
    sizes: &[usize],
    (texel_um, cpu_up_to, tile): (Option<f64>, usize, Option<usize>),
    (bandwidth_gbs, raster_step): (Option<f64>, usize),
) -> anyhow::Result<skinpatch::bench::MapLayout> {
    if !(1..=64).contains(&raster_step) {
        bail!("--raster-step must be in 1 … 64 map texels per raster texel, got {raster_step}");
    }
    if sizes.is_empty() || sizes.contains(&0) {
        bail!("--sizes needs positive map sides, e.g. 1024,2048,4096");
    }
    if let Some(b) = bandwidth_gbs.filter(|b| !(b.is_finite() && *b > 0.0)) {
        bail!("--bandwidth-gbs must be a positive number of GB/s, got {b}");
    }
    Ok(match (texel_um, tile) {
        (None, Some(_)) => bail!("--tile needs --texel-um (tiles hold a map of fixed texels)"),
        (_, Some(t)) if t < 16 => bail!("--tile must be ≥ 16 texels, got {t}"),
        (None, None) => skinpatch::bench::MapLayout::FixedPatch,
        (Some(t), _) if t.is_finite() && t > 0.0 => skinpatch::bench::MapLayout::FixedTexel {
            texel_um: t,
            cpu_up_to,
            tile,
        },
        (Some(t), _) => bail!("--texel-um must be > 0, got {t}"),
    })
}

/// One size's line of `bench micro` (and its tiled line).
fn print_micro_row(r: &skinpatch::bench::MicroRow) {
    let fmt = |x: Option<f64>, p: usize| x.map_or("-".to_string(), |v| format!("{v:.p$}"));
    println!(
        "{:>6} {:>9.3} {:>12} {:>12} {:>16} {:>10} {:>12} {:>8}",
        r.size,
        r.texel_um,
        fmt(r.cpu_ms, 1),
        fmt(r.gpu_ms, 2),
        fmt(r.gpu_readback_ms, 1),
        fmt(r.cpu_ms.zip(r.gpu_ms).map(|(c, g)| c / g), 1),
        r.max_difference
            .map_or("-".to_string(), |d| format!("{d:.1e}")),
        fmt(r.pass_tile_share.map(|s| 100.0 * s), 1),
    );
    if let Some(why) = &r.untiled_skipped {
        println!("{:>6} untiled GPU chain skipped: {why}", r.size);
    }
    if let Some(t) = &r.tiled {
        println!(
            "{:>6} tiled ({} texels, halo {}): {} of {} tiles convolved, GPU {:.2} ms{}",
            r.size,
            t.tile,
            t.halo,
            t.active,
            t.total,
            t.gpu_ms,
            t.max_difference.map_or(String::new(), |d| format!(
                ", max |tiled − untiled| {d:.1e}"
            )),
        );
    }
}

/// `bench micro`'s per-stage tables, when the GPU chain was profiled.
fn print_stage_tables(bench: &skinpatch::bench::MicroBench, bandwidth_gbs: Option<f64>) {
    let profiled: Vec<_> = bench
        .rows
        .iter()
        .filter_map(|r| r.stages.map(|s| (r.size, s)))
        .collect();
    if !profiled.is_empty() {
        let stage_table =
            |title: &str, cell: &dyn Fn(&skinpatch::gpu::micro::StageTimes, usize) -> String| {
                println!("{title}");
                let mut header = format!("{:>6}", "size");
                for stage in skinpatch::gpu::micro::MicroStage::ALL {
                    header += &format!(" {:>10}", stage.name());
                }
                println!("{header}");
                for (size, stages) in &profiled {
                    let mut line = format!("{size:>6}");
                    for k in 0..skinpatch::gpu::micro::MicroStage::COUNT {
                        line += &format!(" {:>10}", cell(stages, k));
                    }
                    println!("{line}");
                }
            };
        stage_table(
            "GPU frame by stage, each submitted alone and waited for (wall time, ms):",
            &|s, k| format!("{:.2}", s.wall_ms[k]),
        );
        if profiled
            .iter()
            .any(|(_, s)| s.gpu_ms.iter().any(Option::is_some))
        {
            stage_table(
                "GPU time of the shader stages from timestamp queries (ms):",
                &|s, k| s.gpu_ms[k].map_or("-".into(), |ms| format!("{ms:.3}")),
            );
        } else {
            println!("(the adapter has no timestamp queries: wall times only)");
        }
        let timestamps = profiled
            .iter()
            .all(|(_, s)| s.gpu_ms.iter().any(Option::is_some));
        stage_table(
            "Bytes each stage must move at least (MB; taps and neighbours counted once, as if \
             a cache served them):",
            &|s, k| format!("{:.1}", s.bytes[k] as f64 * 1e-6),
        );
        stage_table("Achieved GB/s over the wall times:", &|s, k| {
            format!("{:.2}", s.bytes[k] as f64 / (s.wall_ms[k] * 1e6))
        });
        if timestamps {
            stage_table(
                "Achieved GB/s over the GPU times (transfers over wall time):",
                &|s, k| format!("{:.2}", s.gb_per_s(k)),
            );
        }
        let peak = bandwidth_gbs.or(bench.peak_bandwidth_gbs);
        match peak {
            Some(b) => {
                println!(
                    "resident frame (raster, passes, normals) against {b:.0} GB/s peak{}:",
                    if bandwidth_gbs.is_some() {
                        " (--bandwidth-gbs)"
                    } else {
                        " (published figure for this GPU)"
                    }
                );
                for (size, s) in &profiled {
                    let bytes = s.resident_bytes();
                    let floor_ms = bytes as f64 / (b * 1e6);
                    let shader_ms: f64 = skinpatch::gpu::micro::MicroStage::ALL
                        .iter()
                        .enumerate()
                        .filter(|(_, st)| st.runs_shaders())
                        .map(|(k, _)| s.ms(k))
                        .sum();
                    println!(
                        "{size:>6} {:>10.3} MB  floor {floor_ms:>9.3} ms  stages {shader_ms:>9.3} ms  \
                         = {:.1}× the floor, {:.1}% of peak",
                        bytes as f64 * 1e-6,
                        shader_ms / floor_ms,
                        100.0 * floor_ms / shader_ms
                    );
                }
            }
            None => println!(
                "(peak bandwidth of this adapter unknown: --bandwidth-gbs compares the traffic with it)"
            ),
        }
    }
}

fn bench_render(path: &Path, frames: usize, width: usize, height: usize) -> anyhow::Result<()> {
    if !(8..=8192).contains(&width) || !(8..=8192).contains(&height) {
        bail!("--width and --height must be in 8 … 8192 px");
    }
    let setup = Setup::load(path).with_context(|| format!("scenario {}", path.display()))?;
    println!(
        "bench render: {} ({} tets), first {} frames at {width} × {height} px",
        path.display(),
        setup.mesh.num_tets(),
        frames
    );
    let b = skinpatch::bench::bench_render(&setup, frames, (width, height), 5)?;
    let (w, h, ss) = b.size;
    let full = b.fem_ms + b.micro_ms + b.geometry_ms + b.render_ms;
    println!("GPU: {}", b.adapter);
    println!(
        "image {w} × {h} px, supersampling {ss}×{ss}; means over {} frames",
        b.frames
    );
    println!("  FEM step (CPU)          {:>10.2} ms", b.fem_ms);
    println!("  microstructure (GPU)    {:>10.2} ms", b.micro_ms);
    println!("  geometry (CPU, upload)  {:>10.2} ms", b.geometry_ms);
    println!(
        "  render (GPU)            {:>10.2} ms  = {:.1} frames/s",
        b.render_ms,
        1e3 / b.render_ms
    );
    println!(
        "  render + read-back      {:>10.2} ms",
        b.render_readback_ms
    );
    println!("  render, each pass submitted alone:");
    for (stage, ms) in skinpatch::render::FrameStage::ALL.iter().zip(b.stages_ms) {
        println!("    {:<22}{:>10.2} ms", stage.name(), ms);
    }
    println!(
        "  whole frame             {:>10.2} ms  = {:.2} frames/s",
        full,
        1e3 / full
    );
    Ok(())
}
