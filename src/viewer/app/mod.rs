//! The window: winit events and the egui panel become [`Command`]s on the
//! [`ViewerState`]; each redraw hands the probe target to the simulation
//! thread, takes its newest solved state, runs the microstructure chain and
//! the renderer on it when it is new, and presents the image beside the
//! panel. What it decides is in `state`, `script`, `worker` and `record`;
//! its own rooms are [`actions`] (key actions, recording, saved paths),
//! [`panel`] (the egui side panel), [`window`]
//! (presentation and window captures) and [`script_run`] (the `--script`
//! runner).

mod actions;
mod panel;
mod script_run;
mod window;

use std::path::PathBuf;
use std::sync::Arc;
use std::time::{Duration, Instant};

use winit::application::ApplicationHandler;
use winit::event::{ElementState, MouseButton, MouseScrollDelta, WindowEvent};
use winit::event_loop::{ActiveEventLoop, ControlFlow, EventLoopProxy};
use winit::keyboard::{Key, ModifiersState, NamedKey};
use winit::window::{Window, WindowId};

use self::script_run::ScriptRun;
use super::frame::{render_state, run_chain, upload_solved, RenderInputs};
use super::keys;
use super::present::PresentStage;
use super::record::FrameRecorder;
use super::script::Script;
use super::state::{Command, ProbeDrive, ViewerState};
use super::worker::{FemWorker, Solved};
use super::{Loaded, ViewOptions, ViewSummary};
use crate::error::{Error, Result};
use crate::gpu::micro::GpuMicro;
use crate::gpu::Context;
use crate::render::{Image, Renderer};
use crate::strain::SurfaceField;

/// Width of the side panel (logical points).
const PANEL_POINTS: f32 = 300.0;

/// Wakes the event loop from the simulation thread.
#[derive(Debug, Clone, Copy)]
pub(super) enum Wake {
    /// A frame was solved (or failed).
    Solved,
}

/// Everything on the GPU: the device (the chain's, or the viewer's own
/// without a microstructure), the renderer and the window's surface.
struct Gpu {
    window: Arc<Window>,
    surface: wgpu::Surface<'static>,
    config: wgpu::SurfaceConfiguration,
    chain: Option<GpuMicro>,
    own: Option<Context>,
    renderer: Renderer,
    render_size: (usize, usize),
    present: PresentStage,
    present_bind: wgpu::BindGroup,
    egui_state: egui_winit::State,
    egui_renderer: egui_wgpu::Renderer,
}

impl Gpu {
    fn ctx(&self) -> &Context {
        device(&self.chain, &self.own)
    }
}

/// The device: the chain's, or the viewer's own without a microstructure
/// (a free function so the other fields of [`Gpu`] stay borrowable).
fn device<'a>(chain: &'a Option<GpuMicro>, own: &'a Option<Context>) -> &'a Context {
    match (chain, own) {
        (Some(chain), _) => chain.context(),
        (None, Some(ctx)) => ctx,
        (None, None) => unreachable!("a device is always kept"),
    }
}

/// Rates shown in the panel and reported at the end.
#[derive(Default)]
struct Rates {
    frames: usize,
    started: Option<Instant>,
    last_frame: Option<Instant>,
    display_fps: f64,
    // Every chain run and 3D render (ms); the panel shows the last.
    micro_ms: Vec<f64>,
    render_ms: Vec<f64>,
    // Target sent and when, until a shown frame reflects it.
    pending: Option<(Instant, crate::fem::probe::ProbePose)>,
    latencies_ms: Vec<f64>,
}

pub(super) struct App {
    options: ViewOptions,
    loaded: Loaded,
    inputs: RenderInputs,
    state: ViewerState,
    worker: Option<FemWorker>,
    proxy: EventLoopProxy<Wake>,
    gpu: Option<Gpu>,
    egui: egui::Context,
    script: Option<ScriptRun>,
    started: Instant,
    // The solved state shown, the one the chain last ran on, the render
    // settings of the image shown.
    shown: Option<Arc<Solved>>,
    chain_on: Option<usize>,
    field: Option<SurfaceField>,
    dirty: bool,
    materials_sent: u64,
    recorder: Option<FrameRecorder>,
    screenshots: Vec<PathBuf>,
    // Files for captures of the whole window (panel included).
    window_shots: Vec<PathBuf>,
    written: Vec<PathBuf>,
    message: Option<String>,
    modifiers: ModifiersState,
    cursor: Option<[f32; 2]>,
    dragging: Option<MouseButton>,
    probe_tool: bool,
    rates: Rates,
    pub(super) error: Option<Error>,
    pub(super) summary: ViewSummary,
}

impl App {
    pub(super) fn new(
        options: ViewOptions,
        loaded: Loaded,
        script: Option<Script>,
        proxy: EventLoopProxy<Wake>,
    ) -> Result<App> {
        let inputs = RenderInputs::new(&loaded.setup, loaded.render.clone())?;
        let viewport = [options.size.0 as f32, options.size.1 as f32];
        let state = super::initial_state(&loaded.setup, &loaded.render, viewport);
        Ok(App {
            inputs,
            state,
            worker: None,
            proxy,
            gpu: None,
            egui: egui::Context::default(),
            script: script.map(|s| ScriptRun {
                steps: s.step,
                next: 0,
                waiting: None,
            }),
            started: Instant::now(),
            shown: None,
            chain_on: None,
            field: None,
            dirty: true,
            materials_sent: 0,
            recorder: None,
            screenshots: Vec::new(),
            window_shots: Vec::new(),
            written: Vec::new(),
            message: None,
            modifiers: ModifiersState::empty(),
            cursor: None,
            dragging: None,
            probe_tool: false,
            rates: Rates::default(),
            error: None,
            summary: ViewSummary::default(),
            options,
            loaded,
        })
    }

    fn fail(&mut self, event_loop: &ActiveEventLoop, e: Error) {
        if self.error.is_none() {
            self.error = Some(e);
        }
        event_loop.exit();
    }

    /// Opens the window, the device, the renderer and the worker.
    fn start(&mut self, event_loop: &ActiveEventLoop) -> Result<()> {
        let (w, h) = self.options.size;
        let attributes = Window::default_attributes()
            .with_title(format!("skinpatch view — {}", self.loaded.setup.name))
            .with_inner_size(winit::dpi::PhysicalSize::new(w, h));
        let window = Arc::new(
            event_loop
                .create_window(attributes)
                .map_err(|e| Error::Gpu(format!("opening the window: {e}")))?,
        );
        let (ctx, surface, caps) = Context::for_window(window.clone())?;
        let format = caps
            .formats
            .iter()
            .copied()
            .find(|f| !f.is_srgb())
            .or_else(|| caps.formats.first().copied())
            .ok_or_else(|| Error::Gpu("the window's surface offers no format".into()))?;
        let size = window.inner_size();
        // Copies out of the window's frames, where allowed, for window
        // screenshots.
        let copy = caps.usages & wgpu::TextureUsages::COPY_SRC;
        let config = wgpu::SurfaceConfiguration {
            usage: wgpu::TextureUsages::RENDER_ATTACHMENT | copy,
            format,
            width: size.width.max(1),
            height: size.height.max(1),
            present_mode: wgpu::PresentMode::Fifo,
            desired_maximum_frame_latency: 2,
            alpha_mode: caps.alpha_modes[0],
            view_formats: vec![],
            color_space: wgpu::SurfaceColorSpace::Auto,
        };
        surface.configure(&ctx.device, &config);
        let (chain, own) = match &self.loaded.setup.outputs.micro {
            Some(m) => {
                let chain = crate::pipeline::gpu_chain(ctx, m)?;
                (Some(chain), None)
            }
            None => (None, Some(ctx)),
        };
        let device_ctx = chain.as_ref().map(GpuMicro::context).or(own.as_ref());
        let device_ctx = device_ctx.expect("one of the two is set");
        let render_size = view_size(&window, size.width, size.height);
        let renderer = self
            .inputs
            .renderer(device_ctx, chain.as_ref(), render_size)?;
        let present = PresentStage::new(device_ctx, format);
        let (pixels, pw, ph) = renderer.pixels();
        let present_bind = present.bind(device_ctx, pixels, (pw, ph), [0.0, 0.0]);
        let egui_state = egui_winit::State::new(
            self.egui.clone(),
            egui::ViewportId::ROOT,
            &window,
            Some(window.scale_factor() as f32),
            None,
            Some(device_ctx.limits.max_texture_dimension_2d as usize),
        );
        let egui_renderer = egui_wgpu::Renderer::new(
            &device_ctx.device,
            format,
            egui_wgpu::RendererOptions::default(),
        );
        log::info!(
            "viewer on {}: window {}×{} px, surface {format:?}",
            device_ctx.describe(),
            size.width,
            size.height
        );
        self.state.viewport = [render_size.0 as f32, render_size.1 as f32];
        let proxy = self.proxy.clone();
        let initial = self.state.probe.as_ref().map(|p| p.target());
        self.worker = Some(FemWorker::spawn(
            self.loaded.setup.simulation.clone(),
            self.loaded.setup.mesh.clone(),
            initial,
            Box::new(move || {
                let _ = proxy.send_event(Wake::Solved);
            }),
        ));
        self.gpu = Some(Gpu {
            window,
            surface,
            config,
            chain,
            own,
            renderer,
            render_size,
            present,
            present_bind,
            egui_state,
            egui_renderer,
        });
        Ok(())
    }

    fn worker(&self) -> &FemWorker {
        self.worker.as_ref().expect("started with the window")
    }

    /// Sends the probe target and material edits to the simulation.
    fn sync_simulation(&mut self) -> Result<()> {
        if self.state.materials_version != self.materials_sent {
            self.materials_sent = self.state.materials_version;
            let mut scenario = self.loaded.scenario.clone();
            for edited in &self.state.materials {
                let m = scenario.material.entry(edited.region.clone()).or_default();
                m.youngs_modulus_kpa = Some(edited.youngs_kpa);
                m.poisson_ratio = Some(edited.poisson);
            }
            if let (Some(p), Some(mu)) = (scenario.probe.as_mut(), self.state.friction) {
                p.friction = Some(mu);
            }
            match scenario.simulation(&self.loaded.setup.mesh) {
                Ok(sim) => {
                    let mode = sim.probe.as_ref().map(|p| p.mode);
                    self.worker().set_materials(sim.tet_material, mode);
                }
                Err(e) => self.state.rejected = Some(e.to_string()),
            }
        }
        if let Some(probe) = &self.state.probe {
            let target = probe.target();
            let worker = self.worker.as_ref().expect("started with the window");
            let before = worker.status().busy;
            worker.set_target(target);
            if !before && worker.status().busy && self.rates.pending.is_none() {
                self.rates.pending = Some((Instant::now(), target));
            }
        }
        Ok(())
    }

    /// Takes the newest solved state; runs the chain and uploads geometry
    /// when it is new (or the mode now needs the chain).
    fn update_scene(&mut self) -> Result<()> {
        let latest = self.worker().latest();
        let gpu = self.gpu.as_mut().expect("started");
        let fresh = match (&latest, &self.shown) {
            (Some(a), Some(b)) => !Arc::ptr_eq(a, b),
            (Some(_), None) => true,
            _ => false,
        };
        let Some(solved) = latest else {
            return Ok(());
        };
        let mesh = &self.loaded.setup.mesh;
        if fresh {
            let ctx = device(&gpu.chain, &gpu.own);
            let tessellate = self.inputs.setup.tessellate;
            let field = upload_solved(ctx, &mut gpu.renderer, mesh, &solved, tessellate);
            self.field = Some(field);
            self.shown = Some(solved.clone());
            self.dirty = true;
        }
        let frame = solved.metrics.frame;
        if self.state.mode.needs_deformed_map() && self.chain_on != Some(frame) {
            if let (Some(chain), Some(field)) = (gpu.chain.as_mut(), &self.field) {
                self.rates.micro_ms.push(run_chain(chain, field)?);
                self.chain_on = Some(frame);
                self.dirty = true;
            }
        }
        Ok(())
    }

    /// Renders the 3D view when anything it shows changed.
    fn render_view(&mut self) -> Result<bool> {
        let gpu = self.gpu.as_mut().expect("started");
        let size = gpu.window.inner_size();
        let wanted = view_size(&gpu.window, size.width, size.height);
        if wanted != gpu.render_size {
            let ctx = device(&gpu.chain, &gpu.own);
            gpu.renderer = self.inputs.renderer(ctx, gpu.chain.as_ref(), wanted)?;
            gpu.render_size = wanted;
            self.state.viewport = [wanted.0 as f32, wanted.1 as f32];
            let (pixels, pw, ph) = gpu.renderer.pixels();
            gpu.present_bind = gpu.present.bind(ctx, pixels, (pw, ph), [0.0, 0.0]);
            // The new renderer has no geometry yet.
            self.shown = None;
            self.dirty = true;
            return Ok(false);
        }
        if !self.dirty || self.shown.is_none() {
            return Ok(false);
        }
        let ctx = device(&gpu.chain, &gpu.own);
        let ms = render_state(ctx, &mut gpu.renderer, &self.state)?;
        self.rates.render_ms.push(ms);
        self.dirty = false;
        Ok(true)
    }

    /// The image shown, read back.
    fn read_image(&self) -> Result<Image> {
        let gpu = self.gpu.as_ref().expect("started");
        let (pixels, w, h) = gpu.renderer.pixels();
        let data: Vec<[f32; 4]> = crate::gpu::buffers::read(gpu.ctx(), pixels, w * h)?;
        Ok(Image {
            width: w,
            height: h,
            pixels: data,
        })
    }

    fn redraw(&mut self, event_loop: &ActiveEventLoop) -> Result<()> {
        let now = Instant::now();
        let dt = self
            .rates
            .last_frame
            .map_or(0.0, |t| now.duration_since(t).as_secs_f64());
        if let Some(p) = self.state.probe.as_mut() {
            p.advance(dt);
        }
        self.update_scene()?;
        self.run_script(event_loop)?;
        self.sync_simulation()?;
        let rendered = self.render_view()?;
        if rendered {
            if let Some((sent, target)) = self.rates.pending {
                if self.shown.as_ref().and_then(|s| s.pose) == Some(target) {
                    self.rates
                        .latencies_ms
                        .push(sent.elapsed().as_secs_f64() * 1e3);
                    self.rates.pending = None;
                }
            }
            let image = match self.recorder {
                Some(_) => Some(self.read_image()?),
                None => None,
            };
            if let (Some(recorder), Some(image)) = (self.recorder.as_mut(), image) {
                recorder.push(&image)?;
            }
        }
        let shots = std::mem::take(&mut self.screenshots);
        if !shots.is_empty() {
            // One read-back for every shot of this redraw.
            let image = self.read_image()?;
            for path in shots {
                if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
                    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
                }
                crate::export::frames::write_image(
                    &path,
                    &image,
                    crate::render::FrameFormat::Png8,
                )?;
                self.message = Some(format!("saved {}", path.display()));
                self.written.push(path);
            }
        }
        self.present()?;
        // Display rate: frames presented, smoothed.
        if let Some(last) = self.rates.last_frame {
            let fps = 1.0 / now.duration_since(last).as_secs_f64().max(1e-6);
            self.rates.display_fps = if self.rates.display_fps == 0.0 {
                fps
            } else {
                0.9 * self.rates.display_fps + 0.1 * fps
            };
        }
        self.rates.last_frame = Some(now);
        self.rates.started.get_or_insert(now);
        self.rates.frames += 1;
        let playing = matches!(
            self.state.probe.as_ref().map(|p| p.drive),
            Some(ProbeDrive::Path { playing: true, .. })
        );
        let scripted = self
            .script
            .as_ref()
            .is_some_and(|s| s.next < s.steps.len() || s.waiting.is_some());
        if playing || scripted || self.dirty || self.worker().status().busy {
            self.gpu.as_ref().expect("started").window.request_redraw();
        }
        Ok(())
    }

    fn mouse_drag(&mut self, dx: f32, dy: f32, at: [f32; 2]) {
        match self.dragging {
            Some(MouseButton::Left) if self.probe_driving() => {
                self.state.apply(Command::MovePixel(at));
                self.state.rejected = None;
            }
            Some(MouseButton::Left) => self.state.apply(Command::Orbit(-0.3 * dx, 0.3 * dy)),
            Some(MouseButton::Right | MouseButton::Middle) => {
                let h = self.state.viewport[1].max(1.0);
                self.state.apply(Command::Pan(-dx / h, dy / h));
            }
            _ => return,
        }
        self.dirty = true;
    }

    fn probe_driving(&self) -> bool {
        self.state.probe.is_some() && (self.probe_tool || self.modifiers.control_key())
    }
}

impl ApplicationHandler<Wake> for App {
    fn resumed(&mut self, event_loop: &ActiveEventLoop) {
        if self.gpu.is_some() {
            return;
        }
        event_loop.set_control_flow(ControlFlow::Wait);
        if let Err(e) = self.start(event_loop) {
            self.fail(event_loop, e);
            return;
        }
        self.gpu.as_ref().expect("started").window.request_redraw();
    }

    fn user_event(&mut self, _event_loop: &ActiveEventLoop, _event: Wake) {
        if let Some(gpu) = &self.gpu {
            gpu.window.request_redraw();
        }
    }

    fn window_event(&mut self, event_loop: &ActiveEventLoop, _id: WindowId, event: WindowEvent) {
        let Some(gpu) = self.gpu.as_mut() else {
            return;
        };
        let response = gpu.egui_state.on_window_event(&gpu.window, &event);
        if response.repaint {
            gpu.window.request_redraw();
        }
        match event {
            WindowEvent::CloseRequested => {
                self.summary.quit = true;
                event_loop.exit();
            }
            WindowEvent::Resized(size) => {
                let gpu = self.gpu.as_mut().expect("checked");
                gpu.config.width = size.width.max(1);
                gpu.config.height = size.height.max(1);
                gpu.surface.configure(&gpu.ctx().device, &gpu.config);
                gpu.window.request_redraw();
            }
            WindowEvent::RedrawRequested => {
                if let Err(e) = self.redraw(event_loop) {
                    self.fail(event_loop, e);
                }
                if self.summary.quit {
                    event_loop.exit();
                }
            }
            _ if response.consumed => {}
            WindowEvent::ModifiersChanged(m) => self.modifiers = m.state(),
            WindowEvent::KeyboardInput { event, .. } if event.state == ElementState::Pressed => {
                let name = match &event.logical_key {
                    Key::Named(NamedKey::Space) => Some("space".to_string()),
                    Key::Named(NamedKey::ArrowLeft) => Some("left".into()),
                    Key::Named(NamedKey::ArrowRight) => Some("right".into()),
                    Key::Named(NamedKey::ArrowUp) => Some("up".into()),
                    Key::Named(NamedKey::ArrowDown) => Some("down".into()),
                    Key::Named(NamedKey::Escape) => Some("escape".into()),
                    Key::Character(c) => Some(c.to_string()),
                    _ => None,
                };
                if let Some(action) = name.as_deref().and_then(keys::from_name) {
                    if let Err(e) = self.key_action(action) {
                        self.fail(event_loop, e);
                    }
                    if self.summary.quit {
                        event_loop.exit();
                    }
                    self.gpu.as_ref().expect("checked").window.request_redraw();
                }
            }
            WindowEvent::CursorMoved { position, .. } => {
                let at = [position.x as f32, position.y as f32];
                if let Some(last) = self.cursor {
                    self.mouse_drag(at[0] - last[0], at[1] - last[1], at);
                }
                self.cursor = Some(at);
                if self.dirty {
                    self.gpu.as_ref().expect("checked").window.request_redraw();
                }
            }
            WindowEvent::MouseInput { state, button, .. } => {
                match state {
                    ElementState::Pressed => {
                        self.dragging = Some(button);
                        if button == MouseButton::Left && self.probe_driving() {
                            if let Some(at) = self.cursor {
                                self.state.apply(Command::PressPixel(at));
                            }
                        }
                    }
                    ElementState::Released => {
                        if button == MouseButton::Left && self.probe_driving() {
                            self.state.apply(Command::Release);
                        }
                        self.dragging = None;
                    }
                }
                self.dirty = true;
                self.gpu.as_ref().expect("checked").window.request_redraw();
            }
            WindowEvent::MouseWheel { delta, .. } => {
                let lines = match delta {
                    MouseScrollDelta::LineDelta(_, y) => y,
                    MouseScrollDelta::PixelDelta(p) => p.y as f32 / 40.0,
                };
                if self.modifiers.shift_key() {
                    if let Some(p) = &self.state.probe {
                        let d = p.depth_mm + 0.05 * lines as f64;
                        self.state.apply(Command::Depth(d.max(0.0)));
                    }
                } else {
                    self.state.apply(Command::Zoom(0.9f32.powf(lines)));
                }
                self.dirty = true;
                self.gpu.as_ref().expect("checked").window.request_redraw();
            }
            _ => {}
        }
    }

    fn about_to_wait(&mut self, event_loop: &ActiveEventLoop) {
        if let Some(limit) = self.options.exit_after {
            let elapsed = self.started.elapsed().as_secs_f64();
            if elapsed >= limit {
                let unfinished = self
                    .script
                    .as_ref()
                    .is_some_and(|s| s.next < s.steps.len() || s.waiting.is_some());
                if unfinished && self.error.is_none() {
                    let run = self.script.as_ref().expect("checked");
                    self.error = Some(Error::parameter(
                        "--exit-after",
                        format!(
                            "{limit} s ran out with the script still at step {} of {} (not \
                             a solver failure: give it more time)",
                            run.next,
                            run.steps.len()
                        ),
                    ));
                }
                event_loop.exit();
                return;
            }
            event_loop.set_control_flow(ControlFlow::WaitUntil(
                self.started + Duration::from_secs_f64(limit),
            ));
        }
    }

    fn exiting(&mut self, _event_loop: &ActiveEventLoop) {
        if self.recorder.is_some() {
            if let Err(e) = self.toggle_record() {
                self.error.get_or_insert(e);
            }
        }
        // The session's frames as `skinpatch run` would list them.
        let metrics = self
            .worker
            .as_ref()
            .map(|w| w.metrics())
            .unwrap_or_default();
        if !metrics.is_empty() {
            if let Err(e) = write_metrics(&self.options.record_dir, &metrics) {
                self.error.get_or_insert(e);
            } else {
                self.written
                    .push(self.options.record_dir.join("metrics.csv"));
            }
        }
        let status = self.worker.as_ref().map(|w| w.status()).unwrap_or_default();
        let s = &mut self.summary;
        s.frames_shown = self.rates.frames;
        s.display_fps = match (self.rates.started, self.rates.last_frame) {
            (Some(a), Some(b)) if self.rates.frames > 1 => {
                (self.rates.frames - 1) as f64 / b.duration_since(a).as_secs_f64().max(1e-9)
            }
            _ => 0.0,
        };
        s.fem_frames = status.solved;
        s.fem_frame_s = status.last_frame_s;
        s.latencies_ms = self.rates.latencies_ms.clone();
        s.micro_ms = std::mem::take(&mut self.rates.micro_ms);
        s.render_ms = std::mem::take(&mut self.rates.render_ms);
        s.view_size = self.gpu.as_ref().map_or((0, 0), |g| g.render_size);
        s.final_force_n = self.shown.as_ref().map(|x| x.metrics.probe_force_n);
        s.written = std::mem::take(&mut self.written);
    }
}

/// Writes `metrics.csv` of the solved frames into `dir`.
fn write_metrics(dir: &std::path::Path, metrics: &[crate::export::FrameMetrics]) -> Result<()> {
    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    let mut writer = crate::export::MetricsWriter::create(&dir.join("metrics.csv"))?;
    for m in metrics {
        writer.push(m)?;
    }
    Ok(())
}

/// Size of the 3D view: the window less the panel.
fn view_size(window: &Window, width: u32, height: u32) -> (usize, usize) {
    let panel = (PANEL_POINTS as f64 * window.scale_factor()).ceil() as u32;
    (
        width.saturating_sub(panel).max(16) as usize,
        height.max(16) as usize,
    )
}
