//! `skinpatch view --script FILE`: a list of input steps the viewer plays
//! in order, for unattended runs (tests, CI, reproducible captures).
//!
//! ```toml
//! [[step]]
//! action = "press"          # the probe down at a patch point (mm) or pixel
//! at_mm = [-1.0, 0.0]
//! depth_mm = 0.8
//! [[step]]
//! action = "drag"           # slide to a point in equal moves, each solved
//! to_mm = [1.0, 0.0]
//! moves = 4
//! [[step]]
//! action = "screenshot"     # the view as shown, 8-bit PNG
//! file = "pressed.png"       # (window = true: the whole window)
//! ```
//!
//! A step that moves the probe or edits a material waits until the
//! simulation has solved it before the next step runs, so a script
//! produces the same frames whatever the machine's speed. Relative files
//! are relative to the working directory.

use std::path::{Path, PathBuf};

use serde::Deserialize;

use super::state::{Command, Overlay, ViewMode};
use crate::error::{Error, Result};

/// One step of a script.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(tag = "action", rename_all = "snake_case", deny_unknown_fields)]
pub enum Step {
    /// Press the probe at a patch point (`at_mm`) or at the point under a
    /// pixel of the view (`at_px`), optionally setting the depth first.
    Press {
        /// Patch point (x, y in mm).
        at_mm: Option<[f64; 2]>,
        /// Pixel of the view (from its top left).
        at_px: Option<[f32; 2]>,
        /// Press depth (mm) below touching.
        depth_mm: Option<f64>,
    },
    /// Slide the probe to `to_mm` in `moves` equal moves (default 1).
    Drag {
        /// Patch point (x, y in mm).
        to_mm: [f64; 2],
        /// Moves (each one solved frame).
        moves: Option<usize>,
    },
    /// Set the press depth (mm).
    Depth {
        /// Depth (mm).
        mm: f64,
    },
    /// Lift the probe.
    Release {},
    /// Play the scenario's probe path from `from_s` for `seconds` of
    /// display time (or until its end).
    Play {
        /// Start time on the path (s). Default 0.
        from_s: Option<f64>,
        /// Display time to play for (s). Default: the path's length.
        seconds: Option<f64>,
    },
    /// Show the path at time `t_s` (paused) and wait for its frame.
    Scrub {
        /// Time on the path (s).
        t_s: f64,
    },
    /// Wait: `seconds` of display time, or until the simulation is idle.
    Wait {
        /// Display time (s). Default 0: only until the simulation is idle.
        seconds: Option<f64>,
    },
    /// Shading mode: `none`, `static`, `dynamic` or `anisotropic`.
    Mode {
        /// The mode.
        mode: String,
    },
    /// Strain overlay: `off`, `rs`, `rt` or `axes`.
    Overlay {
        /// The overlay.
        overlay: String,
    },
    /// Orbit the camera (degrees).
    Orbit {
        /// Azimuth change.
        azimuth_deg: f32,
        /// Elevation change.
        elevation_deg: f32,
    },
    /// Scale the camera's distance.
    Zoom {
        /// Factor (< 1 closer).
        factor: f32,
    },
    /// Pan the camera by fractions of the view height.
    Pan {
        /// Right.
        right: f32,
        /// Up.
        up: f32,
    },
    /// Back to the scenario's camera.
    ResetCamera {},
    /// The key light: where it comes from, and the scale of all lights.
    Light {
        /// Azimuth (degrees).
        azimuth_deg: Option<f32>,
        /// Elevation (degrees).
        elevation_deg: Option<f32>,
        /// Scale of every light's intensity.
        intensity: Option<f32>,
    },
    /// A region's material.
    Material {
        /// Region name.
        region: String,
        /// Young's modulus (kPa).
        youngs_modulus_kpa: f64,
        /// Poisson ratio.
        poisson_ratio: f64,
    },
    /// The probe's Coulomb friction coefficient.
    Friction {
        /// Coefficient.
        mu: f64,
    },
    /// A key as typed in the window (see the viewer's key list).
    Key {
        /// Key name: a letter, digit, `space`, `left`, `right`, `up`, `down`,
        /// `plus`, `minus`, `escape`.
        key: String,
    },
    /// Save the view as shown (8-bit PNG); with `window = true` the whole
    /// window, panel included.
    Screenshot {
        /// Output file.
        file: PathBuf,
        /// Capture the window instead of the view. Default false.
        #[serde(default)]
        window: bool,
    },
    /// Start writing the frames shown.
    RecordStart {},
    /// Stop writing frames (and encode the MP4 when ffmpeg is present).
    RecordStop {},
    /// Write the probe path driven so far as a scenario file.
    SavePath {
        /// Output file (TOML).
        file: PathBuf,
    },
    /// Close the viewer.
    Quit {},
}

/// A parsed script.
#[derive(Clone, Debug, Default, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Script {
    /// The steps, in order.
    #[serde(default)]
    pub step: Vec<Step>,
}

impl Script {
    /// Reads and checks a script file run on `scenario`: every step's
    /// values, and no file a step writes may be the script or the scenario.
    pub fn load(path: &Path, scenario: &Path) -> Result<Script> {
        let script: Script = crate::scenario::read_toml_file(path)?;
        for (k, step) in script.step.iter().enumerate() {
            let fail = |message: String| Error::Scenario {
                path: path.to_path_buf(),
                message: format!("step {} ({}): {message}", k + 1, step.name()),
                key: None,
                line: None,
            };
            step.check().map_err(fail)?;
            if let Step::Screenshot { file, .. } | Step::SavePath { file } = step {
                crate::export::outputs::refuse_input_overwrite(
                    "file",
                    file,
                    &[("script", path), ("scenario", scenario)],
                )
                .map_err(|e| fail(e.to_string()))?;
            }
        }
        Ok(script)
    }
}

impl Step {
    /// The step's action name.
    pub fn name(&self) -> &'static str {
        match self {
            Step::Press { .. } => "press",
            Step::Drag { .. } => "drag",
            Step::Depth { .. } => "depth",
            Step::Release {} => "release",
            Step::Play { .. } => "play",
            Step::Scrub { .. } => "scrub",
            Step::Wait { .. } => "wait",
            Step::Mode { .. } => "mode",
            Step::Overlay { .. } => "overlay",
            Step::Orbit { .. } => "orbit",
            Step::Zoom { .. } => "zoom",
            Step::Pan { .. } => "pan",
            Step::ResetCamera {} => "reset_camera",
            Step::Light { .. } => "light",
            Step::Material { .. } => "material",
            Step::Friction { .. } => "friction",
            Step::Key { .. } => "key",
            Step::Screenshot { .. } => "screenshot",
            Step::RecordStart {} => "record_start",
            Step::RecordStop {} => "record_stop",
            Step::SavePath { .. } => "save_path",
            Step::Quit {} => "quit",
        }
    }

    /// Values a step cannot run with, found before the window opens.
    fn check(&self) -> std::result::Result<(), String> {
        let finite = |v: f64, what: &str| {
            if v.is_finite() {
                Ok(())
            } else {
                Err(format!("{what} must be finite, got {v}"))
            }
        };
        match self {
            Step::Press {
                at_mm,
                at_px,
                depth_mm,
            } => {
                if at_mm.is_some() == at_px.is_some() {
                    return Err("give exactly one of at_mm and at_px".into());
                }
                if let Some(d) = depth_mm {
                    if !(d.is_finite() && *d >= 0.0) {
                        return Err(format!("depth_mm must be ≥ 0, got {d}"));
                    }
                }
                if let Some(p) = at_mm {
                    finite(p[0], "at_mm")?;
                    finite(p[1], "at_mm")?;
                }
                if let Some(p) = at_px {
                    finite(p[0] as f64, "at_px")?;
                    finite(p[1] as f64, "at_px")?;
                }
            }
            Step::Drag { to_mm, moves } => {
                finite(to_mm[0], "to_mm")?;
                finite(to_mm[1], "to_mm")?;
                if moves.is_some_and(|m| m == 0 || m > 10_000) {
                    return Err(format!(
                        "moves must be 1 to 10000, got {}",
                        moves.unwrap_or(0)
                    ));
                }
            }
            Step::Depth { mm } if !(mm.is_finite() && *mm >= 0.0) => {
                return Err(format!("mm must be ≥ 0, got {mm}"));
            }
            Step::Wait { seconds: Some(s) }
            | Step::Play {
                seconds: Some(s), ..
            } if !(s.is_finite() && *s >= 0.0) => {
                return Err(format!("seconds must be ≥ 0, got {s}"));
            }
            Step::Mode { mode } if ViewMode::from_name(mode).is_none() => {
                return Err(format!(
                    "unknown mode {mode:?}; expected none, static, dynamic or anisotropic"
                ));
            }
            Step::Overlay { overlay } if Overlay::from_name(overlay).is_none() => {
                return Err(format!(
                    "unknown overlay {overlay:?}; expected off, rs, rt or axes"
                ));
            }
            Step::Zoom { factor } if !(factor.is_finite() && *factor > 0.0) => {
                return Err(format!("factor must be > 0, got {factor}"));
            }
            Step::Key { key } if super::keys::from_name(key).is_none() => {
                return Err(format!("unknown key {key:?}"));
            }
            Step::Scrub { t_s } => finite(*t_s, "t_s")?,
            Step::Play {
                from_s: Some(t), ..
            } => finite(*t, "from_s")?,
            Step::Orbit {
                azimuth_deg,
                elevation_deg,
            } => {
                finite(*azimuth_deg as f64, "azimuth_deg")?;
                finite(*elevation_deg as f64, "elevation_deg")?;
            }
            Step::Pan { right, up } => {
                finite(*right as f64, "right")?;
                finite(*up as f64, "up")?;
            }
            Step::Light {
                azimuth_deg,
                elevation_deg,
                intensity,
            } => {
                for (v, what) in [
                    (azimuth_deg, "azimuth_deg"),
                    (elevation_deg, "elevation_deg"),
                ] {
                    if let Some(v) = v {
                        finite(*v as f64, what)?;
                    }
                }
                if let Some(i) = intensity {
                    if !(i.is_finite() && *i >= 0.0) {
                        return Err(format!("intensity must be ≥ 0, got {i}"));
                    }
                }
            }
            Step::Material {
                youngs_modulus_kpa,
                poisson_ratio,
                ..
            } => {
                finite(*youngs_modulus_kpa, "youngs_modulus_kpa")?;
                finite(*poisson_ratio, "poisson_ratio")?;
            }
            Step::Friction { mu } if !(mu.is_finite() && *mu >= 0.0) => {
                return Err(format!("mu must be ≥ 0, got {mu}"));
            }
            _ => {}
        }
        Ok(())
    }

    /// The commands of a step that maps directly onto the state (`None`
    /// for steps the viewer carries out itself: waits, drags, playback,
    /// files).
    pub fn commands(&self) -> Option<Vec<Command>> {
        Some(match self {
            Step::Press {
                at_mm,
                at_px,
                depth_mm,
            } => {
                let mut c = Vec::new();
                if let Some(d) = depth_mm {
                    c.push(Command::Depth(*d));
                }
                match (at_mm, at_px) {
                    (Some(p), _) => c.push(Command::Press(*p)),
                    (None, Some(px)) => c.push(Command::PressPixel(*px)),
                    (None, None) => {}
                }
                c
            }
            Step::Depth { mm } => vec![Command::Depth(*mm)],
            Step::Release {} => vec![Command::Release],
            Step::Mode { mode } => vec![Command::Mode(ViewMode::from_name(mode)?)],
            Step::Overlay { overlay } => vec![Command::Overlay(Overlay::from_name(overlay)?)],
            Step::Orbit {
                azimuth_deg,
                elevation_deg,
            } => vec![Command::Orbit(*azimuth_deg, *elevation_deg)],
            Step::Zoom { factor } => vec![Command::Zoom(*factor)],
            Step::Pan { right, up } => vec![Command::Pan(*right, *up)],
            Step::ResetCamera {} => vec![Command::ResetCamera],
            Step::Material {
                region,
                youngs_modulus_kpa,
                poisson_ratio,
            } => vec![Command::Material(
                region.clone(),
                *youngs_modulus_kpa,
                *poisson_ratio,
            )],
            Step::Friction { mu } => vec![Command::Friction(*mu)],
            _ => return None,
        })
    }

    /// Whether the step changes what the simulation solves (the script
    /// waits for it to be solved).
    pub fn moves_the_simulation(&self) -> bool {
        matches!(
            self,
            Step::Press { .. }
                | Step::Drag { .. }
                | Step::Depth { .. }
                | Step::Release {}
                | Step::Scrub { .. }
                | Step::Material { .. }
                | Step::Friction { .. }
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Loads `text` as `s.toml` beside a scenario `scenario.toml`; `{dir}`
    /// in the text is their folder, `{dir_name}` its name.
    fn parse(text: &str) -> Result<Script> {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("s.toml");
        let scenario = dir.path().join("scenario.toml");
        std::fs::write(&scenario, "").unwrap();
        let name = dir.path().file_name().unwrap().to_str().unwrap();
        let text = text
            .replace("{dir_name}", name)
            .replace("{dir}", dir.path().to_str().unwrap());
        std::fs::write(&path, text).unwrap();
        Script::load(&path, &scenario)
    }

    #[test]
    fn steps_parse_into_commands() {
        let s = parse(
            "[[step]]\naction = \"press\"\nat_mm = [-1.0, 0.0]\ndepth_mm = 0.5\n\
             [[step]]\naction = \"mode\"\nmode = \"static\"\n\
             [[step]]\naction = \"drag\"\nto_mm = [1.0, 0.0]\nmoves = 3\n\
             [[step]]\naction = \"screenshot\"\nfile = \"a.png\"\n",
        )
        .unwrap();
        assert_eq!(s.step.len(), 4);
        assert_eq!(
            s.step[0].commands().unwrap(),
            vec![Command::Depth(0.5), Command::Press([-1.0, 0.0])]
        );
        assert_eq!(
            s.step[1].commands().unwrap(),
            vec![Command::Mode(ViewMode::Static)]
        );
        assert!(s.step[2].commands().is_none() && s.step[2].moves_the_simulation());
        assert!(!s.step[3].moves_the_simulation());
    }

    #[test]
    fn bad_steps_name_their_step_and_reason() {
        for (text, needle) in [
            (
                "[[step]]\naction = \"press\"\n",
                "step 1 (press): give exactly one",
            ),
            (
                "[[step]]\naction = \"mode\"\nmode = \"shiny\"\n",
                "unknown mode \"shiny\"",
            ),
            ("[[step]]\naction = \"jump\"\n", "jump"),
            (
                "[[step]]\naction = \"zoom\"\nfactor = -1.0\n",
                "factor must be > 0",
            ),
            ("[[step]]\naction = \"release\"\nextra = 1\n", "extra"),
            ("[[step]]\naction = \"key\"\nkey = \"f13\"\n", "unknown key"),
            // Non-finite values, which the window accepted and then never
            // finished (a press at a NaN pixel) or drew only background.
            (
                "[[step]]\naction = \"press\"\nat_px = [nan, 0.0]\n",
                "step 1 (press): at_px must be finite",
            ),
            (
                "[[step]]\naction = \"orbit\"\nazimuth_deg = nan\nelevation_deg = 0.0\n",
                "azimuth_deg must be finite",
            ),
            (
                "[[step]]\naction = \"pan\"\nright = inf\nup = 0.0\n",
                "right must be finite",
            ),
            (
                "[[step]]\naction = \"scrub\"\nt_s = nan\n",
                "t_s must be finite",
            ),
            (
                "[[step]]\naction = \"friction\"\nmu = -1.0\n",
                "mu must be ≥ 0",
            ),
            // Outputs over the run's inputs.
            (
                "[[step]]\naction = \"release\"\n\
                 [[step]]\naction = \"screenshot\"\nfile = \"{dir}/scenario.toml\"\n",
                "step 2 (screenshot): file /",
            ),
            (
                "[[step]]\naction = \"screenshot\"\nfile = \"{dir}/scenario.toml\"\n",
                "is the run's scenario",
            ),
            (
                "[[step]]\naction = \"save_path\"\nfile = \"{dir}/../{dir_name}/s.toml\"\n",
                "is the run's script",
            ),
        ] {
            let err = parse(text).unwrap_err().to_string();
            assert!(err.contains(needle), "{text:?}: {err}");
        }
    }
}
