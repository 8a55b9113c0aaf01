//! The renderer: owns every render resource and records a frame as
//! shadow maps → texture-space irradiance → six-Gaussian diffusion →
//! (slope moments of the dynamic normals) → skin pass → supersampling
//! resolve, in one command buffer.

use glam::Vec3;

use super::albedo::{linear_to_srgb, Albedo};
use super::camera::Camera;
use super::diffusion::DiffusionStage;
use super::irradiance::IrradianceStage;
use super::light::Light;
use super::lighting::{Bounds, Globals};
use super::moments::{MomentPyramidGpu, MomentStage};
use super::overlay::OverlayKind;
use super::resolve::ResolveStage;
use super::scene::FrameGeometry;
use super::shadow::{ShadowInfo, ShadowMaps};
use super::skin::{FrameBuffers, SkinStage, HDR_FORMAT};
use super::specular::EnergyTable;
use super::stage::{linear_sampler, texture_entry, uniform_entry, view, DEPTH_FORMAT};
use super::{Image, MicroFilter, Mode, RenderSetup, Roughness};
use crate::error::Result;
use crate::gpu::{bind_group, buffers, encoder, Context};

/// The passes of one frame, in the order they are recorded.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FrameStage {
    /// One depth map per light.
    Shadows,
    /// Texture-space irradiance (four targets).
    Irradiance,
    /// The six-Gaussian diffusion passes.
    Diffusion,
    /// The slope-moment pyramid of the dynamic normals (dynamic mode with
    /// the moment filter only).
    Moments,
    /// Skin, cut sides and probe at the supersampled size.
    Skin,
    /// Supersampling resolve to the output image.
    Resolve,
}

impl FrameStage {
    /// Number of stages.
    pub const COUNT: usize = 6;
    /// Every stage, in recording order.
    pub const ALL: [FrameStage; FrameStage::COUNT] = [
        FrameStage::Shadows,
        FrameStage::Irradiance,
        FrameStage::Diffusion,
        FrameStage::Moments,
        FrameStage::Skin,
        FrameStage::Resolve,
    ];

    /// Short name for tables.
    pub fn name(self) -> &'static str {
        match self {
            FrameStage::Shadows => "shadow maps",
            FrameStage::Irradiance => "irradiance",
            FrameStage::Diffusion => "diffusion",
            FrameStage::Moments => "slope moments",
            FrameStage::Skin => "skin pass",
            FrameStage::Resolve => "resolve",
        }
    }
}

/// Tangent-space normals of a displacement map, for the static mode.
pub struct NormalMap<'a> {
    /// Normals, row-major.
    pub normals: &'a [[f32; 3]],
    /// Width in texels.
    pub width: usize,
    /// Height in texels.
    pub height: usize,
}

/// A vertex buffer that grows as needed.
struct Vertices {
    buffer: wgpu::Buffer,
    capacity: usize,
    count: u32,
}

impl Vertices {
    fn new(ctx: &Context, label: &str) -> Vertices {
        Vertices {
            buffer: vertex_buffer(ctx, label, 1024),
            capacity: 1024,
            count: 0,
        }
    }

    fn upload<T: bytemuck::Pod>(&mut self, ctx: &Context, label: &str, data: &[T]) {
        let bytes: &[u8] = bytemuck::cast_slice(data);
        if bytes.len() > self.capacity {
            self.capacity = bytes.len().next_power_of_two();
            self.buffer = vertex_buffer(ctx, label, self.capacity);
        }
        if !bytes.is_empty() {
            ctx.queue.write_buffer(&self.buffer, 0, bytes);
        }
        self.count = data.len() as u32;
    }
}

fn vertex_buffer(ctx: &Context, label: &str, bytes: usize) -> wgpu::Buffer {
    ctx.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some(label),
        size: bytes as u64,
        usage: wgpu::BufferUsages::VERTEX | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    })
}

/// The slope moments' sampler: trilinear with wrapping when `filtering`
/// (the texture's wrap rule, as the shader's load path applies it), else a
/// nearest sampler that satisfies the layout and is never used.
fn moment_sampler(ctx: &Context, filtering: bool) -> wgpu::Sampler {
    let (filter, mipmap) = if filtering {
        (wgpu::FilterMode::Linear, wgpu::MipmapFilterMode::Linear)
    } else {
        (wgpu::FilterMode::Nearest, wgpu::MipmapFilterMode::Nearest)
    };
    ctx.device.create_sampler(&wgpu::SamplerDescriptor {
        label: Some("slope moments"),
        address_mode_u: wgpu::AddressMode::Repeat,
        address_mode_v: wgpu::AddressMode::Repeat,
        mag_filter: filter,
        min_filter: filter,
        mipmap_filter: mipmap,
        ..Default::default()
    })
}

/// The resident renderer.
pub struct Renderer {
    setup: RenderSetup,
    table: EnergyTable,
    curve: [f32; 16],
    globals: wgpu::Buffer,
    shadows: ShadowMaps,
    lighting: wgpu::BindGroup,
    irradiance: IrradianceStage,
    irradiance_views: [wgpu::TextureView; 4],
    diffusion: DiffusionStage,
    skin: SkinStage,
    // Group 1 of the skin pass with the neutral and the dynamic normals.
    diffused: [wgpu::BindGroup; 2],
    moment_stage: MomentStage,
    // The dynamic normals' slope moments (rebuilt per dynamic frame).
    dynamic_moments: Option<MomentPyramidGpu>,
    // The skin pass samples the moments with the sampler (f32 filterable).
    filter_moments: bool,
    hdr: wgpu::TextureView,
    // The camera pass's multisampled target (MSAA on), resolved into `hdr`.
    multisampled: Option<wgpu::TextureView>,
    depth: wgpu::TextureView,
    resolve: ResolveStage,
    surface: Vertices,
    top: Vertices,
    sides: Vertices,
    probe: Vertices,
    bounds: Bounds,
    // Strain overlay and its saturating range.
    overlay: (OverlayKind, f32),
}

impl Renderer {
    /// Builds every resource. `neutral` is the static microstructure's
    /// normal map (none: a flat one), `dynamic` the texture the
    /// microstructure chain writes D′'s normals to (none: `neutral` again),
    /// `curve` the roughness ratio m(r)/m(1) at
    /// [`super::lighting::curve_ratios`], `texel_mm` the width of a texel
    /// of the texture-space targets on the patch at rest (millimetres; it
    /// sets the sides of the diffusion's textures).
    pub fn new(
        ctx: &Context,
        setup: &RenderSetup,
        albedo: &Albedo,
        neutral: Option<NormalMap<'_>>,
        dynamic: Option<&wgpu::Texture>,
        curve: [f32; 16],
        texel_mm: f64,
    ) -> Result<Renderer> {
        let (w, h, f) = (setup.width, setup.height, setup.supersample);
        let tex = setup.texture_px;
        // Texture sides and the largest storage bindings: the resolved image
        // (16 B a pixel) and the albedo.
        ctx.check_map(w * f, h * f, 0)?;
        ctx.check_map(w, h, 16)?;
        ctx.check_map(tex, tex, 0)?;
        ctx.check_map(setup.shadow_map_px, setup.shadow_map_px, 0)?;
        ctx.check_map(albedo.width, albedo.height, 0)?;
        let table = EnergyTable::skin();
        let globals = ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("globals"),
            size: std::mem::size_of::<Globals>() as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let shadows = ShadowMaps::new(ctx, setup);
        let (lighting_layout, lighting) =
            lighting_group(ctx, &globals, &table, albedo, &shadows.array);

        // Texture-space targets and the diffusion chain.
        let target_usage =
            wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::TEXTURE_BINDING;
        let irradiance_views =
            ["irradiance", "stretch", "transmitted", "shadow factors"].map(|label| {
                view(&buffers::texture(
                    ctx,
                    label,
                    (tex, tex),
                    super::irradiance::FORMAT,
                    target_usage,
                ))
            });
        let diffusion = DiffusionStage::new(
            ctx,
            &irradiance_views[0],
            &irradiance_views[1],
            super::profile::level_sizes(tex, texel_mm),
        );
        let moment_stage = MomentStage::new(ctx);
        let normals = DiffusedGroups::new(
            ctx,
            &diffusion,
            &irradiance_views,
            &moment_stage,
            neutral,
            dynamic,
        );
        let (hdr, multisampled, depth) = camera_targets(ctx, setup);
        let resolve = ResolveStage::new(ctx, &hdr, w, h, f);
        let renderer = Renderer {
            setup: setup.clone(),
            table,
            curve,
            globals,
            lighting,
            shadows,
            irradiance: IrradianceStage::new(ctx, &lighting_layout),
            irradiance_views,
            diffusion,
            skin: SkinStage::new(ctx, [&lighting_layout, &normals.layout], setup.msaa),
            diffused: normals.groups,
            moment_stage,
            dynamic_moments: normals.dynamic_moments,
            filter_moments: normals.filter_moments,
            hdr,
            multisampled,
            depth,
            resolve,
            surface: Vertices::new(ctx, "surface vertices"),
            top: Vertices::new(ctx, "top caster vertices"),
            sides: Vertices::new(ctx, "side vertices"),
            probe: Vertices::new(ctx, "probe vertices"),
            bounds: (Vec3::ZERO, 1.0),
            overlay: (OverlayKind::Off, 0.25),
        };
        ctx.finish()?;
        Ok(renderer)
    }

    /// Uploads a frame's geometry (shared by every mode of the frame).
    pub fn set_geometry(&mut self, ctx: &Context, geometry: &FrameGeometry) {
        self.surface
            .upload(ctx, "surface vertices", &geometry.surface);
        self.top.upload(ctx, "top caster vertices", &geometry.top);
        self.sides.upload(ctx, "side vertices", &geometry.sides);
        let probe: &[super::scene::MeshVertex] = if self.setup.draw_probe {
            &geometry.probe
        } else {
            &[]
        };
        self.probe.upload(ctx, "probe vertices", probe);
        self.bounds = bounds(geometry);
    }

    /// The camera and lights of the next frames (interactive views). The
    /// number of lights is fixed when the renderer is built: `lights` must
    /// have as many.
    pub fn set_view(&mut self, camera: Camera, lights: &[Light]) -> Result<()> {
        if lights.len() != self.setup.lights.len() {
            return Err(crate::error::Error::Gpu(format!(
                "the renderer was built for {} lights, got {}",
                self.setup.lights.len(),
                lights.len()
            )));
        }
        self.setup.camera = camera;
        self.setup.lights = lights.to_vec();
        Ok(())
    }

    /// The roughness model of the next frames (its curve is the one given
    /// to [`Renderer::new`]).
    pub fn set_roughness(&mut self, roughness: Roughness) {
        self.setup.roughness = roughness;
    }

    /// Draws a strain overlay on the skin in place of its albedo; stretch
    /// ratios `1 ± range` saturate its colours.
    pub fn set_overlay(&mut self, kind: OverlayKind, range: f32) {
        self.overlay = (kind, range);
    }

    /// The resolved image of the last frame: `width × height` linear RGBA
    /// f32 texels, row 0 at the top (a storage buffer, for presenting it
    /// without a read-back).
    pub fn pixels(&self) -> (&wgpu::Buffer, usize, usize) {
        (&self.resolve.pixels, self.setup.width, self.setup.height)
    }

    /// Records and submits the frame in `mode` without waiting.
    pub fn submit(&mut self, ctx: &Context, mode: Mode) {
        self.write_globals(ctx, mode);
        let mut enc = encoder(ctx);
        for stage in FrameStage::ALL {
            self.encode_stage(&mut enc, stage, mode);
        }
        ctx.queue.submit([enc.finish()]);
    }

    /// Renders one frame in `mode` stage by stage, each stage submitted
    /// alone and waited for, and returns the wall time of each in ms (the
    /// stages in [`FrameStage::ALL`] order; a stage with nothing to do in
    /// this mode costs only its empty submission). For profiling: the
    /// sum is a little above [`Renderer::submit`]'s time, which overlaps
    /// nothing either but pays one submission.
    pub fn time_stages(&mut self, ctx: &Context, mode: Mode) -> Result<[f64; FrameStage::COUNT]> {
        self.write_globals(ctx, mode);
        ctx.finish()?;
        let mut times = [0.0; FrameStage::COUNT];
        for (k, stage) in FrameStage::ALL.into_iter().enumerate() {
            let start = std::time::Instant::now();
            let mut enc = encoder(ctx);
            self.encode_stage(&mut enc, stage, mode);
            ctx.queue.submit([enc.finish()]);
            ctx.finish()?;
            times[k] = start.elapsed().as_secs_f64() * 1e3;
        }
        Ok(times)
    }

    fn write_globals(&self, ctx: &Context, mode: Mode) {
        let (w, h) = (self.setup.width, self.setup.height);
        let aspect = w as f32 / h as f32;
        let mut globals = Globals::new(
            &self.setup,
            &self.table,
            mode,
            aspect,
            self.bounds,
            self.curve,
        );
        globals.options[1] = self.filter_moments as u32;
        globals.options[2] = self.overlay.0 as u32;
        globals.options[3] = self.overlay.1.to_bits();
        ctx.queue
            .write_buffer(&self.globals, 0, bytemuck::bytes_of(&globals));
        // The shadow passes use the lights exactly as the shading sees them.
        for (light, info) in globals.lights.iter().zip(&self.shadows.infos) {
            let value = ShadowInfo {
                view_proj: light.view_proj,
                where_: light.where_,
            };
            ctx.queue.write_buffer(info, 0, bytemuck::bytes_of(&value));
        }
    }

    fn encode_stage(&self, enc: &mut wgpu::CommandEncoder, stage: FrameStage, mode: Mode) {
        match stage {
            FrameStage::Shadows => {
                let casters = [
                    (&self.top.buffer, self.top.count),
                    (&self.sides.buffer, self.sides.count),
                    (&self.probe.buffer, self.probe.count),
                ];
                for (k, layer) in self
                    .shadows
                    .layers
                    .iter()
                    .enumerate()
                    .take(self.setup.lights.len())
                {
                    self.shadows.stage.encode(
                        enc,
                        &self.shadows.binds[k],
                        layer,
                        &self.shadows.depth,
                        &casters,
                    );
                }
            }
            FrameStage::Irradiance => {
                let v = &self.irradiance_views;
                self.irradiance.encode(
                    enc,
                    &self.lighting,
                    [&v[0], &v[1], &v[2], &v[3]],
                    (&self.surface.buffer, self.surface.count),
                );
            }
            FrameStage::Diffusion => self.diffusion.encode(enc),
            FrameStage::Moments => {
                let prefiltered = self.setup.microstructure_filter == MicroFilter::Moments
                    && self.setup.roughness == Roughness::Microgeometry;
                if let (Mode::Dynamic, true, Some(pyramid)) =
                    (mode, prefiltered, self.dynamic_moments.as_ref())
                {
                    self.moment_stage.encode(enc, pyramid);
                }
            }
            FrameStage::Skin => {
                let normals = &self.diffused[(mode == Mode::Dynamic) as usize];
                let target = match &self.multisampled {
                    Some(samples) => (samples, Some(&self.hdr)),
                    None => (&self.hdr, None),
                };
                self.skin.encode(
                    enc,
                    [&self.lighting, normals],
                    target,
                    &self.depth,
                    &FrameBuffers {
                        surface: (&self.surface.buffer, self.surface.count),
                        sides: (&self.sides.buffer, self.sides.count),
                        probe: (&self.probe.buffer, self.probe.count),
                    },
                );
            }
            FrameStage::Resolve => self.resolve.encode(enc),
        }
    }

    /// Renders the current geometry in `mode` and reads the image back.
    pub fn render(&mut self, ctx: &Context, mode: Mode) -> Result<Image> {
        self.submit(ctx, mode);
        let (w, h) = (self.setup.width, self.setup.height);
        let pixels: Vec<[f32; 4]> = buffers::read(ctx, &self.resolve.pixels, w * h)?;
        ctx.finish()?;
        Ok(Image {
            width: w,
            height: h,
            pixels,
        })
    }
}

/// Group 0 of the texture-space and skin passes: the scene uniforms, the
/// specular energy table, the albedo and the shadow maps, with their
/// samplers.
fn lighting_group(
    ctx: &Context,
    globals: &wgpu::Buffer,
    table: &EnergyTable,
    albedo: &Albedo,
    shadow_array: &wgpu::TextureView,
) -> (wgpu::BindGroupLayout, wgpu::BindGroup) {
    let layout = ctx
        .device
        .create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("lighting"),
            entries: &[
                uniform_entry(0),
                texture_entry(1, false, false),
                texture_entry(2, true, false),
                super::stage::sampler_entry(3),
                texture_entry(4, false, true),
                wgpu::BindGroupLayoutEntry {
                    binding: 5,
                    visibility: wgpu::ShaderStages::FRAGMENT,
                    ty: wgpu::BindingType::Sampler(wgpu::SamplerBindingType::NonFiltering),
                    count: None,
                },
            ],
        });
    let energy = buffers::upload_texture(
        ctx,
        "energy table",
        (table.mu_samples, table.m_samples),
        wgpu::TextureFormat::R32Float,
        4,
        bytemuck::cast_slice(&table.values),
    );
    let albedo_bytes: Vec<u8> = albedo
        .texels
        .iter()
        .flat_map(|t| {
            let c = |x: f32| (linear_to_srgb(x) * 255.0).round() as u8;
            [c(t[0]), c(t[1]), c(t[2]), 255]
        })
        .collect();
    let albedo_tex = buffers::upload_texture(
        ctx,
        "albedo",
        (albedo.width, albedo.height),
        wgpu::TextureFormat::Rgba8UnormSrgb,
        4,
        &albedo_bytes,
    );
    let sampler = linear_sampler(ctx);
    let nearest = ctx.device.create_sampler(&wgpu::SamplerDescriptor {
        label: Some("nearest clamp"),
        ..Default::default()
    });
    let group = bind_group(
        ctx,
        &layout,
        &[
            globals.as_entire_binding(),
            wgpu::BindingResource::TextureView(&view(&energy)),
            wgpu::BindingResource::TextureView(&view(&albedo_tex)),
            wgpu::BindingResource::Sampler(&sampler),
            wgpu::BindingResource::TextureView(shadow_array),
            wgpu::BindingResource::Sampler(&nearest),
        ],
    );
    (layout, group)
}

/// Group 1 of the skin pass: the diffused irradiance levels, the
/// transmitted light and shadow factors, and one set of normals with their
/// slope-moment pyramids — the neutral normals (group 0) and the dynamic
/// ones (group 1; the neutral again without a dynamic texture).
struct DiffusedGroups {
    layout: wgpu::BindGroupLayout,
    groups: [wgpu::BindGroup; 2],
    /// The dynamic normals' slope moments (rebuilt per dynamic frame).
    dynamic_moments: Option<MomentPyramidGpu>,
    /// Whether the moments are sampled with filtering (f32 filterable).
    filter_moments: bool,
}

impl DiffusedGroups {
    fn new(
        ctx: &Context,
        diffusion: &DiffusionStage,
        irradiance_views: &[wgpu::TextureView; 4],
        moment_stage: &MomentStage,
        neutral: Option<NormalMap<'_>>,
        dynamic: Option<&wgpu::Texture>,
    ) -> DiffusedGroups {
        let mut entries: Vec<wgpu::BindGroupLayoutEntry> =
            (0..7).map(|k| texture_entry(k, true, false)).collect();
        entries.push(texture_entry(7, false, false));
        entries.push(texture_entry(8, true, false));
        // The slope moments' pyramids (A and B) of the same normals, and
        // their sampler: trilinear and wrapping where the adapter filters
        // f32 textures, else unused (the shader filters by loads).
        let filter_moments = ctx.features.contains(wgpu::Features::FLOAT32_FILTERABLE);
        entries.push(texture_entry(9, filter_moments, false));
        entries.push(texture_entry(10, filter_moments, false));
        entries.push(wgpu::BindGroupLayoutEntry {
            binding: 11,
            visibility: wgpu::ShaderStages::FRAGMENT,
            ty: wgpu::BindingType::Sampler(if filter_moments {
                wgpu::SamplerBindingType::Filtering
            } else {
                wgpu::SamplerBindingType::NonFiltering
            }),
            count: None,
        });
        let moment_sampler = moment_sampler(ctx, filter_moments);
        let layout = ctx
            .device
            .create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                label: Some("diffused light"),
                entries: &entries,
            });
        let flat = [[0.0f32, 0.0, 1.0]];
        let neutral = neutral.unwrap_or(NormalMap {
            normals: &flat,
            width: 1,
            height: 1,
        });
        let neutral_rgba: Vec<[f32; 4]> = neutral
            .normals
            .iter()
            .map(|n| [n[0], n[1], n[2], 0.0])
            .collect();
        let neutral_tex = buffers::upload_texture(
            ctx,
            "neutral normals",
            (neutral.width, neutral.height),
            wgpu::TextureFormat::Rgba32Float,
            16,
            bytemuck::cast_slice(&neutral_rgba),
        );
        let neutral_view = view(&neutral_tex);
        let dynamic_view = dynamic.map(view);
        // Slope moments: the neutral map's once, the dynamic map's each
        // time its normals change (`submit`).
        let neutral_moments =
            moment_stage.pyramid(ctx, &neutral_tex, (neutral.width, neutral.height));
        let dynamic_moments = dynamic.map(|texture| {
            let size = (texture.width() as usize, texture.height() as usize);
            moment_stage.pyramid(ctx, texture, size)
        });
        let mut enc = encoder(ctx);
        moment_stage.encode(&mut enc, &neutral_moments);
        ctx.queue.submit([enc.finish()]);
        let moment_views = |p: &MomentPyramidGpu| [view(&p.a), view(&p.b)];
        let neutral_moment_views = moment_views(&neutral_moments);
        let dynamic_moment_views = dynamic_moments.as_ref().map(moment_views);
        let groups = [
            (&neutral_view, &neutral_moment_views),
            (
                dynamic_view.as_ref().unwrap_or(&neutral_view),
                dynamic_moment_views
                    .as_ref()
                    .unwrap_or(&neutral_moment_views),
            ),
        ]
        .map(|(normals, moments)| {
            let mut resources: Vec<wgpu::BindingResource<'_>> = diffusion
                .outputs()
                .iter()
                .map(wgpu::BindingResource::TextureView)
                .collect();
            resources.push(wgpu::BindingResource::TextureView(&irradiance_views[2]));
            resources.push(wgpu::BindingResource::TextureView(normals));
            resources.push(wgpu::BindingResource::TextureView(&irradiance_views[3]));
            resources.push(wgpu::BindingResource::TextureView(&moments[0]));
            resources.push(wgpu::BindingResource::TextureView(&moments[1]));
            resources.push(wgpu::BindingResource::Sampler(&moment_sampler));
            bind_group(ctx, &layout, &resources)
        });
        DiffusedGroups {
            layout,
            groups,
            dynamic_moments,
            filter_moments,
        }
    }
}

/// The camera pass's targets, shaded once a pixel of `supersample × size`:
/// the HDR image, with MSAA its multisampled twin (averaged into the HDR
/// image at the end of the pass), and the depth buffer.
fn camera_targets(
    ctx: &Context,
    setup: &RenderSetup,
) -> (
    wgpu::TextureView,
    Option<wgpu::TextureView>,
    wgpu::TextureView,
) {
    let f = setup.supersample;
    let samples = setup.msaa;
    let target = |label, format, usage, samples| {
        view(&ctx.device.create_texture(&wgpu::TextureDescriptor {
            label: Some(label),
            size: wgpu::Extent3d {
                width: (setup.width * f) as u32,
                height: (setup.height * f) as u32,
                depth_or_array_layers: 1,
            },
            mip_level_count: 1,
            sample_count: samples,
            dimension: wgpu::TextureDimension::D2,
            format,
            usage,
            view_formats: &[],
        }))
    };
    let hdr = target(
        "hdr",
        HDR_FORMAT,
        wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::TEXTURE_BINDING,
        1,
    );
    let multisampled = (samples > 1).then(|| {
        target(
            "hdr samples",
            HDR_FORMAT,
            wgpu::TextureUsages::RENDER_ATTACHMENT,
            samples,
        )
    });
    let depth = target(
        "depth",
        DEPTH_FORMAT,
        wgpu::TextureUsages::RENDER_ATTACHMENT,
        samples,
    );
    (hdr, multisampled, depth)
}

/// Bounding sphere of a frame's geometry.
fn bounds(geometry: &FrameGeometry) -> Bounds {
    let points = geometry
        .surface
        .iter()
        .map(|v| v.position)
        .chain(geometry.sides.iter().map(|v| v.position))
        .chain(geometry.probe.iter().map(|v| v.position))
        .map(|p| Vec3::new(p[0], p[1], p[2]));
    let (mut lo, mut hi) = (Vec3::splat(f32::MAX), Vec3::splat(f32::MIN));
    for p in points {
        lo = lo.min(p);
        hi = hi.max(p);
    }
    if lo.x > hi.x {
        return (Vec3::ZERO, 1.0);
    }
    ((lo + hi) * 0.5, ((hi - lo) * 0.5).length().max(1e-3))
}
