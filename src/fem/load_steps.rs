//! Load steps: how a frame's probe motion is split so that contact can
//! follow it. A step may move the probe at most [`MAX_PROBE_STEP`] of its
//! radius (a surface node passed over in one step would end outside the
//! probe and never touch it); a probe that starts inside the skin is
//! pressed in from just above the patch in such steps.

use crate::error::{Error, Result};
use crate::fem::probe::{Probe, ProbePose};
use crate::mesh::TetMesh;

/// Frame 0's load steps and the height (mm) its probe starts above its
/// t = 0 pose: one step from that pose, or, for a probe that starts inside
/// the skin, steps of at most [`MAX_PROBE_STEP`] of its radius from just
/// above the patch (with a warning).
pub fn press_in(probe: Option<&Probe>, mesh: &TetMesh, tol: f64) -> (f64, usize) {
    let Some(probe) = probe else {
        return (0.0, 1);
    };
    let lift = embedded_lift(mesh, &probe.pose(0.0), tol);
    if lift == 0.0 {
        return (0.0, 1);
    }
    let n = ((lift / (MAX_PROBE_STEP * probe.radius_mm())).ceil() as usize).max(1);
    log::warn!(
        "the probe starts inside the skin at t = 0; frame 0 presses it in from {lift:.4} mm \
         higher in {n} load steps (start its path above the surface to choose how it gets there)"
    );
    (lift, n)
}

/// How far (mm) `pose` must be lifted so that no node of `mesh` at rest is
/// inside it by more than `tol`: 0 when none is, else the height that takes
/// its lowest point to the top of the patch.
fn embedded_lift(mesh: &TetMesh, pose: &ProbePose, tol: f64) -> f64 {
    let inside = mesh.positions.iter().any(|p| pose.distance(p).0 < -tol);
    if !inside {
        return 0.0;
    }
    let (_, hi) = mesh.bounds();
    (hi.z - pose.lowest_z()).max(0.0)
}

/// Largest distance the probe may move in one load step, as a fraction of
/// its radius. A frame whose probe moves further is split into more load
/// steps than `time.substeps` asks for, so no surface node can be passed
/// over (a node passed in one step would end outside the probe and never
/// touch it).
pub const MAX_PROBE_STEP: f64 = 0.25;

/// Most load steps a frame may be split into (configured or automatic).
pub const MAX_LOAD_STEPS: usize = 10_000;

/// The end times of the load steps of the frame from `t0` to `t1`:
/// `configured` equal steps, or the smallest multiple of it in which no
/// step moves the probe more than [`MAX_PROBE_STEP`] of its radius. When
/// the motion is concentrated in a small part of a long frame (a slow frame
/// rate, a path that moves only at its start), equal steps would need far
/// too many: the steps then follow the path, each stretch between the
/// configured steps and the path's keyframes split by the distance the
/// probe covers in it. An error when even that takes more than
/// [`MAX_LOAD_STEPS`].
pub fn load_steps(
    probe: Option<&Probe>,
    configured: usize,
    t0: f64,
    t1: f64,
    frame: usize,
) -> Result<Vec<f64>> {
    let equal = |n: usize| -> Vec<f64> {
        (1..=n)
            .map(|k| t0 + (t1 - t0) * k as f64 / n as f64)
            .collect()
    };
    let Some(probe) = probe else {
        return Ok(equal(configured));
    };
    let limit = MAX_PROBE_STEP * probe.radius_mm();
    let mut n = configured;
    loop {
        let at = |k: usize| t0 + (t1 - t0) * k as f64 / n as f64;
        let worst = (0..n)
            .map(|k| probe.travel(at(k), at(k + 1)))
            .fold(0.0, f64::max);
        if worst <= limit {
            return Ok(equal(n));
        }
        let next = n.saturating_mul((worst / limit).ceil().max(2.0) as usize);
        if next > MAX_LOAD_STEPS {
            break;
        }
        n = next;
    }
    // Along the path: between consecutive breaks (the configured steps and
    // the keyframes) the probe moves evenly, so equal parts of each stretch
    // move it equally.
    let mut breaks = equal(configured);
    breaks.extend(probe.keyframe_times().filter(|&t| t > t0 && t < t1));
    breaks.sort_by(f64::total_cmp);
    breaks.dedup();
    let mut times = Vec::new();
    let mut from = t0;
    for to in breaks {
        let parts = ((probe.travel(from, to) / limit).ceil() as usize).max(1);
        times.extend((1..=parts).map(|k| from + (to - from) * k as f64 / parts as f64));
        if times.len() > MAX_LOAD_STEPS {
            return Err(Error::Solver(format!(
                "frame {frame} (t = {t1:.4} s): the probe moves {:.4} mm, {:.1} times its \
                 radius; more than {MAX_LOAD_STEPS} load steps of {MAX_PROBE_STEP} radius would \
                 be needed for contact to follow it. Slow the probe path or raise \
                 time.frame_rate_hz",
                probe.travel(t0, t1),
                probe.travel(t0, t1) / probe.radius_mm()
            )));
        }
        from = to;
    }
    Ok(times)
}
