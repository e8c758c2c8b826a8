//! The pass that turns the run time's irradiance lightmap into the radiance texture Bevy's
//! `Lightmap` samples (`shaders/bevy/lightmap_radiance.wgsl`).

use prm_gpu_kit::pipeline as kit;

/// `shaders/bevy/lightmap_radiance.wgsl`.
const WGSL: &str = include_str!("../../../shaders/bevy/lightmap_radiance.wgsl");

/// The texture format Bevy's lightmap receives: filterable, and writable from a compute pass.
pub const RADIANCE_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba16Float;

/// `E/π` from the run time's lightmap into a [`RADIANCE_FORMAT`] texture of the same size.
pub struct RadiancePass {
    pipeline: wgpu::ComputePipeline,
    /// The bind group for the last target, rebuilt when Bevy replaces the target's texture.
    bind_group: Option<(wgpu::Texture, wgpu::BindGroup)>,
}

impl RadiancePass {
    /// Builds the pipeline on `device`.
    pub fn new(device: &wgpu::Device) -> RadiancePass {
        RadiancePass {
            pipeline: kit::compute(device, "prm lightmap radiance", &[WGSL]),
            bind_group: None,
        }
    }

    /// Records the conversion of `irradiance` into `target` (which needs `STORAGE_BINDING` and
    /// the size of `irradiance`).
    pub fn encode(
        &mut self,
        device: &wgpu::Device,
        encoder: &mut wgpu::CommandEncoder,
        irradiance: &wgpu::TextureView,
        target: &wgpu::Texture,
    ) {
        if self.bind_group.as_ref().is_none_or(|(t, _)| t != target) {
            let view = target.create_view(&Default::default());
            let resources = [
                wgpu::BindingResource::TextureView(irradiance),
                wgpu::BindingResource::TextureView(&view),
            ];
            let group = kit::compute_group(device, "prm lightmap radiance", &self.pipeline, &resources);
            self.bind_group = Some((target.clone(), group));
        }
        let Some((_, group)) = &self.bind_group else { return };
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("prm lightmap radiance"),
            timestamp_writes: None,
        });
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, group, &[]);
        pass.dispatch_workgroups(target.width().div_ceil(8), target.height().div_ceil(8), 1);
    }
}
