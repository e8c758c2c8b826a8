//! The weights pass (`shaders/runtime/weights.wgsl`): the shadow-mapped irradiance of every entry
//! point and each cluster's weight, its members' irradiance weighed by their pane energy, and
//! its score; one workgroup per cluster.

use prm_gpu_kit::{ComputePass, PassTimer};

use crate::Buffers;

/// Computes the cluster weights.
pub(crate) struct WeightsPass(ComputePass);

fn resources<'a>(b: &'a Buffers, shadow_maps: &'a wgpu::TextureView) -> [wgpu::BindingResource<'a>; 7] {
    [
        b.frame.as_entire_binding(),
        b.lights.as_entire_binding(),
        b.views.as_entire_binding(),
        wgpu::BindingResource::TextureView(shadow_maps),
        b.clusters.as_entire_binding(),
        b.entries.as_entire_binding(),
        b.weights.as_entire_binding(),
    ]
}

impl WeightsPass {
    /// The pass, reading the shadow maps `shadow_maps` (a depth 2D array).
    pub fn new(device: &wgpu::Device, b: &Buffers, shadow_maps: &wgpu::TextureView) -> WeightsPass {
        WeightsPass(ComputePass::new(
            device,
            "weights",
            &[
                crate::SHARED_WGSL,
                crate::LIGHTS_WGSL,
                include_str!("../../../shaders/runtime/weights.wgsl"),
            ],
            &resources(b, shadow_maps),
        ))
    }

    /// Binds the pass to other (larger) shadow maps.
    pub fn rebind(&mut self, device: &wgpu::Device, b: &Buffers, shadow_maps: &wgpu::TextureView) {
        self.0.rebind(device, &resources(b, shadow_maps));
    }

    /// One workgroup per cluster (rows of 65535), reading `external` shadow maps for this frame
    /// if given, else the pass's own.
    pub fn encode(
        &self,
        device: &wgpu::Device,
        encoder: &mut wgpu::CommandEncoder,
        b: &Buffers,
        clusters: u32,
        external: Option<&wgpu::TextureView>,
        timer: Option<&PassTimer>,
    ) {
        let groups = [clusters.min(65535), clusters.div_ceil(65535), 1];
        let own = external.map(|maps| resources(b, maps));
        self.0
            .encode_on(device, encoder, own.as_ref().map(|r| &r[..]), groups, timer);
    }
}
