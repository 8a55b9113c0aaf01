//! Isotropic materials per region, in the FEM's unit system (mm, N, MPa,
//! t/mm³, s): Young's modulus, Poisson's ratio, density and the energy
//! density ([`Model`]: corotational linear by default, or stable
//! Neo-Hookean; see [`super::hyperelastic`]).
//!
//! Lamé parameters from Young's modulus E and Poisson's ratio ν:
//! `μ = E / (2(1 + ν))`, `λ = E ν / ((1 + ν)(1 − 2ν))`.
//!
//! Published skin moduli vary by orders of magnitude with site, age, loading
//! rate and test method: epidermis ~1 MPa in vitro, dermis 0.1–1 MPa,
//! hypodermis a few kPa. The defaults (top layer 150 kPa, bottom 15 kPa,
//! ν = 0.45, 1100 kg/m³) are a soft, plausible middle, not a measurement.

use super::hyperelastic::{Law, Model, VolumeLimit};
use crate::error::{shown, Error, Result};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

/// Largest Poisson's ratio accepted. Linear tetrahedra lock as ν → 0.5:
/// each element's one volume constraint is enforced ever more stiffly, and
/// a mesh has too few degrees of freedom to deform at constant volume. On
/// the Hertz block the indentation force exceeds Hertz's by 1.8% at ν = 0.3,
/// −0.8% at 0.45, +7.7% at 0.49, +17% at 0.495 and +72% at 0.499, while the
/// linear iterations grow tenfold (docs/VERIFICATION.md, "Standard tets
/// near incompressibility"). Above this the answers would be wrong, not just slow; a
/// [`Volumetric::LockingFree`] material goes further.
pub const MAX_POISSON: f64 = 0.49;

/// Largest Poisson's ratio of a locking-free material
/// ([`Volumetric::LockingFree`]): λ/μ = 4998 there, about what a linear
/// solve in double precision still resolves.
pub const MAX_POISSON_LOCKING_FREE: f64 = 0.4999;

/// λ/μ a locking-free element keeps (that of ν = 1/3; see
/// [`Material::element_lambda`]).
pub const LOCKING_FREE_ELEMENT_SHARE: f64 = 2.0;

/// The highest volume ratio below which a locking-free tet's volume limit
/// acts ([`Material::element_limit`]).
pub const LIMIT_RATIO: f64 = 0.9;

/// The bulk pressure, in multiples of μ, at whose volume ratio a
/// locking-free tet's volume limit starts if that lies below
/// [`LIMIT_RATIO`]: about three times the peak Hertz pressure of a sphere
/// pressed to a contact radius of 0.7 R.
pub const LIMIT_PRESSURE: f64 = 5.0;

/// The stiffness `k` of the volume limit, in multiples of μ: its pressure
/// `k (J_t − J)²` is 10 μ at 0.1 below the limit.
pub const LIMIT_STIFFNESS: f64 = 1000.0;

/// How an element measures its change of volume.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Deserialize, Serialize, JsonSchema)]
#[serde(rename_all = "kebab-case")]
pub enum Volumetric {
    /// Each tet's own volume ratio (locks as ν → 0.5).
    #[default]
    Standard,
    /// The volume term on nodal volume ratios averaged over the tets
    /// around each node (average nodal pressure; Bonet & Burton 1998, "A
    /// simple average nodal pressure tetrahedral element for incompressible
    /// and nearly incompressible dynamic explicit applications"): one
    /// volume constraint per node instead of per tet, which a tet mesh can
    /// meet without locking. See [`super::nodal_pressure`].
    LockingFree,
}

/// Young's moduli accepted (kPa): softer than any gel to stiffer than
/// diamond. Outside, force scales leave the range the tolerances assume.
pub const YOUNGS_KPA_RANGE: (f64, f64) = (1e-6, 1e9);

/// Densities accepted (kg/m³): about that of air to more than osmium's.
pub const DENSITY_RANGE: (f64, f64) = (1.0, 1e5);

/// Material constants of one region, in FEM units.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Material {
    /// Young's modulus (MPa).
    pub youngs_mpa: f64,
    /// Poisson's ratio, 0 ≤ ν ≤ [`MAX_POISSON`].
    pub poisson: f64,
    /// Mass density (t/mm³); 1100 kg/m³ is 1.1e-9 t/mm³.
    pub density_t_mm3: f64,
    /// The energy density.
    pub model: Model,
    /// How its volume change is measured.
    pub volumetric: Volumetric,
}

impl Material {
    /// Builds a material from scenario units (kPa, kg/m³), validating ranges.
    /// `region` names the material in errors (`material.dermis.poisson …`).
    pub fn from_scenario_units(
        region: &str,
        youngs_kpa: f64,
        poisson: f64,
        density_kg_m3: f64,
    ) -> Result<Material> {
        Material::with_volumetric(
            region,
            youngs_kpa,
            poisson,
            density_kg_m3,
            Volumetric::Standard,
        )
    }

    /// [`Material::from_scenario_units`] with a volume measure: a
    /// locking-free material accepts ν up to [`MAX_POISSON_LOCKING_FREE`].
    pub fn with_volumetric(
        region: &str,
        youngs_kpa: f64,
        poisson: f64,
        density_kg_m3: f64,
        volumetric: Volumetric,
    ) -> Result<Material> {
        let key = |k: &str| format!("material.{region}.{k}");
        let (lo, hi) = YOUNGS_KPA_RANGE;
        if !(lo..=hi).contains(&youngs_kpa) {
            return Err(Error::parameter(
                key("youngs_modulus_kpa"),
                format!(
                    "must be in [{lo:e}, {hi:e}] kPa (softer than any gel to stiffer than \
                     diamond), got {}",
                    shown(youngs_kpa)
                ),
            ));
        }
        if volumetric == Volumetric::LockingFree
            && !(0.0..=MAX_POISSON_LOCKING_FREE).contains(&poisson)
        {
            return Err(Error::parameter(
                key("poisson_ratio"),
                format!(
                    "must be in [0, {MAX_POISSON_LOCKING_FREE}] for a locking-free \
                     material, got {}",
                    shown(poisson)
                ),
            ));
        }
        if volumetric == Volumetric::Standard && !(0.0..=MAX_POISSON).contains(&poisson) {
            return Err(Error::parameter(
                key("poisson_ratio"),
                format!(
                    "must be in [0, {MAX_POISSON}], got {}: closer to 0.5 the linear \
                     tetrahedra lock (at 0.499 a Hertz indentation is 72% too stiff), so \
                     nearly incompressible skin is modelled with ν ≤ {MAX_POISSON}, or \
                     with volumetric = \"locking-free\" (up to {MAX_POISSON_LOCKING_FREE})",
                    shown(poisson)
                ),
            ));
        }
        let (lo, hi) = DENSITY_RANGE;
        if !(lo..=hi).contains(&density_kg_m3) {
            return Err(Error::parameter(
                key("density_kg_m3"),
                format!(
                    "must be in [{lo}, {hi:e}] kg/m³, got {}",
                    shown(density_kg_m3)
                ),
            ));
        }
        Ok(Material {
            youngs_mpa: youngs_kpa * 1e-3,
            poisson,
            density_t_mm3: density_kg_m3 * 1e-12,
            model: Model::Corotational,
            volumetric,
        })
    }

    /// The same material with the energy density `model`.
    pub fn with_model(self, model: Model) -> Material {
        Material { model, ..self }
    }

    /// The energy density with this material's Lamé parameters.
    pub fn law(&self) -> Law {
        Law {
            model: self.model,
            mu: self.mu(),
            lambda: self.lambda(),
            limit: VolumeLimit::default(),
        }
    }

    /// The energy density a tet of this material carries itself: its law
    /// with [`Material::element_lambda`] (the whole law unless the
    /// material is locking-free).
    pub fn element_law(&self) -> Law {
        Law {
            lambda: self.element_lambda(),
            limit: self.element_limit(),
            ..self.law()
        }
    }

    /// The stiffening of a locking-free tet's own volume term below a
    /// volume ratio ([`VolumeLimit`]); none for a standard tet, whose whole
    /// volume term already holds its volume.
    ///
    /// The nodal term holds the volume of each node's patch, not of each
    /// tet, and the element's `2μ` share is too soft to stop a tet from
    /// being squeezed while its neighbours make up the volume: on the main
    /// job at ν = 0.49 surface tets under the probe fell to 0.57 of their
    /// volume while every layer kept its own to 0.1%. A real tissue this
    /// stiff in bulk cannot do that: compressing it to `J` takes a pressure
    /// `κ(1 − J)`, far above what the probe exerts. The limit therefore
    /// acts only below the volume ratio that a pressure of
    /// [`LIMIT_PRESSURE`]` μ` would reach (or [`LIMIT_RATIO`], if that is
    /// lower), where no physical state of the material lies, and adds
    /// nothing above it: the locking-free element's small-strain response
    /// (Hertz) is unchanged. Its stiffness [`LIMIT_STIFFNESS`]` μ` holds
    /// every tet of the main job at ν ≥ 0.49 above 0.8 (docs/VERIFICATION.md,
    /// "Tets that keep their volume").
    pub fn element_limit(&self) -> VolumeLimit {
        let kappa = self.lambda() + 2.0 * self.mu() / 3.0;
        let ratio = LIMIT_RATIO.min(1.0 - LIMIT_PRESSURE * self.mu() / kappa);
        match self.volumetric {
            Volumetric::LockingFree if ratio > 0.0 => VolumeLimit {
                stiffness: LIMIT_STIFFNESS * self.mu(),
                ratio,
            },
            _ => VolumeLimit::default(),
        }
    }

    /// Shear modulus μ (MPa).
    pub fn mu(&self) -> f64 {
        self.youngs_mpa / (2.0 * (1.0 + self.poisson))
    }

    /// The λ an element of this material keeps: all of it for a standard
    /// one. A locking-free one keeps `2μ` (the λ of ν = 1/3; or λ, if
    /// smaller): a share of the volume term small enough not to lock that
    /// still gives each tet's own volume a stiffness, against the volume
    /// modes a purely nodal term cannot see (tets squeezed flat while
    /// their nodes' volumes hold), as the stabilised average-nodal-pressure
    /// elements do (Bonet, Marriott & Hassan 2001). Measured on the Hertz
    /// block at ν = 0.49 and the main job at 0.499 (docs/VERIFICATION.md):
    /// without a share the force is 0.8% above Hertz and tets invert
    /// (smallest J −0.04); a `9μ` share (ν = 0.45) keeps J ≥ 0.37 but is
    /// 3.6% stiff; `2μ` gives +1.5% and J ≥ 0.13.
    pub fn element_lambda(&self) -> f64 {
        match self.volumetric {
            Volumetric::Standard => self.lambda(),
            Volumetric::LockingFree => self.lambda().min(LOCKING_FREE_ELEMENT_SHARE * self.mu()),
        }
    }

    /// The bulk coefficient of the volume term a locking-free material
    /// moves to the nodes (MPa): the λ the element does not keep
    /// ([`Material::element_lambda`]); the nodal term is `κ/2 (J̄ − 1)²`,
    /// which at small strain is the `λ/2 (Σσ̂ − 3)²` of the corotational
    /// energy and the `(λ + μ)/2 (J − 1)²` of the Neo-Hookean one (whose
    /// element keeps its μ part). Zero for a standard material.
    pub fn nodal_bulk(&self) -> f64 {
        self.lambda() - self.element_lambda()
    }

    /// Lamé's first parameter λ (MPa).
    pub fn lambda(&self) -> f64 {
        let nu = self.poisson;
        self.youngs_mpa * nu / ((1.0 + nu) * (1.0 - 2.0 * nu))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lame_parameters_and_units() {
        let m = Material::from_scenario_units("dermis", 150.0, 0.45, 1100.0).unwrap();
        assert_eq!(m.youngs_mpa, 0.15);
        assert!((m.density_t_mm3 - 1.1e-9).abs() < 1e-24);
        assert!((m.mu() - 0.15 / 2.9).abs() < 1e-15);
        assert!((m.lambda() - 0.15 * 0.45 / (1.45 * 0.1)).abs() < 1e-14);
        // E = μ(3λ + 2μ)/(λ + μ)
        let (l, mu) = (m.lambda(), m.mu());
        assert!((mu * (3.0 * l + 2.0 * mu) / (l + mu) - 0.15).abs() < 1e-14);
    }

    /// A locking-free material splits λ between the element (2μ at most)
    /// and the nodes, the whole of it in all; a standard one keeps it.
    #[test]
    fn locking_free_materials_split_the_volume_term() {
        for nu in [0.3, 0.45, 0.499] {
            let m =
                Material::with_volumetric("t", 15.0, nu, 1100.0, Volumetric::LockingFree).unwrap();
            let (le, ln) = (m.element_lambda(), m.nodal_bulk());
            assert!((le + ln - m.lambda()).abs() < 1e-12 * m.lambda());
            assert!(le <= 2.0 * m.mu() * (1.0 + 1e-12) && ln >= 0.0);
            let s = Material::from_scenario_units("t", 15.0, nu.min(0.49), 1100.0).unwrap();
            assert_eq!((s.element_lambda(), s.nodal_bulk()), (s.lambda(), 0.0));
        }
    }

    #[test]
    fn bad_values_name_region_and_key() {
        let e = Material::from_scenario_units("dermis", -1.0, 0.3, 1000.0).unwrap_err();
        assert!(
            e.to_string()
                .starts_with("material.dermis.youngs_modulus_kpa must be in [1e-6, 1e9] kPa"),
            "{e}"
        );
        assert!(e.to_string().ends_with("got -1"), "{e}");
        let e = Material::from_scenario_units("dermis", 1e300, 0.3, 1000.0).unwrap_err();
        assert!(e.to_string().ends_with("got 1e300"), "{e}");
        assert_eq!(shown(0.25), "0.25");
        assert_eq!(shown(-1e-300), "-1e-300");
        for nu in [0.5, 0.495, -0.1, f64::NAN] {
            let e = Material::from_scenario_units("fat", 1.0, nu, 1000.0).unwrap_err();
            assert!(
                e.to_string().starts_with(&format!(
                    "material.fat.poisson_ratio must be in [0, 0.49], got {nu}: "
                )),
                "{e}"
            );
            assert!(e.to_string().contains("lock"), "{e}");
        }
        assert!(Material::from_scenario_units("fat", 1.0, MAX_POISSON, 1000.0).is_ok());
        // Locking-free: up to 0.4999, and the standard refusal names it.
        let lf = |nu| Material::with_volumetric("fat", 1.0, nu, 1000.0, Volumetric::LockingFree);
        assert!(lf(MAX_POISSON_LOCKING_FREE).is_ok());
        for nu in [0.49995, 0.5, -0.1, f64::NAN] {
            let e = lf(nu).unwrap_err().to_string();
            assert!(
                e.starts_with(&format!(
                    "material.fat.poisson_ratio must be in [0, 0.4999] for a locking-free \
                     material, got {nu}"
                )),
                "{e}"
            );
        }
        let e = Material::from_scenario_units("fat", 1.0, 0.499, 1000.0).unwrap_err();
        assert!(
            e.to_string().contains("volumetric = \"locking-free\""),
            "{e}"
        );
        let e = Material::from_scenario_units("fat", 1.0, 0.3, f64::NAN).unwrap_err();
        assert_eq!(
            e.to_string(),
            "material.fat.density_kg_m3 must be in [1, 1e5] kg/m³, got NaN"
        );
    }
}
