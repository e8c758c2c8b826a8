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

/// A buffer of `size` bytes to copy into and map for reading.
pub fn staging(device: &wgpu::Device, label: &str, size: u64) -> wgpu::Buffer {
    crate::pipeline::buffer(
        device,
        label,
        size,
        wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
    )
}

/// The first `size` bytes of `src` (which must have `COPY_SRC`).
pub fn read_buffer(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    src: &wgpu::Buffer,
    size: u64,
) -> Result<Vec<u8>, GpuError> {
    let buffer = staging(device, "readback", size);
    let mut enc = device.create_command_encoder(&Default::default());
    enc.copy_buffer_to_buffer(src, 0, &buffer, 0, size);
    queue.submit([enc.finish()]);
    map_read(device, &buffer)
}

/// Layer `layer` of `texture` (which needs `COPY_SRC`; an uncompressed colour format), its rows
/// from the top without padding.
pub fn read_texture(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    texture: &wgpu::Texture,
    layer: u32,
) -> Result<Vec<u8>, GpuError> {
    let texel = texture.format().block_copy_size(None).unwrap_or(4);
    let (w, h) = (texture.width(), texture.height());
    let (row, padded) = (w as usize * texel as usize, padded_row(w, texel));
    let buffer = staging(device, "readback", padded_size(w, h, texel));
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
    Ok((0..h as usize)
        .flat_map(|y| &bytes[y * padded as usize..y * padded as usize + row])
        .copied()
        .collect())
}

/// Layer `layer` of an `rgba32float` texture as RGBA texels (see [`read_texture`]).
pub fn read_rgba32f(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    texture: &wgpu::Texture,
    layer: u32,
) -> Result<Vec<[f32; 4]>, GpuError> {
    let bytes = read_texture(device, queue, texture, layer)?;
    Ok(bytemuck::pod_collect_to_vec(&bytes))
}
