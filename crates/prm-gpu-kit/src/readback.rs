//! Reading GPU buffers and textures back to the CPU, blocking, on the caller's device: tests,
//! exports and tools read results this way; frames never do.

use crate::GpuError;

/// Bytes of a buffer that holds a `width × height` copy of `texel_bytes`-byte texels with rows
/// padded to wgpu's copy alignment.
pub fn padded_size(width: u32, height: u32, texel_bytes: u32) -> u64 {
    padded_row(width, texel_bytes) as u64 * height as u64
}

fn padded_row(width: u32, texel_bytes: u32) -> u32 {
    let align = wgpu::COPY_BYTES_PER_ROW_ALIGNMENT;
    (width * texel_bytes).div_ceil(align) * align
}

/// Maps `buffer` (which must have `MAP_READ`) and copies it out, waiting for the device.
pub fn map_read(device: &wgpu::Device, buffer: &wgpu::Buffer) -> Result<Vec<u8>, GpuError> {
    let (tx, rx) = std::sync::mpsc::channel();
    buffer.map_async(wgpu::MapMode::Read, .., move |r| {
        let _ = tx.send(r);
    });
    device.poll(wgpu::PollType::wait_indefinitely())?;
    rx.recv().unwrap_or(Err(wgpu::BufferAsyncError))?;
    let bytes = buffer.get_mapped_range(..).map(|v| v.to_vec());
    buffer.unmap();
    bytes.map_err(|_| GpuError::Map(wgpu::BufferAsyncError))
}

fn staging(device: &wgpu::Device, size: u64) -> wgpu::Buffer {
    device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("readback"),
        size,
        usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
        mapped_at_creation: false,
    })
}

/// The first `size` bytes of `src` (which must have `COPY_SRC`).
pub fn read_buffer(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    src: &wgpu::Buffer,
    size: u64,
) -> Result<Vec<u8>, GpuError> {
    let buffer = staging(device, size);
    let mut enc = device.create_command_encoder(&Default::default());
    enc.copy_buffer_to_buffer(src, 0, &buffer, 0, size);
    queue.submit([enc.finish()]);
    map_read(device, &buffer)
}

/// Layer `layer` of a texture of 16-byte texels (`rgba32float`, which needs `COPY_SRC`), row by
/// row from the top, as RGBA.
pub fn read_rgba32f(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    texture: &wgpu::Texture,
    layer: u32,
) -> Result<Vec<[f32; 4]>, GpuError> {
    let (w, h) = (texture.width(), texture.height());
    let (row, padded) = (w as usize * 16, padded_row(w, 16));
    let buffer = staging(device, padded_size(w, h, 16));
    let mut enc = device.create_command_encoder(&Default::default());
    enc.copy_texture_to_buffer(
        wgpu::TexelCopyTextureInfo {
            texture,
            mip_level: 0,
            origin: wgpu::Origin3d { x: 0, y: 0, z: layer },
            aspect: wgpu::TextureAspect::All,
        },
        wgpu::TexelCopyBufferInfo {
            buffer: &buffer,
            layout: wgpu::TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some(padded),
                rows_per_image: Some(h),
            },
        },
        wgpu::Extent3d {
            width: w,
            height: h,
            depth_or_array_layers: 1,
        },
    );
    queue.submit([enc.finish()]);
    let bytes = map_read(device, &buffer)?;
    let mut out = Vec::with_capacity(w as usize * h as usize);
    for y in 0..h as usize {
        let start = y * padded as usize;
        out.extend(bytemuck::cast_slice::<u8, [f32; 4]>(&bytes[start..start + row]));
    }
    Ok(out)
}
