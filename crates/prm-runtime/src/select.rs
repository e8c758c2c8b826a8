//! The select pass (`shaders/runtime/select.wgsl`): the top K clusters with their weights faded
//! near the threshold and scaled to keep the dropped clusters' energy, written by rank for the
//! blend pass.

use prm_gpu_kit::{pipeline, PassTimer};

use crate::Buffers;

/// Keeps the top K.
pub(crate) struct SelectPass {
    pipeline: wgpu::ComputePipeline,
    bind_group: wgpu::BindGroup,
}

impl SelectPass {
    pub fn new(device: &wgpu::Device, b: &Buffers) -> SelectPass {
        let pipeline = pipeline::compute(
            device,
            "prm select",
            &[crate::SHARED_WGSL, include_str!("../../../shaders/runtime/select.wgsl")],
        );
        let bind_group = pipeline::compute_group(
            device,
            "prm select",
            &pipeline,
            &[
                b.frame.as_entire_binding(),
                b.weights.as_entire_binding(),
                b.ranks.as_entire_binding(),
                b.threshold.as_entire_binding(),
                b.selected.as_entire_binding(),
                b.effective.as_entire_binding(),
            ],
        );
        SelectPass { pipeline, bind_group }
    }

    pub fn encode(&self, encoder: &mut wgpu::CommandEncoder, clusters: u32, timer: Option<&PassTimer>) {
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("prm select"),
            timestamp_writes: timer.and_then(|t| t.compute("select")),
        });
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, &self.bind_group, &[]);
        pass.dispatch_workgroups(clusters.div_ceil(64), 1, 1);
    }
}
