//! Corotational tetrahedral FEM (DESIGN §5.2).
//!
//! * [`material`]: per-region isotropic materials and Lamé parameters;
//! * [`corotation`]: per-element rest data, rotation, forces, energy.

pub mod assembly;
pub mod corotation;
pub mod material;

pub use corotation::{Corotation, RestElement};
pub use material::Material;
