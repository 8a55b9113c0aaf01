// Shadow and translucent shadow map of one light (Rg32Float): every boundary face of
// the deformed patch (and the probe) drawn from the light. Each texel keeps
// the nearest surface's distance to the light (mm) and the irradiance
// factor it receives (cosine x point-light falloff), which the translucent
// shadow map needs (seed 001 §2.5). Rust side: src/render/shadow.rs.

// Mirrors `ShadowInfo` in src/render/shadow.rs.
struct ShadowInfo {
    view_proj: mat4x4<f32>,
    // xyz: direction of travel (w = 0) or position in mm (w = 1).
    where_: vec4<f32>,
};

// Mirrors `MeshVertex` in src/render/scene.rs.
struct MeshVertex {
    @location(0) position: vec4<f32>,
    @location(1) normal: vec4<f32>,
};

struct Varyings {
    @builtin(position) clip: vec4<f32>,
    @location(0) world: vec3<f32>,
    @location(1) normal: vec3<f32>,
};

@group(0) @binding(0) var<uniform> info: ShadowInfo;

@vertex
fn vs_main(v: MeshVertex) -> Varyings {
    var out: Varyings;
    out.clip = info.view_proj * vec4<f32>(v.position.xyz, 1.0);
    out.world = v.position.xyz;
    out.normal = v.normal.xyz;
    return out;
}

@fragment
fn fs_main(in: Varyings) -> @location(0) vec4<f32> {
    var distance: f32;
    var towards: vec3<f32>;
    var falloff = 1.0;
    if (info.where_.w == 0.0) {
        distance = dot(in.world, info.where_.xyz);
        towards = -info.where_.xyz;
    } else {
        let to = info.where_.xyz - in.world;
        let d2 = max(dot(to, to), 1e-12);
        distance = sqrt(d2);
        towards = to / distance;
        falloff = 1.0e4 / d2;
    }
    let n = normalize(in.normal);
    // The nearest surface faces the light whatever the winding.
    let cosine = abs(dot(n, towards));
    return vec4<f32>(distance, cosine * falloff, 0.0, 1.0);
}
