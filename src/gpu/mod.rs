//! GPU compute stages on wgpu (§7): the per-frame microstructure
//! stages of [`crate::strain`] and [`crate::micro`], one module and one
//! shader each, every one compared with its CPU reference in the tests.
//!
//! * [`raster`] (`shaders/raster.wgsl`): per-vertex `T` and `Q Rᵀ` rendered
//!   into UV textures — [`crate::strain::StrainRaster`];
//! * [`svd2`] (`shaders/svd2.wgsl`): per-texel closed-form 2×2 SVD, kernel
//!   parameters per axis, dilation past the surface edge —
//!   [`crate::strain::Svd2`], [`crate::micro::KernelField`];
//! * [`convolve`] (`shaders/convolve.wgsl`): one spatially varying 1D pass —
//!   [`mod@crate::micro::convolve`]; in the per-frame chain each pass evaluates
//!   the svd2 functions at its texel instead of reading a parameter buffer;
//! * [`normals`] (`shaders/normals.wgsl`): normal map —
//!   [`crate::micro::normals::normal_map`];
//! * [`histogram`] (`shaders/histogram.wgsl`): 64 × 64 normal histogram with
//!   atomics — [`crate::micro::NormalHistogram`];
//! * [`fit`] (`shaders/fit.wgsl`): normal histograms of batches of (α, σ)
//!   candidates for the kernel fit —
//!   [`crate::micro::fit`];
//! * [`micro`]: the whole per-frame chain with the neutral map resident.
//!
//! [`Context`] owns the device. Adapters come from Vulkan only (lavapipe in
//! CI, vendor drivers on real GPUs); `SKINPATCH_ADAPTER` picks one by a
//! substring of its name. [`acquire`] is what the pipeline calls: without an
//! adapter it logs a warning and returns `None` (the CPU references run),
//! unless `SKINPATCH_REQUIRE_GPU=1`, which makes that an error.
//!
//! Errors the device reports (validation, out of memory) are caught by a
//! handler and returned from the next [`Context::finish`] as [`Error::Gpu`];
//! nothing here panics on a GPU failure.

pub mod active_tiles;
pub mod buffers;
pub mod convolve;
pub mod fit;
pub mod histogram;
pub mod map;
pub mod micro;
pub mod normals;
pub mod raster;
pub mod svd2;
pub mod tiled;
pub mod timing;
pub mod vulkan;

use std::sync::{Arc, Mutex};

use crate::error::{Error, Result};

/// Environment variable choosing the adapter by a substring of its name.
pub const ADAPTER_VAR: &str = "SKINPATCH_ADAPTER";
/// Environment variable that makes a missing adapter an error (`1`).
pub const REQUIRE_VAR: &str = "SKINPATCH_REQUIRE_GPU";

/// Threads per workgroup side of the 2D compute stages (16 × 16); must
/// match `@workgroup_size` in the shaders.
pub const WORKGROUP: u32 = 16;

/// What `skinpatch gpu-info` prints of one adapter.
#[derive(Clone, Debug)]
pub struct AdapterReport {
    /// Name, backend, device type and driver.
    pub info: wgpu::AdapterInfo,
    /// The adapter's limits.
    pub limits: wgpu::Limits,
    /// Which of [`OPTIONAL_FEATURES`] it has.
    pub features: wgpu::Features,
}

/// A headless device and its queue (clones share the device).
#[derive(Clone)]
pub struct Context {
    /// The device.
    pub device: wgpu::Device,
    /// Its queue.
    pub queue: wgpu::Queue,
    /// The adapter it came from.
    pub info: wgpu::AdapterInfo,
    /// Limits granted (the adapter's own).
    pub limits: wgpu::Limits,
    /// Optional features the stages use, where the adapter has them
    /// ([`OPTIONAL_FEATURES`]). Stages read this, not the device's own
    /// list: clearing a bit makes them take the path without it (the
    /// tests compare both paths on one adapter).
    pub features: wgpu::Features,
    errors: Arc<Mutex<Vec<String>>>,
}

fn instance() -> wgpu::Instance {
    let mut desc = wgpu::InstanceDescriptor::new_without_display_handle();
    desc.backends = wgpu::Backends::VULKAN;
    wgpu::Instance::new(desc)
}

/// Features used where the adapter offers them: `FLOAT32_FILTERABLE` lets
/// the skin pass filter the f32 slope-moment pyramid with the sampler
/// instead of eight loads a lookup; the timestamp queries give profiles
/// GPU time ([`timing`]).
pub const OPTIONAL_FEATURES: wgpu::Features = wgpu::Features::FLOAT32_FILTERABLE
    .union(wgpu::Features::TIMESTAMP_QUERY)
    .union(wgpu::Features::TIMESTAMP_QUERY_INSIDE_ENCODERS);

/// Every Vulkan adapter with its limits.
pub fn adapters() -> Vec<AdapterReport> {
    pollster::block_on(instance().enumerate_adapters(wgpu::Backends::VULKAN))
        .into_iter()
        .map(|a| AdapterReport {
            info: a.get_info(),
            limits: a.limits(),
            features: a.features() & OPTIONAL_FEATURES,
        })
        .collect()
}

/// Preference among device types when no adapter is named: real GPUs first.
fn rank(kind: wgpu::DeviceType) -> u8 {
    match kind {
        wgpu::DeviceType::DiscreteGpu => 0,
        wgpu::DeviceType::IntegratedGpu => 1,
        wgpu::DeviceType::VirtualGpu => 2,
        wgpu::DeviceType::Cpu => 3,
        wgpu::DeviceType::Other => 4,
    }
}

impl Context {
    /// Opens the adapter named by `SKINPATCH_ADAPTER` (a case-insensitive
    /// substring of its name), or else the best by device type.
    pub fn new() -> Result<Context> {
        Context::with_adapter(std::env::var(ADAPTER_VAR).ok().as_deref())
    }

    /// Opens the adapter whose name contains `name` (any if `None`).
    pub fn with_adapter(name: Option<&str>) -> Result<Context> {
        Context::open(select_adapter(name)?)
    }

    /// Creates a surface for `window` and opens an adapter that can present
    /// to it (the one `SKINPATCH_ADAPTER` names, else the best by device
    /// type), with the surface's capabilities on that adapter.
    pub fn for_window<W>(
        window: W,
    ) -> Result<(Context, wgpu::Surface<'static>, wgpu::SurfaceCapabilities)>
    where
        W: wgpu::WindowHandle + wgpu::wgt::WgpuHasDisplayHandle + Clone + 'static,
    {
        // The instance knows the window system it presents to.
        let mut desc = wgpu::InstanceDescriptor::new_with_display_handle(Box::new(window.clone()));
        desc.backends = wgpu::Backends::VULKAN;
        let instance = wgpu::Instance::new(desc);
        let surface = instance
            .create_surface(window)
            .map_err(|e| Error::Gpu(format!("creating a Vulkan surface for the window: {e}")))?;
        let all = pollster::block_on(instance.enumerate_adapters(wgpu::Backends::VULKAN));
        if all.is_empty() {
            return Err(Error::Gpu(vulkan::explain(&vulkan::look())));
        }
        let names: Vec<String> = all.iter().map(|a| a.get_info().name).collect();
        let wanted = std::env::var(ADAPTER_VAR)
            .ok()
            .filter(|n| !n.is_empty())
            .map(|n| n.to_lowercase());
        let adapter = all
            .into_iter()
            .filter(|a| a.is_surface_supported(&surface))
            .filter(|a| {
                wanted
                    .as_ref()
                    .is_none_or(|w| a.get_info().name.to_lowercase().contains(w))
            })
            .min_by_key(|a| rank(a.get_info().device_type))
            .ok_or_else(|| {
                Error::Gpu(format!(
                    "no Vulkan adapter{} can present to this window (adapters: {})",
                    wanted
                        .as_ref()
                        .map(|w| format!(" matching {ADAPTER_VAR}={w:?}"))
                        .unwrap_or_default(),
                    names.join(", ")
                ))
            })?;
        let capabilities = surface.get_capabilities(&adapter);
        Ok((Context::open(adapter)?, surface, capabilities))
    }

    fn open(adapter: wgpu::Adapter) -> Result<Context> {
        let info = adapter.get_info();
        let limits = adapter.limits();
        let features = adapter.features() & OPTIONAL_FEATURES;
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("skinpatch"),
            required_features: features,
            required_limits: limits.clone(),
            experimental_features: wgpu::ExperimentalFeatures::disabled(),
            memory_hints: wgpu::MemoryHints::Performance,
            trace: wgpu::Trace::Off,
        }))
        .map_err(|e| Error::Gpu(format!("opening {}: {e}", info.name)))?;
        let errors = Arc::new(Mutex::new(Vec::new()));
        let sink = errors.clone();
        device.on_uncaptured_error(Arc::new(move |e: wgpu::Error| {
            if let Ok(mut list) = sink.lock() {
                list.push(e.to_string());
            }
        }));
        log::info!(
            "GPU adapter: {} ({:?}, {:?}, driver {} {})",
            info.name,
            info.backend,
            info.device_type,
            info.driver,
            info.driver_info
        );
        Ok(Context {
            device,
            queue,
            info,
            limits,
            features,
            errors,
        })
    }

    /// A one-line description of the adapter for logs and reports.
    pub fn describe(&self) -> String {
        format!(
            "{} ({:?}, {:?})",
            self.info.name, self.info.backend, self.info.device_type
        )
    }

    /// Waits for all submitted work and returns the first error the device
    /// reported since the last call.
    pub fn finish(&self) -> Result<()> {
        self.device
            .poll(wgpu::PollType::wait_indefinitely())
            .map_err(|e| Error::Gpu(format!("waiting for {}: {e}", self.info.name)))?;
        self.take_device_errors()
    }

    /// The first error the device reported since the last call, without
    /// waiting for submitted work.
    pub fn take_device_errors(&self) -> Result<()> {
        let mut list = self.errors.lock().map_err(|_| {
            Error::Gpu("the GPU error handler panicked; the device is unusable".into())
        })?;
        if list.is_empty() {
            return Ok(());
        }
        let first = list.remove(0);
        let more = list.len();
        list.clear();
        Err(Error::Gpu(if more > 0 {
            format!("{first} (and {more} more errors)")
        } else {
            first
        }))
    }

    /// Checks that a `width × height` map fits this device: texture side
    /// and the largest storage buffer a stage binds (`bytes_per_texel` per
    /// texel). Names the limit and the adapter when it does not.
    pub fn check_map(&self, width: usize, height: usize, bytes_per_texel: u64) -> Result<()> {
        check_map_limits(
            &self.info.name,
            &self.limits,
            width,
            height,
            bytes_per_texel,
        )
    }

    /// Workgroup counts covering `width × height` texels.
    pub fn groups(width: usize, height: usize) -> (u32, u32) {
        (
            (width as u32).div_ceil(WORKGROUP),
            (height as u32).div_ceil(WORKGROUP),
        )
    }
}

/// The adapter [`Context::with_adapter`] opens: the one whose name
/// contains `name`, else the best by device type.
fn select_adapter(name: Option<&str>) -> Result<wgpu::Adapter> {
    let all = pollster::block_on(instance().enumerate_adapters(wgpu::Backends::VULKAN));
    if all.is_empty() {
        let why = vulkan::explain(&vulkan::look());
        return Err(Error::Gpu(match name.filter(|n| !n.is_empty()) {
            Some(wanted) => format!("{ADAPTER_VAR}={wanted:?} matches no adapter: {why}"),
            None => why,
        }));
    }
    let names: Vec<String> = all.iter().map(|a| a.get_info().name).collect();
    match name.filter(|n| !n.is_empty()) {
        Some(wanted) => {
            let wanted_lc = wanted.to_lowercase();
            all.into_iter()
                .find(|a| a.get_info().name.to_lowercase().contains(&wanted_lc))
                .ok_or_else(|| {
                    Error::Gpu(format!(
                        "{ADAPTER_VAR}={wanted:?} matches no adapter; found: {}",
                        names.join(", ")
                    ))
                })
        }
        None => Ok(all
            .into_iter()
            .min_by_key(|a| rank(a.get_info().device_type))
            .expect("the adapter list is not empty")),
    }
}

/// [`Context::check_map`] against the limits of adapter `name`.
fn check_map_limits(
    name: &str,
    limits: &wgpu::Limits,
    width: usize,
    height: usize,
    bytes_per_texel: u64,
) -> Result<()> {
    let side = limits.max_texture_dimension_2d as usize;
    if width == 0 || height == 0 {
        return Err(Error::Gpu(format!("a {width} × {height} map is empty")));
    }
    if width > side || height > side {
        return Err(Error::Gpu(format!(
            "a {width} × {height} map exceeds max_texture_dimension_2d = {side} of {name}"
        )));
    }
    let bytes = width as u64 * height as u64 * bytes_per_texel;
    let binding = limits.max_storage_buffer_binding_size;
    let buffer = limits.max_buffer_size;
    if bytes > binding.min(buffer) {
        return Err(Error::Gpu(format!(
            "a {width} × {height} map needs storage buffers of {bytes} bytes; {name} allows \
             {binding} per binding (max_storage_buffer_binding_size) and {buffer} per buffer \
             (max_buffer_size): use a smaller map"
        )));
    }
    Ok(())
}

/// Checks a `width × height` microstructure map against the adapter the
/// run would open, before the map is generated (no device is created):
/// minutes of generating a map the GPU cannot hold are not spent first.
/// A map that does not fit (or no adapter) is an error when
/// `SKINPATCH_REQUIRE_GPU=1`, else a warning that the CPU references will
/// run the microstructure.
pub fn precheck_map(width: usize, height: usize) -> Result<()> {
    let adapter = match select_adapter(std::env::var(ADAPTER_VAR).ok().as_deref()) {
        Ok(a) => a,
        Err(e) if gpu_required() => return Err(required(e)),
        // The run warns about the missing adapter when it looks for one.
        Err(_) => return Ok(()),
    };
    let checked = check_map_limits(
        &adapter.get_info().name,
        &adapter.limits(),
        width,
        height,
        micro::LARGEST_BYTES_PER_TEXEL,
    );
    match checked {
        Ok(()) => Ok(()),
        Err(e) if gpu_required() => Err(required(e)),
        Err(e) => {
            log::warn!("{e}; the microstructure will run on the CPU reference stages");
            Ok(())
        }
    }
}

/// A GPU error as the reason a required GPU is unusable.
fn required(e: Error) -> Error {
    let reason = match e {
        Error::Gpu(m) => m,
        other => other.to_string(),
    };
    Error::Gpu(format!("{REQUIRE_VAR}=1, but {reason}"))
}

/// Whether a stage that also has a CPU path should run on `ctx`: on a
/// hardware adapter, yes; on a software one (lavapipe: shaders compiled for
/// the same CPU cores, slower than the hand-written CPU paths — 2.8× for
/// the microstructure chain at 1024², 3.4× for the fit's counting,
/// docs/PERFORMANCE.md) only when `SKINPATCH_REQUIRE_GPU` asks for the GPU.
pub fn worth_using(ctx: &Context) -> bool {
    ctx.info.device_type != wgpu::DeviceType::Cpu || gpu_required()
}

/// Whether `SKINPATCH_REQUIRE_GPU` asks for a GPU (`1`, `true` or `yes`).
pub fn gpu_required() -> bool {
    std::env::var(REQUIRE_VAR)
        .map(|v| matches!(v.trim().to_lowercase().as_str(), "1" | "true" | "yes"))
        .unwrap_or(false)
}

/// The context the pipeline uses: `Some` with an adapter; `None` after a
/// logged warning without one; an error without one when
/// `SKINPATCH_REQUIRE_GPU=1`.
pub fn acquire() -> Result<Option<Context>> {
    match Context::new() {
        Ok(ctx) => Ok(Some(ctx)),
        Err(e) if gpu_required() => Err(Error::Gpu(format!(
            "{REQUIRE_VAR}=1 but no GPU is usable: {e}"
        ))),
        Err(e) => {
            log::warn!("{e}; running the CPU reference stages instead");
            Ok(None)
        }
    }
}

/// The fallback rule for a GPU stage that could not be built (a limit, a
/// device error): `None` after a logged warning, so the caller runs the CPU
/// reference — or the error itself when `SKINPATCH_REQUIRE_GPU=1`.
pub fn or_cpu<T>(built: Result<T>) -> Result<Option<T>> {
    match built {
        Ok(stage) => Ok(Some(stage)),
        Err(e) if gpu_required() => Err(e),
        Err(e) => {
            log::warn!("{e}; running the CPU reference stages instead");
            Ok(None)
        }
    }
}

/// A compute pipeline from `source` with an automatic layout.
pub(crate) fn compute_pipeline(
    ctx: &Context,
    label: &str,
    source: &str,
    entry: &str,
) -> wgpu::ComputePipeline {
    let module = ctx
        .device
        .create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some(label),
            source: wgpu::ShaderSource::Wgsl(source.into()),
        });
    ctx.device
        .create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some(label),
            layout: None,
            module: &module,
            entry_point: Some(entry),
            compilation_options: Default::default(),
            cache: None,
        })
}

/// A bind group for group 0 of `pipeline` with `resources` at bindings
/// 0, 1, 2, … in order.
pub(crate) fn bind_group(
    ctx: &Context,
    layout: &wgpu::BindGroupLayout,
    resources: &[wgpu::BindingResource<'_>],
) -> wgpu::BindGroup {
    let entries: Vec<wgpu::BindGroupEntry<'_>> = resources
        .iter()
        .enumerate()
        .map(|(k, r)| wgpu::BindGroupEntry {
            binding: k as u32,
            resource: r.clone(),
        })
        .collect();
    ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: None,
        layout,
        entries: &entries,
    })
}

/// Records one compute pass of `pipeline` over `width × height` texels
/// (16 × 16 workgroups) with `binds` as groups 0, 1, ….
pub(crate) fn dispatch(
    encoder: &mut wgpu::CommandEncoder,
    label: &str,
    pipeline: &wgpu::ComputePipeline,
    binds: &[&wgpu::BindGroup],
    width: usize,
    height: usize,
) {
    let (gx, gy) = Context::groups(width, height);
    compute_pass(encoder, label, pipeline, binds, (gx, gy));
}

/// Records one compute pass of `pipeline` over `tiles` tiles of a list
/// (`active_tiles.rs`): one workgroup each, in rows of at most 65,535 (the
/// per-dimension limit every adapter has); the shader finds its tile with
/// `tile_index` (map.wgsl) and skips the indices past the list's count.
pub(crate) fn dispatch_tiles(
    encoder: &mut wgpu::CommandEncoder,
    label: &str,
    pipeline: &wgpu::ComputePipeline,
    binds: &[&wgpu::BindGroup],
    tiles: usize,
) {
    if tiles == 0 {
        return;
    }
    let gx = tiles.min(65_535);
    let groups = (gx as u32, tiles.div_ceil(gx) as u32);
    compute_pass(encoder, label, pipeline, binds, groups);
}

/// One compute pass of `groups` workgroups with `binds` as groups 0, 1, ….
fn compute_pass(
    encoder: &mut wgpu::CommandEncoder,
    label: &str,
    pipeline: &wgpu::ComputePipeline,
    binds: &[&wgpu::BindGroup],
    (gx, gy): (u32, u32),
) {
    let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
        label: Some(label),
        timestamp_writes: None,
    });
    pass.set_pipeline(pipeline);
    for (k, bind) in binds.iter().enumerate() {
        pass.set_bind_group(k as u32, *bind, &[]);
    }
    pass.dispatch_workgroups(gx, gy, 1);
}

/// A new command encoder.
pub(crate) fn encoder(ctx: &Context) -> wgpu::CommandEncoder {
    ctx.device
        .create_command_encoder(&wgpu::CommandEncoderDescriptor::default())
}

/// The compute stages' shader sources by file name, for validation: whole
/// modules as compiled (the map-reading stages with `shaders/map.wgsl`
/// prepended). The renderer and the viewer list their own.
pub fn shader_sources() -> Vec<(&'static str, String)> {
    vec![
        ("raster.wgsl", raster::SHADER.to_string()),
        ("svd2.wgsl", svd2::SHADER.to_string()),
        ("convolve.wgsl", convolve::source()),
        ("normals.wgsl", map::with_map_access(normals::SHADER)),
        ("histogram.wgsl", map::with_map_access(histogram::SHADER)),
        ("fit.wgsl", fit::SHADER.to_string()),
    ]
}
