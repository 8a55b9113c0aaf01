//! # skinpatch
//!
//! Simulates a patch of human skin pressed and dragged by a rigid probe and
//! renders its dynamic microstructure. This crate is the library behind the
//! `skinpatch` command; see ARCHITECTURE.md for the pipeline.
//!
//! Stages, one module each, lower layers first (a module never names one
//! above it):
//!
//! * [`error`]: the library's error type;
//! * [`memory`]: the memory available, for checks before large allocations;
//! * [`mesh`]: tetrahedral meshes — TetGen generation, file I/O, quality;
//! * [`fem`]: corotational tetrahedral FEM with a rigid probe;
//! * [`strain`]: principal strains per tet and the surface deformation field
//!   in texture space;
//! * [`surface`]: animated surfaces from other tools (glTF, OBJ);
//! * [`micro`]: displacement maps, kernel model, CPU reference convolution,
//!   normals, histograms, fitting and synthesis;
//! * [`imaging`]: images, colour maps and image files;
//! * [`gpu`]: wgpu compute stages mirroring `strain` and `micro`;
//! * [`render`]: the skin renderer;
//! * [`export`]: frame grids, strain images and metrics;
//! * [`scenario`]: TOML scenario → validated [`scenario::Setup`];
//! * [`pipeline`]: runs a setup frame by frame and writes its outputs;
//! * [`mod@bench`]: the benchmarks behind `skinpatch bench`;
//! * `viewer` (feature `viewer`): the interactive window.
//!
//! Units: millimetres, newtons, MPa, tonnes/mm³ and seconds inside the
//! simulation; configuration fields carry their unit in the name.
//! The library never prints; it logs through `log` and returns [`Error`].

pub mod bench;
pub mod error;
pub mod export;
pub mod fem;
pub mod gpu;
pub mod imaging;
pub mod memory;
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
