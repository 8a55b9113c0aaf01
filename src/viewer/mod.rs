//! `skinpatch view`: the interactive viewer. A window shows the scenario's
//! patch through the batch renderer while the FEM runs in its own thread on
//! the probe target the mouse (or a script) sets; a side panel switches the
//! microstructure mode and strain overlays, turns the light, edits materials
//! and records frames and the probe path.
//!
//! Layout: [`state`] (the view and its commands, no window), [`keys`] (the
//! key table), [`script`] (`--script` steps), [`worker`] (the simulation
//! thread), [`record`] (frames and the replayable path), [`present`]
//! (`shaders/present.wgsl`, the image into the window), `frame` (one
//! frame's GPU work: renderer, geometry, chain, render), `app` (the winit
//! event loop, with its rooms: the egui panel, presentation and window
//! captures, the script runner, key actions) and [`offscreen`] (the same
//! loop without a window, timed for `skinpatch bench gpu`).

use std::path::PathBuf;

use crate::error::{Error, Result};
use crate::scenario::{Scenario, Setup};

mod app;
mod frame;
pub mod keys;
pub mod offscreen;
pub mod present;
pub mod record;
pub mod script;
pub mod state;
pub mod worker;

/// The viewer's shader sources by file name, for validation (the passes
/// it draws through are the renderer's).
pub fn shader_sources() -> Vec<(&'static str, String)> {
    vec![("present.wgsl", present::SHADER.to_string())]
}

/// How the viewer runs.
#[derive(Clone, Debug)]
pub struct ViewOptions {
    /// The scenario file.
    pub scenario: PathBuf,
    /// `--set` overrides, as for `skinpatch run`.
    pub overrides: Vec<String>,
    /// Input steps to play (`--script`).
    pub script: Option<PathBuf>,
    /// Close after this many seconds (`--exit-after`).
    pub exit_after: Option<f64>,
    /// Window size (physical pixels).
    pub size: (u32, u32),
    /// Where screenshots, recordings and saved paths go.
    pub record_dir: PathBuf,
}

/// What a viewer session did.
#[derive(Clone, Debug, Default)]
pub struct ViewSummary {
    /// Frames presented.
    pub frames_shown: usize,
    /// Mean display rate over the session (frames presented / s); the
    /// window redraws only when something changes, so this is a floor.
    pub display_fps: f64,
    /// Frames the FEM solved.
    pub fem_frames: usize,
    /// Wall time of the last solved frame (s).
    pub fem_frame_s: f64,
    /// From each probe move to the first frame shown that reflects it (ms).
    pub latencies_ms: Vec<f64>,
    /// Wall time of each microstructure chain run (ms).
    pub micro_ms: Vec<f64>,
    /// Wall time of each render of the 3D view (ms).
    pub render_ms: Vec<f64>,
    /// Size of the 3D view (pixels).
    pub view_size: (usize, usize),
    /// Probe force of the frame shown last (N).
    pub final_force_n: Option<[f64; 3]>,
    /// Files written (screenshots, recordings, saved paths).
    pub written: Vec<PathBuf>,
    /// Whether the user (or the script) closed the viewer.
    pub quit: bool,
}

/// The scenario as loaded for viewing.
pub(crate) struct Loaded {
    scenario: Scenario,
    setup: Setup,
    render: crate::render::RenderSetup,
}

/// Loads the scenario (with overrides) and its setup; a scenario without
/// `[render]` is viewed with the renderer's defaults.
fn load(options: &ViewOptions) -> Result<Loaded> {
    let path = &options.scenario;
    let scenario = Scenario::load_with(path, &options.overrides)?;
    let setup = Setup::from_scenario(&scenario, path)?;
    let render = view_render(&setup)?;
    Ok(Loaded {
        scenario,
        setup,
        render,
    })
}

/// The render settings the viewer draws `setup` with: its `[render]`, or
/// the renderer's defaults (mode `none` without a microstructure).
fn view_render(setup: &Setup) -> Result<crate::render::RenderSetup> {
    match &setup.outputs.render {
        Some(r) => Ok(r.clone()),
        None => crate::scenario::RenderSection::default_setup(setup.outputs.micro.is_some()),
    }
}

/// The viewer's first state for `setup` drawn with `render`, in a view of
/// `viewport` pixels.
fn initial_state(
    setup: &Setup,
    render: &crate::render::RenderSetup,
    viewport: [f32; 2],
) -> state::ViewerState {
    let (lo, hi) = setup.mesh.bounds();
    let probe = setup
        .simulation
        .probe
        .clone()
        .map(|p| state::ProbeControl::new(p, [lo.x, lo.y, lo.z], [hi.x, hi.y, hi.z]));
    let materials = setup
        .mesh
        .regions
        .iter()
        .filter_map(|region| {
            let t = setup.mesh.tet_region.iter().position(|&r| r == region.id)?;
            let m = &setup.simulation.tet_material[t];
            Some(state::RegionMaterial::new(&region.name, m))
        })
        .collect();
    let friction = match setup.simulation.probe.as_ref().map(|p| p.mode) {
        Some(crate::fem::probe::ContactMode::Coulomb(mu)) => Some(mu),
        _ => None,
    };
    let mut state = state::ViewerState::new(
        &render.camera,
        &render.lights,
        probe,
        materials,
        friction,
        viewport,
    );
    state.has_micro = setup.outputs.micro.is_some();
    if !state.has_micro {
        state.mode = state::ViewMode::None;
    }
    state
}

/// Why there is no window system to open a window on, if there is none.
pub fn missing_display() -> Option<String> {
    if !cfg!(all(unix, not(target_os = "macos"))) {
        return None;
    }
    let set = |v: &str| std::env::var_os(v).is_some_and(|s| !s.is_empty());
    if set("DISPLAY") || set("WAYLAND_DISPLAY") {
        return None;
    }
    Some(
        "skinpatch view needs a display: neither DISPLAY (X11) nor WAYLAND_DISPLAY (Wayland) is \
         set. Run it in a desktop session, over `ssh -X`, or on a virtual display: \
         `xvfb-run -a skinpatch view …` (Debian/Ubuntu: `apt-get install xvfb`)"
            .into(),
    )
}

/// Opens the viewer and runs it until it is closed (by the user, a script's
/// `quit` or `--exit-after`).
pub fn run(options: ViewOptions) -> Result<ViewSummary> {
    if let Some(why) = missing_display() {
        return Err(Error::MissingTool(why));
    }
    if let Some(s) = options.exit_after {
        if !(s.is_finite() && s > 0.0) {
            return Err(Error::parameter(
                "--exit-after",
                format!("must be > 0 s, got {s}"),
            ));
        }
    }
    let script = options
        .script
        .as_deref()
        .map(|path| script::Script::load(path, &options.scenario))
        .transpose()?;
    let loaded = load(&options)?;
    let event_loop = winit::event_loop::EventLoop::<app::Wake>::with_user_event()
        .build()
        .map_err(|e| {
            Error::MissingTool(format!(
                "cannot connect to the display ({e}); check DISPLAY / WAYLAND_DISPLAY, or run \
                 on a virtual display: `xvfb-run -a skinpatch view …`"
            ))
        })?;
    let proxy = event_loop.create_proxy();
    let mut app = app::App::new(options, loaded, script, proxy)?;
    event_loop
        .run_app(&mut app)
        .map_err(|e| Error::Gpu(format!("the window's event loop failed: {e}")))?;
    if let Some(e) = app.error.take() {
        return Err(e);
    }
    Ok(std::mem::take(&mut app.summary))
}
