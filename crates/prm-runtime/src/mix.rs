//! The mix pass (`shaders/runtime/mix.wgsl`): per atlas tile, the kept clusters' and residual
//! groups' coefficients summed under their effective weights, the vector the blend pass
//! ([`crate::blend`]) multiplies every basis row of the tile by. One invocation per tile and
//! four coefficients (one vec4 load per channel and kept pane), a dispatch per chunk of tiles.

use prm_gpu_kit::{linear_workgroups, ComputePass, PassTimer};

use crate::blend::Panes;
use crate::Buffers;

/// The mix: one pipeline, a bind group and dispatch per chunk of tiles.
pub(crate) struct MixPass {
    pass: ComputePass,
    chunks: Vec<(wgpu::BindGroup, [u32; 3])>,
}

impl MixPass {
    /// The pass on `b`'s frame and selection, writing `panes.mixed`; `constants` holds each
    /// chunk's [`GpuBlendChunk`](crate::GpuBlendChunk) uniform.
    pub fn new(device: &wgpu::Device, b: &Buffers, panes: &Panes, constants: &[&wgpu::Buffer]) -> MixPass {
        let mixed_stride = panes.mixed_stride();
        let resources = |c: usize| {
            [
                b.frame.as_entire_binding(),
                b.selected.as_entire_binding(),
                constants[c].as_entire_binding(),
                panes.tiles.as_entire_binding(),
                panes.chunks[c].coefficients.as_entire_binding(),
                panes.mixed.as_entire_binding(),
            ]
        };
        let pass = ComputePass::new(
            device,
            "mix",
            &[crate::SHARED_WGSL, include_str!("../../../shaders/runtime/mix.wgsl")],
            &resources(0),
        );
        let chunks = panes
            .chunks
            .iter()
            .enumerate()
            .filter(|(_, chunk)| chunk.constants.tiles > 0 && mixed_stride > 0)
            .map(|(c, chunk)| {
                let invocations = chunk.constants.tiles * mixed_stride / 4;
                (pass.group(device, &resources(c)), linear_workgroups(invocations))
            })
            .collect();
        MixPass { pass, chunks }
    }

    /// Records the mix: one compute pass, a dispatch per chunk.
    pub fn encode(&self, encoder: &mut wgpu::CommandEncoder, timer: Option<&PassTimer>) {
        if !self.chunks.is_empty() {
            self.pass.encode_groups(encoder, &self.chunks, timer);
        }
    }
}
