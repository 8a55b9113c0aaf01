// One separable pass of the six-Gaussian diffusion (seed 001 §2.2.4): a
// seven-tap blur along u or v adding `variance` mm^2, the taps spaced by
// the blur's standard deviation divided by the local millimetres per texel
// (stretch correction). The output may be smaller than the source (a wide
// Gaussian is stored coarser); every size is addressed by uv. CPU
// reference: src/render/profile.rs `blur_pass`. Rust side:
// src/render/diffusion.rs.

// Mirrors `BlurInfo` in src/render/diffusion.rs.
struct BlurInfo {
    // Tap weights for offsets -3 ... 3 (w of the second vector unused).
    taps_a: vec4<f32>,
    taps_b: vec4<f32>,
    // Blur direction in texels: (1, 0) or (0, 1).
    axis: vec2<f32>,
    // Variance this pass adds (mm^2).
    variance: f32,
    pad: f32,
};

@group(0) @binding(0) var<uniform> info: BlurInfo;
@group(0) @binding(1) var source: texture_2d<f32>;
@group(0) @binding(2) var stretch: texture_2d<f32>;
@group(0) @binding(3) var linear_clamp: sampler;
@group(0) @binding(4) var output: texture_storage_2d<rgba16float, write>;

fn tap_weight(k: u32) -> f32 {
    if (k < 4u) {
        return info.taps_a[k];
    }
    return info.taps_b[k - 4u];
}

@compute @workgroup_size(16, 16)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    let size = textureDimensions(output);
    if (id.x >= size.x || id.y >= size.y) {
        return;
    }
    let uv = (vec2<f32>(id.xy) + 0.5) / vec2<f32>(size);
    // Millimetres per texel of the stretch texture's own grid.
    let mm = dot(textureSampleLevel(stretch, linear_clamp, uv, 0.0).xy, info.axis);
    let grid = vec2<f32>(textureDimensions(stretch));
    // Tap spacing in texture coordinates.
    let step = info.axis * (sqrt(info.variance) / max(mm, 1e-9)) / grid;
    var sum = vec4<f32>(0.0);
    for (var k = 0u; k < 7u; k++) {
        let offset = f32(k) - 3.0;
        sum += tap_weight(k) * textureSampleLevel(source, linear_clamp, uv + offset * step, 0.0);
    }
    textureStore(output, id.xy, sum);
}
