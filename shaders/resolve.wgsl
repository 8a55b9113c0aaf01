// Box-filters the supersampled HDR image down to the output size and
// stores linear RGBA floats for read-back. Rust side: src/render/resolve.rs.

// Mirrors `ResolveInfo` in src/render/resolve.rs.
struct ResolveInfo {
    width: u32,
    height: u32,
    factor: u32,
    pad: u32,
};

@group(0) @binding(0) var<uniform> info: ResolveInfo;
@group(0) @binding(1) var hdr: texture_2d<f32>;
@group(0) @binding(2) var<storage, read_write> pixels: array<vec4<f32>>;

@compute @workgroup_size(16, 16)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    if (id.x >= info.width || id.y >= info.height) {
        return;
    }
    var sum = vec4<f32>(0.0);
    for (var j = 0u; j < info.factor; j++) {
        for (var i = 0u; i < info.factor; i++) {
            sum += textureLoad(hdr, id.xy * info.factor + vec2<u32>(i, j), 0);
        }
    }
    pixels[id.y * info.width + id.x] = sum / f32(info.factor * info.factor);
}
