//! `[microstructure]`: the neutral displacement map, the kernel model and
//! what to write per frame.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::fit::{FIT_BINS, FIT_HEIGHT_UNIT_UM, FIT_RATIO, FIT_TEXEL_UM};
use crate::error::{Error, Result};
use crate::micro::io::{read_map, MapDefaults, TexelSize};
use crate::micro::kernel::ALPHA_RANGE;
use crate::micro::normals::HISTOGRAM_BINS;
use crate::micro::procedural::{
    generate, SkinParams, FEATURE_UM, MAX_DEPTH_UM, MAX_PORES_PER_MM2, MAX_SIZE_PX,
};
use crate::micro::tiled::TiledMap;
use crate::micro::{DisplacementMap, Edge, KernelModel, PiecewiseLinear};

/// How far the default height range of a run's PNG maps reaches beyond the
/// neutral map's, as a fraction of the neutral map's span on each side.
/// Sharpening where the skin compresses deepens the grooves and raises the
/// ridges: on the main job as first measured (`examples/press.toml` with the
/// corotational element and μ = 0.8, its strongest compression) the
/// deformed maps reached 0.20 of the neutral span above its highest texel
/// and 0.18 below its lowest.
pub const HEIGHT_RANGE_MARGIN: f64 = 0.25;

/// `microstructure.height_unit_um` when the section leaves it out.
const HEIGHT_UNIT_UM: f64 = 1.0;

/// `[microstructure]`.
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct MicrostructureSection {
    /// Neutral map file (`.png` 16-bit greyscale or `.exr`), relative to the
    /// scenario file. Default: none, generate one (`[microstructure.procedural]`).
    pub map: Option<PathBuf>,
    /// Texel size (µm) of a map file without skinpatch metadata. Default:
    /// the patch width divided by the map width.
    #[schemars(extend("exclusiveMinimum" = 0.0))]
    pub texel_um: Option<f64>,
    /// Micrometres per height unit of a map file without metadata (a map
    /// file only).
    #[schemars(extend("default" = HEIGHT_UNIT_UM, "exclusiveMinimum" = 0.0))]
    pub height_unit_um: Option<f64>,
    /// Edge handling of a map file without metadata: `wrap` or `clamp`. Default `wrap`.
    pub edge: Edge,
    /// The procedural generator's parameters (used when `map` is not set).
    pub procedural: ProceduralSection,
    /// A neutral map synthesized from an exemplar (Graham et al. 2013 §4) instead of
    /// `map` or `procedural`; the same keys as a `skinpatch synth` file's
    /// `[synthesis]`. Cached in the output folder's `cache/` by a hash of
    /// the settings and input files, so reruns do not synthesize again.
    pub synthesis: Option<super::synth::SynthesisSection>,
    /// Custom kernel model tables. Default: the forehead model (Nagano et al. 2015 eq. 8–9).
    pub kernel: Option<KernelSection>,
    /// A kernel model file written by `skinpatch fit` (its tables, as in
    /// `[microstructure.kernel]`), relative to the scenario file.
    pub kernel_file: Option<PathBuf>,
    /// Per-frame map formats: any of `png16`, `exr`. Default `["png16"]`.
    pub formats: Vec<MapFormat>,
    /// Heights (µm) that the 16-bit PNG maps of a run span, `[low, high]`:
    /// every frame (and the neutral map) shares this offset and scale, so a
    /// sequence does not flicker in tools that ignore the scale metadata;
    /// heights outside are clipped, counted and reported. Default: the
    /// neutral map's range widened by [`HEIGHT_RANGE_MARGIN`] of its span on
    /// each side.
    pub height_range_um: Option<[f64; 2]>,
    /// Also write the normal map of each deformed map. Default true.
    pub normal_maps: bool,
    /// Write the maps of every n-th frame (frame 0 always).
    #[schemars(range(min = 1))]
    pub frame_stride: usize,
    /// Write `micro/roughness.csv`: Beckmann roughness m(r) of the neutral map
    /// under the kernel model for r = 0.70 … 1.40 (Nagano et al. 2014). Default false.
    pub roughness_table: bool,
    /// Incremental frames on the GPU: a map tile is convolved again only
    /// when a surface vertex it depends on changed its stretch (`T − I`
    /// entries) or its UV frame (entries relative to the largest) by more
    /// than this since the tile was last convolved. 0 reuses only tiles
    /// whose inputs are bit-identical (same output as full frames). Default:
    /// none (every tile under the surface, every frame). The CPU reference
    /// always computes whole frames.
    #[schemars(range(min = 0.0))]
    pub incremental_tolerance: Option<f64>,
    /// Map texels per strain-raster texel along each side. 1
    /// rasterises the surface's strain at every map texel; a larger step
    /// rasterises it at one texel per step × step map texels and reads it
    /// bilinearly, which is exact inside each surface triangle and moves
    /// far fewer bytes per frame (on the GPU and the CPU alike).
    #[schemars(range(min = 1, max = 64))]
    pub strain_raster_step: usize,
}

impl Default for MicrostructureSection {
    fn default() -> Self {
        MicrostructureSection {
            map: None,
            texel_um: None,
            height_unit_um: None,
            edge: Edge::Wrap,
            procedural: ProceduralSection::default(),
            synthesis: None,
            kernel: None,
            kernel_file: None,
            formats: vec![MapFormat::Png16],
            height_range_um: None,
            normal_maps: true,
            frame_stride: 1,
            roughness_table: false,
            incremental_tolerance: None,
            strain_raster_step: 1,
        }
    }
}

/// `microstructure.procedural.size_px` when the section leaves it out: a
/// quarter of the generator's texels, enough for the main job's frames.
const SIZE_PX: usize = 1024;

/// `[microstructure.procedural]`: every [`SkinParams`] field, optional.
#[derive(Clone, Debug, Default, Deserialize, Serialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct ProceduralSection {
    /// Texels per side (the generator's own default is 2048).
    #[schemars(extend("default" = SIZE_PX), range(min = 1, max = MAX_SIZE_PX))]
    pub size_px: Option<usize>,
    /// Random seed.
    #[schemars(extend("default" = SkinParams::default().seed))]
    pub seed: Option<u64>,
    /// Mean primary groove spacing (µm).
    #[schemars(extend("default" = SkinParams::default().groove_spacing_um))]
    #[schemars(range(min = FEATURE_UM.0, max = FEATURE_UM.1))]
    pub groove_spacing_um: Option<f64>,
    /// Mean primary groove depth (µm).
    #[schemars(extend("default" = SkinParams::default().groove_depth_um))]
    #[schemars(range(min = 0.0, max = MAX_DEPTH_UM))]
    pub groove_depth_um: Option<f64>,
    /// Primary groove width (µm).
    #[schemars(extend("default" = SkinParams::default().groove_width_um))]
    #[schemars(range(min = FEATURE_UM.0, max = FEATURE_UM.1))]
    pub groove_width_um: Option<f64>,
    /// Relative spread of groove depths.
    #[schemars(extend("default" = SkinParams::default().depth_spread))]
    #[schemars(range(min = 0.0, max = 1.0))]
    pub depth_spread: Option<f64>,
    /// 1: grooves in every direction; 0: mostly along u.
    #[schemars(extend("default" = SkinParams::default().orientation_spread))]
    #[schemars(range(min = 0.0, max = 1.0))]
    pub orientation_spread: Option<f64>,
    /// Pores per mm².
    #[schemars(extend("default" = SkinParams::default().pore_density_per_mm2))]
    #[schemars(range(min = 0.0, max = MAX_PORES_PER_MM2))]
    pub pore_density_per_mm2: Option<f64>,
    /// Pore radius (µm).
    #[schemars(extend("default" = SkinParams::default().pore_radius_um))]
    #[schemars(range(min = FEATURE_UM.0, max = FEATURE_UM.1))]
    pub pore_radius_um: Option<f64>,
    /// Pore depth (µm).
    #[schemars(extend("default" = SkinParams::default().pore_depth_um))]
    #[schemars(range(min = 0.0, max = MAX_DEPTH_UM))]
    pub pore_depth_um: Option<f64>,
    /// Fine noise amplitude (µm).
    #[schemars(extend("default" = SkinParams::default().noise_amplitude_um))]
    #[schemars(range(min = 0.0, max = MAX_DEPTH_UM))]
    pub noise_amplitude_um: Option<f64>,
    /// Fine noise feature size (µm).
    #[schemars(extend("default" = SkinParams::default().noise_scale_um))]
    #[schemars(range(min = FEATURE_UM.0, max = FEATURE_UM.1))]
    pub noise_scale_um: Option<f64>,
}

/// `[microstructure.kernel]`: piecewise-linear tables `[[r, value], …]`.
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct KernelSection {
    /// α(r), through (1, 0), values in [−2, 1].
    #[serde(deserialize_with = "super::arrays::exact_rows")]
    pub alpha: Vec<[f64; 2]>,
    /// σ(r) in µm for r < 1.
    #[serde(deserialize_with = "super::arrays::exact_rows")]
    pub sigma_compression_um: Vec<[f64; 2]>,
    /// σ(r) in µm for r ≥ 1.
    #[serde(deserialize_with = "super::arrays::exact_rows")]
    pub sigma_stretch_um: Vec<[f64; 2]>,
}

/// A scenario's neutral map: held whole, or as a tiled map (a folder of
/// EXR tiles with an index, [`crate::micro::tiled`]) for maps beyond one
/// GPU buffer, which only the GPU chain of `skinpatch run` convolves.
#[derive(Clone, Debug)]
pub enum NeutralMap {
    /// The map in memory.
    Whole(DisplacementMap),
    /// The map on disk as tiles.
    Tiled(TiledMap),
}

impl NeutralMap {
    /// Texels along u and v.
    pub fn size(&self) -> (usize, usize) {
        match self {
            NeutralMap::Whole(m) => (m.width, m.height),
            NeutralMap::Tiled(t) => (t.width, t.height),
        }
    }

    /// Texel side (µm).
    pub fn texel_um(&self) -> f64 {
        match self {
            NeutralMap::Whole(m) => m.texel_um,
            NeutralMap::Tiled(t) => t.texel_um,
        }
    }

    /// The whole map; for a tiled one an error saying `needed_by` needs
    /// the map whole.
    pub fn whole(&self, needed_by: &str) -> Result<&DisplacementMap> {
        match self {
            NeutralMap::Whole(m) => Ok(m),
            NeutralMap::Tiled(t) => Err(Error::parameter(
                "microstructure.map",
                format!(
                    "is a tiled map ({}); {needed_by} needs the map whole (join it with \
                     `skinpatch tiles join`, or leave {needed_by} out)",
                    t.dir.display()
                ),
            )),
        }
    }
}

/// Validated microstructure settings.
#[derive(Clone, Debug)]
pub struct MicroSetup {
    /// The neutral map.
    pub neutral: NeutralMap,
    /// Stretch ratio → kernel parameters.
    pub model: KernelModel,
    /// Write 16-bit PNG maps.
    pub png16: bool,
    /// The heights (map units) every 16-bit PNG of the run spans; `None`
    /// for a tiled map (whose frames are EXR tiles).
    pub png_range: Option<[f64; 2]>,
    /// Write EXR maps.
    pub exr: bool,
    /// Write normal maps.
    pub normal_maps: bool,
    /// Deform and write every n-th frame.
    pub frame_stride: usize,
    /// Write the roughness table.
    pub roughness_table: bool,
    /// Incremental frames' tolerance on the GPU (none: whole frames).
    pub incremental_tolerance: Option<f64>,
    /// Map texels per strain-raster texel along each side.
    pub raster_step: usize,
}

/// A map file format of `formats` lists.
#[derive(Clone, Copy, Debug, Deserialize, Serialize, PartialEq, Eq, schemars::JsonSchema)]
#[serde(rename_all = "lowercase")]
pub enum MapFormat {
    /// 16-bit grey PNG.
    Png16,
    /// OpenEXR, one f32 channel.
    Exr,
}

fn table(points: &[[f64; 2]]) -> PiecewiseLinear {
    PiecewiseLinear {
        points: points.iter().map(|p| (p[0], p[1])).collect(),
    }
}

impl MicrostructureSection {
    /// Builds the neutral map and kernel model. `base` resolves `map`;
    /// `patch_width_mm` is the default extent of a generated map and the
    /// default texel size of a loaded one; `cache` is the folder for a
    /// synthesized map.
    pub fn setup(&self, base: &Path, patch_width_mm: f64, cache: &Path) -> Result<MicroSetup> {
        let model = self.kernel_model(base)?;
        let neutral = self.neutral_map(base, patch_width_mm, cache)?;
        let png16 = self.formats.contains(&MapFormat::Png16);
        let exr = self.formats.contains(&MapFormat::Exr);
        let png_range = match &neutral {
            NeutralMap::Whole(map) if png16 => Some(self.png_range(map)?),
            _ => None,
        };
        if let (None, Some([lo, hi])) = (png_range, self.height_range_um) {
            return Err(Error::parameter(
                "microstructure.height_range_um",
                format!(
                    "has no effect without \"png16\" in microstructure.formats and a whole \
                     (not tiled) map (got [{}, {}])",
                    crate::error::shown(lo),
                    crate::error::shown(hi)
                ),
            ));
        }
        Ok(MicroSetup {
            neutral,
            model,
            png16,
            png_range,
            exr,
            normal_maps: self.normal_maps,
            frame_stride: self.frame_stride,
            roughness_table: self.roughness_table,
            incremental_tolerance: self.incremental_tolerance,
            raster_step: self.strain_raster_step,
        })
    }

    /// The heights (map units) the PNG maps span: `height_range_um`, or the
    /// neutral map's range widened by [`HEIGHT_RANGE_MARGIN`] of its span on
    /// each side.
    fn png_range(&self, neutral: &DisplacementMap) -> Result<[f64; 2]> {
        let unit = neutral.height_unit_um;
        if let Some([lo, hi]) = self.height_range_um {
            if !(lo.is_finite() && hi.is_finite() && lo < hi) {
                return Err(Error::parameter(
                    "microstructure.height_range_um",
                    format!(
                        "must be two finite heights [low, high] with low < high (µm), got [{}, {}]",
                        crate::error::shown(lo),
                        crate::error::shown(hi)
                    ),
                ));
            }
            return Ok([lo / unit, hi / unit]);
        }
        let (lo, hi) = neutral.range();
        if !(lo.is_finite() && hi.is_finite()) {
            return Ok([0.0, 0.0]);
        }
        let margin = HEIGHT_RANGE_MARGIN * (hi - lo) as f64;
        Ok([lo as f64 - margin, hi as f64 + margin])
    }

    /// The kernel model: the table, the kernel file or the forehead's.
    fn kernel_model(&self, base: &Path) -> Result<KernelModel> {
        let (model, key) = match (&self.kernel, &self.kernel_file) {
            (Some(_), Some(_)) => {
                return Err(Error::parameter(
                    "microstructure.kernel_file",
                    "and [microstructure.kernel] both give a model; keep one",
                ))
            }
            (None, None) => (KernelModel::forehead(), "microstructure.kernel".to_string()),
            (Some(k), None) => (k.model(), "microstructure.kernel".to_string()),
            (None, Some(file)) => {
                let path = base.join(file);
                let section: KernelSection = super::read_toml_file(&path)?;
                (section.model(), path.display().to_string())
            }
        };
        model.validate(&key)?;
        Ok(model)
    }

    /// The neutral map: synthesized (and cached), a tiled or whole map
    /// file, or generated.
    fn neutral_map(&self, base: &Path, patch_width_mm: f64, cache: &Path) -> Result<NeutralMap> {
        let (edge, unit) = (self.edge, self.height_unit_um.unwrap_or(HEIGHT_UNIT_UM));
        Ok(match &self.map {
            _ if self.synthesis.is_some() => {
                if self.map.is_some() {
                    return Err(Error::parameter(
                        "microstructure.synthesis",
                        "and microstructure.map both give the neutral map; keep one",
                    ));
                }
                if let Some(k) = self.procedural_keys_set().first() {
                    return Err(Error::parameter(
                        format!("microstructure.procedural.{k}"),
                        "has no effect with [microstructure.synthesis]; remove one of them",
                    ));
                }
                if self.texel_um.is_some() {
                    return Err(Error::parameter(
                        "microstructure.texel_um",
                        "has no effect with [microstructure.synthesis] (its texel_um sets the texel)",
                    ));
                }
                if self.height_unit_um.is_some() {
                    return Err(Error::parameter(
                        "microstructure.height_unit_um",
                        "has no effect with [microstructure.synthesis] (its heights are in µm)",
                    ));
                }
                let section = self.synthesis.as_ref().expect("checked above");
                NeutralMap::Whole(section.cached_map(base, cache, "microstructure.synthesis")?)
            }
            Some(file) if crate::micro::tiled::is_tiled(&base.join(file)) => {
                self.tiled_checks()?;
                NeutralMap::Tiled(TiledMap::open(&base.join(file))?)
            }
            Some(file) => {
                if let Some(k) = self.procedural_keys_set().first() {
                    return Err(Error::parameter(
                        format!("microstructure.procedural.{k}"),
                        "has no effect when microstructure.map is set; remove one of them",
                    ));
                }
                let texel = match self.texel_um {
                    Some(t) => TexelSize::Um(t),
                    None => TexelSize::Extent(patch_width_mm),
                };
                let defaults = MapDefaults {
                    texel,
                    height_unit_um: unit,
                    edge,
                };
                NeutralMap::Whole(read_map(&base.join(file), &defaults)?)
            }
            None => {
                if let Some(t) = self.texel_um {
                    return Err(Error::parameter(
                        "microstructure.texel_um",
                        format!(
                            "has no effect without microstructure.map (got {}): a generated \
                             map's texel is the patch width over procedural.size_px",
                            crate::error::shown(t)
                        ),
                    ));
                }
                if let Some(u) = self.height_unit_um {
                    return Err(Error::parameter(
                        "microstructure.height_unit_um",
                        format!(
                            "has no effect without microstructure.map (got {}): a generated \
                             map's heights are in µm",
                            crate::error::shown(u)
                        ),
                    ));
                }
                let params = self.procedural.params(patch_width_mm);
                params.validate("microstructure.procedural")?;
                crate::gpu::precheck_map(params.size_px, params.size_px)?;
                NeutralMap::Whole(generate(&params)?)
            }
        })
    }

    /// What a tiled `map` allows: its index gives the metadata, its frames
    /// are tiled maps of EXR tiles, and the roughness table needs the map
    /// whole.
    fn tiled_checks(&self) -> Result<()> {
        if let Some(k) = self.procedural_keys_set().first() {
            return Err(Error::parameter(
                format!("microstructure.procedural.{k}"),
                "has no effect when microstructure.map is set; remove one of them",
            ));
        }
        if self.texel_um.is_some() {
            return Err(Error::parameter(
                "microstructure.texel_um",
                "has no effect with a tiled map: its index.toml gives the texel size",
            ));
        }
        if self.formats != [MapFormat::Exr] {
            return Err(Error::parameter(
                "microstructure.formats",
                format!(
                    "must be [\"exr\"] with a tiled map (its frames are tiled maps of f32 EXR \
                     tiles), got {:?}",
                    self.formats
                ),
            ));
        }
        if self.roughness_table {
            return Err(Error::parameter(
                "microstructure.roughness_table",
                "needs the map whole; a tiled map has none (join it with `skinpatch tiles join`)",
            ));
        }
        Ok(())
    }

    fn procedural_keys_set(&self) -> Vec<&'static str> {
        let p = &self.procedural;
        let mut keys = Vec::new();
        macro_rules! check {
            ($($f:ident),*) => { $( if p.$f.is_some() { keys.push(stringify!($f)); } )* };
        }
        check!(
            size_px,
            seed,
            groove_spacing_um,
            groove_depth_um,
            groove_width_um,
            depth_spread,
            orientation_spread,
            pore_density_per_mm2,
            pore_radius_um,
            pore_depth_um,
            noise_amplitude_um,
            noise_scale_um
        );
        keys
    }
}

impl ProceduralSection {
    /// Generator parameters: these values over the defaults, the map spanning
    /// the patch width.
    pub fn params(&self, patch_width_mm: f64) -> SkinParams {
        let d = SkinParams::default();
        SkinParams {
            size_px: self.size_px.unwrap_or(SIZE_PX),
            extent_mm: patch_width_mm,
            seed: self.seed.unwrap_or(d.seed),
            groove_spacing_um: self.groove_spacing_um.unwrap_or(d.groove_spacing_um),
            groove_depth_um: self.groove_depth_um.unwrap_or(d.groove_depth_um),
            groove_width_um: self.groove_width_um.unwrap_or(d.groove_width_um),
            depth_spread: self.depth_spread.unwrap_or(d.depth_spread),
            orientation_spread: self.orientation_spread.unwrap_or(d.orientation_spread),
            pore_density_per_mm2: self.pore_density_per_mm2.unwrap_or(d.pore_density_per_mm2),
            pore_radius_um: self.pore_radius_um.unwrap_or(d.pore_radius_um),
            pore_depth_um: self.pore_depth_um.unwrap_or(d.pore_depth_um),
            noise_amplitude_um: self.noise_amplitude_um.unwrap_or(d.noise_amplitude_um),
            noise_scale_um: self.noise_scale_um.unwrap_or(d.noise_scale_um),
        }
    }
}

/// A `skinpatch fit` samples file.
///
/// ```toml
/// neutral = "neutral.png"       # the undeformed map (relative to this file)
/// texel_um = 5.0                # for maps without skinpatch metadata
/// bins = 64                     # histogram cells per side (default 64)
/// range = 0.5                   # histogram half range (default 0.5)
/// output = "kernel.toml"        # where to write the model (default: none)
///
/// [[sample]]                    # a measured deformed map …
/// map = "stretched_115.png"     # … or histogram = "target.csv" (bins × bins)
/// r = 1.15
/// axis = "u"                    # "u" or "v"
///
/// [[point]]                     # … or an already fitted point
/// r = 0.73
/// alpha = -2.0
/// sigma_um = 6.5
/// ```
#[derive(Clone, Debug, Default, Deserialize, Serialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct FitSamples {
    /// The neutral map (required with `[[sample]]`s).
    pub neutral: Option<PathBuf>,
    /// Texel size of maps without metadata (µm).
    #[schemars(extend("default" = FIT_TEXEL_UM, "exclusiveMinimum" = 0.0))]
    pub texel_um: Option<f64>,
    /// Height (µm) of the brightest value (white) of a PNG without
    /// metadata, or of 1.0 in an EXR without it.
    #[schemars(extend("default" = FIT_HEIGHT_UNIT_UM, "exclusiveMinimum" = 0.0))]
    pub height_unit_um: Option<f64>,
    /// Histogram cells per side.
    #[schemars(extend("default" = HISTOGRAM_BINS), range(min = FIT_BINS.0, max = FIT_BINS.1))]
    pub bins: Option<usize>,
    /// Histogram half range: the largest tangent component of a normal the
    /// cells cover. Default: from the data, the 99.5th percentile of
    /// max(|n_x|, |n_y|) over the resampled neutral map and the sample.
    #[schemars(extend("exclusiveMinimum" = 0.0), range(max = 1.0))]
    pub range: Option<f64>,
    /// Where to write the fitted model, relative to this file.
    pub output: Option<PathBuf>,
    /// Extra knots of the fitted α(r) (stretch ratios ≠ 1): the α model is
    /// connected line segments between them, through (1, 0).
    #[serde(default)]
    pub alpha_breaks: Vec<f64>,
    /// Deformed maps to fit.
    #[serde(default)]
    pub sample: Vec<FitSample>,
    /// Points fitted elsewhere.
    #[serde(default)]
    pub point: Vec<FitPoint>,
}

/// `[[sample]]`: a deformed map or a target histogram (one of them).
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct FitSample {
    /// Deformed map file.
    pub map: Option<PathBuf>,
    /// Target normal histogram: CSV of `bins` rows (n_y ascending) of `bins`
    /// comma-separated weights (n_x ascending) over `[−range, range]²`.
    pub histogram: Option<PathBuf>,
    /// Stretch ratio along `axis`.
    #[schemars(range(min = FIT_RATIO.0, max = FIT_RATIO.1))]
    pub r: f64,
    /// `u` or `v`.
    pub axis: crate::micro::fit::Axis,
}

/// `[[point]]`.
#[derive(Clone, Copy, Debug, Deserialize, Serialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct FitPoint {
    /// Stretch ratio.
    #[schemars(range(min = FIT_RATIO.0, max = FIT_RATIO.1))]
    pub r: f64,
    /// Fitted α, in the kernel model's range.
    #[schemars(range(min = ALPHA_RANGE.0, max = ALPHA_RANGE.1))]
    pub alpha: f64,
    /// Fitted σ (µm).
    #[schemars(extend("exclusiveMinimum" = 0.0))]
    pub sigma_um: f64,
}

impl KernelSection {
    /// The model of these tables (not yet validated).
    pub fn model(&self) -> KernelModel {
        KernelModel {
            alpha: table(&self.alpha),
            sigma_compression_um: table(&self.sigma_compression_um),
            sigma_stretch_um: table(&self.sigma_stretch_um),
        }
    }

    /// The tables of `model`, for a kernel file.
    pub fn of(model: &KernelModel) -> KernelSection {
        let rows = |t: &PiecewiseLinear| t.points.iter().map(|&(r, v)| [r, v]).collect();
        KernelSection {
            alpha: rows(&model.alpha),
            sigma_compression_um: rows(&model.sigma_compression_um),
            sigma_stretch_um: rows(&model.sigma_stretch_um),
        }
    }
}
