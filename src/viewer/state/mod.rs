//! What the viewer shows and drives, without a window: the orbit camera,
//! the probe control, the shading mode, the overlay, the lights and the
//! material edits. Window input and script steps become [`Command`]s
//! applied here, so every interaction is unit-tested headless; the window
//! loop reads the state back (camera, probe target, versions) each frame.

use glam::Vec3;

use crate::fem::probe::{Probe, ProbePose};
use crate::render::camera::{Camera, Projection};
use crate::render::light::{Light, LightKind};
use crate::render::{Mode, Roughness};

/// What the skin shows.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ViewMode {
    /// Mesoscale normals only.
    None,
    /// The neutral microstructure.
    Static,
    /// The microstructure deformed by the strain (D′).
    Dynamic,
    /// The neutral normals with roughness stretched along the strain axes
    /// (the anisotropic-roughness approximation).
    Anisotropic,
}

impl ViewMode {
    /// Every mode, in panel order.
    pub const ALL: [ViewMode; 4] = [
        ViewMode::None,
        ViewMode::Static,
        ViewMode::Dynamic,
        ViewMode::Anisotropic,
    ];

    /// Name in the panel and in scripts.
    pub fn name(self) -> &'static str {
        match self {
            ViewMode::None => "none",
            ViewMode::Static => "static",
            ViewMode::Dynamic => "dynamic",
            ViewMode::Anisotropic => "anisotropic",
        }
    }

    /// The mode of that name.
    pub fn from_name(name: &str) -> Option<ViewMode> {
        ViewMode::ALL.into_iter().find(|m| m.name() == name)
    }

    /// The renderer's mode and roughness model for this view.
    pub fn render(self) -> (Mode, Roughness) {
        match self {
            ViewMode::None => (Mode::None, Roughness::Microgeometry),
            ViewMode::Static => (Mode::Static, Roughness::Microgeometry),
            ViewMode::Dynamic => (Mode::Dynamic, Roughness::Microgeometry),
            ViewMode::Anisotropic => (Mode::Dynamic, Roughness::Anisotropic),
        }
    }

    /// Whether frames in this mode need the deformed microstructure.
    pub fn needs_deformed_map(self) -> bool {
        self == ViewMode::Dynamic
    }
}

/// A strain colour map drawn on the skin in place of its albedo.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Overlay {
    /// The skin's own albedo.
    Off,
    /// The larger stretch ratio r_s (diverging: blue compression, red stretch).
    Rs,
    /// The smaller stretch ratio r_t.
    Rt,
    /// The s axis as hue, anisotropy r_s − r_t as saturation.
    Axes,
}

impl Overlay {
    /// Every overlay, in panel order.
    pub const ALL: [Overlay; 4] = [Overlay::Off, Overlay::Rs, Overlay::Rt, Overlay::Axes];

    /// Name in the panel and in scripts.
    pub fn name(self) -> &'static str {
        match self {
            Overlay::Off => "off",
            Overlay::Rs => "rs",
            Overlay::Rt => "rt",
            Overlay::Axes => "axes",
        }
    }

    /// The overlay of that name.
    pub fn from_name(name: &str) -> Option<Overlay> {
        Overlay::ALL.into_iter().find(|m| m.name() == name)
    }

    /// The shader's code for it (`globals.options.z`).
    pub fn code(self) -> u32 {
        self as u32
    }
}

/// An orbit camera around a target point, z up.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OrbitCamera {
    /// The point orbited and looked at (mm).
    pub target: Vec3,
    /// Distance from the target (mm).
    pub distance: f32,
    /// Angle of the eye around z from +x (degrees).
    pub azimuth_deg: f32,
    /// Angle of the eye above the xy plane (degrees, within ±89).
    pub elevation_deg: f32,
    /// The scenario's projection (an orthographic height scales with zoom).
    pub projection: Projection,
    // Target, distance, azimuth, elevation and projection to reset to.
    home: (Vec3, f32, f32, f32, Projection),
}

/// Closest the camera may come to its target (mm) and furthest it may go.
const DISTANCE_RANGE: (f32, f32) = (0.5, 2000.0);
/// Steepest elevation (degrees): the view never looks straight down the up axis.
const MAX_ELEVATION: f32 = 89.0;

impl OrbitCamera {
    /// The orbit that reproduces `camera` (its eye, target and projection),
    /// which [`OrbitCamera::reset`] returns to.
    pub fn from_camera(camera: &Camera) -> OrbitCamera {
        let d = camera.eye - camera.target;
        let distance = d.length().max(DISTANCE_RANGE.0);
        let azimuth_deg = d.y.atan2(d.x).to_degrees();
        let elevation_deg = (d.z / distance)
            .clamp(-1.0, 1.0)
            .asin()
            .to_degrees()
            .clamp(-MAX_ELEVATION, MAX_ELEVATION);
        OrbitCamera {
            target: camera.target,
            distance,
            azimuth_deg,
            elevation_deg,
            projection: camera.projection,
            home: (
                camera.target,
                distance,
                azimuth_deg,
                elevation_deg,
                camera.projection,
            ),
        }
    }

    /// The renderer's camera.
    pub fn camera(&self) -> Camera {
        let (az, el) = (
            self.azimuth_deg.to_radians(),
            self.elevation_deg.to_radians(),
        );
        let dir = Vec3::new(el.cos() * az.cos(), el.cos() * az.sin(), el.sin());
        Camera {
            eye: self.target + dir * self.distance,
            target: self.target,
            up: Vec3::Z,
            projection: self.projection,
        }
    }

    /// Turns the eye around the target.
    pub fn orbit(&mut self, d_azimuth_deg: f32, d_elevation_deg: f32) {
        self.azimuth_deg = (self.azimuth_deg + d_azimuth_deg).rem_euclid(360.0);
        self.elevation_deg =
            (self.elevation_deg + d_elevation_deg).clamp(-MAX_ELEVATION, MAX_ELEVATION);
    }

    /// Moves target and eye together in the view plane, by fractions of
    /// the view's height (right and up positive).
    pub fn pan(&mut self, right: f32, up: f32) {
        let cam = self.camera();
        let forward = (cam.target - cam.eye).normalize();
        let side = forward.cross(Vec3::Z).normalize();
        let above = side.cross(forward);
        let height = self.view_height();
        self.target += (side * right + above * up) * height;
    }

    /// Moves the eye towards the target (`factor` < 1) or away (> 1).
    pub fn zoom(&mut self, factor: f32) {
        if !(factor.is_finite() && factor > 0.0) {
            return;
        }
        self.distance = (self.distance * factor).clamp(DISTANCE_RANGE.0, DISTANCE_RANGE.1);
        if let Projection::Orthographic { height_mm } = &mut self.projection {
            *height_mm = (*height_mm * factor).max(1e-3);
        }
    }

    /// Back to the scenario's camera.
    pub fn reset(&mut self) {
        (
            self.target,
            self.distance,
            self.azimuth_deg,
            self.elevation_deg,
            self.projection,
        ) = self.home;
    }

    /// Height of the view at the target (mm).
    fn view_height(&self) -> f32 {
        match self.projection {
            Projection::Perspective { fov_deg } => {
                2.0 * self.distance * (0.5 * fov_deg.to_radians()).tan()
            }
            Projection::Orthographic { height_mm } => height_mm,
        }
    }

    /// The ray through pixel (`x`, `y`) of a `width × height` view (origin
    /// top left): origin and unit direction.
    pub fn ray(&self, x: f32, y: f32, width: f32, height: f32) -> (Vec3, Vec3) {
        let cam = self.camera();
        let forward = (cam.target - cam.eye).normalize();
        let right = forward.cross(Vec3::Z).normalize();
        let up = right.cross(forward);
        // The pixel's offset from the view's centre, in view heights.
        let sx = (2.0 * x / width.max(1.0) - 1.0) * 0.5 * width / height.max(1.0);
        let sy = (1.0 - 2.0 * y / height.max(1.0)) * 0.5;
        match self.projection {
            Projection::Perspective { fov_deg } => {
                let h = 2.0 * (0.5 * fov_deg.to_radians()).tan();
                let dir = forward + (right * sx + up * sy) * h;
                (cam.eye, dir.normalize())
            }
            Projection::Orthographic { height_mm } => {
                let origin = cam.eye + (right * sx + up * sy) * height_mm;
                (origin, forward)
            }
        }
    }
}

/// Where the probe goes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ProbeDrive {
    /// Follows the mouse (or script): pressed to a depth at a point of the
    /// patch, or lifted above it.
    Live,
    /// Follows the scenario's keyframed path at a playback time.
    Path {
        /// Playback time (s).
        t_s: f64,
        /// Whether the time advances with the display.
        playing: bool,
        /// Whether playback wraps to the start at the end.
        looping: bool,
    },
}

/// The probe as the user drives it.
#[derive(Clone, Debug, PartialEq)]
pub struct ProbeControl {
    /// The scenario's probe: its shape, contact mode and keyframed path.
    pub scenario: Probe,
    /// Live or path playback.
    pub drive: ProbeDrive,
    /// Point of the patch (x, y in mm) the probe is over.
    pub at_mm: [f64; 2],
    /// How far it presses below the touching height while pressed (mm).
    pub depth_mm: f64,
    /// Whether it presses (else it hovers above the skin).
    pub pressed: bool,
    /// The top of the patch at rest (mm).
    top_z: f64,
    /// The patch's rest bounds in x and y (mm): the probe stays over it.
    extent: ([f64; 2], [f64; 2]),
    /// Deepest press allowed (mm).
    pub max_depth_mm: f64,
}

/// Height above the touching position a lifted probe hovers at, as a
/// fraction of its radius.
const HOVER: f64 = 0.5;

impl ProbeControl {
    /// The control of `probe` over a patch with rest bounds `lo`..`hi`
    /// (mm), starting live, lifted, over the probe's position at t = 0.
    pub fn new(probe: Probe, lo: [f64; 3], hi: [f64; 3]) -> ProbeControl {
        let start = probe.pose(0.0).centre;
        let thickness = hi[2] - lo[2];
        ProbeControl {
            drive: ProbeDrive::Live,
            at_mm: [start.x, start.y],
            depth_mm: (0.5 * probe.radius_mm()).min(0.25 * thickness),
            pressed: false,
            top_z: hi[2],
            extent: ([lo[0], lo[1]], [hi[0], hi[1]]),
            max_depth_mm: (2.0 * probe.radius_mm()).min(0.6 * thickness),
            scenario: probe,
        }
    }

    /// The probe's pose target now.
    pub fn target(&self) -> ProbePose {
        match self.drive {
            ProbeDrive::Path { t_s, .. } => self.scenario.pose(t_s),
            ProbeDrive::Live => {
                let mut pose = self.scenario.pose(0.0);
                pose.centre.x = self.at_mm[0];
                pose.centre.y = self.at_mm[1];
                // Touching: the lowest point of the probe on the rest top.
                let touching = pose.centre.z - pose.lowest_z() + self.top_z;
                pose.centre.z = if self.pressed {
                    touching - self.depth_mm
                } else {
                    touching + HOVER * self.scenario.radius_mm()
                };
                pose
            }
        }
    }

    /// Duration of the scenario's path (its last keyframe's time, s).
    pub fn path_duration(&self) -> f64 {
        self.scenario.path.points.last().map_or(0.0, |p| p.0)
    }

    fn clamp_to_patch(&self, at: [f64; 2]) -> [f64; 2] {
        let (lo, hi) = self.extent;
        [at[0].clamp(lo[0], hi[0]), at[1].clamp(lo[1], hi[1])]
    }

    /// Advances path playback by `dt` seconds of display time.
    pub fn advance(&mut self, dt: f64) {
        let end = self.path_duration();
        if let ProbeDrive::Path {
            t_s,
            playing: true,
            looping,
        } = &mut self.drive
        {
            *t_s += dt;
            if *t_s > end {
                *t_s = if *looping && end > 0.0 {
                    t_s.rem_euclid(end)
                } else {
                    end
                };
            }
        }
    }
}

/// A change to the view or the simulation's inputs.
#[derive(Clone, Debug, PartialEq)]
pub enum Command {
    /// Orbit by these angles (degrees).
    Orbit(f32, f32),
    /// Pan by fractions of the view height (right, up).
    Pan(f32, f32),
    /// Scale the camera distance.
    Zoom(f32),
    /// Back to the scenario's camera.
    ResetCamera,
    /// Press the probe down at this point of the patch (mm).
    Press([f64; 2]),
    /// Press at the patch point under this pixel (x, y from the top left).
    PressPixel([f32; 2]),
    /// Slide the probe to this point of the patch (mm), pressed or not.
    MoveTo([f64; 2]),
    /// Slide to the patch point under this pixel.
    MovePixel([f32; 2]),
    /// Set the press depth (mm).
    Depth(f64),
    /// Lift the probe off the skin.
    Release,
    /// Drive the probe live (mouse and script).
    Live,
    /// Play the scenario's path from this time (s).
    Play(f64),
    /// Pause or resume path playback.
    Pause(bool),
    /// Jump along the path to this time (s), paused.
    Scrub(f64),
    /// Loop path playback.
    Loop(bool),
    /// Shading mode.
    Mode(ViewMode),
    /// Strain overlay.
    Overlay(Overlay),
    /// Key light direction: azimuth and elevation of where it comes from (degrees).
    LightDirection(f32, f32),
    /// Scale of every light's intensity.
    LightIntensity(f32),
    /// Young's modulus (kPa) and Poisson ratio of a region (by name).
    Material(String, f64, f64),
    /// Coulomb friction coefficient of the probe.
    Friction(f64),
}

/// One region's material as the panel edits it.
#[derive(Clone, Debug, PartialEq)]
pub struct RegionMaterial {
    /// Region name (the scenario's `[material.<region>]`).
    pub region: String,
    /// Young's modulus (kPa).
    pub youngs_kpa: f64,
    /// Poisson ratio.
    pub poisson: f64,
    /// The largest ν the region's volume measure accepts
    /// ([`MAX_POISSON`](crate::fem::material::MAX_POISSON) for the standard
    /// tet, more for a locking-free one).
    pub max_poisson: f64,
}

impl RegionMaterial {
    /// The panel's copy of `material`, for region `region`.
    pub fn new(region: &str, material: &crate::fem::Material) -> RegionMaterial {
        use crate::fem::material::{MAX_POISSON, MAX_POISSON_LOCKING_FREE};
        RegionMaterial {
            region: region.to_string(),
            youngs_kpa: material.youngs_mpa * 1e3,
            poisson: material.poisson,
            max_poisson: match material.volumetric {
                crate::fem::Volumetric::Standard => MAX_POISSON,
                crate::fem::Volumetric::LockingFree => MAX_POISSON_LOCKING_FREE,
            },
        }
    }
}

/// Everything the viewer shows and drives.
#[derive(Clone, Debug)]
pub struct ViewerState {
    /// The camera.
    pub camera: OrbitCamera,
    /// The probe, if the scenario has one.
    pub probe: Option<ProbeControl>,
    /// Shading mode.
    pub mode: ViewMode,
    /// Strain overlay.
    pub overlay: Overlay,
    /// Stretch ratios `1 ± overlay_range` saturate the overlay colours.
    pub overlay_range: f64,
    /// The scenario's lights; the first directional one is the key light
    /// the panel turns.
    base_lights: Vec<Light>,
    /// Key light: where it comes from (azimuth, elevation, degrees).
    pub key_light: Option<(f32, f32)>,
    /// Scale of every light's intensity.
    pub light_scale: f32,
    /// Materials by region, as the panel edits them.
    pub materials: Vec<RegionMaterial>,
    /// Coulomb friction (None: the scenario's contact is not Coulomb).
    pub friction: Option<f64>,
    /// Bumped by every material or friction edit (the simulation follows).
    pub materials_version: u64,
    /// The last rejected command and why (shown in the panel).
    pub rejected: Option<String>,
    /// The view's size in pixels (for picking).
    pub viewport: [f32; 2],
    /// Whether the scenario has a microstructure (modes other than `none`
    /// need one).
    pub has_micro: bool,
}

impl ViewerState {
    /// The state a scenario starts in.
    pub fn new(
        camera: &Camera,
        lights: &[Light],
        probe: Option<ProbeControl>,
        materials: Vec<RegionMaterial>,
        friction: Option<f64>,
        viewport: [f32; 2],
    ) -> ViewerState {
        let key_light = lights.iter().find_map(|l| match l.kind {
            LightKind::Directional(d) => Some(from_direction(-d)),
            LightKind::Point(_) => None,
        });
        ViewerState {
            camera: OrbitCamera::from_camera(camera),
            probe,
            mode: ViewMode::Dynamic,
            overlay: Overlay::Off,
            overlay_range: 0.25,
            base_lights: lights.to_vec(),
            key_light,
            light_scale: 1.0,
            materials,
            friction,
            materials_version: 0,
            rejected: None,
            viewport,
            has_micro: true,
        }
    }

    /// The lights as the panel sets them.
    pub fn lights(&self) -> Vec<Light> {
        let mut key_done = false;
        self.base_lights
            .iter()
            .map(|l| {
                let mut l = *l;
                l.intensity *= self.light_scale;
                if let (LightKind::Directional(_), Some((az, el)), false) =
                    (l.kind, self.key_light, key_done)
                {
                    l.kind = LightKind::Directional(-to_direction(az, el));
                    key_done = true;
                }
                l
            })
            .collect()
    }

    /// The point of the patch's rest top (x, y in mm) under pixel `px`,
    /// or `None` when the ray misses the top's plane.
    pub fn pick(&self, px: [f32; 2]) -> Option<[f64; 2]> {
        let probe = self.probe.as_ref()?;
        let (origin, dir) = self
            .camera
            .ray(px[0], px[1], self.viewport[0], self.viewport[1]);
        let top = probe.top_z as f32;
        if dir.z.abs() < 1e-6 {
            return None;
        }
        let s = (top - origin.z) / dir.z;
        if s <= 0.0 {
            return None;
        }
        let p = origin + dir * s;
        Some([p.x as f64, p.y as f64])
    }

    /// Applies `command`. A command that cannot apply (a probe command
    /// without a probe, a bad value) changes nothing and is noted in
    /// [`ViewerState::rejected`].
    pub fn apply(&mut self, command: Command) {
        if let Err(why) = self.try_apply(command) {
            log::warn!("{why}");
            self.rejected = Some(why);
        }
    }

    /// Sets region `region`'s Young's modulus (kPa) and Poisson ratio.
    fn set_material(&mut self, region: String, e: f64, nu: f64) -> std::result::Result<(), String> {
        if !(e.is_finite() && e > 0.0) {
            return Err(format!(
                "material.{region}: Young's modulus must be > 0 kPa, got {e}"
            ));
        }
        let known: Vec<String> = self.materials.iter().map(|m| m.region.clone()).collect();
        let slot = self
            .materials
            .iter_mut()
            .find(|m| m.region == region)
            .ok_or_else(|| format!("no region {region} (regions: {})", known.join(", ")))?;
        let most = slot.max_poisson;
        if !(nu.is_finite() && (0.0..=most).contains(&nu)) {
            return Err(format!(
                "material.{region}: Poisson ratio must be in [0, {most}], got {nu}"
            ));
        }
        if (slot.youngs_kpa, slot.poisson) != (e, nu) {
            slot.youngs_kpa = e;
            slot.poisson = nu;
            self.materials_version += 1;
        }
        Ok(())
    }

    fn try_apply(&mut self, command: Command) -> std::result::Result<(), String> {
        match command {
            Command::Orbit(a, e) => self.camera.orbit(a, e),
            Command::Pan(r, u) => self.camera.pan(r, u),
            Command::Zoom(f) => self.camera.zoom(f),
            Command::ResetCamera => self.camera.reset(),
            Command::Mode(m) => {
                if m != ViewMode::None && !self.has_micro {
                    return Err(format!(
                        "mode {} needs a [microstructure] section in the scenario",
                        m.name()
                    ));
                }
                self.mode = m;
            }
            Command::Overlay(o) => self.overlay = o,
            Command::LightDirection(az, el) => {
                if self.key_light.is_none() {
                    return Err("the scenario has no directional light to turn".into());
                }
                self.key_light = Some((az.rem_euclid(360.0), el.clamp(-90.0, 90.0)));
            }
            Command::LightIntensity(s) => {
                if !(s.is_finite() && s >= 0.0) {
                    return Err(format!("light intensity scale must be ≥ 0, got {s}"));
                }
                self.light_scale = s;
            }
            Command::Material(region, e, nu) => self.set_material(region, e, nu)?,
            Command::Friction(mu) => {
                if self.friction.is_none() {
                    return Err("the probe's contact is not Coulomb: no friction to set".into());
                }
                if !(mu.is_finite() && mu >= 0.0) {
                    return Err(format!("friction must be ≥ 0, got {mu}"));
                }
                if self.friction != Some(mu) {
                    self.friction = Some(mu);
                    self.materials_version += 1;
                }
            }
            probe_command => {
                let picked = match probe_command {
                    Command::PressPixel(px) | Command::MovePixel(px) => Some(
                        self.pick(px)
                            .ok_or_else(|| format!("pixel {px:?} does not point at the patch"))?,
                    ),
                    _ => None,
                };
                self.probe
                    .as_mut()
                    .ok_or("the scenario has no [probe] to drive")?
                    .apply(probe_command, picked)?;
            }
        }
        Ok(())
    }
}

impl ProbeControl {
    /// Applies a probe command; `picked` is the patch point a pixel
    /// command picked (mm).
    fn apply(
        &mut self,
        command: Command,
        picked: Option<[f64; 2]>,
    ) -> std::result::Result<(), String> {
        match command {
            Command::Press(at) | Command::MoveTo(at) => {
                if !(at[0].is_finite() && at[1].is_finite()) {
                    return Err(format!("probe position must be finite, got {at:?}"));
                }
                self.drive = ProbeDrive::Live;
                self.at_mm = self.clamp_to_patch(at);
                if matches!(command, Command::Press(_)) {
                    self.pressed = true;
                }
            }
            Command::PressPixel(_) | Command::MovePixel(_) => {
                self.drive = ProbeDrive::Live;
                self.at_mm = self.clamp_to_patch(picked.expect("picked above"));
                if matches!(command, Command::PressPixel(_)) {
                    self.pressed = true;
                }
            }
            Command::Depth(d) => {
                if !(d.is_finite() && d >= 0.0) {
                    return Err(format!("probe depth must be ≥ 0 mm, got {d}"));
                }
                self.depth_mm = d.min(self.max_depth_mm);
            }
            Command::Release => self.pressed = false,
            Command::Live => self.drive = ProbeDrive::Live,
            Command::Play(t) => {
                self.drive = ProbeDrive::Path {
                    t_s: t.clamp(0.0, self.path_duration()),
                    playing: true,
                    looping: matches!(self.drive, ProbeDrive::Path { looping: true, .. }),
                }
            }
            Command::Pause(paused) => {
                if let ProbeDrive::Path { playing, .. } = &mut self.drive {
                    *playing = !paused;
                }
            }
            Command::Scrub(t) => {
                let looping = matches!(self.drive, ProbeDrive::Path { looping: true, .. });
                self.drive = ProbeDrive::Path {
                    t_s: t.clamp(0.0, self.path_duration()),
                    playing: false,
                    looping,
                };
            }
            Command::Loop(on) => {
                if let ProbeDrive::Path { looping, .. } = &mut self.drive {
                    *looping = on;
                }
            }
            _ => unreachable!("view commands are handled above"),
        }
        Ok(())
    }
}

/// Unit vector towards azimuth/elevation (degrees), z up.
fn to_direction(azimuth_deg: f32, elevation_deg: f32) -> Vec3 {
    let (a, e) = (azimuth_deg.to_radians(), elevation_deg.to_radians());
    Vec3::new(e.cos() * a.cos(), e.cos() * a.sin(), e.sin())
}

/// Azimuth and elevation (degrees) of a direction.
fn from_direction(d: Vec3) -> (f32, f32) {
    let d = d.normalize_or(Vec3::Z);
    (
        d.y.atan2(d.x).to_degrees().rem_euclid(360.0),
        d.z.clamp(-1.0, 1.0).asin().to_degrees(),
    )
}

#[cfg(test)]
mod tests;
