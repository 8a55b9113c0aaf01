// Texture-space irradiance (seed 001 §2.2.3, §2.5, §2.6). The top surface
// is drawn with its UVs as positions; each texel receives
//   target 0: rgb = albedo^mix * sum_lights(shadow * rho_dt(n.l) * E_l (n.l)) / pi
//                  + albedo^mix * (1 - rho_s <A>) * E_env(n) / pi
//   target 1: millimetres per texel along u and v (stretch correction)
//   target 2: rgb = light transmitted through the patch from lights behind
//             it (translucent shadow map), already summed over the profile
//   target 3: the shadow factor of light k in component k (the skin pass
//             reads it instead of filtering the shadow maps again)
// Rust side: src/render/irradiance.rs. Prepended: lighting.wgsl.

struct Varyings {
    @builtin(position) clip: vec4<f32>,
    @location(0) world: vec3<f32>,
    @location(1) normal: vec3<f32>,
    @location(2) uv: vec2<f32>,
};

struct Targets {
    @location(0) irradiance: vec4<f32>,
    @location(1) stretch: vec4<f32>,
    @location(2) transmitted: vec4<f32>,
    @location(3) shadows: vec4<f32>,
};

@vertex
fn vs_main(v: SurfaceVertex) -> Varyings {
    var out: Varyings;
    // Framebuffer row 0 is NDC y = +1; it holds v = 0.
    out.clip = vec4<f32>(2.0 * v.uv.x - 1.0, 1.0 - 2.0 * v.uv.y, 0.0, 1.0);
    out.world = v.position.xyz;
    out.normal = v.normal.xyz;
    out.uv = v.uv.xy;
    return out;
}

@fragment
fn fs_main(in: Varyings) -> Targets {
    let n = normalize(in.normal);
    let p = in.world;
    let lobes = select(globals.micro_lobes, globals.meso_lobes, globals.flags.y == 0u);
    let env_atten = select(globals.params.z, globals.params.w, globals.flags.y == 0u);
    var e = env_atten * sh_irradiance(n);
    var transmitted = vec3<f32>(0.0);
    var shadows = vec4<f32>(0.0);
    for (var k = 0u; k < globals.flags.x; k++) {
        let inc = incident(k, p);
        let nl = dot(n, inc.dir);
        if (nl > 0.0) {
            let shadow = shadow_pcf(k, p, n);
            shadows[k] = shadow;
            e += shadow * energy_factor(nl, lobes) * nl * inc.irradiance;
        } else if (globals.flags.w != 0u) {
            // Back-lit: distance through the patch to the light-facing
            // surface, and that surface's irradiance.
            let c = shadow_coords(k, p);
            if (c.z != 0.0) {
                let tsm = shadow_texel(k, c.xy);
                let d = max(inc.distance - tsm.x, 0.0);
                // Diffusion profile at distance d: R(sqrt(r^2 + d^2)) =
                // sum_i w_i exp(-d^2 / 2 v_i) G(v_i, r).
                var through = vec3<f32>(0.0);
                for (var i = 0u; i < 6u; i++) {
                    let g = globals.profile[i];
                    through += g.rgb * exp(-d * d / (2.0 * g.w));
                }
                transmitted += through * tsm.y * inc.irradiance;
            }
        }
    }
    let albedo = textureSampleLevel(albedo_map, linear_clamp, in.uv, 0.0).rgb;
    let pre = pow(albedo, vec3<f32>(globals.params.x));
    // Millimetres per texel: the UV raster steps one texel per pixel.
    let mm = vec2<f32>(length(dpdx(p)), length(dpdy(p)));
    var out: Targets;
    out.irradiance = vec4<f32>(pre * e / PI, 1.0);
    out.stretch = vec4<f32>(mm, 0.0, 1.0);
    out.transmitted = vec4<f32>(pre * transmitted / PI, 1.0);
    out.shadows = shadows;
    return out;
}
