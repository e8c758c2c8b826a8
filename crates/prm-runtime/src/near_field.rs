//! The near field passes (`shaders/runtime/near_radiance.wgsl`, `near_field.wgsl`), for
//! archives that hold the near field (format 1.7): first the radiance every gather point sends
//! this frame from the lights' direct light (through the shadow maps, times albedo/π), then every exit point's share of what the
//! panes' VPL disk bound removes, summed along its near rays into the near lightmap the blend
//! adds. The panes' depth-0 VPLs sample the entry points' direct light with a bounded falloff,
//! which leaves inner edges and contacts too dark (issue #11); this gathers that light back.

use prm_format::NearField;
use prm_gpu_kit::{linear_workgroups, pipeline, ComputePass, PassTimer};

use crate::{Buffers, GpuGatherPoint, GpuNearExit, GpuNearField, GpuNearHit};

/// The two passes and the buffers they own.
pub(crate) struct NearFieldPass {
    radiance_pass: ComputePass,
    sum: ComputePass,
    inputs: RadianceBindings,
    exit_count: u32,
    point_count: u32,
}

/// The radiance pass's own bindings; the shadow maps and the frame's buffers come per bind group.
struct RadianceBindings {
    points: wgpu::Buffer,
    radiance: wgpu::Buffer,
    info: wgpu::Buffer,
}

impl RadianceBindings {
    /// The radiance pass's bindings, in the order of `near_radiance.wgsl`.
    fn resources<'a>(&'a self, b: &'a Buffers, shadow_maps: &'a wgpu::TextureView) -> [wgpu::BindingResource<'a>; 7] {
        [
            b.frame.as_entire_binding(),
            b.lights.as_entire_binding(),
            b.views.as_entire_binding(),
            wgpu::BindingResource::TextureView(shadow_maps),
            self.points.as_entire_binding(),
            self.radiance.as_entire_binding(),
            self.info.as_entire_binding(),
        ]
    }
}

impl NearFieldPass {
    /// Uploads the near field; the sum writes `near_map` (the atlas's size, `rgba32float`).
    pub fn new(
        device: &wgpu::Device,
        b: &Buffers,
        near: &NearField,
        shadow_maps: &wgpu::TextureView,
        near_map: &wgpu::TextureView,
    ) -> NearFieldPass {
        let st = wgpu::BufferUsages::STORAGE;
        // Never empty: a binding of zero bytes is invalid.
        fn at_least_one<T: Default>(mut v: Vec<T>) -> Vec<T> {
            if v.is_empty() {
                v.push(T::default());
            }
            v
        }
        let points = at_least_one(
            near.points
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
                .collect(),
        );
        let exits = at_least_one(
            near.exits
                .iter()
                .map(|x| GpuNearExit {
                    texel: x.texel,
                    end: x.end,
                })
                .collect(),
        );
        let hits = at_least_one(
            near.hits
                .iter()
                .map(|h| GpuNearHit {
                    point: h.point,
                    distance2: h.distance2,
                })
                .collect(),
        );
        let points_buf = pipeline::buffer_init(device, "prm near points", bytemuck::cast_slice(&points), st);
        let radiance = pipeline::storage(
            device,
            "prm near radiance",
            points.len() as u64 * 16,
            wgpu::BufferUsages::COPY_SRC,
        );
        let info = GpuNearField {
            exits: near.exits.len() as u32,
            points: near.points.len() as u32,
            disk: near.disk,
            scale: std::f32::consts::PI / near.rays_per_exit.max(1) as f32,
        };
        let info = pipeline::buffer_init(
            device,
            "prm near field",
            bytemuck::bytes_of(&info),
            wgpu::BufferUsages::UNIFORM,
        );
        let exits_buf = pipeline::buffer_init(device, "prm near exits", bytemuck::cast_slice(&exits), st);
        let hits_buf = pipeline::buffer_init(device, "prm near hits", bytemuck::cast_slice(&hits), st);
        let sum = ComputePass::new(
            device,
            "near field",
            &[
                crate::SHARED_WGSL,
                include_str!("../../../shaders/runtime/near_field.wgsl"),
            ],
            &[
                info.as_entire_binding(),
                exits_buf.as_entire_binding(),
                hits_buf.as_entire_binding(),
                radiance.as_entire_binding(),
                wgpu::BindingResource::TextureView(near_map),
            ],
        );
        let inputs = RadianceBindings {
            points: points_buf,
            radiance,
            info,
        };
        let parts = [
            crate::SHARED_WGSL,
            crate::LIGHTS_WGSL,
            include_str!("../../../shaders/runtime/near_radiance.wgsl"),
        ];
        let radiance_pass = ComputePass::new(device, "near radiance", &parts, &inputs.resources(b, shadow_maps));
        NearFieldPass {
            radiance_pass,
            sum,
            inputs,
            exit_count: near.exits.len() as u32,
            point_count: near.points.len() as u32,
        }
    }

    /// The radiance buffer (one `vec4` per gather point, `w` unused, then a placeholder when
    /// there are none) and the gather point count, for tests.
    pub fn radiance(&self) -> (&wgpu::Buffer, u32) {
        (&self.inputs.radiance, self.point_count)
    }

    /// Binds the radiance pass to other (larger) shadow maps.
    pub fn rebind(&mut self, device: &wgpu::Device, b: &Buffers, shadow_maps: &wgpu::TextureView) {
        self.radiance_pass
            .rebind(device, &self.inputs.resources(b, shadow_maps));
    }

    /// The radiance pass (one invocation per gather point, reading `external` shadow maps for
    /// this frame if given), then the sum (one per exit point with near hits).
    pub fn encode(
        &self,
        device: &wgpu::Device,
        encoder: &mut wgpu::CommandEncoder,
        b: &Buffers,
        external: Option<&wgpu::TextureView>,
        timer: Option<&PassTimer>,
    ) {
        let groups = linear_workgroups(self.point_count);
        let own = external.map(|maps| self.inputs.resources(b, maps));
        self.radiance_pass
            .encode_on(device, encoder, own.as_ref().map(|r| &r[..]), groups, timer);
        self.sum.encode(encoder, linear_workgroups(self.exit_count), timer);
    }
}
