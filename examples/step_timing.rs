//! Times a scenario's frames stepped in memory through the run API
//! (`skinpatch::pipeline::Run`), with no files written: the Rust side of
//! the Python package's per-frame overhead (docs/PERFORMANCE.md, "Python
//! layer"), whose Python side is `examples/python/step_timing.py`.
//!
//! ```sh
//! cargo run --release --example step_timing -- examples/press.toml
//! ```
//!
//! Prints the frames, the total wall time of the steps, the mean per frame
//! and the part of it in the FEM solve (the frames' `step_wall_s`).

use std::path::PathBuf;
use std::time::Instant;

use clap::Parser;
use skinpatch::pipeline::Run;
use skinpatch::scenario::Setup;

#[derive(Parser)]
#[command(about = "Times a scenario's frames stepped through the run API")]
struct Args {
    /// Scenario file.
    #[arg(default_value = "examples/press.toml")]
    scenario: PathBuf,
}

fn main() -> anyhow::Result<()> {
    let args = Args::parse();
    let setup = Setup::load(&args.scenario)?;
    let mut run = Run::new(&setup);
    let frames = run.scenario_frames();
    let start = Instant::now();
    let (mut force, mut solve) = (0.0, 0.0);
    for _ in 0..frames {
        let frame = run.step()?;
        force = frame.metrics.probe_force_n[2];
        solve += frame.metrics.step_wall_s;
    }
    let total = start.elapsed().as_secs_f64();
    println!(
        "rust: {frames} frames in {total:.3} s, {:.2} ms a frame, {:.2} ms of it the FEM solve \
         (last force {force:.6} N)",
        1e3 * total / frames as f64,
        1e3 * solve / frames as f64
    );
    Ok(())
}
