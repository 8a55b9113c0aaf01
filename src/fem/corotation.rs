//! Corotational linear tetrahedra (Müller & Gross 2004) with the invertible
//! rotation of Irving et al. 2004.
//!
//! Per tet with rest vertices `X0..X3`, `Dm = [X1−X0, X2−X0, X3−X0]`; the
//! shape-function gradients are the rows of `Dm⁻¹` (`g1..g3`) and
//! `g0 = −(g1 + g2 + g3)`, so `F = Σ_a x_a ⊗ g_a = Ds·Dm⁻¹`.
//!
//! The rest stiffness of isotropic linear elasticity, in 3×3 blocks:
//! `K0_ab = V [λ g_a g_bᵀ + μ g_b g_aᵀ + μ (g_a·g_b) I]`.
//!
//! Rotation: SVD `F = U Σ Vᵀ`; when `det U < 0` or `det V < 0` the column of
//! the smallest singular value is negated (and that σ with it), so `U`, `V`
//! are rotations and an inverted tet has one negative σ̂. `R = U Vᵀ`.
//!
//! Force `f_a = −R Σ_b K0_ab (Rᵀ x_b − X_b)`, stiffness `K_ab ≈ R K0_ab Rᵀ`.
//! Because `RᵀF = V Σ̂ Vᵀ` is symmetric, this force is exactly minus the
//! gradient of the corotated energy
//! `Ψ = V [μ Σ_i (σ̂_i − 1)² + (λ/2)(Σ_i σ̂_i − 3)²]`,
//! which the tests check by finite differences.
//!
//! Tangent stiffness: the exact Hessian of Ψ, projected to be positive
//! semi-definite through its analytic eigensystem (Smith, de Goes & Kim
//! 2019). With `Ψ_i = ∂Ψ/∂σ̂_i = 2μ(σ̂_i − 1) + λ(Σσ̂ − 3)`, the Hessian in F
//! has three *scaling* modes `U diag(z) Vᵀ` governed by `A = 2μI + λ11ᵀ`
//! (positive definite), and per pair (i, j) a *flip* mode
//! `U (e_i e_jᵀ + e_j e_iᵀ) Vᵀ/√2` with eigenvalue
//! `(Ψ_i − Ψ_j)/(σ̂_i − σ̂_j) = 2μ` and a *twist* mode
//! `U (e_i e_jᵀ − e_j e_iᵀ) Vᵀ/√2` with eigenvalue `(Ψ_i + Ψ_j)/(σ̂_i + σ̂_j)`,
//! which turns negative under compression. [`TangentKind::Exact`] keeps it
//! (Newton then converges quadratically, while the assembled matrix stays
//! positive definite as long as the compressed tets are held by the rest);
//! [`TangentKind::Projected`] clamps it at zero, which is always positive
//! semi-definite but converges only linearly under compression. Near
//! `σ̂_i + σ̂_j = 0` (inverted tets) both clamp, as the exact value blows up. With
//! `c_a = Vᵀ g_a`, the block `K_ab = V · U M_ab Uᵀ` where `M_ab` collects
//! the modes in the principal frame (see [`Tangent::block`]). At rest it
//! equals `K0_ab`; compared with the stiffness-warping tangent `R K0 Rᵀ` it
//! keeps Newton's quadratic convergence under large rotations.

use nalgebra::{Matrix3, Vector3};

use super::hyperelastic::{Law, Model, VolumeLimit};
use super::material::{Material, LIMIT_STIFFNESS};
use crate::mesh::Vec3;

/// Precomputed rest data of one tet: 304 bytes, so that the elements of a
/// 25k-tet patch (7 MB) stay in the processor's last-level cache while
/// forces and tangents are evaluated; the rest stiffness blocks
/// ([`RestElement::k0`], 1.2 kB a tet) are computed where they are needed,
/// not stored. The fields every force evaluation reads come first, in
/// declaration order (`repr(C)`).
#[derive(Clone, Debug)]
#[repr(C)]
pub struct RestElement {
    /// `Dm⁻¹`.
    pub dm_inv: Matrix3<f64>,
    /// Rest volume (mm³).
    pub volume: f64,
    /// Shear modulus μ (MPa).
    pub mu: f64,
    /// Lamé λ (MPa).
    pub lambda: f64,
    /// The energy density (corotational linear unless the material says).
    pub model: Model,
    /// The volume ratio below which its volume term stiffens (a
    /// locking-free tet's, [`VolumeLimit`] with stiffness
    /// [`LIMIT_STIFFNESS`]` μ`); zero for none.
    pub limit_ratio: f64,
    /// Shape-function gradients `g_a` (1/mm).
    pub grads: [Vector3<f64>; 4],
    /// Rest positions (mm).
    pub rest: [Vec3; 4],
}

impl RestElement {
    /// Rest data of the positively oriented tet `rest` with `material`.
    pub fn new(rest: [Vec3; 4], material: &Material) -> RestElement {
        let dm = Matrix3::from_columns(&[rest[1] - rest[0], rest[2] - rest[0], rest[3] - rest[0]]);
        let volume = dm.determinant() / 6.0;
        let dm_inv = dm
            .try_inverse()
            .expect("mesh validation rejects degenerate tets");
        let g1 = dm_inv.row(0).transpose();
        let g2 = dm_inv.row(1).transpose();
        let g3 = dm_inv.row(2).transpose();
        let grads = [-(g1 + g2 + g3), g1, g2, g3];
        let (mu, lambda) = (material.mu(), material.element_lambda());
        RestElement {
            dm_inv,
            volume,
            grads,
            rest,
            mu,
            lambda,
            model: material.model,
            limit_ratio: material.element_limit().ratio,
        }
    }

    /// The rest stiffness block `K0_ab` (N/mm) of local vertices `a` and
    /// `b`: linear elasticity with the element's (μ, λ),
    /// `V (λ g_a g_bᵀ + μ g_b g_aᵀ + μ (g_a·g_b) I)`.
    pub fn k0(&self, a: usize, b: usize) -> Matrix3<f64> {
        let (ga, gb) = (&self.grads[a], &self.grads[b]);
        (ga * gb.transpose() * self.lambda
            + gb * ga.transpose() * self.mu
            + Matrix3::identity() * (self.mu * ga.dot(gb)))
            * self.volume
    }

    /// The element's energy density with its Lamé parameters.
    pub fn law(&self) -> Law {
        Law {
            model: self.model,
            mu: self.mu,
            lambda: self.lambda,
            limit: self.limit(),
        }
    }

    /// Its volume limit.
    pub fn limit(&self) -> VolumeLimit {
        if self.limit_ratio > 0.0 {
            VolumeLimit {
                stiffness: LIMIT_STIFFNESS * self.mu,
                ratio: self.limit_ratio,
            }
        } else {
            VolumeLimit::default()
        }
    }

    /// Deformation gradient `F = Σ_a x_a ⊗ g_a`.
    #[inline]
    pub fn deformation_gradient(&self, x: &[Vec3; 4]) -> Matrix3<f64> {
        let ds = Matrix3::from_columns(&[x[1] - x[0], x[2] - x[0], x[3] - x[0]]);
        ds * self.dm_inv
    }

    /// Elastic forces on the four vertices at positions `x`, with rotation
    /// `r` (a law other than the corotational one takes them from `F`, and
    /// `r` is not used).
    pub fn forces(&self, x: &[Vec3; 4], r: &Matrix3<f64>) -> [Vec3; 4] {
        if self.model != Model::Corotational || self.limit_ratio != 0.0 {
            return self.forces_from(&Corotation::of(&self.deformation_gradient(x)));
        }
        let rt = r.transpose();
        let u: [Vec3; 4] = std::array::from_fn(|b| rt * x[b] - self.rest[b]);
        std::array::from_fn(|a| {
            let mut s = Vec3::zeros();
            for (b, ub) in u.iter().enumerate() {
                s += self.k0(a, b) * ub;
            }
            -(r * s)
        })
    }

    /// The same forces from the rotation data alone, through the first
    /// Piola stress `P = U diag(Ψ_i) Vᵀ` (`Ψ_i = ∂Ψ/∂σ̂_i` per unit rest
    /// volume): `f_a = −V P g_a`. Since `RᵀF = V Σ̂ Vᵀ`, this is
    /// [`RestElement::forces`] to round-off, with 4 small products in place
    /// of 16 blocks of `K0` — the element pass reads 150 bytes of rest data
    /// per tet instead of 1.3 kB.
    #[inline]
    pub fn forces_from(&self, rot: &Corotation) -> [Vec3; 4] {
        let s = rot.sigma;
        let psi = match self.model {
            Model::Corotational if self.limit_ratio == 0.0 => {
                let trace_term = self.lambda * (s.sum() - 3.0);
                s.map(|si| 2.0 * self.mu * (si - 1.0) + trace_term) * self.volume
            }
            _ => self.law_gradient(&s) * self.volume,
        };
        // −V P = −U diag(VΨ) Vᵀ: scale U's columns, then multiply by Vᵀ.
        let mut us = rot.u;
        for k in 0..3 {
            us.column_mut(k).scale_mut(-psi[k]);
        }
        let p = us * rot.v.transpose();
        self.grads.map(|g| p * g)
    }

    /// `Ψ_i` of a law other than the corotational one. Kept out of line (and
    /// cold) so that the corotational path of [`Self::forces_from`], run for
    /// every tet at every Newton iteration, compiles as it would alone.
    #[cold]
    #[inline(never)]
    fn law_gradient(&self, s: &Vector3<f64>) -> Vector3<f64> {
        self.law().gradient(s)
    }

    /// Elastic energy at `x` (N·mm).
    pub fn energy(&self, x: &[Vec3; 4]) -> f64 {
        let sigma = Corotation::of(&self.deformation_gradient(x)).sigma;
        self.volume * self.law().energy(&sigma)
    }
}

/// Per-element data of the projected tangent stiffness (see the module docs).
#[derive(Clone, Copy, Debug)]
pub struct Tangent {
    u: Matrix3<f64>,
    c: [Vector3<f64>; 4],
    /// `V·A`, the scaling-mode Hessian times the rest volume.
    a: Matrix3<f64>,
    /// `V·(λ_twist + λ_flip)/2` and `V·(λ_flip − λ_twist)/2` per pair (1,2), (0,2), (0,1).
    diag: [f64; 3],
    cross: [f64; 3],
}

/// Which element tangent Newton iterations assemble (see the module docs).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TangentKind {
    /// The exact Hessian of the corotated energy (may be indefinite).
    Exact,
    /// The Hessian with negative twist eigenvalues clamped at zero (PSD).
    Projected,
}

/// Twist modes of pairs with `σ̂_i + σ̂_j` below this are clamped even in the
/// exact tangent: their eigenvalue grows without bound as the pair inverts.
const EXACT_TWIST_MIN_SUM: f64 = 0.2;

/// The index pairs (i, j), i < j, in the order of [`Tangent`]'s arrays.
const PAIRS: [(usize, usize); 3] = [(1, 2), (0, 2), (0, 1)];

impl RestElement {
    /// Tangent data at the configuration whose rotation data is `rot`.
    #[inline]
    pub fn tangent(&self, rot: &Corotation, kind: TangentKind) -> Tangent {
        if self.model != Model::Corotational || self.limit_ratio != 0.0 {
            return self.law_tangent(rot, kind);
        }
        let (mu, lambda, vol) = (self.mu, self.lambda, self.volume);
        let s = rot.sigma;
        let trace_term = lambda * (s.sum() - 3.0);
        let psi = s.map(|si| 2.0 * mu * (si - 1.0) + trace_term);
        let a = (Matrix3::identity() * (2.0 * mu) + Matrix3::repeat(lambda)) * vol;
        let modes = PAIRS.map(|(i, j)| {
            let flip = 2.0 * mu;
            let denom = s[i] + s[j];
            let twist = if denom > 1e-8 {
                let exact = (psi[i] + psi[j]) / denom;
                if kind == TangentKind::Exact && denom >= EXACT_TWIST_MIN_SUM {
                    exact
                } else {
                    exact.max(0.0)
                }
            } else {
                0.0
            };
            (flip, twist)
        });
        self.tangent_of_modes(rot, a, modes)
    }

    /// The tangent with scaling-mode Hessian `a` (times the volume) and the
    /// (flip, twist) eigenvalues of each pair of [`PAIRS`].
    fn tangent_of_modes(
        &self,
        rot: &Corotation,
        a: Matrix3<f64>,
        modes: [(f64, f64); 3],
    ) -> Tangent {
        let vol = self.volume;
        let diag = modes.map(|(flip, twist)| vol * 0.5 * (twist + flip));
        let cross = modes.map(|(flip, twist)| vol * 0.5 * (flip - twist));
        let vt = rot.v.transpose();
        Tangent {
            u: rot.u,
            c: self.grads.map(|g| vt * g),
            a,
            diag,
            cross,
        }
    }
}

impl RestElement {
    /// The tangent of a hyperelastic law ([`Law`]) from its eigensystem:
    /// exact, or projected to be positive semi-definite (the scaling Hessian
    /// with its negative eigenvalues clamped, flip and twist eigenvalues
    /// clamped at zero). The Neo-Hookean Hessian is indefinite wherever a
    /// tet is compressed by more than a few percent (its twist eigenvalue
    /// `μ + cσ̂_k` turns negative) or dilated by a fifth (its flip one), and
    /// the Newton loop then falls back to the projection as it does for the
    /// corotational element's twist modes.
    #[cold]
    #[inline(never)]
    fn law_tangent(&self, rot: &Corotation, kind: TangentKind) -> Tangent {
        let (law, vol, s) = (self.law(), self.volume, rot.sigma);
        let project = kind == TangentKind::Projected;
        let clamp = |x: f64| if project { x.max(0.0) } else { x };
        let hessian = law.scaling_hessian(&s);
        let a = if project {
            super::hyperelastic::project_psd(&hessian)
        } else {
            hessian
        } * vol;
        let modes = PAIRS.map(|(i, j)| {
            (
                clamp(law.flip(&s, i, j)),
                law.twist(&s, i, j).map_or(0.0, clamp),
            )
        });
        self.tangent_of_modes(rot, a, modes)
    }
}

/// Slot of block `(a, b)`, `a ≤ b`, among a tet's 10 distinct stiffness
/// blocks ([`Tangent::upper_blocks`]); `(b, a)` is its transpose.
pub const UPPER: [[usize; 4]; 4] = [[0, 1, 2, 3], [1, 4, 5, 6], [2, 5, 7, 8], [3, 6, 8, 9]];

impl Tangent {
    /// The 10 distinct blocks `scale·K_ab`, `a ≤ b`, at the slots of
    /// [`UPPER`] (the tangent is symmetric: `K_ba = K_abᵀ`).
    pub fn upper_blocks(&self, scale: f64) -> [Matrix3<f64>; 10] {
        let mut out = [Matrix3::zeros(); 10];
        for a in 0..4 {
            for b in a..4 {
                out[UPPER[a][b]] = self.block(a, b) * scale;
            }
        }
        out
    }

    /// The 3×3 stiffness block `K_ab` (N/mm).
    pub fn block(&self, a: usize, b: usize) -> Matrix3<f64> {
        let (ca, cb) = (&self.c[a], &self.c[b]);
        let mut m = Matrix3::from_fn(|i, j| ca[i] * self.a[(i, j)] * cb[j]);
        for (k, &(i, j)) in PAIRS.iter().enumerate() {
            m[(i, i)] += self.diag[k] * ca[j] * cb[j];
            m[(j, j)] += self.diag[k] * ca[i] * cb[i];
            m[(i, j)] += self.cross[k] * ca[j] * cb[i];
            m[(j, i)] += self.cross[k] * ca[i] * cb[j];
        }
        self.u * m * self.u.transpose()
    }
}

/// The sign-corrected SVD of a deformation gradient.
#[derive(Clone, Copy, Debug)]
pub struct Corotation {
    /// Rotation `R = U Vᵀ`.
    pub r: Matrix3<f64>,
    /// Left rotation (principal directions in the deformed frame, columns).
    pub u: Matrix3<f64>,
    /// Right rotation (principal directions in the rest frame, columns).
    pub v: Matrix3<f64>,
    /// Sign-corrected singular values σ̂, descending except that an inverted
    /// tet's negative value sits last.
    pub sigma: Vector3<f64>,
}

impl Corotation {
    /// Computes the rotation of `f`. A non-finite `f` (which the solver
    /// guards against) yields the identity.
    ///
    /// `V` and `σ̂²` are the eigenvectors and eigenvalues of `FᵀF` by cyclic
    /// Jacobi rotations (which, unlike a tridiagonal QR, need no special
    /// case for the repeated values of an undeformed tet and stay in
    /// registers); sorted descending, `V` made a rotation. The columns of
    /// `B = F V` are then orthogonal with lengths `σ̂`, and Gram–Schmidt gives
    /// `U`: `u₁ = b₁/|b₁|`, `u₂` from `b₂` without its `u₁` part,
    /// `u₃ = u₁ × u₂`, so `U` is a rotation and `σ̂₃ = u₃·b₃` carries the
    /// sign of `det F` (McAdams et al. 2011 take the same route with QR).
    pub fn of(f: &Matrix3<f64>) -> Corotation {
        Corotation::near(f, &Matrix3::identity())
    }

    /// [`Corotation::of`], with the Jacobi rotations started from the
    /// rotation `guess` (the tet's `V` at the last evaluation): `FᵀF` in
    /// that frame is nearly diagonal, so one or two sweeps finish it where
    /// a cold start takes four to six. The result is the same
    /// decomposition to round-off; `guess` is re-orthonormalised first, so
    /// round-off does not build up over a run.
    pub fn near(f: &Matrix3<f64>, guess: &Matrix3<f64>) -> Corotation {
        if !f.iter().all(|c| c.is_finite()) {
            return Corotation {
                r: Matrix3::identity(),
                u: Matrix3::identity(),
                v: Matrix3::identity(),
                sigma: Vector3::from_fn(|i, _| f[(i, i)]),
            };
        }
        let frame = orthonormal(guess);
        // `FᵀF` in the guessed frame as `GᵀG` with `G = F·frame`; `G` then
        // gives `B = F V = G W` without another product with `F`.
        let g = f * frame;
        let (eigenvalues, mut w) = symmetric_eigen_jacobi(&g.tr_mul(&g));
        // Sort descending.
        let mut order = [0usize, 1, 2];
        order.sort_by(|&i, &j| eigenvalues[j].total_cmp(&eigenvalues[i]));
        if order != [0, 1, 2] {
            let w0 = w;
            for (k, &i) in order.iter().enumerate() {
                w.set_column(k, &w0.column(i));
            }
        }
        // det V = det W, as the frame is a rotation.
        if w.determinant() < 0.0 {
            w.column_mut(2).neg_mut();
        }
        let v = frame * w;
        let b = g * w;
        let tiny = SVD_TINY * f.norm();
        let (b1, b2, b3) = (b.column(0), b.column(1), b.column(2));
        let s1 = b1.norm();
        let u1 = if s1 > tiny {
            b1 * (1.0 / s1)
        } else {
            Vector3::x()
        };
        let b2_perp = b2 - u1 * u1.dot(&b2);
        let n2 = b2_perp.norm();
        let u2 = if n2 > tiny {
            b2_perp * (1.0 / n2)
        } else {
            any_orthogonal(&u1)
        };
        let u3 = u1.cross(&u2);
        let u = Matrix3::from_columns(&[u1, u2, u3]);
        let sigma = Vector3::new(s1, u2.dot(&b2), u3.dot(&b3));
        Corotation {
            r: u * v.transpose(),
            u,
            v,
            sigma,
        }
    }
}

/// Below this fraction of `|F|` a column of `F V` counts as zero (its
/// direction is then any one orthogonal to the columns before it).
const SVD_TINY: f64 = 1e-14;

/// Jacobi sweeps after which the eigen-decomposition stops even if the
/// off-diagonal part is not yet at round-off (it converges quadratically;
/// 3×3 matrices take 3–5 sweeps).
const MAX_JACOBI_SWEEPS: usize = 12;

/// Eigenvalues and eigenvectors (columns) of the symmetric `a`, by cyclic
/// Jacobi rotations until the off-diagonal part is at round-off.
///
/// The matrix lives in plain arrays and each plane's rotation is its own
/// instance of [`jacobi_rotate`], so every index is a constant and the
/// whole solve stays in registers (this is the element pass's inner loop).
fn symmetric_eigen_jacobi(m: &Matrix3<f64>) -> (Vector3<f64>, Matrix3<f64>) {
    // Far from 1 (never so in the element pass), scaled to a largest entry
    // of 1, so that no square below over- or underflows.
    let amax = m.amax();
    if !(amax > 0.0 && amax.is_finite()) {
        return (m.diagonal(), Matrix3::identity());
    }
    let size = if (1e-100..=1e100).contains(&amax) {
        1.0
    } else {
        amax
    };
    let unit = 1.0 / size;
    let mut a: [[f64; 3]; 3] = std::array::from_fn(|i| std::array::from_fn(|j| m[(i, j)] * unit));
    let mut v = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    for _ in 0..MAX_JACOBI_SWEEPS {
        let off = a[0][1].powi(2) + a[0][2].powi(2) + a[1][2].powi(2);
        let diag = a[0][0].powi(2) + a[1][1].powi(2) + a[2][2].powi(2);
        if off <= 1e-32 * diag || off == 0.0 {
            break;
        }
        jacobi_rotate::<0, 1, 2>(&mut a, &mut v);
        jacobi_rotate::<0, 2, 1>(&mut a, &mut v);
        jacobi_rotate::<1, 2, 0>(&mut a, &mut v);
    }
    (
        Vector3::new(a[0][0], a[1][1], a[2][2]) * size,
        Matrix3::from_fn(|i, j| v[i][j]),
    )
}

/// One Jacobi rotation in the (P, Q) plane (R the third index) that zeroes
/// `a[P][Q]`: `a ← Jᵀ a J`, `v ← v J`.
fn jacobi_rotate<const P: usize, const Q: usize, const R: usize>(
    a: &mut [[f64; 3]; 3],
    v: &mut [[f64; 3]; 3],
) {
    let apq = a[P][Q];
    if apq == 0.0 {
        return;
    }
    // With d = a_qq − a_pp, h = 2 a_pq and r = √(d² + h²), the smaller
    // angle φ has tan φ = sgn(d)·h / (|d| + r), cos φ = √((r + |d|)/(2r))
    // and sin φ = sgn(d)·h / √(2r(r + |d|)): two square roots and one
    // division in a row, where tan φ first and cos φ from it take five.
    let d = a[Q][Q] - a[P][P];
    let h = 2.0 * apq;
    let sh = if d >= 0.0 { h } else { -h };
    if h * h < 1e-17 * (d * d) {
        // A tiny angle (the last sweep of a warm start): r = |d| and
        // cos φ = 1 to round-off, tan φ = sin φ.
        let t = sh / (2.0 * d.abs());
        return rotate_by::<P, Q, R>(a, v, (1.0, t, t));
    }
    let r2 = d * d + h * h;
    if r2 <= f64::MIN_POSITIVE {
        // Both below 1e-154: nothing to rotate at the matrix's scale.
        return;
    }
    let r = r2.sqrt();
    let sum = r + d.abs();
    let inv = 1.0 / (2.0 * r * sum).sqrt();
    let c = sum * inv;
    let s = sh * inv;
    let t = sh / sum;
    rotate_by::<P, Q, R>(a, v, (c, s, t));
}

/// Applies the Jacobi rotation with cosine, sine and tangent `(c, s, t)`
/// in the (P, Q) plane.
fn rotate_by<const P: usize, const Q: usize, const R: usize>(
    a: &mut [[f64; 3]; 3],
    v: &mut [[f64; 3]; 3],
    (c, s, t): (f64, f64, f64),
) {
    let apq = a[P][Q];
    a[P][P] -= t * apq;
    a[Q][Q] += t * apq;
    a[P][Q] = 0.0;
    a[Q][P] = 0.0;
    let (arp, arq) = (a[R][P], a[R][Q]);
    a[R][P] = c * arp - s * arq;
    a[P][R] = a[R][P];
    a[R][Q] = s * arp + c * arq;
    a[Q][R] = a[R][Q];
    for row in v.iter_mut() {
        let (vkp, vkq) = (row[P], row[Q]);
        row[P] = c * vkp - s * vkq;
        row[Q] = s * vkp + c * vkq;
    }
}

/// The rotation nearest `m` by Gram–Schmidt on its columns (the third
/// from the first two); the identity when `m` is not near a rotation.
fn orthonormal(m: &Matrix3<f64>) -> Matrix3<f64> {
    let c1 = m.column(0).into_owned();
    let c2 = m.column(1).into_owned();
    let n1 = c1.norm();
    if !(n1 > 0.5 && n1 < 2.0) {
        return Matrix3::identity();
    }
    let e1 = c1 * (1.0 / n1);
    let p2 = c2 - e1 * e1.dot(&c2);
    let n2 = p2.norm();
    if !(n2 > 0.5 && n2 < 2.0) {
        return Matrix3::identity();
    }
    let e2 = p2 * (1.0 / n2);
    Matrix3::from_columns(&[e1, e2, e1.cross(&e2)])
}

/// A unit vector orthogonal to the unit `u`.
fn any_orthogonal(u: &Vector3<f64>) -> Vector3<f64> {
    // Cross with the axis least aligned with u.
    let axis = if u.x.abs() <= u.y.abs() && u.x.abs() <= u.z.abs() {
        Vector3::x()
    } else if u.y.abs() <= u.z.abs() {
        Vector3::y()
    } else {
        Vector3::z()
    };
    u.cross(&axis).normalize()
}

#[cfg(test)]
mod tests;
