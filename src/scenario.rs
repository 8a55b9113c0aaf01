//! Scenario files (TOML) and their validation into a [`Setup`].
//!
//! Configuration comes in two steps (DESIGN §9.2): [`Scenario`] mirrors the
//! file — serde with `deny_unknown_fields`, every field documented with unit
//! and default — and [`Setup::from_scenario`] checks ranges, resolves paths
//! and builds or loads the mesh. Stages only ever see a `Setup`.
//!
//! Errors name the dotted key and the reason (`mesh.top_layer_mm must be > 0,
//! got -1`), and unknown keys get a suggestion (`unknown key mesh.widht_mm;
//! did you mean width_mm?`) with the line of the file.
//!
//! Relative paths: `mesh.file` is relative to the scenario file's folder (so
//! a scenario can sit beside its mesh); `output.dir` is relative to the
//! working directory, like any output flag.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
use crate::mesh::generate::{LayerSpec, PatchSpec, RefineZone, ZoneShape};
use crate::mesh::{io, TetMesh};

/// Region id of the top layer (epidermis + dermis) in generated meshes.
pub const TOP_REGION_ID: i32 = 1;
/// Region id of the bottom layer (hypodermis) in generated meshes.
pub const BOTTOM_REGION_ID: i32 = 2;

/// A whole scenario file.
#[derive(Clone, Debug, Default, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Scenario {
    /// The patch mesh: generated (default) or loaded from a file.
    #[serde(default)]
    pub mesh: MeshSection,
    /// Where and what to write.
    #[serde(default)]
    pub output: OutputSection,
}

/// `[mesh]`: a layered box patch generated with TetGen, or a mesh file.
///
/// The patch spans x ∈ [−w/2, w/2], y ∈ [−d/2, d/2], z ∈ [−h, 0] with the
/// skin surface at z = 0. All generation keys are optional; their defaults
/// are the design's skin patch (DESIGN §5.1–5.2).
#[derive(Clone, Debug, Default, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct MeshSection {
    /// Mesh file to load instead of generating: `.msh` (Gmsh 4.1 ASCII),
    /// `.node`/`.ele` or a TetGen base name. Relative to the scenario file.
    pub file: Option<PathBuf>,
    /// Patch extent in x (mm). Default 10.
    pub width_mm: Option<f64>,
    /// Patch extent in y (mm). Default 10.
    pub depth_mm: Option<f64>,
    /// Thickness of the top layer, epidermis + dermis (mm). Default 1.5.
    pub top_layer_mm: Option<f64>,
    /// Thickness of the bottom layer, hypodermis (mm); 0 for a single layer. Default 3.5.
    pub bottom_layer_mm: Option<f64>,
    /// Region name of the top layer. Default `dermis`.
    pub top_region: Option<String>,
    /// Region name of the bottom layer. Default `hypodermis`.
    pub bottom_region: Option<String>,
    /// Largest tet volume in the top layer (mm³). Default 0.004.
    pub top_max_volume_mm3: Option<f64>,
    /// Largest tet volume in the bottom layer (mm³). Default 0.02.
    pub bottom_max_volume_mm3: Option<f64>,
    /// Aim for this many tets by scaling all volume limits together. Default: none.
    pub target_tets: Option<usize>,
    /// Relative tolerance on `target_tets`. Default 0.05.
    pub target_tolerance: Option<f64>,
    /// TetGen radius–edge ratio bound (`-q`), ≥ 1.1. Default 1.5.
    pub radius_edge_max: Option<f64>,
    /// Smallest dihedral angle the mesh must reach (degrees); 0 = no check. Default 0.
    pub min_dihedral_deg: Option<f64>,
    /// Optional zone of smaller tets under the top surface.
    pub refine: Option<RefineSection>,
}

/// Shape of a refinement zone.
#[derive(Clone, Copy, Debug, Deserialize, Serialize, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
pub enum ZoneKind {
    /// Hemisphere of `radius_mm` below `center_mm` (meshed as its circumscribing box).
    Sphere,
    /// Box of `size_mm = [x, y, depth]` hanging from `center_mm`.
    Box,
}

/// `[mesh.refine]`: where tets are smaller (contact accuracy needs it).
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct RefineSection {
    /// `sphere` or `box`.
    pub shape: ZoneKind,
    /// Centre (x, y) on the top surface (mm). Default [0, 0].
    #[serde(default)]
    pub center_mm: [f64; 2],
    /// Sphere radius (mm); required for `sphere`.
    pub radius_mm: Option<f64>,
    /// Box extent [x, y, depth] (mm); required for `box`.
    pub size_mm: Option<[f64; 3]>,
    /// Largest tet volume inside the zone (mm³).
    pub max_volume_mm3: f64,
}

/// `[output]`: where results go.
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct OutputSection {
    /// Output folder, relative to the working directory. Default `out/<scenario name>`.
    pub dir: Option<PathBuf>,
    /// Write the rest mesh as `mesh.vtu`. Default true.
    pub mesh_vtu: bool,
    /// Also write the mesh as TetGen files `mesh.node/.ele/.face`. Default false.
    pub mesh_tetgen: bool,
}

impl Default for OutputSection {
    fn default() -> Self {
        OutputSection {
            dir: None,
            mesh_vtu: true,
            mesh_tetgen: false,
        }
    }
}

/// A validated scenario, ready to run.
#[derive(Clone, Debug)]
pub struct Setup {
    /// Scenario name (the file stem).
    pub name: String,
    /// The patch mesh.
    pub mesh: TetMesh,
    /// How the mesh was obtained, for logs.
    pub mesh_source: MeshSource,
    /// Output folder.
    pub output_dir: PathBuf,
    /// Write `mesh.vtu`.
    pub write_mesh_vtu: bool,
    /// Write `mesh.node/.ele/.face`.
    pub write_mesh_tetgen: bool,
}

/// Where a setup's mesh comes from.
#[derive(Clone, Debug, PartialEq)]
pub enum MeshSource {
    /// Generated with TetGen from this spec.
    Generated(PatchSpec),
    /// Read from this file.
    File(PathBuf),
}

impl Scenario {
    /// Parses scenario text; `path` names the file in errors.
    pub fn parse(text: &str, path: &Path) -> Result<Scenario> {
        let fail = |message: String| Error::Scenario {
            path: path.to_path_buf(),
            message,
        };
        let de =
            toml::Deserializer::parse(text).map_err(|e| fail(describe_toml_error(&e, text)))?;
        serde_path_to_error::deserialize(de).map_err(|e| {
            let key = e.path().to_string();
            fail(describe_schema_error(&key, e.inner(), text))
        })
    }

    /// Reads and parses a scenario file.
    pub fn load(path: &Path) -> Result<Scenario> {
        let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
        Scenario::parse(&text, path)
    }
}

fn line_of(text: &str, offset: usize) -> usize {
    1 + text[..offset.min(text.len())].matches('\n').count()
}

fn describe_toml_error(e: &toml::de::Error, text: &str) -> String {
    match e.span() {
        Some(span) => format!("line {}: {}", line_of(text, span.start), e.message().trim()),
        None => e.message().trim().to_string(),
    }
}

/// Turns a schema error into `line N: <key>: <reason>`, with a suggestion for
/// unknown keys.
fn describe_schema_error(key: &str, e: &toml::de::Error, text: &str) -> String {
    let at = e
        .span()
        .map(|s| format!("line {}: ", line_of(text, s.start)))
        .unwrap_or_default();
    let message = e.message().trim();
    if let Some((unknown, expected)) = parse_unknown_field(message) {
        let full = if key.is_empty() || key == "." || key.ends_with(&unknown) {
            key.trim_start_matches('.').to_string()
        } else {
            format!("{key}.{unknown}")
        };
        let full = if full.is_empty() {
            unknown.clone()
        } else {
            full
        };
        let hint = closest(&unknown, &expected)
            .map(|s| format!("; did you mean {s}?"))
            .unwrap_or_default();
        return format!(
            "{at}unknown key {full}{hint} (valid keys here: {})",
            expected.join(", ")
        );
    }
    if key.is_empty() || key == "." {
        format!("{at}{message}")
    } else {
        format!("{at}{key}: {message}")
    }
}

/// Extracts the unknown name and the expected names from serde's message
/// "unknown field `x`, expected one of `a`, `b`" (or "expected `a`").
fn parse_unknown_field(message: &str) -> Option<(String, Vec<String>)> {
    let rest = message.strip_prefix("unknown field `")?;
    let (name, rest) = rest.split_once('`')?;
    let expected = rest
        .split('`')
        .skip(1)
        .step_by(2)
        .map(str::to_string)
        .collect();
    Some((name.to_string(), expected))
}

/// The candidate closest to `name` by edit distance, if close enough.
fn closest(name: &str, candidates: &[String]) -> Option<String> {
    candidates
        .iter()
        .map(|c| (strsim::damerau_levenshtein(name, c), c))
        .filter(|(d, c)| *d <= 2.max(c.len() / 3))
        .min_by_key(|(d, _)| *d)
        .map(|(_, c)| c.clone())
}

/// A finite value `> 0`.
fn positive(key: &str, v: f64) -> Result<f64> {
    if v.is_finite() && v > 0.0 {
        Ok(v)
    } else {
        Err(Error::parameter(key, format!("must be > 0, got {v}")))
    }
}

/// A finite value `≥ 0`.
fn non_negative(key: &str, v: f64) -> Result<f64> {
    if v.is_finite() && v >= 0.0 {
        Ok(v)
    } else {
        Err(Error::parameter(key, format!("must be ≥ 0, got {v}")))
    }
}

fn region_name(key: &str, name: &str) -> Result<String> {
    let ok = !name.is_empty()
        && name
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-');
    if ok {
        Ok(name.to_string())
    } else {
        Err(Error::parameter(
            key,
            format!("must be a non-empty name of letters, digits, '_' or '-', got '{name}'"),
        ))
    }
}

impl MeshSection {
    /// Names of the generation keys that are set, for conflicts with `file`.
    fn generation_keys_set(&self) -> Vec<&'static str> {
        let mut keys = Vec::new();
        let mut check = |set: bool, k: &'static str| {
            if set {
                keys.push(k)
            }
        };
        check(self.width_mm.is_some(), "width_mm");
        check(self.depth_mm.is_some(), "depth_mm");
        check(self.top_layer_mm.is_some(), "top_layer_mm");
        check(self.bottom_layer_mm.is_some(), "bottom_layer_mm");
        check(self.top_region.is_some(), "top_region");
        check(self.bottom_region.is_some(), "bottom_region");
        check(self.top_max_volume_mm3.is_some(), "top_max_volume_mm3");
        check(
            self.bottom_max_volume_mm3.is_some(),
            "bottom_max_volume_mm3",
        );
        check(self.target_tets.is_some(), "target_tets");
        check(self.target_tolerance.is_some(), "target_tolerance");
        check(self.radius_edge_max.is_some(), "radius_edge_max");
        check(self.min_dihedral_deg.is_some(), "min_dihedral_deg");
        check(self.refine.is_some(), "refine");
        keys
    }

    /// Validates the generation keys into a [`PatchSpec`], applying defaults.
    pub fn patch_spec(&self) -> Result<PatchSpec> {
        let width = positive("mesh.width_mm", self.width_mm.unwrap_or(10.0))?;
        let depth = positive("mesh.depth_mm", self.depth_mm.unwrap_or(10.0))?;
        let top = positive("mesh.top_layer_mm", self.top_layer_mm.unwrap_or(1.5))?;
        let bottom = non_negative("mesh.bottom_layer_mm", self.bottom_layer_mm.unwrap_or(3.5))?;
        let top_vol = positive(
            "mesh.top_max_volume_mm3",
            self.top_max_volume_mm3.unwrap_or(0.004),
        )?;
        let bottom_vol = positive(
            "mesh.bottom_max_volume_mm3",
            self.bottom_max_volume_mm3.unwrap_or(0.02),
        )?;
        let top_name = region_name(
            "mesh.top_region",
            self.top_region.as_deref().unwrap_or("dermis"),
        )?;
        let bottom_name = region_name(
            "mesh.bottom_region",
            self.bottom_region.as_deref().unwrap_or("hypodermis"),
        )?;
        if bottom > 0.0 && top_name == bottom_name {
            return Err(Error::parameter(
                "mesh.bottom_region",
                format!("must differ from mesh.top_region, both are '{top_name}'"),
            ));
        }
        let mut layers = vec![LayerSpec {
            name: top_name,
            id: TOP_REGION_ID,
            thickness_mm: top,
            max_volume_mm3: top_vol,
        }];
        if bottom > 0.0 {
            layers.push(LayerSpec {
                name: bottom_name,
                id: BOTTOM_REGION_ID,
                thickness_mm: bottom,
                max_volume_mm3: bottom_vol,
            });
        }
        if let Some(0) = self.target_tets {
            return Err(Error::parameter("mesh.target_tets", "must be > 0, got 0"));
        }
        let tolerance = positive(
            "mesh.target_tolerance",
            self.target_tolerance.unwrap_or(0.05),
        )?;
        let spec = PatchSpec {
            width_mm: width,
            depth_mm: depth,
            layers,
            refine: self.refine.as_ref().map(RefineSection::zone).transpose()?,
            radius_edge_max: self.radius_edge_max.unwrap_or(1.5),
            min_dihedral_deg: self.min_dihedral_deg.unwrap_or(0.0),
            target_tets: self.target_tets,
            target_tolerance: tolerance,
        };
        spec.check()?;
        Ok(spec)
    }

    /// Where the mesh comes from; `base` is the scenario file's folder.
    pub fn source(&self, base: &Path) -> Result<MeshSource> {
        match &self.file {
            None => Ok(MeshSource::Generated(self.patch_spec()?)),
            Some(file) => {
                if let Some(k) = self.generation_keys_set().first() {
                    return Err(Error::parameter(
                        format!("mesh.{k}"),
                        "has no effect when mesh.file is set; remove one of them",
                    ));
                }
                Ok(MeshSource::File(base.join(file)))
            }
        }
    }
}

impl RefineSection {
    fn zone(&self) -> Result<RefineZone> {
        let key = "mesh.refine";
        for (i, c) in self.center_mm.iter().enumerate() {
            if !c.is_finite() {
                return Err(Error::parameter(
                    format!("{key}.center_mm[{i}]"),
                    format!("must be finite, got {c}"),
                ));
            }
        }
        let shape = match self.shape {
            ZoneKind::Sphere => {
                if self.size_mm.is_some() {
                    return Err(Error::parameter(
                        format!("{key}.size_mm"),
                        "applies to shape = \"box\"; a sphere takes radius_mm",
                    ));
                }
                let r = self.radius_mm.ok_or_else(|| {
                    Error::parameter(
                        format!("{key}.radius_mm"),
                        "is required for shape = \"sphere\"",
                    )
                })?;
                ZoneShape::Sphere {
                    center_mm: self.center_mm,
                    radius_mm: positive(&format!("{key}.radius_mm"), r)?,
                }
            }
            ZoneKind::Box => {
                if self.radius_mm.is_some() {
                    return Err(Error::parameter(
                        format!("{key}.radius_mm"),
                        "applies to shape = \"sphere\"; a box takes size_mm",
                    ));
                }
                let s = self.size_mm.ok_or_else(|| {
                    Error::parameter(format!("{key}.size_mm"), "is required for shape = \"box\"")
                })?;
                for (i, v) in s.iter().enumerate() {
                    positive(&format!("{key}.size_mm[{i}]"), *v)?;
                }
                ZoneShape::Box {
                    center_mm: self.center_mm,
                    size_mm: s,
                }
            }
        };
        Ok(RefineZone {
            shape,
            max_volume_mm3: positive(&format!("{key}.max_volume_mm3"), self.max_volume_mm3)?,
        })
    }
}

impl Setup {
    /// Validates a scenario and builds or loads its mesh. `path` is the
    /// scenario file (its folder resolves `mesh.file`; its stem names the run).
    pub fn from_scenario(scenario: &Scenario, path: &Path) -> Result<Setup> {
        let name = path
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| "scenario".into());
        let base = path.parent().unwrap_or(Path::new("."));
        let mesh_source = scenario.mesh.source(base)?;
        let output_dir = scenario
            .output
            .dir
            .clone()
            .unwrap_or_else(|| Path::new("out").join(&name));
        let mesh = match &mesh_source {
            MeshSource::Generated(spec) => crate::mesh::generate::generate(spec)?,
            MeshSource::File(file) => io::read_mesh(file)?,
        };
        Ok(Setup {
            name,
            mesh,
            mesh_source,
            output_dir,
            write_mesh_vtu: scenario.output.mesh_vtu,
            write_mesh_tetgen: scenario.output.mesh_tetgen,
        })
    }

    /// Loads, parses and validates a scenario file.
    pub fn load(path: &Path) -> Result<Setup> {
        Setup::from_scenario(&Scenario::load(path)?, path)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<Scenario> {
        Scenario::parse(text, Path::new("test.toml"))
    }

    #[test]
    fn unknown_key_names_path_line_and_suggestion() {
        let err = parse("[mesh]\nwidth_mm = 10\nwidht_mm = 12\n")
            .unwrap_err()
            .to_string();
        assert!(err.contains("unknown key mesh.widht_mm"), "{err}");
        assert!(err.contains("did you mean width_mm?"), "{err}");
        assert!(err.contains("line 3"), "{err}");
    }

    #[test]
    fn unknown_section_is_rejected() {
        let err = parse("[meshh]\n").unwrap_err().to_string();
        assert!(err.contains("unknown key meshh"), "{err}");
        assert!(err.contains("did you mean mesh?"), "{err}");
    }

    #[test]
    fn wrong_type_names_key() {
        let err = parse("[mesh]\nwidth_mm = \"wide\"\n")
            .unwrap_err()
            .to_string();
        assert!(err.contains("mesh.width_mm"), "{err}");
        assert!(err.contains("line 2"), "{err}");
    }

    #[test]
    fn range_errors_name_key_and_value() {
        let s = parse("[mesh]\ntop_layer_mm = -1\n").unwrap();
        let err = s.mesh.patch_spec().unwrap_err().to_string();
        assert_eq!(err, "mesh.top_layer_mm must be > 0, got -1");
        let s = parse("[mesh]\nwidth_mm = nan\n").unwrap();
        let err = s.mesh.patch_spec().unwrap_err().to_string();
        assert_eq!(err, "mesh.width_mm must be > 0, got NaN");
    }

    #[test]
    fn file_conflicts_with_generation_keys() {
        let s = parse("[mesh]\nfile = \"a.msh\"\nwidth_mm = 3\n").unwrap();
        let err = s.mesh.source(Path::new(".")).unwrap_err().to_string();
        assert!(err.starts_with("mesh.width_mm has no effect"), "{err}");
    }

    #[test]
    fn defaults_are_the_design_patch() {
        let spec = parse("").unwrap().mesh.patch_spec().unwrap();
        assert_eq!((spec.width_mm, spec.depth_mm), (10.0, 10.0));
        let t: Vec<f64> = spec.layers.iter().map(|l| l.thickness_mm).collect();
        assert_eq!(t, vec![1.5, 3.5]);
        assert_eq!(spec.layers[0].name, "dermis");
    }

    #[test]
    fn refine_zone_outside_patch_is_rejected() {
        let s = parse(
            "[mesh.refine]\nshape = \"sphere\"\ncenter_mm = [4.5, 0]\nradius_mm = 1\nmax_volume_mm3 = 0.001\n",
        )
        .unwrap();
        let err = s.mesh.patch_spec().unwrap_err().to_string();
        assert!(err.contains("strictly inside the patch"), "{err}");
    }
}
