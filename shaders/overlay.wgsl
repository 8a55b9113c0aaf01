// Strain colour maps drawn on the skin (the viewer's overlays), the same
// colours as the strain images (src/export/strain_images.rs): stretch
// ratios on a diverging map (blue compression, grey rest, red stretch;
// 1 +/- range saturate), the s axis as hue with the anisotropy r_s - r_t
// as saturation. Outputs are linear RGB. Rust side: src/render/overlay.rs.

const OVERLAY_COMPRESSION: vec3<f32> = vec3<f32>(59.0, 76.0, 192.0);
const OVERLAY_NEUTRAL: vec3<f32> = vec3<f32>(221.0, 221.0, 221.0);
const OVERLAY_STRETCH: vec3<f32> = vec3<f32>(180.0, 4.0, 38.0);
const OVERLAY_PI: f32 = 3.14159265358979;

fn overlay_srgb_to_linear(c: vec3<f32>) -> vec3<f32> {
    let low = c / 12.92;
    let high = pow((c + 0.055) / 1.055, vec3<f32>(2.4));
    return select(high, low, c <= vec3<f32>(0.04045));
}

// sRGB colour in [0, 1] of stretch ratio r.
fn overlay_diverging(r: f32, range: f32) -> vec3<f32> {
    let x = clamp((r - 1.0) / range, -1.0, 1.0);
    let to = select(OVERLAY_STRETCH, OVERLAY_COMPRESSION, x < 0.0);
    return (OVERLAY_NEUTRAL + (to - OVERLAY_NEUTRAL) * abs(x)) / 255.0;
}

// sRGB colour in [0, 1] of hue h in [0, 1), saturation s, value 1.
fn overlay_hsv(h: f32, s: f32) -> vec3<f32> {
    let h6 = h * 6.0 - floor(h) * 6.0;
    let sector = floor(h6);
    let f = h6 - sector;
    let p = 1.0 - s;
    let q = 1.0 - s * f;
    let t = 1.0 - s * (1.0 - f);
    switch (u32(sector)) {
        case 0u: { return vec3<f32>(1.0, t, p); }
        case 1u: { return vec3<f32>(q, 1.0, p); }
        case 2u: { return vec3<f32>(p, 1.0, t); }
        case 3u: { return vec3<f32>(p, q, 1.0); }
        case 4u: { return vec3<f32>(t, p, 1.0); }
        default: { return vec3<f32>(1.0, p, q); }
    }
}

// Linear RGB of overlay `kind` (1 r_s, 2 r_t, 3 axes) for the strain
// varying (r_s, r_t, s axis in uv).
fn strain_overlay(kind: u32, strain: vec4<f32>, range: f32) -> vec3<f32> {
    var c: vec3<f32>;
    if (kind == 1u) {
        c = overlay_diverging(strain.x, range);
    } else if (kind == 2u) {
        c = overlay_diverging(strain.y, range);
    } else {
        var angle = atan2(strain.w, strain.z);
        angle = angle - floor(angle / OVERLAY_PI) * OVERLAY_PI;
        let hue = angle / OVERLAY_PI;
        c = overlay_hsv(hue, clamp((strain.x - strain.y) / range, 0.0, 1.0));
    }
    return overlay_srgb_to_linear(c);
}
