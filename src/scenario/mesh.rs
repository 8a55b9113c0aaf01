//! `[mesh]`: generation parameters or a mesh file.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::{positive, MeshSource, BOTTOM_REGION_ID, TOP_REGION_ID};
use crate::error::{Error, Result};
use crate::mesh::generate::{
    LayerSpec, PatchSpec, RefineZone, ZoneShape, MAX_DIHEDRAL_DEG, MIN_RADIUS_EDGE,
};

// The design's skin patch: the defaults of the generation keys.
const WIDTH_MM: f64 = 10.0;
const DEPTH_MM: f64 = 10.0;
const TOP_LAYER_MM: f64 = 1.5;
const BOTTOM_LAYER_MM: f64 = 3.5;
const TOP_REGION: &str = "dermis";
const BOTTOM_REGION: &str = "hypodermis";
const TOP_MAX_VOLUME_MM3: f64 = 0.004;
const BOTTOM_MAX_VOLUME_MM3: f64 = 0.02;
const TARGET_TOLERANCE: f64 = 0.05;
const RADIUS_EDGE_MAX: f64 = 1.5;

/// `[mesh]`: a layered box patch generated with TetGen, or a mesh file.
///
/// The patch spans x ∈ [−w/2, w/2], y ∈ [−d/2, d/2], z ∈ [−h, 0] with the
/// skin surface at z = 0. All generation keys are optional; their defaults
/// are the design's skin patch.
#[derive(Clone, Debug, Default, Deserialize, Serialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct MeshSection {
    /// Mesh file to load instead of generating: `.msh` (Gmsh 4.1 or 2.2),
    /// `.vtu`/`.vtk`, `.node`/`.ele` or a TetGen base name. Relative to the
    /// scenario file.
    pub file: Option<PathBuf>,
    /// Patch extent in x (mm).
    #[schemars(extend("default" = WIDTH_MM, "exclusiveMinimum" = 0.0))]
    pub width_mm: Option<f64>,
    /// Patch extent in y (mm).
    #[schemars(extend("default" = DEPTH_MM, "exclusiveMinimum" = 0.0))]
    pub depth_mm: Option<f64>,
    /// Thickness of the top layer, epidermis + dermis (mm).
    #[schemars(extend("default" = TOP_LAYER_MM, "exclusiveMinimum" = 0.0))]
    pub top_layer_mm: Option<f64>,
    /// Thickness of the bottom layer, hypodermis (mm); 0 for a single layer.
    #[schemars(extend("default" = BOTTOM_LAYER_MM), range(min = 0.0))]
    pub bottom_layer_mm: Option<f64>,
    /// Region name of the top layer.
    #[schemars(extend("default" = TOP_REGION))]
    pub top_region: Option<String>,
    /// Region name of the bottom layer.
    #[schemars(extend("default" = BOTTOM_REGION))]
    pub bottom_region: Option<String>,
    /// Largest tet volume in the top layer (mm³).
    #[schemars(extend("default" = TOP_MAX_VOLUME_MM3, "exclusiveMinimum" = 0.0))]
    pub top_max_volume_mm3: Option<f64>,
    /// Largest tet volume in the bottom layer (mm³).
    #[schemars(extend("default" = BOTTOM_MAX_VOLUME_MM3, "exclusiveMinimum" = 0.0))]
    pub bottom_max_volume_mm3: Option<f64>,
    /// Aim for this many tets by scaling all volume limits together. Default: none.
    #[schemars(range(min = 1))]
    pub target_tets: Option<usize>,
    /// Relative tolerance on `target_tets`.
    #[schemars(extend("default" = TARGET_TOLERANCE, "exclusiveMinimum" = 0.0))]
    pub target_tolerance: Option<f64>,
    /// TetGen radius–edge ratio bound (`-q`); TetGen may not terminate
    /// below the smallest accepted.
    #[schemars(extend("default" = RADIUS_EDGE_MAX), range(min = MIN_RADIUS_EDGE))]
    pub radius_edge_max: Option<f64>,
    /// Smallest dihedral angle the mesh must reach (degrees); 0 = no check.
    #[schemars(extend("default" = 0.0, "exclusiveMaximum" = MAX_DIHEDRAL_DEG), range(min = 0.0))]
    pub min_dihedral_deg: Option<f64>,
    /// Optional zone of smaller tets under the top surface.
    pub refine: Option<RefineSection>,
}

/// Shape of a refinement zone.
#[derive(Clone, Copy, Debug, Deserialize, Serialize, PartialEq, Eq, schemars::JsonSchema)]
#[serde(rename_all = "lowercase")]
pub enum ZoneKind {
    /// Hemisphere of `radius_mm` below `center_mm` (meshed as its circumscribing box).
    Sphere,
    /// Box of `size_mm = [x, y, depth]` hanging from `center_mm`.
    Box,
}

/// `[mesh.refine]`: where tets are smaller (contact accuracy needs it).
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct RefineSection {
    /// `sphere` or `box`.
    pub shape: ZoneKind,
    /// Centre (x, y) on the top surface (mm). Default [0, 0].
    #[serde(default)]
    #[serde(deserialize_with = "super::arrays::exact")]
    pub center_mm: [f64; 2],
    /// Sphere radius (mm); required for `sphere`.
    #[schemars(extend("exclusiveMinimum" = 0.0))]
    pub radius_mm: Option<f64>,
    /// Box extent [x, y, depth] (mm); required for `box`.
    #[serde(default, deserialize_with = "super::arrays::exact_opt")]
    pub size_mm: Option<[f64; 3]>,
    /// Largest tet volume inside the zone (mm³).
    #[schemars(extend("exclusiveMinimum" = 0.0))]
    pub max_volume_mm3: f64,
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
        let width = self.width_mm.unwrap_or(WIDTH_MM);
        let depth = self.depth_mm.unwrap_or(DEPTH_MM);
        let top = self.top_layer_mm.unwrap_or(TOP_LAYER_MM);
        let bottom = self.bottom_layer_mm.unwrap_or(BOTTOM_LAYER_MM);
        let top_vol = self.top_max_volume_mm3.unwrap_or(TOP_MAX_VOLUME_MM3);
        let bottom_vol = self.bottom_max_volume_mm3.unwrap_or(BOTTOM_MAX_VOLUME_MM3);
        let top_name = region_name(
            "mesh.top_region",
            self.top_region.as_deref().unwrap_or(TOP_REGION),
        )?;
        let bottom_name = region_name(
            "mesh.bottom_region",
            self.bottom_region.as_deref().unwrap_or(BOTTOM_REGION),
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
        let tolerance = self.target_tolerance.unwrap_or(TARGET_TOLERANCE);
        let spec = PatchSpec {
            width_mm: width,
            depth_mm: depth,
            layers,
            refine: self.refine.as_ref().map(RefineSection::zone).transpose()?,
            radius_edge_max: self.radius_edge_max.unwrap_or(RADIUS_EDGE_MAX),
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
                    radius_mm: r,
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
            max_volume_mm3: self.max_volume_mm3,
        })
    }
}
