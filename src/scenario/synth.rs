//! Synthesis settings: the `[synthesis]` table of a `skinpatch synth` file
//! and `[microstructure.synthesis]` of a scenario (the same keys), and
//! their inputs read from files or generated.
//!
//! ```toml
//! [synthesis]
//! exemplar = "forehead_patch.exr"   # A′, 16-bit PNG or EXR (relative to this file)
//! exemplar_texel_um = 10.0          # for files without skinpatch metadata
//! exemplar_albedo = "forehead_albedo.png"   # optional: synthesized alongside
//! mesostructure = "scan_forehead.exr"       # B, optional (else size_px)
//! mesostructure_texel_um = 60.0
//! alpha = 0.5                       # A′/B′ against A/B neighbourhoods
//!
//! [synthesis.exemplar_generated]    # instead of `exemplar`: procedural skin
//! extent_mm = 2.56
//! [synthesis.exemplar_generated.skin]   # [microstructure.procedural] keys
//! size_px = 512
//! seed = 1
//! ```

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::micro::{MapFormat, ProceduralSection};
use crate::error::{shown, Error, Result};
use crate::micro::io::{read_map, MapDefaults, TexelSize};
use crate::micro::procedural::generate;
use crate::micro::procedural::MAX_EXTENT_MM;
use crate::micro::synth::{
    gauss, SynthInputs, SynthParams, MAX_LEVELS, MAX_PASSES, MAX_SIDE, MAX_WINDOW,
};
use crate::micro::{DisplacementMap, Edge};

/// A `skinpatch synth` file: `[synthesis]` and `[output]`.
#[derive(Clone, Debug, Default, Deserialize, Serialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct SynthFile {
    /// What to synthesize from, and how.
    pub synthesis: SynthesisSection,
    /// What to write.
    #[serde(default)]
    pub output: SynthOutputSection,
}

/// `[output]` of a synthesis file.
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct SynthOutputSection {
    /// Output folder, relative to the working directory. Default
    /// `out/<file stem>`.
    pub dir: Option<PathBuf>,
    /// Map formats: any of `exr`, `png16`. Default both.
    pub formats: Vec<MapFormat>,
    /// Also write the normal map of the result. Default true.
    pub normal_maps: bool,
    /// Write `preview.png`: exemplar, mesostructure, result and a render of
    /// the result side by side. Default true.
    pub preview: bool,
    /// Side of each preview panel (px).
    #[schemars(range(min = 16, max = 4096))]
    pub preview_px: usize,
}

impl Default for SynthOutputSection {
    fn default() -> Self {
        SynthOutputSection {
            dir: None,
            formats: vec![MapFormat::Exr, MapFormat::Png16],
            normal_maps: true,
            preview: true,
            preview_px: 384,
        }
    }
}

impl SynthOutputSection {
    /// (EXR, PNG16) from `formats`, checked.
    pub fn formats(&self) -> Result<(bool, bool)> {
        let exr = self.formats.contains(&MapFormat::Exr);
        let png = self.formats.contains(&MapFormat::Png16);
        if !(exr || png) {
            return Err(Error::parameter(
                "output.formats",
                "must name at least one of \"exr\", \"png16\"",
            ));
        }
        Ok((exr, png))
    }
}

/// `[synthesis]` / `[microstructure.synthesis]`.
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct SynthesisSection {
    /// The exemplar micro map A′ (16-bit PNG or EXR), relative to the file
    /// naming it. One of `exemplar` and `[…exemplar_generated]`.
    pub exemplar: Option<PathBuf>,
    /// Texel size (µm) of an exemplar file without skinpatch metadata
    /// (required for such files: an image editor's PNG says nothing of scale).
    #[schemars(extend("exclusiveMinimum" = 0.0))]
    pub exemplar_texel_um: Option<f64>,
    /// Micrometres per height unit of an exemplar file without metadata.
    #[schemars(extend("exclusiveMinimum" = 0.0))]
    pub exemplar_height_unit_um: f64,
    /// Edge rule of an exemplar file without metadata: `clamp` (a measured
    /// patch; default) or `wrap` (a tileable one).
    pub exemplar_edge: Edge,
    /// The exemplar's specular albedo (PNG, the exemplar's size): the
    /// output borrows the pixels its heights came from.
    pub exemplar_albedo: Option<PathBuf>,
    /// A generated exemplar instead of a file.
    pub exemplar_generated: Option<GeneratedSection>,
    /// The mesostructure map B (16-bit PNG or EXR); none: plain texture
    /// synthesis of `size_px`.
    pub mesostructure: Option<PathBuf>,
    /// Texel size (µm) of a mesostructure file without metadata (required for such files).
    #[schemars(extend("exclusiveMinimum" = 0.0))]
    pub mesostructure_texel_um: Option<f64>,
    /// Micrometres per height unit of a mesostructure file without metadata.
    #[schemars(extend("exclusiveMinimum" = 0.0))]
    pub mesostructure_height_unit_um: f64,
    /// Edge rule of a mesostructure file without metadata. Default `clamp`.
    pub mesostructure_edge: Edge,
    /// A generated mesostructure map instead of a file.
    pub mesostructure_generated: Option<GeneratedSection>,
    /// Output texel (µm). Default: the exemplar's.
    #[schemars(extend("exclusiveMinimum" = 0.0))]
    pub texel_um: Option<f64>,
    /// Output side in texels without a mesostructure map (square).
    #[schemars(range(min = 1, max = MAX_SIDE))]
    pub size_px: Option<usize>,
    /// Output edge rule: `wrap` (a torus, tiles without a seam) or `clamp`.
    /// Default: the mesostructure map's, else `wrap`.
    pub edge: Option<Edge>,
    /// σ (µm) that takes the exemplar to the mesostructure's detail.
    /// Default: one mesostructure texel.
    #[schemars(extend("exclusiveMinimum" = 0.0))]
    pub mesostructure_sigma_um: Option<f64>,
    /// σ (µm) of the low pass kept from the mesostructure. Default 4 × the above.
    #[schemars(extend("exclusiveMinimum" = 0.0))]
    pub lowpass_sigma_um: Option<f64>,
    /// Pyramid levels.
    #[schemars(extend("default" = SynthParams::default().levels), range(min = 1, max = MAX_LEVELS))]
    pub levels: Option<usize>,
    /// Window side at the coarsest level (odd, at most `window_fine`).
    #[schemars(extend("default" = SynthParams::default().window_coarse))]
    #[schemars(range(min = 3, max = MAX_WINDOW))]
    pub window_coarse: Option<usize>,
    /// Window side at the finest level (odd).
    #[schemars(extend("default" = SynthParams::default().window_fine))]
    #[schemars(range(min = 3, max = MAX_WINDOW))]
    pub window_fine: Option<usize>,
    /// Weight of the A′/B′ neighbourhoods.
    #[schemars(extend("default" = SynthParams::default().alpha), range(min = 0.0, max = 1.0))]
    pub alpha: Option<f64>,
    /// Coherence parameter κ.
    #[schemars(extend("default" = SynthParams::default().kappa), range(min = 0.0))]
    pub kappa: Option<f64>,
    /// Correction passes per level.
    #[schemars(extend("default" = SynthParams::default().passes), range(min = 1, max = MAX_PASSES))]
    pub passes: Option<usize>,
    /// PCA dimensions (0: no PCA), at most 2 × `window_coarse`². Default:
    /// the window side.
    pub pca_dims: Option<usize>,
    /// k-d tree leaves visited per query (0: exact).
    #[schemars(extend("default" = SynthParams::default().ann_leaves))]
    pub ann_leaves: Option<usize>,
    /// Random seed.
    #[schemars(extend("default" = SynthParams::default().seed))]
    pub seed: Option<u64>,
    /// Seam blending radius (texels; 0: plain copies).
    #[schemars(extend("default" = SynthParams::default().blend_radius), range(max = 8))]
    pub blend_radius: Option<usize>,
    /// Mesostructure restoring passes.
    #[schemars(extend("default" = SynthParams::default().restore_passes), range(max = 16))]
    pub restore_passes: Option<usize>,
}

impl Default for SynthesisSection {
    fn default() -> Self {
        SynthesisSection {
            exemplar: None,
            exemplar_texel_um: None,
            exemplar_height_unit_um: 1.0,
            exemplar_edge: Edge::Clamp,
            exemplar_albedo: None,
            exemplar_generated: None,
            mesostructure: None,
            mesostructure_texel_um: None,
            mesostructure_height_unit_um: 1.0,
            mesostructure_edge: Edge::Clamp,
            mesostructure_generated: None,
            texel_um: None,
            size_px: None,
            edge: None,
            mesostructure_sigma_um: None,
            lowpass_sigma_um: None,
            levels: None,
            window_coarse: None,
            window_fine: None,
            alpha: None,
            kappa: None,
            passes: None,
            pca_dims: None,
            ann_leaves: None,
            seed: None,
            blend_radius: None,
            restore_passes: None,
        }
    }
}

/// `[…_generated]`: a map from the procedural generator, optionally
/// blurred and resampled (a stand-in for a scan).
#[derive(Clone, Debug, Default, Deserialize, Serialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct GeneratedSection {
    /// Side of the map on the skin (mm).
    #[schemars(extend("exclusiveMinimum" = 0.0, "maximum" = MAX_EXTENT_MM))]
    pub extent_mm: f64,
    /// Gaussian blur (σ, µm) after generation. Default none.
    #[schemars(range(min = 0.0))]
    pub blur_um: Option<f64>,
    /// Resampled to this texel (µm) after the blur. Default: as generated.
    #[schemars(extend("exclusiveMinimum" = 0.0))]
    pub texel_um: Option<f64>,
    /// The generator's parameters (`[microstructure.procedural]` keys).
    #[serde(default)]
    pub skin: ProceduralSection,
}

/// Everything a synthesis reads, loaded.
#[derive(Clone, Debug)]
pub struct SynthSources {
    /// A′.
    pub exemplar: DisplacementMap,
    /// B.
    pub mesostructure: Option<DisplacementMap>,
    /// The exemplar's albedo.
    pub albedo: Option<image::DynamicImage>,
    /// Output texel (µm; None: the exemplar's).
    pub texel_um: Option<f64>,
    /// Output size without B.
    pub size: Option<(usize, usize)>,
    /// Output edge rule.
    pub edge: Option<Edge>,
}

impl SynthSources {
    /// The synthesis inputs over these sources.
    pub fn inputs(&self) -> SynthInputs<'_> {
        SynthInputs {
            exemplar: &self.exemplar,
            mesostructure: self.mesostructure.as_ref(),
            texel_um: self.texel_um,
            size: self.size,
            edge: self.edge,
        }
    }
}

impl SynthesisSection {
    /// The algorithm's parameters over the defaults, checked; `key` is the
    /// table's dotted name (errors name `key.field`).
    pub fn params(&self, key: &str) -> Result<SynthParams> {
        let d = SynthParams::default();
        let p = SynthParams {
            mesostructure_sigma_um: self.mesostructure_sigma_um,
            lowpass_sigma_um: self.lowpass_sigma_um,
            levels: self.levels.unwrap_or(d.levels),
            window_coarse: self.window_coarse.unwrap_or(d.window_coarse),
            window_fine: self.window_fine.unwrap_or(d.window_fine),
            alpha: self.alpha.unwrap_or(d.alpha),
            kappa: self.kappa.unwrap_or(d.kappa),
            passes: self.passes.unwrap_or(d.passes),
            pca_dims: self.pca_dims,
            ann_leaves: self.ann_leaves.unwrap_or(d.ann_leaves),
            seed: self.seed.unwrap_or(d.seed),
            blend_radius: self.blend_radius.unwrap_or(d.blend_radius),
            restore_passes: self.restore_passes.unwrap_or(d.restore_passes),
        };
        p.validate(key)?;
        Ok(p)
    }

    /// The files this section reads (relative to `base`), for change
    /// detection.
    pub fn files(&self, base: &Path) -> Vec<PathBuf> {
        [&self.exemplar, &self.mesostructure, &self.exemplar_albedo]
            .into_iter()
            .flatten()
            .map(|f| base.join(f))
            .collect()
    }

    /// Reads or generates the inputs; `key` names the table in errors.
    pub fn load(&self, base: &Path, key: &str) -> Result<SynthSources> {
        let exemplar = self
            .map_source(
                base,
                key,
                "exemplar",
                &self.exemplar,
                &self.exemplar_generated,
                self.exemplar_texel_um,
                self.exemplar_height_unit_um,
                self.exemplar_edge,
            )?
            .ok_or_else(|| {
                Error::parameter(
                    format!("{key}.exemplar"),
                    format!("is required (a map file), or [{key}.exemplar_generated]"),
                )
            })?;
        let mesostructure = self.map_source(
            base,
            key,
            "mesostructure",
            &self.mesostructure,
            &self.mesostructure_generated,
            self.mesostructure_texel_um,
            self.mesostructure_height_unit_um,
            self.mesostructure_edge,
        )?;
        let albedo = match &self.exemplar_albedo {
            None => None,
            Some(file) => {
                let path = base.join(file);
                crate::mesh::io::regular_file(&path)?;
                let img = image::open(&path)
                    .map_err(|e| Error::malformed(&path, format!("not a readable image: {e}")))?;
                if (img.width() as usize, img.height() as usize)
                    != (exemplar.width, exemplar.height)
                {
                    return Err(Error::parameter(
                        format!("{key}.exemplar_albedo"),
                        format!(
                            "{} is {} × {} px, the exemplar {} × {} texels: they must be the same size",
                            path.display(),
                            img.width(),
                            img.height(),
                            exemplar.width,
                            exemplar.height
                        ),
                    ));
                }
                Some(img)
            }
        };
        let size = match (self.size_px, &mesostructure) {
            (Some(_), Some(_)) => {
                return Err(Error::parameter(
                    format!("{key}.size_px"),
                    "has no effect with a mesostructure map: the output covers the map",
                ))
            }
            (Some(n), None) => Some((n, n)),
            (None, None) => {
                return Err(Error::parameter(
                    format!("{key}.size_px"),
                    "is required without a mesostructure map (the output side in texels)",
                ))
            }
            (None, Some(_)) => None,
        };
        let edge = self.edge;
        Ok(SynthSources {
            exemplar,
            mesostructure,
            albedo,
            texel_um: self.texel_um,
            size,
            edge,
        })
    }

    /// One map input: a file, a generated map, or none.
    #[allow(clippy::too_many_arguments)]
    fn map_source(
        &self,
        base: &Path,
        key: &str,
        name: &str,
        file: &Option<PathBuf>,
        generated: &Option<GeneratedSection>,
        texel_um: Option<f64>,
        unit: f64,
        edge: Edge,
    ) -> Result<Option<DisplacementMap>> {
        match (file, generated) {
            (Some(_), Some(_)) => Err(Error::parameter(
                format!("{key}.{name}"),
                format!("and [{key}.{name}_generated] both give the map; keep one"),
            )),
            (Some(f), None) => {
                let texel = match texel_um {
                    Some(t) => TexelSize::Um(t),
                    None => TexelSize::Required(match name {
                        "exemplar" => "exemplar_texel_um",
                        _ => "mesostructure_texel_um",
                    }),
                };
                let defaults = MapDefaults {
                    texel,
                    height_unit_um: unit,
                    edge,
                };
                read_map(&base.join(f), &defaults).map(Some)
            }
            (None, Some(g)) => {
                let k = format!("{key}.{name}_generated");
                if texel_um.is_some() {
                    return Err(Error::parameter(
                        format!("{key}.{name}_texel_um"),
                        format!("has no effect with [{k}] (its extent_mm and size give the texel)"),
                    ));
                }
                g.generate(&k).map(Some)
            }
            (None, None) => Ok(None),
        }
    }
}

impl SynthesisSection {
    /// The synthesized map for a scenario: read from `cache` when a
    /// previous run synthesized it from the same settings and input files
    /// (a 128-bit hash of both names the file), else synthesized and
    /// written there. `key` names the table in errors.
    pub fn cached_map(&self, base: &Path, cache: &Path, key: &str) -> Result<DisplacementMap> {
        let params = self.params(key)?;
        let mut hash = Fnv128::default();
        hash.write(b"skinpatch synthesis 1 ");
        hash.write(env!("CARGO_PKG_VERSION").as_bytes());
        let settings = serde_json::to_string(self)
            .map_err(|e| Error::parameter(key, format!("cannot be hashed: {e}")))?;
        hash.write(settings.as_bytes());
        for file in self.files(base) {
            let bytes = std::fs::read(&file).map_err(|e| Error::io(&file, e))?;
            hash.write(&(bytes.len() as u64).to_le_bytes());
            hash.write(&bytes);
        }
        let path = cache.join(format!("synthesis-{}.exr", hash.hex()));
        if path.is_file() {
            let defaults = MapDefaults {
                texel: TexelSize::Required("the synthesis settings"),
                height_unit_um: 1.0,
                edge: Edge::Wrap,
            };
            match read_map(&path, &defaults) {
                Ok(map) => {
                    log::info!(
                        "neutral map: synthesized earlier, read from {}",
                        path.display()
                    );
                    return Ok(map);
                }
                Err(e) => log::warn!("{e}; synthesizing the neutral map again"),
            }
        }
        let sources = self.load(base, key)?;
        let (w, h) = sources.inputs().output_size()?;
        crate::gpu::precheck_map(w, h)?;
        log::info!("neutral map: synthesizing from the exemplar (Graham et al. 2013 §4)");
        let result = crate::micro::synth::synthesize(&sources.inputs(), &params, &mut |l| {
            log::info!(
                "synthesis level {}: {} × {} texels, window {}, {:.1} s",
                l.level,
                l.size.0,
                l.size.1,
                l.window,
                l.seconds
            )
        })?;
        std::fs::create_dir_all(cache).map_err(|e| Error::io(cache, e))?;
        crate::micro::io::write_exr(&path, &result.map)?;
        Ok(result.map)
    }
}

/// FNV-1a over two 64-bit lanes with different offset bases: a stable
/// 128-bit hash (the standard library's hasher may change between Rust
/// releases, which would make every cached file look stale).
struct Fnv128([u64; 2]);

impl Default for Fnv128 {
    fn default() -> Self {
        Fnv128([0xcbf2_9ce4_8422_2325, 0x6c62_272e_07bb_0142])
    }
}

impl Fnv128 {
    fn write(&mut self, bytes: &[u8]) {
        const PRIME: u64 = 0x0000_0100_0000_01b3;
        for &b in bytes {
            for (k, h) in self.0.iter_mut().enumerate() {
                *h ^= (b ^ (k as u8 * 0x5a)) as u64;
                *h = h.wrapping_mul(PRIME);
            }
        }
    }

    fn hex(&self) -> String {
        format!("{:016x}{:016x}", self.0[0], self.0[1])
    }
}

impl GeneratedSection {
    /// The generated, blurred and resampled map; `key` names the table.
    pub fn generate(&self, key: &str) -> Result<DisplacementMap> {
        let extent = self.extent_mm;
        let params = self.skin.params(extent);
        params.validate(&format!("{key}.skin"))?;
        let mut map = generate(&params)?;
        if let Some(b) = self.blur_um {
            map = gauss(&map, b / map.texel_um);
        }
        if let Some(t) = self.texel_um {
            let side = extent * 1000.0 / t;
            let fits = (1.0..=crate::micro::synth::MAX_SIDE as f64).contains(&side.round());
            if !(t.is_finite() && t > 0.0 && fits) {
                return Err(Error::parameter(
                    format!("{key}.texel_um"),
                    format!(
                        "must be finite, > 0 and give 1 … {} texels over extent_mm, got {}",
                        crate::micro::synth::MAX_SIDE,
                        shown(t)
                    ),
                ));
            }
            let n = side.round() as usize;
            map = map.resampled(n, n);
        }
        Ok(map)
    }
}
