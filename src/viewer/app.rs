//! The window: winit events and the egui panel become [`Command`]s on the
//! [`ViewerState`]; each redraw hands the probe target to the simulation
//! thread, takes its newest solved state, runs the microstructure chain and
//! the renderer on it when it is new, and presents the image beside the
//! panel. Kept thin on purpose: what it decides is in `state`, `script`,
//! `worker` and `record`.

use std::path::PathBuf;
use std::sync::Arc;
use std::time::{Duration, Instant};

use image::ImageEncoder;
use winit::application::ApplicationHandler;
use winit::event::{ElementState, MouseButton, MouseScrollDelta, WindowEvent};
use winit::event_loop::{ActiveEventLoop, ControlFlow, EventLoopProxy};
use winit::keyboard::{Key, ModifiersState, NamedKey};
use winit::window::{Window, WindowId};

use super::keys::{self, KeyAction};
use super::present::PresentStage;
use super::record::{self, FrameRecorder};
use super::script::{Script, Step};
use super::state::{Command, Overlay, ProbeDrive, ViewMode, ViewerState};
use super::worker::{FemWorker, Solved};
use super::{Loaded, ViewOptions, ViewSummary};
use crate::error::{Error, Result};
use crate::gpu::micro::GpuMicro;
use crate::gpu::Context;
use crate::render::albedo::Albedo;
use crate::render::overlay::OverlayKind;
use crate::render::{Image, NormalMap, RenderSetup, Renderer};
use crate::strain::SurfaceField;

/// Width of the side panel (logical points).
const PANEL_POINTS: f32 = 300.0;
/// How long a script waits for one simulated frame before giving up.
const FEM_TIMEOUT: Duration = Duration::from_secs(600);

/// Wakes the event loop from the simulation thread.
#[derive(Debug, Clone, Copy)]
pub(super) enum Wake {
    /// A frame was solved (or failed).
    Solved,
}

/// What a running script waits for before its next step.
enum Waiting {
    /// The simulation to solve every target so far (and its frame to be
    /// shown), since this instant; then the remaining moves of a drag, each
    /// solved before the next.
    Fem(Instant, Vec<[f64; 2]>),
    /// Display time to pass.
    Until(Instant),
}

/// What the panel asked for in one frame.
#[derive(Default)]
struct PanelOutput {
    commands: Vec<Command>,
    actions: Vec<KeyAction>,
    // The "mouse drives probe" box was clicked.
    toggle_probe_tool: bool,
}

struct ScriptRun {
    steps: Vec<Step>,
    next: usize,
    waiting: Option<Waiting>,
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

/// Inputs the renderer is rebuilt from when the view changes size.
struct RenderInputs {
    setup: RenderSetup,
    albedo: Albedo,
    // The neutral map's normals and its width and height.
    neutral: Option<(Vec<[f32; 3]>, usize, usize)>,
    curve: [f32; 16],
    texel_mm: f64,
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
    pending: Option<(Instant, crate::fem::contact::ProbePose)>,
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
        let setup = &loaded.setup;
        let render = loaded.render.clone();
        let (lo, hi) = setup.mesh.bounds();
        let albedo = Albedo::from_source(&render.albedo, render.texture_px, hi.x - lo.x)?;
        let neutral = setup
            .micro
            .as_ref()
            .map(|m| m.neutral.whole("skinpatch view"))
            .transpose()?
            .map(|map| {
                (
                    crate::micro::normals::normal_map(map),
                    map.width,
                    map.height,
                )
            });
        let mut anisotropic = render.clone();
        anisotropic.roughness = crate::render::Roughness::Anisotropic;
        let curve = crate::pipeline::roughness_curve(&anisotropic, setup.micro.as_ref());
        let texel_mm = crate::pipeline::texel_mm((lo, hi), render.texture_px);
        let state = super::initial_state(&loaded, [options.size.0 as f32, options.size.1 as f32]);
        Ok(App {
            inputs: RenderInputs {
                setup: render,
                albedo,
                neutral,
                curve,
                texel_mm,
            },
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
        let (chain, own) = match &self.loaded.setup.micro {
            Some(m) => {
                let chain = crate::pipeline::gpu_chain(ctx, m)?;
                (Some(chain), None)
            }
            None => (None, Some(ctx)),
        };
        let device_ctx = chain.as_ref().map(GpuMicro::context).or(own.as_ref());
        let device_ctx = device_ctx.expect("one of the two is set");
        let render_size = view_size(&window, size.width, size.height);
        let renderer = build_renderer(device_ctx, &self.inputs, chain.as_ref(), render_size)?;
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
            for (region, e, nu) in &self.state.materials {
                let m = scenario.material.entry(region.clone()).or_default();
                m.youngs_modulus_kpa = Some(*e);
                m.poisson_ratio = Some(*nu);
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
            let field = SurfaceField::new(&mesh.top, &mesh.positions, &solved.positions);
            let geometry = crate::render::scene::build(
                mesh,
                &solved.positions,
                &field,
                solved.pose.as_ref(),
                self.inputs.setup.tessellate,
            );
            let ctx = device(&gpu.chain, &gpu.own);
            gpu.renderer.set_geometry(ctx, &geometry);
            self.field = Some(field);
            self.shown = Some(solved.clone());
            self.dirty = true;
        }
        let frame = solved.metrics.frame;
        if self.state.mode.needs_deformed_map() && self.chain_on != Some(frame) {
            if let (Some(chain), Some(field)) = (gpu.chain.as_mut(), &self.field) {
                let start = Instant::now();
                chain.submit(field, true);
                chain.context().finish()?;
                self.rates
                    .micro_ms
                    .push(start.elapsed().as_secs_f64() * 1e3);
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
            gpu.renderer = build_renderer(ctx, &self.inputs, gpu.chain.as_ref(), wanted)?;
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
        let (mode, roughness) = self.state.mode.render();
        let overlay = match self.state.overlay {
            Overlay::Off => OverlayKind::Off,
            Overlay::Rs => OverlayKind::Rs,
            Overlay::Rt => OverlayKind::Rt,
            Overlay::Axes => OverlayKind::Axes,
        };
        let lights = self.state.lights();
        let camera = self.state.camera.camera();
        let ctx = device(&gpu.chain, &gpu.own);
        let start = Instant::now();
        let renderer = &mut gpu.renderer;
        renderer.set_view(camera, &lights)?;
        renderer.set_roughness(roughness);
        renderer.set_overlay(overlay, self.state.overlay_range as f32);
        renderer.submit(ctx, mode);
        ctx.finish()?;
        self.rates
            .render_ms
            .push(start.elapsed().as_secs_f64() * 1e3);
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

    /// Draws the image and the panel into the window.
    fn present(&mut self) -> Result<()> {
        let raw = {
            let gpu = self.gpu.as_mut().expect("started");
            gpu.egui_state.take_egui_input(&gpu.window)
        };
        let egui_ctx = self.egui.clone();
        let mut panel = PanelOutput::default();
        let output = egui_ctx.run_ui(raw, |ui| self.panel(ui, &mut panel));
        if panel.toggle_probe_tool {
            self.probe_tool = !self.probe_tool;
            self.state.apply(Command::Live);
        }
        for c in panel.commands {
            self.state.apply(c);
            self.dirty = true;
        }
        for a in panel.actions {
            self.key_action(a)?;
        }
        let gpu = self.gpu.as_mut().expect("started");
        gpu.egui_state
            .handle_platform_output(&gpu.window, output.platform_output);
        let ppp = output.pixels_per_point;
        let jobs = egui_ctx.tessellate(output.shapes, ppp);
        let frame = match gpu.surface.get_current_texture() {
            wgpu::CurrentSurfaceTexture::Success(f)
            | wgpu::CurrentSurfaceTexture::Suboptimal(f) => f,
            wgpu::CurrentSurfaceTexture::Outdated | wgpu::CurrentSurfaceTexture::Lost => {
                let size = gpu.window.inner_size();
                gpu.config.width = size.width.max(1);
                gpu.config.height = size.height.max(1);
                let ctx = device(&gpu.chain, &gpu.own);
                gpu.surface.configure(&ctx.device, &gpu.config);
                gpu.window.request_redraw();
                return Ok(());
            }
            other => {
                log::debug!("no window frame this time: {other:?}");
                gpu.window.request_redraw();
                return Ok(());
            }
        };
        let view = frame
            .texture
            .create_view(&wgpu::TextureViewDescriptor::default());
        let ctx = device(&gpu.chain, &gpu.own);
        for (id, deltas) in &output.textures_delta.set {
            for delta in deltas {
                gpu.egui_renderer
                    .update_texture(&ctx.device, &ctx.queue, *id, delta);
            }
        }
        let screen = egui_wgpu::ScreenDescriptor {
            size_in_pixels: [gpu.config.width, gpu.config.height],
            pixels_per_point: ppp,
        };
        let mut enc = ctx
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor::default());
        let extra =
            gpu.egui_renderer
                .update_buffers(&ctx.device, &ctx.queue, &mut enc, &jobs, &screen);
        {
            let pass = enc.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("window"),
                color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                    view: &view,
                    resolve_target: None,
                    depth_slice: None,
                    ops: wgpu::Operations {
                        load: wgpu::LoadOp::Clear(wgpu::Color {
                            r: 0.02,
                            g: 0.02,
                            b: 0.025,
                            a: 1.0,
                        }),
                        store: wgpu::StoreOp::Store,
                    },
                })],
                depth_stencil_attachment: None,
                timestamp_writes: None,
                occlusion_query_set: None,
                multiview_mask: None,
            });
            let mut pass = pass.forget_lifetime();
            if self.shown.is_some() {
                let (w, h) = gpu.render_size;
                let fits = w as u32 <= gpu.config.width && h as u32 <= gpu.config.height;
                if fits {
                    gpu.present
                        .draw(&mut pass, &gpu.present_bind, [0.0, 0.0, w as f32, h as f32]);
                }
            }
            pass.set_viewport(
                0.0,
                0.0,
                gpu.config.width as f32,
                gpu.config.height as f32,
                0.0,
                1.0,
            );
            gpu.egui_renderer.render(&mut pass, &jobs, &screen);
        }
        let capture = if self.window_shots.is_empty() {
            None
        } else {
            Some(capture_window(ctx, &mut enc, &frame.texture, &gpu.config)?)
        };
        ctx.queue
            .submit(extra.into_iter().chain(std::iter::once(enc.finish())));
        if let Some((staging, row)) = capture {
            let (w, h) = (gpu.config.width as usize, gpu.config.height as usize);
            let bytes: Vec<u8> = crate::gpu::buffers::map_read(ctx, &staging, row * h)?;
            let bgra = matches!(
                gpu.config.format,
                wgpu::TextureFormat::Bgra8Unorm | wgpu::TextureFormat::Bgra8UnormSrgb
            );
            let mut rgb = Vec::with_capacity(w * h * 3);
            for y in 0..h {
                for px in bytes[y * row..y * row + 4 * w].chunks(4) {
                    if bgra {
                        rgb.extend_from_slice(&[px[2], px[1], px[0]]);
                    } else {
                        rgb.extend_from_slice(&px[..3]);
                    }
                }
            }
            for path in std::mem::take(&mut self.window_shots) {
                write_rgb_png(&path, w, h, &rgb)?;
                self.written.push(path);
            }
        }
        gpu.window.pre_present_notify();
        ctx.queue.present(frame);
        for id in &output.textures_delta.free {
            gpu.egui_renderer.free_texture(id);
        }
        ctx.take_device_errors()
    }

    /// The side panel.
    fn panel(&self, ui: &mut egui::Ui, out: &mut PanelOutput) {
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
        // Probe.
        if let Some(p) = &s.probe {
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
        // Lights.
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
        for (region, e, nu) in &s.materials {
            let (mut e2, mut nu2) = (*e, *nu);
            ui.horizontal(|ui| {
                ui.label(region);
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
                            .range(0.0..=crate::fem::material::MAX_POISSON)
                            .speed(0.005)
                            .prefix("ν "),
                    )
                    .changed();
                if a || b {
                    out.commands
                        .push(Command::Material(region.clone(), e2, nu2));
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
        ui.separator();
        // Rates.
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

    /// Carries out a key's action.
    fn key_action(&mut self, action: KeyAction) -> Result<()> {
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

    fn toggle_record(&mut self) -> Result<()> {
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

    fn save_path(&mut self, file: &std::path::Path) -> Result<()> {
        let (path, axis) = self.worker().path();
        let base = self
            .options
            .scenario
            .parent()
            .unwrap_or(std::path::Path::new("."));
        let recorded = record::recorded_scenario(
            &self.loaded.scenario,
            base,
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

    /// Runs script steps until one has to wait.
    fn run_script(&mut self, event_loop: &ActiveEventLoop) -> Result<()> {
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
                    self.error = Some(Error::Solver(format!(
                        "--exit-after {limit} s: the script was still at step {} of {}",
                        run.next,
                        run.steps.len()
                    )));
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

/// Records a copy of the window's frame into a read-back buffer; returns it
/// with its padded row length (bytes). Needs an 8-bit RGBA or BGRA window
/// format that allows copies.
fn capture_window(
    ctx: &Context,
    enc: &mut wgpu::CommandEncoder,
    texture: &wgpu::Texture,
    config: &wgpu::SurfaceConfiguration,
) -> Result<(wgpu::Buffer, usize)> {
    use wgpu::TextureFormat as F;
    if !config.usage.contains(wgpu::TextureUsages::COPY_SRC)
        || !matches!(
            config.format,
            F::Bgra8Unorm | F::Bgra8UnormSrgb | F::Rgba8Unorm | F::Rgba8UnormSrgb
        )
    {
        return Err(Error::Gpu(format!(
            "window screenshots need a window that allows copies in 8-bit RGBA or BGRA; this one \
             is {:?} ({:?}): take view screenshots instead",
            config.format, config.usage
        )));
    }
    let row =
        (4 * config.width as usize).next_multiple_of(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT as usize);
    let staging = crate::gpu::buffers::staging(ctx, (row * config.height as usize) as u64);
    enc.copy_texture_to_buffer(
        wgpu::TexelCopyTextureInfo {
            texture,
            mip_level: 0,
            origin: wgpu::Origin3d::ZERO,
            aspect: wgpu::TextureAspect::All,
        },
        wgpu::TexelCopyBufferInfo {
            buffer: &staging,
            layout: wgpu::TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some(row as u32),
                rows_per_image: None,
            },
        },
        wgpu::Extent3d {
            width: config.width,
            height: config.height,
            depth_or_array_layers: 1,
        },
    );
    Ok((staging, row))
}

/// Writes 8-bit sRGB pixels as a PNG (atomically).
fn write_rgb_png(path: &std::path::Path, w: usize, h: usize, rgb: &[u8]) -> Result<()> {
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    }
    let mut out = Vec::new();
    image::codecs::png::PngEncoder::new(&mut out)
        .write_image(rgb, w as u32, h as u32, image::ExtendedColorType::Rgb8)
        .map_err(|e| Error::io(path, std::io::Error::other(e)))?;
    crate::mesh::io::write_atomically(path, &out)
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

/// The renderer for a view of `size` pixels.
fn build_renderer(
    ctx: &Context,
    inputs: &RenderInputs,
    chain: Option<&GpuMicro>,
    size: (usize, usize),
) -> Result<Renderer> {
    let mut setup = inputs.setup.clone();
    setup.width = size.0;
    setup.height = size.1;
    setup.supersample = 1;
    let neutral = inputs
        .neutral
        .as_ref()
        .map(|(normals, width, height)| NormalMap {
            normals,
            width: *width,
            height: *height,
        });
    Renderer::new(
        ctx,
        &setup,
        &inputs.albedo,
        neutral,
        chain.map(GpuMicro::normals_texture),
        inputs.curve,
        inputs.texel_mm,
    )
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
