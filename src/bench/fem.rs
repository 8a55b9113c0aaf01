//! `skinpatch bench fem`: the FEM frames of a scenario without outputs,
//! with the solver's time split.

use std::time::Instant;

use crate::error::Result;
use crate::pipeline::simulate;
use crate::scenario::Setup;

/// Figures of one benchmark run (see [`bench_fem`]).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct BenchFigures {
    /// Frames simulated (after the rest frame).
    pub frames: usize,
    /// Wall time of those frames (s).
    pub wall_s: f64,
    /// Newton iterations.
    pub newton_iterations: usize,
    /// Linear-solver iterations.
    pub linear_iterations: usize,
    /// Solver time split.
    pub timings: crate::fem::simulation::Timings,
}

/// Simulates the first `frames` frames of `setup` without writing anything
/// and reports where the time went.
pub fn bench_fem(setup: &Setup, frames: usize) -> Result<BenchFigures> {
    let mut setup = setup.clone();
    setup.simulation.frames = frames.min(setup.simulation.frames);
    let mut figures = BenchFigures::default();
    let start = Instant::now();
    let timings = simulate(&setup, |m, _| {
        figures.newton_iterations += m.newton_iterations;
        figures.linear_iterations += m.linear_iterations;
        Ok(())
    })?;
    figures.wall_s = start.elapsed().as_secs_f64();
    figures.frames = setup.simulation.frames;
    figures.timings = timings;
    Ok(figures)
}
