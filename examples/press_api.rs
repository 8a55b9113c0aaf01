//! skinpatch as a library: load a scenario, change a parameter in Rust, run
//! it, and read each frame's probe force and strain fields in a callback
//! instead of from the output files.
//!
//! ```sh
//! cargo run --release --example press_api                       # examples/press.toml, dermis at 300 kPa
//! cargo run --release --example press_api -- --dermis-kpa 75 --mesh meshes/patch_3k.node
//! ```
//!
//! It prints one line per frame (probe force, contact area, the surface
//! stretch range, the largest principal Green strain over the tets, the
//! largest displacement) and the peak force, and writes the scenario's
//! simulation outputs (frames, metrics.csv) under `--out`. Rendering, the
//! microstructure and the strain images are switched off: this program
//! reads the fields directly.

use std::path::PathBuf;

use clap::Parser;
use skinpatch::pipeline::{self, Frame};
use skinpatch::scenario::{MaterialSection, Scenario, Setup};

#[derive(Parser)]
#[command(about = "Runs a press scenario through the skinpatch library API")]
struct Args {
    /// Scenario file.
    #[arg(default_value = "examples/press.toml")]
    scenario: PathBuf,
    /// Young's modulus of the `dermis` region (kPa); the file's is replaced.
    #[arg(long, default_value_t = 300.0)]
    dermis_kpa: f64,
    /// Mesh file to use instead of the scenario's (relative to the working
    /// directory).
    #[arg(long)]
    mesh: Option<PathBuf>,
    /// Output folder.
    #[arg(long, default_value = "out/press_api")]
    out: PathBuf,
}

/// What the callback keeps of one frame.
struct Row {
    frame: usize,
    time_s: f64,
    force_z_n: f64,
    contact_area_mm2: f64,
    rs_max: f64,
    rt_min: f64,
    green_max: f64,
    displacement_max_mm: f64,
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args = Args::parse();
    let mut scenario = Scenario::load(&args.scenario)?;

    // Parameters are plain fields of the scenario, as the file spells them.
    scenario
        .material
        .entry("dermis".into())
        .or_insert_with(MaterialSection::default)
        .youngs_modulus_kpa = Some(args.dermis_kpa);
    if let Some(mesh) = &args.mesh {
        // Scenario paths are relative to the scenario file; an absolute
        // path stays as it is.
        scenario.mesh.file = Some(std::path::absolute(mesh)?);
    }
    scenario.render = None;
    scenario.microstructure = None;
    scenario.output.strain_images = false;

    // Validation happens here: a bad value is an error naming the key.
    let mut setup = Setup::from_scenario(&scenario, &args.scenario)?;
    setup.outputs.dir = args.out.clone();
    eprintln!(
        "{}: {} tets, dermis E = {} kPa, {} frames",
        args.scenario.display(),
        setup.mesh.num_tets(),
        args.dermis_kpa,
        setup.simulation.frames + 1
    );

    let mut rows = Vec::new();
    let summary = pipeline::run(&setup, |frame: &Frame<'_>| rows.push(row(frame)))?;

    println!(
        "{:>5} {:>7} {:>9} {:>10} {:>7} {:>7} {:>9} {:>8}",
        "frame", "t (s)", "F_z (N)", "area mm²", "r_s max", "r_t min", "Green max", "|u| mm"
    );
    for r in &rows {
        println!(
            "{:>5} {:>7.4} {:>9.5} {:>10.4} {:>7.4} {:>7.4} {:>9.4} {:>8.4}",
            r.frame,
            r.time_s,
            r.force_z_n,
            r.contact_area_mm2,
            r.rs_max,
            r.rt_min,
            r.green_max,
            r.displacement_max_mm
        );
    }
    let peak = rows
        .iter()
        .max_by(|a, b| a.force_z_n.total_cmp(&b.force_z_n));
    if let Some(peak) = peak {
        println!(
            "peak force {:.5} N at frame {} (t = {:.4} s)",
            peak.force_z_n, peak.frame, peak.time_s
        );
    }
    println!(
        "{} files written under {}",
        summary.written.len(),
        args.out.display()
    );
    Ok(())
}

/// Reads one frame's fields.
fn row(frame: &Frame<'_>) -> Row {
    let m = frame.metrics;
    // Stretch ratios of the top surface, per surface vertex.
    let (mut rs_max, mut rt_min) = (f64::NEG_INFINITY, f64::INFINITY);
    for v in &frame.surface.vertices {
        let svd = v.strain().svd;
        rs_max = rs_max.max(svd.rs);
        rt_min = rt_min.min(svd.rt);
    }
    // Principal Green strains of every tet.
    let green_max = frame
        .strains()
        .tets
        .iter()
        .map(|s| s.green().max())
        .fold(f64::NEG_INFINITY, f64::max);
    let displacement_max_mm = (0..frame.positions.len())
        .map(|v| frame.displacement(v).norm())
        .fold(0.0, f64::max);
    Row {
        frame: m.frame,
        time_s: m.time_s,
        force_z_n: m.probe_force_n[2],
        contact_area_mm2: m.contact_area_mm2,
        rs_max,
        rt_min,
        green_max,
        displacement_max_mm,
    }
}
