//! # skinpatch
//!
//! Simulates a patch of human skin pressed and dragged by a rigid probe and
//! renders its dynamic microstructure. This crate is the library behind the
//! `skinpatch` command; see ARCHITECTURE.md for the pipeline.
//!
//! Stages, one module each:
//!
//! * [`scenario`]: TOML scenario → validated [`scenario::Setup`];
//! * [`mesh`]: tetrahedral meshes — TetGen generation, file I/O, quality;
//! * [`fem`]: corotational tetrahedral FEM with a rigid probe;
//! * [`strain`]: principal strains per tet and the surface deformation field
//!   in texture space;
//! * [`micro`]: displacement maps, kernel model, CPU reference convolution,
//!   normals, histograms and fitting;
//! * [`gpu`]: wgpu compute stages mirroring `strain` and `micro`;
//! * [`export`]: frame grids, strain images and metrics;
//! * [`pipeline`]: runs a setup and writes its outputs.
//!
//! Units follow DESIGN §4: millimetres, newtons, MPa, tonnes/mm³ and seconds
//! inside the simulation; configuration fields carry their unit in the name.
//! The library never prints; it logs through `log` and returns [`Error`].

pub mod bench;
pub mod error;
pub mod export;
pub mod fem;
pub mod gpu;
pub mod mesh;
pub mod micro;
pub mod pipeline;
pub mod render;
pub mod scenario;
pub mod strain;
pub mod surface;
#[cfg(feature = "viewer")]
pub mod viewer;

pub use error::{Error, Result};
