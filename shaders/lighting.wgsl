// Shared lighting: scene uniforms, the skin BRDF, SH irradiance and
// shadow-map lookups. Prepended to irradiance.wgsl and skin.wgsl.
// Rust side: src/render/lighting.rs (Globals), CPU references in
// src/render/specular.rs and src/render/light.rs.

const PI: f32 = 3.14159265358979;

// Mirrors `SurfaceVertex` in src/render/scene.rs: a top-surface vertex.
struct SurfaceVertex {
    @location(0) position: vec4<f32>,
    @location(1) normal: vec4<f32>,
    @location(2) tangent: vec4<f32>,
    // uv in xy; zw unused.
    @location(3) uv: vec4<f32>,
    // r_s, r_t, and the s axis in uv (anisotropic roughness).
    @location(4) strain: vec4<f32>,
};

// Mirrors `GpuLight` in src/render/lighting.rs.
struct Light {
    // xyz: direction of travel (w = 0) or position in mm (w = 1).
    where_: vec4<f32>,
    // rgb: irradiance at normal incidence (at 100 mm for a point light);
    // w: the shadow map's texel size at the scene (mm).
    radiance: vec4<f32>,
    view_proj: mat4x4<f32>,
};

// Mirrors `Globals` in src/render/lighting.rs.
struct Globals {
    view_proj: mat4x4<f32>,
    // xyz eye (mm); w = 1 perspective, 0 orthographic.
    eye: vec4<f32>,
    // xyz unit view direction (orthographic rays).
    forward: vec4<f32>,
    lights: array<Light, 4>,
    sh: array<vec4<f32>, 9>,
    // Gaussian i of the diffusion profile: rgb weights, w variance (mm^2).
    profile: array<vec4<f32>, 6>,
    // m1, m2, w, rho_s of the microscale lobes.
    micro_lobes: vec4<f32>,
    // m1, m2, w, rho_s of the mesoscale lobes.
    meso_lobes: vec4<f32>,
    // Beckmann m(r) / m(1) at r = 0.70, 0.75, ... 1.45 (anisotropic mode).
    roughness_curve: array<vec4<f32>, 4>,
    // x: mix ratio; y: shadow-map side (texels); z: environment
    // attenuation (1 - rho_s <A>) micro; w: the same for meso lobes.
    params: vec4<f32>,
    // x: light count; y: mode (0 none, 1 static, 2 dynamic);
    // z: roughness (0 microgeometry, 1 anisotropic); w: translucency on.
    flags: vec4<u32>,
    // x: microstructure filter (0 bilinear normals, 1 slope moments);
    // y: moments sampled with the sampler (f32 filterable); z: strain
    // overlay (0 none, 1 r_s, 2 r_t, 3 axes; overlay.wgsl); w: the
    // overlay's saturating range, as f32 bits.
    options: vec4<u32>,
};

@group(0) @binding(0) var<uniform> globals: Globals;
// A(mu, m) of the KS BRDF: 64 x 64, x = mu in [0, 1], y = m in [0.02, 1].
@group(0) @binding(1) var energy_table: texture_2d<f32>;
@group(0) @binding(2) var albedo_map: texture_2d<f32>;
@group(0) @binding(3) var linear_clamp: sampler;
// Per light: x distance to the light (mm) of the nearest surface,
// y its irradiance factor (cosine x falloff), cleared to 1e9.
@group(0) @binding(4) var shadow_maps: texture_2d_array<f32>;
// Nearest, clamp to edge: gathers of the shadow maps (shadow_pcf).
@group(0) @binding(5) var nearest_clamp: sampler;

const ENERGY_M_MIN: f32 = 0.02;
const ENERGY_M_MAX: f32 = 1.0;

fn beckmann(cos_h: f32, m: f32) -> f32 {
    if (cos_h <= 0.0) {
        return 0.0;
    }
    let c2 = cos_h * cos_h;
    let tan2 = (1.0 - c2) / c2;
    return exp(-tan2 / (m * m)) / (PI * m * m * c2 * c2);
}

// Anisotropic Beckmann; h = (h_s, h_t, h_n) in the strain frame.
fn beckmann_aniso(h: vec3<f32>, ms: f32, mt: f32) -> f32 {
    if (h.z <= 0.0) {
        return 0.0;
    }
    let hn2 = h.z * h.z;
    let e = (h.x * h.x / (ms * ms) + h.y * h.y / (mt * mt)) / hn2;
    return exp(-e) / (PI * ms * mt * hn2 * hn2);
}

fn schlick(cos: f32, f0: f32) -> f32 {
    let e = pow(clamp(1.0 - cos, 0.0, 1.0), 5.0);
    return e + f0 * (1.0 - e);
}

// A(mu, m), bilinear in the table.
fn energy_albedo(mu: f32, m: f32) -> f32 {
    let size = vec2<f32>(textureDimensions(energy_table));
    let x = clamp(mu, 0.0, 1.0) * (size.x - 1.0);
    let y = clamp((m - ENERGY_M_MIN) / (ENERGY_M_MAX - ENERGY_M_MIN), 0.0, 1.0) * (size.y - 1.0);
    let i0 = min(u32(floor(x)), u32(size.x) - 2u);
    let j0 = min(u32(floor(y)), u32(size.y) - 2u);
    let f = vec2<f32>(x - f32(i0), y - f32(j0));
    let a = textureLoad(energy_table, vec2<u32>(i0, j0), 0).x;
    let b = textureLoad(energy_table, vec2<u32>(i0 + 1u, j0), 0).x;
    let c = textureLoad(energy_table, vec2<u32>(i0, j0 + 1u), 0).x;
    let d = textureLoad(energy_table, vec2<u32>(i0 + 1u, j0 + 1u), 0).x;
    return mix(mix(a, b, f.x), mix(c, d, f.x), f.y);
}

// rho_dt = 1 - rho_s A for two lobes (m1, m2, w, rho_s).
fn energy_factor(mu: f32, lobes: vec4<f32>) -> f32 {
    let a = lobes.z * energy_albedo(mu, lobes.x) + (1.0 - lobes.z) * energy_albedo(mu, lobes.y);
    return clamp(1.0 - lobes.w * a, 0.0, 1.0);
}

// Ramamoorthi & Hanrahan (2001) irradiance for unit normal n.
fn sh_irradiance(n: vec3<f32>) -> vec3<f32> {
    let c1 = 0.429043;
    let c2 = 0.511664;
    let c3 = 0.743125;
    let c4 = 0.886227;
    let c5 = 0.247708;
    let l = globals.sh;
    return c1 * l[8].rgb * (n.x * n.x - n.y * n.y) + c3 * l[6].rgb * n.z * n.z + c4 * l[0].rgb
        - c5 * l[6].rgb
        + 2.0 * c1 * (l[4].rgb * n.x * n.y + l[7].rgb * n.x * n.z + l[5].rgb * n.y * n.z)
        + 2.0 * c2 * (l[3].rgb * n.x + l[1].rgb * n.y + l[2].rgb * n.z);
}

// Unit vector towards light k and its irradiance at normal incidence.
struct Incident {
    dir: vec3<f32>,
    irradiance: vec3<f32>,
    // Distance along the light's shadow-map measure (mm).
    distance: f32,
};

fn incident(k: u32, p: vec3<f32>) -> Incident {
    let light = globals.lights[k];
    var out: Incident;
    if (light.where_.w == 0.0) {
        out.dir = -light.where_.xyz;
        out.irradiance = light.radiance.rgb;
        out.distance = dot(p, light.where_.xyz);
    } else {
        let to = light.where_.xyz - p;
        let d2 = max(dot(to, to), 1e-12);
        out.dir = to * inverseSqrt(d2);
        out.irradiance = light.radiance.rgb * (1.0e4 / d2);
        out.distance = sqrt(d2);
    }
    return out;
}

// Shadow-map texel coordinates of p for light k (xy), and whether inside.
fn shadow_coords(k: u32, p: vec3<f32>) -> vec3<f32> {
    let clip = globals.lights[k].view_proj * vec4<f32>(p, 1.0);
    let ndc = clip.xyz / clip.w;
    let uv = vec2<f32>(0.5 * ndc.x + 0.5, 0.5 - 0.5 * ndc.y);
    let inside = all(uv >= vec2<f32>(0.0)) && all(uv <= vec2<f32>(1.0)) && clip.w > 0.0;
    return vec3<f32>(uv * globals.params.y, select(0.0, 1.0, inside));
}

fn shadow_texel(k: u32, xy: vec2<f32>) -> vec4<f32> {
    let side = i32(globals.params.y);
    let t = clamp(vec2<i32>(floor(xy)), vec2<i32>(0), vec2<i32>(side - 1));
    return textureLoad(shadow_maps, t, i32(k), 0);
}

// Fraction of light k reaching p (unit normal n): 4 x 4 percentage-closer
// filtering. The receiver is moved 1.5 shadow texels along its normal and
// compared with half a texel of bias, which keeps slopes of the deformed
// surface free of acne without detaching contact shadows.
fn shadow_pcf(k: u32, p: vec3<f32>, n: vec3<f32>) -> f32 {
    let texel = globals.lights[k].radiance.w;
    let q = p + n * (1.5 * texel);
    let c = shadow_coords(k, q);
    if (c.z == 0.0) {
        return 1.0;
    }
    let distance = incident(k, q).distance;
    let bias = 0.5 * texel + 0.005;
    // The 4 x 4 texels floor(c - 1.5) + (0 ... 3), clamped to the map, as
    // four gathers of 2 x 2 texels each: a gather at the corner shared by
    // texels i and i + 1 returns exactly those.
    let side = globals.params.y;
    let first = floor(c.xy - 1.5);
    let reference = vec4<f32>(distance - bias);
    var lit = 0.0;
    for (var j = 0; j < 2; j++) {
        for (var i = 0; i < 2; i++) {
            let corner = (first + vec2<f32>(f32(2 * i + 1), f32(2 * j + 1))) / side;
            let stored = textureGather(0, shadow_maps, nearest_clamp, corner, i32(k));
            lit += dot(select(vec4<f32>(0.0), vec4<f32>(1.0), reference <= stored), vec4<f32>(1.0));
        }
    }
    return lit / 16.0;
}

// Beckmann distribution of a Gaussian slope distribution (LEAN mapping):
// mean slope `mean`, covariance `cov` = (xx, yy, xy); h in the tangent
// frame. The slopes of h as a facet normal are (-h.x, -h.y) / h.z. With
// mean 0 and cov = (m^2/2, m^2/2, 0) this is beckmann(h.z, m).
fn beckmann_slopes(h: vec3<f32>, mean: vec2<f32>, cov: vec3<f32>) -> f32 {
    if (h.z <= 0.0) {
        return 0.0;
    }
    let s = vec2<f32>(-h.x, -h.y) / h.z - mean;
    let det = cov.x * cov.y - cov.z * cov.z;
    let e = (cov.y * s.x * s.x - 2.0 * cov.z * s.x * s.y + cov.x * s.y * s.y) / det;
    let hz2 = h.z * h.z;
    return exp(-0.5 * e) / (2.0 * PI * sqrt(det) * hz2 * hz2);
}

// What the KS BRDF's lobes share for light l and view v in `frame`
// (two tangent axes and the normal): the half vector in that frame and
// F(v.h) n.l / |l + v|^2, the factor that multiplies D (0 when l or v is
// below the surface).
struct KsTerms {
    h: vec3<f32>,
    factor: f32,
};

fn ks_terms(frame: mat3x3<f32>, l: vec3<f32>, v: vec3<f32>) -> KsTerms {
    let n = frame[2];
    let nl = dot(n, l);
    if (nl <= 0.0 || dot(n, v) <= 0.0) {
        return KsTerms(vec3<f32>(0.0, 0.0, 1.0), 0.0);
    }
    let hv = l + v;
    let h = normalize(hv);
    let ht = vec3<f32>(dot(h, frame[0]), dot(h, frame[1]), dot(h, n));
    return KsTerms(ht, schlick(dot(v, h), 0.028) / dot(hv, hv) * nl);
}

// The KS BRDF times n.l for two lobes (without rho_s) over a slope
// distribution of mean `mean` and covariance `cov` (xx, yy, xy); each
// lobe's own Beckmann slope variance m^2/2 adds to `cov`. `frame` holds
// the tangent, bitangent and geometric normal.
fn ks_specular_moments(
    frame: mat3x3<f32>,
    l: vec3<f32>,
    v: vec3<f32>,
    lobes: vec4<f32>,
    mean: vec2<f32>,
    cov: vec3<f32>,
) -> f32 {
    let k = ks_terms(frame, l, v);
    if (k.factor == 0.0) {
        return 0.0;
    }
    let v1 = 0.5 * lobes.x * lobes.x;
    let v2 = 0.5 * lobes.y * lobes.y;
    let d = lobes.z * beckmann_slopes(k.h, mean, cov + vec3<f32>(v1, v1, 0.0))
        + (1.0 - lobes.z) * beckmann_slopes(k.h, mean, cov + vec3<f32>(v2, v2, 0.0));
    return d * k.factor;
}

// Kelemen/Szirmay-Kalos BRDF times n.l for two lobes (without rho_s).
fn ks_specular(n: vec3<f32>, l: vec3<f32>, v: vec3<f32>, lobes: vec4<f32>) -> f32 {
    let nl = dot(n, l);
    if (nl <= 0.0 || dot(n, v) <= 0.0) {
        return 0.0;
    }
    let hv = l + v;
    let h = normalize(hv);
    let nh = dot(n, h);
    let d = lobes.z * beckmann(nh, lobes.x) + (1.0 - lobes.z) * beckmann(nh, lobes.y);
    return d * schlick(dot(v, h), 0.028) / dot(hv, hv) * nl;
}
