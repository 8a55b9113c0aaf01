//! `skinpatch fit`: a progress bar over [`skinpatch::pipeline::fit`] (the
//! samples file validated by [`skinpatch::scenario::fit::FitSetup`]) and
//! its report printed.

use std::path::PathBuf;

use clap::Args;
use skinpatch::pipeline::fit::fit_file;

use super::print_stdout;

/// `skinpatch fit`'s arguments.
#[derive(Args)]
pub struct FitArgs {
    /// Samples file (TOML).
    pub samples: PathBuf,
}

/// Runs `skinpatch fit` and prints its report.
pub fn run(args: FitArgs) -> anyhow::Result<()> {
    let samples = args.samples.as_path();
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
    let report = fit_file(samples, |k, total, fraction| {
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
    if !l.alpha_at_clamp.is_empty() {
        let at: Vec<String> = l
            .alpha_at_clamp
            .iter()
            .map(|(r, a)| format!("({r:.3}, {a:.2})"))
            .collect();
        line(format!(
            "note: {} sample(s) at α's clamp, (r, α) = {}: the line through the others runs \
             past the clamp there, so the clamped model meets them and they are left out of \
             its least squares",
            at.len(),
            at.join(", ")
        ));
    }
    if let Some(path) = &report.written {
        line(format!("wrote {}", path.display()));
    }
    if let Some(device) = &report.device {
        line(format!("candidates counted on {device}"));
    }
    print_stdout(&text)
}
