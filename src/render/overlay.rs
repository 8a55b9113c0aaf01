//! Strain overlays (`shaders/overlay.wgsl`): the skin pass can draw the
//! stretch ratios or the stretch axes as colour in place of the skin's
//! albedo (the viewer's overlays). The colours are those of the strain
//! images ([`crate::imaging::colour`]), which are the CPU reference:
//! [`reference()`] here, [`evaluate_gpu`] runs the shader's function on the
//! GPU for the parity test.

use crate::error::Result;
use crate::gpu::{bind_group, buffers, compute_pipeline, encoder, Context};
use crate::imaging::colour::{direction_colour, diverging, srgb_to_linear};
use crate::strain::Svd2;

/// The shader's functions (prepended to the skin pass).
pub const SHADER: &str = include_str!("../../shaders/overlay.wgsl");

/// The overlays, as the skin pass's `globals.options.z` codes them.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum OverlayKind {
    /// None: the skin's albedo.
    Off = 0,
    /// r_s on the diverging map.
    Rs = 1,
    /// r_t on the diverging map.
    Rt = 2,
    /// The s axis as hue, r_s − r_t as saturation.
    Axes = 3,
}

/// The overlay's linear RGB for a vertex strain `(r_s, r_t, s_u, s_v)`
/// (the skin pass's varying), from the strain images' colour maps.
pub fn reference(kind: OverlayKind, strain: [f32; 4], range: f32) -> [f32; 3] {
    let [rs, rt, su, sv] = strain.map(f64::from);
    let rgb = match kind {
        OverlayKind::Off => return [1.0; 3],
        OverlayKind::Rs => diverging(rs, range as f64),
        OverlayKind::Rt => diverging(rt, range as f64),
        OverlayKind::Axes => {
            let svd = Svd2 {
                rs,
                rt,
                u_angle: 0.0,
                v_angle: 0.0,
            };
            direction_colour(su, sv, &svd, range as f64)
        }
    };
    rgb.0.map(|c| srgb_to_linear(c as f32 / 255.0))
}

const HARNESS: &str = r#"
@group(0) @binding(0) var<storage, read> inputs: array<vec4<f32>>;
@group(0) @binding(1) var<storage, read_write> outputs: array<vec4<f32>>;
@group(0) @binding(2) var<uniform> info: vec4<u32>;

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    if (id.x >= info.x) {
        return;
    }
    let range = bitcast<f32>(info.z);
    outputs[id.x] = vec4<f32>(strain_overlay(info.y, inputs[id.x], range), 1.0);
}
"#;

/// Evaluates the shader's `strain_overlay` for each strain on the GPU.
pub fn evaluate_gpu(
    ctx: &Context,
    kind: OverlayKind,
    strains: &[[f32; 4]],
    range: f32,
) -> Result<Vec<[f32; 3]>> {
    let source = format!("{SHADER}\n{HARNESS}");
    let pipeline = compute_pipeline(ctx, "overlay harness", &source, "main");
    let inputs = buffers::storage(ctx, "overlay inputs", strains);
    let outputs = buffers::storage_zeroed(ctx, "overlay outputs", (strains.len() * 16) as u64);
    let info = buffers::uniform(
        ctx,
        "overlay info",
        &[strains.len() as u32, kind as u32, range.to_bits(), 0],
    );
    let bind = bind_group(
        ctx,
        &pipeline.get_bind_group_layout(0),
        &[
            inputs.as_entire_binding(),
            outputs.as_entire_binding(),
            info.as_entire_binding(),
        ],
    );
    let mut enc = encoder(ctx);
    {
        let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor::default());
        pass.set_pipeline(&pipeline);
        pass.set_bind_group(0, &bind, &[]);
        pass.dispatch_workgroups(strains.len().div_ceil(64) as u32, 1, 1);
    }
    ctx.queue.submit([enc.finish()]);
    let out: Vec<[f32; 4]> = buffers::read(ctx, &outputs, strains.len())?;
    ctx.finish()?;
    Ok(out.into_iter().map(|c| [c[0], c[1], c[2]]).collect())
}
