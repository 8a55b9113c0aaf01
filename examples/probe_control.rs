//! Driving the probe from code: press straight down, a step a frame, until
//! the skin pushes back with a chosen force, then stop — a force-controlled
//! indentation through the step-by-step run API (`skinpatch::pipeline::Run`).
//!
//! ```sh
//! cargo run --release --example probe_control                    # examples/press.toml, stop at 0.05 N
//! cargo run --release --example probe_control -- --force-n 0.02 --mesh meshes/patch_3k.node --out out/probe_control
//! ```
//!
//! Each frame it prints the probe's depth below its start, the probe force,
//! the contact area, the peak contact pressure and the largest von Mises
//! stress in the patch. It stops at the first frame whose force reaches
//! `--force-n`, and fails if `--max-frames` pass first. Nothing is written
//! unless `--out` is given; then the scenario's simulation outputs (VTU
//! frames, metrics.csv) are written for the frames solved, up to the
//! scenario's frame count.

use std::path::PathBuf;

use clap::Parser;
use skinpatch::mesh::Vec3;
use skinpatch::pipeline::{Frame, Run};
use skinpatch::scenario::{Scenario, Setup};

#[derive(Parser)]
#[command(about = "Presses the probe from code until a force threshold")]
struct Args {
    /// Scenario file (its mesh, materials, supports and probe shape).
    #[arg(default_value = "examples/press.toml")]
    scenario: PathBuf,
    /// Stop at the first frame whose probe force (|F|, N) reaches this.
    #[arg(long, default_value_t = 0.05)]
    force_n: f64,
    /// How far the probe moves down each frame (mm).
    #[arg(long, default_value_t = 0.05)]
    step_mm: f64,
    /// Give up after this many frames.
    #[arg(long, default_value_t = 100)]
    max_frames: usize,
    /// Mesh file to use instead of the scenario's (relative to the working
    /// directory).
    #[arg(long)]
    mesh: Option<PathBuf>,
    /// Write the simulation outputs into this folder.
    #[arg(long)]
    out: Option<PathBuf>,
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args = Args::parse();
    if !(args.force_n > 0.0 && args.step_mm > 0.0) {
        return Err("--force-n and --step-mm must be positive".into());
    }
    let mut scenario = Scenario::load(&args.scenario)?;
    if let Some(mesh) = &args.mesh {
        scenario.mesh.file = Some(std::path::absolute(mesh)?);
    }
    scenario.render = None;
    scenario.microstructure = None;
    scenario.output.strain_images = false;
    let mut setup = Setup::from_scenario(&scenario, &args.scenario)?;
    let mut run = match &args.out {
        Some(out) => {
            setup.outputs.dir = out.clone();
            Run::writing(&setup)?
        }
        None => Run::new(&setup),
    };
    let start = run
        .probe_pose()
        .ok_or("the scenario has no [probe] to drive")?
        .centre;

    println!(
        "{:>5} {:>9} {:>9} {:>10} {:>12} {:>12}",
        "frame", "depth mm", "|F| (N)", "area mm²", "p max N/mm²", "σ_vM max"
    );
    for k in 0..args.max_frames {
        run.set_probe_target(start - Vec3::z() * (args.step_mm * k as f64))?;
        let frame = run.step()?;
        let force = frame.contact.total().norm();
        print_row(&frame, args.step_mm * k as f64, force);
        if force >= args.force_n {
            println!(
                "reached {force:.5} N ≥ {} N at frame {k}, {:.3} mm below the start",
                args.force_n,
                args.step_mm * k as f64
            );
            let summary = run.finish()?;
            if let Some(out) = &args.out {
                println!(
                    "{} files written under {}",
                    summary.written.len(),
                    out.display()
                );
            }
            return Ok(());
        }
    }
    Err(format!(
        "the force stayed below {} N for {} frames ({:.3} mm of travel)",
        args.force_n,
        args.max_frames,
        args.step_mm * (args.max_frames - 1) as f64
    )
    .into())
}

/// One line of the table.
fn print_row(frame: &Frame<'_>, depth_mm: f64, force: f64) {
    let contact = frame.contact;
    let p_max = (0..contact.nodes.len())
        .map(|k| contact.pressure(k))
        .fold(0.0, f64::max);
    let von_mises = frame
        .stresses()
        .iter()
        .map(|s| s.von_mises())
        .fold(0.0, f64::max);
    println!(
        "{:>5} {:>9.3} {:>9.5} {:>10.4} {:>12.5} {:>12.5}",
        frame.metrics.frame, depth_mm, force, frame.metrics.contact_area_mm2, p_max, von_mises
    );
}
