//! The smoke pass (`shaders/smoke.wgsl`): `y = a·x + b` on the GPU, to prove a device works end to end.

use bytemuck::{Pod, Zeroable};
use wgpu::util::DeviceExt;

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
    let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some("smoke"),
        source: wgpu::ShaderSource::Wgsl(include_str!("../../../shaders/smoke.wgsl").into()),
    });
    let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
        label: Some("smoke"),
        layout: None,
        module: &module,
        entry_point: Some("main"),
        compilation_options: Default::default(),
        cache: None,
    });
    let params = SmokeParams {
        a,
        b,
        count: xs.len() as u32,
        _pad: 0,
    };
    let size = (xs.len().max(1) * 4) as u64;
    let uniform = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("smoke params"),
        contents: bytemuck::bytes_of(&params),
        usage: wgpu::BufferUsages::UNIFORM,
    });
    let input = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("smoke x"),
        size,
        usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    ctx.queue.write_buffer(&input, 0, bytemuck::cast_slice(xs));
    let output = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("smoke y"),
        size,
        usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
        mapped_at_creation: false,
    });
    let readback = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("smoke readback"),
        size,
        usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some("smoke"),
        layout: &pipeline.get_bind_group_layout(0),
        entries: &[
            wgpu::BindGroupEntry {
                binding: 0,
                resource: uniform.as_entire_binding(),
            },
            wgpu::BindGroupEntry {
                binding: 1,
                resource: input.as_entire_binding(),
            },
            wgpu::BindGroupEntry {
                binding: 2,
                resource: output.as_entire_binding(),
            },
        ],
    });
    let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("smoke") });
    {
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("smoke"),
            timestamp_writes: None,
        });
        pass.set_pipeline(&pipeline);
        pass.set_bind_group(0, &bind_group, &[]);
        pass.dispatch_workgroups((xs.len() as u32).div_ceil(64).max(1), 1, 1);
    }
    encoder.copy_buffer_to_buffer(&output, 0, &readback, 0, size);
    ctx.queue.submit([encoder.finish()]);
    scope.pop("smoke")?;
    let bytes = ctx.read_buffer(&readback)?;
    Ok(bytemuck::cast_slice::<u8, f32>(&bytes)[..xs.len()].to_vec())
}
