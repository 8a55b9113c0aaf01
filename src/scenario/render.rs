//! `[render]`: image size, camera, lights, environment, skin shading and
//! the frame files, validated into a [`RenderSetup`].

use std::path::Path;

use glam::Vec3;
use serde::{Deserialize, Serialize};

use crate::error::{shown, Error, Result};
use crate::render::camera::{Camera, Projection};
use crate::render::light::{Environment, Light, LightKind, GRACE_CATHEDRAL, MAX_LIGHTS};
use crate::render::specular::{region_lobes, Lobes};
use crate::render::{AlbedoSource, FrameFormat, MicroFilter, Mode, RenderSetup, Roughness};

/// `[render]`.
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct RenderSection {
    /// Image width in pixels.
    #[schemars(range(min = MIN_IMAGE_PX, max = MAX_IMAGE_PX))]
    pub width_px: usize,
    /// Image height in pixels.
    #[schemars(range(min = MIN_IMAGE_PX, max = MAX_IMAGE_PX))]
    pub height_px: usize,
    /// Supersampling factor per axis: shading runs at
    /// `factor × size` and is box-filtered down. Default 1 (the moment
    /// filter antialiases the microstructure's specular; `msaa` the edges).
    #[schemars(range(min = 1, max = 8))]
    pub supersample: usize,
    /// Multisample antialiasing of geometric edges (the patch's and the
    /// probe's silhouettes): 1 (off) or 4 samples a pixel, shading still
    /// once a pixel. Default 4.
    #[schemars(range(min = 1, max = 4))]
    pub msaa: usize,
    /// Also write `render/difference/frame_NNNN.png`: |dynamic − static|
    /// relative to static, in false colour (black 0, white ≥ 50%). Needs
    /// both modes. Default false.
    pub difference: bool,
    /// Also write `render/comparison/frame_NNNN.png`: static | dynamic |
    /// difference side by side (10 px of white between). Needs both modes.
    /// Default false.
    pub comparison: bool,
    /// Comparison modes rendered per frame (Nagano et al. 2015 Fig. 1): any of `none`
    /// (mesoscale surface, mesoscale BRDF), `static` (neutral
    /// microstructure), `dynamic` (deformed microstructure D′). Default
    /// `["dynamic"]`.
    pub modes: Vec<Mode>,
    /// Frame files: `png8` (sRGB), `png16` (sRGB, 16 bits) or `exr` (linear
    /// 32-bit floats). Default `png8`.
    pub format: FrameFormat,
    /// Render every n-th frame (frame 0 always).
    #[schemars(range(min = 1))]
    pub frame_stride: usize,
    /// Also encode `render/<mode>.mp4` with ffmpeg (must be installed). Default false.
    pub mp4: bool,
    /// Side of the texture-space irradiance textures (texels).
    #[schemars(range(min = 16, max = MAX_IMAGE_PX))]
    pub texture_px: usize,
    /// Side of each light's shadow map (texels).
    #[schemars(range(min = 16, max = MAX_IMAGE_PX))]
    pub shadow_map_px: usize,
    /// Subdivisions of each surface-triangle edge.
    #[schemars(range(min = 1, max = 8))]
    pub tessellate: usize,
    /// Pre-scatter share of the albedo (Chappuis 2011 §2.2.4).
    #[schemars(range(min = 0.0, max = 1.0))]
    pub mix_ratio: f64,
    /// Draw the probe. Default true.
    pub draw_probe: bool,
    /// Light through thin, back-lit parts (translucent shadow map). Default true.
    pub translucency: bool,
    /// `procedural` or an sRGB image file (relative to the scenario file)
    /// mapped over the patch's UV square. Default `procedural`.
    pub albedo: String,
    /// Facial region of the measured specular lobes (Graham et al. 2013 Tables 1–2):
    /// forehead, temple, cheek, nose, chin. Default `forehead`.
    pub region: FacialRegion,
    /// Subject of the measured lobes.
    #[schemars(range(min = 1, max = 2))]
    pub subject: usize,
    /// Explicit two-lobe microscale fit `[m1, m2, w]` in place of the region's.
    #[serde(default, deserialize_with = "super::arrays::exact_opt")]
    pub lobes: Option<[f64; 3]>,
    /// Specular intensity ρ_s multiplying the normalised BRDF.
    #[schemars(range(min = 0.0, max = 10.0))]
    pub specular_intensity: f64,
    /// Specular detail in `static`/`dynamic` modes: `microgeometry` (normals
    /// of the displacement map) or `anisotropic` (mesoscale normals with
    /// Beckmann roughness along the strain axes following the map's m(r),
    /// Nagano et al. 2014). Default `microgeometry`.
    pub roughness: Roughness,
    /// How `microgeometry` specular reads the map: `moments` (the slope
    /// moments' mip pyramid over each pixel's footprint, LEAN mapping:
    /// antialiased, no sparkle) or `none` (the normal map looked up
    /// bilinearly at the pixel centre, which aliases unless supersampled).
    /// Default `moments`.
    pub microstructure_filter: MicroFilter,
    /// The camera.
    pub camera: CameraSection,
    /// Up to four lights. Default: one directional light from above-left-front.
    pub lights: Option<Vec<LightSection>>,
    /// Environment light.
    pub environment: EnvironmentSection,
}

impl Default for RenderSection {
    fn default() -> Self {
        RenderSection {
            width_px: 640,
            height_px: 360,
            supersample: 1,
            msaa: 4,
            modes: vec![Mode::Dynamic],
            difference: false,
            comparison: false,
            format: FrameFormat::Png8,
            frame_stride: 1,
            mp4: false,
            texture_px: 1024,
            shadow_map_px: 1024,
            tessellate: 1,
            mix_ratio: 0.5,
            draw_probe: true,
            translucency: true,
            albedo: "procedural".into(),
            region: FacialRegion::Forehead,
            subject: 1,
            lobes: None,
            specular_intensity: 1.0,
            roughness: Roughness::Microgeometry,
            microstructure_filter: MicroFilter::Moments,
            camera: CameraSection::default(),
            lights: None,
            environment: EnvironmentSection::default(),
        }
    }
}

/// `render.region`: the facial region of the measured specular lobes.
#[derive(Clone, Copy, Debug, Deserialize, Serialize, PartialEq, Eq, schemars::JsonSchema)]
#[serde(rename_all = "lowercase")]
pub enum FacialRegion {
    /// Forehead.
    Forehead,
    /// Temple.
    Temple,
    /// Cheek.
    Cheek,
    /// Nose.
    Nose,
    /// Chin.
    Chin,
}

impl FacialRegion {
    /// The name of the lobe tables ([`region_lobes`]).
    pub fn name(self) -> &'static str {
        match self {
            FacialRegion::Forehead => "forehead",
            FacialRegion::Temple => "temple",
            FacialRegion::Cheek => "cheek",
            FacialRegion::Nose => "nose",
            FacialRegion::Chin => "chin",
        }
    }
}

/// `render.camera.projection`.
#[derive(Clone, Copy, Debug, Deserialize, Serialize, PartialEq, Eq, schemars::JsonSchema)]
#[serde(rename_all = "lowercase")]
pub enum ProjectionKind {
    /// Perspective with `fov_deg`.
    Perspective,
    /// Orthographic with `height_mm`.
    Orthographic,
}

/// `render.lights[k].kind`.
#[derive(Clone, Copy, Debug, Deserialize, Serialize, PartialEq, Eq, schemars::JsonSchema)]
#[serde(rename_all = "lowercase")]
pub enum LightType {
    /// Parallel light along `direction`.
    Directional,
    /// A point light at `position_mm`.
    Point,
}

/// `render.environment.preset`.
#[derive(Clone, Copy, Debug, Deserialize, Serialize, PartialEq, Eq, schemars::JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum EnvironmentPreset {
    /// Grace Cathedral's irradiance (Ramamoorthi & Hanrahan 2001).
    GraceCathedral,
    /// No environment light.
    None,
}

/// `[render.camera]`.
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct CameraSection {
    /// `perspective` or `orthographic`. Default `perspective`.
    pub projection: ProjectionKind,
    /// Eye position (mm). Default `[0, -14, 12]`.
    #[serde(deserialize_with = "super::arrays::exact")]
    pub eye_mm: [f64; 3],
    /// Point looked at (mm). Default `[0, 0, -0.5]`.
    #[serde(deserialize_with = "super::arrays::exact")]
    pub target_mm: [f64; 3],
    /// Up direction. Default `[0, 0, 1]`.
    #[serde(deserialize_with = "super::arrays::exact")]
    pub up: [f64; 3],
    /// Vertical field of view (degrees, perspective only).
    #[schemars(extend("default" = FOV_DEG, "exclusiveMaximum" = 170.0), range(min = 0.01))]
    pub fov_deg: Option<f64>,
    /// Height of the view (mm, orthographic only).
    #[schemars(extend("default" = HEIGHT_MM), range(min = 0.001, max = 1e4))]
    pub height_mm: Option<f64>,
}

impl Default for CameraSection {
    fn default() -> Self {
        CameraSection {
            projection: ProjectionKind::Perspective,
            eye_mm: [0.0, -14.0, 12.0],
            target_mm: [0.0, 0.0, -0.5],
            up: [0.0, 0.0, 1.0],
            fov_deg: None,
            height_mm: None,
        }
    }
}

/// `[[render.lights]]`.
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct LightSection {
    /// `directional` or `point`.
    pub kind: LightType,
    /// Direction the light travels (directional).
    #[serde(default, deserialize_with = "super::arrays::exact_opt")]
    pub direction: Option<[f64; 3]>,
    /// Position (mm, point).
    #[serde(default, deserialize_with = "super::arrays::exact_opt")]
    pub position_mm: Option<[f64; 3]>,
    /// Linear RGB colour.
    #[serde(default = "white")]
    #[serde(deserialize_with = "super::arrays::exact")]
    #[schemars(inner(range(min = 0.0, max = MAX_RENDER_VALUE)))]
    pub color: [f64; 3],
    /// Irradiance at normal incidence (at 100 mm for a point light).
    #[schemars(range(min = 0.0, max = MAX_RENDER_VALUE))]
    pub intensity: f64,
}

fn white() -> [f64; 3] {
    [1.0; 3]
}

/// `[render.environment]`.
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
pub struct EnvironmentSection {
    /// `grace_cathedral` (Ramamoorthi & Hanrahan 2001) or `none`; not
    /// together with `coefficients`. Default `grace_cathedral`.
    pub preset: Option<EnvironmentPreset>,
    /// Nine RGB SH radiance coefficients L00, L1−1, L10, L11, L2−2, L2−1,
    /// L20, L21, L22 (z up).
    #[serde(default, deserialize_with = "super::arrays::exact_rows_opt")]
    pub coefficients: Option<Vec<[f64; 3]>>,
    /// Scale of the radiance.
    #[schemars(range(min = 0.0, max = MAX_RENDER_VALUE))]
    pub intensity: f64,
}

impl Default for EnvironmentSection {
    fn default() -> Self {
        EnvironmentSection {
            preset: None,
            coefficients: None,
            intensity: 0.4,
        }
    }
}

/// Largest magnitude of a render input — a position (mm), a colour, an
/// intensity. The GPU stages compute in f32 and square distances and
/// multiply radiances, so a value that fits f64 but not that headroom
/// would turn the frame into infinities (a black image).
pub const MAX_RENDER_VALUE: f64 = 1e6;

/// Smallest and largest image side (px).
const MIN_IMAGE_PX: usize = 8;
const MAX_IMAGE_PX: usize = 8192;

/// `render.camera.fov_deg` when the file leaves it out (degrees).
const FOV_DEG: f64 = 35.0;

/// `render.camera.height_mm` when the file leaves it out (mm).
const HEIGHT_MM: f64 = 12.0;

/// `v` as written in a message.
fn triple(v: [f64; 3]) -> String {
    format!("[{}, {}, {}]", shown(v[0]), shown(v[1]), shown(v[2]))
}

fn finite_vec(key: &str, v: [f64; 3]) -> Result<Vec3> {
    if v.iter().all(|x| x.abs() <= MAX_RENDER_VALUE) {
        Ok(Vec3::new(v[0] as f32, v[1] as f32, v[2] as f32))
    } else {
        Err(Error::parameter(
            key,
            format!(
                "must be finite and within ±{MAX_RENDER_VALUE:e} (the renderer computes in f32), \
                 got {}",
                triple(v)
            ),
        ))
    }
}

/// A direction of any finite length, normalised in f64 after scaling by
/// its largest component (so a huge one does not overflow, in f32 or in
/// its norm).
fn unit_vec(key: &str, v: [f64; 3]) -> Result<Vec3> {
    if v.iter().any(|x| !x.is_finite()) {
        return Err(Error::parameter(
            key,
            format!("must be finite, got {}", triple(v)),
        ));
    }
    let largest = v.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    if largest < 1e-6 {
        return Err(Error::parameter(
            key,
            format!("must not be zero, got {}", triple(v)),
        ));
    }
    let u = (nalgebra::Vector3::from(v) / largest).normalize();
    Ok(Vec3::new(u.x as f32, u.y as f32, u.z as f32))
}

impl CameraSection {
    fn camera(&self) -> Result<Camera> {
        let eye = finite_vec("render.camera.eye_mm", self.eye_mm)?;
        let target = finite_vec("render.camera.target_mm", self.target_mm)?;
        let up = unit_vec("render.camera.up", self.up)?;
        let view = target - eye;
        if view.length() < 1e-6 {
            return Err(Error::parameter(
                "render.camera.target_mm",
                "must differ from render.camera.eye_mm",
            ));
        }
        if view.normalize().cross(up).length() < 1e-3 {
            return Err(Error::parameter(
                "render.camera.up",
                format!("must not be parallel to the view direction {view}"),
            ));
        }
        let unused = |key: &str, kind: &str| {
            Error::parameter(
                key,
                format!(
                    "has no effect with projection = \"{kind}\"; remove it or change the \
                     projection"
                ),
            )
        };
        let projection = match self.projection {
            ProjectionKind::Perspective => {
                if self.height_mm.is_some() {
                    return Err(unused("render.camera.height_mm", "perspective"));
                }
                let fov = self.fov_deg.unwrap_or(FOV_DEG);
                Projection::Perspective {
                    fov_deg: fov as f32,
                }
            }
            ProjectionKind::Orthographic => {
                if self.fov_deg.is_some() {
                    return Err(unused("render.camera.fov_deg", "orthographic"));
                }
                let height = self.height_mm.unwrap_or(HEIGHT_MM);
                Projection::Orthographic {
                    height_mm: height as f32,
                }
            }
        };
        Ok(Camera {
            eye,
            target,
            up,
            projection,
        })
    }
}

impl LightSection {
    fn light(&self, k: usize) -> Result<Light> {
        let key = |field: &str| format!("render.lights[{k}].{field}");
        // A key of the other kind of light would be silently ignored.
        let (unused, used_by, name) = match self.kind {
            LightType::Directional => ("position_mm", self.position_mm.is_some(), "directional"),
            LightType::Point => ("direction", self.direction.is_some(), "point"),
        };
        if used_by {
            return Err(Error::parameter(
                key(unused),
                format!("has no effect on a {name} light; remove it"),
            ));
        }
        let kind = match self.kind {
            LightType::Directional => {
                let d = self.direction.ok_or_else(|| {
                    Error::parameter(key("direction"), "is required for a directional light")
                })?;
                LightKind::Directional(unit_vec(&key("direction"), d)?)
            }
            LightType::Point => {
                let p = self.position_mm.ok_or_else(|| {
                    Error::parameter(key("position_mm"), "is required for a point light")
                })?;
                LightKind::Point(finite_vec(&key("position_mm"), p)?)
            }
        };
        Ok(Light {
            kind,
            color: finite_vec(&key("color"), self.color)?,
            intensity: self.intensity as f32,
        })
    }
}

impl EnvironmentSection {
    fn environment(&self) -> Result<Option<Environment>> {
        let intensity = self.intensity as f32;
        let coefficients = match &self.coefficients {
            Some(_) if self.preset.is_some() => return Err(Error::parameter(
                "render.environment.preset",
                "has no effect together with render.environment.coefficients; remove one of them",
            )),
            Some(list) => {
                if list.len() != 9 {
                    return Err(Error::parameter(
                        "render.environment.coefficients",
                        format!("must hold 9 RGB triples (L00 … L22), got {}", list.len()),
                    ));
                }
                let mut c = [[0.0f32; 3]; 9];
                for (k, v) in list.iter().enumerate() {
                    let key = format!("render.environment.coefficients[{k}]");
                    c[k] = finite_vec(&key, *v)?.to_array();
                }
                c
            }
            None => match self.preset.unwrap_or(EnvironmentPreset::GraceCathedral) {
                EnvironmentPreset::None => return Ok(None),
                EnvironmentPreset::GraceCathedral => GRACE_CATHEDRAL,
            },
        };
        Ok(Some(Environment {
            coefficients,
            intensity,
        }))
    }
}

impl RenderSection {
    /// The render settings of a scenario without `[render]`: the defaults,
    /// in mode `none` without a microstructure (the default `dynamic`
    /// needs one).
    pub fn default_setup(has_micro: bool) -> Result<RenderSetup> {
        let mut section = RenderSection::default();
        if !has_micro {
            section.modes = vec![Mode::None];
        }
        section.setup(Path::new("."), has_micro)
    }

    /// `modes`: known, needing a microstructure where they do, each once.
    fn modes(&self, has_micro: bool) -> Result<Vec<Mode>> {
        let mut modes = Vec::new();
        for (k, &mode) in self.modes.iter().enumerate() {
            let key = format!("render.modes[{k}]");
            let m = mode.name();
            if mode != Mode::None && !has_micro {
                return Err(Error::parameter(
                    key,
                    format!("\"{m}\" needs a [microstructure] section"),
                ));
            }
            if modes.contains(&mode) {
                return Err(Error::parameter(key, format!("\"{m}\" is listed twice")));
            }
            modes.push(mode);
        }
        Ok(modes)
    }

    /// Microscale lobes (explicit or the region's) and mesoscale lobes.
    fn lobes(&self) -> Result<(Lobes, Lobes)> {
        let region = self.region.name();
        let micro_lobes = match self.lobes {
            Some([m1, m2, w]) => {
                for (name, m) in [("m1", m1), ("m2", m2)] {
                    if !(m.is_finite() && (0.02..=1.0).contains(&m)) {
                        return Err(Error::parameter(
                            "render.lobes",
                            format!("{name} must be in [0.02, 1], got {m}"),
                        ));
                    }
                }
                if !(0.0..=1.0).contains(&w) {
                    return Err(Error::parameter(
                        "render.lobes",
                        format!("w must be in [0, 1], got {w}"),
                    ));
                }
                Lobes { m1, m2, w }
            }
            None => region_lobes(region, self.subject, true).expect("region and subject checked"),
        };
        let meso_lobes =
            region_lobes(region, self.subject, false).expect("region and subject checked");
        Ok((micro_lobes, meso_lobes))
    }

    /// `albedo`: procedural or an existing file relative to `base`.
    fn albedo(&self, base: &Path) -> Result<AlbedoSource> {
        let albedo = if self.albedo == "procedural" {
            AlbedoSource::Procedural
        } else {
            let path = base.join(&self.albedo);
            if !path.is_file() {
                return Err(Error::parameter(
                    "render.albedo",
                    format!(
                        "\"procedural\" or an image file; {} does not exist",
                        path.display()
                    ),
                ));
            }
            AlbedoSource::File(path)
        };
        Ok(albedo)
    }

    /// `lights`: at most four, each validated; one default light without.
    fn lights(&self) -> Result<Vec<Light>> {
        let lights = match &self.lights {
            Some(list) => {
                if list.len() > MAX_LIGHTS {
                    return Err(Error::parameter(
                        "render.lights",
                        format!("at most {MAX_LIGHTS} lights, got {}", list.len()),
                    ));
                }
                list.iter()
                    .enumerate()
                    .map(|(k, l)| l.light(k))
                    .collect::<Result<_>>()?
            }
            None => vec![Light {
                kind: LightKind::Directional(Vec3::new(0.45, 0.6, -0.66).normalize()),
                color: Vec3::new(1.0, 0.97, 0.92),
                intensity: 2.5,
            }],
        };
        Ok(lights)
    }

    /// Validates the section; `base` resolves an albedo file and
    /// `has_micro` says whether the scenario has a microstructure.
    pub fn setup(&self, base: &Path, has_micro: bool) -> Result<RenderSetup> {
        super::bounds::check_at(self, "render")?;
        self.setup_in_range(base, has_micro)
    }

    /// [`RenderSection::setup`] for a section whose ranges the whole
    /// file's check ([`super::bounds::check`]) has already held.
    pub(super) fn setup_in_range(&self, base: &Path, has_micro: bool) -> Result<RenderSetup> {
        let (width, height, supersample) = (self.width_px, self.height_px, self.supersample);
        if width * supersample > 16384 || height * supersample > 16384 {
            return Err(Error::parameter(
                "render.supersample",
                format!("{width} × {height} px × {supersample} exceeds 16384 px per side"),
            ));
        }
        if ![1, 4].contains(&self.msaa) {
            return Err(Error::parameter(
                "render.msaa",
                format!("must be 1 (off) or 4, got {}", self.msaa),
            ));
        }
        if self.modes.is_empty() {
            return Err(Error::parameter(
                "render.modes",
                "must name at least one mode",
            ));
        }
        let modes = self.modes(has_micro)?;
        let both = modes.contains(&Mode::Static) && modes.contains(&Mode::Dynamic);
        for (key, asked) in [
            ("render.difference", self.difference),
            ("render.comparison", self.comparison),
        ] {
            if asked && !both {
                return Err(Error::parameter(
                    key,
                    "needs both \"static\" and \"dynamic\" in render.modes",
                ));
            }
        }
        let format = self.format;
        if self.mp4 && format == FrameFormat::Exr {
            return Err(Error::parameter(
                "render.mp4",
                "needs PNG frames (render.format = \"png8\" or \"png16\"), not exr",
            ));
        }
        let (micro_lobes, meso_lobes) = self.lobes()?;
        let albedo = self.albedo(base)?;
        let lights = self.lights()?;
        Ok(RenderSetup {
            width,
            height,
            supersample,
            msaa: self.msaa as u32,
            modes,
            difference: self.difference,
            comparison: self.comparison,
            format,
            frame_stride: self.frame_stride,
            mp4: self.mp4,
            texture_px: self.texture_px,
            shadow_map_px: self.shadow_map_px,
            tessellate: self.tessellate,
            mix_ratio: self.mix_ratio as f32,
            draw_probe: self.draw_probe,
            translucency: self.translucency,
            albedo,
            micro_lobes,
            meso_lobes,
            specular_intensity: self.specular_intensity as f32,
            roughness: self.roughness,
            microstructure_filter: self.microstructure_filter,
            camera: self.camera.camera()?,
            lights,
            environment: self.environment.environment()?,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A direction is normalised before it meets f32, so a huge one is
    /// the same direction, not infinities; positions and intensities that
    /// f32 arithmetic cannot carry are refused with the key.
    #[test]
    fn render_inputs_fit_f32() {
        let u = unit_vec("d", [1e300, 1e300, -1e300]).unwrap();
        let expected = Vec3::new(1.0, 1.0, -1.0).normalize();
        assert!((u - expected).length() < 1e-7, "{u}");
        assert_eq!(
            unit_vec("d", [0.0, 3.0, 4.0]).unwrap(),
            Vec3::new(0.0, 0.6, 0.8)
        );
        let e = unit_vec("d", [0.0, 0.0, 1e-9]).unwrap_err();
        assert!(e.to_string().contains("must not be zero"), "{e}");
        let e = unit_vec("d", [f64::NAN, 0.0, 1.0]).unwrap_err();
        assert!(e.to_string().contains("must be finite"), "{e}");
        let e = finite_vec("render.camera.eye_mm", [0.0, -1e39, 1.0]).unwrap_err();
        assert_eq!(
            e.to_string(),
            "render.camera.eye_mm must be finite and within ±1e6 (the renderer computes in f32), \
             got [0, -1e39, 1]"
        );
    }
}
