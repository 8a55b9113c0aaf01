// Normal histograms of kernel-fitting candidates (seed 000 eq. 7). CPU
// reference: src/micro/fit.rs (count_histograms). Rust side: src/gpu/fit.rs.
//
// Candidate c's slope at texel t is base[t] + alphas[c] * dir[t] (the
// convolved and resampled neutral map is linear in α). Its normal
// (-s, 1) / sqrt(1 + |s|^2) falls into cell floor((n + range) * bins /
// (2 range)) per tangent component, clamped to the edge cells. Each
// workgroup counts a tile of TILE texels into a workgroup histogram per
// candidate and adds its non-zero cells to the global counts (integer
// counts: the order of additions does not change the result).

// Mirrors `FitInfo` in src/gpu/fit.rs.
struct FitInfo {
    texels: u32,
    bins: u32,
    candidates: u32,
    _pad0: u32,
    range: f32,
    _pad1: f32,
    _pad2: f32,
    _pad3: f32,
};

const TILE: u32 = 4096u;
const THREADS: u32 = 256u;
// bins * bins at most (64 x 64).
const MAX_CELLS: u32 = 4096u;

@group(0) @binding(0) var<uniform> info: FitInfo;
@group(0) @binding(1) var<storage, read> base: array<vec2<f32>>;
@group(0) @binding(2) var<storage, read> dir: array<vec2<f32>>;
@group(0) @binding(3) var<storage, read> alphas: array<f32>;
// bins x bins counts per candidate, row-major by n_y then n_x.
@group(0) @binding(4) var<storage, read_write> counts: array<atomic<u32>>;

var<workgroup> local: array<atomic<u32>, MAX_CELLS>;

fn cell(c: f32) -> u32 {
    let v = (c + info.range) * (f32(info.bins) / (2.0 * info.range));
    if (v > 0.0) {
        return min(u32(v), info.bins - 1u);
    }
    return 0u;
}

@compute @workgroup_size(256)
fn main(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
    @builtin(local_invocation_index) li: u32,
) {
    let first = (wg.y * groups.x + wg.x) * TILE;
    let cells = info.bins * info.bins;
    for (var c = 0u; c < info.candidates; c++) {
        for (var k = li; k < cells; k += THREADS) {
            atomicStore(&local[k], 0u);
        }
        workgroupBarrier();
        let a = alphas[c];
        for (var k = li; k < TILE; k += THREADS) {
            let t = first + k;
            if (t < info.texels) {
                let s = base[t] + a * dir[t];
                let inv = 1.0 / sqrt(1.0 + s.x * s.x + s.y * s.y);
                atomicAdd(&local[cell(-s.y * inv) * info.bins + cell(-s.x * inv)], 1u);
            }
        }
        workgroupBarrier();
        for (var k = li; k < cells; k += THREADS) {
            let v = atomicLoad(&local[k]);
            if (v != 0u) {
                atomicAdd(&counts[c * cells + k], v);
            }
        }
        workgroupBarrier();
    }
}
