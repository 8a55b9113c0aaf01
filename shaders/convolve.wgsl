// One pass of the spatially varying separable convolution (DESIGN §5.4,
// seed 000 eq. 4-6). CPU reference: src/micro/convolve.rs
// (convolve_texel). Rust side: src/gpu/convolve.rs. Needs map.wgsl and
// svd2.wgsl (prepended).
//
// Three entry points differ only in where a texel's parameters come from:
// `convolve_strain` computes them from the raster (svd2.wgsl, group 1), as
// the per-frame chain does, over the tiles of a list (the others keep their
// values; src/gpu/tiles.rs says why that is exact); `convolve_field` reads
// them from a buffer; `convolve_constant` takes one set from the uniform
// (the fitting search).
//
// Texel p with unit axis a (texels), strength alpha and sigma (texels):
//   (1 - alpha) D(p) + alpha * sum_k g_k D(p - k a) / sum_k g_k,  k = -N..N,
// N = ceil(3 sigma), g_k = exp(-k^2 / 2 sigma^2) by the recurrence
// g_{k+1} = g_k q^(2k+1), q = exp(-1 / 2 sigma^2), in the CPU's order; the
// outermost pair is scaled by 3 sigma - (N - 1), so the kernel is continuous
// in sigma.

// Mirrors `PassInfo` in src/gpu/convolve.rs.
struct PassInfo {
    // 0: the pass along s, 1: along t.
    pass_index: u32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
    // (axis x, axis y, alpha, sigma in texels) for `convolve_constant`.
    params: vec4<f32>,
};

@group(0) @binding(0) var<uniform> map: MapInfo;
@group(0) @binding(1) var<storage, read> src: array<f32>;
@group(0) @binding(2) var<uniform> pass_info: PassInfo;
// Per texel two entries (s pass, t pass): (axis x, axis y, alpha, sigma),
// for `convolve_field`.
@group(0) @binding(3) var<storage, read> field_passes: array<vec4<f32>>;
@group(0) @binding(4) var<storage, read_write> dst: array<f32>;
// The tiles `convolve_strain` runs on (map.wgsl, tile_index).
@group(0) @binding(5) var<storage, read> tiles: array<u32>;

fn convolve_texel(i: i32, j: i32, p: vec4<f32>) -> f32 {
    let centre = src[u32(j) * map.width + u32(i)];
    let alpha = p.z;
    let sigma = p.w;
    if (alpha == 0.0 || !(sigma > 0.0)) {
        return centre;
    }
    let n = i32(ceil(3.0 * sigma));
    let taper = 3.0 * sigma - f32(n - 1);
    let q = exp(-0.5 / (sigma * sigma));
    let x = f32(i);
    let y = f32(j);
    var sum = centre;
    var norm = 1.0;
    var g = 1.0;
    var step = q;
    for (var k = 1; k <= n; k++) {
        g *= step;
        step *= q * q;
        var w = g;
        if (k == n) {
            w = g * taper;
        }
        let d = f32(k) * p.xy;
        sum += w * (bilinear(x - d.x, y - d.y) + bilinear(x + d.x, y + d.y));
        norm += 2.0 * w;
    }
    return (1.0 - alpha) * centre + alpha * (sum / norm);
}

@compute @workgroup_size(16, 16)
fn convolve_strain(
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
    let p = texel_passes(id.xy);
    var params = p.s;
    if (pass_info.pass_index == 1u) {
        params = p.t;
    }
    dst[id.y * map.width + id.x] = convolve_texel(i32(id.x), i32(id.y), params);
}

@compute @workgroup_size(16, 16)
fn convolve_field(@builtin(global_invocation_id) id: vec3<u32>) {
    if (id.x >= map.width || id.y >= map.height) {
        return;
    }
    let idx = id.y * map.width + id.x;
    dst[idx] = convolve_texel(i32(id.x), i32(id.y), field_passes[2u * idx + pass_info.pass_index]);
}

@compute @workgroup_size(16, 16)
fn convolve_constant(@builtin(global_invocation_id) id: vec3<u32>) {
    if (id.x >= map.width || id.y >= map.height) {
        return;
    }
    dst[id.y * map.width + id.x] = convolve_texel(i32(id.x), i32(id.y), pass_info.params);
}
