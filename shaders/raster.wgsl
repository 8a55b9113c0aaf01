// Raster of the surface deformation field into UV textures.
// CPU reference: src/strain/raster.rs. Rust side: src/gpu/raster.rs.
//
// Each surface triangle is drawn with its UVs as positions: texel (i, j) of a
// width x height target covers u in [i, i+1)/width, v in [j, j+1)/height, with
// row 0 at v = 0, and the rasteriser samples at texel centres, as the CPU
// raster does. The per-vertex 2x2 matrices T - I and Q R^T (row-major in a
// vec4) are interpolated linearly (w = 1, so perspective correction is
// exact). T - I rather than T keeps full f32 precision in the small
// deviations that fix the principal axes.
// Targets are cleared to zero: a zero Q R^T marks a texel off the surface.

// Mirrors `RasterVertex` in src/gpu/raster.rs.
struct RasterVertex {
    @location(0) uv: vec2<f32>,
    @location(1) t: vec4<f32>,
    @location(2) frame: vec4<f32>,
};

struct Varyings {
    @builtin(position) position: vec4<f32>,
    @location(0) t: vec4<f32>,
    @location(1) frame: vec4<f32>,
};

struct Targets {
    @location(0) t: vec4<f32>,
    @location(1) frame: vec4<f32>,
};

@vertex
fn vs_main(v: RasterVertex) -> Varyings {
    var out: Varyings;
    // Framebuffer row 0 is NDC y = +1; it must hold v = 0.
    out.position = vec4<f32>(2.0 * v.uv.x - 1.0, 1.0 - 2.0 * v.uv.y, 0.0, 1.0);
    out.t = v.t;
    out.frame = v.frame;
    return out;
}

@fragment
fn fs_main(in: Varyings) -> Targets {
    return Targets(in.t, in.frame);
}
