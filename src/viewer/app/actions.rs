//! The user's actions beyond view commands: the key table's actions
//! (screenshots, recording, saving the probe path, quitting), shared by
//! keys, the panel and scripts.

use super::App;
use crate::error::Result;
use crate::viewer::keys::KeyAction;
use crate::viewer::record::{self, FrameRecorder};
use crate::viewer::state::{Command, Overlay, ProbeDrive};

impl App {
    /// Carries out a key's action.
    pub(super) fn key_action(&mut self, action: KeyAction) -> Result<()> {
        match action {
            KeyAction::Command(c) => self.state.apply(c),
            KeyAction::CycleOverlay => {
                let k = Overlay::ALL
                    .iter()
                    .position(|o| *o == self.state.overlay)
                    .unwrap_or(0);
                self.state
                    .apply(Command::Overlay(Overlay::ALL[(k + 1) % Overlay::ALL.len()]));
            }
            KeyAction::PlayPause => match self.state.probe.as_ref().map(|p| p.drive) {
                Some(ProbeDrive::Path { playing, .. }) => self.state.apply(Command::Pause(playing)),
                Some(ProbeDrive::Live) => self.state.apply(Command::Play(0.0)),
                None => {}
            },
            KeyAction::Screenshot => {
                let k = self.written.len();
                self.screenshots.push(
                    self.options
                        .record_dir
                        .join(format!("screenshot_{k:04}.png")),
                );
            }
            KeyAction::ToggleRecord => self.toggle_record()?,
            KeyAction::SavePath => {
                let file = self.options.record_dir.join("recorded.toml");
                self.save_path(&file)?;
            }
            KeyAction::Quit => self.summary.quit = true,
        }
        self.dirty = true;
        Ok(())
    }

    pub(super) fn toggle_record(&mut self) -> Result<()> {
        match self.recorder.take() {
            Some(r) => {
                let fps = self.rates.display_fps.clamp(1.0, 120.0);
                let n = r.frames();
                let files = r.finish(fps)?;
                self.message = Some(format!(
                    "recorded {n} frames in {}",
                    self.options.record_dir.join("frames").display()
                ));
                self.written.extend(files);
            }
            None => {
                self.recorder = Some(FrameRecorder::start(
                    &self.options.record_dir.join("frames"),
                )?);
                self.dirty = true;
            }
        }
        Ok(())
    }

    pub(super) fn save_path(&mut self, file: &std::path::Path) -> Result<()> {
        let (path, axis) = self.worker().path();
        let base = self
            .options
            .scenario
            .parent()
            .unwrap_or(std::path::Path::new("."));
        let dest = file
            .parent()
            .filter(|d| !d.as_os_str().is_empty())
            .unwrap_or(std::path::Path::new("."));
        std::fs::create_dir_all(dest).map_err(|e| crate::error::Error::io(dest, e))?;
        let recorded = record::recorded_scenario(
            &self.loaded.scenario,
            base,
            dest,
            &path,
            &axis,
            &self.state.materials,
            self.state.friction,
        );
        match recorded {
            Ok(s) => {
                let mut header = format!(
                    "The probe path driven in `skinpatch view {}`: one keyframe per solved frame.\n\
                     Replay: skinpatch run {}",
                    self.options.scenario.display(),
                    file.display()
                );
                if self.state.materials_version > 0 {
                    header.push_str(
                        "\nMaterials or friction were edited during the session: this file has \
                         the last values, so frames before the edit replay with them too.",
                    );
                }
                record::save_scenario(file, &s, &header)?;
                self.message = Some(format!("saved the path to {}", file.display()));
                self.written.push(file.to_path_buf());
            }
            Err(e) => self.state.rejected = Some(e.to_string()),
        }
        Ok(())
    }
}
