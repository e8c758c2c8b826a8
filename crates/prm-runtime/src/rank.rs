//! The rank pass (`shaders/runtime/rank.wgsl`): every cluster's rank by score, and the score of
//! the first cluster dropped (rank K) as the fade threshold.

use prm_gpu_kit::{pipeline, PassTimer};

use crate::Buffers;

/// Ranks the clusters.
pub(crate) struct RankPass {
    pipeline: wgpu::ComputePipeline,
    bind_group: wgpu::BindGroup,
}

impl RankPass {
    pub fn new(device: &wgpu::Device, b: &Buffers) -> RankPass {
        let pipeline = pipeline::compute(
            device,
            "prm rank",
            &[crate::SHARED_WGSL, include_str!("../../../shaders/runtime/rank.wgsl")],
        );
        let bind_group = pipeline::compute_group(
            device,
            "prm rank",
            &pipeline,
            &[
                b.frame.as_entire_binding(),
                b.weights.as_entire_binding(),
                b.ranks.as_entire_binding(),
                b.threshold.as_entire_binding(),
            ],
        );
        RankPass { pipeline, bind_group }
    }

    pub fn encode(&self, encoder: &mut wgpu::CommandEncoder, clusters: u32, timer: Option<&PassTimer>) {
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("prm rank"),
            timestamp_writes: timer.and_then(|t| t.compute("rank")),
        });
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, &self.bind_group, &[]);
        pass.dispatch_workgroups(clusters.div_ceil(64), 1, 1);
    }
}
