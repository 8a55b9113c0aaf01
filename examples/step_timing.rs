//! Times a scenario's frames stepped in memory through the run API
//! (`skinpatch::pipeline::Run`), with no files written: the Rust side of
//! the Python package's per-frame overhead (docs/PERFORMANCE.md, "Python
//! layer"), whose Python side is `examples/python/step_timing.py`.
//!
//! ```sh
//! cargo run --release --example step_timing -- examples/press.toml
//! ```
//!
//! Prints the frames, the total wall time of the steps and the mean per
//! frame.

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
    let mut force = 0.0;
    for _ in 0..frames {
        force = run.step()?.metrics.probe_force_n[2];
    }
    let total = start.elapsed().as_secs_f64();
    println!(
        "rust: {frames} frames in {total:.3} s, {:.2} ms a frame (last force {force:.6} N)",
        1e3 * total / frames as f64
    );
    Ok(())
}
