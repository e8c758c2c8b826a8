//! The shape of a compute pass: a pipeline built from WGSL parts (entry point `main`, layout from
//! the shader), one bind group whose bindings are numbered in order, and a dispatch that times
//! itself under its name. Each pass of PRM is a named struct around one of these (or a few, for
//! small passes on the same buffers), in a file beside its WGSL file.

use crate::{pipeline, PassTimer};

/// A compute pipeline and its bind group.
pub struct ComputePass {
    name: &'static str,
    pipeline: wgpu::ComputePipeline,
    bind_group: wgpu::BindGroup,
}

impl ComputePass {
    /// The pass `name` (also its label and its [`PassTimer`] name) from WGSL `parts` joined in
    /// order, with binding `i` of group 0 bound to `resources[i]`.
    pub fn new(
        device: &wgpu::Device,
        name: &'static str,
        parts: &[&str],
        resources: &[wgpu::BindingResource],
    ) -> ComputePass {
        let pipeline = pipeline::compute(device, name, parts);
        let bind_group = pipeline::compute_group(device, name, &pipeline, resources);
        ComputePass {
            name,
            pipeline,
            bind_group,
        }
    }

    /// Binds other resources (after a buffer or texture they name was replaced).
    pub fn rebind(&mut self, device: &wgpu::Device, resources: &[wgpu::BindingResource]) {
        self.bind_group = pipeline::compute_group(device, self.name, &self.pipeline, resources);
    }

    /// A bind group of this pass's layout on other resources, for one [`encode_with`](Self::encode_with).
    pub fn group(&self, device: &wgpu::Device, resources: &[wgpu::BindingResource]) -> wgpu::BindGroup {
        pipeline::compute_group(device, self.name, &self.pipeline, resources)
    }

    /// Records a dispatch of `workgroups`, timed as `name` when `timer` is given.
    pub fn encode(&self, encoder: &mut wgpu::CommandEncoder, workgroups: [u32; 3], timer: Option<&PassTimer>) {
        self.encode_with(encoder, &self.bind_group, workgroups, timer);
    }

    /// [`encode`](Self::encode) on `resources` when given (a bind group made for this dispatch,
    /// e.g. a caller's shadow maps for one frame), else on the pass's own.
    pub fn encode_on(
        &self,
        device: &wgpu::Device,
        encoder: &mut wgpu::CommandEncoder,
        resources: Option<&[wgpu::BindingResource]>,
        workgroups: [u32; 3],
        timer: Option<&PassTimer>,
    ) {
        match resources {
            Some(r) => self.encode_with(encoder, &self.group(device, r), workgroups, timer),
            None => self.encode(encoder, workgroups, timer),
        }
    }

    /// [`encode`](Self::encode) with another bind group of this pass's layout.
    pub fn encode_with(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        bind_group: &wgpu::BindGroup,
        [x, y, z]: [u32; 3],
        timer: Option<&PassTimer>,
    ) {
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some(self.name),
            timestamp_writes: timer.and_then(|t| t.compute(self.name)),
        });
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, bind_group, &[]);
        pass.dispatch_workgroups(x, y, z);
    }
}
