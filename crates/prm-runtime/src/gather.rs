//! Gather points on the GPU: the surface points whose radiance of the frame the near field and
//! the probe rays sum ([`prm_format::GatherPoint`]), the buffer their radiance pass writes, and
//! the two passes, radiance then sum, both run.

use prm_format::GatherPoint;
use prm_gpu_kit::{linear_workgroups, pipeline, ComputePass};

use crate::lit::{LitBindings, LitFrame, LitPass};
use crate::{Buffers, GpuGatherPoint, GpuNearPoint};

/// `v`, or one default element when it is empty: a binding of zero bytes is invalid.
pub(crate) fn at_least_one<T: Default>(mut v: Vec<T>) -> Vec<T> {
    if v.is_empty() {
        v.push(T::default());
    }
    v
}

/// The gather points (at least one) and their radiance (one `vec4` each, `w` unused).
pub(crate) struct GatherPoints {
    pub points: wgpu::Buffer,
    pub radiance: wgpu::Buffer,
}

impl GatherPoints {
    /// Uploads `points` as `"{label} points"` and makes room for their radiance,
    /// `"{label} radiance"` (readable back, for tests).
    pub fn upload(device: &wgpu::Device, label: &str, points: &[GatherPoint]) -> GatherPoints {
        let gpu = points
            .iter()
            .map(|g| GpuGatherPoint {
                position: g.position,
                texel: g.texel,
                normal: g.normal,
                albedo: g.albedo,
                emitter: g.emitter,
                emission: g.emission,
                ..Default::default()
            })
            .collect();
        Self::upload_as(device, label, gpu)
    }

    /// Uploads the near field's `points` as [`GpuNearPoint`]s, which leave out what only the
    /// probes read (the emission) and pack the normal and albedo, flagging those at the texel
    /// of one of the `exits` (texels strictly increasing).
    pub fn upload_near(
        device: &wgpu::Device,
        label: &str,
        points: &[GatherPoint],
        exits: &[prm_format::NearExit],
    ) -> GatherPoints {
        let is_exit = |t: u32| exits.binary_search_by_key(&t, |x| x.texel).is_ok();
        let gpu = points.iter().map(|g| GpuNearPoint::new(g, is_exit(g.texel))).collect();
        Self::upload_as(device, label, gpu)
    }

    /// Uploads `gpu` (at least one) and makes room for its radiance.
    fn upload_as<T: bytemuck::Pod + Default>(device: &wgpu::Device, label: &str, gpu: Vec<T>) -> GatherPoints {
        let gpu = at_least_one(gpu);
        let points = pipeline::buffer_init(
            device,
            &format!("{label} points"),
            bytemuck::cast_slice(&gpu),
            wgpu::BufferUsages::STORAGE,
        );
        let radiance = pipeline::storage(
            device,
            &format!("{label} radiance"),
            gpu.len() as u64 * 16,
            wgpu::BufferUsages::COPY_SRC,
        );
        GatherPoints { points, radiance }
    }
}

/// The two passes of a gather: the radiance every gather point sends this frame (one invocation
/// per point, reading the frame's direct light), then the sum that reads it.
pub(crate) struct GatherPasses<B> {
    radiance: LitPass<B>,
    /// The buffer the radiance pass writes ([`GatherPoints::radiance`]).
    radiance_buffer: wgpu::Buffer,
    sum: ComputePass,
    point_count: u32,
    sum_workgroups: [u32; 3],
}

impl<B: LitBindings> GatherPasses<B> {
    /// The radiance pass over `point_count` gather points, writing `radiance_buffer`
    /// ([`GatherPoints::radiance`]), then `sum` dispatched as `sum_workgroups`.
    pub fn new(
        radiance_buffer: wgpu::Buffer,
        radiance: LitPass<B>,
        point_count: u32,
        sum: ComputePass,
        sum_workgroups: [u32; 3],
    ) -> GatherPasses<B> {
        GatherPasses {
            radiance,
            radiance_buffer,
            sum,
            point_count,
            sum_workgroups,
        }
    }

    /// The radiance pass's own bindings.
    pub fn bindings(&self) -> &B {
        &self.radiance.bindings
    }

    /// Gather points.
    pub fn point_count(&self) -> u32 {
        self.point_count
    }

    /// Binds the radiance pass to other (larger) shadow maps.
    pub fn rebind(&mut self, device: &wgpu::Device, b: &Buffers, shadow_maps: &wgpu::TextureView) {
        self.radiance.rebind(device, b, shadow_maps);
    }

    /// The radiance pass (one invocation per gather point, reading the frame's external shadow
    /// maps if it has them), then the sum.
    pub fn encode(&self, encoder: &mut wgpu::CommandEncoder, frame: &LitFrame) {
        self.radiance
            .encode(encoder, frame, linear_workgroups(self.point_count));
        self.sum.encode(encoder, self.sum_workgroups, frame.timer);
    }

    /// The radiance buffer (one `vec4` per gather point, `w` unused, then a placeholder when
    /// there are none) and the gather point count, for tests.
    pub fn radiance(&self) -> (&wgpu::Buffer, u32) {
        (&self.radiance_buffer, self.point_count)
    }
}
