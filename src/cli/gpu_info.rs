//! `skinpatch gpu-info`: the Vulkan adapters with the limits the stages
//! depend on, and the one a run would use.

use anyhow::bail;

use super::print_stdout;

/// Runs `skinpatch gpu-info`.
pub fn run() -> anyhow::Result<()> {
    let adapters = skinpatch::gpu::adapters();
    if adapters.is_empty() {
        bail!(
            "{}",
            skinpatch::gpu::vulkan::explain(&skinpatch::gpu::vulkan::look())
        );
    }
    let mut text = String::new();
    for (k, a) in adapters.iter().enumerate() {
        let (i, l) = (&a.info, &a.limits);
        text += &format!(
            "adapter {k}: {}\n  backend {:?}, type {:?}, vendor {:#06x}, device {:#06x}\n  driver {} {}\n",
            i.name, i.backend, i.device_type, i.vendor, i.device, i.driver, i.driver_info
        );
        text += &format!(
            "  max_texture_dimension_2d {}\n  max_storage_buffer_binding_size {}\n  max_buffer_size {}\n  \
             max_compute_workgroup_storage_size {}\n  max_compute_invocations_per_workgroup {}\n  \
             max_compute_workgroups_per_dimension {}\n",
            l.max_texture_dimension_2d,
            l.max_storage_buffer_binding_size,
            l.max_buffer_size,
            l.max_compute_workgroup_storage_size,
            l.max_compute_invocations_per_workgroup,
            l.max_compute_workgroups_per_dimension,
        );
        let names: Vec<&str> = [
            (wgpu::Features::FLOAT32_FILTERABLE, "FLOAT32_FILTERABLE"),
            (wgpu::Features::TIMESTAMP_QUERY, "TIMESTAMP_QUERY"),
            (
                wgpu::Features::TIMESTAMP_QUERY_INSIDE_ENCODERS,
                "TIMESTAMP_QUERY_INSIDE_ENCODERS",
            ),
        ]
        .into_iter()
        .filter(|(f, _)| a.features.contains(*f))
        .map(|(_, name)| name)
        .collect();
        let features = if names.is_empty() {
            "none".to_string()
        } else {
            names.join(", ")
        };
        text += &format!("  optional features used: {features}\n");
    }
    match skinpatch::gpu::Context::new() {
        Ok(ctx) => text += &format!("in use: {}\n", ctx.describe()),
        Err(e) => text += &format!("in use: none ({e})\n"),
    }
    print_stdout(&text)
}
