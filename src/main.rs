//! The `skinpatch` command: parses arguments, calls the library, prints
//! results and errors. All work happens in the library.

mod cli;

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::{bail, Context};
use clap::{Args, Parser, Subcommand};
use skinpatch::mesh::generate::{generate_scaled, poly_text};
use skinpatch::mesh::quality::max_edge_within;
use skinpatch::mesh::{io, QualityReport, TetMesh, Vec3};
use skinpatch::scenario::{MeshSection, RefineSection, Scenario, Setup, ZoneKind};

/// Simulates a deforming patch of human skin and renders its dynamic microstructure.
#[derive(Parser)]
#[command(version, about, long_about = None)]
struct Cli {
    /// More log output (-v info, -vv debug, -vvv trace); RUST_LOG overrides.
    #[arg(short, long, action = clap::ArgAction::Count, global = true)]
    verbose: u8,
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Run a scenario file: validate it, build or load its mesh, write outputs.
    ///
    /// Outputs go to [output] dir of the scenario (default out/<name>), or
    /// --output:
    /// mesh.vtu (rest mesh with regions, volumes, top-surface UVs), optionally
    /// mesh.node/.ele/.face; metrics.csv (one row per frame); summary.json
    /// (the run's record: scenario as run, overrides, metrics, files);
    /// frames/frame_NNNN.vtu and frames.pvd (deformed mesh, displacement,
    /// principal strains and directions, surface stretch); with [output]
    /// frames_vtkhdf, the same frames in one frames.vtkhdf (a build with
    /// the vtkhdf feature); with [output] strain_images,
    /// strain/{rs,rt,axes}_NNNN.png; with
    /// [microstructure], micro/height_neutral.png, micro/height_NNNN.png and
    /// micro/normal_NNNN.png (16-bit; .exr too when asked) and, when asked,
    /// micro/roughness.csv; with [render], render/<mode>/frame_NNNN.png (or
    /// .exr) and, when asked, render/<mode>.mp4. The README lists every
    /// array and column.
    Run {
        /// Scenario file (TOML).
        scenario: PathBuf,
        /// Output folder, overriding the scenario's [output] dir.
        #[arg(short, long)]
        output: Option<PathBuf>,
        /// Run even if the outputs would exceed 50 GB (the estimate is
        /// checked before anything is written).
        #[arg(long)]
        force: bool,
        /// Override a scenario key: a dotted key and a TOML value, e.g.
        /// `--set probe.friction=0.3 --set material.dermis.youngs_modulus_kpa=200`
        /// (repeatable; validated like the file).
        #[arg(long = "set", value_name = "KEY=VALUE")]
        set: Vec<String>,
        /// No progress on stderr and no report on stdout (errors and
        /// warnings only).
        #[arg(short, long)]
        quiet: bool,
    },
    /// Generate a layered patch mesh with TetGen, or inspect a mesh file.
    ///
    /// Generation takes its parameters from a scenario's [mesh] section and/or
    /// flags (flags win). With --out BASE it writes BASE.node/.ele/.face
    /// (TetGen), BASE.vtu and BASE.poly (the TetGen input that regenerates the
    /// mesh). It always prints the quality report.
    Mesh(Box<MeshArgs>),
    /// Fit kernel parameters (α, σ) to measured deformed maps and a
    /// piecewise-linear kernel model to them (Nagano et al. 2015 eq. 7, Fig. 11–12).
    ///
    /// The samples file names the neutral map, each deformed map with its
    /// stretch ratio and axis, and/or already fitted points; with `output`
    /// set it writes a kernel file for `[microstructure] kernel_file`.
    Fit {
        /// Samples file (TOML).
        samples: PathBuf,
    },
    /// Synthesize a neutral microstructure map from an exemplar (Graham et al. 2013 §4).
    ///
    /// Image-analogies texture synthesis: a measured micro map (the
    /// exemplar) details a coarser mesostructure map (a scan), keeping the
    /// scan's low frequencies. The file's [synthesis] table names the
    /// inputs and parameters (README, "Synthesizing a neutral map"); the
    /// outputs go to [output] dir (default out/<name>) or --output:
    /// synthesized.exr/.png (+ normal maps), albedo.png with an exemplar
    /// albedo, preview.png (exemplar, mesostructure, result, render) and
    /// synthesis.json (parameters, timings, statistics).
    Synth {
        /// Synthesis file (TOML).
        file: PathBuf,
        /// Output folder, overriding the file's [output] dir.
        #[arg(short, long)]
        output: Option<PathBuf>,
        /// Override a key: `--set synthesis.alpha=1` (repeatable).
        #[arg(long = "set", value_name = "KEY=VALUE")]
        set: Vec<String>,
    },
    /// Split a displacement map into a tiled map, or join one back.
    ///
    /// A tiled map is a folder of f32 EXR tiles with `index.toml` (size,
    /// tile side, texel size, height unit, edge rule): the form of
    /// face-scale maps beyond one GPU buffer, which the library's
    /// `TiledMicro` and `bench micro --tile` convolve tile by tile. Split and
    /// joined back, a map keeps its bits.
    Tiles {
        /// `split` (a map file into a folder) or `join` (a folder into a map
        /// file).
        action: String,
        /// split: the map (.png, 16-bit, or .exr); join: the tiled map's
        /// folder.
        input: PathBuf,
        /// split: the folder to write; join: the map file to write (.exr,
        /// or .png for 16-bit).
        #[arg(short, long)]
        output: PathBuf,
        /// split: tile side (texels).
        #[arg(long, default_value_t = 4096)]
        tile: usize,
        /// split: texel size (µm) of a map file without skinpatch metadata.
        #[arg(long, value_name = "UM")]
        texel_um: Option<f64>,
    },
    /// Benchmark a stage and print its figures.
    ///
    /// `bench fem` simulates the first frames of a scenario (default the
    /// press-and-drag example) with each linear solver in one run and prints
    /// frames/s, iterations, the time split and the ratio between solvers.
    ///
    /// `bench micro` runs one microstructure frame (raster, SVD, two
    /// convolution passes, normals) on the GPU and on the CPU references at
    /// each map size, on the scenario's mesh under a fixed deformation, and
    /// prints both times, their ratio and the largest difference; then per
    /// stage its time, the bytes it must move and the GB/s achieved, and
    /// the frame against the GPU's peak bandwidth where known.
    ///
    /// `bench render` simulates the first frames of the scenario and times
    /// per frame the FEM step, the microstructure chain, the geometry and
    /// the render at `--width × --height` (dynamic mode), and prints frames
    /// per second for rendering alone and for the whole frame.
    Bench {
        /// Stage to benchmark: `fem`, `micro` or `render`.
        stage: String,
        /// Scenario (its mesh and, for `micro`, its kernel model).
        #[arg(long, default_value = "examples/press.toml")]
        scenario: PathBuf,
        /// Frames to simulate (`fem`) or timed GPU frames per size (`micro`).
        #[arg(long, default_value_t = 10)]
        frames: usize,
        /// Map sides for `micro` (texels).
        #[arg(long, value_delimiter = ',', default_value = "1024,2048,4096")]
        sizes: Vec<usize>,
        /// `micro` with fixed texels of this size (µm, e.g. 10): the map
        /// covers size × texel with the patch's strain on its centre,
        /// instead of spanning the patch at every size.
        #[arg(long, value_name = "UM")]
        texel_um: Option<f64>,
        /// With --texel-um, the largest side the CPU reference runs at.
        #[arg(long, default_value_t = 2048)]
        cpu_up_to: usize,
        /// With --texel-um, also hold the map as tiles of this side and
        /// convolve it tile by tile (maps beyond one GPU binding run only
        /// this way).
        #[arg(long, value_name = "TEXELS")]
        tile: Option<usize>,
        /// `micro`: the GPU's peak memory bandwidth (GB/s) the per-stage
        /// traffic is compared with, for adapters the bench does not know
        /// by name.
        #[arg(long, value_name = "GBS")]
        bandwidth_gbs: Option<f64>,
        /// `micro`: map texels per strain-raster texel along each side (as
        /// `[microstructure] strain_raster_step`; 1 is the exact raster).
        #[arg(long, default_value_t = 1, value_name = "N")]
        raster_step: usize,
        /// Image width for `render` (px).
        #[arg(long, default_value_t = 1920)]
        width: usize,
        /// Image height for `render` (px).
        #[arg(long, default_value_t = 1080)]
        height: usize,
    },
    /// List the GPU adapters (Vulkan) with the limits the stages depend on,
    /// and the one `run` would use (`SKINPATCH_ADAPTER` picks by name).
    GpuInfo,
    /// Open a window on a scenario: press and drag the skin with the mouse
    /// and watch its microstructure respond.
    ///
    /// Mouse: left drag orbits, right or middle drag pans, the wheel zooms;
    /// ctrl + left drag (or the panel's "mouse drives probe") presses the
    /// probe where the cursor points and slides it; shift + wheel sets the
    /// depth. The FEM runs in its own thread on the latest probe target.
    /// Screenshots, recorded frames (PNG, and MP4 with ffmpeg) and the saved
    /// probe path (a scenario that `skinpatch run` replays) go to
    /// --record-dir. Needs a display (X11 or Wayland; `xvfb-run -a` for none).
    #[cfg(feature = "viewer")]
    View(Box<ViewArgs>),
}

#[cfg(feature = "viewer")]
#[derive(Args)]
struct ViewArgs {
    /// Scenario file (TOML).
    scenario: PathBuf,
    /// Play these input steps (TOML, see the README) as the window runs.
    #[arg(long)]
    script: Option<PathBuf>,
    /// Close the window after this many seconds (an error if a script has
    /// not finished by then).
    #[arg(long, value_name = "SECONDS")]
    exit_after: Option<f64>,
    /// Window width (px).
    #[arg(long, default_value_t = 1600)]
    width: u32,
    /// Window height (px).
    #[arg(long, default_value_t = 900)]
    height: u32,
    /// Folder for screenshots, recordings and saved paths [default
    /// out/<scenario name>/view].
    #[arg(long)]
    record_dir: Option<PathBuf>,
    /// Override a scenario key, as for `run` (repeatable).
    #[arg(long = "set", value_name = "KEY=VALUE")]
    set: Vec<String>,
}

#[derive(Args)]
struct MeshArgs {
    /// Read the [mesh] section of this scenario.
    #[arg(long, conflicts_with = "input")]
    scenario: Option<PathBuf>,
    /// Load this mesh (.msh, .node/.ele or TetGen base name) instead of generating.
    #[arg(long)]
    input: Option<PathBuf>,
    /// Write BASE.node/.ele/.face, BASE.vtu (and BASE.poly when generating).
    #[arg(long, value_name = "BASE")]
    out: Option<PathBuf>,
    /// Patch extent in x (mm) [default 10].
    #[arg(long)]
    width_mm: Option<f64>,
    /// Patch extent in y (mm) [default 10].
    #[arg(long)]
    depth_mm: Option<f64>,
    /// Top layer (epidermis + dermis) thickness (mm) [default 1.5].
    #[arg(long)]
    top_layer_mm: Option<f64>,
    /// Bottom layer (hypodermis) thickness (mm); 0 for one layer [default 3.5].
    #[arg(long)]
    bottom_layer_mm: Option<f64>,
    /// Largest tet volume in the top layer (mm³) [default 0.004].
    #[arg(long)]
    top_max_volume_mm3: Option<f64>,
    /// Largest tet volume in the bottom layer (mm³) [default 0.02].
    #[arg(long)]
    bottom_max_volume_mm3: Option<f64>,
    /// Scale all volume limits until the mesh has about this many tets.
    #[arg(long)]
    target_tets: Option<usize>,
    /// TetGen radius-edge ratio bound (≥ 1.1) [default 1.5].
    #[arg(long)]
    radius_edge_max: Option<f64>,
    /// Fail unless every dihedral angle is at least this (degrees) [default 0: off].
    #[arg(long)]
    min_dihedral_deg: Option<f64>,
    /// Refine a hemisphere under the top surface: X,Y,RADIUS (mm).
    #[arg(
        long,
        value_delimiter = ',',
        value_name = "X,Y,R",
        conflicts_with = "refine_box"
    )]
    refine_sphere: Option<Vec<f64>>,
    /// Refine a box hanging from the top surface: X,Y,SIZE_X,SIZE_Y,DEPTH (mm).
    #[arg(long, value_delimiter = ',', value_name = "X,Y,SX,SY,D")]
    refine_box: Option<Vec<f64>>,
    /// Largest tet volume inside the refinement zone (mm³).
    #[arg(long)]
    refine_max_volume_mm3: Option<f64>,
    /// Also report the longest edge of the tets within R of the point (X, Y, Z) (mm).
    #[arg(long, value_delimiter = ',', value_name = "X,Y,Z,R")]
    edges_within: Option<Vec<f64>>,
}

fn synth(file: &Path, output: Option<&Path>, set: &[String]) -> anyhow::Result<()> {
    let started = std::time::Instant::now();
    let run = skinpatch::pipeline::synth::run(file, set, output, &mut |l| {
        eprintln!(
            "level {}: {} × {} texels from {} × {} exemplar texels, window {}, {} dims, \
             {:.0}% coherent, {:.1} s",
            l.level,
            l.size.0,
            l.size.1,
            l.exemplar.0,
            l.exemplar.1,
            l.window,
            l.dims,
            100.0 * l.coherent_share,
            l.seconds
        );
    })?;
    let m = &run.synthesis.map;
    let st = &run.statistics;
    println!(
        "synthesized {} × {} texels at {} µm in {:.1} s (σ_m {} µm, σ_L {} µm)",
        m.width,
        m.height,
        m.texel_um,
        run.synthesis.seconds,
        run.synthesis.sigmas_um.0,
        run.synthesis.sigmas_um.1
    );
    if let Some(e) = st.low_frequency_rms {
        println!(
            "mesostructure kept: RMS of the difference at its resolution {:.2}% of its range",
            100.0 * e
        );
    }
    println!(
        "normal histogram total variation to the exemplar: {:.3}",
        st.histogram_tv
    );
    if let Some(w) = st.spectrum_worst {
        println!(
            "power spectrum, microstructure band: worst octave {:+.1}% from the exemplar",
            100.0 * w
        );
    }
    if !run.rendered_on_gpu && run.written.iter().any(|p| p.ends_with("preview.png")) {
        println!("preview: no GPU adapter, the render panel is CPU shading");
    }
    for p in &run.written {
        println!("wrote {}", p.display());
    }
    log::info!("synth took {:.1} s", started.elapsed().as_secs_f64());
    Ok(())
}

fn fit(samples: &Path) -> anyhow::Result<()> {
    use std::io::IsTerminal;
    let bar = std::io::stderr().is_terminal().then(|| {
        let bar = indicatif::ProgressBar::new(1000);
        bar.set_style(
            indicatif::ProgressStyle::with_template("{elapsed_precise} [{bar:30}] {msg}")
                .expect("valid template")
                .progress_chars("=> "),
        );
        bar
    });
    let report = cli::fit::fit(samples, |k, total, fraction| {
        if let Some(bar) = &bar {
            bar.set_message(format!("sample {}/{total}", k + 1));
            bar.set_position(((k as f64 + fraction) / total as f64 * 1000.0) as u64);
        }
    })?;
    if let Some(bar) = &bar {
        bar.finish_and_clear();
    }
    let mut text = String::new();
    let mut line = |s: String| {
        text.push_str(&s);
        text.push('\n');
    };
    line(format!(
        "{:>8}  {:>6}  {:>8}  {:>9}  {:>6}  {:>13}  {:>13}  {:>6}  source",
        "r", "α", "σ (µm)", "distance", "range", "α valley", "σ valley", "s"
    ));
    for row in &report.rows {
        match &row.fit {
            Some(f) => {
                let v = &f.result;
                line(format!(
                    "{:>8.3}  {:>6.2}  {:>8.1}  {:>9.4}  {:>6.2}  {:>13}  {:>13}  {:>6.1}  {}",
                    row.r,
                    row.alpha,
                    row.sigma_um,
                    v.distance,
                    f.range,
                    format!("{:.2}…{:.2}", v.alpha_range.0, v.alpha_range.1),
                    format!("{:.1}…{:.1}", v.sigma_range_um.0, v.sigma_range_um.1),
                    f.seconds,
                    row.source
                ))
            }
            None => line(format!(
                "{:>8.3}  {:>6.2}  {:>8.1}  {:>9}  {:>6}  {:>13}  {:>13}  {:>6}  {}",
                row.r, row.alpha, row.sigma_um, "-", "-", "-", "-", "-", row.source
            )),
        }
    }
    if report.rows.iter().any(|r| r.fit.is_some()) {
        line(
            "valley: the α and σ of the candidates whose distance is within 10% (at least \
             0.002) of the optimum's"
                .to_string(),
        );
    }
    let l = &report.lines;
    let knots: Vec<String> = report
        .model
        .alpha
        .points
        .iter()
        .map(|(r, a)| format!("({r:.3}, {a:.3})"))
        .collect();
    line(format!(
        "model: α = {:.3}·(r − 1) next to r = 1 below, {:.3}·(r − 1) above; through (r, α) = {}",
        l.alpha_compression_slope,
        l.alpha_stretch_slope,
        knots.join(", ")
    ));
    line(format!(
        "       σ = {:.2}·r {:+.2} µm for r < 1, {:.2}·r {:+.2} µm for r ≥ 1 (at least 1 µm)",
        l.sigma_compression.0, l.sigma_compression.1, l.sigma_stretch.0, l.sigma_stretch.1
    ));
    if let Some(path) = &report.written {
        line(format!("wrote {}", path.display()));
    }
    if let Some(device) = &report.device {
        line(format!("candidates counted on {device}"));
    }
    print_stdout(&text)
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let level = match cli.verbose {
        0 => "warn",
        1 => "info",
        2 => "debug",
        _ => "trace",
    };
    env_logger::Builder::from_env(env_logger::Env::default().default_filter_or(level))
        .format_timestamp(None)
        .init();
    let result = match cli.command {
        Command::Run {
            scenario,
            output,
            force,
            set,
            quiet,
        } => run(&scenario, output, force, &set, quiet),
        Command::Mesh(args) => mesh(*args),
        Command::Fit { samples } => fit(&samples),
        Command::Synth { file, output, set } => synth(&file, output.as_deref(), &set),
        Command::Tiles {
            action,
            input,
            output,
            tile,
            texel_um,
        } => tiles(&action, &input, &output, tile, texel_um),
        #[cfg(feature = "viewer")]
        Command::View(args) => view(*args),
        Command::Bench {
            stage,
            scenario,
            frames,
            sizes,
            texel_um,
            cpu_up_to,
            tile,
            bandwidth_gbs,
            raster_step,
            width,
            height,
        } => match stage.as_str() {
            "micro" => bench_micro(
                &scenario,
                frames,
                &sizes,
                (texel_um, cpu_up_to, tile),
                (bandwidth_gbs, raster_step),
            ),
            "render" => bench_render(&scenario, frames, width, height),
            _ => bench(&stage, &scenario, frames),
        },
        Command::GpuInfo => gpu_info(),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}

fn run(
    path: &Path,
    output: Option<PathBuf>,
    force: bool,
    overrides: &[String],
    quiet: bool,
) -> anyhow::Result<()> {
    let mut scenario = Scenario::load_with(path, overrides)?;
    // Before the setup: it places the synthesized map's cache there.
    if let Some(dir) = output {
        scenario.output.dir = Some(dir);
    }
    if scenario.surface.is_some() {
        return run_surface(path, &scenario, overrides, force, quiet);
    }
    let mut setup = Setup::from_scenario(&scenario, path)
        .with_context(|| format!("scenario {}", path.display()))?;
    setup.force_large_output = force;
    let progress = (!quiet).then(Progress::new);
    let result = skinpatch::pipeline::run(&setup, |frame| {
        if let Some(p) = &progress {
            p.frame(frame.metrics, frame.total_frames)
        }
    });
    let summary = finished(result, progress, path, &setup.output_dir)?;
    let mut record = run_record(path, overrides, &scenario, &setup.output_dir, &summary)?;
    record["fem_wall_s"] = summary
        .frames
        .iter()
        .map(|m| m.step_wall_s)
        .sum::<f64>()
        .into();
    let summary_path = write_record(&setup.output_dir, &record)?;
    let report = format!("scenario {}: mesh\n{}", setup.name, summary.quality);
    report_run(
        report,
        summary.micro_device.as_deref(),
        &summary.written,
        &summary_path,
        quiet,
    )
}

/// Prints a finished run's report: where the microstructure ran and the
/// files written (nothing with `--quiet`).
fn report_run(
    mut report: String,
    micro_device: Option<&str>,
    written: &[PathBuf],
    summary_path: &Path,
    quiet: bool,
) -> anyhow::Result<()> {
    if let Some(device) = micro_device {
        report += &format!("microstructure stages: {device}\n");
    }
    for file in written.iter().map(|p| p.as_path()).chain([summary_path]) {
        report += &format!("wrote {}\n", file.display());
    }
    if quiet {
        return Ok(());
    }
    print_stdout(&report)
}

/// Ends the progress bar and names the scenario and folder of a failed run.
fn finished<T>(
    result: skinpatch::Result<T>,
    progress: Option<Progress>,
    path: &Path,
    output_dir: &Path,
) -> anyhow::Result<T> {
    if let Some(p) = &progress {
        p.finish();
    }
    result.with_context(|| {
        format!(
            "running scenario {} (output folder {})",
            path.display(),
            output_dir.display()
        )
    })
}

/// The machine-readable record of a run (`summary.json`).
fn run_record(
    path: &Path,
    overrides: &[String],
    scenario: &Scenario,
    output_dir: &Path,
    summary: &impl serde::Serialize,
) -> anyhow::Result<serde_json::Value> {
    Ok(serde_json::json!({
        "skinpatch_version": env!("CARGO_PKG_VERSION"),
        "scenario_file": path,
        "overrides": overrides,
        "scenario": scenario,
        "output_dir": output_dir,
        "run": serde_json::to_value(summary)?,
    }))
}

/// Writes the record next to the run's outputs.
fn write_record(output_dir: &Path, record: &serde_json::Value) -> anyhow::Result<PathBuf> {
    let path = output_dir.join("summary.json");
    let text = serde_json::to_string_pretty(record)?;
    skinpatch::mesh::io::write_atomically(&path, format!("{text}\n").as_bytes())?;
    Ok(path)
}

/// `skinpatch run` of a scenario with `[surface]`.
fn run_surface(
    path: &Path,
    scenario: &Scenario,
    overrides: &[String],
    force: bool,
    quiet: bool,
) -> anyhow::Result<()> {
    let mut setup = skinpatch::scenario::SurfaceSetup::from_scenario(scenario, path)
        .with_context(|| format!("scenario {}", path.display()))?;
    setup.force_large_output = force;
    let progress = (!quiet).then(Progress::new);
    let result = skinpatch::pipeline::surface::run(&setup, |frame| {
        if let Some(p) = &progress {
            p.surface_frame(frame.metrics, frame.total_frames)
        }
    });
    let summary = finished(result, progress, path, &setup.output_dir)?;
    let record = run_record(path, overrides, scenario, &setup.output_dir, &summary)?;
    let summary_path = write_record(&setup.output_dir, &record)?;
    let s = &setup.surface;
    let mut report = format!(
        "scenario {}: surface {}\n  {} positions, {} surface vertices, {} triangles, {} frames at {} Hz, {:.1} mm² at rest\n",
        setup.name,
        s.origin,
        s.positions.len(),
        s.top.vertices.len(),
        s.top.triangles.len(),
        s.num_frames(),
        s.frame_rate_hz,
        s.area()
    );
    if setup.pieces.iter().any(|p| p.udim.is_some()) {
        let tiles: Vec<String> = setup
            .pieces
            .iter()
            .filter_map(|p| p.udim)
            .map(|u| u.to_string())
            .collect();
        report += &format!("  UDIM tiles {}\n", tiles.join(", "));
    }
    report_run(
        report,
        summary.micro_device.as_deref(),
        &summary.written,
        &summary_path,
        quiet,
    )
}

fn bench(stage: &str, path: &Path, frames: usize) -> anyhow::Result<()> {
    use skinpatch::fem::integrate::LinearSolver;
    if stage != "fem" {
        bail!("unknown stage '{stage}': `bench` knows `fem`, `micro` and `render`");
    }
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

fn tiles(
    action: &str,
    input: &Path,
    output: &Path,
    tile: usize,
    texel_um: Option<f64>,
) -> anyhow::Result<()> {
    use skinpatch::micro::io::{read_map, write_exr, write_png16, MapDefaults, TexelSize};
    use skinpatch::micro::tiled::TiledMap;
    match action {
        "split" => {
            if tile == 0 {
                bail!("--tile must be ≥ 1 texel");
            }
            if let Some(t) = texel_um.filter(|t| !(t.is_finite() && *t > 0.0)) {
                bail!("--texel-um must be finite and > 0, got {t}");
            }
            // Without --texel-um a sentinel texel size shows whether the
            // file brought its own.
            let unset = f64::MIN_POSITIVE;
            let defaults = MapDefaults {
                texel: TexelSize::Um(texel_um.unwrap_or(unset)),
                height_unit_um: 1.0,
                edge: skinpatch::micro::Edge::Wrap,
            };
            let map = read_map(input, &defaults)?;
            if texel_um.is_none() && map.texel_um == unset {
                bail!(
                    "{} carries no texel size (no skinpatch metadata): give --texel-um",
                    input.display()
                );
            }
            let tiled = TiledMap::write(output, &map, tile)?;
            let (cols, rows) = tiled.grid();
            println!(
                "wrote {} ({} × {} texels of {} µm in {cols} × {rows} tiles of {tile})",
                output.display(),
                map.width,
                map.height,
                map.texel_um
            );
        }
        "join" => {
            let map = TiledMap::open(input)?.read_all()?;
            match output.extension().and_then(|e| e.to_str()) {
                Some("exr") => write_exr(output, &map)?,
                Some("png") => write_png16(output, &map)?,
                _ => bail!(
                    "--output must end in .exr or .png, got {}",
                    output.display()
                ),
            }
            println!(
                "wrote {} ({} × {} texels)",
                output.display(),
                map.width,
                map.height
            );
        }
        other => bail!("tiles: the action is `split` or `join`, got `{other}`"),
    }
    Ok(())
}

/// `bench micro`; `fixed_texel` is (--texel-um, --cpu-up-to, --tile).
fn bench_micro(
    path: &Path,
    frames: usize,
    sizes: &[usize],
    (texel_um, cpu_up_to, tile): (Option<f64>, usize, Option<usize>),
    (bandwidth_gbs, raster_step): (Option<f64>, usize),
) -> anyhow::Result<()> {
    if !(1..=64).contains(&raster_step) {
        bail!("--raster-step must be in 1 … 64 map texels per raster texel, got {raster_step}");
    }
    if sizes.is_empty() || sizes.contains(&0) {
        bail!("--sizes needs positive map sides, e.g. 1024,2048,4096");
    }
    if let Some(b) = bandwidth_gbs.filter(|b| !(b.is_finite() && *b > 0.0)) {
        bail!("--bandwidth-gbs must be a positive number of GB/s, got {b}");
    }
    let layout = match (texel_um, tile) {
        (None, Some(_)) => bail!("--tile needs --texel-um (tiles hold a map of fixed texels)"),
        (_, Some(t)) if t < 16 => bail!("--tile must be ≥ 16 texels, got {t}"),
        (None, None) => skinpatch::bench::MapLayout::FixedPatch,
        (Some(t), _) if t.is_finite() && t > 0.0 => skinpatch::bench::MapLayout::FixedTexel {
            texel_um: t,
            cpu_up_to,
            tile,
        },
        (Some(t), _) => bail!("--texel-um must be > 0, got {t}"),
    };
    let setup = Setup::load(path).with_context(|| format!("scenario {}", path.display()))?;
    let model = setup
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
    let fmt = |x: Option<f64>, p: usize| x.map_or("-".to_string(), |v| format!("{v:.p$}"));
    if raster_step > 1 {
        println!(
            "strain raster: one texel per {raster_step} × {raster_step} map texels, read bilinearly"
        );
    }
    let stepped = (layout, raster_step);
    let bench = skinpatch::bench::bench_micro(&setup.mesh, &model, sizes, frames, stepped, |r| {
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
    })?;
    println!(
        "tiles %: share of the map's tiles the GPU passes ran on (the others keep the neutral map)"
    );
    match &bench.adapter {
        Some(a) => println!("GPU: {a}; GPU ms is the mean of {} frames", frames.max(1)),
        None => println!("no GPU adapter: CPU figures only"),
    }
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
    Ok(())
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

fn gpu_info() -> anyhow::Result<()> {
    let adapters = skinpatch::gpu::adapters();
    if adapters.is_empty() {
        bail!(
            "{}",
            skinpatch::gpu::vulkan::explain(&skinpatch::gpu::vulkan::look())
        );
    }
    let mut text = String::new();
    for (k, a) in adapters.iter().enumerate() {
        let (i, l) = (&a.info, &a.limits);
        text += &format!(
            "adapter {k}: {}\n  backend {:?}, type {:?}, vendor {:#06x}, device {:#06x}\n  driver {} {}\n",
            i.name, i.backend, i.device_type, i.vendor, i.device, i.driver, i.driver_info
        );
        text += &format!(
            "  max_texture_dimension_2d {}\n  max_storage_buffer_binding_size {}\n  max_buffer_size {}\n  \
             max_compute_workgroup_storage_size {}\n  max_compute_invocations_per_workgroup {}\n  \
             max_compute_workgroups_per_dimension {}\n",
            l.max_texture_dimension_2d,
            l.max_storage_buffer_binding_size,
            l.max_buffer_size,
            l.max_compute_workgroup_storage_size,
            l.max_compute_invocations_per_workgroup,
            l.max_compute_workgroups_per_dimension,
        );
        let names: Vec<&str> = [
            (wgpu::Features::FLOAT32_FILTERABLE, "FLOAT32_FILTERABLE"),
            (wgpu::Features::TIMESTAMP_QUERY, "TIMESTAMP_QUERY"),
            (
                wgpu::Features::TIMESTAMP_QUERY_INSIDE_ENCODERS,
                "TIMESTAMP_QUERY_INSIDE_ENCODERS",
            ),
        ]
        .into_iter()
        .filter(|(f, _)| a.features.contains(*f))
        .map(|(_, name)| name)
        .collect();
        let features = if names.is_empty() {
            "none".to_string()
        } else {
            names.join(", ")
        };
        text += &format!("  optional features used: {features}\n");
    }
    match skinpatch::gpu::Context::new() {
        Ok(ctx) => text += &format!("in use: {}\n", ctx.describe()),
        Err(e) => text += &format!("in use: none ({e})\n"),
    }
    print_stdout(&text)
}

/// A progress bar on a terminal, plain lines otherwise.
struct Progress {
    bar: Option<indicatif::ProgressBar>,
}

impl Progress {
    fn new() -> Progress {
        use std::io::IsTerminal;
        let bar = std::io::stderr().is_terminal().then(|| {
            let bar = indicatif::ProgressBar::new(0);
            bar.set_style(
                indicatif::ProgressStyle::with_template(
                    "{elapsed_precise} [{bar:30}] frame {pos}/{len} {msg}",
                )
                .expect("valid template")
                .progress_chars("=> "),
            );
            bar
        });
        Progress { bar }
    }

    fn frame(&self, m: &skinpatch::export::FrameMetrics, total: usize) {
        let [fx, fy, fz] = m.probe_force_n;
        let msg = format!(
            "t = {:.3} s, probe force ({fx:.3e}, {fy:.3e}, {fz:.3e}) N, {} contact nodes",
            m.time_s, m.contact_nodes
        );
        self.show(m.frame, total, msg);
    }

    fn surface_frame(&self, m: &skinpatch::pipeline::surface::SurfaceMetrics, total: usize) {
        let msg = format!(
            "t = {:.3} s, r_s {:.4} … {:.4}, r_t {:.4} … {:.4}",
            m.time_s, m.rs_range[0], m.rs_range[1], m.rt_range[0], m.rt_range[1]
        );
        self.show(m.frame, total, msg);
    }

    fn show(&self, frame: usize, total: usize, msg: String) {
        match &self.bar {
            Some(bar) => {
                bar.set_length(total as u64);
                bar.set_position(frame as u64 + 1);
                bar.set_message(msg);
            }
            None => eprintln!("frame {}/{}: {msg}", frame + 1, total),
        }
    }

    fn finish(&self) {
        if let Some(bar) = &self.bar {
            bar.finish();
        }
    }
}

impl MeshArgs {
    /// Applies the flags on top of a [mesh] section.
    fn overlay(&self, mut m: MeshSection) -> anyhow::Result<MeshSection> {
        macro_rules! set {
            ($($field:ident),*) => { $( if self.$field.is_some() { m.$field = self.$field; } )* };
        }
        set!(
            width_mm,
            depth_mm,
            top_layer_mm,
            bottom_layer_mm,
            top_max_volume_mm3,
            bottom_max_volume_mm3,
            target_tets,
            radius_edge_max,
            min_dihedral_deg
        );
        let zone = match (&self.refine_sphere, &self.refine_box) {
            (Some(s), _) if s.len() != 3 => bail!("--refine-sphere takes X,Y,R, got {s:?}"),
            (_, Some(b)) if b.len() != 5 => bail!("--refine-box takes X,Y,SX,SY,D, got {b:?}"),
            (Some(s), _) => Some(RefineSection {
                shape: ZoneKind::Sphere,
                center_mm: [s[0], s[1]],
                radius_mm: Some(s[2]),
                size_mm: None,
                max_volume_mm3: f64::NAN,
            }),
            (_, Some(b)) => Some(RefineSection {
                shape: ZoneKind::Box,
                center_mm: [b[0], b[1]],
                radius_mm: None,
                size_mm: Some([b[2], b[3], b[4]]),
                max_volume_mm3: f64::NAN,
            }),
            _ => None,
        };
        if let Some(mut zone) = zone {
            zone.max_volume_mm3 = self
                .refine_max_volume_mm3
                .or(m.refine.as_ref().map(|r| r.max_volume_mm3))
                .context("--refine-sphere/--refine-box need --refine-max-volume-mm3")?;
            m.refine = Some(zone);
        } else if let (Some(v), Some(r)) = (self.refine_max_volume_mm3, m.refine.as_mut()) {
            r.max_volume_mm3 = v;
        } else if self.refine_max_volume_mm3.is_some() {
            bail!(
                "--refine-max-volume-mm3 needs a refinement zone (--refine-sphere or --refine-box)"
            );
        }
        Ok(m)
    }
}

fn mesh(args: MeshArgs) -> anyhow::Result<()> {
    let (mesh, poly) = if let Some(input) = &args.input {
        let mesh = io::read_mesh(input)?;
        (mesh, None)
    } else {
        let section = match &args.scenario {
            Some(path) => Scenario::load(path)?.mesh,
            None => MeshSection::default(),
        };
        if section.file.is_some() {
            bail!("the scenario's [mesh] loads a file; use --input to inspect a mesh file");
        }
        let spec = args.overlay(section)?.patch_spec()?;
        let (mesh, scale) = generate_scaled(&spec)?;
        (mesh, Some(poly_text(&spec, scale)))
    };
    let mut report = QualityReport::of(&mesh).to_string();
    if let Some(e) = &args.edges_within {
        let [x, y, z, r] = e[..] else {
            bail!("--edges-within takes X,Y,Z,R, got {e:?}");
        };
        let (longest, n) = max_edge_within(&mesh, &Vec3::new(x, y, z), r);
        report +=
            &format!("within {r} mm of ({x}, {y}, {z}): {n} tets, longest edge {longest:.4} mm\n");
    }
    // Files first: a closed stdout must not cost the user their mesh.
    if let Some(base) = &args.out {
        report += &write_mesh_files(&mesh, base, poly.as_deref())?;
    }
    print_stdout(&report)
}

/// Prints to stdout; a reader that went away (broken pipe) is not an error.
fn print_stdout(text: &str) -> anyhow::Result<()> {
    use std::io::Write;
    let mut out = std::io::stdout().lock();
    match out.write_all(text.as_bytes()).and_then(|()| out.flush()) {
        Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => Ok(()),
        other => Ok(other?),
    }
}

fn write_mesh_files(mesh: &TetMesh, base: &Path, poly: Option<&str>) -> anyhow::Result<String> {
    if let Some(dir) = base.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    let mut written: Vec<PathBuf> = io::tetgen_paths(base).into();
    io::write_tetgen(mesh, base)?;
    let vtu = PathBuf::from(format!("{}.vtu", base.display()));
    io::write_vtu(&vtu, &io::Grid::from_mesh(mesh))?;
    written.push(vtu);
    if let Some(text) = poly {
        let path = PathBuf::from(format!("{}.poly", base.display()));
        io::write_atomically(&path, text.as_bytes())?;
        written.push(path);
    }
    Ok(written
        .iter()
        .map(|p| format!("wrote {}\n", p.display()))
        .collect())
}

/// `skinpatch view`.
#[cfg(feature = "viewer")]
fn view(args: ViewArgs) -> anyhow::Result<()> {
    use skinpatch::viewer::{run, ViewOptions};
    let name = args
        .scenario
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "scenario".into());
    let record_dir = args
        .record_dir
        .unwrap_or_else(|| Path::new("out").join(name).join("view"));
    let summary = run(ViewOptions {
        scenario: args.scenario,
        overrides: args.set,
        script: args.script,
        exit_after: args.exit_after,
        size: (args.width.max(64), args.height.max(64)),
        record_dir,
    })?;
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len().max(1) as f64;
    println!(
        "viewer: {} frames shown ({:.1} frames/s over the session), {} FEM frames (last {:.3} s)",
        summary.frames_shown, summary.display_fps, summary.fem_frames, summary.fem_frame_s
    );
    if !summary.render_ms.is_empty() {
        println!(
            "3D view {} × {} px: {} renders, mean {:.1} ms; microstructure chain: {} runs, mean {:.1} ms",
            summary.view_size.0,
            summary.view_size.1,
            summary.render_ms.len(),
            mean(&summary.render_ms),
            summary.micro_ms.len(),
            mean(&summary.micro_ms)
        );
    }
    if !summary.latencies_ms.is_empty() {
        println!(
            "probe move to first frame showing it: mean {:.0} ms over {} moves",
            mean(&summary.latencies_ms),
            summary.latencies_ms.len()
        );
    }
    if let Some(f) = summary.final_force_n {
        println!("final probe force: [{:e}, {:e}, {:e}] N", f[0], f[1], f[2]);
    }
    for file in &summary.written {
        println!("wrote {}", file.display());
    }
    Ok(())
}
