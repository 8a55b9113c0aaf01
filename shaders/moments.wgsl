// Slope moments of the microstructure normals and their mip pyramid, for
// prefiltered specular (LEAN mapping). CPU reference: src/micro/moments.rs;
// Rust side: src/gpu/moments.rs.
//
// Texture A holds (x, y, x^2, y^2) and texture B (x y) of the slopes
// x = dh/du = -n.x / n.z, y = dh/dv = -n.y / n.z; mip level k + 1 is the
// mean of 2 x 2 texels of level k (3 at the end of an odd side).

// `texel_moments`: the normals; `downsample`: level k of A.
@group(0) @binding(0) var src_a: texture_2d<f32>;
// `downsample`: level k of B.
@group(0) @binding(1) var src_b: texture_2d<f32>;
@group(0) @binding(2) var dst_a: texture_storage_2d<rgba32float, write>;
@group(0) @binding(3) var dst_b: texture_storage_2d<r32float, write>;

@compute @workgroup_size(16, 16)
fn texel_moments(@builtin(global_invocation_id) id: vec3<u32>) {
    let size = textureDimensions(dst_a);
    if (id.x >= size.x || id.y >= size.y) {
        return;
    }
    let n = textureLoad(src_a, id.xy, 0).xyz;
    let nz = max(n.z, 1e-6);
    let x = -n.x / nz;
    let y = -n.y / nz;
    textureStore(dst_a, id.xy, vec4<f32>(x, y, x * x, y * y));
    textureStore(dst_b, id.xy, vec4<f32>(x * y, 0.0, 0.0, 0.0));
}

// Source texels [first, end) of texel i of the next level: 2i and 2i + 1,
// and the left-over last texel of an odd side with the last one.
fn source_span(i: u32, n: u32, m: u32) -> vec2<u32> {
    let first = min(2u * i, n - 1u);
    let end = select(2u * i + 2u, n, i + 1u == m);
    return vec2<u32>(first, max(end, first + 1u));
}

@compute @workgroup_size(16, 16)
fn downsample(@builtin(global_invocation_id) id: vec3<u32>) {
    let size = textureDimensions(dst_a);
    if (id.x >= size.x || id.y >= size.y) {
        return;
    }
    let src = textureDimensions(src_a);
    let xs = source_span(id.x, src.x, size.x);
    let ys = source_span(id.y, src.y, size.y);
    var a = vec4<f32>(0.0);
    var b = 0.0;
    for (var y = ys.x; y < ys.y; y++) {
        for (var x = xs.x; x < xs.y; x++) {
            a += textureLoad(src_a, vec2<u32>(x, y), 0);
            b += textureLoad(src_b, vec2<u32>(x, y), 0).x;
        }
    }
    let count = f32((xs.y - xs.x) * (ys.y - ys.x));
    textureStore(dst_a, id.xy, a / count);
    textureStore(dst_b, id.xy, vec4<f32>(b / count, 0.0, 0.0, 0.0));
}
