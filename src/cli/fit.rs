//! `skinpatch fit`: reads a samples file (its format is
//! [`skinpatch::scenario::FitSamples`]), fits each map sample's kernel
//! (α, σ) with the histogram search of [`skinpatch::micro::fit`] — counted
//! on the GPU when a hardware adapter exists — and writes the fitted kernel
//! model as a `[microstructure.kernel]` table.

use std::path::PathBuf;

use clap::Args;
use skinpatch::error::{Error, Result};
use skinpatch::mesh::io;
use skinpatch::micro::fit::HistogramSettings;
use skinpatch::micro::{DisplacementMap, NormalHistogram};
use skinpatch::scenario::{FitSample, FitSamples};

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
    let report = fit(samples, |k, total, fraction| {
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

/// One row of a fit: a sample's stretch ratio and fitted parameters.
#[derive(Clone, Debug, PartialEq)]
pub struct FitRow {
    /// Where the row came from (map file or `point`).
    pub source: String,
    /// Stretch ratio.
    pub r: f64,
    /// α.
    pub alpha: f64,
    /// σ (µm).
    pub sigma_um: f64,
    /// The search's outcome (fitted samples only).
    pub fit: Option<SampleFit>,
}

/// What the search found for one sample.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SampleFit {
    /// Axis of the sample.
    pub axis: skinpatch::micro::fit::Axis,
    /// Histogram half range used for target and candidates.
    pub range: f64,
    /// The optimum, its distance and valley.
    pub result: skinpatch::micro::fit::FitResult,
    /// Seconds the search took.
    pub seconds: f64,
}

/// What `skinpatch fit` found.
#[derive(Clone, Debug)]
pub struct FitReport {
    /// Per sample, in file order (samples, then points).
    pub rows: Vec<FitRow>,
    /// The fitted model.
    pub model: skinpatch::micro::KernelModel,
    /// Its lines, for the report.
    pub lines: skinpatch::micro::fit::ModelLines,
    /// The kernel file written, if the samples file names one.
    pub written: Option<PathBuf>,
    /// Where the candidates were counted (`None` without map samples).
    pub device: Option<String>,
}

/// Smallest side (texels) of a map `fit` reads: below it a map has too
/// few normals for a histogram.
const MIN_FIT_SIDE: usize = 8;

/// Reads the samples file at `path`, fits its map samples (`progress`
/// gets the sample, the count and the fraction of its search done), fits
/// the kernel model to all points and writes it where the file says.
pub fn fit(
    path: &std::path::Path,
    mut progress: impl FnMut(usize, usize, f64),
) -> Result<FitReport> {
    use skinpatch::micro::fit::{fit_model, FittedPoint};
    use skinpatch::micro::io::{read_map, MapDefaults, TexelSize};
    let samples: FitSamples = skinpatch::scenario::read_toml_file(path)?;
    let base = path.parent().unwrap_or(std::path::Path::new("."));
    let bins = checked_bins(&samples)?;
    refuse_overwriting_inputs(path, base, &samples)?;
    let height_unit_um = samples.height_unit_um.unwrap_or(1.0);
    if !(height_unit_um.is_finite() && height_unit_um > 0.0) {
        return Err(Error::parameter(
            "height_unit_um",
            format!("must be a finite height > 0 µm, got {height_unit_um}"),
        ));
    }
    let defaults = MapDefaults {
        texel: TexelSize::Um(samples.texel_um.unwrap_or(1.0)),
        height_unit_um,
        edge: skinpatch::micro::Edge::Clamp,
    };
    let mut rows = Vec::new();
    let mut device = None;
    if !samples.sample.is_empty() {
        let neutral_path = samples
            .neutral
            .as_ref()
            .ok_or_else(|| Error::parameter("neutral", "is required to fit [[sample]] maps"))?;
        let neutral = read_map(&base.join(neutral_path), &defaults)?;
        if neutral.width.min(neutral.height) < MIN_FIT_SIDE {
            return Err(Error::parameter(
                "neutral",
                format!(
                    "{} is {} × {} texels; a normal histogram needs at least {MIN_FIT_SIDE} a side",
                    neutral_path.display(),
                    neutral.width,
                    neutral.height
                ),
            ));
        }
        let ctx = skinpatch::gpu::acquire()?.filter(skinpatch::gpu::worth_using);
        device = Some(match &ctx {
            Some(c) => format!("GPU: {}", c.describe()),
            None => "CPU".to_string(),
        });
        let total = samples.sample.len();
        for (k, s) in samples.sample.iter().enumerate() {
            if !(s.r.is_finite() && s.r >= 0.1 && s.r <= 10.0) {
                return Err(Error::parameter(
                    format!("sample[{k}].r"),
                    format!("must be in [0.1, 10], got {}", s.r),
                ));
            }
            let target = SampleTarget::read(k, s, &samples, base, &neutral, &defaults, bins)?;
            rows.push(fit_sample(s, target, &neutral, ctx.as_ref(), bins, |x| {
                progress(k, total, x)
            })?);
        }
    }
    for (k, p) in samples.point.iter().enumerate() {
        check_point(k, p)?;
        rows.push(FitRow {
            source: "point".into(),
            r: p.r,
            alpha: p.alpha,
            sigma_um: p.sigma_um,
            fit: None,
        });
    }
    let points: Vec<FittedPoint> = rows
        .iter()
        .map(|r| FittedPoint {
            r: r.r,
            alpha: r.alpha,
            sigma_um: r.sigma_um,
        })
        .collect();
    let (model, lines) = fit_model(&points, &samples.alpha_breaks)?;
    let written = match &samples.output {
        Some(out) => {
            let out = base.join(out);
            write_kernel_file(path, &out, &rows, &model, bins)?;
            Some(out)
        }
        None => None,
    };
    Ok(FitReport {
        rows,
        model,
        lines,
        written,
        device,
    })
}

/// A `[[point]]` fitted elsewhere: r in [0.1, 10], α in the model's
/// range [−2, 1], σ > 0.
fn check_point(k: usize, p: &skinpatch::scenario::FitPoint) -> Result<()> {
    let checks = [
        ("r", p.r, p.r >= 0.1 && p.r <= 10.0, "[0.1, 10]"),
        (
            "alpha",
            p.alpha,
            p.alpha >= -2.0 && p.alpha <= 1.0,
            "[-2, 1]",
        ),
        ("sigma_um", p.sigma_um, p.sigma_um > 0.0, "> 0"),
    ];
    for (key, v, ok, range) in checks {
        if !(v.is_finite() && ok) {
            return Err(Error::parameter(
                format!("point[{k}].{key}"),
                format!(
                    "must be {}{range}, got {}",
                    if range.starts_with('[') { "in " } else { "" },
                    skinpatch::error::shown(v)
                ),
            ));
        }
    }
    Ok(())
}

/// The kernel file must not be the samples file or one of its maps.
fn refuse_overwriting_inputs(
    path: &std::path::Path,
    base: &std::path::Path,
    samples: &FitSamples,
) -> Result<()> {
    let Some(output) = &samples.output else {
        return Ok(());
    };
    let mut inputs: Vec<(String, std::path::PathBuf)> =
        vec![("samples file".into(), path.to_path_buf())];
    if let Some(n) = &samples.neutral {
        inputs.push(("neutral map".into(), base.join(n)));
    }
    for (k, s) in samples.sample.iter().enumerate() {
        for (what, file) in [("map", &s.map), ("histogram", &s.histogram)] {
            if let Some(f) = file {
                inputs.push((format!("sample[{k}].{what}"), base.join(f)));
            }
        }
    }
    let inputs: Vec<(&str, &std::path::Path)> = inputs
        .iter()
        .map(|(w, p)| (w.as_str(), p.as_path()))
        .collect();
    skinpatch::export::outputs::refuse_input_overwrite("output", &base.join(output), &inputs)
}

/// The histogram cells per side, with `range` checked too.
fn checked_bins(samples: &FitSamples) -> Result<usize> {
    let bins = samples
        .bins
        .unwrap_or(skinpatch::micro::normals::HISTOGRAM_BINS);
    if !(2..=1024).contains(&bins) {
        return Err(Error::parameter(
            "bins",
            format!("must be in 2..=1024, got {bins}"),
        ));
    }
    if let Some(range) = samples.range {
        if !(range.is_finite() && range > 0.0 && range <= 1.0) {
            return Err(Error::parameter(
                "range",
                format!("must be in (0, 1] (a normal's tangent component), got {range}"),
            ));
        }
    }
    Ok(bins)
}

/// A sample's target histogram, its half range and where it came from.
struct SampleTarget {
    histogram: NormalHistogram,
    range: f64,
    source: String,
}

impl SampleTarget {
    /// The histogram of sample `k`'s deformed map (its range from the file
    /// or the data) or its histogram file (the range from the file).
    fn read(
        k: usize,
        s: &FitSample,
        samples: &FitSamples,
        base: &std::path::Path,
        neutral: &DisplacementMap,
        defaults: &skinpatch::micro::io::MapDefaults,
        bins: usize,
    ) -> Result<SampleTarget> {
        match (&s.map, &s.histogram) {
            (Some(map), None) => {
                let deformed = skinpatch::micro::io::read_map(&base.join(map), defaults)?;
                let range = samples.range.unwrap_or_else(|| {
                    skinpatch::micro::fit::auto_range(&[
                        &skinpatch::micro::fit::resample(neutral, s.axis, s.r),
                        &deformed,
                    ])
                });
                Ok(SampleTarget {
                    histogram: NormalHistogram::of(&deformed, bins, range, [1.0, 1.0]),
                    range,
                    source: map.display().to_string(),
                })
            }
            (None, Some(file)) => {
                let range = samples.range.ok_or_else(|| {
                    Error::parameter(
                        format!("sample[{k}].histogram"),
                        "needs `range` in the samples file: the half range its cells cover",
                    )
                })?;
                Ok(SampleTarget {
                    histogram: read_histogram(&base.join(file), HistogramSettings { bins, range })?,
                    range,
                    source: file.display().to_string(),
                })
            }
            _ => Err(Error::parameter(
                format!("sample[{k}]"),
                "needs exactly one of map and histogram",
            )),
        }
    }
}

/// Fits one sample's (α, σ): on the GPU of `ctx` when it has one that
/// takes the problem, else on the CPU.
fn fit_sample(
    s: &FitSample,
    target: SampleTarget,
    neutral: &DisplacementMap,
    ctx: Option<&skinpatch::gpu::Context>,
    bins: usize,
    mut progress: impl FnMut(f64),
) -> Result<FitRow> {
    use skinpatch::micro::fit::Objective;
    let range = target.range;
    let hist = HistogramSettings { bins, range };
    let objective = Objective::new(neutral, &target.histogram, s.axis, s.r, hist);
    let start = std::time::Instant::now();
    let on_gpu = match ctx {
        Some(c) => {
            skinpatch::gpu::or_cpu(skinpatch::gpu::fit::GpuFit::new(c, &objective.base, bins))?
        }
        None => None,
    };
    let result = match &on_gpu {
        Some(f) => f.fit_params(&objective, &mut progress)?,
        None => skinpatch::micro::fit::search(
            &objective,
            |b, d, alphas| {
                Ok(skinpatch::micro::fit::count_histograms(
                    b, d, alphas, bins, range,
                ))
            },
            &mut progress,
        )?,
    };
    let seconds = start.elapsed().as_secs_f64();
    log::info!(
        "fitted {}: α {:.2}, σ {:.1} µm, TV {:.4} ({} candidates, {seconds:.1} s)",
        target.source,
        result.alpha,
        result.sigma_um,
        result.distance,
        result.evaluations
    );
    Ok(FitRow {
        source: target.source,
        r: s.r,
        alpha: result.alpha,
        sigma_um: result.sigma_um,
        fit: Some(SampleFit {
            axis: s.axis,
            range,
            result,
            seconds,
        }),
    })
}

/// Writes the fitted model as a `[microstructure.kernel]` table to `out`,
/// headed by comments that list every row it was fitted to.
fn write_kernel_file(
    samples_path: &std::path::Path,
    out: &std::path::Path,
    rows: &[FitRow],
    model: &skinpatch::micro::KernelModel,
    bins: usize,
) -> Result<()> {
    let section = skinpatch::scenario::KernelSection::of(model);
    let body = toml::to_string(&section).map_err(|e| Error::io(out, std::io::Error::other(e)))?;
    let mut fitted = String::new();
    for row in rows {
        match &row.fit {
            Some(f) => {
                let v = &f.result;
                fitted += &format!(
                    "#   {}: r {}, axis {:?}, bins {bins}, range {}: α {:.2}, σ {:.1} µm, \
                     TV {:.4}; within {:.4}: α {:.2}…{:.2}, σ {:.1}…{:.1} µm\n",
                    row.source,
                    row.r,
                    f.axis,
                    f.range,
                    v.alpha,
                    v.sigma_um,
                    v.distance,
                    skinpatch::micro::fit::valley_margin(v.distance),
                    v.alpha_range.0,
                    v.alpha_range.1,
                    v.sigma_range_um.0,
                    v.sigma_range_um.1
                )
            }
            None => {
                fitted += &format!(
                    "#   point: r {}, α {}, σ {} µm\n",
                    row.r, row.alpha, row.sigma_um
                )
            }
        }
    }
    let text = format!(
        "# Kernel model fitted by `skinpatch fit` from {}:\n{fitted}\
         # Use it with [microstructure] kernel_file = \"…\".\n{body}",
        samples_path.display()
    );
    if let Some(folder) = out.parent().filter(|f| !f.as_os_str().is_empty()) {
        std::fs::create_dir_all(folder).map_err(|e| Error::io(folder, e))?;
    }
    io::write_atomically(out, text.as_bytes())
}

/// Reads a target histogram: `bins` lines of `bins` comma-separated
/// non-negative weights, normalised to sum 1.
fn read_histogram(path: &std::path::Path, hist: HistogramSettings) -> Result<NormalHistogram> {
    let text = io::read_input_text(path)?;
    let bad = |line: usize, message: String| Error::Parse {
        path: path.to_path_buf(),
        line,
        message,
    };
    let rows: Vec<&str> = text.lines().filter(|l| !l.trim().is_empty()).collect();
    if rows.len() != hist.bins {
        return Err(bad(
            0,
            format!(
                "expected {} rows of weights, found {}",
                hist.bins,
                rows.len()
            ),
        ));
    }
    let mut cells = Vec::with_capacity(hist.bins * hist.bins);
    for (k, row) in rows.iter().enumerate() {
        let values: Vec<&str> = row.split(',').collect();
        if values.len() != hist.bins {
            return Err(bad(
                k + 1,
                format!("expected {} weights, found {}", hist.bins, values.len()),
            ));
        }
        for v in values {
            let w: f64 = v
                .trim()
                .parse()
                .ok()
                .filter(|w: &f64| w.is_finite() && *w >= 0.0)
                .ok_or_else(|| {
                    bad(
                        k + 1,
                        format!("{:?} is not a non-negative number", v.trim()),
                    )
                })?;
            cells.push(w);
        }
    }
    let total: f64 = cells.iter().sum();
    if total <= 0.0 {
        return Err(bad(0, "the histogram is empty (all weights 0)".into()));
    }
    cells.iter_mut().for_each(|c| *c /= total);
    Ok(NormalHistogram {
        bins: hist.bins,
        range: hist.range,
        cells,
    })
}
