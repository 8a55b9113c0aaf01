//! The simulation thread of the viewer: solves a frame for each new probe
//! target (the latest one; targets that arrive while a frame is solving
//! replace each other) and publishes each converged state. A frame that
//! fails leaves the last good state in place and is reported; the next
//! new target tries again from that state.
//!
//! Each solved frame becomes a keyframe of the probe's path at the frame's
//! time (frame × frame_dt), so the path so far, written as `[probe]
//! path_mm`, makes `skinpatch run` solve the same frames in the same order
//! ([`crate::pipeline::Run`], stepped in memory here, is the frame step of
//! both).

use std::sync::{Arc, Condvar, Mutex, MutexGuard};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use nalgebra::Vector3;

use crate::export::FrameMetrics;
use crate::fem::material::Material;
use crate::fem::probe::{ContactMode, ProbePose};
use crate::mesh::{TetMesh, Vec3};
use crate::pipeline::Run;
use crate::scenario::SimulationSetup;

/// One converged frame.
#[derive(Clone, Debug)]
pub struct Solved {
    /// Its metrics (probe force, contact, iterations, wall time).
    pub metrics: FrameMetrics,
    /// Deformed positions of every vertex (mm).
    pub positions: Vec<Vec3>,
    /// The probe where it was solved.
    pub pose: Option<ProbePose>,
}

/// What the worker has done, for the panel.
#[derive(Clone, Debug, Default)]
pub struct WorkerStatus {
    /// Frames solved.
    pub solved: usize,
    /// Whether a frame is being solved or a new target waits.
    pub busy: bool,
    /// Why the last frame failed, until one succeeds again.
    pub failure: Option<String>,
    /// Wall time of the last solved frame (s).
    pub last_frame_s: f64,
}

struct Inbox {
    target: Option<ProbePose>,
    materials: Option<(Vec<Material>, Option<ContactMode>)>,
    quit: bool,
}

/// A solved frame's keyframe: time (s), probe centre and axis.
type Keyframe = (f64, Vector3<f64>, Vector3<f64>);

struct Shared {
    inbox: Mutex<Inbox>,
    wake: Condvar,
    latest: Mutex<Option<Arc<Solved>>>,
    status: Mutex<WorkerStatus>,
    // Keyframes of the solved frames: (time, centre, axis).
    path: Mutex<Vec<Keyframe>>,
    // Metrics of the solved frames, in order.
    metrics: Mutex<Vec<FrameMetrics>>,
    done: Condvar,
}

/// Locks `m`, recovering the data of a thread that panicked while holding
/// it (the worker catches its own errors; this keeps the window alive
/// whatever happens).
fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|e| e.into_inner())
}

/// The simulation thread and its mailbox.
pub struct FemWorker {
    shared: Arc<Shared>,
    thread: Option<JoinHandle<()>>,
}

impl FemWorker {
    /// Starts the thread on `mesh` at rest; it solves frame 0 with
    /// `initial` (the probe's first target) at once. `notify` is called
    /// after every frame (solved or failed), from the worker thread.
    pub fn spawn(
        setup: SimulationSetup,
        mesh: TetMesh,
        initial: Option<ProbePose>,
        notify: Box<dyn Fn() + Send>,
    ) -> FemWorker {
        let shared = Arc::new(Shared {
            inbox: Mutex::new(Inbox {
                target: initial,
                materials: None,
                quit: false,
            }),
            wake: Condvar::new(),
            latest: Mutex::new(None),
            status: Mutex::new(WorkerStatus {
                busy: true,
                ..Default::default()
            }),
            path: Mutex::new(Vec::new()),
            metrics: Mutex::new(Vec::new()),
            done: Condvar::new(),
        });
        let inner = shared.clone();
        let thread = std::thread::Builder::new()
            .name("fem".into())
            .spawn(move || run(&inner, setup, mesh, notify))
            .expect("the operating system starts a thread");
        FemWorker {
            shared,
            thread: Some(thread),
        }
    }

    /// Asks for a frame at `pose` (ignored when it equals the target
    /// already asked for).
    pub fn set_target(&self, pose: ProbePose) {
        let mut inbox = lock(&self.shared.inbox);
        if inbox.target != Some(pose) {
            inbox.target = Some(pose);
            lock(&self.shared.status).busy = true;
            self.shared.wake.notify_all();
        }
    }

    /// New materials (one per tet) and probe contact mode, applied from the
    /// next frame, which is solved at once at the current target.
    pub fn set_materials(&self, tet_material: Vec<Material>, mode: Option<ContactMode>) {
        let mut inbox = lock(&self.shared.inbox);
        inbox.materials = Some((tet_material, mode));
        lock(&self.shared.status).busy = true;
        self.shared.wake.notify_all();
    }

    /// The newest converged frame.
    pub fn latest(&self) -> Option<Arc<Solved>> {
        lock(&self.shared.latest).clone()
    }

    /// What the worker has done.
    pub fn status(&self) -> WorkerStatus {
        lock(&self.shared.status).clone()
    }

    /// The probe path of the solved frames: rows `[t, x, y, z]` (s, mm)
    /// and, alike, the axis rows.
    pub fn path(&self) -> (Vec<[f64; 4]>, Vec<[f64; 4]>) {
        let path = lock(&self.shared.path);
        (
            path.iter().map(|(t, c, _)| [*t, c.x, c.y, c.z]).collect(),
            path.iter().map(|(t, _, a)| [*t, a.x, a.y, a.z]).collect(),
        )
    }

    /// Metrics of every solved frame, in order.
    pub fn metrics(&self) -> Vec<FrameMetrics> {
        lock(&self.shared.metrics).clone()
    }

    /// Waits until the worker has nothing left to do (the last target
    /// solved or failed); false after `timeout`.
    pub fn wait_idle(&self, timeout: Duration) -> bool {
        let deadline = Instant::now() + timeout;
        let mut status = lock(&self.shared.status);
        while status.busy {
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return false;
            }
            status = self
                .shared
                .done
                .wait_timeout(status, left)
                .unwrap_or_else(|e| e.into_inner())
                .0;
        }
        true
    }
}

impl Drop for FemWorker {
    fn drop(&mut self) {
        lock(&self.shared.inbox).quit = true;
        self.shared.wake.notify_all();
        if let Some(thread) = self.thread.take() {
            // A frame in progress finishes first.
            let _ = thread.join();
        }
    }
}

/// The worker's loop.
fn run(shared: &Shared, setup: SimulationSetup, mesh: TetMesh, notify: Box<dyn Fn() + Send>) {
    let mut run = Run::from_parts(&setup, &mesh);
    // The target of the last frame tried (solved or failed).
    let mut tried: Option<Option<ProbePose>> = None;
    loop {
        let (target, materials) = {
            let mut inbox = lock(&shared.inbox);
            loop {
                if inbox.quit {
                    return;
                }
                let fresh = tried.as_ref() != Some(&inbox.target);
                if fresh || inbox.materials.is_some() {
                    break;
                }
                lock(&shared.status).busy = false;
                shared.done.notify_all();
                inbox = shared.wake.wait(inbox).unwrap_or_else(|e| e.into_inner());
            }
            (inbox.target, inbox.materials.take())
        };
        if let Some((tet_material, mode)) = materials {
            let changed = run.set_materials(tet_material).and_then(|()| match mode {
                Some(mode) if setup.probe.is_some() => run.set_contact_mode(mode),
                _ => Ok(()),
            });
            if let Err(e) = changed {
                log::warn!("{e}");
            }
        }
        tried = Some(target);
        let t = run.next_frame() as f64 * setup.frame_dt;
        let aimed = match target {
            Some(pose) if setup.probe.is_some() => run.set_probe_pose(pose.centre, pose.axis),
            _ => Ok(()),
        };
        // A failed frame leaves the in-memory run at its last good state.
        let outcome = aimed.and_then(|()| run.step()).map(|frame| Solved {
            metrics: *frame.metrics,
            positions: frame.positions.to_vec(),
            pose: None,
        });
        match outcome {
            Ok(mut solved) => {
                solved.pose = run.probe_pose();
                if let Some(pose) = solved.pose {
                    lock(&shared.path).push((t, pose.centre, pose.axis));
                }
                lock(&shared.metrics).push(solved.metrics);
                let last_frame_s = solved.metrics.step_wall_s;
                *lock(&shared.latest) = Some(Arc::new(solved));
                let mut status = lock(&shared.status);
                status.solved += 1;
                status.failure = None;
                status.last_frame_s = last_frame_s;
            }
            Err(e) => {
                log::warn!("{e}; the viewer keeps the last good state");
                lock(&shared.status).failure = Some(e.to_string());
            }
        }
        notify();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scenario::Setup;

    const WAIT: Duration = Duration::from_secs(120);

    /// A worker on `setup` started at `start`, with its first frame solved.
    fn started(setup: &Setup, start: ProbePose) -> FemWorker {
        let worker = FemWorker::spawn(
            setup.simulation.clone(),
            setup.mesh.clone(),
            Some(start),
            Box::new(|| {}),
        );
        assert!(worker.wait_idle(WAIT));
        assert_eq!(worker.status().solved, 1);
        worker
    }

    #[test]
    fn worker_solves_each_new_target_and_records_its_path() {
        let setup = Setup::load(std::path::Path::new("tests/fixtures/press_small.toml")).unwrap();
        let probe = setup.simulation.probe.clone().unwrap();
        let start = probe.pose(0.0);
        let worker = started(&setup, start);
        let rest_force = worker.latest().unwrap().metrics.probe_force_n[2];
        let pressed = start.lifted(-1.0);
        worker.set_target(pressed);
        worker.set_target(pressed); // the same target: no second frame
        assert!(worker.wait_idle(WAIT));
        let status = worker.status();
        assert_eq!(status.solved, 2, "{status:?}");
        assert!(status.failure.is_none());
        let latest = worker.latest().unwrap();
        assert_eq!(latest.metrics.frame, 1);
        assert!(
            latest.metrics.probe_force_n[2] > rest_force + 1e-3,
            "{:?}",
            latest.metrics
        );
        let (path, _) = worker.path();
        let dt = setup.simulation.frame_dt;
        assert_eq!(path.len(), 2);
        assert_eq!(
            path[1],
            [dt, pressed.centre.x, pressed.centre.y, pressed.centre.z]
        );
    }

    #[test]
    fn a_failed_frame_keeps_the_last_good_state_and_the_next_target_retries() {
        let mut setup =
            Setup::load(std::path::Path::new("tests/fixtures/press_small.toml")).unwrap();
        // One Newton iteration: the hovering frame needs none, a press
        // cannot converge in one.
        setup.simulation.newton.max_iterations = 1;
        let start = setup
            .simulation
            .probe
            .as_ref()
            .unwrap()
            .pose(0.0)
            .lifted(0.5);
        let worker = started(&setup, start);
        assert!(worker.status().failure.is_none());
        worker.set_target(start.lifted(-1.5));
        assert!(worker.wait_idle(WAIT));
        let status = worker.status();
        let failure = status.failure.as_deref().expect("the press fails");
        assert!(failure.contains("frame 1"), "{failure}");
        assert_eq!(status.solved, 1);
        // The state shown is still frame 0, and the path has no keyframe
        // for the failed frame.
        assert_eq!(worker.latest().unwrap().metrics.frame, 0);
        assert_eq!(worker.path().0.len(), 1);
        // A reachable target afterwards is solved as frame 1 from the kept
        // state.
        worker.set_target(start.lifted(0.1));
        assert!(worker.wait_idle(WAIT));
        let status = worker.status();
        assert!(status.failure.is_none(), "{status:?}");
        assert_eq!(worker.latest().unwrap().metrics.frame, 1);
        assert_eq!(worker.path().0.len(), 2);
    }
}
