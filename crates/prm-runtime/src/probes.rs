//! The probes pass (`shaders/runtime/probes.wgsl`): every probe's irradiance coefficients under
//! this frame's cluster weights, Σ_c weight_c ⊙ transfer[c][probe] over all clusters (not the
//! blend's top K, see the shader), one invocation per probe and coefficient, after the weights;
//! or, when the archive holds the probes' rays, the probe rays passes
//! ([`crate::probe_rays`]) after the blend, which gather them from the surfaces' light of the
//! frame; plus the sky's part, summed on the CPU when the sky changes
//! ([`ProbesPass::write_sky`]); and the probe volume it fills, which shaders sample with
//! [`crate::PROBES_WGSL`].
//!
//! Why the rays (`cargo xtask eval --probes`; README, *Probes*): through the panes a probe
//! sees the direct light only at the entry points, point-sampled, which put the default
//! Cornell box's probes 27% from the reference; gathered from the surfaces they see it at
//! every texel.

use prm_format::{sky_irradiance_sh, ProbeRays, ProbeSkyTransfer, Probes, SH_COEFFS};
use prm_gpu_kit::{pipeline, ComputePass};

use crate::lit::LitFrame;
use crate::probe_rays::ProbeRaysPass;
use crate::{Buffers, GpuProbeGrid, RuntimeError};

/// How the probes are lit.
enum Light {
    /// Σ over clusters of the weights times the archive's transfer.
    Panes(ComputePass),
    /// Gathered along the archive's rays.
    Rays(Box<ProbeRaysPass>),
}

/// The views the probe rays read: the shadow maps, the indirect lightmap and the baked direct
/// lightmap of emitters and sky.
pub(crate) struct RayInputs<'a> {
    pub shadow_maps: &'a wgpu::TextureView,
    pub lightmap: &'a wgpu::TextureView,
    pub baked_direct: &'a wgpu::TextureView,
    /// The archive's emitter groups.
    pub groups: usize,
}

/// What a shader needs to light moving objects from the probes with [`crate::PROBES_WGSL`]:
/// bind `grid` as `var<uniform> probe_grid: ProbeGrid`, `cells` as
/// `var<storage, read> probe_cells: array<i32>` and `coefficients` as
/// `var<storage, read> probe_sh: array<vec4<f32>>`.
pub struct ProbeVolume<'a> {
    /// The grid and probe count (uniform [`GpuProbeGrid`]).
    pub grid: &'a wgpu::Buffer,
    /// Every grid cell's probe index, or −1 where the cell is inside geometry (storage `i32`).
    pub cells: &'a wgpu::Buffer,
    /// Nine RGB coefficients per probe (storage `vec4<f32>`, `w` unused), rewritten by every
    /// [`crate::Runtime::encode`]: `E(n) = Σ_i c_i · Y_i(n)` in [`prm_format::sh_basis`].
    pub coefficients: &'a wgpu::Buffer,
    /// Each probe's world position, in the order of `coefficients`.
    pub positions: &'a [[f32; 3]],
}

impl<'a> ProbeVolume<'a> {
    /// `grid`, `cells` and `coefficients`, in that order.
    pub fn resources(&self) -> [wgpu::BindingResource<'a>; 3] {
        [
            self.grid.as_entire_binding(),
            self.cells.as_entire_binding(),
            self.coefficients.as_entire_binding(),
        ]
    }
}

/// Sums the probes' coefficients.
pub(crate) struct ProbesPass {
    light: Light,
    pub grid: wgpu::Buffer,
    pub cells: wgpu::Buffer,
    pub coefficients: wgpu::Buffer,
    /// The sky's part of every probe's coefficients (vec4 per coefficient), written by
    /// [`ProbesPass::write_sky`]; zero without a sky.
    sky: wgpu::Buffer,
    /// Each probe's position (for [`ProbeVolume`]) and the sky's transfer to the probes (for
    /// [`ProbesPass::write_sky`]); the cluster transfer lives on the device only.
    pub positions: Vec<[f32; 3]>,
    sky_transfer: Option<Vec<ProbeSkyTransfer>>,
}

impl ProbesPass {
    /// Uploads the archive's probes and their rays, or without rays their transfer; refused
    /// when the transfer or the rays exceed the device's storage binding size or dispatch.
    pub fn new(
        device: &wgpu::Device,
        b: &Buffers,
        probes: &Probes,
        rays: Option<&ProbeRays>,
        inputs: RayInputs,
    ) -> Result<ProbesPass, RuntimeError> {
        // Cluster-major arrays of nine RGB triples: the f32 layout the shader reads, as is.
        let transfer: &[u8] = bytemuck::cast_slice(&probes.transfer);
        let bytes = transfer.len() as u64;
        let max = device.limits().max_storage_buffer_binding_size;
        if rays.is_none() && bytes > max {
            return Err(RuntimeError::Probes(format!(
                "{} probes × {} clusters take {:.1} MiB of transfer, over the device's {:.1} MiB storage binding",
                probes.len(),
                probes.clusters(),
                bytes as f64 / (1 << 20) as f64,
                max as f64 / (1 << 20) as f64
            )));
        }
        let st = wgpu::BufferUsages::STORAGE;
        let g = probes.grid;
        let gpu_grid = GpuProbeGrid {
            origin: g.origin,
            spacing: g.spacing,
            dims: g.dims,
            count: probes.len() as u32,
        };
        let grid = pipeline::buffer_init(
            device,
            "prm probe grid",
            bytemuck::bytes_of(&gpu_grid),
            wgpu::BufferUsages::UNIFORM,
        );
        let mut cell_probe = vec![-1i32; g.cells() as usize];
        for (p, &c) in probes.cells.iter().enumerate() {
            cell_probe[c as usize] = p as i32;
        }
        let cells = pipeline::buffer_init(device, "prm probe cells", bytemuck::cast_slice(&cell_probe), st);
        let coefficients = pipeline::storage(
            device,
            "prm probe coefficients",
            (probes.len() * SH_COEFFS * 16) as u64,
            wgpu::BufferUsages::COPY_SRC,
        );
        let sky = pipeline::storage(
            device,
            "prm probe sky coefficients",
            (probes.len() * SH_COEFFS * 16) as u64,
            wgpu::BufferUsages::empty(),
        );
        let (light, sky_transfer) = match rays {
            Some(rays) => {
                let points = rays.points.len() as u64;
                let buffers = [
                    ("ray hits", rays.hits.len() as u64 * 4),
                    (
                        "gather points",
                        points * std::mem::size_of::<crate::GpuGatherPoint>() as u64,
                    ),
                ];
                for (what, bytes) in buffers {
                    if bytes > max {
                        return Err(RuntimeError::Probes(format!(
                            "the probes' {what} take {:.1} MiB, over the device's {:.1} MiB storage binding",
                            bytes as f64 / (1 << 20) as f64,
                            max as f64 / (1 << 20) as f64
                        )));
                    }
                }
                let pass = ProbeRaysPass::new(
                    device,
                    b,
                    rays,
                    inputs.shadow_maps,
                    inputs.lightmap,
                    inputs.baked_direct,
                    &coefficients,
                    &sky,
                    inputs.groups,
                );
                // The sky's direct light along the rays that leave the scene; its light on the
                // surfaces comes with their radiance.
                (Light::Rays(Box::new(pass)), Some(rays.sky_transfer()))
            }
            None => {
                let transfer = pipeline::buffer_init(device, "prm probe transfer", transfer, st);
                let pass = ComputePass::new(
                    device,
                    "probes",
                    &[crate::SHARED_WGSL, include_str!("../../../shaders/runtime/probes.wgsl")],
                    &[
                        b.frame.as_entire_binding(),
                        b.weights.as_entire_binding(),
                        grid.as_entire_binding(),
                        transfer.as_entire_binding(),
                        coefficients.as_entire_binding(),
                        sky.as_entire_binding(),
                    ],
                );
                (Light::Panes(pass), probes.sky.clone())
            }
        };
        Ok(ProbesPass {
            light,
            grid,
            cells,
            coefficients,
            sky,
            positions: probes.positions.clone(),
            sky_transfer,
        })
    }

    /// Whether the probes are gathered along their rays (else through the panes).
    pub fn has_rays(&self) -> bool {
        matches!(self.light, Light::Rays(_))
    }

    /// The gather points' radiance buffer and their count, when the probes have rays.
    pub fn ray_radiance(&self) -> Option<(&wgpu::Buffer, u32)> {
        match &self.light {
            Light::Rays(r) => Some(r.gathered.radiance()),
            Light::Panes(_) => None,
        }
    }

    /// Uploads the emitter groups' scales, which the probe rays' emissive gather points take.
    pub fn write_scales(&self, queue: &wgpu::Queue, scales: &[[f32; 3]]) {
        if let Light::Rays(r) = &self.light {
            r.write_scales(queue, scales);
        }
    }

    /// Binds the probe rays to other (larger) shadow maps.
    pub fn rebind(&mut self, device: &wgpu::Device, b: &Buffers, shadow_maps: &wgpu::TextureView) {
        if let Light::Rays(r) = &mut self.light {
            r.gathered.rebind(device, b, shadow_maps);
        }
    }

    /// Uploads the sky's part of the probes' coefficients under the sky `coeffs` (zeros when
    /// the archive has no sky transfer to the probes).
    pub fn write_sky(&self, queue: &wgpu::Queue, coeffs: &[[f32; 3]; SH_COEFFS]) {
        let Some(sky) = &self.sky_transfer else {
            return;
        };
        let v: Vec<[f32; 4]> = sky_irradiance_sh(sky, coeffs)
            .iter()
            .flatten()
            .map(|c| [c[0], c[1], c[2], 0.0])
            .collect();
        queue.write_buffer(&self.sky, 0, bytemuck::cast_slice(&v));
    }

    /// Through the panes one invocation per probe and coefficient (workgroups of 64), after
    /// the weights; along the rays the probe rays passes, after the blend, reading the frame's
    /// external shadow maps if it has them.
    pub fn encode(&self, encoder: &mut wgpu::CommandEncoder, frame: &LitFrame) {
        match &self.light {
            Light::Panes(pass) => {
                let slots = (self.positions.len() * SH_COEFFS) as u32;
                pass.encode(encoder, [slots.div_ceil(64), 1, 1], frame.timer);
            }
            Light::Rays(rays) => rays.gathered.encode(encoder, frame),
        }
    }
}
