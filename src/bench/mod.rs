//! Benchmarks behind `skinpatch bench`, in one room: [`fem`] (the solver's
//! frames and time split), [`micro`] (the microstructure stages on the GPU
//! and their CPU references at several map sizes), [`render`] (the whole
//! frame) and [`gpu`] (every GPU figure in one report). Figures, not tests:
//! the CLI prints them and docs/PERFORMANCE.md records them with their
//! commands.

pub mod fem;
pub mod gpu;
pub mod micro;
pub mod render;

pub use fem::{bench_fem, BenchFigures};
pub use micro::*;
pub use render::{bench_render, RenderBench};
