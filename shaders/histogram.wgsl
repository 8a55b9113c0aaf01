// Histogram of the tangent-plane normal components (DESIGN §5.4, seed 000
// §4). CPU reference: src/micro/normals.rs (NormalHistogram::of). Rust
// side: src/gpu/histogram.rs. Needs map.wgsl.
//
// Each texel's (n_x, n_y) falls into cell floor((c + range) / (2 range) * bins)
// per component, clamped to the edge cells; counts are added atomically
// (integer counts: the order of additions does not change the result).

// Mirrors `HistogramInfo` in src/gpu/histogram.rs.
struct HistogramInfo {
    bins: u32,
    // First count of this histogram in `counts` (batched histograms).
    offset: u32,
    _pad0: u32,
    _pad1: u32,
    range: f32,
    _pad2: f32,
    _pad3: f32,
    _pad4: f32,
};

@group(0) @binding(0) var<uniform> map: MapInfo;
@group(0) @binding(1) var<storage, read> src: array<f32>;
@group(0) @binding(2) var<uniform> hist: HistogramInfo;
// bins x bins counts per histogram, row-major by n_y then n_x.
@group(0) @binding(3) var<storage, read_write> counts: array<atomic<u32>>;

fn cell(c: f32) -> u32 {
    let x = floor((c + hist.range) / (2.0 * hist.range) * f32(hist.bins));
    return u32(clamp(x, 0.0, f32(hist.bins) - 1.0));
}

@compute @workgroup_size(16, 16)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    if (id.x >= map.width || id.y >= map.height) {
        return;
    }
    let n = normal_of(slope(i32(id.x), i32(id.y)));
    atomicAdd(&counts[hist.offset + cell(n.y) * hist.bins + cell(n.x)], 1u);
}
