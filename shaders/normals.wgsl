// Normal map of a displacement map (DESIGN §5.4). CPU reference:
// src/micro/normals.rs (normal_map). Rust side: src/gpu/normals.rs.
// Needs map.wgsl.

@group(0) @binding(0) var<uniform> map: MapInfo;
@group(0) @binding(1) var<storage, read> src: array<f32>;
// (x, y, z, 0) per texel; a texture, so large maps stay within the storage
// buffer binding limit.
@group(0) @binding(2) var normals: texture_storage_2d<rgba32float, write>;

@compute @workgroup_size(16, 16)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    if (id.x >= map.width || id.y >= map.height) {
        return;
    }
    let n = normal_of(slope(i32(id.x), i32(id.y)));
    textureStore(normals, vec2<i32>(id.xy), vec4<f32>(n, 0.0));
}
