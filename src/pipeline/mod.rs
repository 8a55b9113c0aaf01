//! Orchestration: runs a validated setup frame by frame through the stages
//! and writes its outputs. One room per job; this file only declares and
//! re-exports.
//!
//! * [`run`](run()): the FEM run — [`Run`], a run a caller steps frame by
//!   frame (probe targets, fields, files only when asked), stepped through
//!   the scenario's frames;
//! * [`surface`]: the run of an animated surface from another tool;
//! * `stepper`: the FEM frame source and its load-step rules;
//! * `micro`: where the microstructure stages run and what they write;
//! * `render`: the render engine of a run (frames, differences, MP4);
//! * [`plan`]: the output-size estimate checked before anything is written;
//! * `vtkhdf`: all frames in one VTKHDF file (feature `vtkhdf`);
//! * [`synth`]: `skinpatch synth`, microstructure synthesis from an exemplar;
//! * [`fit`](mod@fit): `skinpatch fit`, kernel parameters and a kernel model
//!   fitted to deformed maps.
//!
//! The microstructure stages run on the GPU when an adapter exists and on
//! their CPU references otherwise (see [`crate::gpu::acquire`]); both write
//! the same files.

pub mod fit;
mod micro;
mod outputs;
pub mod plan;
pub(crate) mod render;
mod run;
mod stepper;
pub mod surface;
pub mod synth;
mod vtkhdf;

pub use micro::{gpu_chain, MapDeformer};
pub use outputs::{RunKind, RunSummary};
pub use render::{roughness_curve, texel_mm};
pub use run::{run, FemRunSummary, Frame, Run};
pub use stepper::{simulate, Stepper};
