//! The viewer's keys, by name: one table for the window and for scripts'
//! `key` steps.

use super::state::{Command, ViewMode};

/// What a key does.
#[derive(Clone, Debug, PartialEq)]
pub enum KeyAction {
    /// A state command.
    Command(Command),
    /// The next strain overlay.
    CycleOverlay,
    /// Play or pause the scenario's probe path (starts it when live).
    PlayPause,
    /// Save the view as shown to the record folder.
    Screenshot,
    /// Start or stop writing the frames shown.
    ToggleRecord,
    /// Write the probe path driven so far as a scenario.
    SavePath,
    /// Close the viewer.
    Quit,
}

/// The key table: name, action description (for the help text).
pub const KEYS: [(&str, &str); 17] = [
    ("1", "mode none"),
    ("2", "mode static"),
    ("3", "mode dynamic"),
    ("4", "mode anisotropic roughness"),
    ("o", "next strain overlay (off, r_s, r_t, axes)"),
    ("r", "reset the camera"),
    ("left", "orbit left"),
    ("right", "orbit right"),
    ("up", "orbit up"),
    ("down", "orbit down"),
    ("plus", "zoom in"),
    ("minus", "zoom out"),
    ("space", "play / pause the scenario's probe path"),
    ("p", "screenshot"),
    ("v", "start / stop recording frames"),
    ("s", "save the probe path as a scenario"),
    ("escape", "quit (also q)"),
];

/// Degrees an arrow key orbits by.
const ORBIT_STEP: f32 = 5.0;
/// Zoom factor of one key press.
const ZOOM_STEP: f32 = 0.9;

/// The action of a key name (case-insensitive).
pub fn from_name(name: &str) -> Option<KeyAction> {
    let c = KeyAction::Command;
    Some(match name.to_lowercase().as_str() {
        "1" => c(Command::Mode(ViewMode::None)),
        "2" => c(Command::Mode(ViewMode::Static)),
        "3" => c(Command::Mode(ViewMode::Dynamic)),
        "4" => c(Command::Mode(ViewMode::Anisotropic)),
        "o" => KeyAction::CycleOverlay,
        "r" => c(Command::ResetCamera),
        "left" => c(Command::Orbit(-ORBIT_STEP, 0.0)),
        "right" => c(Command::Orbit(ORBIT_STEP, 0.0)),
        "up" => c(Command::Orbit(0.0, ORBIT_STEP)),
        "down" => c(Command::Orbit(0.0, -ORBIT_STEP)),
        "plus" | "=" | "+" => c(Command::Zoom(ZOOM_STEP)),
        "minus" | "-" => c(Command::Zoom(1.0 / ZOOM_STEP)),
        "space" | " " => KeyAction::PlayPause,
        "p" => KeyAction::Screenshot,
        "v" => KeyAction::ToggleRecord,
        "s" => KeyAction::SavePath,
        "escape" | "q" => KeyAction::Quit,
        _ => return None,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_listed_key_has_an_action() {
        for (name, _) in KEYS {
            assert!(from_name(name).is_some(), "{name}");
        }
        assert_eq!(from_name("Q"), Some(KeyAction::Quit));
        assert!(from_name("f13").is_none());
    }
}
