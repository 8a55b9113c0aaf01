//! `skinpatch view`: the interactive window (feature `viewer`).

use std::path::{Path, PathBuf};

use clap::Args;

/// `skinpatch view`'s arguments.
#[derive(Args)]
pub struct ViewArgs {
    /// Scenario file (TOML).
    scenario: PathBuf,
    /// Play these input steps (TOML, see docs/GUIDE.md, "Interactive viewer") as the window runs.
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

/// `skinpatch view`.
pub fn run(args: ViewArgs) -> anyhow::Result<()> {
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
