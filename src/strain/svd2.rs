//! Closed-form SVD of a 2×2 matrix (Nagano et al. 2015 eq. 11–12).
//!
//! Any real 2×2 matrix splits into a conformal part (a scaled rotation) and
//! an anticonformal part (a scaled reflection):
//!
//! ```text
//! T = [a b; c d],  E = (a+d)/2, F = (a−d)/2, G = (c+b)/2, H = (c−b)/2
//! T = q·Rot(φ₂) + p·Refl(φ₁),  q = √(E²+H²), φ₂ = atan2(H, E),
//!                              p = √(F²+G²), φ₁ = atan2(G, F)
//! ```
//!
//! with `Rot(φ) = [cos −sin; sin cos]` and `Refl(φ) = [cos sin; sin −cos]`.
//! Since `Rot(β)·diag(x, y)·Rot(γ)ᵀ = ((x+y)/2)·Rot(β−γ) + ((x−y)/2)·Refl(β+γ)`,
//! `T = U Σ Vᵀ` with `U = Rot((φ₁+φ₂)/2)`, `V = Rot((φ₁−φ₂)/2)` and
//! `Σ = diag(q + p, q − p)`.
//!
//! Both `U` and `V` are rotations, so the second value carries the sign of
//! `det T = q² − p²`: `r_t < 0` marks a folded (orientation-reversing) map,
//! the 2D counterpart of the sign-corrected 3D SVD of the FEM. Always
//! `r_s ≥ |r_t|`. Equal singular values (`p = 0`, a scaled rotation) give
//! `φ₁ = atan2(0, 0) = 0`: any axes are principal there and these are finite;
//! the zero matrix gives `r_s = r_t = 0` with identity axes. No branch
//! divides, so near-equal values and degenerate maps stay accurate. The same
//! arithmetic runs per texel on the GPU.

use nalgebra::{Matrix2, Vector2};

/// `T = U diag(r_s, r_t) Vᵀ` with `U`, `V` rotations.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Svd2 {
    /// Larger stretch ratio (≥ |r_t|, ≥ 0).
    pub rs: f64,
    /// Smaller stretch ratio; negative when `det T < 0`.
    pub rt: f64,
    /// Rotation angle of `U` (principal directions after the map), radians.
    pub u_angle: f64,
    /// Rotation angle of `V` (principal directions before the map), radians.
    pub v_angle: f64,
}

impl Svd2 {
    /// Decomposes `t`.
    pub fn of(t: &Matrix2<f64>) -> Svd2 {
        let (a, b, c, d) = (t[(0, 0)], t[(0, 1)], t[(1, 0)], t[(1, 1)]);
        let e = 0.5 * (a + d);
        let f = 0.5 * (a - d);
        let g = 0.5 * (c + b);
        let h = 0.5 * (c - b);
        let q = e.hypot(h);
        let p = f.hypot(g);
        let phi1 = g.atan2(f);
        let phi2 = h.atan2(e);
        Svd2 {
            rs: q + p,
            rt: q - p,
            u_angle: 0.5 * (phi1 + phi2),
            v_angle: 0.5 * (phi1 - phi2),
        }
    }

    /// `U`.
    pub fn u(&self) -> Matrix2<f64> {
        rotation(self.u_angle)
    }

    /// `V`.
    pub fn v(&self) -> Matrix2<f64> {
        rotation(self.v_angle)
    }

    /// First column of `V`: the direction stretched by `r_s`, before the map.
    pub fn s_axis(&self) -> Vector2<f64> {
        Vector2::new(self.v_angle.cos(), self.v_angle.sin())
    }

    /// Second column of `V`: the direction stretched by `r_t`.
    pub fn t_axis(&self) -> Vector2<f64> {
        Vector2::new(-self.v_angle.sin(), self.v_angle.cos())
    }

    /// Whether the map reverses orientation (`det T < 0`).
    pub fn folded(&self) -> bool {
        self.rt < 0.0
    }

    /// `U Σ Vᵀ` (for checks).
    pub fn matrix(&self) -> Matrix2<f64> {
        self.u() * Matrix2::new(self.rs, 0.0, 0.0, self.rt) * self.v().transpose()
    }
}

/// The rotation by `angle` (counter-clockwise).
pub fn rotation(angle: f64) -> Matrix2<f64> {
    let (s, c) = angle.sin_cos();
    Matrix2::new(c, -s, s, c)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stretch_at_an_angle() {
        let (l1, l2, theta) = (1.3, 0.8, 0.4);
        let t = rotation(theta) * Matrix2::new(l1, 0.0, 0.0, l2) * rotation(theta).transpose();
        let svd = Svd2::of(&t);
        assert!((svd.rs - l1).abs() < 1e-15 && (svd.rt - l2).abs() < 1e-15);
        assert!((svd.v_angle - theta).abs() < 1e-15, "{svd:?}");
        assert!((svd.matrix() - t).norm() < 1e-15);
    }

    #[test]
    fn degenerate_cases_are_finite() {
        for t in [
            Matrix2::zeros(),
            Matrix2::identity() * 2.0,
            rotation(2.0) * 0.5,
            Matrix2::new(1.0, 0.0, 0.0, 0.0),
            Matrix2::new(1.0, 0.0, 0.0, -1.0),
            Matrix2::new(0.0, 1.0, 0.0, 0.0),
        ] {
            let svd = Svd2::of(&t);
            assert!(svd.rs.is_finite() && svd.u_angle.is_finite() && svd.v_angle.is_finite());
            assert!((svd.matrix() - t).norm() < 1e-15, "{t} → {svd:?}");
            assert!(svd.rs >= svd.rt.abs());
        }
        let reflected = Svd2::of(&Matrix2::new(1.0, 0.0, 0.0, -0.5));
        assert!(reflected.folded() && (reflected.rt + 0.5).abs() < 1e-15);
    }
}
