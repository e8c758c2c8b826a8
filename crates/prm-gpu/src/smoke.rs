//! The smoke pass (`shaders/smoke.wgsl`): `y = a·x + b` on the GPU, to prove a device works end to end.

use bytemuck::{Pod, Zeroable};
use prm_gpu_kit::{pipeline, readback, ComputePass};

use crate::{GpuContext, GpuError};

/// Uniforms of the smoke pass; layout shared with WGSL.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct SmokeParams {
    /// Scale.
    pub a: f32,
    /// Offset.
    pub b: f32,
    /// Number of elements.
    pub count: u32,
    /// Padding to 16 bytes.
    pub _pad: u32,
}
const _: () = assert!(std::mem::size_of::<SmokeParams>() == 16);

/// Computes `a·x + b` for every element of `xs` on the GPU and reads the result back.
pub fn run(ctx: &GpuContext, a: f32, b: f32, xs: &[f32]) -> Result<Vec<f32>, GpuError> {
    let device = &ctx.device;
    let scope = crate::ErrorScopes::push(device);
    let params = SmokeParams {
        a,
        b,
        count: xs.len() as u32,
        _pad: 0,
    };
    let size = (xs.len().max(1) * 4) as u64;
    let uniform = pipeline::buffer_init(
        device,
        "smoke params",
        bytemuck::bytes_of(&params),
        wgpu::BufferUsages::UNIFORM,
    );
    let input = pipeline::storage(device, "smoke x", size, wgpu::BufferUsages::empty());
    ctx.queue.write_buffer(&input, 0, bytemuck::cast_slice(xs));
    let output = pipeline::storage(device, "smoke y", size, wgpu::BufferUsages::COPY_SRC);
    let pass = ComputePass::new(
        device,
        "smoke",
        &[include_str!("../../../shaders/smoke.wgsl")],
        &[
            uniform.as_entire_binding(),
            input.as_entire_binding(),
            output.as_entire_binding(),
        ],
    );
    let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("smoke") });
    pass.encode(&mut encoder, [(xs.len() as u32).div_ceil(64).max(1), 1, 1], None);
    ctx.queue.submit([encoder.finish()]);
    scope.pop("smoke")?;
    let bytes = readback::read_buffer(device, &ctx.queue, &output, size)?;
    ctx.take_uncaptured()?;
    Ok(bytemuck::cast_slice::<u8, f32>(&bytes)[..xs.len()].to_vec())
}
