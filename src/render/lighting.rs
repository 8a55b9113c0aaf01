//! The scene uniforms shared by the lighting shaders
//! (`shaders/lighting.wgsl`, prepended to `irradiance.wgsl` and
//! `skin.wgsl`) and the light-space projections of the shadow maps.

use bytemuck::{Pod, Zeroable};
use glam::{Mat4, Vec3};

use super::camera::{Camera, Projection};
use super::light::{Light, LightKind, MAX_LIGHTS};
use super::profile::{VARIANCES_MM2, WEIGHTS};
use super::specular::{EnergyTable, Lobes};
use super::{Mode, RenderSetup, Roughness};

/// The shader source.
pub const SHADER: &str = include_str!("../../shaders/lighting.wgsl");

/// One light; mirrors WGSL `Light`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct GpuLight {
    /// Direction of travel (w = 0) or position in mm (w = 1).
    pub where_: [f32; 4],
    /// Irradiance at normal incidence (rgb); w: shadow texel size (mm).
    pub radiance: [f32; 4],
    /// The light's shadow-map projection.
    pub view_proj: [[f32; 4]; 4],
}

/// Scene uniforms; mirrors WGSL `Globals`.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
pub struct Globals {
    /// Camera view-projection.
    pub view_proj: [[f32; 4]; 4],
    /// Eye (mm); w = 1 perspective, 0 orthographic.
    pub eye: [f32; 4],
    /// Unit view direction.
    pub forward: [f32; 4],
    /// Lights (the first `flags[0]` are used).
    pub lights: [GpuLight; MAX_LIGHTS],
    /// SH radiance coefficients (rgb), scaled by the environment intensity.
    pub sh: [[f32; 4]; 9],
    /// Per Gaussian: rgb weights and variance (mm²).
    pub profile: [[f32; 4]; 6],
    /// m1, m2, w, ρ_s of the microscale lobes.
    pub micro_lobes: [f32; 4],
    /// m1, m2, w, ρ_s of the mesoscale lobes.
    pub meso_lobes: [f32; 4],
    /// m(r)/m(1) at r = 0.70, 0.75, … 1.45.
    pub roughness_curve: [f32; 16],
    /// Mix ratio, shadow-map side, environment attenuation (micro, meso).
    pub params: [f32; 4],
    /// Light count, mode, roughness kind, translucency.
    pub flags: [u32; 4],
    /// Microstructure filter (0 bilinear normals, 1 slope moments); the
    /// moments sampled with the sampler (1) or by loads (0); the strain
    /// overlay ([`super::overlay::OverlayKind`]); its range as f32 bits.
    pub options: [u32; 4],
}

/// Stretch ratios of [`Globals::roughness_curve`].
pub fn curve_ratios() -> [f64; 16] {
    std::array::from_fn(|i| 0.7 + 0.05 * i as f64)
}

/// The bounding sphere of the scene (centre, radius in mm).
pub type Bounds = (Vec3, f32);

/// A light's shadow-map projection covering the sphere `bounds`, and the
/// width the map spans at the scene's centre (mm).
pub fn light_view(light: &Light, (centre, radius): Bounds) -> (Mat4, f32) {
    let r = radius.max(1e-3);
    let up_for = |dir: Vec3| {
        if dir.cross(Vec3::Z).length() > 1e-3 {
            Vec3::Z
        } else {
            Vec3::X
        }
    };
    match light.kind {
        LightKind::Directional(d) => {
            let eye = centre - d * 2.0 * r;
            let m = Mat4::orthographic_rh(-r, r, -r, r, 0.0, 4.0 * r)
                * Mat4::look_at_rh(eye, centre, up_for(d));
            (m, 2.0 * r)
        }
        LightKind::Point(p) => {
            let to = centre - p;
            let dist = to.length().max(1e-3);
            let half = if dist > r * 1.05 {
                (r / dist).asin() * 1.05
            } else {
                1.1
            };
            let near = (dist - r).max(dist * 1e-3).max(1e-3);
            let m = Mat4::perspective_rh(2.0 * half, 1.0, near, dist + r)
                * Mat4::look_at_rh(p, centre, up_for(to / dist));
            (m, 2.0 * dist * half.tan())
        }
    }
}

impl Globals {
    /// Uniforms for `mode` with camera aspect `aspect` and scene `bounds`;
    /// `curve` is m(r)/m(1) at [`curve_ratios`].
    pub fn new(
        setup: &RenderSetup,
        table: &EnergyTable,
        mode: Mode,
        aspect: f32,
        bounds: Bounds,
        curve: [f32; 16],
    ) -> Globals {
        let camera: &Camera = &setup.camera;
        let forward = (camera.target - camera.eye).normalize();
        let mut lights = [GpuLight::default(); MAX_LIGHTS];
        for (g, l) in lights.iter_mut().zip(&setup.lights) {
            let where_ = match l.kind {
                LightKind::Directional(d) => d.extend(0.0),
                LightKind::Point(p) => p.extend(1.0),
            };
            let (view_proj, extent_mm) = light_view(l, bounds);
            *g = GpuLight {
                where_: where_.to_array(),
                // w: the shadow map's texel size at the scene (mm).
                radiance: (l.color * l.intensity)
                    .extend(extent_mm / setup.shadow_map_px as f32)
                    .to_array(),
                view_proj: view_proj.to_cols_array_2d(),
            };
        }
        let mut sh = [[0.0; 4]; 9];
        if let Some(env) = &setup.environment {
            for (s, c) in sh.iter_mut().zip(env.coefficients) {
                *s = (Vec3::from(c) * env.intensity).extend(0.0).to_array();
            }
        }
        let profile = std::array::from_fn(|i| {
            let w = WEIGHTS[i];
            [
                w[0] as f32,
                w[1] as f32,
                w[2] as f32,
                VARIANCES_MM2[i] as f32,
            ]
        });
        let rho_s = setup.specular_intensity;
        let lobes = |l: &Lobes| [l.m1 as f32, l.m2 as f32, l.w as f32, rho_s];
        let env = |l: &Lobes| (1.0 - rho_s as f64 * table.hemispherical(l)).max(0.0) as f32;
        Globals {
            view_proj: camera
                .view_projection(aspect, bounds.0, bounds.1)
                .to_cols_array_2d(),
            eye: camera
                .eye
                .extend(matches!(camera.projection, Projection::Perspective { .. }) as u32 as f32)
                .to_array(),
            forward: forward.extend(0.0).to_array(),
            lights,
            sh,
            profile,
            micro_lobes: lobes(&setup.micro_lobes),
            meso_lobes: lobes(&setup.meso_lobes),
            roughness_curve: curve,
            params: [
                setup.mix_ratio,
                setup.shadow_map_px as f32,
                env(&setup.micro_lobes),
                env(&setup.meso_lobes),
            ],
            flags: [
                setup.lights.len() as u32,
                mode as u32,
                (setup.roughness == Roughness::Anisotropic) as u32,
                setup.translucency as u32,
            ],
            options: [
                (setup.microstructure_filter == super::MicroFilter::Moments) as u32,
                0,
                0,
                0,
            ],
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn uniform_sizes_match_wgsl() {
        // WGSL: Light 96 B; Globals 64 + 16 + 16 + 4·96 + 9·16 + 6·16 + 16
        // + 16 + 64 + 16 + 16 + 16.
        assert_eq!(std::mem::size_of::<GpuLight>(), 96);
        assert_eq!(std::mem::size_of::<Globals>(), 864);
    }

    #[test]
    fn light_projection_contains_the_scene() {
        let bounds = (Vec3::new(0.0, 0.0, -2.0), 8.0);
        for kind in [
            LightKind::Directional(Vec3::new(0.3, 0.2, -1.0).normalize()),
            LightKind::Point(Vec3::new(10.0, -5.0, 40.0)),
        ] {
            let light = Light {
                kind,
                color: Vec3::ONE,
                intensity: 1.0,
            };
            let (m, _) = light_view(&light, bounds);
            for d in [Vec3::X, -Vec3::X, Vec3::Y, -Vec3::Y, Vec3::Z, -Vec3::Z] {
                let p = m.project_point3(bounds.0 + d * 7.9);
                assert!(p.x.abs() <= 1.0 && p.y.abs() <= 1.0, "{kind:?}: {p}");
                assert!((0.0..=1.0).contains(&p.z), "{kind:?}: {p}");
            }
        }
    }
}
