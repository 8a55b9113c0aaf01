// Normal map of a displacement map (DESIGN §5.4). CPU reference:
// src/micro/normals.rs (normal_map). Rust side: src/gpu/normals.rs.
// Needs map.wgsl.

@group(0) @binding(0) var<uniform> map: MapInfo;
@group(0) @binding(1) var<storage, read> src: array<f32>;
// (x, y, z, 0) per texel; a texture, so large maps stay within the storage
// buffer binding limit.
@group(0) @binding(2) var normals: texture_storage_2d<rgba32float, write>;
// The tiles `normals_tiles` runs on (map.wgsl, tile_index).
@group(0) @binding(3) var<storage, read> tiles: array<u32>;

fn store_normal(id: vec2<u32>) {
    let n = normal_of(slope(i32(id.x), i32(id.y)));
    textureStore(normals, vec2<i32>(id), vec4<f32>(n, 0.0));
}

// Every texel.
@compute @workgroup_size(16, 16)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    if (id.x >= map.width || id.y >= map.height) {
        return;
    }
    store_normal(id.xy);
}

// The texels of the listed tiles (the per-frame chain).
@compute @workgroup_size(16, 16)
fn normals_tiles(
    @builtin(workgroup_id) group: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
    @builtin(local_invocation_id) local: vec3<u32>,
) {
    let k = tile_index(group, groups);
    if (k >= tiles[0]) {
        return;
    }
    let id = tile_texel(tiles[1u + k], local.xy);
    if (id.x >= map.width || id.y >= map.height) {
        return;
    }
    store_normal(id);
}
