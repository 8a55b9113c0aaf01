//! Scenario files (TOML) and their validation into a [`Setup`].
//!
//! Configuration comes in two steps: [`Scenario`] mirrors the
//! file — serde with `deny_unknown_fields`, every field documented with unit
//! and default, each number's range an attribute beside it — and
//! [`Setup::from_scenario`] checks those ranges ([`bounds`]) and the rules
//! between keys, resolves paths and builds or loads the mesh. Stages only
//! ever see a `Setup`.
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

use crate::error::{shown, Error, Result};
use crate::mesh::generate::PatchSpec;
use crate::mesh::{io, TetMesh};

mod arrays;
pub mod bounds;
pub mod fit;
mod mesh;
mod micro;
pub mod reference;
mod render;
mod simulation;
mod surface;
mod synth;

pub use mesh::{MeshSection, RefineSection, ZoneKind};
pub use micro::{
    FitPoint, FitSample, FitSamples, KernelSection, MapFormat, MicroSetup, MicrostructureSection,
    NeutralMap, ProceduralSection, HEIGHT_RANGE_MARGIN,
};
pub use render::{CameraSection, EnvironmentSection, LightSection, RenderSection};
pub use simulation::{
    BoundarySection, CaliperAxis, CaliperSection, ContactKind, Integrator, MaterialSection,
    PrescribedSection, ProbeSection, ProbeShapeKind, SimulationSetup, SolverSection, TimeSection,
};
pub use surface::{SurfaceSection, SurfaceSetup};
pub use synth::{GeneratedSection, SynthFile, SynthOutputSection, SynthSources, SynthesisSection};

/// Region id of the top layer (epidermis + dermis) in generated meshes.
pub const TOP_REGION_ID: i32 = 1;
/// Region id of the bottom layer (hypodermis) in generated meshes.
pub const BOTTOM_REGION_ID: i32 = 2;

/// A whole scenario file.
#[derive(Clone, Debug, Default, Deserialize, Serialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Scenario {
    /// The patch mesh: generated (default) or loaded from a file.
    #[serde(default)]
    pub mesh: MeshSection,
    /// Materials by region name.
    #[serde(default)]
    pub material: std::collections::BTreeMap<String, MaterialSection>,
    /// Supports, caliper and prescribed node sets.
    #[serde(default)]
    pub boundary: BoundarySection,
    /// The rigid probe (none: no contact).
    pub probe: Option<ProbeSection>,
    /// Equilibrium and linear-solver tolerances.
    #[serde(default)]
    pub solver: SolverSection,
    /// Duration, frame rate and substeps.
    #[serde(default)]
    pub time: TimeSection,
    /// Where and what to write.
    #[serde(default)]
    pub output: OutputSection,
    /// The microstructure driven by the surface strain (none: not computed).
    pub microstructure: Option<MicrostructureSection>,
    /// The rendered frames (none: nothing rendered).
    pub render: Option<RenderSection>,
    /// An animated surface from another tool in place of the FEM patch
    /// (none: the FEM patch). Runs through [`SurfaceSetup`].
    pub surface: Option<SurfaceSection>,
}

/// `[output]`: where results go.
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct OutputSection {
    /// Output folder, relative to the working directory. Default `out/<scenario name>`.
    pub dir: Option<PathBuf>,
    /// Write the rest mesh as `mesh.vtu`. Default true.
    pub mesh_vtu: bool,
    /// Also write the mesh as TetGen files `mesh.node/.ele/.face`. Default false.
    pub mesh_tetgen: bool,
    /// Write `frames/frame_NNNN.vtu` (deformed mesh, displacement, principal
    /// strains and directions, surface stretch ratios and axes) and
    /// `frames.pvd` for ParaView. Default true.
    pub frames_vtu: bool,
    /// Write every frame into one `frames.vtkhdf` (VTK's HDF5 format, read
    /// by ParaView 5.12+): the same grid and arrays as the VTUs, with the
    /// connectivity and unchanged arrays stored once; float precision and
    /// compression follow `vtu_precision` and `vtu_compression`. Needs a
    /// build with the `vtkhdf` feature. Default false.
    pub frames_vtkhdf: bool,
    /// Write PNG maps of the surface strain per frame under `strain/`
    /// (`rs_NNNN.png`, `rt_NNNN.png`, `axes_NNNN.png`). Default false.
    pub strain_images: bool,
    /// Write the surface strain per frame as float data, `strain/strain_NNNN.exr`:
    /// channels `rs`, `rt` (stretch ratios), `su`, `sv` (the s axis, a unit
    /// vector in UV with `su ≥ 0`) and `A` (1 on the surface, 0 outside,
    /// where the ratios are 1 and the axis is u). At the microstructure
    /// map's size when the scenario has a whole map, else
    /// `strain_image_px` square. Default false.
    pub strain_data: bool,
    /// Side of the strain maps in pixels (the UV square).
    #[schemars(range(min = 1, max = 8192))]
    pub strain_image_px: usize,
    /// Stretch ratios `1 ± strain_image_range` saturate the colour map.
    #[schemars(extend("exclusiveMinimum" = 0.0), range(max = 1.0))]
    pub strain_image_range: f64,
    /// Write the top surface's animation as `surface.glb` at the end of the
    /// run: one glTF morph target per frame and a step animation (Blender
    /// imports them as shape keys; a `[surface]` scenario reads it back).
    /// Default false.
    pub surface_glb: bool,
    /// Write the top surface of every frame as `surface/frame_NNNN.obj`
    /// (mm, full precision). Default false.
    pub surface_obj: bool,
    /// Float arrays and points of the VTU files: `f64` (default) or `f32`
    /// (7 significant digits, half the size before compression).
    pub vtu_precision: VtuPrecision,
    /// Storage of the VTU arrays: `zlib` (default, lossless) or `none`.
    pub vtu_compression: VtuCompression,
}

/// `output.vtu_precision`.
#[derive(
    Clone, Copy, Debug, Default, Deserialize, Serialize, PartialEq, Eq, schemars::JsonSchema,
)]
#[serde(rename_all = "lowercase")]
pub enum VtuPrecision {
    /// Float64 arrays and points.
    #[default]
    F64,
    /// Float32 (7 significant digits).
    F32,
}

/// `output.vtu_compression`.
#[derive(
    Clone, Copy, Debug, Default, Deserialize, Serialize, PartialEq, Eq, schemars::JsonSchema,
)]
#[serde(rename_all = "lowercase")]
pub enum VtuCompression {
    /// zlib blocks (lossless).
    #[default]
    Zlib,
    /// Plain arrays.
    None,
}

impl Default for OutputSection {
    fn default() -> Self {
        OutputSection {
            dir: None,
            mesh_vtu: true,
            mesh_tetgen: false,
            frames_vtu: true,
            frames_vtkhdf: false,
            strain_images: false,
            strain_data: false,
            strain_image_px: 512,
            strain_image_range: 0.25,
            surface_glb: false,
            surface_obj: false,
            vtu_precision: VtuPrecision::default(),
            vtu_compression: VtuCompression::default(),
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
    /// The per-frame outputs (shared with surface scenarios).
    pub outputs: OutputSetup,
    /// Write `mesh.vtu`.
    pub write_mesh_vtu: bool,
    /// Write `mesh.node/.ele/.face`.
    pub write_mesh_tetgen: bool,
    /// Write every frame into `frames.vtkhdf`.
    pub write_vtkhdf: bool,
    /// Write the top surface's animation as `surface.glb`.
    pub write_surface_glb: bool,
    /// Write the top surface of every frame as `surface/frame_NNNN.obj`.
    pub write_surface_obj: bool,
    /// The simulation.
    pub simulation: SimulationSetup,
}

/// What both kinds of scenario write per frame (the FEM patch and an
/// animated surface): the settings of the pipeline's one output stage.
#[derive(Clone, Debug)]
pub struct OutputSetup {
    /// Output folder.
    pub dir: PathBuf,
    /// Write `frames/frame_NNNN.vtu` and `frames.pvd`.
    pub write_frames: bool,
    /// How the VTU files store their arrays.
    pub vtu_format: crate::mesh::io::VtuFormat,
    /// Strain maps per frame, if asked for.
    pub strain_images: Option<StrainImageSettings>,
    /// The microstructure stage, if the scenario has one.
    pub micro: Option<MicroSetup>,
    /// The renderer, if the scenario has one.
    pub render: Option<crate::render::RenderSetup>,
    /// Run even when the planned output exceeds
    /// the pipeline's planned-output limit (`skinpatch run --force`).
    pub force_large_output: bool,
    /// Every file the scenario reads, as (key, path): the scenario file, its
    /// mesh, maps, kernel tables, albedo and surface. A run refuses to start
    /// when one of them is a file it would clear or write
    /// ([`Scenario::input_files`]).
    pub inputs: Vec<(String, PathBuf)>,
}

/// The per-frame strain maps: coloured previews and float data.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StrainImageSettings {
    /// Side of the previews in pixels.
    pub px: usize,
    /// Colour-map half range around a stretch ratio of 1.
    pub range: f64,
    /// Write the coloured PNG previews (`output.strain_images`).
    pub previews: bool,
    /// Width and height of the float data maps (`output.strain_data`), if asked.
    pub data: Option<[usize; 2]>,
}

impl StrainImageSettings {
    /// The data maps at the size of the microstructure's whole map, if any.
    pub fn sized_to(mut self, micro: Option<&MicroSetup>) -> StrainImageSettings {
        if let (Some(data), Some(NeutralMap::Whole(map))) =
            (self.data.as_mut(), micro.map(|m| &m.neutral))
        {
            *data = [map.width, map.height];
        }
        self
    }
}

impl OutputSection {
    /// The VTU format of `vtu_precision` and `vtu_compression`.
    fn vtu_format(&self) -> crate::mesh::io::VtuFormat {
        crate::mesh::io::VtuFormat {
            compress: self.vtu_compression == VtuCompression::Zlib,
            f32: self.vtu_precision == VtuPrecision::F32,
        }
    }

    /// Whether to write `frames.vtkhdf`; an error when asked of a build
    /// without the `vtkhdf` feature.
    fn vtkhdf(&self) -> Result<bool> {
        if self.frames_vtkhdf && !cfg!(feature = "vtkhdf") {
            return Err(Error::parameter(
                "output.frames_vtkhdf",
                "needs skinpatch built with HDF5, which this build is not: install the \
                 HDF5 library (Debian/Ubuntu: `apt-get install libhdf5-dev`) and build \
                 with `cargo build --release --features vtkhdf`, or write the VTU frames \
                 (`frames_vtu`, the default)",
            ));
        }
        Ok(self.frames_vtkhdf)
    }

    fn strain_image_settings(&self) -> Option<StrainImageSettings> {
        let (px, range) = (self.strain_image_px, self.strain_image_range);
        (self.strain_images || self.strain_data).then_some(StrainImageSettings {
            px,
            range,
            previews: self.strain_images,
            data: self.strain_data.then_some([px, px]),
        })
    }
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
    /// Every file this scenario (read from `path`) names as an input, as
    /// (key, path) with relative paths resolved as the setup resolves them:
    /// the scenario file itself, the mesh (all three TetGen files), the
    /// neutral map, the kernel file, the synthesis inputs, the albedo image
    /// and the animated surface.
    pub fn input_files(&self, path: &Path) -> Vec<(String, PathBuf)> {
        let base = path.parent().unwrap_or(Path::new("."));
        let mut inputs = vec![("scenario file".to_string(), path.to_path_buf())];
        if let Some(file) = &self.mesh.file {
            let file = base.join(file);
            let tetgen = match file.extension().and_then(|e| e.to_str()) {
                Some("node" | "ele" | "face") => Some(file.with_extension("")),
                None => Some(file.clone()),
                Some(_) => None,
            };
            match tetgen {
                Some(stem) => {
                    inputs.extend(io::tetgen_paths(&stem).map(|p| ("mesh.file".to_string(), p)))
                }
                None => inputs.push(("mesh.file".to_string(), file)),
            }
        }
        if let Some(m) = &self.microstructure {
            let mut add = |key: &str, file: &Option<PathBuf>| {
                if let Some(f) = file {
                    inputs.push((key.to_string(), base.join(f)));
                }
            };
            add("microstructure.map", &m.map);
            add("microstructure.kernel_file", &m.kernel_file);
            if let Some(synthesis) = &m.synthesis {
                for f in synthesis.files(base) {
                    inputs.push(("microstructure.synthesis".to_string(), f));
                }
            }
        }
        if let Some(r) = self.render.as_ref().filter(|r| r.albedo != "procedural") {
            inputs.push(("render.albedo".to_string(), base.join(&r.albedo)));
        }
        if let Some(surface) = &self.surface {
            inputs.push(("surface.file".to_string(), base.join(&surface.file)));
            if let Some(rest) = &surface.rest {
                inputs.push(("surface.rest".to_string(), base.join(rest)));
            }
        }
        inputs
    }

    /// Validates the simulation sections against `mesh` (with the ranges
    /// of every key, [`bounds::check`]).
    pub fn simulation(&self, mesh: &TetMesh) -> Result<SimulationSetup> {
        bounds::check(self)?;
        self.simulation_in_range(mesh)
    }

    /// [`Scenario::simulation`] once [`bounds::check`] has passed.
    fn simulation_in_range(&self, mesh: &TetMesh) -> Result<SimulationSetup> {
        let sets = crate::fem::boundary::NodeSets::of(mesh);
        let (frames, frame_dt, substeps) = self.time.frames()?;
        Ok(SimulationSetup {
            tet_material: simulation::materials(&self.material, mesh)?,
            boundary: self.boundary.conditions(&sets)?,
            sets,
            probe: self.probe.as_ref().map(ProbeSection::probe).transpose()?,
            newton: self.solver.settings(),
            frames,
            frame_dt,
            substeps,
            predict: self.solver.predict,
            dynamics: self.time.dynamics(frame_dt, substeps)?,
            max_inverted_fraction: self.solver.max_inverted_fraction,
            warn_volume_ratio: self.solver.warn_volume_ratio,
        })
    }

    /// Parses scenario text; `path` names the file in errors.
    pub fn parse(text: &str, path: &Path) -> Result<Scenario> {
        parse_toml(text, path)
    }

    /// Reads and parses a scenario file.
    pub fn load(path: &Path) -> Result<Scenario> {
        Scenario::load_with(path, &[])
    }

    /// Reads a scenario file and applies `overrides` (`key=value` with a
    /// dotted key such as `probe.friction` or `render.lights.0.intensity`,
    /// and a TOML value; a value that is not TOML is taken as a string).
    /// The file is validated on its own first (errors name its lines), then
    /// with the overrides (errors name the key as `--set key`).
    pub fn load_with(path: &Path, overrides: &[String]) -> Result<Scenario> {
        load_with(path, overrides)
    }
}

/// Reads a TOML file of type `T` (any of the project's files: scenarios,
/// synthesis files) and applies `overrides` (`key=value` with a dotted key
/// and a TOML value; a value that is not TOML is taken as a string). The
/// file is validated on its own first (errors name its lines), then with
/// the overrides (errors name the key as `--set key`).
pub fn load_with<T: serde::de::DeserializeOwned>(path: &Path, overrides: &[String]) -> Result<T> {
    let text = crate::mesh::io::read_input_text(path)?;
    let parsed: T = parse_toml(&text, path)?;
    if overrides.is_empty() {
        return Ok(parsed);
    }
    let fail = |key: Option<&str>, message: String| Error::Scenario {
        path: path.to_path_buf(),
        message,
        key: key.map(str::to_string),
        line: None,
    };
    let mut table: toml::Table =
        toml::from_str(&text).map_err(|e| fail(None, describe_toml_error(&e, &text)))?;
    for o in overrides {
        if o.contains(['\n', '\r']) {
            return Err(fail(
                None,
                format!(
                    "--set {}: the override spans lines; give each key its own --set",
                    o.lines().next().unwrap_or("")
                ),
            ));
        }
        let (key, value) = o
            .split_once('=')
            .ok_or_else(|| fail(None, format!("--set {o}: expected key=value")))?;
        let key = key.trim();
        set_key(&mut table, key, override_value(value.trim()))
            .map_err(|reason| fail(Some(key), format!("--set {key}: {reason}")))?;
    }
    // A value tree has no spans, so the message names the key without a
    // line.
    serde_path_to_error::deserialize(toml::Value::Table(table)).map_err(|e| {
        let key = e.path().to_string();
        let message = format!("with --set: {}", describe_schema_error(&key, e.inner(), ""));
        fail(schema_key(&key, e.inner()).as_deref(), message)
    })
}

/// `--output` and `--set output.dir=…` both name the output folder: one
/// of them may be given, not both (one would be dropped without a word).
pub fn check_output_flag(output: Option<&Path>, overrides: &[String]) -> Result<()> {
    let sets_dir = overrides.iter().any(|o| {
        o.split_once('=')
            .is_some_and(|(k, _)| k.trim() == "output.dir")
    });
    match output {
        Some(dir) if sets_dir => Err(Error::parameter(
            "--output",
            format!(
                "({}) and --set output.dir both name the output folder; give one",
                dir.display()
            ),
        )),
        _ => Ok(()),
    }
}

/// Parses TOML text of type `T`; errors name `path`, the key and line.
fn parse_toml<T: serde::de::DeserializeOwned>(text: &str, path: &Path) -> Result<T> {
    let fail = |e: &toml::de::Error, key: Option<String>, message: String| Error::Scenario {
        path: path.to_path_buf(),
        message,
        key,
        line: e.span().map(|s| line_of(text, s.start)),
    };
    let de = toml::Deserializer::parse(text)
        .map_err(|e| fail(&e, None, describe_toml_error(&e, text)))?;
    serde_path_to_error::deserialize(de).map_err(|e| {
        let key = e.path().to_string();
        fail(
            e.inner(),
            schema_key(&key, e.inner()),
            describe_schema_error(&key, e.inner(), text),
        )
    })
}

/// The full dotted key of a schema error at `key`: for an unknown key, the
/// key itself (serde's path stops at its table); `None` at the top level.
fn schema_key(key: &str, e: &toml::de::Error) -> Option<String> {
    let key = key.trim_start_matches('.');
    let full = match parse_unknown_field(e.message().trim()) {
        Some((unknown, _)) if key.is_empty() => unknown,
        Some((unknown, _)) if !key.ends_with(&unknown) => format!("{key}.{unknown}"),
        _ => key.to_string(),
    };
    (!full.is_empty()).then_some(full)
}

/// The 1-based line of the dotted `key` (`material.dermis.poisson_ratio`,
/// `render.lights.0.intensity`) in TOML `text`: where its value is written,
/// or for a table, its header; `None` when the text does not parse or does
/// not hold the key. Lets a caller point a validation error
/// ([`Error::Parameter`], which names the key) at its line.
pub fn key_line(text: &str, key: &str) -> Option<usize> {
    use toml::de::{DeTable, DeValue};
    let doc = DeTable::parse(text).ok()?;
    let mut table = doc.get_ref();
    let mut parts = key.split('.').peekable();
    while let Some(part) = parts.next() {
        let (k, v) = table.get_key_value(part)?;
        let mut value = v;
        // Numeric parts index arrays (of tables).
        while let (DeValue::Array(items), Some(next)) = (value.get_ref(), parts.peek()) {
            let Ok(index) = next.parse::<usize>() else {
                break;
            };
            parts.next();
            value = items.get(index)?;
        }
        match (value.get_ref(), parts.peek()) {
            (DeValue::Table(inner), Some(_)) => table = inner,
            (_, None) => {
                let span = if matches!(value.get_ref(), DeValue::Table(_)) {
                    k.span()
                } else {
                    value.span()
                };
                return Some(line_of(text, span.start));
            }
            _ => return None,
        }
    }
    None
}

/// The TOML value of an override's right-hand side, or the text itself as
/// a string when it is not TOML (`--set probe.contact=frictionless`).
fn override_value(text: &str) -> toml::Value {
    toml::from_str::<toml::Table>(&format!("v = {text}"))
        .ok()
        .and_then(|mut t| t.remove("v"))
        .unwrap_or_else(|| toml::Value::String(text.to_string()))
}

/// Sets the dotted `key` of `table` to `value`, creating tables on the way;
/// a numeric part indexes an array (of tables).
fn set_key(
    table: &mut toml::Table,
    key: &str,
    value: toml::Value,
) -> std::result::Result<(), String> {
    let parts: Vec<&str> = key.split('.').collect();
    if parts.iter().any(|p| p.is_empty()) {
        return Err("the key has an empty part".into());
    }
    let mut node: &mut toml::Value = table
        .entry(parts[0])
        .or_insert_with(|| toml::Value::Table(Default::default()));
    if parts.len() == 1 {
        *node = value;
        return Ok(());
    }
    for (k, part) in parts.iter().enumerate().skip(1) {
        let last = k == parts.len() - 1;
        node = match node {
            toml::Value::Table(t) => {
                if last {
                    t.insert(part.to_string(), value);
                    return Ok(());
                }
                t.entry(*part)
                    .or_insert_with(|| toml::Value::Table(Default::default()))
            }
            toml::Value::Array(a) => {
                let index: usize = part.parse().map_err(|_| {
                    format!(
                        "{} is a list: expected an index, got {part}",
                        parts[..k].join(".")
                    )
                })?;
                let len = a.len();
                let slot = a.get_mut(index).ok_or_else(|| {
                    format!("{} has {len} entries, no [{index}]", parts[..k].join("."))
                })?;
                if last {
                    *slot = value;
                    return Ok(());
                }
                slot
            }
            _ => return Err(format!("{} is a value, not a table", parts[..k].join("."))),
        };
    }
    Ok(())
}

/// Reads and deserialises a small TOML file (kernel files, fit samples);
/// errors name the file and line.
pub fn read_toml_file<T: serde::de::DeserializeOwned>(path: &Path) -> Result<T> {
    let text = crate::mesh::io::read_input_text(path)?;
    let fail = |e: &toml::de::Error, message: String| Error::Parse {
        path: path.to_path_buf(),
        line: e.span().map_or(0, |s| line_of(&text, s.start)),
        message,
    };
    let de = toml::Deserializer::parse(&text).map_err(|e| fail(&e, e.message().trim().into()))?;
    serde_path_to_error::deserialize(de).map_err(|e| {
        let key = e.path().to_string();
        fail(e.inner(), schema_message(&key, e.inner().message().trim()))
    })
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
    format!("{at}{}", schema_message(key, e.message().trim()))
}

/// A schema error's message at `key`: unknown keys with the valid ones and
/// the closest, unknown values of enum-like keys with the accepted ones.
fn schema_message(key: &str, message: &str) -> String {
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
            "unknown key {full}{hint} (valid keys here: {})",
            expected.join(", ")
        );
    }
    if let Some((value, expected)) = parse_unknown_variant(message) {
        let hint = closest(&value, &expected)
            .map(|s| format!("; did you mean {s}?"))
            .unwrap_or_default();
        let listed: Vec<String> = expected.iter().map(|e| format!("\"{e}\"")).collect();
        let listed = match listed.split_last() {
            Some((last, [])) => last.clone(),
            Some((last, rest)) => format!("{} or {last}", rest.join(", ")),
            None => String::new(),
        };
        return format!("{key} must be {listed}, got \"{value}\"{hint}");
    }
    if key.is_empty() || key == "." {
        message.to_string()
    } else {
        format!("{key}: {message}")
    }
}

/// Extracts the unknown name and the expected names from serde's message
/// "unknown field `x`, expected one of `a`, `b`" (or "expected `a`").
fn parse_unknown_field(message: &str) -> Option<(String, Vec<String>)> {
    let rest = message.strip_prefix("unknown field `")?;
    let (name, rest) = rest.split_once('`')?;
    Some((name.to_string(), backticked(rest)))
}

/// Extracts the value and the expected names from serde's message
/// "unknown variant `x`, expected one of `a`, `b`" (or "expected `a` or
/// `b`"): an enum-like key given a value it does not know.
fn parse_unknown_variant(message: &str) -> Option<(String, Vec<String>)> {
    let rest = message.strip_prefix("unknown variant `")?;
    let (value, rest) = rest.rsplit_once("`, expected")?;
    Some((value.to_string(), backticked(rest)))
}

/// The names between backticks in `text`, in order.
fn backticked(text: &str) -> Vec<String> {
    text.split('`')
        .skip(1)
        .step_by(2)
        .map(str::to_string)
        .collect()
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
pub(crate) fn positive(key: &str, v: f64) -> Result<f64> {
    if v.is_finite() && v > 0.0 {
        Ok(v)
    } else {
        Err(Error::parameter(
            key,
            format!("must be > 0, got {}", shown(v)),
        ))
    }
}

impl Setup {
    /// Validates a scenario and builds or loads its mesh. `path` is the
    /// scenario file (its folder resolves `mesh.file`; its stem names the run).
    pub fn from_scenario(scenario: &Scenario, path: &Path) -> Result<Setup> {
        bounds::check(scenario)?;
        if scenario.surface.is_some() {
            return Err(Error::parameter(
                "surface",
                "makes this an animated-surface scenario: `skinpatch run` runs it (from Rust: \
                 SurfaceSetup and pipeline::surface::run); the viewer, `bench` and Setup \
                 simulate the FEM patch",
            ));
        }
        let name = path
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| "scenario".into());
        let base = path.parent().unwrap_or(Path::new("."));
        let mesh_source = scenario.mesh.source(base)?;
        let strain_images = scenario.output.strain_image_settings();
        let output_dir = scenario
            .output
            .dir
            .clone()
            .unwrap_or_else(|| Path::new("out").join(&name));
        let mesh = match &mesh_source {
            MeshSource::Generated(spec) => crate::mesh::generate::generate(spec)?,
            MeshSource::File(file) => io::read_mesh(file)?,
        };
        if mesh.top.is_empty() {
            let needs = [
                ("probe contact ([probe])", scenario.probe.is_some()),
                (
                    "strain maps (output.strain_images, output.strain_data)",
                    strain_images.is_some(),
                ),
                (
                    "the microstructure ([microstructure])",
                    scenario.microstructure.is_some(),
                ),
                ("rendering ([render])", scenario.render.is_some()),
                (
                    "the surface export (output.surface_glb, output.surface_obj)",
                    scenario.output.surface_glb || scenario.output.surface_obj,
                ),
            ];
            if let Some((stage, _)) = needs.iter().find(|(_, asked)| *asked) {
                return Err(Error::InvalidMesh {
                    origin: match &mesh_source {
                        MeshSource::Generated(_) => "generated mesh".to_string(),
                        MeshSource::File(f) => f.display().to_string(),
                    },
                    message: format!(
                        "has no top surface (no boundary face marked {} and none facing +z at \
                         the highest z), which {stage} needs; mark the skin faces with {} or \
                         remove that section",
                        crate::mesh::markers::TOP,
                        crate::mesh::markers::TOP
                    ),
                });
            }
        }
        let simulation = scenario.simulation_in_range(&mesh)?;
        let micro = match &scenario.microstructure {
            Some(m) => {
                let (lo, hi) = mesh.bounds();
                Some(m.setup(base, hi.x - lo.x, &output_dir.join("cache"))?)
            }
            None => None,
        };
        let render = scenario
            .render
            .as_ref()
            .map(|r| r.setup_in_range(base, micro.is_some()))
            .transpose()?;
        if let (Some(m), Some(_)) = (&micro, &render) {
            // The renderer samples the deformed map's normals as one texture.
            m.neutral.whole("[render]")?;
        }
        Ok(Setup {
            name,
            mesh,
            mesh_source,
            outputs: OutputSetup {
                dir: output_dir,
                write_frames: scenario.output.frames_vtu,
                vtu_format: scenario.output.vtu_format(),
                strain_images: strain_images.map(|s| s.sized_to(micro.as_ref())),
                micro,
                render,
                force_large_output: false,
                inputs: scenario.input_files(path),
            },
            write_mesh_vtu: scenario.output.mesh_vtu,
            write_mesh_tetgen: scenario.output.mesh_tetgen,
            write_vtkhdf: scenario.output.vtkhdf()?,
            write_surface_glb: scenario.output.surface_glb,
            write_surface_obj: scenario.output.surface_obj,
            simulation,
        })
    }

    /// Loads, parses and validates a scenario file: paths in it are taken
    /// relative to the file, and a bad value is an error naming its key.
    ///
    /// ```
    /// # fn main() -> skinpatch::Result<()> {
    /// use skinpatch::scenario::{Scenario, Setup};
    /// let path = std::path::Path::new("tests/fixtures/press_small.toml");
    /// let setup = Setup::load(path)?;
    /// assert_eq!(setup.simulation.frames + 1, 7); // 1 s at 6 Hz, and t = 0
    /// assert!(setup.mesh.num_tets() > 3000);
    ///
    /// // Edit the scenario first, then validate it like a file.
    /// let mut scenario = Scenario::load(path)?;
    /// scenario.probe.as_mut().unwrap().friction = Some(-0.5);
    /// let err = Setup::from_scenario(&scenario, path).unwrap_err();
    /// assert!(err.to_string().contains("friction"), "{err}");
    /// # Ok(())
    /// # }
    /// ```
    pub fn load(path: &Path) -> Result<Setup> {
        Setup::from_scenario(&Scenario::load(path)?, path)
    }
}

#[cfg(test)]
mod tests;
