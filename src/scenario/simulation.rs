//! Simulation sections: `[material.<region>]`, `[boundary]`, `[probe]`,
//! `[solver]` and `[time]`, and their validation into FEM types.
//!
//! Keyframes are arrays of rows whose first entry is the time in seconds:
//! `path_mm = [[0.0, 0, 0, 1.5], [1.0, 0, 0, 0.5]]`. Times must increase.

use std::collections::BTreeMap;

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use super::positive;
use crate::error::{shown, Error, Result};
use crate::fem::boundary::{
    BottomCondition, BoundaryConditions, Caliper, Keyframes, NodeSets, Prescribed, SideCondition,
};
use crate::fem::load_steps::MAX_LOAD_STEPS;
use crate::fem::material::{DENSITY_RANGE, MAX_POISSON_LOCKING_FREE, YOUNGS_KPA_RANGE};
use crate::fem::probe::{ContactMode, Probe, ProbeShape};
use crate::fem::simulation::{Dynamics, LinearSolver, NewtonSettings};
use crate::fem::solve::CgSettings;
use crate::fem::Material;
use crate::mesh::TetMesh;

/// `material.<region>.poisson_ratio` when the section leaves it out.
const POISSON_RATIO: f64 = 0.45;
/// `material.<region>.density_kg_m3` when the section leaves it out.
const DENSITY_KG_M3: f64 = 1100.0;

/// `[material.<region>]`: one region's material. Defaults: the top layer
/// (`dermis`) 150 kPa, the bottom layer (`hypodermis`) 15 kPa, ν = 0.45,
/// 1100 kg/m³. Other regions need a section.
#[derive(Clone, Debug, Default, Deserialize, Serialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct MaterialSection {
    /// Young's modulus (kPa).
    #[schemars(range(min = YOUNGS_KPA_RANGE.0, max = YOUNGS_KPA_RANGE.1))]
    pub youngs_modulus_kpa: Option<f64>,
    /// Poisson's ratio: at most 0.49 with `volumetric = "standard"`.
    #[schemars(extend("default" = POISSON_RATIO), range(min = 0.0, max = MAX_POISSON_LOCKING_FREE))]
    pub poisson_ratio: Option<f64>,
    /// Density (kg/m³).
    #[schemars(extend("default" = DENSITY_KG_M3), range(min = DENSITY_RANGE.0, max = DENSITY_RANGE.1))]
    pub density_kg_m3: Option<f64>,
    /// Energy density: `corotational` (default), `stable-neo-hookean` or
    /// `neo-hookean` (its volume term in ln J).
    pub model: Option<crate::fem::Model>,
    /// Volume measure: `standard` (default: each tet's own) or
    /// `locking-free` (nodal averages, for ν near 0.5).
    pub volumetric: Option<crate::fem::Volumetric>,
}

/// `[boundary]`.
#[derive(Clone, Debug, Default, Deserialize, Serialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct BoundarySection {
    /// `fixed` (default) or `rollers`.
    pub bottom: BottomCondition,
    /// `clamped`, `rollers` (default) or `free`.
    pub sides: SideCondition,
    /// Optional caliper on two opposite sides.
    pub caliper: Option<CaliperSection>,
    /// Prescribed displacements of named node sets.
    pub prescribed: Vec<PrescribedSection>,
}

/// `[boundary.caliper]`: frictionless jaws on the sides normal to `axis`.
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct CaliperSection {
    /// `x` or `y`.
    pub axis: CaliperAxis,
    /// Rows `[time_s, stretch_ratio]`.
    #[serde(deserialize_with = "super::arrays::exact_rows")]
    pub stretch: Vec<[f64; 2]>,
}

/// The axis a caliper's jaws are normal to.
#[derive(Clone, Copy, Debug, Deserialize, Serialize, PartialEq, Eq, schemars::JsonSchema)]
#[serde(rename_all = "lowercase")]
pub enum CaliperAxis {
    /// Jaws on the x_min and x_max sides.
    X,
    /// Jaws on the y_min and y_max sides.
    Y,
}

/// `probe.shape`.
#[derive(Clone, Copy, Debug, Deserialize, Serialize, PartialEq, Eq, schemars::JsonSchema)]
#[serde(rename_all = "lowercase")]
pub enum ProbeShapeKind {
    /// A sphere of `radius_mm`.
    Sphere,
    /// A capsule of `radius_mm` and `length_mm` along `axis`.
    Capsule,
    /// A flat cylindrical punch of `radius_mm`.
    Punch,
}

/// `probe.contact`.
#[derive(
    Clone, Copy, Debug, Default, Deserialize, Serialize, PartialEq, Eq, schemars::JsonSchema,
)]
#[serde(rename_all = "lowercase")]
pub enum ContactKind {
    /// No friction.
    #[default]
    Frictionless,
    /// Coulomb friction with `probe.friction`.
    Coulomb,
    /// The skin sticks to the probe.
    Bonded,
}

/// `time.integrator`.
#[derive(
    Clone, Copy, Debug, Default, Deserialize, Serialize, PartialEq, Eq, schemars::JsonSchema,
)]
#[serde(rename_all = "kebab-case")]
pub enum Integrator {
    /// Equilibrium at every step.
    #[default]
    QuasiStatic,
    /// Backward-Euler dynamics, one step per substep.
    ImplicitEuler,
}

/// `[[boundary.prescribed]]`: a node set moved by a displacement over time.
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct PrescribedSection {
    /// `top`, `bottom`, `x_min`, `x_max`, `y_min` or `y_max`.
    pub set: crate::fem::boundary::NodeSet,
    /// Rows `[time_s, dx_mm, dy_mm, dz_mm]`.
    #[serde(deserialize_with = "super::arrays::exact_rows")]
    pub displacement_mm: Vec<[f64; 4]>,
}

/// `[probe]`: a rigid probe on a keyframed path.
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ProbeSection {
    /// `sphere`, `capsule` or `punch`.
    pub shape: ProbeShapeKind,
    /// Radius (mm).
    #[schemars(extend("exclusiveMinimum" = 0.0, "maximum" = MAX_PROBE_MM))]
    pub radius_mm: f64,
    /// Capsule length between the end centres (mm).
    #[schemars(range(min = 0.0, max = MAX_PROBE_MM))]
    pub length_mm: Option<f64>,
    /// Rows `[time_s, x_mm, y_mm, z_mm]`: centre of the sphere or capsule,
    /// centre of the punch face.
    #[serde(deserialize_with = "super::arrays::exact_rows")]
    pub path_mm: Vec<[f64; 4]>,
    /// Capsule axis rows `[time_s, ax, ay, az]`. Default: x.
    #[serde(default, deserialize_with = "super::arrays::exact_rows_opt")]
    pub axis: Option<Vec<[f64; 4]>>,
    /// `frictionless` (default), `coulomb` or `bonded`.
    pub contact: Option<ContactKind>,
    /// Coulomb friction coefficient (with `contact = "coulomb"`).
    #[schemars(range(min = 0.0))]
    pub friction: Option<f64>,
}

/// `[solver]`.
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct SolverSection {
    /// Linear solver for Newton steps: `two-level` (PCG with block Jacobi
    /// plus a coarse rigid-mode correction, default), `cg` (block-Jacobi
    /// PCG), `factored-cg` (PCG with a reused Cholesky factor) or
    /// `direct` (sparse Cholesky).
    pub linear: LinearSolver,
    /// Relative residual at which a frame is in equilibrium.
    #[schemars(extend("exclusiveMinimum" = 0.0, "exclusiveMaximum" = 1.0))]
    pub rel_tol: f64,
    /// Newton iterations per equilibrium solve.
    #[schemars(range(min = 1))]
    pub max_newton_iterations: usize,
    /// Tightest relative tolerance of a linear (CG) solve; Newton steps use
    /// an adaptive tolerance between this and 0.1.
    #[schemars(extend("exclusiveMinimum" = 0.0, "exclusiveMaximum" = 1.0))]
    pub linear_rel_tol: f64,
    /// Iteration limit of each linear solve.
    #[schemars(range(min = 1))]
    pub max_linear_iterations: usize,
    /// Start each solve from the last state moved on by the last increment
    /// (constant velocity) instead of the last state itself. Default true.
    pub predict: bool,
    /// Largest fraction of tets that may be inverted (det F ≤ 0) in a
    /// solved frame; a frame with more stops the run with an error (the
    /// patch has turned inside out and its outputs would be meaningless).
    /// 0 refuses any inverted tet, 1 never stops.
    #[schemars(range(min = 0.0, max = 1.0))]
    pub max_inverted_fraction: f64,
    /// A tet squeezed below this volume ratio (J = det F) is counted in
    /// `volume.csv`, and the first frame in which a region has such tets
    /// logs a warning.
    #[schemars(extend("exclusiveMinimum" = 0.0), range(max = 1.0))]
    pub warn_volume_ratio: f64,
}

/// Largest mass-proportional damping `time.damping_alpha_per_s` (1/s).
pub const MAX_DAMPING_ALPHA_PER_S: f64 = 1e6;

/// Largest stiffness-proportional damping `time.damping_beta_s` (s). At
/// 100 s a dragging probe's contact set no longer settles (the drag frames
/// of `tests/fixtures/press_small.toml` fail even with their load steps
/// halved four times); up to 30 s they run at 6 and at 60 frames/s.
pub const MAX_DAMPING_BETA_S: f64 = 10.0;

impl Default for SolverSection {
    fn default() -> Self {
        SolverSection {
            linear: LinearSolver::default(),
            rel_tol: 1e-6,
            max_newton_iterations: 50,
            linear_rel_tol: 1e-4,
            max_linear_iterations: 3000,
            predict: true,
            max_inverted_fraction: 0.01,
            warn_volume_ratio: 0.5,
        }
    }
}

/// `[time]`: frames at a fixed rate; each frame may take several quasi-static
/// load substeps.
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct TimeSection {
    /// `quasi-static` (default: equilibrium at every step) or
    /// `implicit-euler` (backward-Euler dynamics, one step per substep).
    pub integrator: Integrator,
    /// Rayleigh mass-proportional damping α (1/s); beyond the largest
    /// accepted it swamps the elastic and inertial terms.
    #[schemars(range(min = 0.0, max = MAX_DAMPING_ALPHA_PER_S))]
    pub damping_alpha_per_s: f64,
    /// Rayleigh stiffness-proportional damping β (s); beyond the largest
    /// accepted the damped, nearly rigid skin holds a dragging probe's
    /// contact from settling.
    #[schemars(range(min = 0.0, max = MAX_DAMPING_BETA_S))]
    pub damping_beta_s: f64,
    /// Simulated time (s).
    #[schemars(extend("exclusiveMinimum" = 0.0))]
    pub duration_s: f64,
    /// Frames per second of simulated time.
    #[schemars(extend("exclusiveMinimum" = 0.0))]
    pub frame_rate_hz: f64,
    /// Load substeps per frame; a frame whose probe would move more than a
    /// quarter of its radius in one is split further.
    #[schemars(range(min = 1, max = MAX_LOAD_STEPS))]
    pub substeps: usize,
}

impl Default for TimeSection {
    fn default() -> Self {
        TimeSection {
            integrator: Integrator::default(),
            damping_alpha_per_s: 0.0,
            damping_beta_s: 0.0,
            duration_s: 1.0,
            frame_rate_hz: 60.0,
            substeps: 1,
        }
    }
}

/// Validated simulation settings.
#[derive(Clone, Debug)]
pub struct SimulationSetup {
    /// Material of each tet.
    pub tet_material: Vec<Material>,
    /// Boundary conditions.
    pub boundary: BoundaryConditions,
    /// Geometric node sets of the patch.
    pub sets: NodeSets,
    /// The probe, if any.
    pub probe: Option<Probe>,
    /// Newton and linear-solver settings.
    pub newton: NewtonSettings,
    /// Number of frames after the rest frame.
    pub frames: usize,
    /// Frame interval (s).
    pub frame_dt: f64,
    /// Substeps per frame.
    pub substeps: usize,
    /// Whether solves start from a constant-velocity prediction.
    pub predict: bool,
    /// Backward-Euler dynamics (step = frame interval / substeps), or quasi-static.
    pub dynamics: Option<Dynamics>,
    /// Largest fraction of inverted tets a frame may end with.
    pub max_inverted_fraction: f64,
    /// Volume ratio below which a tet counts as over-compressed.
    pub warn_volume_ratio: f64,
}

fn keyframes<const N: usize>(key: &str, rows: &[[f64; N]]) -> Result<Vec<(f64, [f64; N])>> {
    if rows.is_empty() {
        return Err(Error::parameter(key, "needs at least one row [time_s, …]"));
    }
    let mut last = f64::NEG_INFINITY;
    for (i, row) in rows.iter().enumerate() {
        if let Some(bad) = row.iter().find(|v| !v.is_finite()) {
            return Err(Error::parameter(
                format!("{key}[{i}]"),
                format!("must be finite, got {bad}"),
            ));
        }
        if row[0] <= last {
            return Err(Error::parameter(
                format!("{key}[{i}]"),
                format!("times must increase, got {} after {last}", row[0]),
            ));
        }
        last = row[0];
    }
    Ok(rows.iter().map(|r| (r[0], *r)).collect())
}

fn vector_keyframes(key: &str, rows: &[[f64; 4]]) -> Result<Keyframes<Vector3<f64>>> {
    Ok(Keyframes {
        points: keyframes(key, rows)?
            .into_iter()
            .map(|(t, r)| (t, Vector3::new(r[1], r[2], r[3])))
            .collect(),
    })
}

/// Materials per tet from the `[material.*]` sections.
pub fn materials(
    sections: &BTreeMap<String, MaterialSection>,
    mesh: &TetMesh,
) -> Result<Vec<Material>> {
    for name in sections.keys() {
        if mesh.region_by_name(name).is_none() {
            let known: Vec<&str> = mesh.regions.iter().map(|r| r.name.as_str()).collect();
            return Err(Error::parameter(
                format!("material.{name}"),
                format!(
                    "names no region of the mesh (regions: {})",
                    known.join(", ")
                ),
            ));
        }
    }
    let mut by_id = BTreeMap::new();
    for region in &mesh.regions {
        let s = sections.get(&region.name).cloned().unwrap_or_default();
        let default_kpa = match region.name.as_str() {
            "dermis" => Some(150.0),
            "hypodermis" => Some(15.0),
            _ => None,
        };
        let kpa = s.youngs_modulus_kpa.or(default_kpa).ok_or_else(|| {
            Error::parameter(
                format!("material.{}.youngs_modulus_kpa", region.name),
                "is required: the region has no default material",
            )
        })?;
        let m = Material::with_volumetric(
            &region.name,
            kpa,
            s.poisson_ratio.unwrap_or(POISSON_RATIO),
            s.density_kg_m3.unwrap_or(DENSITY_KG_M3),
            s.volumetric.unwrap_or_default(),
        )?
        .with_model(s.model.unwrap_or_default());
        by_id.insert(region.id, m);
    }
    Ok(mesh.tet_region.iter().map(|id| by_id[id]).collect())
}

impl BoundarySection {
    /// Validates into boundary conditions on `mesh`'s node sets.
    pub fn conditions(&self, sets: &NodeSets) -> Result<BoundaryConditions> {
        let (bottom, sides) = (self.bottom, self.sides);
        let caliper = match &self.caliper {
            None => None,
            Some(c) => {
                let axis = match c.axis {
                    CaliperAxis::X => 0,
                    CaliperAxis::Y => 1,
                };
                let points = keyframes("boundary.caliper.stretch", &c.stretch)?;
                for (i, (_, r)) in points.iter().enumerate() {
                    positive(&format!("boundary.caliper.stretch[{i}] ratio"), r[1])?;
                }
                Some(Caliper {
                    axis,
                    stretch: Keyframes {
                        points: points.into_iter().map(|(t, r)| (t, r[1])).collect(),
                    },
                })
            }
        };
        let mut prescribed = Vec::new();
        for (i, p) in self.prescribed.iter().enumerate() {
            let key = format!("boundary.prescribed[{i}]");
            prescribed.push(Prescribed {
                name: p.set.name().to_string(),
                nodes: sets.get(p.set).to_vec(),
                displacement: vector_keyframes(
                    &format!("{key}.displacement_mm"),
                    &p.displacement_mm,
                )?,
            });
        }
        Ok(BoundaryConditions {
            bottom,
            sides,
            caliper,
            prescribed,
        })
    }
}

/// Largest probe size and distance from the origin (mm): 100 m. A double
/// keeps about 16 digits, so beyond this the signed distances of the
/// patch's nodes (µm apart) to the probe would be round-off.
pub const MAX_PROBE_MM: f64 = 1e5;

impl ProbeSection {
    /// Validates into a [`Probe`].
    pub fn probe(&self) -> Result<Probe> {
        let radius = self.radius_mm;
        let shape = match self.shape {
            ProbeShapeKind::Sphere => ProbeShape::Sphere { radius_mm: radius },
            ProbeShapeKind::Punch => ProbeShape::Punch { radius_mm: radius },
            ProbeShapeKind::Capsule => {
                let length = self.length_mm.ok_or_else(|| {
                    Error::parameter("probe.length_mm", "is required for shape = \"capsule\"")
                })?;
                ProbeShape::Capsule {
                    radius_mm: radius,
                    length_mm: length,
                }
            }
        };
        if self.length_mm.is_some() && !matches!(shape, ProbeShape::Capsule { .. }) {
            return Err(Error::parameter(
                "probe.length_mm",
                "applies to shape = \"capsule\" only",
            ));
        }
        let mode = match (self.contact.unwrap_or_default(), self.friction) {
            (ContactKind::Frictionless, None) => ContactMode::Frictionless,
            (ContactKind::Bonded, None) => ContactMode::Bonded,
            (ContactKind::Coulomb, Some(mu)) => ContactMode::Coulomb(mu),
            (ContactKind::Coulomb, None) => {
                return Err(Error::parameter(
                    "probe.friction",
                    "is required with contact = \"coulomb\"",
                ))
            }
            (ContactKind::Frictionless | ContactKind::Bonded, Some(_)) => {
                return Err(Error::parameter(
                    "probe.friction",
                    "applies to contact = \"coulomb\" only",
                ))
            }
        };
        let axis = match &self.axis {
            Some(rows) => {
                let k = vector_keyframes("probe.axis", rows)?;
                if let Some((t, _)) = k.points.iter().find(|(_, a)| a.norm() == 0.0) {
                    return Err(Error::parameter(
                        "probe.axis",
                        format!("is zero at t = {t}"),
                    ));
                }
                k
            }
            None => Keyframes {
                points: vec![(0.0, Vector3::x())],
            },
        };
        let path = vector_keyframes("probe.path_mm", &self.path_mm)?;
        for (i, (_, p)) in path.points.iter().enumerate() {
            if p.amax() > MAX_PROBE_MM {
                return Err(Error::parameter(
                    format!("probe.path_mm[{i}]"),
                    format!(
                        "must stay within {MAX_PROBE_MM:e} mm of the origin, got [{}, {}, {}]",
                        shown(p.x),
                        shown(p.y),
                        shown(p.z)
                    ),
                ));
            }
        }
        Ok(Probe {
            shape,
            path,
            axis,
            mode,
        })
    }
}

impl SolverSection {
    /// Newton settings (their ranges checked with the file's,
    /// [`super::bounds`]).
    pub fn settings(&self) -> NewtonSettings {
        NewtonSettings {
            linear: self.linear,
            rel_tol: self.rel_tol,
            max_iterations: self.max_newton_iterations,
            cg: CgSettings {
                rel_tol: self.linear_rel_tol,
                max_iterations: self.max_linear_iterations,
            },
        }
    }
}

impl TimeSection {
    /// The integrator: `None` for quasi-static, else backward-Euler settings.
    pub fn dynamics(&self, frame_dt: f64, substeps: usize) -> Result<Option<Dynamics>> {
        match self.integrator {
            Integrator::QuasiStatic => {
                for (key, v) in [
                    ("time.damping_alpha_per_s", self.damping_alpha_per_s),
                    ("time.damping_beta_s", self.damping_beta_s),
                ] {
                    if v != 0.0 {
                        return Err(Error::parameter(
                            key,
                            format!(
                                "has no effect with integrator = \"quasi-static\" (got {}); \
                                 remove it or set integrator = \"implicit-euler\"",
                                shown(v)
                            ),
                        ));
                    }
                }
                Ok(None)
            }
            Integrator::ImplicitEuler => Ok(Some(Dynamics {
                dt: frame_dt / substeps as f64,
                alpha: self.damping_alpha_per_s,
                beta: self.damping_beta_s,
            })),
        }
    }

    /// (frames, frame interval, substeps).
    pub fn frames(&self) -> Result<(usize, f64, usize)> {
        let (duration, rate) = (self.duration_s, self.frame_rate_hz);
        let frames = (duration * rate).round() as usize;
        if frames == 0 || frames > 1_000_000 {
            return Err(Error::parameter(
                "time",
                format!(
                    "duration_s × frame_rate_hz must give 1 to 1e6 frames, got {}",
                    duration * rate
                ),
            ));
        }
        Ok((frames, 1.0 / rate, self.substeps))
    }
}
