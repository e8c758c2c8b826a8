//! The weights pass (`shaders/runtime/weights.wgsl`): the shadow-mapped irradiance of every entry
//! point and each cluster's weight, its members' irradiance weighed by their pane energy, and
//! its score; one workgroup per cluster.

use prm_gpu_kit::{pipeline, PassTimer};

use crate::Buffers;

/// Computes the cluster weights.
pub(crate) struct WeightsPass {
    pipeline: wgpu::ComputePipeline,
    bind_group: wgpu::BindGroup,
}

impl WeightsPass {
    /// The pass, reading the shadow maps `shadow_maps` (a depth 2D array).
    pub fn new(device: &wgpu::Device, buffers: &Buffers, shadow_maps: &wgpu::TextureView) -> WeightsPass {
        let pipeline = pipeline::compute(
            device,
            "prm weights",
            &[
                crate::SHARED_WGSL,
                crate::LIGHTS_WGSL,
                include_str!("../../../shaders/runtime/weights.wgsl"),
            ],
        );
        let bind_group = Self::group(device, &pipeline, buffers, shadow_maps);
        WeightsPass { pipeline, bind_group }
    }

    /// The bind group of this pass's pipeline on `buffers` and `shadow_maps`.
    pub fn group(
        device: &wgpu::Device,
        pipeline: &wgpu::ComputePipeline,
        b: &Buffers,
        shadow_maps: &wgpu::TextureView,
    ) -> wgpu::BindGroup {
        pipeline::compute_group(
            device,
            "prm weights",
            pipeline,
            &[
                b.frame.as_entire_binding(),
                b.lights.as_entire_binding(),
                b.views.as_entire_binding(),
                wgpu::BindingResource::TextureView(shadow_maps),
                b.clusters.as_entire_binding(),
                b.entries.as_entire_binding(),
                b.weights.as_entire_binding(),
            ],
        )
    }

    /// Binds the pass to other shadow maps.
    pub fn rebind(&mut self, device: &wgpu::Device, buffers: &Buffers, shadow_maps: &wgpu::TextureView) {
        self.bind_group = Self::group(device, &self.pipeline, buffers, shadow_maps);
    }

    /// The pipeline (for a bind group on shadow maps handed in for one frame).
    pub fn pipeline(&self) -> &wgpu::ComputePipeline {
        &self.pipeline
    }

    /// Dispatches one workgroup per cluster (rows of 65535), with `group` if given (other shadow
    /// maps) else the pass's own.
    pub fn encode(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        clusters: u32,
        group: Option<&wgpu::BindGroup>,
        timer: Option<&PassTimer>,
    ) {
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("prm weights"),
            timestamp_writes: timer.and_then(|t| t.compute("weights")),
        });
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, group.unwrap_or(&self.bind_group), &[]);
        pass.dispatch_workgroups(clusters.min(65535), clusters.div_ceil(65535), 1);
    }
}
