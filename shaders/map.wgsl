// Displacement-map access shared by convolve.wgsl, normals.wgsl and
// histogram.wgsl; src/gpu/map.rs prepends it to each of them.
// CPU reference: src/micro/map.rs (texel, bilinear) and
// src/micro/normals.rs (slope, normal_of).
//
// The including shader binds `map: MapInfo` (group 0, binding 0) and the
// heights `src: array<f32>` (binding 1), row-major, texel (i, j) at
// j * width + i with its centre at integer coordinates (i, j).

// Mirrors `MapInfo` in src/gpu/map.rs.
struct MapInfo {
    width: u32,
    height: u32,
    // 1: reads outside the grid wrap around (tileable map); 0: clamp.
    wrap: u32,
    _pad0: u32,
    // height_unit_um / (2 texel_um): central difference -> slope.
    slope_scale: f32,
    // Stretch of the texel spacing along x and y for slopes (1, 1 = as is).
    stretch_x: f32,
    stretch_y: f32,
    _pad1: f32,
};

fn texel(i: i32, j: i32) -> f32 {
    let w = i32(map.width);
    let h = i32(map.height);
    var x: i32;
    var y: i32;
    if (map.wrap != 0u) {
        x = ((i % w) + w) % w;
        y = ((j % h) + h) % h;
    } else {
        x = clamp(i, 0, w - 1);
        y = clamp(j, 0, h - 1);
    }
    return src[u32(y) * map.width + u32(x)];
}

// Bilinear read at continuous texel coordinates (texel centres at integers).
fn bilinear(x: f32, y: f32) -> f32 {
    let x0 = floor(x);
    let y0 = floor(y);
    let fx = x - x0;
    let fy = y - y0;
    let i = i32(x0);
    let j = i32(y0);
    let a = texel(i, j);
    let b = texel(i + 1, j);
    let c = texel(i, j + 1);
    let d = texel(i + 1, j + 1);
    let top = a + (b - a) * fx;
    let bottom = c + (d - c) * fx;
    return top + (bottom - top) * fy;
}

// Central-difference slope (dimensionless) at texel (i, j).
fn slope(i: i32, j: i32) -> vec2<f32> {
    let dx = (texel(i + 1, j) - texel(i - 1, j)) * map.slope_scale / map.stretch_x;
    let dy = (texel(i, j + 1) - texel(i, j - 1)) * map.slope_scale / map.stretch_y;
    return vec2<f32>(dx, dy);
}

// Unit normal (x along u, y along v, z out of the skin) of a slope.
fn normal_of(s: vec2<f32>) -> vec3<f32> {
    let n = sqrt(s.x * s.x + s.y * s.y + 1.0);
    return vec3<f32>(-s.x / n, -s.y / n, 1.0 / n);
}

// Tiled dispatches (src/gpu/tiles.rs): one 16 x 16 workgroup per tile of a
// list holding the count, then each tile as x | y << 16. The list index of
// a workgroup of a (possibly 2D) dispatch.
fn tile_index(group: vec3<u32>, groups: vec3<u32>) -> u32 {
    return group.y * groups.x + group.x;
}

// The texel of invocation `local` in tile `packed`.
fn tile_texel(packed: u32, local: vec2<u32>) -> vec2<u32> {
    return vec2<u32>(packed & 0xffffu, packed >> 16u) * 16u + local;
}
