//! The probe rays passes (`shaders/runtime/probe_radiance.wgsl`, `probe_rays.wgsl`), for archives
//! whose probes carry their rays (format 1.6): first the radiance every gather point sends this
//! frame (its direct light through the shadow maps, the lightmap's indirect light and the baked
//! direct lightmap of emitters and sky, times albedo/π, plus on emissive surfaces their
//! emission times their group's scale), then every probe's irradiance
//! coefficients summed along its rays. The probes so see the surfaces' light of the frame, as
//! the lightmap holds it, instead of the panes' VPLs, which sample the direct light at the
//! entry points only.

use prm_format::{probe_ray_direction, sh_basis, ProbeRays, SH_COEFFS, SH_COSINE_LOBE};
use prm_gpu_kit::{linear_workgroups, pipeline, ComputePass, PassTimer};

use crate::{Buffers, GpuGatherPoint, GpuProbeRays};

/// The two passes and the buffers they own.
pub(crate) struct ProbeRaysPass {
    radiance_pass: ComputePass,
    sum: ComputePass,
    inputs: RadianceBindings,
    point_count: u32,
    probe_count: u32,
}

/// The radiance pass's own bindings; the shadow maps and the frame's buffers come per bind group.
struct RadianceBindings {
    points: wgpu::Buffer,
    lightmap: wgpu::TextureView,
    baked_direct: wgpu::TextureView,
    radiance: wgpu::Buffer,
    /// Every emitter group's scale (`vec4`, at least one).
    scales: wgpu::Buffer,
}

impl RadianceBindings {
    /// The radiance pass's bindings, in the order of `probe_radiance.wgsl`.
    fn resources<'a>(&'a self, b: &'a Buffers, shadow_maps: &'a wgpu::TextureView) -> [wgpu::BindingResource<'a>; 9] {
        [
            b.frame.as_entire_binding(),
            b.lights.as_entire_binding(),
            b.views.as_entire_binding(),
            wgpu::BindingResource::TextureView(shadow_maps),
            self.points.as_entire_binding(),
            wgpu::BindingResource::TextureView(&self.lightmap),
            wgpu::BindingResource::TextureView(&self.baked_direct),
            self.radiance.as_entire_binding(),
            self.scales.as_entire_binding(),
        ]
    }
}

impl ProbeRaysPass {
    /// Uploads the rays; the sum writes `coefficients` and adds `sky` (both nine `vec4` per
    /// probe). `lightmap` is the run time's indirect lightmap, `baked_direct` the emitters' and
    /// sky's direct lightmap; `groups` the archive's emitter groups, each at scale 1 until
    /// [`ProbeRaysPass::write_scales`].
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        device: &wgpu::Device,
        b: &Buffers,
        rays: &ProbeRays,
        shadow_maps: &wgpu::TextureView,
        lightmap: &wgpu::TextureView,
        baked_direct: &wgpu::TextureView,
        coefficients: &wgpu::Buffer,
        sky: &wgpu::Buffer,
        groups: usize,
    ) -> ProbeRaysPass {
        let st = wgpu::BufferUsages::STORAGE;
        let gpu_points: Vec<GpuGatherPoint> = rays
            .points
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
        // Never empty: a binding of zero bytes is invalid.
        let gpu_points = if gpu_points.is_empty() {
            vec![GpuGatherPoint::default()]
        } else {
            gpu_points
        };
        let points = pipeline::buffer_init(device, "prm gather points", bytemuck::cast_slice(&gpu_points), st);
        let radiance = pipeline::storage(
            device,
            "prm gather radiance",
            gpu_points.len() as u64 * 16,
            wgpu::BufferUsages::COPY_SRC,
        );
        let ones = vec![[1.0f32; 4]; groups.max(1)];
        let scales = pipeline::buffer_init(
            device,
            "prm gather emitter scales",
            bytemuck::cast_slice(&ones),
            st | wgpu::BufferUsages::COPY_DST,
        );
        let m = rays.rays_per_probe;
        let solid = 4.0 * std::f32::consts::PI / m as f32;
        let basis: Vec<f32> = (0..m)
            .flat_map(|d| {
                let y = sh_basis(probe_ray_direction(d, m));
                (0..SH_COEFFS).map(move |i| y[i] * SH_COSINE_LOBE[i] * solid)
            })
            .collect();
        let basis = pipeline::buffer_init(device, "prm probe ray basis", bytemuck::cast_slice(&basis), st);
        let hits = pipeline::buffer_init(device, "prm probe ray hits", bytemuck::cast_slice(&rays.hits), st);
        let info = GpuProbeRays {
            probes: rays.probes() as u32,
            rays_per_probe: m,
            points: rays.points.len() as u32,
            ..Default::default()
        };
        let info = pipeline::buffer_init(
            device,
            "prm probe rays",
            bytemuck::bytes_of(&info),
            wgpu::BufferUsages::UNIFORM,
        );
        let sum = ComputePass::new(
            device,
            "probes",
            &[
                crate::SHARED_WGSL,
                include_str!("../../../shaders/runtime/probe_rays.wgsl"),
            ],
            &[
                info.as_entire_binding(),
                basis.as_entire_binding(),
                hits.as_entire_binding(),
                radiance.as_entire_binding(),
                coefficients.as_entire_binding(),
                sky.as_entire_binding(),
            ],
        );
        let parts = [
            crate::SHARED_WGSL,
            crate::LIGHTS_WGSL,
            include_str!("../../../shaders/runtime/probe_radiance.wgsl"),
        ];
        let inputs = RadianceBindings {
            points,
            lightmap: lightmap.clone(),
            baked_direct: baked_direct.clone(),
            radiance,
            scales,
        };
        let radiance_pass = ComputePass::new(device, "probe radiance", &parts, &inputs.resources(b, shadow_maps));
        ProbeRaysPass {
            radiance_pass,
            sum,
            inputs,
            point_count: rays.points.len() as u32,
            probe_count: rays.probes() as u32,
        }
    }

    /// Binds the radiance pass to other (larger) shadow maps.
    pub fn rebind(&mut self, device: &wgpu::Device, b: &Buffers, shadow_maps: &wgpu::TextureView) {
        self.radiance_pass
            .rebind(device, &self.inputs.resources(b, shadow_maps));
    }

    /// The radiance pass (one invocation per gather point, reading `external` shadow maps for
    /// this frame if given), then the sum (one per probe).
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
        self.sum.encode(encoder, [self.probe_count.div_ceil(64), 1, 1], timer);
    }

    /// Uploads the emitter groups' scales (one RGB each, the archive's order).
    pub fn write_scales(&self, queue: &wgpu::Queue, scales: &[[f32; 3]]) {
        if scales.is_empty() {
            return;
        }
        let v: Vec<[f32; 4]> = scales.iter().map(|s| [s[0], s[1], s[2], 0.0]).collect();
        queue.write_buffer(&self.inputs.scales, 0, bytemuck::cast_slice(&v));
    }

    /// The radiance buffer (one `vec4` per gather point, `w` unused, then a placeholder when
    /// there are none) and the gather point count, for tests.
    pub fn radiance(&self) -> (&wgpu::Buffer, u32) {
        (&self.inputs.radiance, self.point_count)
    }
}
