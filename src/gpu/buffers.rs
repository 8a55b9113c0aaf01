//! Buffer and texture helpers shared by the stages: creation with data,
//! and blocking read-back of buffers and textures.

use bytemuck::Pod;
use wgpu::util::DeviceExt;

use super::Context;
use crate::error::{Error, Result};

/// Usage of the stages' storage buffers: bound in shaders, filled by
/// uploads, copied out for read-back.
pub const STORAGE: wgpu::BufferUsages = wgpu::BufferUsages::STORAGE
    .union(wgpu::BufferUsages::COPY_DST)
    .union(wgpu::BufferUsages::COPY_SRC);

/// A storage buffer holding `data` (at least 16 bytes, so an empty slice
/// still binds).
pub fn storage<T: Pod>(ctx: &Context, label: &str, data: &[T]) -> wgpu::Buffer {
    let bytes: &[u8] = bytemuck::cast_slice(data);
    if bytes.len() < 16 {
        let mut padded = bytes.to_vec();
        padded.resize(16, 0);
        return init(ctx, label, &padded, STORAGE);
    }
    init(ctx, label, bytes, STORAGE)
}

/// A zero-filled storage buffer of `bytes` bytes (rounded up to 16).
pub fn storage_zeroed(ctx: &Context, label: &str, bytes: u64) -> wgpu::Buffer {
    ctx.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some(label),
        size: bytes.max(16).next_multiple_of(4),
        usage: STORAGE,
        mapped_at_creation: false,
    })
}

/// A uniform buffer holding `value`.
pub fn uniform<T: Pod>(ctx: &Context, label: &str, value: &T) -> wgpu::Buffer {
    init(
        ctx,
        label,
        bytemuck::bytes_of(value),
        wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
    )
}

/// A buffer with `usage` holding `bytes`.
pub fn init(ctx: &Context, label: &str, bytes: &[u8], usage: wgpu::BufferUsages) -> wgpu::Buffer {
    ctx.device
        .create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some(label),
            contents: bytes,
            usage,
        })
}

/// A 2D texture of `width × height` texels.
pub fn texture(
    ctx: &Context,
    label: &str,
    (width, height): (usize, usize),
    format: wgpu::TextureFormat,
    usage: wgpu::TextureUsages,
) -> wgpu::Texture {
    ctx.device.create_texture(&wgpu::TextureDescriptor {
        label: Some(label),
        size: wgpu::Extent3d {
            width: width as u32,
            height: height as u32,
            depth_or_array_layers: 1,
        },
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format,
        usage,
        view_formats: &[],
    })
}

/// A mappable buffer to copy `bytes` into for read-back.
pub fn staging(ctx: &Context, bytes: u64) -> wgpu::Buffer {
    ctx.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("read-back"),
        size: bytes.max(4).next_multiple_of(4),
        usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    })
}

/// Maps a staging buffer (after its copy was submitted), waits, and
/// returns its first `count` elements.
pub fn map_read<T: Pod>(ctx: &Context, staging: &wgpu::Buffer, count: usize) -> Result<Vec<T>> {
    let bytes = (count * std::mem::size_of::<T>()) as u64;
    let (tx, rx) = std::sync::mpsc::channel();
    let slice = staging.slice(..bytes.max(4));
    slice.map_async(wgpu::MapMode::Read, move |r| {
        let _ = tx.send(r);
    });
    ctx.finish()?;
    rx.recv()
        .map_err(|_| Error::Gpu("read-back was never mapped".into()))?
        .map_err(|e| Error::Gpu(format!("mapping a read-back buffer: {e}")))?;
    let out = {
        let view = slice
            .get_mapped_range()
            .map_err(|e| Error::Gpu(format!("reading a mapped buffer: {e}")))?;
        bytemuck::cast_slice::<u8, T>(&view[..bytes as usize]).to_vec()
    };
    staging.unmap();
    Ok(out)
}

/// Reads `count` elements of type `T` from the start of `buffer`.
pub fn read<T: Pod>(ctx: &Context, buffer: &wgpu::Buffer, count: usize) -> Result<Vec<T>> {
    let bytes = (count * std::mem::size_of::<T>()) as u64;
    let staging = staging(ctx, bytes);
    let mut encoder = ctx
        .device
        .create_command_encoder(&wgpu::CommandEncoderDescriptor::default());
    encoder.copy_buffer_to_buffer(buffer, 0, &staging, 0, bytes.next_multiple_of(4));
    ctx.queue.submit([encoder.finish()]);
    map_read(ctx, &staging, count)
}

/// Reads a 2D texture of 16-byte texels (`Rgba32Float`) row by row.
pub fn read_texture_rgba32(
    ctx: &Context,
    texture: &wgpu::Texture,
    width: usize,
    height: usize,
) -> Result<Vec<[f32; 4]>> {
    read_texture_texels(ctx, texture, width, height)
}

/// Reads a 2D texture row by row as texels of type `T` (whose size must be
/// the format's bytes per texel).
pub fn read_texture_texels<T: Pod>(
    ctx: &Context,
    texture: &wgpu::Texture,
    width: usize,
    height: usize,
) -> Result<Vec<T>> {
    let texel = std::mem::size_of::<T>();
    let row = (width * texel) as u32;
    let padded = row.next_multiple_of(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT);
    let staging = staging(ctx, padded as u64 * height as u64);
    let mut encoder = ctx
        .device
        .create_command_encoder(&wgpu::CommandEncoderDescriptor::default());
    encoder.copy_texture_to_buffer(
        texture.as_image_copy(),
        wgpu::TexelCopyBufferInfo {
            buffer: &staging,
            layout: wgpu::TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some(padded),
                rows_per_image: Some(height as u32),
            },
        },
        wgpu::Extent3d {
            width: width as u32,
            height: height as u32,
            depth_or_array_layers: 1,
        },
    );
    ctx.queue.submit([encoder.finish()]);
    let stride = padded as usize / texel;
    let words: Vec<T> = map_read(ctx, &staging, stride * height)?;
    Ok((0..height)
        .flat_map(|j| words[j * stride..j * stride + width].iter().copied())
        .collect())
}

/// Uploads a 2D texture of `format` from raw texel bytes.
pub fn upload_texture(
    ctx: &Context,
    label: &str,
    (width, height): (usize, usize),
    format: wgpu::TextureFormat,
    bytes_per_texel: usize,
    data: &[u8],
) -> wgpu::Texture {
    let usage = wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST;
    let texture = texture(ctx, label, (width, height), format, usage);
    ctx.queue.write_texture(
        wgpu::TexelCopyTextureInfo {
            texture: &texture,
            mip_level: 0,
            origin: wgpu::Origin3d::ZERO,
            aspect: wgpu::TextureAspect::All,
        },
        data,
        wgpu::TexelCopyBufferLayout {
            offset: 0,
            bytes_per_row: Some((width * bytes_per_texel) as u32),
            rows_per_image: Some(height as u32),
        },
        wgpu::Extent3d {
            width: width as u32,
            height: height as u32,
            depth_or_array_layers: 1,
        },
    );
    texture
}
