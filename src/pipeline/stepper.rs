//! The FEM frame source: a [`Stepper`] carries the simulation from one
//! frame to the next — load steps (the rules of
//! [`crate::fem::load_steps`]), the predicted start of each solve,
//! equilibrium with contact, the inversion rule — and [`simulate`] steps it
//! through a scenario's frames.

use std::collections::VecDeque;
use std::time::Instant;

use crate::error::{Error, Result};
use crate::export::FrameMetrics;
use crate::fem::boundary::{rigid_motion_pins, Pin};
use crate::fem::contact::{solve_with_contact, ContactState, ProbePose};
use crate::fem::load_steps::{load_steps, press_in, MAX_PROBE_STEP};
use crate::fem::simulation::{Dynamics, Simulation};
use crate::fem::solve::Filter;
use crate::mesh::Vec3;
use crate::scenario::Setup;

/// Longest prediction, in increments of the last step. A step much longer
/// than the last (the first after a frame split for a fast probe) would
/// carry the skin on at the old speed after the load has stopped, through
/// and past the probe.
const MAX_PREDICTION_RATIO: f64 = 1.5;

/// The most times a load step whose solve fails is halved and taken again
/// (a cut-back): at most 2^MAX_CUTS steps in its place.
pub const MAX_CUTS: u32 = 4;

/// The frame loop; `emit` receives each finished frame. Returns the solver
/// timings.
pub fn simulate(
    setup: &Setup,
    mut emit: impl FnMut(&FrameMetrics, &Stepper) -> Result<()>,
) -> Result<crate::fem::simulation::Timings> {
    let s = &setup.simulation;
    let mut stepper = Stepper::new(s, &setup.mesh);
    for _ in 0..=s.frames {
        let m = stepper.step(s, &setup.mesh, s.probe.as_ref())?;
        emit(&m, &stepper)?;
    }
    Ok(stepper.simulation().timings)
}

/// The state carried from one frame to the next: the simulation, the
/// contact set, the last solved state (for the predicted start of the next
/// solve) and the warnings already given. [`simulate`] steps it through a
/// scenario's frames; the viewer steps it frame by frame with a probe path
/// that grows as the user drives it — the same frames, so a recorded path
/// replays to the same states.
#[derive(Clone)]
pub struct Stepper {
    sim: Simulation,
    contact: ContactState,
    no_loads: Vec<Vec3>,
    frame: usize,
    t_prev: f64,
    prediction: Prediction,
    inverted_before: usize,
    split_before: bool,
    cut_before: bool,
    // Nodes held so that no rigid motion is free (quasi-static runs).
    pins: Vec<Pin>,
    ledger: Ledger,
    /// Whether the energy balance was warned about.
    balance_warned: bool,
    /// Whether the free-node force was warned about.
    free_force_warned: bool,
}

/// The work done on the patch by what holds it (the supports and the
/// probe; in a dynamic run also inertia and damping), summed over the load
/// steps, for the energy balance of `metrics.csv`.
#[derive(Clone, Debug)]
struct Ledger {
    /// Positions and held forces after the last load step.
    x: Vec<Vec3>,
    held: Vec<Vec3>,
    /// The work since the start, plus the energy a change of materials
    /// added (N·mm).
    work: f64,
    /// Load steps that did work.
    loaded_steps: usize,
    /// The mesh diagonal (mm): work below the force floor over it is noise.
    reach: f64,
}

impl Ledger {
    fn new(mesh: &crate::mesh::TetMesh) -> Ledger {
        let (lo, hi) = mesh.bounds();
        let x = &mesh.positions;
        Ledger {
            reach: (hi - lo).norm(),
            x: x.to_vec(),
            held: vec![Vec3::zeros(); x.len()],
            work: 0.0,
            loaded_steps: 0,
        }
    }

    /// Adds a solved load step's work: at each node the mean of the held
    /// forces before and after it times its displacement (trapezoids, in
    /// node order).
    fn step(&mut self, sim: &Simulation) {
        let held = sim.held_forces();
        let x = sim.positions();
        let mut work = 0.0;
        for i in 0..x.len() {
            work += 0.5 * (self.held[i] + held[i]).dot(&(x[i] - self.x[i]));
        }
        if work != 0.0 {
            self.loaded_steps += 1;
        }
        self.work += work;
        self.x.copy_from_slice(x);
        self.held = held;
    }
}

impl Stepper {
    /// The patch at rest, before frame 0.
    pub fn new(s: &crate::scenario::SimulationSetup, mesh: &crate::mesh::TetMesh) -> Stepper {
        let mut sim = Simulation::new(mesh, &s.tet_material);
        sim.settings = s.newton;
        sim.dynamics = s.dynamics;
        let sides: Vec<usize> = s.sets.sides.iter().flatten().copied().collect();
        // A quasi-static patch whose supports leave it free to move rigidly
        // has no unique equilibrium; backward Euler's inertia gives one.
        let (supports, _) = s.boundary.constraints(&s.sets, &mesh.positions, 0.0);
        let pins = if s.dynamics.is_none() {
            rigid_motion_pins(&mesh.positions, &supports, &s.sets.bottom)
        } else {
            Vec::new()
        };
        for pin in &pins {
            let p = mesh.positions[pin.node];
            log::info!(
                "the supports leave the patch free to move rigidly: node {} at ({:.3}, {:.3}, \
                 {:.3}) mm is held at rest along {} more direction(s), which carry no force \
                 unless the loads push the patch as a whole",
                pin.node,
                p.x,
                p.y,
                p.z,
                held_directions(&pin.filter) - held_directions(&supports[pin.node]),
            );
        }
        Stepper {
            sim,
            contact: ContactState::new(mesh, &sides),
            no_loads: vec![Vec3::zeros(); mesh.num_vertices()],
            frame: 0,
            t_prev: 0.0,
            prediction: Prediction::default(),
            inverted_before: 0,
            split_before: false,
            cut_before: false,
            pins,
            ledger: Ledger::new(mesh),
            balance_warned: false,
            free_force_warned: false,
        }
    }

    /// The frame [`Stepper::step`] solves next.
    pub fn next_frame(&self) -> usize {
        self.frame
    }

    /// The simulation as last solved.
    pub fn simulation(&self) -> &Simulation {
        &self.sim
    }

    /// The probe's force and traction per contact node after the last
    /// frame (empty without a probe or contact).
    pub fn contact_forces(&self) -> &crate::fem::contact::ContactForces {
        self.contact.forces()
    }

    /// New materials (one per tet) from the next frame on; the deformed
    /// state is kept.
    pub fn set_materials(
        &mut self,
        mesh: &crate::mesh::TetMesh,
        tet_material: &[crate::fem::material::Material],
    ) {
        // The energy stored so far changes with the moduli; the balance
        // goes on from the new energy.
        let before = self.sim.elastic_energy();
        self.sim.set_materials(mesh, tet_material);
        self.ledger.work += self.sim.elastic_energy() - before;
    }

    /// Solves the next frame (at `frame × frame_dt`) with `probe` — the
    /// scenario's, or one whose path reaches at least that time — and
    /// returns its metrics. After an error the stepper must not be stepped
    /// again.
    pub fn step(
        &mut self,
        s: &crate::scenario::SimulationSetup,
        mesh: &crate::mesh::TetMesh,
        probe: Option<&crate::fem::probe::Probe>,
    ) -> Result<FrameMetrics> {
        let sim = &mut self.sim;
        let frame = self.frame;
        let t_prev = self.t_prev;
        let start = Instant::now();
        let t = frame as f64 * s.frame_dt;
        let mut m = FrameMetrics {
            frame,
            time_s: t,
            ..Default::default()
        };
        // A probe that starts inside the skin is pressed in from just above
        // it during frame 0, in steps like any other motion.
        let mut lift = 0.0;
        let times = if frame == 0 {
            let (height, n) = press_in(probe, mesh, sim.position_tol());
            lift = height;
            vec![t; n]
        } else {
            let times = load_steps(probe, s.substeps, t_prev, t, frame)?;
            let n = times.len();
            if n > s.substeps {
                if !self.split_before {
                    log::warn!(
                        "frame {frame}: the probe moves more than {MAX_PROBE_STEP} of its radius in \
                         a load step; the frame is split into {n} load steps (and so is any later \
                         frame that needs it) so that it cannot pass through the skin"
                    );
                    self.split_before = true;
                }
                log::info!("frame {frame}: {n} load steps for the probe's motion");
            }
            if let Some(d) = s.dynamics {
                // A split frame takes shorter backward-Euler steps.
                let dt = if n == s.substeps {
                    d.dt
                } else {
                    (t - t_prev) / n as f64
                };
                sim.dynamics = Some(Dynamics { dt, ..d });
            }
            times
        };
        let substeps = times.len();
        // Equal steps (the usual case) keep the frame's one step length;
        // steps that follow the path each take their own.
        let equal = frame == 0
            || times
                .iter()
                .copied()
                .eq((1..=substeps).map(|k| t_prev + (t - t_prev) * k as f64 / substeps as f64));
        let frame_dynamics = sim.dynamics;
        // Each load step as (its time, the share of frame 0's press-in lift
        // left after it, how many times it was halved). A step whose solve
        // fails is taken again from the state before it as two half steps
        // (a cut-back), at most MAX_CUTS times over.
        let mut pending: VecDeque<(f64, f64, u32)> = times
            .iter()
            .enumerate()
            .map(|(k, &ts)| (ts, 1.0 - (k + 1) as f64 / substeps as f64, 0))
            .collect();
        let mut solved = (t_prev, 1.0);
        while let Some((ts, left, cuts)) = pending.pop_front() {
            let (t_solved, left_solved) = solved;
            if let Some(d) = frame_dynamics {
                // Steps that follow the path, and halved ones, are of
                // unequal length (frame 0's press-in keeps the frame's).
                let own = frame > 0 && (!equal || cuts > 0);
                sim.dynamics = Some(if own {
                    Dynamics {
                        dt: ts - t_solved,
                        ..d
                    }
                } else {
                    d
                });
            }
            let context = format!("frame {frame} (t = {ts:.4} s)");
            let before = (cuts < MAX_CUTS).then(|| {
                (
                    sim.snapshot(),
                    self.contact.clone(),
                    self.prediction.clone(),
                )
            });
            let mut solve = || -> Result<()> {
                let (mut filters, targets) = s.boundary.constraints(&s.sets, &mesh.positions, ts);
                for pin in &self.pins {
                    filters[pin.node] = pin.filter;
                }
                if sim.dynamics.is_some() {
                    sim.begin_step();
                }
                let pose = probe.map(|p| p.pose(ts).lifted(lift * left));
                self.prediction.start(
                    sim,
                    s.predict,
                    pose,
                    (t_solved, ts),
                    probe.map_or(1.0, |p| p.radius_mm()),
                );
                match (probe, &pose) {
                    (Some(probe), Some(pose)) => {
                        let r = solve_with_contact(
                            sim,
                            (&filters, &targets, &self.no_loads),
                            pose,
                            probe.mode,
                            &mut self.contact,
                            &context,
                        )?;
                        m.probe_force_n = r.probe_force.into();
                        m.contact_nodes = r.contact_nodes;
                        m.contact_area_mm2 = r.contact_area_mm2;
                        m.max_penetration_mm = r.max_penetration_mm;
                        m.newton_iterations += r.newton_iterations;
                        m.linear_iterations += r.cg_iterations;
                        m.rel_residual = r.rel_residual;
                    }
                    _ => {
                        sim.set_constraints(filters, targets);
                        let st = sim.solve_static(&context)?;
                        m.newton_iterations += st.iterations;
                        m.linear_iterations += st.cg_iterations;
                        m.rel_residual = st.rel_residual;
                    }
                }
                sim.end_step();
                Ok(())
            };
            match (solve(), before) {
                (Ok(()), _) => {
                    solved = (ts, left);
                    self.ledger.step(sim);
                }
                (Err(Error::Solver(why)), Some((snapshot, contact, prediction))) => {
                    if !self.cut_before {
                        log::warn!(
                            "{why}; the load step is taken again from the state before it as \
                             two half steps (and so is any later step that fails, up to \
                             {MAX_CUTS} halvings)"
                        );
                        self.cut_before = true;
                    } else {
                        log::info!("{why}; the load step is taken again as two half steps");
                    }
                    sim.restore(&snapshot);
                    self.contact = contact;
                    self.prediction = prediction;
                    let mid = (0.5 * (t_solved + ts), 0.5 * (left_solved + left));
                    pending.push_front((ts, left, cuts + 1));
                    pending.push_front((mid.0, mid.1, cuts + 1));
                }
                (Err(Error::Solver(why)), None) => {
                    return Err(Error::Solver(format!(
                        "{why} (after halving the load step {MAX_CUTS} times)"
                    )))
                }
                (Err(e), _) => return Err(e),
            }
        }
        self.t_prev = t;
        self.frame += 1;
        let inversion = sim.inversion();
        m.inverted_tets = inversion.inverted;
        m.min_volume_ratio = inversion.min_volume_ratio;
        check_inversion(
            &m,
            mesh.num_tets(),
            s.max_inverted_fraction,
            &mut self.inverted_before,
        )?;
        self.balance(&mut m);
        m.step_wall_s = start.elapsed().as_secs_f64();
        log::info!(
            "frame {frame}: t = {t:.4} s, probe force {:?} N, {} contact nodes, {} Newton / {} CG iterations",
            m.probe_force_n,
            m.contact_nodes,
            m.newton_iterations,
            m.linear_iterations
        );
        Ok(m)
    }
}

/// The energy balance's tolerance: `|(W − E)/W|` above it, from
/// [`BALANCE_AFTER_STEPS`] loaded steps on, is warned about. The work is
/// summed by trapezoids over the load steps, whose own error falls with
/// their number; it is largest where contact begins within a step (a node
/// taken in halfway is counted with half its final force over its whole
/// move). Measured: 1.4% after press_small's first step, 0.5% after the
/// Hertz block's, within 0.16% over the main job.
pub const BALANCE_TOLERANCE: f64 = 0.02;

/// Loaded steps before the energy balance is judged.
pub const BALANCE_AFTER_STEPS: usize = 4;

/// The tolerance of the largest free-node force relative to the probe
/// force: a node that carries no load may keep 0.1% of it.
pub const FREE_FORCE_TOLERANCE: f64 = 1e-3;

impl Stepper {
    /// Fills a solved frame's self-checks, the energy balance and the
    /// largest free-node force (see [`FrameMetrics`]), and warns the first
    /// time each exceeds its tolerance.
    fn balance(&mut self, m: &mut FrameMetrics) {
        let sim = &mut self.sim;
        // Below a thousand times the round-off, forces and work are noise.
        let floor = 1e3 * sim.force_floor();
        let probe = Vec3::from(m.probe_force_n).norm();
        let scale = if probe > floor {
            probe
        } else {
            self.ledger
                .held
                .iter()
                .map(|f| f.norm())
                .fold(0.0, f64::max)
        };
        m.free_node_force_ratio = if scale > floor {
            sim.largest_free_force() / scale
        } else {
            0.0
        };
        let work = self.ledger.work;
        m.energy_balance = if work.abs() > floor * self.ledger.reach {
            (work - sim.elastic_energy()) / work
        } else {
            0.0
        };
        let frame = m.frame;
        if !self.balance_warned
            && self.ledger.loaded_steps >= BALANCE_AFTER_STEPS
            && m.energy_balance.abs() > BALANCE_TOLERANCE
        {
            self.balance_warned = true;
            log::warn!(
                "frame {frame}: the work done on the patch and the energy stored in it differ by \
                 {:.1}% of the work (energy_balance in metrics.csv; tolerance {:.0}%): the \
                 solution is not the equilibrium path; check the frame's rel_residual, and try \
                 more load steps (time.substeps) or a smaller solver.rel_tol",
                100.0 * m.energy_balance,
                100.0 * BALANCE_TOLERANCE
            );
        }
        if !self.free_force_warned && m.free_node_force_ratio > FREE_FORCE_TOLERANCE {
            self.free_force_warned = true;
            log::warn!(
                "frame {frame}: a node that nothing holds carries {:.2e} of the probe force \
                 (free_node_force_ratio in metrics.csv; tolerance {FREE_FORCE_TOLERANCE:e}): \
                 the frame is not in equilibrium; try a smaller solver.rel_tol",
                m.free_node_force_ratio
            );
        }
    }
}

/// A solved state kept for the next solve's predicted start.
#[derive(Clone)]
struct Solved {
    x: Vec<Vec3>,
    t: f64,
    /// The probe it was solved with.
    pose: Option<ProbePose>,
}

/// What the predicted start of a solve needs: the last solved state and
/// the probe of the last solve.
#[derive(Clone, Default)]
struct Prediction {
    last_solved: Option<Solved>,
    last_pose: Option<ProbePose>,
}

impl Prediction {
    /// Before the solve at `ts` with the probe at `pose`: keeps the state
    /// solved at `t_solved` and, when `predict`, moves `sim` on from it by
    /// its last increment (constant velocity) scaled to this step's length,
    /// unless the probe turns or stops here ([`probe_keeps_going`], `lever`
    /// the probe's radius).
    fn start(
        &mut self,
        sim: &mut Simulation,
        predict: bool,
        pose: Option<ProbePose>,
        (t_solved, ts): (f64, f64),
        lever: f64,
    ) {
        if predict {
            let solved = sim.positions().to_vec();
            if let Some(last) = &self.last_solved {
                if t_solved > last.t
                    && probe_keeps_going(
                        last,
                        self.last_pose.as_ref(),
                        pose.as_ref(),
                        t_solved,
                        ts,
                        lever,
                    )
                {
                    let ratio = (ts - t_solved) / (t_solved - last.t);
                    sim.predict(&last.x, ratio.min(MAX_PREDICTION_RATIO));
                }
            }
            self.last_solved = Some(Solved {
                x: solved,
                t: t_solved,
                pose: self.last_pose,
            });
        }
        self.last_pose = pose;
    }
}

/// Largest change of the probe's velocity between two steps, relative to
/// its speed, for which the next start is predicted.
const MAX_PROBE_TURN: f64 = 0.1;

/// Whether the probe moves on from `solved` (the last solve's probe, at
/// `t_solved`) to `next` (at `t_next`) at nearly the velocity it had from
/// `before` to `solved`. Where it turns or stops — the end of a press — the
/// skin's velocity is no guide to where it goes next, and a start predicted
/// from it would carry the skin on past the probe.
fn probe_keeps_going(
    before: &Solved,
    solved: Option<&ProbePose>,
    next: Option<&ProbePose>,
    t_solved: f64,
    t_next: f64,
    lever: f64,
) -> bool {
    let (Some(b), Some(s), Some(n)) = (before.pose.as_ref(), solved, next) else {
        return true;
    };
    // Two points of the probe: its centre and one `lever` (its radius)
    // along its axis.
    let points = |p: &ProbePose| [p.centre, p.centre + p.axis * lever];
    let (pb, ps, pn) = (points(b), points(s), points(n));
    (0..2).all(|i| {
        let v_old = (ps[i] - pb[i]) / (t_solved - before.t);
        let v_new = (pn[i] - ps[i]) / (t_next - t_solved);
        (v_new - v_old).norm() <= MAX_PROBE_TURN * v_new.norm().max(v_old.norm())
    })
}

/// How many directions `filter` holds.
fn held_directions(filter: &Filter) -> usize {
    3 - filter.matrix().trace().round() as usize
}

/// Applies the inversion rule to a solved frame: a warning when inverted
/// tets appear (or their number changes from none), an error when more
/// than `max_fraction` of the `tets` are inverted. The frame is not
/// written then: its state has no physical meaning.
fn check_inversion(
    m: &FrameMetrics,
    tets: usize,
    max_fraction: f64,
    inverted_before: &mut usize,
) -> Result<()> {
    let fraction = m.inverted_tets as f64 / tets.max(1) as f64;
    if fraction > max_fraction || m.min_volume_ratio.is_nan() {
        return Err(Error::Solver(format!(
            "frame {} (t = {:.4} s): {} of {tets} tets ({:.2}%) are inverted, the smallest volume \
             ratio is {:.3}; solver.max_inverted_fraction is {max_fraction}. The patch has turned \
             inside out (a load beyond what the mesh and material can follow): reduce the load, \
             add substeps, or raise the limit to keep going",
            m.frame,
            m.time_s,
            m.inverted_tets,
            100.0 * fraction,
            m.min_volume_ratio
        )));
    }
    if m.inverted_tets > 0 && *inverted_before == 0 {
        log::warn!(
            "frame {}: {} tets are inverted (smallest volume ratio {:.3}); their strains are not \
             physical",
            m.frame,
            m.inverted_tets,
            m.min_volume_ratio
        );
    }
    *inverted_before = m.inverted_tets;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fem::probe::ProbeShape;

    fn pose(x: f64, z: f64) -> ProbePose {
        ProbePose {
            shape: ProbeShape::Sphere { radius_mm: 1.0 },
            centre: Vec3::new(x, 0.0, z),
            axis: Vec3::x(),
        }
    }

    fn solved(p: ProbePose, t: f64) -> Solved {
        Solved {
            x: Vec::new(),
            t,
            pose: Some(p),
        }
    }

    /// The prediction runs on while the probe keeps its velocity (steps of
    /// different lengths included) and stops where it turns, stops or
    /// speeds up by more than [`MAX_PROBE_TURN`].
    #[test]
    fn prediction_stops_where_the_probe_turns() {
        let keeps = |before: (f64, f64), now: (f64, f64), next: (f64, f64), times: [f64; 3]| {
            probe_keeps_going(
                &solved(pose(before.0, before.1), times[0]),
                Some(&pose(now.0, now.1)),
                Some(&pose(next.0, next.1)),
                times[1],
                times[2],
                1.0,
            )
        };
        // Pressing down at 1 mm/s, then a step twice as long.
        assert!(keeps((0.0, 0.0), (0.0, -0.1), (0.0, -0.3), [0.0, 0.1, 0.3]));
        // The press ends and the drag begins: the velocity turns.
        assert!(!keeps(
            (0.0, -0.1),
            (0.0, -0.2),
            (0.1, -0.2),
            [0.1, 0.2, 0.3]
        ));
        // The probe stops.
        assert!(!keeps(
            (0.0, -0.1),
            (0.0, -0.2),
            (0.0, -0.2),
            [0.1, 0.2, 0.3]
        ));
        // 5 % faster still counts as going on; 20 % does not.
        assert!(keeps((0.0, 0.0), (0.1, 0.0), (0.205, 0.0), [0.0, 0.1, 0.2]));
        assert!(!keeps((0.0, 0.0), (0.1, 0.0), (0.22, 0.0), [0.0, 0.1, 0.2]));
        // A resting probe: the skin's own motion is predicted.
        assert!(keeps((0.0, 0.0), (0.0, 0.0), (0.0, 0.0), [0.0, 0.1, 0.2]));
        // No probe pose to compare: predict as before.
        assert!(probe_keeps_going(
            &Solved {
                x: Vec::new(),
                t: 0.0,
                pose: None
            },
            None,
            None,
            0.1,
            0.2,
            1.0
        ));
    }
}
