//! Strain fields: analytic surface deformations, agreement with the tets'
//! deformation gradients, independence of the UV layout, the raster, and the
//! closed-form 2×2 SVD.

use crate::common;
use crate::common::patch_3k;

use nalgebra::{Matrix2, Matrix3, Rotation3, Vector2};
use proptest::prelude::*;
use skinpatch::mesh::{io, TetMesh, Vec3};
use skinpatch::strain::element::deformation_gradient;
use skinpatch::strain::svd2::rotation;
use skinpatch::strain::{StrainRaster, SurfaceField, Svd2};

/// `x = A p + c` for every node.
fn affine(mesh: &TetMesh, a: &Matrix3<f64>, c: Vec3) -> Vec<Vec3> {
    mesh.positions.iter().map(|p| a * p + c).collect()
}

/// A 3D map whose tangential part (in the rest plane z = 0) is `t2`, with
/// thickness stretch `lz`, then turned rigidly by `spin`.
fn surface_map(t2: &Matrix2<f64>, lz: f64, spin: &Matrix3<f64>) -> Matrix3<f64> {
    let mut a = Matrix3::zeros();
    a.fixed_view_mut::<2, 2>(0, 0).copy_from(t2);
    a[(2, 2)] = lz;
    spin * a
}

/// Angle between two directions, ignoring sign (radians).
fn axis_angle(a: &Vec3, b: &Vec3) -> f64 {
    a.cross(b).norm().atan2(a.dot(b).abs())
}

/// Random UV points inside [0, 1]².
fn sample_points() -> Vec<Vector2<f64>> {
    (0..200)
        .map(|k| {
            let k = k as f64;
            Vector2::new((k * 0.618_034).fract(), (k * 0.414_214 + 0.1).fract())
        })
        .collect()
}

/// Checks r_s, r_t (1e-9) and the rest-world s axis (1e-6 rad) at every
/// vertex and at sample points for the map with tangential part `t2`.
fn check_analytic(t2: Matrix2<f64>, spin: Matrix3<f64>, rs: f64, rt: f64, s_dir: Option<Vec3>) {
    let mesh = patch_3k();
    let x = affine(
        &mesh,
        &surface_map(&t2, 0.9, &spin),
        Vec3::new(0.3, -0.2, 0.1),
    );
    let field = SurfaceField::new(&mesh.top, &mesh.positions, &x);
    assert_eq!(field.degenerate_triangles, 0);
    for v in &field.vertices {
        let s = v.strain();
        assert!(
            (s.rs() - rs).abs() < 1e-9 && (s.rt() - rt).abs() < 1e-9,
            "{:?}",
            s.svd
        );
        if let Some(dir) = s_dir {
            let [axis_s, axis_t] = v.rest_axes();
            assert!(axis_angle(&axis_s, &dir) < 1e-6, "s axis {axis_s} vs {dir}");
            assert!(axis_s.dot(&axis_t).abs() < 1e-9);
        }
    }
    for p in sample_points() {
        let s = field.at(p).expect("inside the patch");
        assert!(
            (s.rs() - rs).abs() < 1e-9 && (s.rt() - rt).abs() < 1e-9,
            "{:?}",
            s.svd
        );
        if let Some(dir) = s_dir {
            // The default layout scales x and y alike (10 × 10 mm), so the
            // UV axis has the world axis's direction.
            let uv = s.s_uv();
            let world = Vec3::new(uv.x, uv.y, 0.0);
            assert!(axis_angle(&world, &dir) < 1e-6, "UV s axis {uv} vs {dir}");
            // Its length is UV per millimetre: 1/10.
            assert!((s.s_matrix.column(0).norm() - 0.1).abs() < 1e-12);
        }
    }
}

#[test]
fn stretch_along_axes_at_an_angle() {
    for (l1, l2, theta) in [(1.25, 0.8, 0.3), (1.1, 1.02, -1.2), (0.9, 0.7, 2.0)] {
        let t2 = rotation(theta) * Matrix2::new(l1, 0.0, 0.0, l2) * rotation(theta).transpose();
        let dir = Vec3::new(theta.cos(), theta.sin(), 0.0);
        check_analytic(t2, Matrix3::identity(), l1, l2, Some(dir));
    }
}

#[test]
fn pure_shear() {
    let g: f64 = 0.3;
    let t2 = Matrix2::new(1.0, g, 0.0, 1.0);
    // Singular values of [1 γ; 0 1]: √(1 + γ²/4) ± γ/2; the s axis (in the
    // rest frame) is at angle atan2(1, −γ/2 + √(1 + γ²/4))… computed as the
    // leading eigenvector of TᵀT.
    let rs = (1.0 + g * g / 4.0).sqrt() + g / 2.0;
    let rt = (1.0 + g * g / 4.0).sqrt() - g / 2.0;
    let ata = t2.transpose() * t2;
    let eig = ata.symmetric_eigen();
    let k = if eig.eigenvalues[0] > eig.eigenvalues[1] {
        0
    } else {
        1
    };
    let e = eig.eigenvectors.column(k);
    check_analytic(
        t2,
        Matrix3::identity(),
        rs,
        rt,
        Some(Vec3::new(e.x, e.y, 0.0)),
    );
}

#[test]
fn rigid_rotation_is_neutral() {
    let spin = Rotation3::from_euler_angles(0.7, -0.4, 1.1).into_inner();
    let mesh = patch_3k();
    let x = affine(&mesh, &spin, Vec3::new(1.0, 2.0, 3.0));
    let field = SurfaceField::new(&mesh.top, &mesh.positions, &x);
    for v in &field.vertices {
        let s = v.strain();
        assert!((s.rs() - 1.0).abs() < 1e-9 && (s.rt() - 1.0).abs() < 1e-9);
    }
}

#[test]
fn stretch_then_rotation_out_of_plane() {
    // A composition: stretch at 0.5 rad, then a rigid turn that tilts the
    // surface. The stretches stay, and the deformed axis is the rotated one.
    let (l1, l2, theta) = (1.3, 0.85, 0.5);
    let t2 = rotation(theta) * Matrix2::new(l1, 0.0, 0.0, l2) * rotation(theta).transpose();
    let spin = Rotation3::from_euler_angles(0.4, 0.3, -0.6).into_inner();
    let dir = Vec3::new(theta.cos(), theta.sin(), 0.0);
    check_analytic(t2, spin, l1, l2, Some(dir));
    let mesh = patch_3k();
    let x = affine(&mesh, &surface_map(&t2, 1.0, &spin), Vec3::zeros());
    let field = SurfaceField::new(&mesh.top, &mesh.positions, &x);
    for v in &field.vertices {
        let [s_def, _] = v.deformed_axes();
        assert!(axis_angle(&s_def, &(spin * dir)) < 1e-6, "{s_def}");
    }
}

/// A smooth non-affine deformation of the whole patch.
fn wavy(mesh: &TetMesh) -> Vec<Vec3> {
    mesh.positions
        .iter()
        .map(|p| {
            p + Vec3::new(
                0.15 * (0.7 * p.y + 0.3 * p.z).sin() + 0.05 * p.x,
                0.1 * (0.5 * p.x).cos() * (1.0 + 0.2 * p.z),
                0.2 * (0.4 * p.x + 0.6 * p.y).sin(),
            )
        })
        .collect()
}

#[test]
fn face_strain_is_the_tangential_part_of_the_owning_tets_gradient() {
    let mesh = patch_3k();
    let x = wavy(&mesh);
    let field = SurfaceField::new(&mesh.top, &mesh.positions, &x);
    for (k, ts) in field.triangles.iter().enumerate() {
        let f = deformation_gradient(&mesh.positions, &x, &mesh.tets[mesh.top.face_tet[k]]);
        let expected = ts.r_deformed * f * ts.r.transpose();
        assert!(
            (ts.t - expected).norm() < 1e-12 * expected.norm(),
            "triangle {k}: {} vs {expected}",
            ts.t
        );
    }
}

#[test]
fn uv_layout_rotation_and_scale_leave_the_strain_unchanged() {
    let mesh = patch_3k();
    let x = wavy(&mesh);
    let field = SurfaceField::new(&mesh.top, &mesh.positions, &x);
    let (phi, scale) = (0.9, 2.5);
    let mut turned = mesh.top.clone();
    for w in &mut turned.uvs {
        let p = rotation(phi) * Vector2::new(w[0], w[1]) * scale + Vector2::new(0.3, -0.7);
        *w = [p.x, p.y];
    }
    let other = SurfaceField::new(&turned, &mesh.positions, &x);
    for (a, b) in field.vertices.iter().zip(&other.vertices) {
        let (sa, sb) = (a.strain(), b.strain());
        assert!((sa.rs() - sb.rs()).abs() < 1e-12 && (sa.rt() - sb.rt()).abs() < 1e-12);
        if sa.rs() - sa.rt() > 1e-6 {
            let ([wa, _], [wb, _]) = (a.rest_axes(), b.rest_axes());
            assert!(axis_angle(&wa, &wb) < 1e-9, "{wa} vs {wb}");
            let ([da, _], [db, _]) = (a.deformed_axes(), b.deformed_axes());
            assert!(axis_angle(&da, &db) < 1e-9, "{da} vs {db}");
            // The UV axis turns with the layout.
            let (ua, ub) = (rotation(phi) * sa.s_uv(), sb.s_uv());
            assert!(ua.dot(&ub).abs() > 1.0 - 1e-12, "{ua} vs {ub}");
        }
    }
    // Any affine layout (here a shear) keeps each triangle's stretches.
    let mut sheared = mesh.top.clone();
    for w in &mut sheared.uvs {
        *w = [w[0] + 0.4 * w[1], 0.7 * w[1]];
    }
    let third = SurfaceField::new(&sheared, &mesh.positions, &x);
    for (a, b) in field.triangles.iter().zip(&third.triangles) {
        let (sa, sb) = (Svd2::of(&a.t), Svd2::of(&b.t));
        assert!((sa.rs - sb.rs).abs() < 1e-12 && (sa.rt - sb.rt).abs() < 1e-12);
    }
}

#[test]
fn raster_matches_point_evaluation_and_marks_the_outside() {
    let mesh = patch_3k();
    let x = wavy(&mesh);
    // The surface covers u, v ∈ [0, 0.6]² of this layout.
    let mut top = mesh.top.clone();
    for w in &mut top.uvs {
        *w = [0.6 * w[0], 0.6 * w[1]];
    }
    let field = SurfaceField::new(&top, &mesh.positions, &x);
    // 100 rows: bands of rows drawn in parallel meet inside the surface.
    for (w, h) in [(37, 23), (64, 64), (1, 1), (50, 100)] {
        let raster = StrainRaster::new(&field, w, h);
        let mut inside = 0;
        for j in 0..h {
            for i in 0..w {
                let uv = raster.texel_uv(i, j);
                let idx = raster.index(i, j);
                let expect_inside = uv.x <= 0.6 && uv.y <= 0.6;
                assert_eq!(
                    raster.inside[idx], expect_inside,
                    "texel ({i}, {j}) at {uv}"
                );
                if expect_inside {
                    let s = field.at(uv).unwrap();
                    assert!((raster.t[idx] - s.t).norm() < 1e-12, "texel ({i}, {j})");
                    assert!((raster.uv_frame[idx] - s.uv_frame).norm() < 1e-12);
                    inside += 1;
                } else {
                    assert_eq!(raster.t[idx], Matrix2::zeros());
                }
            }
        }
        assert!(w * h == 1 || inside > 0);
    }
}

/// The dilation equals its definition, texel by texel: each outside texel
/// within the window of an inside one copies the nearest (ties to the first
/// in row-major window order); the others stay outside.
#[test]
fn dilation_copies_the_nearest_inside_texel() {
    let mesh = patch_3k();
    let mut top = mesh.top.clone();
    for w in &mut top.uvs {
        *w = [0.2 + 0.5 * w[0], 0.3 + 0.4 * w[1]];
    }
    let field = SurfaceField::new(&top, &mesh.positions, &wavy(&mesh));
    let (w, h) = (70, 90);
    let raster = StrainRaster::new(&field, w, h);
    for radius in [1, 4, 7] {
        let dilated = raster.clone().dilated(radius);
        let r = radius as isize;
        let mut filled = 0;
        for j in 0..h as isize {
            for i in 0..w as isize {
                let idx = (j * w as isize + i) as usize;
                let mut best: Option<(isize, usize)> = None;
                if !raster.inside[idx] {
                    for dj in -r..=r {
                        for di in -r..=r {
                            let (x, y) = (i + di, j + dj);
                            if x < 0 || y < 0 || x >= w as isize || y >= h as isize {
                                continue;
                            }
                            let k = (y * w as isize + x) as usize;
                            let d2 = di * di + dj * dj;
                            if raster.inside[k] && best.is_none_or(|b| d2 < b.0) {
                                best = Some((d2, k));
                            }
                        }
                    }
                }
                let source = match best {
                    Some((_, k)) => {
                        filled += 1;
                        k
                    }
                    None => idx,
                };
                assert_eq!(
                    dilated.inside[idx], raster.inside[source],
                    "({i}, {j}) r {radius}"
                );
                assert_eq!(dilated.t[idx], raster.t[source], "({i}, {j}) r {radius}");
                assert_eq!(dilated.uv_frame[idx], raster.uv_frame[source]);
            }
        }
        assert!(filled > 0, "radius {radius} fills some texels");
    }
}

#[test]
fn degenerate_triangles_are_left_out() {
    let mesh = patch_3k();
    let mut x = mesh.positions.clone();
    // Collapse one top triangle onto a point.
    let tri = mesh.top.triangles[10];
    let target = x[mesh.top.vertices[tri[0]]];
    for s in tri {
        x[mesh.top.vertices[s]] = target;
    }
    let field = SurfaceField::new(&mesh.top, &mesh.positions, &x);
    assert!(field.degenerate_triangles >= 1);
    for v in &field.vertices {
        let s = v.strain();
        assert!(s.rs().is_finite() && s.rt().is_finite());
    }
}

proptest! {
    /// The closed-form SVD reconstructs T, orders and signs its values like
    /// the reference SVD, and keeps U, V rotations — including near-equal
    /// values, folded maps and rank-deficient ones.
    #[test]
    fn closed_form_svd_matches_the_reference(
        a in -2.0f64..2.0, b in -2.0f64..2.0, c in -2.0f64..2.0, d in -2.0f64..2.0,
        kind in 0usize..4,
    ) {
        let t = match kind {
            0 => Matrix2::new(a, b, c, d),
            // A scaled rotation nudged: near-equal singular values.
            1 => rotation(a) * (1.0 + b.abs()) + Matrix2::new(1e-9 * c, 0.0, 0.0, 1e-9 * d),
            // Rank one.
            2 => Matrix2::new(a, b, a * c, b * c),
            // Folded: a reflection composed with a stretch.
            _ => rotation(a) * Matrix2::new(1.0 + b.abs(), 0.0, 0.0, -(0.1 + c.abs())),
        };
        let svd = Svd2::of(&t);
        let scale = t.norm().max(1e-300);
        prop_assert!((svd.matrix() - t).norm() <= 1e-12 * scale.max(1.0));
        prop_assert!(svd.rs >= svd.rt.abs() - 1e-15);
        let reference = t.singular_values();
        let (big, small) = (reference.max(), reference.min());
        prop_assert!((svd.rs - big).abs() <= 1e-12 * scale.max(1.0));
        prop_assert!((svd.rt.abs() - small).abs() <= 1e-12 * scale.max(1.0));
        // r_t carries the sign of det T.
        let det = t.determinant();
        if det.abs() > 1e-12 * scale * scale {
            prop_assert_eq!(svd.folded(), det < 0.0);
        }
        prop_assert!((svd.u().determinant() - 1.0).abs() < 1e-12);
        prop_assert!((svd.v().determinant() - 1.0).abs() < 1e-12);
    }
}

/// Hertz consistency: a frictionless sphere (R = 2 mm) pressed δ = 0.1 mm
/// into the hertz block (E = 100 kPa, ν = 0.3). Outside the contact circle
/// linear theory gives a surface in in-plane pure shear with hoop strain
/// u_r/r = −(1+ν)(1−2ν)·p0·a²/(3E·r²), a = √(Rδ), p0 = 2E·a/(π(1−ν²)R).
/// The hoop stretch is r_t: r_t − 1 within 20% of that at r = 1.25a, 1.5a
/// and 2a (mean over 16 directions, each direction within 30%), t axis
/// tangential; r_s > 1 with the s axis radial.
#[test]
fn hertz_surface_strain_outside_the_contact() {
    let (summary, dir) = common::run_fixture("hertz.toml", |t| {
        t.replace(
            "[[0.0, 0.0, 0.0, 2.0], [1.0, 0.0, 0.0, 1.8]]",
            "[[0.0, 0.0, 0.0, 2.0], [1.0, 0.0, 0.0, 1.9]]",
        )
        .replace("frame_rate_hz = 4.0", "frame_rate_hz = 2.0")
        .replace("frames_vtu = false", "frames_vtu = true")
    });
    assert_eq!(summary.frames.len(), 3);
    let mesh = io::read_tetgen(&common::root().join("meshes/hertz_block")).unwrap();
    let frame = io::read_vtu(&dir.path().join("frames/frame_0002.vtu")).unwrap();
    let field = SurfaceField::new(&mesh.top, &mesh.positions, &frame.points);
    let (e, nu, r_sphere, delta): (f64, f64, f64, f64) = (0.1, 0.3, 2.0, 0.1);
    let a = (r_sphere * delta).sqrt();
    let p0 = 2.0 * e * a / (std::f64::consts::PI * (1.0 - nu * nu) * r_sphere);
    let (lo, hi) = mesh.bounds();
    let mut report = String::new();
    for k in [1.25, 1.5, 2.0] {
        let r = k * a;
        let hoop = -(1.0 + nu) * (1.0 - 2.0 * nu) * p0 * a * a / (3.0 * e * r * r);
        let (mut sum_t, mut sum_s) = (0.0, 0.0);
        let n = 16;
        for j in 0..n {
            let phi = std::f64::consts::TAU * j as f64 / n as f64;
            let radial = Vec3::new(phi.cos(), phi.sin(), 0.0);
            let p = radial * r;
            let uv = Vector2::new((p.x - lo.x) / (hi.x - lo.x), (p.y - lo.y) / (hi.y - lo.y));
            let s = field.at(uv).unwrap();
            let (rs, rt) = (s.rs(), s.rt());
            assert!(
                (rt - 1.0) / hoop > 0.7 && (rt - 1.0) / hoop < 1.3,
                "r = {k}a, φ = {phi:.2}: r_t − 1 = {:.4e} vs {hoop:.4e}",
                rt - 1.0
            );
            assert!(rs > 1.0, "r = {k}a, φ = {phi:.2}: r_s = {rs}");
            // Axes in the rest world frame: the block's UVs are axis-aligned
            // and the x and y scales are equal, so UV directions are world ones.
            let (su, tu) = (s.s_uv(), s.t_uv());
            let s_world = Vec3::new(su.x, su.y, 0.0);
            let t_world = Vec3::new(tu.x, tu.y, 0.0);
            let hoop_dir = Vec3::new(-phi.sin(), phi.cos(), 0.0);
            assert!(
                axis_angle(&s_world, &radial) < 0.1,
                "s axis {s_world} at φ = {phi:.2}"
            );
            assert!(
                axis_angle(&t_world, &hoop_dir) < 0.1,
                "t axis {t_world} at φ = {phi:.2}"
            );
            sum_t += rt - 1.0;
            sum_s += rs - 1.0;
        }
        let (mean_t, mean_s) = (sum_t / n as f64, sum_s / n as f64);
        report += &format!(
            "r = {k:.2}a: r_t − 1 = {mean_t:.4e} vs {hoop:.4e} ({:+.1}%), r_s − 1 = {mean_s:.4e} vs linear {:.4e}\n",
            100.0 * (mean_t / hoop - 1.0),
            -hoop
        );
        assert!((mean_t / hoop - 1.0).abs() < 0.2, "{report}");
    }
    println!("{report}");
}

/// r_s and r_t after the press phase of tests/fixtures/press_small.toml
/// (sphere R = 1.5 mm, 0.5 mm deep, μ = 0.8) at fixed surface points on
/// patch_3k, patch_25k and a generated ~80k-tet patch, outside the contact
/// patch (radius ≈ 1 mm). The differences between successive meshes shrink:
/// the field converges under refinement. (Under a sticking probe the field
/// also depends on when each node was caught — on the load steps — and
/// does not converge with the mesh alone; docs/VERIFICATION.md.)
#[test]
fn surface_strain_converges_under_refinement() {
    let generated_80k = {
        let text = std::fs::read_to_string(common::root().join("benches/press_80k.toml")).unwrap();
        let start = text.find("[mesh]").unwrap();
        let end = text.find("[material.dermis]").unwrap();
        text[start..end].to_string()
    };
    let points = [
        (1.5, 0.0),
        (0.0, 2.0),
        (-2.5, 0.0),
        (1.5, 1.5),
        (-1.2, -1.2),
        (3.5, -1.0),
    ];
    let mut values = Vec::new();
    for mesh_section in [
        "[mesh]\nfile = \"../../meshes/patch_3k.node\"\n".to_string(),
        "[mesh]\nfile = \"../../meshes/patch_25k.node\"\n".to_string(),
        generated_80k,
    ] {
        let (summary, dir) = common::run_fixture("press_small.toml", |t| {
            t.replace(
                "[mesh]\nfile = \"../../meshes/patch_3k.node\"\n",
                &mesh_section,
            )
            .replace("duration_s = 1.0", "duration_s = 0.5")
                + "\n[output]\nmesh_vtu = false\nmesh_tetgen = true\n"
        });
        let last = summary.frames.len() - 1;
        let mesh = io::read_tetgen(&dir.path().join("mesh")).unwrap();
        let frame = io::read_vtu(&dir.path().join(format!("frames/frame_{last:04}.vtu"))).unwrap();
        let field = SurfaceField::new(&mesh.top, &mesh.positions, &frame.points);
        let (lo, hi) = mesh.bounds();
        let at = |x: f64, y: f64| {
            let uv = Vector2::new((x - lo.x) / (hi.x - lo.x), (y - lo.y) / (hi.y - lo.y));
            let s = field.at(uv).unwrap();
            (s.rs(), s.rt())
        };
        values.push((mesh.num_tets(), points.map(|(x, y)| at(x, y))));
    }
    let mut report = String::new();
    for (tets, v) in &values {
        report += &format!("{tets:>6} tets:");
        for (rs, rt) in v {
            report += &format!("  ({rs:.4}, {rt:.4})");
        }
        report += "\n";
    }
    let difference = |a: &[(f64, f64); 6], b: &[(f64, f64); 6]| {
        a.iter()
            .zip(b)
            .map(|(p, q)| (p.0 - q.0).abs().max((p.1 - q.1).abs()))
            .fold(0.0, f64::max)
    };
    let coarse = difference(&values[0].1, &values[1].1);
    let fine = difference(&values[1].1, &values[2].1);
    report += &format!("max difference 3k→25k {coarse:.4}, 25k→80k {fine:.4}\n");
    println!("{report}");
    assert!(fine < coarse, "{report}");
    assert!(fine < 0.01, "{report}");
}
