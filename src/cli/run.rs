//! `skinpatch run`: a scenario (the FEM patch, or an animated surface with
//! `[surface]`) through the pipeline, with progress on stderr, the run's
//! record (`summary.json`) and a report on stdout.

use std::path::{Path, PathBuf};

use anyhow::Context;
use clap::Args;
use skinpatch::export::{FrameMetrics, SurfaceMetrics};
use skinpatch::scenario::{Scenario, Setup};

use super::print_stdout;

/// `skinpatch run`'s arguments.
#[derive(Args)]
pub struct RunArgs {
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
}

/// Runs `skinpatch run`.
pub fn run(args: RunArgs) -> anyhow::Result<()> {
    let RunArgs {
        scenario: path,
        output,
        force,
        set: overrides,
        quiet,
    } = args;
    let (path, overrides) = (path.as_path(), overrides.as_slice());
    skinpatch::scenario::check_output_flag(output.as_deref(), overrides)?;
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
    setup.outputs.force_large_output = force;
    let progress = (!quiet).then(|| Progress::new(setup.simulation.frames + 1));
    let result = skinpatch::pipeline::run(&setup, |frame| {
        if let Some(p) = &progress {
            p.frame(frame.metrics, frame.total_frames)
        }
    });
    let summary = finished(result, progress, path, &setup.outputs.dir)?;
    let mut record = run_record(path, overrides, &scenario, &setup.outputs.dir, &summary)?;
    record["fem_wall_s"] = summary
        .frames
        .iter()
        .map(|m| m.step_wall_s)
        .sum::<f64>()
        .into();
    let summary_path = write_record(&setup.outputs.dir, &record)?;
    let mut report = format!("scenario {}: mesh\n", setup.name);
    if let Some(quality) = &summary.quality {
        report += &quality.to_string();
    }
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
    // The output folder's own files by name, a subfolder's as a count
    // (summary.json lists each).
    let dir = summary_path.parent().unwrap_or(Path::new(""));
    let mut folders = std::collections::BTreeMap::<&Path, usize>::new();
    for file in written.iter().map(|p| p.as_path()).chain([summary_path]) {
        match file.parent() {
            Some(folder) if folder != dir => *folders.entry(folder).or_default() += 1,
            _ => report += &format!("wrote {}\n", file.display()),
        }
    }
    for (folder, count) in folders {
        let files = if count == 1 { "file" } else { "files" };
        report += &format!("wrote {count} {files} in {}\n", folder.display());
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
    setup.outputs.force_large_output = force;
    let progress = (!quiet).then(|| Progress::new(setup.surface.num_frames()));
    let result = skinpatch::pipeline::surface::run(&setup, |frame| {
        if let Some(p) = &progress {
            p.frame(frame.metrics, frame.total_frames)
        }
    });
    let summary = finished(result, progress, path, &setup.outputs.dir)?;
    let mut record = run_record(path, overrides, scenario, &setup.outputs.dir, &summary)?;
    // The same fields as a FEM run's record; no FEM ran.
    record["fem_wall_s"] = serde_json::Value::Null;
    let summary_path = write_record(&setup.outputs.dir, &record)?;
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

/// What the progress shows of a frame's metrics row.
trait ProgressLine {
    /// The frame's index.
    fn index(&self) -> usize;
    /// The frame's line after "frame k/n".
    fn line(&self) -> String;
}

impl ProgressLine for FrameMetrics {
    fn index(&self) -> usize {
        self.frame
    }

    fn line(&self) -> String {
        let [fx, fy, fz] = self.probe_force_n;
        format!(
            "t = {:.3} s, probe force ({fx:.3e}, {fy:.3e}, {fz:.3e}) N, {} contact nodes",
            self.time_s, self.contact_nodes
        )
    }
}

impl ProgressLine for SurfaceMetrics {
    fn index(&self) -> usize {
        self.frame
    }

    fn line(&self) -> String {
        format!(
            "t = {:.3} s, r_s {:.4} … {:.4}, r_t {:.4} … {:.4}",
            self.time_s, self.rs_range[0], self.rs_range[1], self.rt_range[0], self.rt_range[1]
        )
    }
}

fn bar_style(template: &str) -> indicatif::ProgressStyle {
    indicatif::ProgressStyle::with_template(template)
        .expect("valid template")
        .progress_chars("=> ")
}

/// A progress bar on a terminal, plain lines otherwise.
struct Progress {
    bar: Option<indicatif::ProgressBar>,
}

impl Progress {
    /// A bar for `total` frames, shown at once with the set-up (mesh, GPU
    /// device, neutral map, first renders) as its message and a running
    /// clock, so that the seconds before the first frame do not look like
    /// a hang; from the first frame on it also shows the time left.
    fn new(total: usize) -> Progress {
        use std::io::IsTerminal;
        let bar = std::io::stderr().is_terminal().then(|| {
            let bar = indicatif::ProgressBar::new(total as u64);
            bar.set_style(bar_style(
                "{elapsed_precise} [{bar:30}] frame {pos}/{len}: {msg}",
            ));
            bar.set_message("setting up (mesh, GPU device, maps)");
            bar.enable_steady_tick(std::time::Duration::from_millis(250));
            bar
        });
        if bar.is_none() {
            eprintln!("setting up {total} frames (mesh, GPU device, maps)");
        }
        Progress { bar }
    }

    /// Shows frame `row` of `total` (either kind of run).
    fn frame(&self, row: &impl ProgressLine, total: usize) {
        let (frame, msg) = (row.index(), row.line());
        match &self.bar {
            Some(bar) => {
                if bar.position() == 0 {
                    // From the first frame on the rate is known.
                    bar.set_style(bar_style(
                        "{elapsed_precise} [{bar:30}] frame {pos}/{len}, {eta} left: {msg}",
                    ));
                }
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
