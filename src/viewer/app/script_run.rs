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

/// What a step leaves the runner to do.
enum After {
    /// Go on with the next step.
    Next,
    /// Wait for this before the next step (checked from the next redraw on,
    /// after this one has handed the step's target to the simulation).
    Wait(Waiting),
    /// Stop until the next redraw (a screenshot is taken after this
    /// redraw's render, so it shows every step before it) or for good.
    Yield,
}

impl App {
    /// Runs script steps until one has to wait.
    pub(super) fn run_script(&mut self, event_loop: &ActiveEventLoop) -> Result<()> {
        // Scripts start on the first frame shown.
        if self.shown.is_none() {
            return Ok(());
        }
        while self.script_may_go_on()? {
            let run = self.script.as_mut().expect("checked");
            let Some(step) = run.steps.get(run.next).cloned() else {
                return Ok(());
            };
            run.next += 1;
            let index = run.next;
            log::info!("script step {index}: {}", step.name());
            self.dirty = true;
            match self.perform_step(&step, index, event_loop)? {
                After::Next => {}
                After::Yield => return Ok(()),
                After::Wait(wait) => {
                    self.script.as_mut().expect("checked").waiting = Some(wait);
                    return Ok(());
                }
            }
        }
        Ok(())
    }

    /// Whether the script may take its next step: what it waits for has
    /// happened (the next move of a drag is handed on here).
    fn script_may_go_on(&mut self) -> Result<bool> {
        loop {
            let Some(run) = self.script.as_mut() else {
                return Ok(false);
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
                        return Ok(false);
                    }
                    if !moves.is_empty() {
                        let at = moves.remove(0);
                        run.waiting = Some(Waiting::Fem(Instant::now(), moves));
                        self.state.apply(Command::MoveTo(at));
                        self.dirty = true;
                        return Ok(false);
                    }
                    return Ok(true);
                }
                Some(Waiting::Until(t)) => {
                    if Instant::now() < t {
                        run.waiting = Some(Waiting::Until(t));
                        return Ok(false);
                    }
                    run.waiting = Some(Waiting::Fem(Instant::now(), Vec::new()));
                }
                None => return Ok(true),
            }
        }
    }

    /// An error of script step `index`.
    fn step_error(&self, index: usize, what: &str, why: impl std::fmt::Display) -> Error {
        Error::Scenario {
            path: self.options.script.clone().unwrap_or_default(),
            message: format!("step {index} ({what}): {why}"),
            key: None,
            line: None,
        }
    }

    /// Performs one step (the `index`th).
    fn perform_step(
        &mut self,
        step: &Step,
        index: usize,
        event_loop: &ActiveEventLoop,
    ) -> Result<After> {
        if let Some(commands) = step.commands() {
            for c in commands {
                self.state.apply(c);
            }
            if let Some(why) = self.state.rejected.take() {
                return Err(self.step_error(index, step.name(), why));
            }
        }
        let now = Instant::now();
        Ok(match step {
            Step::Drag { to_mm, moves } => {
                let Some(p) = &self.state.probe else {
                    return Err(self.step_error(index, "drag", "the scenario has no [probe]"));
                };
                After::Wait(Waiting::Fem(
                    now,
                    drag_moves(p.at_mm, *to_mm, moves.unwrap_or(1)),
                ))
            }
            Step::Play { from_s, seconds } => {
                self.state.apply(Command::Play(from_s.unwrap_or(0.0)));
                let length = self
                    .state
                    .probe
                    .as_ref()
                    .map_or(0.0, |p| p.path_duration() - from_s.unwrap_or(0.0));
                let s = seconds.unwrap_or(length).max(0.0);
                After::Wait(Waiting::Until(now + Duration::from_secs_f64(s)))
            }
            Step::Scrub { t_s } => {
                self.state.apply(Command::Scrub(*t_s));
                After::Wait(Waiting::Fem(now, Vec::new()))
            }
            Step::Wait { seconds } => After::Wait(Waiting::Until(
                now + Duration::from_secs_f64(seconds.unwrap_or(0.0)),
            )),
            Step::Key { key } => {
                self.key_action(keys::from_name(key).expect("checked when loaded"))?;
                After::Next
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
                After::Next
            }
            Step::Screenshot { file, window } => {
                if *window {
                    self.window_shots.push(file.clone());
                } else {
                    self.screenshots.push(file.clone());
                }
                After::Yield
            }
            Step::RecordStart {} | Step::RecordStop {} => {
                if self.recorder.is_none() == matches!(step, Step::RecordStart {}) {
                    self.toggle_record()?;
                }
                After::Next
            }
            Step::SavePath { file } => {
                self.save_path(file)?;
                if let Some(why) = self.state.rejected.take() {
                    return Err(self.step_error(index, "save_path", why));
                }
                After::Next
            }
            Step::Quit {} => {
                self.summary.quit = true;
                event_loop.exit();
                After::Yield
            }
            _ if step.moves_the_simulation() => After::Wait(Waiting::Fem(now, Vec::new())),
            _ => After::Next,
        })
    }
}

/// The `n` probe positions of a drag from `from` to `to`, evenly spaced,
/// `to` last.
fn drag_moves(from: [f64; 2], to: [f64; 2], n: usize) -> Vec<[f64; 2]> {
    (1..=n)
        .map(|k| {
            let a = k as f64 / n as f64;
            [
                from[0] + (to[0] - from[0]) * a,
                from[1] + (to[1] - from[1]) * a,
            ]
        })
        .collect()
}
