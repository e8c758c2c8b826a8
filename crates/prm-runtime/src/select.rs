//! The select pass (`shaders/runtime/select.wgsl`): the top K clusters with their weights faded
//! near the threshold and scaled to keep the dropped clusters' energy, written by rank for the
//! blend pass; one invocation per cluster.

use prm_gpu_kit::{ComputePass, PassTimer};

use crate::Buffers;

/// Keeps the top K.
pub(crate) struct SelectPass(ComputePass);

impl SelectPass {
    pub fn new(device: &wgpu::Device, b: &Buffers) -> SelectPass {
        SelectPass(ComputePass::new(
            device,
            "select",
            &[crate::SHARED_WGSL, include_str!("../../../shaders/runtime/select.wgsl")],
            &[
                b.frame.as_entire_binding(),
                b.weights.as_entire_binding(),
                b.ranks.as_entire_binding(),
                b.threshold.as_entire_binding(),
                b.selected.as_entire_binding(),
                b.effective.as_entire_binding(),
            ],
        ))
    }

    pub fn encode(&self, encoder: &mut wgpu::CommandEncoder, clusters: u32, timer: Option<&PassTimer>) {
        self.0.encode(encoder, [clusters.div_ceil(64), 1, 1], timer);
    }
}
