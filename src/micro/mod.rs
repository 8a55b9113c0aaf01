//! Microstructure on the CPU (Nagano et al. 2015 §3–5): the reference
//! implementation the GPU stages are compared with.
//!
//! * [`map`]: displacement maps (f32 heights, texel size, edge handling);
//! * [`procedural`]: the seeded neutral skin generator;
//! * [`kernel`]: the 1D kernel `(1 − α)δ + αG(σ)` and the kernel model
//!   (stretch ratio → α, σ; the forehead model built in);
//! * [`mod@convolve`]: the spatially varying two-pass convolution along the
//!   strain axes, and its constant-kernel form;
//! * [`normals`]: normal maps, 64 × 64 normal histograms, slope variance;
//! * [`fit`]: fitting (α, σ) to measured deformations (eq. 7) and the
//!   piecewise-linear model to fitted points;
//! * [`moments`]: slope moments of a normal map and their mip pyramid, for
//!   prefiltered (LEAN) specular;
//! * [`roughness`]: per-axis Beckmann roughness m(r) from the kernel model
//!   (Nagano et al. 2014), for the renderer;
//! * [`synth`]: microstructure synthesis from an exemplar (Graham et al. 2013 §4,
//!   Image Analogies): a neutral map from a measured patch and a scan;
//! * [`spectrum`]: radially averaged height power spectra per octave;
//! * [`io`]: 16-bit PNG and f32 EXR files;
//! * [`tiled`]: maps held as a folder of EXR tiles with an index
//!   (face-scale maps, read and written a tile at a time).
//!
//! File I/O lives in [`io`] only; the rest is numeric.

pub mod convolve;
pub mod fit;
pub mod io;
pub mod kernel;
pub mod map;
pub mod moments;
pub mod normals;
pub mod procedural;
pub mod roughness;
pub mod spectrum;
pub mod synth;
pub mod tiled;

pub use convolve::{convolve, KernelField, PassParams};
pub use kernel::{KernelModel, KernelParams, PiecewiseLinear};
pub use map::{DisplacementMap, Edge};
pub use normals::NormalHistogram;
pub use procedural::SkinParams;
