//! The rigid probe's geometry: shapes, the keyframed path, and per pose the
//! signed distance, closest point, normal, curvature and rigid carry that
//! the contact solve ([`super::contact`]) works with.
//!
//! Shapes: sphere (centre, radius), capsule (segment through the centre
//! along an axis, radius) and flat cylindrical punch (circular flat face of a
//! radius, pressing along −z; its rim is sharp). A keyframed path gives the
//! centre (and the capsule's axis) over time, linearly interpolated.

use nalgebra::Vector3;

use super::boundary::Keyframes;
use crate::mesh::Vec3;

/// Probe geometry.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ProbeShape {
    /// A ball.
    Sphere {
        /// Radius (mm).
        radius_mm: f64,
    },
    /// A cylinder with hemispherical ends, of `length_mm` between the end
    /// centres, along the keyframed axis.
    Capsule {
        /// Radius (mm).
        radius_mm: f64,
        /// Distance between the two end centres (mm).
        length_mm: f64,
    },
    /// A flat circular face of `radius_mm` facing −z at the probe position.
    Punch {
        /// Radius (mm).
        radius_mm: f64,
    },
}

/// How contact nodes interact with the probe.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ContactMode {
    /// No friction.
    Frictionless,
    /// Coulomb friction with this coefficient (stick and slip).
    Coulomb(f64),
    /// Nodes that touch stay attached.
    Bonded,
}

/// The probe: shape, path and contact mode.
#[derive(Clone, Debug, PartialEq)]
pub struct Probe {
    /// Geometry.
    pub shape: ProbeShape,
    /// Position of the centre (sphere, capsule) or face centre (punch) over time (mm).
    pub path: Keyframes<Vector3<f64>>,
    /// Capsule axis over time (normalised after interpolation); ignored otherwise.
    pub axis: Keyframes<Vector3<f64>>,
    /// Contact mode.
    pub mode: ContactMode,
}

/// The probe at one instant.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ProbePose {
    /// Geometry.
    pub shape: ProbeShape,
    /// Centre (mm).
    pub centre: Vec3,
    /// Unit axis (capsule).
    pub axis: Vec3,
}

impl Probe {
    /// The pose at time `t`.
    pub fn pose(&self, t: f64) -> ProbePose {
        let axis = self.axis.at(t);
        let axis = if axis.norm() > 0.0 {
            axis.normalize()
        } else {
            Vector3::x()
        };
        ProbePose {
            shape: self.shape,
            centre: self.path.at(t),
            axis,
        }
    }
}

impl Probe {
    /// Radius of the probe's rounded or flat part (mm). The probe is at
    /// least twice this thick, so a load step in which it moves less than
    /// that cannot carry it past a node without the node ending inside it.
    pub fn radius_mm(&self) -> f64 {
        match self.shape {
            ProbeShape::Sphere { radius_mm }
            | ProbeShape::Capsule { radius_mm, .. }
            | ProbeShape::Punch { radius_mm } => radius_mm,
        }
    }

    /// The times of the path's and the axis's keyframes, in no order.
    pub fn keyframe_times(&self) -> impl Iterator<Item = f64> + '_ {
        let path = self.path.points.iter().map(|p| p.0);
        path.chain(self.axis.points.iter().map(|p| p.0))
    }

    /// How far the probe's points move between `t0` and `t1` at most (mm):
    /// the length of the centre's path plus, for a capsule, its half length
    /// times the angle its axis turns through (both piecewise between the
    /// keyframes inside the interval).
    pub fn travel(&self, t0: f64, t1: f64) -> f64 {
        let mut times = vec![t0];
        for k in [&self.path, &self.axis] {
            times.extend(k.points.iter().map(|p| p.0).filter(|&t| t > t0 && t < t1));
        }
        times.push(t1);
        times.sort_by(f64::total_cmp);
        let half_length = match self.shape {
            ProbeShape::Capsule { length_mm, .. } => length_mm / 2.0,
            _ => 0.0,
        };
        times
            .windows(2)
            .map(|w| {
                let (a, b) = (self.pose(w[0]), self.pose(w[1]));
                (b.centre - a.centre).norm() + half_length * a.axis.angle(&b.axis)
            })
            .sum()
    }
}

impl ProbePose {
    /// Signed distance of `p` to the probe surface (negative inside) and the
    /// outward unit normal of the closest surface point.
    pub fn distance(&self, p: &Vec3) -> (f64, Vec3) {
        match self.shape {
            ProbeShape::Sphere { radius_mm } => sphere_distance(&self.centre, radius_mm, p),
            ProbeShape::Capsule {
                radius_mm,
                length_mm,
            } => {
                let d = p - self.centre;
                let s = d.dot(&self.axis).clamp(-length_mm / 2.0, length_mm / 2.0);
                sphere_distance(&(self.centre + self.axis * s), radius_mm, p)
            }
            ProbeShape::Punch { radius_mm } => {
                let d = p - self.centre;
                let r = (d.x * d.x + d.y * d.y).sqrt();
                if r <= radius_mm {
                    // Below the face is outside; above it is inside.
                    (-d.z, -Vec3::z())
                } else {
                    (f64::INFINITY, -Vec3::z())
                }
            }
        }
    }

    /// The probe's lowest point (mm): the bottom of the sphere, of the
    /// capsule's lower end (its middle when level), the punch's face centre.
    pub fn lowest_point(&self) -> Vec3 {
        match self.shape {
            ProbeShape::Sphere { radius_mm } => self.centre - Vec3::z() * radius_mm,
            ProbeShape::Capsule {
                radius_mm,
                length_mm,
            } => {
                let end = self.axis * (0.5 * length_mm * -self.axis.z.signum());
                let end = if self.axis.z == 0.0 {
                    Vec3::zeros()
                } else {
                    end
                };
                self.centre + end - Vec3::z() * radius_mm
            }
            ProbeShape::Punch { .. } => self.centre,
        }
    }

    /// Height of the probe's lowest point (mm).
    pub fn lowest_z(&self) -> f64 {
        match self.shape {
            ProbeShape::Sphere { radius_mm } => self.centre.z - radius_mm,
            ProbeShape::Capsule {
                radius_mm,
                length_mm,
            } => self.centre.z - radius_mm - 0.5 * length_mm * self.axis.z.abs(),
            ProbeShape::Punch { .. } => self.centre.z,
        }
    }

    /// The pose moved up by `h` (mm).
    pub fn lifted(&self, h: f64) -> ProbePose {
        ProbePose {
            centre: self.centre + Vec3::z() * h,
            ..*self
        }
    }

    /// The Hessian of the distance to the probe surface at `p` (1/mm): its
    /// curvature, `(I − n nᵀ)/ρ` at distance ρ from a sphere's centre,
    /// `(I − n nᵀ − a aᵀ)/ρ` from a capsule's axis `a` between its ends,
    /// zero for the flat punch.
    pub fn distance_hessian(&self, p: &Vec3) -> nalgebra::Matrix3<f64> {
        let curved = |centre: &Vec3, along: Option<&Vec3>| {
            let d = p - centre;
            let rho = d.norm();
            if rho == 0.0 {
                return nalgebra::Matrix3::zeros();
            }
            let n = d / rho;
            let mut m = nalgebra::Matrix3::identity() - n * n.transpose();
            if let Some(a) = along {
                m -= a * a.transpose();
            }
            m / rho
        };
        match self.shape {
            ProbeShape::Sphere { .. } => curved(&self.centre, None),
            ProbeShape::Capsule { length_mm, .. } => {
                let s = (p - self.centre).dot(&self.axis);
                let half = length_mm / 2.0;
                let on_axis = self.centre + self.axis * s.clamp(-half, half);
                if s.abs() < half {
                    curved(&on_axis, Some(&self.axis))
                } else {
                    curved(&on_axis, None)
                }
            }
            ProbeShape::Punch { .. } => nalgebra::Matrix3::zeros(),
        }
    }

    /// The closest point on the probe surface to `p`, with its outward normal.
    pub fn project(&self, p: &Vec3) -> (Vec3, Vec3) {
        let (d, n) = self.distance(p);
        if d.is_finite() {
            (p - n * d, n)
        } else {
            (*p, n)
        }
    }

    /// The rigid motion from `self` to `other` applied to `p` (translation,
    /// plus the rotation taking one capsule axis to the other).
    pub fn carry(&self, other: &ProbePose, p: &Vec3) -> Vec3 {
        let rot = nalgebra::Rotation3::rotation_between(&self.axis, &other.axis)
            .unwrap_or_else(nalgebra::Rotation3::identity);
        other.centre + rot * (p - self.centre)
    }
}

fn sphere_distance(c: &Vec3, r: f64, p: &Vec3) -> (f64, Vec3) {
    let d = p - c;
    let len = d.norm();
    let n = if len > 0.0 { d / len } else { Vec3::z() };
    (len - r, n)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pose(shape: ProbeShape) -> ProbePose {
        ProbePose {
            shape,
            centre: Vec3::new(0.0, 0.0, 1.0),
            axis: Vec3::x(),
        }
    }

    /// Travel sums the path between keyframes (a chord would cut the
    /// corner) and adds the capsule ends' arc when its axis turns.
    #[test]
    fn travel_follows_the_path_and_the_turn() {
        let keys = |points: &[(f64, [f64; 3])]| Keyframes {
            points: points.iter().map(|&(t, v)| (t, Vector3::from(v))).collect(),
        };
        let probe = Probe {
            shape: ProbeShape::Capsule {
                radius_mm: 1.0,
                length_mm: 4.0,
            },
            path: keys(&[
                (0.0, [0.0, 0.0, 1.0]),
                (0.5, [3.0, 0.0, 1.0]),
                (1.0, [3.0, 4.0, 1.0]),
            ]),
            axis: keys(&[(0.0, [1.0, 0.0, 0.0]), (1.0, [0.0, 1.0, 0.0])]),
            mode: ContactMode::Frictionless,
        };
        let quarter = std::f64::consts::FRAC_PI_2;
        assert!((probe.travel(0.0, 1.0) - (3.0 + 4.0 + 2.0 * quarter)).abs() < 1e-12);
        // At t = 0.25 the axis is (0.75, 0.25, 0) normalised.
        let turn = (1.0_f64 / 3.0).atan();
        assert!((probe.travel(0.0, 0.25) - (1.5 + 2.0 * turn)).abs() < 1e-12);
        assert_eq!(probe.radius_mm(), 1.0);
        let pose = probe.pose(0.0);
        assert_eq!(pose.lowest_z(), 0.0);
        assert_eq!(pose.lifted(2.0).centre, Vec3::new(0.0, 0.0, 3.0));
    }

    #[test]
    fn distances_and_normals() {
        let s = pose(ProbeShape::Sphere { radius_mm: 1.5 });
        let (d, n) = s.distance(&Vec3::new(0.0, 0.0, -0.2));
        assert!((d - -0.3).abs() < 1e-15 && (n + Vec3::z()).norm() < 1e-15);
        let c = pose(ProbeShape::Capsule {
            radius_mm: 1.0,
            length_mm: 4.0,
        });
        let (d, n) = c.distance(&Vec3::new(1.7, 0.0, 0.5));
        assert!((d + 0.5).abs() < 1e-15 && (n + Vec3::z()).norm() < 1e-15);
        let (d, _) = c.distance(&Vec3::new(3.0, 0.0, 1.0));
        assert!((d - 0.0).abs() < 1e-15, "end cap at x = 2 + 1");
        let p = pose(ProbeShape::Punch { radius_mm: 1.0 });
        // Below the face (z = 1) is outside, above it inside.
        assert!((p.distance(&Vec3::new(0.5, 0.5, 0.8)).0 - 0.2).abs() < 1e-15);
        assert!((p.distance(&Vec3::new(0.5, 0.5, 1.2)).0 + 0.2).abs() < 1e-15);
        assert!(p.distance(&Vec3::new(1.5, 0.0, 0.8)).0.is_infinite());
        let (q, _) = s.project(&Vec3::new(0.0, 0.0, 0.0));
        assert!((q - Vec3::new(0.0, 0.0, -0.5)).norm() < 1e-15);
    }

    #[test]
    fn carry_moves_rigidly() {
        let a = pose(ProbeShape::Capsule {
            radius_mm: 1.0,
            length_mm: 2.0,
        });
        let mut b = a;
        b.centre = Vec3::new(1.0, 0.0, 1.0);
        b.axis = Vec3::y();
        let p = Vec3::new(1.0, 0.0, 0.0);
        // Offset (1, 0, −1) from the centre turns with the axis into (0, 1, −1).
        assert!((a.carry(&b, &p) - Vec3::new(1.0, 1.0, 0.0)).norm() < 1e-12);
    }
}
