// The final camera pass (seed 001 §2.8): the skin surface with diffused
// light from the six blurred irradiance textures, pre/post-scatter albedo,
// energy conservation and two-lobe Kelemen/Szirmay-Kalos specular from the
// microstructure normals; plus the cut sides of the patch and the probe.
// Rust side: src/render/skin.rs. Prepended: lighting.wgsl, overlay.wgsl.

@group(1) @binding(0) var blur0: texture_2d<f32>;
@group(1) @binding(1) var blur1: texture_2d<f32>;
@group(1) @binding(2) var blur2: texture_2d<f32>;
@group(1) @binding(3) var blur3: texture_2d<f32>;
@group(1) @binding(4) var blur4: texture_2d<f32>;
@group(1) @binding(5) var blur5: texture_2d<f32>;
@group(1) @binding(6) var transmitted: texture_2d<f32>;
// Tangent-space normals of the displacement map (static or deformed).
@group(1) @binding(7) var micro_normals: texture_2d<f32>;
// Shadow factor of light k in component k, in texture space.
@group(1) @binding(8) var shadow_factors: texture_2d<f32>;
// Slope moments of the same normals with every mip level (moments.wgsl):
// (x, y, x^2, y^2) and x y.
@group(1) @binding(9) var moments_a: texture_2d<f32>;
@group(1) @binding(10) var moments_b: texture_2d<f32>;
// Trilinear, wrapping; used only when globals.options.y == 1 (the adapter
// filters f32 textures).
@group(1) @binding(11) var moments_sampler: sampler;

// Most taps per footprint axis (footprint).
const MAX_TAPS: i32 = 4;
// Footprint width (texels) one tap covers before another is added.
const TAP_TEXELS: f32 = 1.0;
// log2(sqrt(3)): the level shift that matches a bilinear tap's spread to
// its box footprint (footprint).
const LOD_BIAS: f32 = 0.7925;

// Mirrors `MeshVertex` in src/render/scene.rs.
struct MeshVertex {
    @location(0) position: vec4<f32>,
    @location(1) normal: vec4<f32>,
};

struct SurfaceVaryings {
    @builtin(position) clip: vec4<f32>,
    @location(0) world: vec3<f32>,
    @location(1) normal: vec3<f32>,
    @location(2) tangent: vec3<f32>,
    @location(3) uv: vec2<f32>,
    @location(4) strain: vec4<f32>,
};

struct MeshVaryings {
    @builtin(position) clip: vec4<f32>,
    @location(0) world: vec3<f32>,
    @location(1) normal: vec3<f32>,
};

@vertex
fn vs_surface(v: SurfaceVertex) -> SurfaceVaryings {
    var out: SurfaceVaryings;
    out.clip = globals.view_proj * vec4<f32>(v.position.xyz, 1.0);
    out.world = v.position.xyz;
    out.normal = v.normal.xyz;
    out.tangent = v.tangent.xyz;
    out.uv = v.uv.xy;
    out.strain = v.strain;
    return out;
}

@vertex
fn vs_mesh(v: MeshVertex) -> MeshVaryings {
    var out: MeshVaryings;
    out.clip = globals.view_proj * vec4<f32>(v.position.xyz, 1.0);
    out.world = v.position.xyz;
    out.normal = v.normal.xyz;
    return out;
}

fn view_dir(p: vec3<f32>) -> vec3<f32> {
    if (globals.eye.w == 1.0) {
        return normalize(globals.eye.xyz - p);
    }
    return -globals.forward.xyz;
}

// Bilinear, wrapped lookup of the microstructure normal at uv.
fn micro_normal(uv: vec2<f32>) -> vec3<f32> {
    let size = vec2<i32>(textureDimensions(micro_normals));
    let x = uv * vec2<f32>(size) - 0.5;
    let base = vec2<i32>(floor(x));
    let f = x - floor(x);
    var sum = vec3<f32>(0.0);
    for (var j = 0; j < 2; j++) {
        for (var i = 0; i < 2; i++) {
            let t = ((base + vec2<i32>(i, j)) % size + size) % size;
            let w = select(1.0 - f.x, f.x, i == 1) * select(1.0 - f.y, f.y, j == 1);
            sum += w * textureLoad(micro_normals, t, 0).xyz;
        }
    }
    return normalize(sum);
}

struct SlopeMoments {
    // Means of x, y, x^2, y^2.
    a: vec4<f32>,
    // Mean of x y.
    b: f32,
};

// Bilinear, wrapped lookup of the slope moments at level `level`.
fn moments_bilinear(uv: vec2<f32>, level: i32) -> SlopeMoments {
    let size = vec2<i32>(textureDimensions(moments_a, level));
    let x = uv * vec2<f32>(size) - 0.5;
    let base = vec2<i32>(floor(x));
    let f = x - floor(x);
    var out = SlopeMoments(vec4<f32>(0.0), 0.0);
    for (var j = 0; j < 2; j++) {
        for (var i = 0; i < 2; i++) {
            let t = ((base + vec2<i32>(i, j)) % size + size) % size;
            let w = select(1.0 - f.x, f.x, i == 1) * select(1.0 - f.y, f.y, j == 1);
            out.a += w * textureLoad(moments_a, t, level);
            out.b += w * textureLoad(moments_b, t, level).x;
        }
    }
    return out;
}

// Trilinear moments at `lod`: by the sampler where it filters f32, else
// the same filter by loads.
fn moments_trilinear(uv: vec2<f32>, lod: f32) -> SlopeMoments {
    if (globals.options.y == 1u) {
        return SlopeMoments(
            textureSampleLevel(moments_a, moments_sampler, uv, lod),
            textureSampleLevel(moments_b, moments_sampler, uv, lod).x,
        );
    }
    let top = i32(textureNumLevels(moments_a)) - 1;
    let l0 = min(i32(floor(lod)), top);
    let l1 = min(l0 + 1, top);
    let t = lod - f32(l0);
    let m0 = moments_bilinear(uv, l0);
    let m1 = moments_bilinear(uv, l1);
    return SlopeMoments(mix(m0.a, m1.a, t), mix(m0.b, m1.b, t));
}

// Mean slope and covariance (xx, yy, xy) of filtered moments.
struct SlopeGaussian {
    mean: vec2<f32>,
    cov: vec3<f32>,
};

fn gaussian_of(m: SlopeMoments) -> SlopeGaussian {
    let mean = m.a.xy;
    let cov = vec3<f32>(
        max(m.a.z - mean.x * mean.x, 0.0),
        max(m.a.w - mean.y * mean.y, 0.0),
        m.b - mean.x * mean.y,
    );
    return SlopeGaussian(mean, cov);
}

// How the slope distribution under a pixel is sampled: a grid of
// count.x x count.y taps (up to MAX_TAPS a side) over the footprint, each
// a Gaussian from the moments filtered at `lod` over its share of the
// footprint (at most about TAP_TEXELS texels wide). One Gaussian for the
// whole footprint would flatten the peaky slope distribution of skin
// (flat cells, steep grooves); a few keep its shape. Anisotropic
// footprints get more taps along their long axis.
struct Footprint {
    count: vec2<i32>,
    lod: f32,
};

// The footprint of a pixel spanning `dx` and `dy` in uv (its screen
// derivatives).
fn footprint(dx: vec2<f32>, dy: vec2<f32>) -> Footprint {
    let size = vec2<f32>(textureDimensions(moments_a, 0));
    let top = f32(textureNumLevels(moments_a) - 1u);
    let lx = length(dx * size);
    let ly = length(dy * size);
    let nx = clamp(i32(ceil(lx / TAP_TEXELS)), 1, MAX_TAPS);
    let ny = clamp(i32(ceil(ly / TAP_TEXELS)), 1, MAX_TAPS);
    let width = max(lx / f32(nx), ly / f32(ny));
    // A bilinear tap at level L spreads the box-averaged texels of side 2^L
    // over a tent of the same half-width: its standard deviation, 2^L / 2,
    // equals a box of `width`'s (width / sqrt(12)) at L = log2(width) - 0.79.
    let lod = clamp(log2(max(width, 1.0)) - LOD_BIAS, 0.0, top);
    return Footprint(vec2<i32>(nx, ny), lod);
}

// Tap (i, j) of the footprint's grid.
fn footprint_tap(
    f: Footprint,
    uv: vec2<f32>,
    dx: vec2<f32>,
    dy: vec2<f32>,
    i: i32,
    j: i32,
) -> SlopeGaussian {
    let p = uv + dx * ((f32(i) + 0.5) / f32(f.count.x) - 0.5)
        + dy * ((f32(j) + 0.5) / f32(f.count.y) - 0.5);
    return gaussian_of(moments_trilinear(p, f.lod));
}

// m(r) / m(1) of the strain-driven roughness model, linear in r.
fn roughness_scale(r: f32) -> f32 {
    let x = clamp((r - 0.7) / 0.05, 0.0, 15.0);
    let i = min(u32(floor(x)), 14u);
    let f = x - f32(i);
    let a = globals.roughness_curve[i / 4u][i % 4u];
    let b = globals.roughness_curve[(i + 1u) / 4u][(i + 1u) % 4u];
    return mix(a, b, f);
}

// Two anisotropic lobes; s, t, n an orthonormal frame along the strain axes.
fn ks_specular_aniso(
    frame: mat3x3<f32>,
    l: vec3<f32>,
    v: vec3<f32>,
    lobes: vec4<f32>,
    scale: vec2<f32>,
) -> f32 {
    let k = ks_terms(frame, l, v);
    if (k.factor == 0.0) {
        return 0.0;
    }
    let d = lobes.z * beckmann_aniso(k.h, lobes.x * scale.x, lobes.x * scale.y)
        + (1.0 - lobes.z) * beckmann_aniso(k.h, lobes.y * scale.x, lobes.y * scale.y);
    return d * k.factor;
}

fn diffused(uv: vec2<f32>) -> vec3<f32> {
    let p = globals.profile;
    var sum = p[0].rgb * textureSampleLevel(blur0, linear_clamp, uv, 0.0).rgb;
    sum += p[1].rgb * textureSampleLevel(blur1, linear_clamp, uv, 0.0).rgb;
    sum += p[2].rgb * textureSampleLevel(blur2, linear_clamp, uv, 0.0).rgb;
    sum += p[3].rgb * textureSampleLevel(blur3, linear_clamp, uv, 0.0).rgb;
    sum += p[4].rgb * textureSampleLevel(blur4, linear_clamp, uv, 0.0).rgb;
    sum += p[5].rgb * textureSampleLevel(blur5, linear_clamp, uv, 0.0).rgb;
    return sum + textureSampleLevel(transmitted, linear_clamp, uv, 0.0).rgb;
}

@fragment
fn fs_skin(in: SurfaceVaryings) -> @location(0) vec4<f32> {
    // The pixel's footprint in uv (derivatives need uniform control flow).
    let duv_dx = dpdx(in.uv);
    let duv_dy = dpdy(in.uv);
    let n = normalize(in.normal);
    let t = normalize(in.tangent - n * dot(n, in.tangent));
    let b = cross(n, t);
    let p = in.world;
    let v = view_dir(p);
    let mode = globals.flags.y;
    let anisotropic = globals.flags.z == 1u;
    let lobes = select(globals.micro_lobes, globals.meso_lobes, mode == 0u);
    let rho_s = lobes.w;

    // Diffuse: light diffused in texture space, the remaining albedo, and
    // the share of it that leaves through the rough interface.
    var diffuse = diffused(in.uv);
    let albedo = textureSampleLevel(albedo_map, linear_clamp, in.uv, 0.0).rgb;
    diffuse *= pow(albedo, vec3<f32>(1.0 - globals.params.x));
    diffuse *= energy_factor(max(dot(n, v), 0.0), lobes);
    // A strain overlay (options.z, range in options.w) recolours the
    // diffuse light: its colour times the light's brightness.
    let overlay = globals.options.z;
    if (overlay != 0u) {
        let luma = vec3<f32>(0.2126, 0.7152, 0.0722);
        let light = dot(diffuse, luma) / max(dot(albedo, luma), 1e-3);
        diffuse = strain_overlay(overlay, in.strain, bitcast<f32>(globals.options.w)) * light;
    }

    // Specular normal: the microstructure's in static and dynamic modes,
    // either looked up bilinearly or, prefiltered, as the mean slope with
    // the slopes' covariance under the pixel (LEAN).
    var ns = n;
    let prefiltered = mode != 0u && !anisotropic && globals.options.x == 1u;
    let tangent_frame = mat3x3<f32>(t, b, n);
    // Prefiltered: each light's BRDF averaged over the footprint's taps
    // (component k for light k), taps outermost so each is looked up once.
    var tap_brdf = vec4<f32>(0.0);
    if (prefiltered) {
        let f = footprint(duv_dx, duv_dy);
        var mean = vec2<f32>(0.0);
        for (var j = 0; j < f.count.y; j++) {
            for (var i = 0; i < f.count.x; i++) {
                let g = footprint_tap(f, in.uv, duv_dx, duv_dy, i, j);
                mean += g.mean;
                for (var k = 0u; k < globals.flags.x; k++) {
                    let l = incident(k, p).dir;
                    if (dot(n, l) > 0.0) {
                        tap_brdf[k] += ks_specular_moments(tangent_frame, l, v, lobes, g.mean, g.cov);
                    }
                }
            }
        }
        let count = f32(f.count.x * f.count.y);
        mean /= count;
        tap_brdf /= count;
        ns = normalize(n - mean.x * t - mean.y * b);
    } else if (mode != 0u && !anisotropic) {
        let m = micro_normal(in.uv);
        ns = normalize(m.x * t + m.y * b + m.z * n);
    }
    // Strain frame for anisotropic roughness.
    let s_uv = in.strain.zw;
    var s_axis = t * s_uv.x + b * s_uv.y;
    s_axis = select(t, normalize(s_axis), dot(s_axis, s_axis) > 1e-8);
    let frame = mat3x3<f32>(s_axis, cross(n, s_axis), n);
    // The static mode keeps the neutral (isotropic) roughness.
    var scale = vec2<f32>(1.0);
    if (mode == 2u) {
        scale = vec2<f32>(roughness_scale(in.strain.x), roughness_scale(in.strain.y));
    }

    var specular = vec3<f32>(0.0);
    let shadows = textureSampleLevel(shadow_factors, linear_clamp, in.uv, 0.0);
    for (var k = 0u; k < globals.flags.x; k++) {
        let inc = incident(k, p);
        if (dot(n, inc.dir) <= 0.0) {
            continue;
        }
        let shadow = shadows[k];
        var brdf: f32;
        if (mode != 0u && anisotropic) {
            brdf = ks_specular_aniso(frame, inc.dir, v, lobes, scale);
        } else if (prefiltered) {
            brdf = tap_brdf[k];
        } else {
            brdf = ks_specular(ns, inc.dir, v, lobes);
        }
        specular += shadow * rho_s * brdf * inc.irradiance;
    }
    // Environment: irradiance about the mirror direction, a coarse stand-in
    // for the glossy environment reflection.
    let r = reflect(-v, ns);
    specular += rho_s * schlick(max(dot(ns, v), 0.0), 0.028) * sh_irradiance(r) / PI;
    // Under an overlay the sheen is dimmed so the colours read.
    if (overlay != 0u) {
        specular *= 0.25;
    }
    return vec4<f32>(diffuse + specular, 1.0);
}

// Lambertian surface lit by every light (with shadows) and the environment.
fn lambert(p: vec3<f32>, n: vec3<f32>) -> vec3<f32> {
    var e = sh_irradiance(n);
    for (var k = 0u; k < globals.flags.x; k++) {
        let inc = incident(k, p);
        let nl = dot(n, inc.dir);
        if (nl > 0.0) {
            e += shadow_pcf(k, p, n) * nl * inc.irradiance;
        }
    }
    return e / PI;
}

// The cut sides and bottom of the patch: subcutaneous tissue colour.
@fragment
fn fs_tissue(in: MeshVaryings) -> @location(0) vec4<f32> {
    var n = normalize(in.normal);
    if (dot(n, view_dir(in.world)) < 0.0) {
        n = -n;
    }
    return vec4<f32>(vec3<f32>(0.62, 0.30, 0.24) * lambert(in.world, n), 1.0);
}

// The probe: brushed steel.
@fragment
fn fs_probe(in: MeshVaryings) -> @location(0) vec4<f32> {
    let n = normalize(in.normal);
    let v = view_dir(in.world);
    var color = vec3<f32>(0.08) * lambert(in.world, n);
    for (var k = 0u; k < globals.flags.x; k++) {
        let inc = incident(k, in.world);
        let nl = dot(n, inc.dir);
        if (nl <= 0.0 || dot(n, v) <= 0.0) {
            continue;
        }
        let hv = inc.dir + v;
        let h = normalize(hv);
        let brdf = beckmann(dot(n, h), 0.2) * schlick(dot(v, h), 0.6) / dot(hv, hv);
        color += brdf * nl * inc.irradiance;
    }
    let r = reflect(-v, n);
    color += schlick(max(dot(n, v), 0.0), 0.6) * sh_irradiance(r) / PI;
    return vec4<f32>(color, 1.0);
}
