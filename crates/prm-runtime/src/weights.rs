//! The weights pass (`shaders/runtime/weights.wgsl`): the shadow-mapped irradiance of every entry
//! point and each cluster's weight, its members' irradiance weighed by their pane energy, and
//! its score; one workgroup per cluster.

use crate::lit::{LitBindings, LitFrame, LitPass};
use crate::Buffers;

/// Computes the cluster weights.
pub(crate) struct WeightsPass(LitPass<WeightsBindings>);

/// The pass's bindings after the direct light's: the clusters, the entries, their cell points
/// and the weights, all shared buffers.
pub(crate) struct WeightsBindings;

impl LitBindings for WeightsBindings {
    fn own<'a>(&'a self, b: &'a Buffers) -> Vec<wgpu::BindingResource<'a>> {
        vec![
            b.clusters.as_entire_binding(),
            b.entries.as_entire_binding(),
            b.cell_points.as_entire_binding(),
            b.weights.as_entire_binding(),
        ]
    }
}

impl WeightsPass {
    /// The pass, reading the shadow maps `shadow_maps` (a depth 2D array).
    pub fn new(device: &wgpu::Device, b: &Buffers, shadow_maps: &wgpu::TextureView) -> WeightsPass {
        let parts = [
            crate::SHARED_WGSL,
            crate::LIGHTS_WGSL,
            include_str!("../../../shaders/runtime/weights.wgsl"),
        ];
        WeightsPass(LitPass::new(device, "weights", &parts, WeightsBindings, b, shadow_maps))
    }

    /// Binds the pass to other (larger) shadow maps.
    pub fn rebind(&mut self, device: &wgpu::Device, b: &Buffers, shadow_maps: &wgpu::TextureView) {
        self.0.rebind(device, b, shadow_maps);
    }

    /// One workgroup per cluster (rows of 65535), reading the frame's external shadow maps if
    /// it has them, else the pass's own.
    pub fn encode(&self, encoder: &mut wgpu::CommandEncoder, frame: &LitFrame, clusters: u32) {
        let groups = [clusters.min(65535), clusters.div_ceil(65535), 1];
        self.0.encode(encoder, frame, groups);
    }
}
