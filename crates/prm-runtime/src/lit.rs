//! The shape of the passes that compute direct light with `lights.wgsl` (the weights, the near
//! field's and the probe rays' radiance): bindings 0 to 3 are the frame, its lights, their
//! shadow views and the shadow maps, then the pass's own; bound to the run time's shadow maps
//! (again when they grow) or, for one frame, to a caller's.

use prm_gpu_kit::{ComputePass, PassTimer};

use crate::Buffers;

/// What the passes that read the frame's direct light record a frame with.
#[derive(Clone, Copy)]
pub(crate) struct LitFrame<'a> {
    pub device: &'a wgpu::Device,
    pub buffers: &'a Buffers,
    /// A caller's shadow maps for this frame ([`crate::Shadows::External`]), else `None`: the
    /// run time's own, bound when the passes were built.
    pub external: Option<&'a wgpu::TextureView>,
    pub timer: Option<&'a PassTimer>,
}

/// A pass's bindings after the frame's direct light.
pub(crate) trait LitBindings {
    /// The pass's own bindings, 4 onwards in the order of its WGSL.
    fn own<'a>(&'a self, b: &'a Buffers) -> Vec<wgpu::BindingResource<'a>>;

    /// Every binding of the pass on `shadow_maps`: [`Buffers::direct_light`], then its own.
    fn resources<'a>(&'a self, b: &'a Buffers, shadow_maps: &'a wgpu::TextureView) -> Vec<wgpu::BindingResource<'a>> {
        let mut r = b.direct_light(shadow_maps).to_vec();
        r.extend(self.own(b));
        r
    }
}

/// A compute pass that reads the frame's direct light, and its own bindings.
pub(crate) struct LitPass<B> {
    pass: ComputePass,
    pub bindings: B,
}

impl<B: LitBindings> LitPass<B> {
    /// The pass `name` from WGSL `parts`, on `bindings` and the shadow maps `shadow_maps`.
    pub fn new(
        device: &wgpu::Device,
        name: &'static str,
        parts: &[&str],
        bindings: B,
        b: &Buffers,
        shadow_maps: &wgpu::TextureView,
    ) -> LitPass<B> {
        let pass = ComputePass::new(device, name, parts, &bindings.resources(b, shadow_maps));
        LitPass { pass, bindings }
    }

    /// Binds the pass to other (larger) shadow maps.
    pub fn rebind(&mut self, device: &wgpu::Device, b: &Buffers, shadow_maps: &wgpu::TextureView) {
        self.pass.rebind(device, &self.bindings.resources(b, shadow_maps));
    }

    /// Records a dispatch of `workgroups`, reading the frame's external shadow maps if it has
    /// them, else the pass's own.
    pub fn encode(&self, encoder: &mut wgpu::CommandEncoder, frame: &LitFrame, workgroups: [u32; 3]) {
        let own = frame.external.map(|maps| self.bindings.resources(frame.buffers, maps));
        self.pass
            .encode_on(frame.device, encoder, own.as_deref(), workgroups, frame.timer);
    }
}

impl Buffers {
    /// The frame, its lights and shadow views and `shadow_maps`: bindings 0 to 3 of every pass
    /// that computes direct light with `lights.wgsl`.
    pub(crate) fn direct_light<'a>(&'a self, shadow_maps: &'a wgpu::TextureView) -> [wgpu::BindingResource<'a>; 4] {
        crate::DirectLight {
            frame: &self.frame,
            lights: &self.lights,
            views: &self.views,
            shadow_maps,
        }
        .resources()
    }
}
