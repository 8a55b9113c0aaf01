//! GPU stages against their CPU references, on whatever Vulkan
//! adapter is present — lavapipe in CI, where `SKINPATCH_REQUIRE_GPU=1`
//! makes a missing adapter fail these tests instead of skipping them.
//!
//! Tolerances: maps within 1e-4 of their height range, SVD outputs (r_s,
//! r_t, axes) within 1e-5 relative, α within 1e-5 and σ within 1e-4
//! relative (σ in texels follows the axis through the UV frame), raster
//! values within 1e-5 relative; normals within 1e-5;
//! histograms within a total variation of 2e-3 (texels whose normal lies on
//! a cell border can fall either side in f32 versus f64).

use crate::common;
use crate::common::patch_3k;

use common::context;

use nalgebra::Matrix2;
use skinpatch::gpu::{self, Context};
use skinpatch::mesh::{TetMesh, Vec3};
use skinpatch::micro::fit::{
    candidate_histogram, count_histograms, fit_params, Axis, HistogramSettings, Objective,
};
use skinpatch::micro::normals::normal_map;
use skinpatch::micro::procedural::{generate, SkinParams};
use skinpatch::micro::{
    convolve, DisplacementMap, Edge, KernelField, KernelModel, KernelParams, NormalHistogram,
    PassParams,
};
use skinpatch::strain::raster::DILATE_TEXELS;
use skinpatch::strain::{StrainRaster, SurfaceField, Svd2};

/// A small deterministic generator (xorshift64*), uniform in [lo, hi).
struct Rng(u64);

impl Rng {
    fn next(&mut self, lo: f64, hi: f64) -> f64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        let x = self.0.wrapping_mul(0x2545_f491_4f6c_dd1d) >> 11;
        lo + (hi - lo) * (x as f64 / (1u64 << 53) as f64)
    }
}

/// A smooth, strongly non-uniform deformation of the patch: stretch on one
/// side, compression on the other, shear and a dimple.
fn deformed(mesh: &TetMesh) -> Vec<Vec3> {
    mesh.positions
        .iter()
        .map(|p| {
            p + Vec3::new(
                0.08 * p.x + 0.35 * (0.6 * p.x).sin() + 0.05 * p.y,
                -0.06 * p.y + 0.2 * (0.5 * p.x + 0.3 * p.y).cos(),
                0.3 * (-(p.x * p.x + p.y * p.y) / 4.0).exp(),
            )
        })
        .collect()
}

/// A skin map tiled to `width × height` (the generator makes square,
/// tileable maps).
fn skin_map(width: usize, height: usize, edge: Edge) -> DisplacementMap {
    let tile = generate(&SkinParams {
        size_px: 256,
        extent_mm: 1.28,
        seed: 11,
        groove_spacing_um: 150.0,
        ..SkinParams::default()
    })
    .unwrap();
    let mut map = DisplacementMap::from_fn(width, height, tile.texel_um, edge, |i, j| {
        tile.data[(j % 256) * 256 + i % 256]
    });
    map.height_unit_um = tile.height_unit_um;
    map
}

/// Every shader module as compiled: the compute stages', the renderer's and
/// the viewer's lists chained.
fn all_shader_sources() -> Vec<(&'static str, String)> {
    let mut sources = gpu::shader_sources();
    sources.extend(skinpatch::render::shader_sources());
    #[cfg(feature = "viewer")]
    sources.extend(skinpatch::viewer::shader_sources());
    sources
}

#[test]
fn every_shader_validates_with_naga() {
    for (name, source) in all_shader_sources() {
        let module = naga::front::wgsl::parse_str(&source)
            .unwrap_or_else(|e| panic!("{name}: {}", e.emit_to_string(&source)));
        naga::valid::Validator::new(
            naga::valid::ValidationFlags::all(),
            naga::valid::Capabilities::empty(),
        )
        .validate(&module)
        .unwrap_or_else(|e| panic!("{name}: {e:?}"));
    }
}

/// No shader file escapes validation: each file under `shaders/` is a
/// listed module or part of one (a file prepended to others, such as
/// `map.wgsl`).
#[test]
fn every_shader_file_is_in_a_validated_module() {
    let sources = all_shader_sources();
    let mut files = 0;
    for entry in std::fs::read_dir(common::root().join("shaders")).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_none_or(|e| e != "wgsl") {
            continue;
        }
        files += 1;
        let name = path.file_name().unwrap().to_str().unwrap();
        let text = std::fs::read_to_string(&path).unwrap();
        #[cfg(not(feature = "viewer"))]
        if name == "present.wgsl" {
            continue;
        }
        assert!(
            sources.iter().any(|(_, s)| s.contains(text.trim())),
            "shaders/{name} is in no validated module"
        );
    }
    assert!(files >= 16, "only {files} shader files found");
    for (name, _) in &sources {
        assert!(
            common::root().join("shaders").join(name).exists(),
            "{name} is listed but is no file of shaders/"
        );
    }
}

#[test]
fn a_named_adapter_that_does_not_exist_is_a_clear_error() {
    let Err(e) = Context::with_adapter(Some("no-such-adapter-xyz")) else {
        panic!("an adapter matched a name no adapter has");
    };
    let text = e.to_string();
    assert!(text.contains("no-such-adapter-xyz"), "{text}");
}

#[test]
fn maps_beyond_the_device_limits_are_refused_up_front() {
    let Some(ctx) = context() else { return };
    let side = ctx.limits.max_texture_dimension_2d as usize;
    let e = ctx.check_map(side + 1, 8, 4).unwrap_err().to_string();
    assert!(e.contains("max_texture_dimension_2d"), "{e}");
    let binding = ctx.limits.max_storage_buffer_binding_size;
    let per_texel = binding / (side * side) as u64 + 1;
    let e = ctx
        .check_map(side, side, per_texel)
        .unwrap_err()
        .to_string();
    assert!(e.contains("max_storage_buffer_binding_size"), "{e}");
    assert!(ctx.check_map(1000, 777, 32).is_ok());
}

#[test]
fn raster_matches_the_cpu_reference() {
    let Some(ctx) = context() else { return };
    let mesh = patch_3k();
    let x = deformed(&mesh);
    // The surface covers u, v ∈ [0, 0.6]²: a third of the texels are outside.
    let mut top = mesh.top.clone();
    for w in &mut top.uvs {
        *w = [0.6 * w[0], 0.6 * w[1]];
    }
    let field = SurfaceField::new(&top, &mesh.positions, &x);
    for (w, h) in [(1000, 777), (37, 23), (64, 64)] {
        let cpu = StrainRaster::new(&field, w, h);
        let gpu = gpu::raster::rasterize(&ctx, &field, w, h).unwrap();
        let mut worst = 0.0f64;
        for k in 0..w * h {
            assert_eq!(gpu.inside[k], cpu.inside[k], "{w}×{h} texel {k}");
            let scale = 1.0 + cpu.t[k].norm();
            worst = worst.max((gpu.t[k] - cpu.t[k]).norm() / scale);
            let scale = cpu.uv_frame[k].norm().max(1e-30);
            if cpu.inside[k] {
                worst = worst.max((gpu.uv_frame[k] - cpu.uv_frame[k]).norm() / scale);
            }
        }
        assert!(worst < 1e-5, "{w}×{h}: worst relative difference {worst:e}");
    }
}

/// A random raster: general, folded, rank-one, near-isotropic and zero `T`;
/// frames of patch-like size; blobs of outside texels (some far from any
/// inside texel, so they stay outside after dilation).
fn random_raster(width: usize, height: usize, rng: &mut Rng) -> StrainRaster {
    let n = width * height;
    let mut raster = StrainRaster::outside(width, height);
    for k in 0..n {
        let (i, j) = ((k % width) as f64, (k / width) as f64);
        let hole = width > 100
            && (((i - 60.0).powi(2) + (j - 50.0).powi(2)).sqrt() < 30.0
                || (i > width as f64 - 20.0 && j < 40.0));
        if hole {
            continue;
        }
        let mut r = || rng.next(-1.0, 1.0);
        let t = match k % 5 {
            0 => Matrix2::new(1.0 + 0.4 * r(), 0.4 * r(), 0.4 * r(), 1.0 + 0.4 * r()),
            1 => Matrix2::new(0.9 + 0.2 * r(), 0.3 * r(), 0.3 * r(), -0.5 - 0.2 * r()),
            2 => {
                let (a, b) = (r(), r());
                Matrix2::new(a, 2.0 * a, b, 2.0 * b)
            }
            3 => {
                let (c, s) = (r().cos(), r().sin());
                Matrix2::new(c, -s, s, c) * (1.0 + 1e-4 * r())
                    + Matrix2::new(1e-6 * r(), 0.0, 0.0, 0.0)
            }
            _ => {
                if k % 35 == 4 {
                    Matrix2::zeros()
                } else {
                    Matrix2::new(
                        0.7 + 0.6 * r().abs(),
                        0.1 * r(),
                        0.1 * r(),
                        0.7 + 0.6 * r().abs(),
                    )
                }
            }
        };
        raster.t[k] = t;
        // UV per millimetre of a 10 × 8 mm patch, slightly sheared.
        raster.uv_frame[k] =
            Matrix2::new(0.1 + 0.01 * r(), 0.01 * r(), 0.01 * r(), 0.125 + 0.01 * r());
        raster.inside[k] = true;
    }
    raster
}

#[test]
fn per_texel_svd_and_kernel_parameters_match_the_cpu_reference() {
    let Some(ctx) = context() else { return };
    let model = KernelModel::forehead();
    let mut rng = Rng(0x5eed_cafe);
    for (w, h) in [(333, 257), (16, 16), (17, 1)] {
        let raster = random_raster(w, h, &mut rng);
        let dilated = raster.clone().dilated(DILATE_TEXELS);
        let map = DisplacementMap::zeros(w, h, 10.0, Edge::Clamp);
        let cpu = KernelField::from_strain(&dilated, &model, &map);
        let gpu = gpu::svd2::kernel_field(&ctx, &raster, &model, DILATE_TEXELS).unwrap();
        let (mut checked_axes, mut identity) = (0, 0);
        for k in 0..w * h {
            let svd = Svd2::of(&dilated.t[k]);
            let [rs, rt] = gpu.stretch[k].map(f64::from);
            let scale = svd.rs.max(1e-30);
            assert!(
                (rs - svd.rs).abs() <= 1e-5 * scale && (rt - svd.rt).abs() <= 1e-5 * scale,
                "texel {k}: ({rs}, {rt}) vs ({}, {})",
                svd.rs,
                svd.rt
            );
            for (g, c) in [
                (&gpu.kernels.s[k], &cpu.s[k]),
                (&gpu.kernels.t[k], &cpu.t[k]),
            ] {
                if *c == PassParams::IDENTITY {
                    identity += 1;
                    assert_eq!(g.alpha, 0.0, "texel {k}");
                    continue;
                }
                assert!(
                    (g.alpha - c.alpha).abs() <= 1e-5,
                    "texel {k}: α {} vs {}",
                    g.alpha,
                    c.alpha
                );
                // Axes are defined up to sign, and not at all where the
                // stretches coincide; near there an f32 axis turns by about
                // ε/(r_s − |r_t|), and σ in texels turns with it through the
                // UV frame's anisotropy. Compare where the gap is ≥ 5%.
                if svd.rs - svd.rt.abs() > 0.05 * svd.rs {
                    assert!(
                        (g.sigma - c.sigma).abs() <= 1e-4 * c.sigma.abs().max(1e-3),
                        "texel {k}: σ {} vs {}",
                        g.sigma,
                        c.sigma
                    );
                    let dot = g.axis[0] * c.axis[0] + g.axis[1] * c.axis[1];
                    assert!(
                        1.0 - dot.abs() < 1e-5,
                        "texel {k}: axis {:?} vs {:?}",
                        g.axis,
                        c.axis
                    );
                    checked_axes += 1;
                }
            }
        }
        assert!(checked_axes > w * h / 3, "{checked_axes} axes checked");
        if w > 100 {
            assert!(identity > 0, "the far part of the holes stays outside");
        }
    }
}

/// Random per-texel passes: unit axes at any angle, α ∈ [−2, 1], σ up to 6
/// texels, some identity texels.
fn random_field(width: usize, height: usize, rng: &mut Rng) -> KernelField {
    let mut pass = |k: usize| {
        if k.is_multiple_of(13) {
            return PassParams::IDENTITY;
        }
        let angle = rng.next(0.0, std::f64::consts::TAU);
        PassParams {
            axis: [angle.cos() as f32, angle.sin() as f32],
            alpha: rng.next(-2.0, 1.0) as f32,
            sigma: rng.next(0.05, 6.0) as f32,
        }
    };
    let n = width * height;
    let s = (0..n).map(&mut pass).collect();
    let t = (0..n).map(&mut pass).collect();
    KernelField {
        width,
        height,
        s,
        t,
    }
}

#[test]
fn convolution_matches_the_cpu_reference_on_odd_sizes_and_both_edges() {
    let Some(ctx) = context() else { return };
    let mut rng = Rng(42);
    for (w, h, edge) in [
        (1000, 777, Edge::Wrap),
        (203, 61, Edge::Clamp),
        (5, 3, Edge::Wrap),
    ] {
        let map = skin_map(w, h, edge);
        let field = random_field(w, h, &mut rng);
        let cpu = convolve(&map, &field);
        let gpu = gpu::convolve::convolve(&ctx, &map, &field).unwrap();
        let d = cpu.max_difference(&gpu);
        eprintln!("convolution {w}×{h} {edge:?}: GPU − CPU ≤ {d:.2e} of the height range");
        assert!(d < 1e-4, "{w}×{h} {edge:?}: {d:e} of the height range");
        assert!(map.max_difference(&cpu) > 1e-2, "the passes change the map");
    }
}

#[test]
fn normals_and_histograms_match_the_cpu_reference() {
    let Some(ctx) = context() else { return };
    for (w, h, edge) in [(1000, 777, Edge::Wrap), (61, 203, Edge::Clamp)] {
        let map = skin_map(w, h, edge);
        let cpu = normal_map(&map);
        let gpu = gpu::normals::normal_map(&ctx, &map).unwrap();
        let worst = cpu
            .iter()
            .zip(&gpu)
            .flat_map(|(a, b)| (0..3).map(move |c| (a[c] - b[c]).abs()))
            .fold(0.0f32, f32::max);
        assert!(worst < 1e-5, "{w}×{h}: normals differ by {worst:e}");
        for stretch in [[1.0, 1.0], [1.3, 1.0], [1.0, 0.8]] {
            let cpu = NormalHistogram::of(&map, 64, 0.5, stretch);
            let gpu = gpu::histogram::histogram(&ctx, &map, 64, 0.5, stretch).unwrap();
            let tv = cpu.distance(&gpu);
            assert!(tv < 2e-3, "{w}×{h} stretch {stretch:?}: TV {tv:e}");
            let occupied = cpu.cells.iter().filter(|&&c| c > 0.0).count();
            assert!(occupied > 50, "a non-trivial histogram ({occupied} cells)");
        }
    }
}

/// The whole-frame case: patch_3k deformed, the forehead model, 1000 ×
/// 777 texels over the 10 × 10 mm patch (10 × 12.9 µm texels).
fn whole_frame_case() -> (TetMesh, SurfaceField, KernelModel, DisplacementMap) {
    let mesh = patch_3k();
    let field = SurfaceField::new(&mesh.top, &mesh.positions, &deformed(&mesh));
    let mut neutral = skin_map(1000, 777, Edge::Clamp);
    neutral.texel_um = 10.0;
    (mesh, field, KernelModel::forehead(), neutral)
}

#[test]
fn one_whole_frame_matches_the_cpu_path() {
    let Some(ctx) = context() else { return };
    let (mesh, field, model, neutral) = whole_frame_case();
    let cpu = skinpatch::micro::convolve::deform(&neutral, &model, &field);
    let mut chain = gpu::micro::GpuMicro::new(ctx, &neutral, &model, DILATE_TEXELS).unwrap();
    for round in 0..2 {
        // The second round reuses the resident buffers.
        let frame = chain.deform(&field, true).unwrap();
        let d = cpu.max_difference(&frame.map);
        eprintln!("whole frame 1000×777, round {round}: GPU − CPU ≤ {d:.2e} of the height range");
        assert!(d < 1e-4, "round {round}: {d:e} of the height range");
        assert!(neutral.max_difference(&cpu) > 0.05, "the frame is deformed");
        let normals = frame.normals.unwrap();
        let reference = normal_map(&cpu);
        let worst = normals
            .iter()
            .zip(&reference)
            .flat_map(|(a, b)| (0..3).map(move |c| (a[c] - b[c]).abs()))
            .fold(0.0f32, f32::max);
        assert!(worst < 1e-3, "round {round}: normals differ by {worst:e}");
    }
    // A neutral surface leaves the map as it is.
    let rest = SurfaceField::new(&mesh.top, &mesh.positions, &mesh.positions);
    let frame = chain.deform(&rest, false).unwrap();
    assert!(neutral.max_difference(&frame.map) < 1e-4);
    assert!(frame.normals.is_none());
}

/// A coarse strain raster (one texel per `step²` map texels, read
/// bilinearly) on the GPU equals its CPU reference, on a map whose sides
/// are not multiples of the step; against the exact raster it differs by
/// what the bilinear read misses where the field's gradient jumps between
/// triangles.
#[test]
fn a_coarse_strain_raster_matches_its_cpu_reference() {
    let Some(ctx) = context() else { return };
    let (_, field, model, neutral) = whole_frame_case();
    let exact = skinpatch::micro::convolve::deform(&neutral, &model, &field);
    let mut chain =
        gpu::micro::GpuMicro::new(ctx.clone(), &neutral, &model, DILATE_TEXELS).unwrap();
    for step in [3, 8, 1] {
        chain.set_raster_step(step);
        assert_eq!(chain.raster_step(), step);
        let cpu = skinpatch::micro::convolve::deform_stepped(&neutral, &model, &field, step);
        let frame = chain.deform(&field, true).unwrap();
        let d = cpu.max_difference(&frame.map);
        let from_exact = cpu.max_difference(&exact);
        eprintln!(
            "raster step {step}: GPU − CPU ≤ {d:.2e}, CPU step {step} − exact ≤ {from_exact:.2e} \
             of the height range"
        );
        assert!(d < 1e-4, "step {step}: {d:e} of the height range");
        let normals = frame.normals.unwrap();
        let worst = normals
            .iter()
            .zip(&normal_map(&cpu))
            .flat_map(|(a, b)| (0..3).map(move |c| (a[c] - b[c]).abs()))
            .fold(0.0f32, f32::max);
        assert!(worst < 1e-3, "step {step}: normals differ by {worst:e}");
        if step == 1 {
            // Back to the exact raster: the same bits as a chain that
            // never changed it.
            let fresh = gpu::micro::GpuMicro::new(ctx.clone(), &neutral, &model, DILATE_TEXELS)
                .unwrap()
                .deform(&field, false)
                .unwrap();
            assert!(fresh.map.data == frame.map.data);
            assert_eq!(from_exact, 0.0);
        } else {
            assert!(
                from_exact > 0.0 && from_exact < 1e-2,
                "step {step}: {from_exact:e}"
            );
        }
    }
}

/// The chain runs its passes only on the tiles the surface can reach, and
/// still gives the CPU's frame on a map larger than the patch (after a UV
/// layout that covered the whole map, so the tiles it leaves must return to
/// the neutral map); incremental frames with tolerance 0 give a whole
/// frame's bits while convolving fewer tiles; a tolerance above the change
/// keeps the last output.
#[test]
fn tiled_and_incremental_frames_match_whole_frames() {
    let Some(ctx) = context() else { return };
    let mesh = patch_3k();
    let model = KernelModel::forehead();
    // The patch on the centre half of the map: 25 µm texels.
    let mut neutral = skin_map(800, 736, Edge::Clamp);
    neutral.texel_um = 25.0;
    let mut top = mesh.top.clone();
    for uv in &mut top.uvs {
        *uv = uv.map(|c| 0.5 + (c - 0.5) / 2.0);
    }
    let field_of = |x: &[Vec3]| SurfaceField::new(&top, &mesh.positions, x);
    let a = deformed(&mesh);
    // B moves only the vertices with x < −3 mm (a local push along x).
    let b: Vec<Vec3> = a
        .iter()
        .zip(&mesh.positions)
        .map(|(p, rest)| p + Vec3::new(0.3 * (-3.0 - rest.x).max(0.0).powi(2), 0.0, 0.0))
        .collect();
    // C changes every vertex far below the tolerance.
    let c: Vec<Vec3> = b.iter().map(|p| p * (1.0 + 1e-7)).collect();
    let (field_a, field_b, field_c) = (field_of(&a), field_of(&b), field_of(&c));
    let whole_map = SurfaceField::new(&mesh.top, &mesh.positions, &a);

    let mut whole = gpu::micro::GpuMicro::new(ctx, &neutral, &model, DILATE_TEXELS).unwrap();
    whole.deform(&whole_map, true).unwrap();
    let frame_a = whole.deform(&field_a, true).unwrap();
    let tiles = whole.last_tiles();
    eprintln!("tiles of frame A: {tiles:?}");
    assert!(
        tiles.pass_s > 0 && 2 * tiles.pass_s < tiles.total,
        "{tiles:?}"
    );
    assert_eq!(tiles.pass_s, tiles.pass_t);
    let cpu = skinpatch::micro::convolve::deform(&neutral, &model, &field_a);
    assert!(neutral.max_difference(&cpu) > 0.05, "the frame is deformed");
    let d = cpu.max_difference(&frame_a.map);
    assert!(d < 1e-4, "GPU − CPU: {d:e} of the height range");
    let reference = normal_map(&cpu);
    let worst = frame_a
        .normals
        .as_ref()
        .unwrap()
        .iter()
        .zip(&reference)
        .flat_map(|(p, q)| (0..3).map(move |k| (p[k] - q[k]).abs()))
        .fold(0.0f32, f32::max);
    assert!(worst < 1e-3, "normals differ by {worst:e}");

    let ctx = context().unwrap();
    let mut incremental = gpu::micro::GpuMicro::new(ctx, &neutral, &model, DILATE_TEXELS).unwrap();
    incremental.set_incremental(Some(0.0));
    incremental.deform(&field_a, true).unwrap();
    let step_b = incremental.deform(&field_b, true).unwrap();
    let fewer = incremental.last_tiles();
    eprintln!("tiles of incremental frame B: {fewer:?}");
    assert!(
        fewer.pass_s > 0 && 2 * fewer.pass_s < tiles.pass_s,
        "{fewer:?}"
    );
    let full_b = whole.deform(&field_b, true).unwrap();
    assert!(
        full_b.map.max_difference(&frame_a.map) > 1e-3,
        "B differs from A"
    );
    assert!(
        step_b.map.data == full_b.map.data,
        "incremental B ≠ whole B"
    );
    assert!(
        step_b.normals == full_b.normals,
        "incremental normals ≠ whole"
    );

    // Tolerance 1e-3: the next frame is whole, then C (a 1e-7 change)
    // convolves nothing and keeps B's output, within 1e-4 of C's own.
    incremental.set_incremental(Some(1e-3));
    incremental.deform(&field_b, true).unwrap();
    let step_c = incremental.deform(&field_c, true).unwrap();
    let none = incremental.last_tiles();
    assert_eq!(
        (none.pass_s, none.pass_t, none.normals),
        (0, 0, 0),
        "{none:?}"
    );
    assert!(step_c.map.data == full_b.map.data);
    assert!(step_c.normals == full_b.normals);
    let full_c = whole.deform(&field_c, false).unwrap();
    let d = full_c.map.max_difference(&step_c.map);
    assert!(d < 1e-4, "kept frame vs C: {d:e} of the height range");

    // With a coarse strain raster (step 8) the tiles reach farther, and an
    // incremental frame B still gives the whole frame's bits.
    for chain in [&mut whole, &mut incremental] {
        chain.set_raster_step(8);
    }
    incremental.set_incremental(Some(0.0));
    whole.deform(&field_a, false).unwrap();
    let coarse_a = whole.last_tiles();
    assert!(
        coarse_a.pass_s > tiles.pass_s && 2 * coarse_a.pass_s < coarse_a.total,
        "{coarse_a:?} vs {tiles:?}"
    );
    incremental.deform(&field_a, true).unwrap();
    let coarse_b = incremental.deform(&field_b, true).unwrap();
    let fewer = incremental.last_tiles();
    assert!(
        fewer.pass_s > 0 && 2 * fewer.pass_s < coarse_a.pass_s,
        "{fewer:?}"
    );
    let whole_b = whole.deform(&field_b, true).unwrap();
    assert!(
        coarse_b.map.data == whole_b.map.data,
        "coarse: incremental B ≠ whole B"
    );
    assert!(coarse_b.normals == whole_b.normals);
    let cpu = skinpatch::micro::convolve::deform_stepped(&neutral, &model, &field_b, 8);
    let d = cpu.max_difference(&whole_b.map);
    assert!(d < 1e-4, "coarse GPU − CPU: {d:e} of the height range");
}

/// A tiled map convolved tile by tile equals the untiled chain within 1e-5
/// of the height range (heights and normals, seams included), on a clamped
/// map with the patch on its centre (tiles beyond the surface's reach keep
/// the neutral map and get no chain) and on a wrapping map the patch covers
/// (every tile works, across the map's edges too).
#[test]
fn tiled_maps_match_the_untiled_chain_across_seams() {
    use skinpatch::gpu::tiled::{TileFrame, TiledMicro};
    use skinpatch::micro::tiled::{crop, TiledMap};
    let Some(ctx) = context() else { return };
    let mesh = patch_3k();
    let model = KernelModel::forehead();
    let dir = tempfile::tempdir().unwrap();
    for (edge, shrink, size, step) in [
        (Edge::Clamp, 3.0, (560, 496), 1),
        (Edge::Wrap, 1.0, (300, 260), 1),
        (Edge::Clamp, 3.0, (560, 496), 4),
        (Edge::Wrap, 1.0, (300, 260), 4),
    ] {
        let mut neutral = skin_map(size.0, size.1, edge);
        neutral.texel_um = 10_000.0 * shrink / size.0 as f64;
        let mut top = mesh.top.clone();
        for uv in &mut top.uvs {
            *uv = uv.map(|c| 0.5 + (c - 0.5) / shrink);
        }
        let field = SurfaceField::new(&top, &mesh.positions, &deformed(&mesh));
        let mut whole =
            gpu::micro::GpuMicro::new(ctx.clone(), &neutral, &model, DILATE_TEXELS).unwrap();
        whole.set_raster_step(step);
        let reference = whole.deform(&field, true).unwrap();
        let normals = reference.normals.unwrap();
        let (lo, hi) = neutral.range();
        let folder = dir.path().join(format!("{edge:?}-{step}"));
        let tiled = TiledMap::write(&folder, &neutral, 128).unwrap();
        let mut chains = TiledMicro::new(ctx.clone(), tiled.clone(), &model, DILATE_TEXELS);
        // A step the tiles (or a wrapping map's size) do not divide is
        // refused by name: the windows would leave the map's raster grid.
        let refused = if edge == Edge::Wrap { 8 } else { 3 };
        let err = chains.set_raster_step(refused).unwrap_err().to_string();
        assert!(
            err.contains("microstructure.strain_raster_step") && err.contains("multiple"),
            "{err}"
        );
        chains.set_raster_step(step).unwrap();
        let (mut worst, mut worst_normal, mut kept, mut seen) = (0.0f32, 0.0f32, 0, 0);
        chains
            .deform(&field, true, |col, row, tile| {
                seen += 1;
                let rect = tiled.tile_rect(col, row);
                let want = crop(&reference.map, rect);
                match tile {
                    TileFrame::Deformed { map, normals: n } => {
                        for (a, b) in map.data.iter().zip(&want.data) {
                            worst = worst.max((a - b).abs() / (hi - lo));
                        }
                        let n_want = skinpatch::micro::tiled::crop_values(&normals, size.0, rect);
                        for (a, b) in n.unwrap().iter().zip(&n_want) {
                            for k in 0..3 {
                                worst_normal = worst_normal.max((a[k] - b[k]).abs());
                            }
                        }
                    }
                    TileFrame::Neutral => {
                        kept += 1;
                        assert!(want == crop(&neutral, rect), "tile ({col}, {row}) moved");
                    }
                }
                Ok(())
            })
            .unwrap();
        eprintln!(
            "{edge:?}, raster step {step}: tiled − untiled ≤ {worst:.1e} of the range, normals \
             ≤ {worst_normal:.1e}; {kept} of {seen} tiles kept, halo {}",
            chains.halo()
        );
        assert!(chains.halo().is_multiple_of(step));
        assert_eq!(seen, tiled.grid().0 * tiled.grid().1);
        assert!(worst <= 1e-5, "{edge:?}: {worst:e}");
        assert!(worst_normal <= 1e-5, "{edge:?}: normals {worst_normal:e}");
        match edge {
            Edge::Clamp => assert!(kept > 0 && kept < seen, "{kept} of {seen}"),
            Edge::Wrap => assert_eq!(kept, 0),
        }
    }
}

/// The GPU counts the CPU's candidate histograms (up to texels on a cell
/// edge, where f32 square roots may round apart) and its search finds the
/// CPU's optimum.
#[test]
fn the_batched_fit_finds_the_cpu_optimum() {
    let Some(ctx) = context() else { return };
    let neutral = {
        let mut m = skin_map(96, 80, Edge::Wrap);
        m.texel_um = 5.0;
        m
    };
    let hist = HistogramSettings {
        bins: 64,
        range: 0.5,
    };
    for (axis, r, alpha, sigma_um) in [(Axis::U, 1.2, 0.6, 20.0), (Axis::V, 0.85, -1.2, 10.0)] {
        let truth = KernelParams { alpha, sigma_um };
        let target = candidate_histogram(&neutral, axis, r, truth, hist);
        let objective = Objective::new(&neutral, &target, axis, r, hist);
        let fitter = gpu::fit::GpuFit::new(&ctx, &objective.base, hist.bins).unwrap();
        let dir = objective.direction(38);
        let alphas = [-2.0, -0.5, 0.0, 0.6, 1.0];
        let cpu = count_histograms(&objective.base, &dir, &alphas, hist.bins, hist.range);
        let gpu = fitter.count(&dir, &alphas, hist.bins, hist.range).unwrap();
        for ((c, g), a) in cpu.iter().zip(&gpu).zip(alphas) {
            let moved: u64 = c.iter().zip(g).map(|(&x, &y)| x.abs_diff(y) as u64).sum();
            assert_eq!(
                g.iter().map(|&v| v as u64).sum::<u64>(),
                objective.base.len() as u64
            );
            assert!(moved <= 4, "α {a}: {moved} counts differ");
        }
        let cpu = fit_params(&neutral, &target, axis, r, hist);
        let gpu = fitter.fit_params(&objective, |_| {}).unwrap();
        assert_eq!(
            (gpu.alpha, gpu.sigma_um),
            (cpu.alpha, cpu.sigma_um),
            "{axis:?} r {r}"
        );
        assert_eq!(gpu.evaluations, cpu.evaluations);
        assert!(
            (gpu.alpha - alpha).abs() < 0.011 && (gpu.sigma_um - sigma_um).abs() <= 0.5,
            "{gpu:?}"
        );
    }
}

/// The slope-moment pyramid on the GPU equals the CPU reference at every
/// level (within 2e-6 of the level's largest moment: the GPU's division may
/// differ in the last bit, the averages are summed in the same order), on
/// a power-of-two map and on one with odd sides.
#[test]
fn moment_pyramid_matches_the_cpu_reference() {
    use skinpatch::micro::moments::MomentPyramid;
    let Some(ctx) = context() else { return };
    for (w, h) in [(256, 256), (203, 61)] {
        let map = skin_map(w, h, Edge::Wrap);
        let normals = normal_map(&map);
        let cpu = MomentPyramid::from_normals(&normals, w, h);
        let gpu = skinpatch::render::moments::moment_pyramid(&ctx, &normals, w, h).unwrap();
        assert_eq!(gpu.levels.len(), cpu.levels.len());
        for (k, (g, c)) in gpu.levels.iter().zip(&cpu.levels).enumerate() {
            assert_eq!((g.width, g.height), (c.width, c.height), "level {k}");
            let scale = c
                .texels
                .iter()
                .flatten()
                .fold(0.0f32, |m, v| m.max(v.abs()));
            let worst = g
                .texels
                .iter()
                .zip(&c.texels)
                .flat_map(|(a, b)| (0..5).map(move |i| (a[i] - b[i]).abs()))
                .fold(0.0f32, f32::max);
            assert!(
                worst <= 2e-6 * scale,
                "{w}×{h} level {k}: {worst:e} of {scale:e}"
            );
        }
        // Not trivially flat: the map has slope variance at the top level.
        let top = cpu.levels.last().unwrap().texels[0];
        assert!(top[2] - top[0] * top[0] > 1e-3, "{top:?}");
    }
}

/// `bench micro`'s per-stage profile: every stage timed, the two
/// convolution passes doing the work, and the frame still equal to the CPU
/// reference.
#[test]
fn bench_micro_profiles_every_stage() {
    if context().is_none() {
        return;
    }
    let mesh = patch_3k();
    let model = skinpatch::micro::KernelModel::forehead();
    let layout = skinpatch::bench::MapLayout::FixedPatch;
    let bench =
        skinpatch::bench::bench_micro(&mesh, &model, &[128], 1, (layout, 1), |_| {}).unwrap();
    let row = &bench.rows[0];
    let times = row.stages.expect("a GPU row has its stages");
    let stages = times.wall_ms;
    println!("stages (ms): {times:?}");
    assert!(
        stages.iter().all(|t| t.is_finite() && *t >= 0.0),
        "{stages:?}"
    );
    // Raster, pass s, pass t and normals each submit real work.
    assert!(stages[1..5].iter().all(|&t| t > 0.0), "{stages:?}");
    // With timestamp queries, each shader stage has a GPU time within its
    // wall time (which adds the submission and the wait); the transfers
    // have none.
    let ctx = context().unwrap();
    let timestamps =
        wgpu::Features::TIMESTAMP_QUERY | wgpu::Features::TIMESTAMP_QUERY_INSIDE_ENCODERS;
    if ctx.features.contains(timestamps) {
        for (k, stage) in skinpatch::gpu::micro::MicroStage::ALL
            .into_iter()
            .enumerate()
        {
            match times.gpu_ms[k] {
                Some(g) => {
                    assert!(stage.runs_shaders(), "{stage:?}");
                    // Some drivers (lavapipe) write a stage's end stamp
                    // before its last work finishes: 0 is possible.
                    assert!(
                        g >= 0.0 && g <= stages[k] * 1.05 + 0.05,
                        "{stage:?}: {g} vs {}",
                        stages[k]
                    );
                }
                None => assert!(!stage.runs_shaders(), "{stage:?} has no GPU time"),
            }
        }
        let passes = times.gpu_ms[2].unwrap() + times.gpu_ms[3].unwrap();
        assert!(
            passes > 0.0,
            "the convolution passes take GPU time: {times:?}"
        );
    } else {
        assert!(times.gpu_ms.iter().all(Option::is_none));
    }
    assert!(row.max_difference.unwrap() <= 1e-4, "{row:?}");
    // The traffic model: the patch's UVs fill the map, so the passes run on
    // every texel, the raster covers the whole map (its UV area), and the
    // read-back is D′ and its normals.
    use skinpatch::gpu::micro::{
        NORMALS_BYTES_PER_TEXEL, PASS_BYTES_PER_TEXEL, RASTER_BYTES_PER_TEXEL,
    };
    let texels = 128 * 128;
    assert_eq!(row.pass_tile_share, Some(1.0));
    let b = times.bytes;
    assert_eq!(b[2], PASS_BYTES_PER_TEXEL * texels, "{b:?}");
    assert_eq!(b[3], PASS_BYTES_PER_TEXEL * texels, "{b:?}");
    assert_eq!(b[4], NORMALS_BYTES_PER_TEXEL * texels, "{b:?}");
    assert_eq!(b[5], 20 * texels, "{b:?}");
    let raster = b[1] as f64 / (RASTER_BYTES_PER_TEXEL * texels) as f64;
    assert!(
        (0.98..=1.0).contains(&raster),
        "{raster} of the map covered"
    );
    // 40 bytes a vertex and three tile lists of 65 entries.
    assert!(b[0] > 40 * mesh.top.vertices.len() as u64, "{b:?}");
    assert_eq!(times.resident_bytes(), b[1] + b[2] + b[3] + b[4]);
    let gbs = times.gb_per_s(2);
    assert!(gbs > 0.0 && gbs.is_finite(), "{gbs}");
}

#[test]
fn bench_micro_fixed_texel_puts_the_patch_on_a_larger_map() {
    use skinpatch::bench::{bench_micro, MapLayout};
    if context().is_none() {
        return;
    }
    let mesh = patch_3k();
    let model = skinpatch::micro::KernelModel::forehead();
    let (lo, hi) = mesh.bounds();
    // At 256 texels the map is twice the patch's width.
    let texel_um = 2.0 * (hi.x - lo.x) * 1000.0 / 256.0;
    let layout = MapLayout::FixedTexel {
        texel_um,
        cpu_up_to: 256,
        tile: Some(128),
    };
    let bench = bench_micro(&mesh, &model, &[256, 512], 1, (layout, 1), |_| {}).unwrap();
    let (small, large) = (&bench.rows[0], &bench.rows[1]);
    assert!(
        (small.texel_um - texel_um).abs() < 1e-9 * texel_um,
        "{small:?}"
    );
    assert!(
        (large.texel_um - texel_um).abs() < 1e-9 * texel_um,
        "{large:?}"
    );
    assert!(small.max_difference.unwrap() <= 1e-4, "{small:?}");
    // Beyond cpu_up_to only the GPU runs.
    assert!(large.cpu_ms.is_none() && large.max_difference.is_none());
    assert!(large.gpu_ms.is_some() && large.stages.is_some());
    // The patch covers a quarter of the large map's side: the passes ran on
    // a part of its tiles, and its tiled form convolves a part of its tiles
    // and agrees with the untiled chain.
    assert!(large.pass_tile_share.unwrap() < 0.5, "{large:?}");
    // Its traffic follows: the passes move bytes for under half the map,
    // the raster for a sixteenth of it (the patch's UV area: a quarter of
    // the side).
    let b = large.stages.unwrap().bytes;
    let per_pass = skinpatch::gpu::micro::PASS_BYTES_PER_TEXEL * 512 * 512;
    assert!(b[2] > 0 && b[2] < per_pass / 2, "{b:?}");
    let raster = b[1] as f64 / (skinpatch::gpu::micro::RASTER_BYTES_PER_TEXEL * 512 * 512) as f64;
    assert!(
        (raster - 1.0 / 16.0).abs() < 1e-3,
        "{raster} of the map covered"
    );
    let tiled = large.tiled.as_ref().unwrap();
    assert_eq!(tiled.total, 16, "{tiled:?}");
    assert!(tiled.active > 0 && tiled.active < tiled.total, "{tiled:?}");
    assert!(tiled.max_difference.unwrap() <= 1e-5, "{tiled:?}");
    // A map smaller than the patch at that texel size is refused.
    let err = bench_micro(&mesh, &model, &[64], 1, (layout, 1), |_| {}).unwrap_err();
    assert!(err.to_string().contains("--texel-um"), "{err}");
}
