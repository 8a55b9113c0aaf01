//! `skinpatch fit` as a library call: fits each sample's kernel (α, σ) of a
//! validated samples file ([`FitSetup`]) with the histogram search of
//! [`crate::micro::fit`] (Nagano et al. 2015 eq. 7) — counting candidates on
//! the GPU when an adapter is worth using ([`crate::gpu::worth_using`]) —
//! fits the kernel model to every point, and writes it as a
//! `[microstructure.kernel]` table where the file asks.

use std::path::{Path, PathBuf};

use crate::error::{Error, Result};
use crate::gpu::Context;
use crate::micro::fit::{fit_model, FittedPoint, HistogramSettings, Objective};
use crate::micro::DisplacementMap;
use crate::scenario::fit::{FitSetup, FitTarget};

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
    pub axis: crate::micro::fit::Axis,
    /// Histogram half range used for target and candidates.
    pub range: f64,
    /// The optimum, its distance and valley.
    pub result: crate::micro::fit::FitResult,
    /// Seconds the search took.
    pub seconds: f64,
}

/// What `skinpatch fit` found.
#[derive(Clone, Debug)]
pub struct FitReport {
    /// Per sample, in file order (samples, then points).
    pub rows: Vec<FitRow>,
    /// The fitted model.
    pub model: crate::micro::KernelModel,
    /// Its lines, for the report.
    pub lines: crate::micro::fit::ModelLines,
    /// The kernel file written, if the samples file names one.
    pub written: Option<PathBuf>,
    /// Where the candidates were counted (`None` without map samples).
    pub device: Option<String>,
}

/// Reads and validates the samples file at `path`, then fits it
/// ([`fit`]).
pub fn fit_file(path: &Path, progress: impl FnMut(usize, usize, f64)) -> Result<FitReport> {
    fit(&FitSetup::load(path)?, progress)
}

/// Fits the map samples of `setup` (`progress` gets the sample, the count
/// and the fraction of its search done), fits the kernel model to them and
/// the points, and writes it where the file says.
pub fn fit(setup: &FitSetup, mut progress: impl FnMut(usize, usize, f64)) -> Result<FitReport> {
    let mut rows = Vec::new();
    let mut device = None;
    if let Some(neutral) = &setup.neutral {
        let ctx = crate::gpu::acquire()?.filter(crate::gpu::worth_using);
        device = Some(match &ctx {
            Some(c) => format!("GPU: {}", c.describe()),
            None => "CPU".to_string(),
        });
        let total = setup.targets.len();
        for (k, target) in setup.targets.iter().enumerate() {
            rows.push(fit_sample(
                target,
                neutral,
                ctx.as_ref(),
                setup.bins,
                |x| progress(k, total, x),
            )?);
        }
    }
    rows.extend(setup.points.iter().map(|p| FitRow {
        source: "point".into(),
        r: p.r,
        alpha: p.alpha,
        sigma_um: p.sigma_um,
        fit: None,
    }));
    let points: Vec<FittedPoint> = rows
        .iter()
        .map(|r| FittedPoint {
            r: r.r,
            alpha: r.alpha,
            sigma_um: r.sigma_um,
        })
        .collect();
    let (model, lines) = fit_model(&points, &setup.alpha_breaks)?;
    if let Some(out) = &setup.output {
        write_kernel_file(&setup.path, out, &rows, &model, setup.bins)?;
    }
    Ok(FitReport {
        rows,
        model,
        lines,
        written: setup.output.clone(),
        device,
    })
}

/// Fits one sample's (α, σ): on the GPU of `ctx` when it has one that
/// takes the problem, else on the CPU.
fn fit_sample(
    target: &FitTarget,
    neutral: &DisplacementMap,
    ctx: Option<&Context>,
    bins: usize,
    mut progress: impl FnMut(f64),
) -> Result<FitRow> {
    let range = target.range;
    let hist = HistogramSettings { bins, range };
    let objective = Objective::new(neutral, &target.histogram, target.axis, target.r, hist);
    let start = std::time::Instant::now();
    let on_gpu = match ctx {
        Some(c) => crate::gpu::or_cpu(crate::gpu::fit::GpuFit::new(c, &objective.base, bins))?,
        None => None,
    };
    let result = match &on_gpu {
        Some(f) => f.fit_params(&objective, &mut progress)?,
        None => crate::micro::fit::search(
            &objective,
            |b, d, alphas| {
                Ok(crate::micro::fit::count_histograms(
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
        source: target.source.clone(),
        r: target.r,
        alpha: result.alpha,
        sigma_um: result.sigma_um,
        fit: Some(SampleFit {
            axis: target.axis,
            range,
            result,
            seconds,
        }),
    })
}

/// Writes the fitted model as a `[microstructure.kernel]` table to `out`,
/// headed by comments that list every row it was fitted to.
fn write_kernel_file(
    samples_path: &Path,
    out: &Path,
    rows: &[FitRow],
    model: &crate::micro::KernelModel,
    bins: usize,
) -> Result<()> {
    let section = crate::scenario::KernelSection::of(model);
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
                    crate::micro::fit::valley_margin(v.distance),
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
    crate::mesh::io::write_atomically(out, text.as_bytes())
}
