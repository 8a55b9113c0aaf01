//! The scenario camera: look-at with a perspective or orthographic
//! projection, in millimetres (z up, like the patch).
//!
//! Projections map depth to wgpu's [0, 1] range; the near and far planes
//! are fitted to the scene's bounding sphere each frame so the depth buffer
//! keeps its precision.

use glam::{Mat4, Vec3};

/// Projection kind.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Projection {
    /// Perspective with this vertical field of view (degrees, in (0, 180)).
    Perspective {
        /// Vertical field of view (degrees).
        fov_deg: f32,
    },
    /// Orthographic showing this height (mm).
    Orthographic {
        /// Height of the view (mm).
        height_mm: f32,
    },
}

/// A validated camera.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    /// Eye position (mm).
    pub eye: Vec3,
    /// Point looked at (mm).
    pub target: Vec3,
    /// Up direction (not parallel to the view direction).
    pub up: Vec3,
    /// Projection.
    pub projection: Projection,
}

impl Camera {
    /// View matrix (right-handed, looking down −z in view space).
    pub fn view(&self) -> Mat4 {
        Mat4::look_at_rh(self.eye, self.target, self.up)
    }

    /// Projection for `aspect` (width / height) with depth planes enclosing
    /// a sphere of `radius` around `centre`.
    pub fn projection(&self, aspect: f32, centre: Vec3, radius: f32) -> Mat4 {
        let dist = (centre - self.eye).dot((self.target - self.eye).normalize());
        let far = (dist + radius).max(1e-3) * 1.01;
        match self.projection {
            Projection::Perspective { fov_deg } => {
                let near = (dist - radius).max(far * 1e-4);
                Mat4::perspective_rh(fov_deg.to_radians(), aspect, near, far)
            }
            Projection::Orthographic { height_mm } => {
                let (h, w) = (0.5 * height_mm, 0.5 * height_mm * aspect);
                let near = dist - radius * 1.01;
                Mat4::orthographic_rh(-w, w, -h, h, near, far)
            }
        }
    }

    /// Combined view-projection.
    pub fn view_projection(&self, aspect: f32, centre: Vec3, radius: f32) -> Mat4 {
        self.projection(aspect, centre, radius) * self.view()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn target_projects_to_the_centre_within_depth_range() {
        for projection in [
            Projection::Perspective { fov_deg: 30.0 },
            Projection::Orthographic { height_mm: 12.0 },
        ] {
            let cam = Camera {
                eye: Vec3::new(3.0, -20.0, 25.0),
                target: Vec3::ZERO,
                up: Vec3::Z,
                projection,
            };
            let m = cam.view_projection(16.0 / 9.0, Vec3::ZERO, 8.0);
            let p = m.project_point3(Vec3::ZERO);
            assert!(p.x.abs() < 1e-5 && p.y.abs() < 1e-5, "{p}");
            assert!(p.z > 0.0 && p.z < 1.0, "{p}");
            // A point on the bounding sphere stays within the depth range.
            let near = m.project_point3((cam.eye - cam.target).normalize() * 7.9);
            assert!(near.z > 0.0 && near.z < 1.0, "{near}");
        }
    }
}
