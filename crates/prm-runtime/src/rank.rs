//! The rank pass (`shaders/runtime/rank.wgsl`): every cluster's rank by score, and the score of
//! the first cluster dropped (rank K) as the fade threshold; one invocation per cluster.

use prm_gpu_kit::{ComputePass, PassTimer};

use crate::Buffers;

/// Ranks the clusters.
pub(crate) struct RankPass(ComputePass);

impl RankPass {
    pub fn new(device: &wgpu::Device, b: &Buffers) -> RankPass {
        RankPass(ComputePass::new(
            device,
            "rank",
            &[crate::SHARED_WGSL, include_str!("../../../shaders/runtime/rank.wgsl")],
            &[
                b.frame.as_entire_binding(),
                b.weights.as_entire_binding(),
                b.ranks.as_entire_binding(),
                b.threshold.as_entire_binding(),
            ],
        ))
    }

    pub fn encode(&self, encoder: &mut wgpu::CommandEncoder, clusters: u32, timer: Option<&PassTimer>) {
        self.0.encode(encoder, [clusters.div_ceil(64), 1, 1], timer);
    }
}
