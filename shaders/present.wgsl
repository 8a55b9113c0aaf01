// Shows the renderer's resolved image (linear RGBA f32 texels, row 0 at
// the top) in a rectangle of the viewer's window, one texel a pixel, with
// the sRGB encoding the frame files use (clamped to [0, 1]). Rust side:
// src/viewer/present.rs.

struct PresentInfo {
    // Top-left pixel of the rectangle in the window.
    origin: vec2<f32>,
    // The image's width and height.
    size: vec2<u32>,
    // 1: encode sRGB here (the window's format is not an sRGB one).
    encode: u32,
    pad0: u32,
    pad1: u32,
    pad2: u32,
};

@group(0) @binding(0) var<uniform> info: PresentInfo;
@group(0) @binding(1) var<storage, read> pixels: array<vec4<f32>>;

@vertex
fn vs_main(@builtin(vertex_index) i: u32) -> @builtin(position) vec4<f32> {
    // One triangle covering the viewport.
    let x = f32((i << 1u) & 2u) * 2.0 - 1.0;
    let y = f32(i & 2u) * 2.0 - 1.0;
    return vec4<f32>(x, y, 0.0, 1.0);
}

fn encode_srgb(c: vec3<f32>) -> vec3<f32> {
    let x = clamp(c, vec3<f32>(0.0), vec3<f32>(1.0));
    let low = 12.92 * x;
    let high = 1.055 * pow(x, vec3<f32>(1.0 / 2.4)) - 0.055;
    return select(high, low, x <= vec3<f32>(0.0031308));
}

@fragment
fn fs_main(@builtin(position) p: vec4<f32>) -> @location(0) vec4<f32> {
    let q = min(vec2<u32>(max(p.xy - info.origin, vec2<f32>(0.0))), info.size - vec2<u32>(1u));
    let c = clamp(pixels[q.y * info.size.x + q.x].rgb, vec3<f32>(0.0), vec3<f32>(1.0));
    if (info.encode == 1u) {
        return vec4<f32>(encode_srgb(c), 1.0);
    }
    return vec4<f32>(c, 1.0);
}
