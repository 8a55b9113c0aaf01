//! The skin renderer (Chappuis 2011 ch. 2–3, Graham et al. 2013 §3, §5).
//!
//! Per frame and comparison mode, on the GPU (wgpu render and compute
//! passes):
//! 1. [`shadow`]: one shadow / translucent shadow map per light;
//! 2. [`irradiance`]: the top surface drawn in texture space — irradiance
//!    from the lights (shadowed, PCF, scaled by `ρ_dt`) and the SH
//!    environment, times the pre-scatter albedo; the stretch map; light
//!    transmitted through the patch from lights behind it;
//! 3. [`diffusion`]: the six-Gaussian skin profile as twelve separable
//!    seven-tap passes with stretch correction ([`profile`] is the CPU
//!    reference);
//! 4. [`skin`]: the camera pass — diffused light × post-scatter albedo ×
//!    `ρ_dt(n·v)`, plus two-lobe Kelemen/Szirmay-Kalos specular
//!    ([`specular`]) from the microstructure normals; the patch's cut sides
//!    and the probe;
//! 5. [`resolve`]: the supersampled image box-filtered to the output size.
//!
//! Comparison modes (Nagano et al. 2015 Fig. 1): `None` shades with mesoscale normals
//! and the mesoscale lobes (Graham et al. 2013 Table 2), `Static` with the neutral
//! map's normals and the microscale lobes (Table 1), `Dynamic` with the
//! deformed map D′'s normals. Everything is linear until the frame writer
//! encodes sRGB.

pub mod albedo;
pub mod camera;
pub mod diffusion;
pub mod irradiance;
pub mod light;
pub mod lighting;
pub mod moments;
pub mod overlay;
pub mod profile;
pub mod renderer;
pub mod resolve;
pub mod scene;
pub mod shadow;
pub mod skin;
pub mod specular;
pub mod stage;

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use std::path::PathBuf;

pub use crate::imaging::{FrameFormat, Image};
pub use renderer::{FrameStage, NormalMap, Renderer};

/// A comparison mode (`none`, `static`, `dynamic` in scenario files).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Deserialize, Serialize, JsonSchema)]
#[serde(rename_all = "lowercase")]
pub enum Mode {
    /// No microstructure: mesoscale normals and lobes.
    None = 0,
    /// The neutral microstructure.
    Static = 1,
    /// The deformed microstructure D′.
    Dynamic = 2,
}

impl Mode {
    /// Name used in scenario files and folder names.
    pub fn name(self) -> &'static str {
        match self {
            Mode::None => "none",
            Mode::Static => "static",
            Mode::Dynamic => "dynamic",
        }
    }
}

/// Where the albedo comes from.
#[derive(Clone, Debug, PartialEq)]
pub enum AlbedoSource {
    /// [`albedo::Albedo::procedural`].
    Procedural,
    /// An sRGB PNG over the UV square.
    File(PathBuf),
}

/// Specular detail in the static and dynamic modes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize, Serialize, JsonSchema)]
#[serde(rename_all = "lowercase")]
pub enum Roughness {
    /// Normals of the displacement map.
    Microgeometry,
    /// Mesoscale normals with anisotropic Beckmann roughness along the
    /// strain axes (Nagano et al. 2014).
    Anisotropic,
}

/// How the skin pass reads the microstructure in the static and dynamic
/// modes (with `Roughness::Microgeometry`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize, Serialize, JsonSchema)]
#[serde(rename_all = "lowercase")]
pub enum MicroFilter {
    /// The normal map looked up bilinearly at the pixel's centre: aliases
    /// where a pixel covers several texels (supersampling hides it).
    None,
    /// The slope moments' mip pyramid over the pixel's footprint (LEAN):
    /// mean slope and covariance widen the Beckmann lobes.
    Moments,
}

/// Validated render settings (from `[render]`).
#[derive(Clone, Debug, PartialEq)]
pub struct RenderSetup {
    /// Output width (px).
    pub width: usize,
    /// Output height (px).
    pub height: usize,
    /// Supersampling factor per axis.
    pub supersample: usize,
    /// Multisample count of the camera pass (1 or 4).
    pub msaa: u32,
    /// Modes rendered per frame.
    pub modes: Vec<Mode>,
    /// Write |dynamic − static| in false colour per rendered frame.
    pub difference: bool,
    /// Write static | dynamic | difference side by side per rendered frame.
    pub comparison: bool,
    /// Frame file format.
    pub format: FrameFormat,
    /// Render every n-th frame.
    pub frame_stride: usize,
    /// Encode an MP4 per mode with ffmpeg.
    pub mp4: bool,
    /// Side of the texture-space textures.
    pub texture_px: usize,
    /// Side of the shadow maps.
    pub shadow_map_px: usize,
    /// Edge subdivisions of the surface.
    pub tessellate: usize,
    /// Pre-scatter share of the albedo.
    pub mix_ratio: f32,
    /// Draw the probe.
    pub draw_probe: bool,
    /// Translucent shadow map on.
    pub translucency: bool,
    /// Albedo source.
    pub albedo: AlbedoSource,
    /// Microscale lobes (static and dynamic modes).
    pub micro_lobes: specular::Lobes,
    /// Mesoscale lobes (mode none).
    pub meso_lobes: specular::Lobes,
    /// ρ_s.
    pub specular_intensity: f32,
    /// Specular detail.
    pub roughness: Roughness,
    /// Prefiltering of the microstructure's specular.
    pub microstructure_filter: MicroFilter,
    /// Camera.
    pub camera: camera::Camera,
    /// Lights.
    pub lights: Vec<light::Light>,
    /// Environment light.
    pub environment: Option<light::Environment>,
}

/// The renderer's shader sources by file name, for validation: whole
/// modules as compiled (`shaders/lighting.wgsl` and `overlay.wgsl`
/// prepended where the passes use them).
pub fn shader_sources() -> Vec<(&'static str, String)> {
    vec![
        ("moments.wgsl", moments::SHADER.to_string()),
        ("shadow.wgsl", shadow::SHADER.to_string()),
        ("irradiance.wgsl", irradiance::source()),
        ("diffusion.wgsl", diffusion::SHADER.to_string()),
        ("skin.wgsl", skin::source()),
        ("resolve.wgsl", resolve::SHADER.to_string()),
    ]
}
