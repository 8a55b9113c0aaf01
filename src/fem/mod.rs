//! Corotational tetrahedral FEM.
//!
//! * [`material`]: per-region isotropic materials and Lamé parameters;
//! * [`hyperelastic`]: the energy densities (corotational linear, stable
//!   Neo-Hookean) in principal stretches;
//! * [`corotation`]: per-element rest data, rotation, forces, energy;
//! * [`nodal_pressure`]: the nodal volume term of locking-free materials.

pub mod assembly;
pub mod boundary;
pub mod coarse;
pub mod contact;
pub mod corotation;
pub mod hyperelastic;
pub mod load_steps;
pub mod material;
mod newton;
pub mod nodal_pressure;
pub mod probe;
pub mod simulation;
pub mod solve;

pub use corotation::{Corotation, RestElement, TangentKind};
pub use hyperelastic::Model;
pub use material::{Material, Volumetric};
