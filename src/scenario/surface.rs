//! `[surface]`: an animated surface from another tool in place of the FEM
//! patch, validated into a [`SurfaceSetup`] (which the pipeline's surface
//! run takes).

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::{OutputSetup, Scenario};
use crate::error::{Error, Result};
use crate::surface::{AnimatedSurface, LengthUnit, ReadOptions, UvLayout, UvPiece};

/// `surface.frame_rate_hz` when the file leaves it out.
const FRAME_RATE_HZ: f64 = 30.0;

/// `[surface]`: the rest mesh with UVs and its animation.
#[derive(Clone, Debug, Default, Deserialize, Serialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct SurfaceSection {
    /// The surface: `.gltf`/`.glb` (mesh with `TEXCOORD_0`, morph targets
    /// and an animation of their weights), one `.obj`, or an OBJ sequence
    /// named by a pattern (`frames/frame_%04d.obj`). Relative to the
    /// scenario file.
    pub file: PathBuf,
    /// OBJ: the rest mesh, when it is not the first frame.
    pub rest: Option<PathBuf>,
    /// glTF: the node whose mesh is read. Default: the only node with a mesh.
    pub node: Option<String>,
    /// glTF: the animation to sample. Default: the first that animates the
    /// node's morph weights.
    pub animation: Option<String>,
    /// Length unit of the file: `"mm"`, `"cm"`, `"m"` or `"in"`. Default
    /// `"m"` for glTF (the format's unit); required for OBJ.
    pub units: Option<LengthUnit>,
    /// Frames per second: the sampling of a glTF animation, the rate of an
    /// OBJ sequence.
    #[schemars(extend("default" = FRAME_RATE_HZ, "exclusiveMinimum" = 0.0))]
    pub frame_rate_hz: Option<f64>,
    /// UVs outside [0, 1]: `"unit"` (refused, default), `"udim"` (UDIM
    /// tiles, maps per tile) or `"wrap"` (one repeating texture).
    pub uv_layout: Option<UvLayout>,
}

/// A validated surface scenario, ready to run.
#[derive(Clone, Debug)]
pub struct SurfaceSetup {
    /// Scenario name (the file stem).
    pub name: String,
    /// The surface and its frames (mm).
    pub surface: AnimatedSurface,
    /// How its UVs are laid out.
    pub layout: UvLayout,
    /// The maps: one per UDIM tile, or the unit square.
    pub pieces: Vec<UvPiece>,
    /// The per-frame outputs (shared with FEM scenarios).
    pub outputs: OutputSetup,
    /// Write the rest surface as `surface.vtu`.
    pub write_surface_vtu: bool,
}

impl SurfaceSetup {
    /// Validates a scenario with a `[surface]` and reads the surface.
    /// `path` is the scenario file (its folder resolves `surface.file`).
    pub fn from_scenario(scenario: &Scenario, path: &Path) -> Result<SurfaceSetup> {
        super::bounds::check(scenario)?;
        let Some(section) = &scenario.surface else {
            return Err(Error::parameter(
                "surface",
                "is missing: this scenario simulates the FEM patch (use Setup)",
            ));
        };
        refuse_fem_sections(scenario, path)?;
        let name = path
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| "scenario".into());
        let base = path.parent().unwrap_or(Path::new("."));
        let output_dir = scenario
            .output
            .dir
            .clone()
            .unwrap_or_else(|| Path::new("out").join(&name));
        let rate = section.frame_rate_hz.unwrap_or(FRAME_RATE_HZ);
        let layout = section.uv_layout.unwrap_or_default();
        let options = ReadOptions {
            mm_per_unit: section.units.map(LengthUnit::mm),
            frame_rate_hz: rate,
            node: section.node.clone(),
            animation: section.animation.clone(),
            rest: section.rest.as_ref().map(|r| base.join(r)),
        };
        let file = base.join(&section.file);
        let is_obj = file.to_string_lossy().to_lowercase().ends_with(".obj");
        if !is_obj && section.rest.is_some() {
            return Err(Error::parameter(
                "surface.rest",
                "applies to OBJ files only (a glTF's rest is its mesh without morph targets)",
            ));
        }
        if is_obj && (section.node.is_some() || section.animation.is_some()) {
            return Err(Error::parameter(
                if section.node.is_some() {
                    "surface.node"
                } else {
                    "surface.animation"
                },
                "applies to glTF files only",
            ));
        }
        let surface = AnimatedSurface::read(&file, &options)?;
        let pieces = surface.pieces(layout)?;
        let micro = match &scenario.microstructure {
            Some(m) => {
                let micro = m.setup(base, surface.mm_per_uv(), &output_dir.join("cache"))?;
                if let super::NeutralMap::Tiled(_) = micro.neutral {
                    return Err(Error::parameter(
                        "microstructure.map",
                        "is a tiled map, which [surface] scenarios do not take; use one map \
                         file (UDIM tiles each get their own deformed map from it)",
                    ));
                }
                Some(micro)
            }
            None => None,
        };
        let render = scenario
            .render
            .as_ref()
            .map(|r| r.setup_in_range(base, micro.is_some()))
            .transpose()?;
        if render.is_some() && layout != UvLayout::Unit {
            return Err(Error::parameter(
                "surface.uv_layout",
                format!(
                    "is \"{}\", but [render] draws surfaces whose UVs lie in [0, 1] only; \
                     remove [render] or lay the UVs out in the unit square",
                    layout.name()
                ),
            ));
        }
        Ok(SurfaceSetup {
            name,
            surface,
            layout,
            pieces,
            outputs: OutputSetup {
                dir: output_dir,
                write_frames: scenario.output.frames_vtu,
                vtu_format: scenario.output.vtu_format(),
                strain_images: scenario
                    .output
                    .strain_image_settings()
                    .map(|s| s.sized_to(micro.as_ref())),
                micro,
                render,
                force_large_output: false,
                inputs: scenario.input_files(path),
            },
            write_surface_vtu: scenario.output.mesh_vtu,
        })
    }

    /// Loads and validates a surface scenario file.
    pub fn load(path: &Path) -> Result<SurfaceSetup> {
        SurfaceSetup::from_scenario(&Scenario::load(path)?, path)
    }
}

/// The FEM's sections mean nothing beside `[surface]` (its animation
/// replaces the simulation): each one the file at `path` holds, even with
/// its defaults, or that differs from its default (through `--set`), is an
/// error naming it.
fn refuse_fem_sections(s: &Scenario, path: &Path) -> Result<()> {
    let in_file: Vec<String> = std::fs::read_to_string(path)
        .ok()
        .and_then(|text| text.parse::<toml::Table>().ok())
        .map(|t| t.keys().cloned().collect())
        .unwrap_or_default();
    let written = |key: &str| in_file.iter().any(|k| k == key);
    let given = [
        ("mesh", written("mesh") || s.mesh != Default::default()),
        ("material", written("material") || !s.material.is_empty()),
        (
            "boundary",
            written("boundary") || s.boundary != Default::default(),
        ),
        ("probe", s.probe.is_some()),
        (
            "solver",
            written("solver") || s.solver != Default::default(),
        ),
        ("time", written("time") || s.time != Default::default()),
        ("output.mesh_tetgen", s.output.mesh_tetgen),
        ("output.frames_vtkhdf", s.output.frames_vtkhdf),
        ("output.surface_glb", s.output.surface_glb),
        ("output.surface_obj", s.output.surface_obj),
    ];
    match given.iter().find(|(_, g)| *g) {
        Some((key, _)) => Err(Error::parameter(
            *key,
            "has no meaning beside [surface]: the surface's own animation replaces the FEM \
             patch (its frame rate is surface.frame_rate_hz); remove it",
        )),
        None => Ok(()),
    }
}
