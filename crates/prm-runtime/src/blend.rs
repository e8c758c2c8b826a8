//! The blend pass (`shaders/runtime/blend.wgsl`): the indirect-irradiance lightmap, Σ over the
//! kept clusters of effective weight × pane, one invocation per atlas texel.

use prm_gpu_kit::{ComputePass, PassTimer};

use crate::Buffers;

/// Blends the kept panes into the lightmap.
pub(crate) struct BlendPass(ComputePass);

impl BlendPass {
    pub fn new(
        device: &wgpu::Device,
        b: &Buffers,
        panes: &wgpu::TextureView,
        lightmap: &wgpu::TextureView,
    ) -> BlendPass {
        BlendPass(ComputePass::new(
            device,
            "blend",
            &[crate::SHARED_WGSL, include_str!("../../../shaders/runtime/blend.wgsl")],
            &[
                b.frame.as_entire_binding(),
                b.selected.as_entire_binding(),
                wgpu::BindingResource::TextureView(panes),
                wgpu::BindingResource::TextureView(lightmap),
            ],
        ))
    }

    /// One invocation per texel of a `resolution`² lightmap (8×8 workgroups).
    pub fn encode(&self, encoder: &mut wgpu::CommandEncoder, resolution: u32, timer: Option<&PassTimer>) {
        let groups = resolution.div_ceil(8);
        self.0.encode(encoder, [groups, groups, 1], timer);
    }
}
