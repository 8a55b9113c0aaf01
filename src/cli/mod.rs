//! The command line: argument definitions ([`Cli`], [`Command`]) and one
//! driver per command, each in its own file with its arguments. `main.rs`
//! parses, sets up logging and dispatches ([`dispatch`]); the drivers call
//! the library and print its results. Nothing in the library prints.

use clap::{Parser, Subcommand};

pub mod bench;
pub mod fit;
pub mod gpu_info;
pub mod mesh;
pub mod run;
pub mod synth;
pub mod tiles;
#[cfg(feature = "viewer")]
pub mod view;

#[derive(Parser)]
#[command(version, about, long_about = None)]
pub struct Cli {
    /// More log output (-v info, -vv debug, -vvv trace); RUST_LOG overrides.
    #[arg(short, long, action = clap::ArgAction::Count, global = true)]
    pub verbose: u8,
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Subcommand)]
pub enum Command {
    /// Run a scenario file: validate it, build or load its mesh, write outputs.
    ///
    /// Outputs go to [output] dir of the scenario (default out/<name>), or
    /// --output:
    /// mesh.vtu (rest mesh with regions, volumes, top-surface UVs), optionally
    /// mesh.node/.ele/.face; metrics.csv (one row per frame); volume.csv
    /// (each region's volume change per frame); summary.json (the run's
    /// record: scenario as run, overrides, metrics, files);
    /// frames/frame_NNNN.vtu and frames.pvd (deformed mesh, displacement,
    /// principal strains and directions, surface stretch); with [output]
    /// frames_vtkhdf, the same frames in one frames.vtkhdf (a build with
    /// the vtkhdf feature); with [output] strain_images,
    /// strain/{rs,rt,axes}_NNNN.png; with
    /// [microstructure], micro/height_neutral.png, micro/height_NNNN.png and
    /// micro/normal_NNNN.png (16-bit; .exr too when asked) and, when asked,
    /// micro/roughness.csv; with [render], render/<mode>/frame_NNNN.png (or
    /// .exr) and, when asked, render/<mode>.mp4. docs/GUIDE.md lists every
    /// array and column.
    Run(run::RunArgs),
    /// Generate a layered patch mesh with TetGen, or inspect a mesh file.
    ///
    /// Generation takes its parameters from a scenario's [mesh] section and/or
    /// flags (flags win). With --out BASE it writes BASE.node/.ele/.face
    /// (TetGen), BASE.vtu and BASE.poly (the TetGen input that regenerates the
    /// mesh). It always prints the quality report.
    Mesh(Box<mesh::MeshArgs>),
    /// Fit kernel parameters (α, σ) to measured deformed maps and a
    /// piecewise-linear kernel model to them (Nagano et al. 2015 eq. 7, Fig. 11–12).
    ///
    /// The samples file names the neutral map, each deformed map with its
    /// stretch ratio and axis, and/or already fitted points; with `output`
    /// set it writes a kernel file for `[microstructure] kernel_file`.
    Fit(fit::FitArgs),
    /// Synthesize a neutral microstructure map from an exemplar (Graham et al. 2013 §4).
    ///
    /// Image-analogies texture synthesis: a measured micro map (the
    /// exemplar) details a coarser mesostructure map (a scan), keeping the
    /// scan's low frequencies. The file's [synthesis] table names the
    /// inputs and parameters (docs/GUIDE.md, "Synthesizing a neutral map"); the
    /// outputs go to [output] dir (default out/<name>) or --output:
    /// synthesized.exr/.png (+ normal maps), albedo.png with an exemplar
    /// albedo, preview.png (exemplar, mesostructure, result, render) and
    /// synthesis.json (parameters, timings, statistics).
    Synth(synth::SynthArgs),
    /// Split a displacement map into a tiled map, or join one back.
    ///
    /// A tiled map is a folder of f32 EXR tiles with `index.toml` (size,
    /// tile side, texel size, height unit, edge rule): the form of
    /// face-scale maps beyond one GPU buffer, which the library's
    /// `TiledMicro` and `bench micro --tile` convolve tile by tile. Split and
    /// joined back, a map keeps its bits.
    #[command(subcommand)]
    Tiles(tiles::TilesCommand),
    /// Benchmark a stage and print its figures: `fem`, `micro` or `render`.
    #[command(subcommand)]
    Bench(bench::BenchCommand),
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
    View(Box<view::ViewArgs>),
}

/// Runs the command's driver.
pub fn dispatch(command: Command) -> anyhow::Result<()> {
    match command {
        Command::Run(args) => run::run(args),
        Command::Mesh(args) => mesh::run(*args),
        Command::Fit(args) => {
            let file = args.samples.clone();
            fit::run(args).map_err(|e| naming(&file, "samples file", e))
        }
        Command::Synth(args) => {
            let file = args.file.clone();
            synth::run(args).map_err(|e| naming(&file, "synthesis file", e))
        }
        Command::Tiles(command) => tiles::run(command),
        Command::Bench(command) => bench::run(command),
        Command::GpuInfo => gpu_info::run(),
        #[cfg(feature = "viewer")]
        Command::View(args) => view::run(*args),
    }
}

/// `e`, led by the input file it came from (`what file`) unless its
/// message already names that file: every error of a command that reads
/// one file names the file.
fn naming(file: &std::path::Path, what: &str, e: anyhow::Error) -> anyhow::Error {
    let name = file.file_name().map(|n| n.to_string_lossy());
    if name.is_some_and(|n| format!("{e:#}").contains(n.as_ref())) {
        e
    } else {
        e.context(format!("{what} {}", file.display()))
    }
}

/// Prints to stdout; a reader that went away (broken pipe) is not an error.
pub fn print_stdout(text: &str) -> anyhow::Result<()> {
    use std::io::Write;
    let mut out = std::io::stdout().lock();
    match out.write_all(text.as_bytes()).and_then(|()| out.flush()) {
        Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => Ok(()),
        other => Ok(other?),
    }
}
