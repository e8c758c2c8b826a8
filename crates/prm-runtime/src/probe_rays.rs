//! The probe rays passes (`shaders/runtime/probe_radiance.wgsl`, `probe_rays.wgsl`), for archives
//! whose probes carry their rays: first the radiance every gather point sends this
//! frame (its direct light through the shadow maps, the lightmap's indirect light and the baked
//! direct lightmap of emitters and sky, times albedo/π, plus on emissive surfaces their
//! emission times their group's scale), then every probe's irradiance
//! coefficients summed along its rays. The probes so see the surfaces' light of the frame, as
//! the lightmap holds it, instead of the panes' VPLs, which sample the direct light at the
//! entry points only.

use prm_format::{probe_ray_direction, sh_basis, ProbeRays, SH_COEFFS, SH_COSINE_LOBE};
use prm_gpu_kit::{pipeline, ComputePass};

use crate::gather::{GatherPasses, GatherPoints};
use crate::lit::{LitBindings, LitPass};
use crate::{Buffers, GpuProbeRays};

/// The two passes and the buffers they own.
pub(crate) struct ProbeRaysPass {
    /// The radiance pass (one invocation per gather point), then the sum (one per probe).
    pub gathered: GatherPasses<RadianceBindings>,
}

/// The radiance pass's own bindings; the shadow maps and the frame's buffers come per bind group.
pub(crate) struct RadianceBindings {
    gather: GatherPoints,
    lightmap: wgpu::TextureView,
    baked_direct: wgpu::TextureView,
    /// Every emitter group's scale (`vec4`, at least one).
    scales: wgpu::Buffer,
}

impl LitBindings for RadianceBindings {
    /// The radiance pass's own bindings, in the order of `probe_radiance.wgsl`.
    fn own<'a>(&'a self, _: &'a Buffers) -> Vec<wgpu::BindingResource<'a>> {
        vec![
            self.gather.points.as_entire_binding(),
            wgpu::BindingResource::TextureView(&self.lightmap),
            wgpu::BindingResource::TextureView(&self.baked_direct),
            self.gather.radiance.as_entire_binding(),
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
        let gather = GatherPoints::upload(device, "prm gather", &rays.points);
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
                gather.radiance.as_entire_binding(),
                coefficients.as_entire_binding(),
                sky.as_entire_binding(),
            ],
        );
        let parts = [
            crate::SHARED_WGSL,
            crate::LIGHT_BINDINGS_WGSL,
            crate::LIGHTS_WGSL,
            include_str!("../../../shaders/runtime/probe_radiance.wgsl"),
        ];
        let inputs = RadianceBindings {
            gather,
            lightmap: lightmap.clone(),
            baked_direct: baked_direct.clone(),
            scales,
        };
        let radiance = LitPass::new(device, "probe radiance", &parts, inputs, b, shadow_maps);
        let probe_groups = (rays.probes() as u32).div_ceil(64);
        ProbeRaysPass {
            gathered: GatherPasses::new(
                radiance.bindings.gather.radiance.clone(),
                radiance,
                rays.points.len() as u32,
                sum,
                [probe_groups, 1, 1],
            ),
        }
    }

    /// Uploads the emitter groups' scales (one RGB each, the archive's order).
    pub fn write_scales(&self, queue: &wgpu::Queue, scales: &[[f32; 3]]) {
        if scales.is_empty() {
            return;
        }
        let v: Vec<[f32; 4]> = scales.iter().map(|s| [s[0], s[1], s[2], 0.0]).collect();
        queue.write_buffer(&self.gathered.bindings().scales, 0, bytemuck::cast_slice(&v));
    }
}
