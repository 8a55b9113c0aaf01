//! The side panel (egui): the view's state as widgets, and what the user
//! changed as [`Command`]s and key actions for the event loop to apply.

use super::{App, PANEL_POINTS};
use crate::viewer::keys::{self, KeyAction};
use crate::viewer::state::{Command, Overlay, ProbeControl, ProbeDrive, ViewMode};

/// What the panel asked for in one frame.
#[derive(Default)]
pub(super) struct PanelOutput {
    pub(super) commands: Vec<Command>,
    pub(super) actions: Vec<KeyAction>,
    // The "mouse drives probe" box was clicked.
    pub(super) toggle_probe_tool: bool,
}

impl App {
    /// The side panel.
    pub(super) fn panel(&self, ui: &mut egui::Ui, out: &mut PanelOutput) {
        egui::Panel::right("panel")
            .exact_size(PANEL_POINTS)
            .resizable(false)
            .show(ui, |ui| {
                egui::ScrollArea::vertical().show(ui, |ui| {
                    self.panel_contents(ui, out);
                });
            });
    }

    fn panel_contents(&self, ui: &mut egui::Ui, out: &mut PanelOutput) {
        let s = &self.state;
        ui.heading(format!("skinpatch — {}", self.loaded.setup.name));
        ui.separator();
        ui.label("Microstructure");
        ui.horizontal_wrapped(|ui| {
            for m in ViewMode::ALL {
                if ui.selectable_label(s.mode == m, m.name()).clicked() {
                    out.commands.push(Command::Mode(m));
                }
            }
        });
        ui.label("Overlay");
        ui.horizontal_wrapped(|ui| {
            for o in Overlay::ALL {
                let name = match o {
                    Overlay::Off => "off",
                    Overlay::Rs => "r_s",
                    Overlay::Rt => "r_t",
                    Overlay::Axes => "axes",
                };
                if ui.selectable_label(s.overlay == o, name).clicked() {
                    out.commands.push(Command::Overlay(o));
                }
            }
        });
        if s.overlay != Overlay::Off {
            legend(ui, s.overlay, s.overlay_range);
        }
        ui.separator();
        if let Some(p) = &s.probe {
            self.probe_section(ui, p, out);
        }
        self.light_and_material_section(ui, out);
        ui.separator();
        self.status_section(ui, out);
    }

    /// The probe: force and contact, depth, press/lift, path playback.
    fn probe_section(&self, ui: &mut egui::Ui, p: &ProbeControl, out: &mut PanelOutput) {
        ui.label("Probe");
        let status = self.worker.as_ref().map(|w| w.status()).unwrap_or_default();
        if let Some(solved) = &self.shown {
            let f = solved.metrics.probe_force_n;
            ui.label(format!(
                "force {:.4} N (z {:.4}), contact {:.3} mm², frame {}",
                (f[0] * f[0] + f[1] * f[1] + f[2] * f[2]).sqrt(),
                f[2],
                solved.metrics.contact_area_mm2,
                solved.metrics.frame
            ));
        }
        if let Some(failure) = &status.failure {
            ui.colored_label(
                egui::Color32::from_rgb(230, 80, 60),
                format!("last solve failed, showing the last good state: {failure}"),
            );
        }
        let mut depth = p.depth_mm;
        if ui
            .add(egui::Slider::new(&mut depth, 0.0..=p.max_depth_mm).text("depth mm"))
            .changed()
        {
            out.commands.push(Command::Depth(depth));
        }
        ui.horizontal(|ui| {
            if p.pressed {
                if ui.button("lift").clicked() {
                    out.commands.push(Command::Release);
                }
            } else if ui.button("press here").clicked() {
                out.commands.push(Command::Press(p.at_mm));
            }
            let mut tool = self.probe_tool;
            if ui.checkbox(&mut tool, "mouse drives probe").changed() {
                out.toggle_probe_tool = true;
            }
        });
        ui.horizontal(|ui| match p.drive {
            ProbeDrive::Live => {
                if ui.button("play path").clicked() {
                    out.commands.push(Command::Play(0.0));
                }
            }
            ProbeDrive::Path {
                t_s,
                playing,
                looping,
            } => {
                if ui.button(if playing { "pause" } else { "play" }).clicked() {
                    out.commands.push(Command::Pause(playing));
                }
                let mut l = looping;
                if ui.checkbox(&mut l, "loop").changed() {
                    out.commands.push(Command::Loop(l));
                }
                if ui.button("live").clicked() {
                    out.commands.push(Command::Live);
                }
                let mut t = t_s;
                if ui
                    .add(egui::Slider::new(&mut t, 0.0..=p.path_duration()).text("s"))
                    .changed()
                {
                    out.commands.push(Command::Scrub(t));
                }
            }
        });
        ui.separator();
    }

    /// The key light, the lights' intensity, materials and friction.
    fn light_and_material_section(&self, ui: &mut egui::Ui, out: &mut PanelOutput) {
        let s = &self.state;
        ui.label("Light");
        if let Some((az, el)) = s.key_light {
            let (mut a, mut e) = (az, el);
            let mut changed = ui
                .add(egui::Slider::new(&mut a, 0.0..=360.0).text("azimuth °"))
                .changed();
            changed |= ui
                .add(egui::Slider::new(&mut e, -90.0..=90.0).text("elevation °"))
                .changed();
            if changed {
                out.commands.push(Command::LightDirection(a, e));
            }
        }
        let mut scale = s.light_scale;
        if ui
            .add(egui::Slider::new(&mut scale, 0.0..=4.0).text("intensity ×"))
            .changed()
        {
            out.commands.push(Command::LightIntensity(scale));
        }
        ui.separator();
        // Materials: edits apply from the next frame.
        ui.label("Material (applied from the next frame)");
        for m in &s.materials {
            let (mut e2, mut nu2) = (m.youngs_kpa, m.poisson);
            ui.horizontal(|ui| {
                ui.label(&m.region);
                let a = ui
                    .add(
                        egui::DragValue::new(&mut e2)
                            .range(0.1..=1e6)
                            .suffix(" kPa"),
                    )
                    .changed();
                let b = ui
                    .add(
                        egui::DragValue::new(&mut nu2)
                            .range(0.0..=m.max_poisson)
                            .speed(0.005)
                            .prefix("ν "),
                    )
                    .changed();
                if a || b {
                    out.commands
                        .push(Command::Material(m.region.clone(), e2, nu2));
                }
            });
        }
        if let Some(mu) = s.friction {
            let mut m = mu;
            if ui
                .add(egui::Slider::new(&mut m, 0.0..=2.0).text("friction μ"))
                .changed()
            {
                out.commands.push(Command::Friction(m));
            }
        }
    }

    /// Rates, recording and screenshots, messages and the key reference.
    fn status_section(&self, ui: &mut egui::Ui, out: &mut PanelOutput) {
        let s = &self.state;
        let status = self.worker.as_ref().map(|w| w.status()).unwrap_or_default();
        ui.label(format!("display {:.1} frames/s", self.rates.display_fps));
        ui.label(format!(
            "FEM {:.2} frames/s ({} solved{})",
            if status.last_frame_s > 0.0 {
                1.0 / status.last_frame_s
            } else {
                0.0
            },
            status.solved,
            if status.busy { ", solving" } else { "" }
        ));
        ui.label(format!(
            "microstructure {:.1} ms, render {:.1} ms",
            self.rates.micro_ms.last().unwrap_or(&0.0),
            self.rates.render_ms.last().unwrap_or(&0.0)
        ));
        if let Some(l) = self.rates.latencies_ms.last() {
            ui.label(format!("probe move to frame shown: {l:.0} ms"));
        }
        ui.separator();
        ui.horizontal_wrapped(|ui| {
            let label = if self.recorder.is_some() {
                "stop recording"
            } else {
                "record"
            };
            if ui.button(label).clicked() {
                out.actions.push(KeyAction::ToggleRecord);
            }
            if ui.button("screenshot").clicked() {
                out.actions.push(KeyAction::Screenshot);
            }
            if ui.button("save path").clicked() {
                out.actions.push(KeyAction::SavePath);
            }
        });
        if let Some(r) = &self.recorder {
            ui.label(format!("recording: {} frames", r.frames()));
        }
        if let Some(m) = &self.message {
            ui.label(m);
        }
        if let Some(r) = &s.rejected {
            ui.colored_label(egui::Color32::from_rgb(230, 160, 60), r);
        }
        egui::CollapsingHeader::new("Keys and mouse").show(ui, |ui| {
            ui.label("left drag: orbit · right/middle drag: pan · wheel: zoom");
            ui.label("ctrl + left drag (or 'mouse drives probe'): press and slide the probe");
            ui.label("shift + wheel: probe depth");
            for (k, what) in keys::KEYS {
                ui.label(format!("{k}: {what}"));
            }
        });
    }
}

/// The overlay's colour bar: 1 − range … 1 + range (r_s, r_t) or the hue
/// circle of the axes.
fn legend(ui: &mut egui::Ui, overlay: Overlay, range: f64) {
    let (rect, _) =
        ui.allocate_exact_size(egui::vec2(PANEL_POINTS - 30.0, 14.0), egui::Sense::hover());
    let painter = ui.painter();
    let steps = 64;
    for k in 0..steps {
        let a = k as f64 / (steps - 1) as f64;
        let rgb = match overlay {
            Overlay::Axes => crate::imaging::colour::direction_colour(
                (a * std::f64::consts::PI).cos(),
                (a * std::f64::consts::PI).sin(),
                &crate::strain::Svd2 {
                    rs: 1.0 + range,
                    rt: 1.0,
                    u_angle: 0.0,
                    v_angle: 0.0,
                },
                range,
            ),
            _ => crate::imaging::colour::diverging(1.0 - range + 2.0 * range * a, range),
        };
        let x0 = rect.left() + rect.width() * k as f32 / steps as f32;
        let x1 = rect.left() + rect.width() * (k + 1) as f32 / steps as f32;
        painter.rect_filled(
            egui::Rect::from_min_max(egui::pos2(x0, rect.top()), egui::pos2(x1, rect.bottom())),
            0.0,
            egui::Color32::from_rgb(rgb[0], rgb[1], rgb[2]),
        );
    }
    ui.horizontal(|ui| match overlay {
        Overlay::Axes => {
            ui.label("s axis 0° … 180° (saturation: r_s − r_t)");
        }
        _ => {
            ui.label(format!(
                "{:.2} (compressed) … 1 … {:.2} (stretched)",
                1.0 - range,
                1.0 + range
            ));
        }
    });
}
