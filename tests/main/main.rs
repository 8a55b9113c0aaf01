//! The integration and verification tests, one module per topic, in one
//! test binary: every binary links wgpu, faer and TetGen again, so one
//! binary instead of one per topic saves most of the suite's build time.
//! Shared helpers live in [`common`]. The `vtkhdf` cases are a binary of
//! their own (`tests/vtkhdf.rs`), built only with that feature.

mod common;

mod bad_input;
mod cli;
mod contact;
mod dcc_outputs;
mod docs;
mod doors;
mod fem_verification;
mod fuzz;
mod fuzz_doors;
mod gpu;
mod mesh_generation;
mod mesh_invariants;
mod mesh_io;
mod mesh_tools;
mod micro;
mod peer;
mod ranges;
mod readme;
mod render;
mod robustness;
mod run_api;
mod strain;
mod stress;
mod surface;
mod synth;
mod viewer;
