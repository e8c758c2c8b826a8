//! The blend pass (`shaders/runtime/blend.wgsl`): the indirect-irradiance lightmap, Σ over the
//! kept clusters of effective weight × pane, per atlas texel.

use prm_gpu_kit::{pipeline, PassTimer};

use crate::Buffers;

/// Blends the kept panes into the lightmap.
pub(crate) struct BlendPass {
    pipeline: wgpu::ComputePipeline,
    bind_group: wgpu::BindGroup,
}

impl BlendPass {
    pub fn new(
        device: &wgpu::Device,
        b: &Buffers,
        panes: &wgpu::TextureView,
        lightmap: &wgpu::TextureView,
    ) -> BlendPass {
        let pipeline = pipeline::compute(
            device,
            "prm blend",
            &[crate::SHARED_WGSL, include_str!("../../../shaders/runtime/blend.wgsl")],
        );
        let bind_group = pipeline::compute_group(
            device,
            "prm blend",
            &pipeline,
            &[
                b.frame.as_entire_binding(),
                b.selected.as_entire_binding(),
                wgpu::BindingResource::TextureView(panes),
                wgpu::BindingResource::TextureView(lightmap),
            ],
        );
        BlendPass { pipeline, bind_group }
    }

    /// One invocation per texel of a `resolution`² lightmap.
    pub fn encode(&self, encoder: &mut wgpu::CommandEncoder, resolution: u32, timer: Option<&PassTimer>) {
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("prm blend"),
            timestamp_writes: timer.and_then(|t| t.compute("blend")),
        });
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, &self.bind_group, &[]);
        let groups = resolution.div_ceil(8);
        pass.dispatch_workgroups(groups, groups, 1);
    }
}
