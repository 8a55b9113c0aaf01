// Per-texel closed-form 2x2 SVD and kernel parameters per axis (DESIGN
// §5.3-5.4, seed 000 eq. 8-13). CPU references: src/strain/svd2.rs (Svd2),
// src/micro/convolve.rs (KernelField::from_strain), src/strain/raster.rs
// (StrainRaster::dilated). Rust side: src/gpu/svd2.rs.
//
// The functions here also run inside convolve.wgsl (which prepends this
// file): each pass computes its texel's parameters on the fly, so no
// per-texel parameter buffer (32 bytes a texel) is needed per frame. The
// entry point `svd2_main` writes them out, for tests and inspection.
//
// Reads the raster textures of raster.wgsl. A raster texel off the surface
// (zero Q R^T) first takes the values of its nearest surface texel within
// `dilate` raster texels (square window, Euclidean distance, ties to the
// first in row-major window order); one with none stays the identity pass.
//
// With `step` = 1 the raster has the map's texels and each map texel reads
// its own. With `step` > 1 the raster has one texel per step x step map
// texels (CPU reference: src/strain/raster.rs, CoarseRaster): map texel i
// reads raster coordinate x = (i + 1/2) / step - 1/2, clamped to the
// raster, as the bilinear mix of its four neighbours (each dilated as
// above); neighbours off the surface drop out and the others' weights are
// renormalised.
//
// SVD of T from the raster's T - I = [a' b'; c' d'] (so that F and G, which
// fix the axes, keep full f32 precision when T is near a rotation):
// T = [a b; c d], E = (a+d)/2, F = (a-d)/2, G = (c+b)/2, H = (c-b)/2,
// q = |(E, H)|, p = |(F, G)|, phi1 = atan2(G, F), phi2 = atan2(H, E);
// r_s = q + p, r_t = q - p, V = Rot((phi1 - phi2) / 2).
// Axes in the map: S = (Q R^T) V scaled to texels; each column gives a unit
// direction and texels per millimetre, which turns sigma (um) into texels.

// Mirrors `FieldInfo` in src/gpu/svd2.rs. Tables are (r, value) pairs in
// `table`: alpha(r), sigma(r < 1) and sigma(r >= 1) in micrometres.
struct FieldInfo {
    // The map's texels.
    width: u32,
    height: u32,
    dilate: u32,
    // Map texels per raster texel along each side.
    step: u32,
    alpha_start: u32,
    alpha_len: u32,
    compression_start: u32,
    compression_len: u32,
    stretch_start: u32,
    stretch_len: u32,
    // The raster's texels.
    raster_width: u32,
    raster_height: u32,
    // For a window of a larger map (src/gpu/tiled.rs): the window's first
    // texel in the larger map's raster texels, the larger map's raster
    // texels, and whether it wraps (then a texel beyond its edge reads as
    // its wrapped twin does); else 0, the raster's size and 0. Bilinear
    // reads clamp at the larger map's edges, as its own chain's do.
    raster_origin: vec2<i32>,
    map_raster: vec2<i32>,
    wrap: u32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
};

// Inputs in group 1 (shared with convolve.wgsl, whose own bindings are in
// group 0 at 0-4); the outputs of `svd2_main` in group 0 at 8-9.
@group(1) @binding(0) var<uniform> info: FieldInfo;
@group(1) @binding(1) var t_tex: texture_2d<f32>;
@group(1) @binding(2) var frame_tex: texture_2d<f32>;
@group(1) @binding(3) var<storage, read> table: array<vec2<f32>>;
// Two per texel: (axis x, axis y, alpha, sigma texels) along s, then t.
@group(0) @binding(8) var<storage, read_write> passes: array<vec4<f32>>;
// (r_s, r_t) per texel.
@group(0) @binding(9) var<storage, read_write> stretch: array<vec2<f32>>;

// No axis, alpha 0: all zeros, like the CPU's PassParams::IDENTITY.
const IDENTITY = vec4<f32>(0.0, 0.0, 0.0, 0.0);

// Piecewise-linear table, constant beyond its ends (kernel.rs PiecewiseLinear::at).
fn table_at(start: u32, len: u32, r: f32) -> f32 {
    let first = table[start];
    let last = table[start + len - 1u];
    if (r <= first.x) {
        return first.y;
    }
    if (r >= last.x) {
        return last.y;
    }
    var k = start + 1u;
    for (; k < start + len - 1u; k++) {
        if (table[k].x > r) {
            break;
        }
    }
    let p0 = table[k - 1u];
    let p1 = table[k];
    return p0.y + (p1.y - p0.y) * (r - p0.x) / (p1.x - p0.x);
}

// (r_s, r_t, U angle, V angle) of T, given T - I row-major.
fn svd2(m: vec4<f32>) -> vec4<f32> {
    let e = 1.0 + 0.5 * (m.x + m.w);
    let f = 0.5 * (m.x - m.w);
    let g = 0.5 * (m.z + m.y);
    let h = 0.5 * (m.z - m.y);
    let q = sqrt(e * e + h * h);
    let p = sqrt(f * f + g * g);
    // atan2(0, 0) is 0 on the CPU; it is undefined in WGSL.
    var phi1 = 0.0;
    if (p > 0.0) {
        phi1 = atan2(g, f);
    }
    var phi2 = 0.0;
    if (q > 0.0) {
        phi2 = atan2(h, e);
    }
    return vec4<f32>(q + p, q - p, 0.5 * (phi1 + phi2), 0.5 * (phi1 - phi2));
}

// Pass parameters along an axis with texel-space direction `a` (texels per
// millimetre as its length) and stretch ratio r.
fn pass_params(a: vec2<f32>, r: f32) -> vec4<f32> {
    let per_mm = length(a);
    if (!(per_mm > 0.0) || per_mm > 3.0e38) {
        return IDENTITY;
    }
    let ra = abs(r);
    let alpha = table_at(info.alpha_start, info.alpha_len, ra);
    var sigma_um: f32;
    if (ra < 1.0) {
        sigma_um = table_at(info.compression_start, info.compression_len, ra);
    } else {
        sigma_um = table_at(info.stretch_start, info.stretch_len, ra);
    }
    return vec4<f32>(a / per_mm, alpha, sigma_um * 1.0e-3 * per_mm);
}

fn on_surface(frame: vec4<f32>) -> bool {
    return any(frame != vec4<f32>(0.0));
}

// Both passes' parameters and (r_s, r_t) of one texel.
struct TexelPasses {
    s: vec4<f32>,
    t: vec4<f32>,
    stretch: vec2<f32>,
};

// The raster texel holding the values of raster texel `coord` and its
// Q R^T: itself on the surface, else its nearest surface texel within
// `info.dilate`, else itself (off the surface, a zero frame).
struct Dilated {
    coord: vec2<i32>,
    frame: vec4<f32>,
};

fn dilated(coord: vec2<i32>) -> Dilated {
    let own = textureLoad(frame_tex, coord, 0);
    if (on_surface(own)) {
        return Dilated(coord, own);
    }
    let r = i32(info.dilate);
    var best = -1;
    var best_coord = coord;
    var best_frame = own;
    for (var dj = -r; dj <= r; dj++) {
        for (var di = -r; di <= r; di++) {
            let c = coord + vec2<i32>(di, dj);
            if (c.x < 0 || c.y < 0 || c.x >= i32(info.raster_width) || c.y >= i32(info.raster_height)) {
                continue;
            }
            let d2 = di * di + dj * dj;
            if (best < 0 || d2 < best) {
                let f = textureLoad(frame_tex, c, 0);
                if (on_surface(f)) {
                    best = d2;
                    best_coord = c;
                    best_frame = f;
                }
            }
        }
    }
    return Dilated(best_coord, best_frame);
}

// Bilinear read along one side: the lower raster texel, the upper one's
// weight, and the last raster texel the read may use.
struct Axis {
    lower: i32,
    weight: f32,
    last: i32,
};

// The read for texel `i` of this chain's map along a side whose window
// starts at raster texel `origin` of a larger map `n` raster texels long
// (CPU: coarse_neighbours, where origin = 0 and there are no copies).
fn coarse_axis(i: u32, origin: i32, n: i32) -> Axis {
    let step = i32(info.step);
    var copy = 0;
    if (info.wrap != 0u) {
        let g = i32(i) + origin * step;
        let m = n * step;
        copy = g / m;
        if (g % m != 0 && g < 0) {
            copy -= 1;
        }
    }
    let lo = copy * n - origin;
    let hi = lo + n - 1;
    let x = clamp((f32(i) + 0.5) / f32(step) - 0.5, f32(lo), f32(hi));
    let lower = min(floor(x), f32(max(hi - 1, lo)));
    return Axis(i32(lower), x - lower, hi);
}

// T - I and Q R^T at map texel `id`: its own raster texel (step 1) or the
// renormalised bilinear mix of the surface values among its four raster
// neighbours; a zero frame where there is none.
struct RasterSample {
    t: vec4<f32>,
    frame: vec4<f32>,
};

fn raster_sample(id: vec2<u32>) -> RasterSample {
    if (info.step == 1u) {
        let d = dilated(vec2<i32>(id));
        if (!on_surface(d.frame)) {
            return RasterSample(vec4<f32>(0.0), d.frame);
        }
        return RasterSample(textureLoad(t_tex, d.coord, 0), d.frame);
    }
    let ax = coarse_axis(id.x, info.raster_origin.x, info.map_raster.x);
    let ay = coarse_axis(id.y, info.raster_origin.y, info.map_raster.y);
    let last = vec2<i32>(ax.last, ay.last);
    var weight = 0.0;
    var t = vec4<f32>(0.0);
    var frame = vec4<f32>(0.0);
    for (var dy = 0; dy < 2; dy++) {
        for (var dx = 0; dx < 2; dx++) {
            let wx = select(1.0 - ax.weight, ax.weight, dx == 1);
            let wy = select(1.0 - ay.weight, ay.weight, dy == 1);
            let w = wx * wy;
            if (w > 0.0) {
                let d = dilated(min(vec2<i32>(ax.lower + dx, ay.lower + dy), last));
                if (on_surface(d.frame)) {
                    weight += w;
                    t += w * textureLoad(t_tex, d.coord, 0);
                    frame += w * d.frame;
                }
            }
        }
    }
    if (weight > 0.0) {
        return RasterSample(t / weight, frame / weight);
    }
    return RasterSample(vec4<f32>(0.0), vec4<f32>(0.0));
}

fn texel_passes(id: vec2<u32>) -> TexelPasses {
    let sample = raster_sample(id);
    let frame = sample.frame;
    if (!on_surface(frame)) {
        return TexelPasses(IDENTITY, IDENTITY, vec2<f32>(0.0));
    }
    let svd = svd2(sample.t);
    let c = cos(svd.w);
    let s = sin(svd.w);
    let size = vec2<f32>(f32(info.width), f32(info.height));
    let s_col = vec2<f32>(frame.x * c + frame.y * s, frame.z * c + frame.w * s);
    let t_col = vec2<f32>(frame.y * c - frame.x * s, frame.w * c - frame.z * s);
    return TexelPasses(pass_params(s_col * size, svd.x), pass_params(t_col * size, svd.y), svd.xy);
}

@compute @workgroup_size(16, 16)
fn svd2_main(@builtin(global_invocation_id) id: vec3<u32>) {
    if (id.x >= info.width || id.y >= info.height) {
        return;
    }
    let idx = id.y * info.width + id.x;
    let p = texel_passes(id.xy);
    passes[2u * idx] = p.s;
    passes[2u * idx + 1u] = p.t;
    stretch[idx] = p.stretch;
}
