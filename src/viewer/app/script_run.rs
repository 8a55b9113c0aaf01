//! The `--script` runner: plays the parsed steps (`viewer::script`) against
//! the window one by one, waiting for the simulation or for display time
//! where a step asks.

use std::sync::Arc;
use std::time::{Duration, Instant};

use winit::event_loop::ActiveEventLoop;

use super::App;
use crate::error::{Error, Result};
use crate::viewer::keys;
use crate::viewer::script::Step;
use crate::viewer::state::Command;

/// How long a script waits for one simulated frame before giving up.
const FEM_TIMEOUT: Duration = Duration::from_secs(600);

/// What a running script waits for before its next step.
pub(super) enum Waiting {
    /// The simulation to solve every target so far (and its frame to be
    /// shown), since this instant; then the remaining moves of a drag, each
    /// solved before the next.
    Fem(Instant, Vec<[f64; 2]>),
    /// Display time to pass.
    Until(Instant),
}

pub(super) struct ScriptRun {
    pub(super) steps: Vec<Step>,
    pub(super) next: usize,
    pub(super) waiting: Option<Waiting>,
}

impl App {
    /// Runs script steps until one has to wait.
    pub(super) fn run_script(&mut self, event_loop: &ActiveEventLoop) -> Result<()> {
        // Scripts start on the first frame shown.
        if self.shown.is_none() {
            return Ok(());
        }
        loop {
            let Some(run) = self.script.as_mut() else {
                return Ok(());
            };
            match run.waiting.take() {
                Some(Waiting::Fem(since, mut moves)) => {
                    let worker = self.worker.as_ref().expect("started");
                    let status = worker.status();
                    let shown = match (worker.latest(), &self.shown) {
                        (Some(a), Some(b)) => Arc::ptr_eq(&a, b),
                        (None, _) => true,
                        _ => false,
                    };
                    if status.busy || !shown {
                        if since.elapsed() > FEM_TIMEOUT {
                            return Err(Error::Solver(format!(
                                "script step {}: the simulation did not finish a frame within {} s",
                                run.next,
                                FEM_TIMEOUT.as_secs()
                            )));
                        }
                        run.waiting = Some(Waiting::Fem(since, moves));
                        return Ok(());
                    }
                    if !moves.is_empty() {
                        let at = moves.remove(0);
                        run.waiting = Some(Waiting::Fem(Instant::now(), moves));
                        self.state.apply(Command::MoveTo(at));
                        self.dirty = true;
                        return Ok(());
                    }
                }
                Some(Waiting::Until(t)) => {
                    if Instant::now() < t {
                        run.waiting = Some(Waiting::Until(t));
                        return Ok(());
                    }
                    run.waiting = Some(Waiting::Fem(Instant::now(), Vec::new()));
                    continue;
                }
                None => {}
            }
            let run = self.script.as_mut().expect("checked");
            let Some(step) = run.steps.get(run.next).cloned() else {
                return Ok(());
            };
            run.next += 1;
            let index = run.next;
            log::info!("script step {index}: {}", step.name());
            self.dirty = true;
            if let Some(commands) = step.commands() {
                for c in commands {
                    self.state.apply(c);
                }
                if let Some(why) = self.state.rejected.take() {
                    return Err(Error::Scenario {
                        path: self.options.script.clone().unwrap_or_default(),
                        message: format!("step {index} ({}): {why}", step.name()),
                    });
                }
            }
            let wait = match &step {
                Step::Drag { to_mm, moves } => {
                    let Some(p) = &self.state.probe else {
                        return Err(Error::Scenario {
                            path: self.options.script.clone().unwrap_or_default(),
                            message: format!("step {index} (drag): the scenario has no [probe]"),
                        });
                    };
                    let n = moves.unwrap_or(1);
                    let from = p.at_mm;
                    let points = (1..=n)
                        .map(|k| {
                            let a = k as f64 / n as f64;
                            [
                                from[0] + (to_mm[0] - from[0]) * a,
                                from[1] + (to_mm[1] - from[1]) * a,
                            ]
                        })
                        .collect();
                    Some(Waiting::Fem(Instant::now(), points))
                }
                Step::Play { from_s, seconds } => {
                    self.state.apply(Command::Play(from_s.unwrap_or(0.0)));
                    let length = self
                        .state
                        .probe
                        .as_ref()
                        .map_or(0.0, |p| p.path_duration() - from_s.unwrap_or(0.0));
                    let s = seconds.unwrap_or(length).max(0.0);
                    Some(Waiting::Until(Instant::now() + Duration::from_secs_f64(s)))
                }
                Step::Scrub { t_s } => {
                    self.state.apply(Command::Scrub(*t_s));
                    Some(Waiting::Fem(Instant::now(), Vec::new()))
                }
                Step::Wait { seconds } => Some(Waiting::Until(
                    Instant::now() + Duration::from_secs_f64(seconds.unwrap_or(0.0)),
                )),
                Step::Key { key } => {
                    let action = keys::from_name(key).expect("checked when loaded");
                    self.key_action(action)?;
                    None
                }
                Step::Light {
                    azimuth_deg,
                    elevation_deg,
                    intensity,
                } => {
                    if let Some((az, el)) = self.state.key_light {
                        self.state.apply(Command::LightDirection(
                            azimuth_deg.unwrap_or(az),
                            elevation_deg.unwrap_or(el),
                        ));
                    }
                    if let Some(i) = intensity {
                        self.state.apply(Command::LightIntensity(*i));
                    }
                    None
                }
                Step::Screenshot { file, window } => {
                    // Taken after this redraw's render, so it shows every
                    // step before it.
                    if *window {
                        self.window_shots.push(file.clone());
                    } else {
                        self.screenshots.push(file.clone());
                    }
                    return Ok(());
                }
                Step::RecordStart {} => {
                    if self.recorder.is_none() {
                        self.toggle_record()?;
                    }
                    None
                }
                Step::RecordStop {} => {
                    if self.recorder.is_some() {
                        self.toggle_record()?;
                    }
                    None
                }
                Step::SavePath { file } => {
                    self.save_path(file)?;
                    if let Some(why) = self.state.rejected.take() {
                        return Err(Error::Scenario {
                            path: self.options.script.clone().unwrap_or_default(),
                            message: format!("step {index} (save_path): {why}"),
                        });
                    }
                    None
                }
                Step::Quit {} => {
                    self.summary.quit = true;
                    event_loop.exit();
                    return Ok(());
                }
                _ if step.moves_the_simulation() => Some(Waiting::Fem(Instant::now(), Vec::new())),
                _ => None,
            };
            let run = self.script.as_mut().expect("checked");
            if wait.is_some() {
                // Checked from the next redraw on, after this one has
                // handed the step's target to the simulation.
                run.waiting = wait;
                return Ok(());
            }
        }
    }
}
