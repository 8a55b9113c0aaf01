// Normal map of a displacement map (DESIGN §5.4). CPU reference:
// src/micro/normals.rs (normal_map). Rust side: src/gpu/normals.rs.
// Needs map.wgsl.

@group(0) @binding(0) var<uniform> map: MapInfo;
@group(0) @binding(1) var<storage, read> src: array<f32>;
// Three floats (x, y, z) per texel, row-major.
@group(0) @binding(2) var<storage, read_write> normals: array<f32>;

@compute @workgroup_size(16, 16)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    if (id.x >= map.width || id.y >= map.height) {
        return;
    }
    let idx = id.y * map.width + id.x;
    let n = normal_of(slope(i32(id.x), i32(id.y)));
    normals[3u * idx] = n.x;
    normals[3u * idx + 1u] = n.y;
    normals[3u * idx + 2u] = n.z;
}
