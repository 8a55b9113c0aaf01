//! A `skinpatch fit` samples file ([`FitSamples`]) validated into a
//! [`FitSetup`]: every range checked, the kernel file refused where it would
//! land on an input, the neutral map read and each sample's target
//! histogram made (from its deformed map, or read from its histogram file),
//! so that the search (`pipeline::fit`, a layer above) only ever sees
//! checked data.

use std::path::{Path, PathBuf};

use super::{FitPoint, FitSample, FitSamples};
use crate::error::{Error, Result};
use crate::micro::fit::{auto_range, resample, Axis, HistogramSettings};
use crate::micro::io::{read_histogram, read_map, MapDefaults, TexelSize};
use crate::micro::normals::HISTOGRAM_BINS;
use crate::micro::{DisplacementMap, Edge, NormalHistogram};

/// Smallest side (texels) of a map `fit` reads: below it a map has too few
/// normals for a histogram.
pub const MIN_FIT_SIDE: usize = 8;

/// `texel_um` of a samples file that leaves it out (µm).
pub const FIT_TEXEL_UM: f64 = 1.0;

/// `height_unit_um` of a samples file that leaves it out (µm).
pub const FIT_HEIGHT_UNIT_UM: f64 = 1.0;

/// Accepted histogram cells per side: (fewest, most).
pub const FIT_BINS: (usize, usize) = (2, 1024);

/// Accepted stretch ratios of a sample or point: (smallest, largest).
pub const FIT_RATIO: (f64, f64) = (0.1, 10.0);

/// A validated samples file.
#[derive(Clone, Debug)]
pub struct FitSetup {
    /// The samples file.
    pub path: PathBuf,
    /// The neutral map (read when the file has map samples).
    pub neutral: Option<DisplacementMap>,
    /// Histogram cells per side.
    pub bins: usize,
    /// Per `[[sample]]`, in file order.
    pub targets: Vec<FitTarget>,
    /// The `[[point]]`s, checked.
    pub points: Vec<FitPoint>,
    /// Extra knots of the fitted α(r).
    pub alpha_breaks: Vec<f64>,
    /// Where the kernel file goes (resolved against the samples file).
    pub output: Option<PathBuf>,
}

/// One sample's target: the histogram the search matches.
#[derive(Clone, Debug)]
pub struct FitTarget {
    /// Where it came from (the map or histogram file, as the file names it).
    pub source: String,
    /// Stretch ratio along `axis`.
    pub r: f64,
    /// The stretch axis.
    pub axis: Axis,
    /// The target normal histogram.
    pub histogram: NormalHistogram,
    /// Its half range, which the candidates share.
    pub range: f64,
}

impl FitSetup {
    /// Reads and validates the samples file at `path`; errors name the key
    /// (`sample[2].r`, `bins`, …) or the file and line.
    pub fn load(path: &Path) -> Result<FitSetup> {
        let samples: FitSamples = super::read_toml_file(path)?;
        FitSetup::from_samples(&samples, path)
    }

    /// Validates `samples`, read from `path` (paths resolve against its
    /// folder).
    pub fn from_samples(samples: &FitSamples, path: &Path) -> Result<FitSetup> {
        super::bounds::check(samples)?;
        let base = path.parent().unwrap_or(Path::new("."));
        let bins = samples.bins.unwrap_or(HISTOGRAM_BINS);
        refuse_overwriting_inputs(path, base, samples)?;
        let defaults = MapDefaults {
            texel: TexelSize::Um(samples.texel_um.unwrap_or(FIT_TEXEL_UM)),
            height_unit_um: samples.height_unit_um.unwrap_or(FIT_HEIGHT_UNIT_UM),
            edge: Edge::Clamp,
        };
        let mut neutral = None;
        let mut targets = Vec::new();
        if !samples.sample.is_empty() {
            let neutral_path = samples
                .neutral
                .as_ref()
                .ok_or_else(|| Error::parameter("neutral", "is required to fit [[sample]] maps"))?;
            let map = read_map(&base.join(neutral_path), &defaults)?;
            if map.width.min(map.height) < MIN_FIT_SIDE {
                return Err(Error::parameter(
                    "neutral",
                    format!(
                        "{} is {} × {} texels; a normal histogram needs at least \
                         {MIN_FIT_SIDE} a side",
                        neutral_path.display(),
                        map.width,
                        map.height
                    ),
                ));
            }
            for (k, s) in samples.sample.iter().enumerate() {
                targets.push(target(k, s, samples, base, &map, &defaults, bins)?);
            }
            neutral = Some(map);
        }
        Ok(FitSetup {
            path: path.to_path_buf(),
            neutral,
            bins,
            targets,
            points: samples.point.clone(),
            alpha_breaks: samples.alpha_breaks.clone(),
            output: samples.output.as_ref().map(|o| base.join(o)),
        })
    }
}

/// The kernel file must not be the samples file or one of its maps.
fn refuse_overwriting_inputs(path: &Path, base: &Path, samples: &FitSamples) -> Result<()> {
    let Some(output) = &samples.output else {
        return Ok(());
    };
    let mut inputs: Vec<(String, PathBuf)> = vec![("samples file".into(), path.to_path_buf())];
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
    let inputs: Vec<(&str, &Path)> = inputs
        .iter()
        .map(|(w, p)| (w.as_str(), p.as_path()))
        .collect();
    crate::export::outputs::refuse_input_overwrite("output", &base.join(output), &inputs)
}

/// Sample `k`'s target: the histogram of its deformed map (the range from
/// the file or the data) or its histogram file (the range from the file).
fn target(
    k: usize,
    s: &FitSample,
    samples: &FitSamples,
    base: &Path,
    neutral: &DisplacementMap,
    defaults: &MapDefaults,
    bins: usize,
) -> Result<FitTarget> {
    let (histogram, range, source) = match (&s.map, &s.histogram) {
        (Some(map), None) => {
            let deformed = read_map(&base.join(map), defaults)?;
            let range = samples
                .range
                .unwrap_or_else(|| auto_range(&[&resample(neutral, s.axis, s.r), &deformed]));
            (
                NormalHistogram::of(&deformed, bins, range, [1.0, 1.0]),
                range,
                map.display().to_string(),
            )
        }
        (None, Some(file)) => {
            let range = samples.range.ok_or_else(|| {
                Error::parameter(
                    format!("sample[{k}].histogram"),
                    "needs `range` in the samples file: the half range its cells cover",
                )
            })?;
            (
                read_histogram(&base.join(file), HistogramSettings { bins, range })?,
                range,
                file.display().to_string(),
            )
        }
        _ => {
            return Err(Error::parameter(
                format!("sample[{k}]"),
                "needs exactly one of map and histogram",
            ))
        }
    };
    Ok(FitTarget {
        source,
        r: s.r,
        axis: s.axis,
        histogram,
        range,
    })
}
