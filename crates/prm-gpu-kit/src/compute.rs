//! The shape of a compute pass: a pipeline built from WGSL parts (entry point `main`, layout from
//! the shader), one bind group whose bindings are numbered in order, and a dispatch that times
//! itself under its name. Each pass of PRM is a named struct around one of these (or a few, for
//! small passes on the same buffers), in a file beside its WGSL file.

use crate::{pipeline, PassTimer};

/// Invocations per workgroup of a [`linear_workgroups`] dispatch (`@workgroup_size(64)`).
pub const LINEAR_GROUP_SIZE: u32 = 64;
/// Workgroups along x of a [`linear_workgroups`] dispatch: WebGPU's guaranteed
/// `maxComputeWorkgroupsPerDimension`, which lavapipe also reports.
const LINEAR_GROUPS_X: u32 = 65_535;

/// The workgroups of a dispatch of `invocations` one-dimensional items, 64 per group: one row
/// while it fits one dimension, else rows of `LINEAR_GROUPS_X` groups, so that any count a
/// storage buffer can hold dispatches at once (a large atlas's near field has millions of items,
/// more than 65 535 × 64). The shader numbers an item `gid.x + gid.y × 64 × num_workgroups.x`
/// and returns past the count (`linear_index` in `shaders/runtime/shared.wgsl`).
pub fn linear_workgroups(invocations: u32) -> [u32; 3] {
    let groups = invocations.div_ceil(LINEAR_GROUP_SIZE).max(1);
    if groups <= LINEAR_GROUPS_X {
        [groups, 1, 1]
    } else {
        [LINEAR_GROUPS_X, groups.div_ceil(LINEAR_GROUPS_X), 1]
    }
}

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

    /// One compute pass, timed as `name`, of a dispatch per `(bind group, workgroups)` in
    /// `dispatches` (bind groups of this pass's layout, made with [`group`](Self::group)): the
    /// same work over resources split across several bindings.
    pub fn encode_groups(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        dispatches: &[(wgpu::BindGroup, [u32; 3])],
        timer: Option<&PassTimer>,
    ) {
        let mut pass = self.begin(encoder, timer);
        for (group, [x, y, z]) in dispatches {
            pass.set_bind_group(0, group, &[]);
            pass.dispatch_workgroups(*x, *y, *z);
        }
    }

    /// A compute pass of this pipeline, timed as `name` when `timer` is given.
    fn begin<'e>(&self, encoder: &'e mut wgpu::CommandEncoder, timer: Option<&PassTimer>) -> wgpu::ComputePass<'e> {
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some(self.name),
            timestamp_writes: timer.and_then(|t| t.compute(self.name)),
        });
        pass.set_pipeline(&self.pipeline);
        pass
    }

    /// [`encode`](Self::encode) with another bind group of this pass's layout.
    pub fn encode_with(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        bind_group: &wgpu::BindGroup,
        [x, y, z]: [u32; 3],
        timer: Option<&PassTimer>,
    ) {
        let mut pass = self.begin(encoder, timer);
        pass.set_bind_group(0, bind_group, &[]);
        pass.dispatch_workgroups(x, y, z);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn linear_workgroups_cover_every_item_once() {
        for n in [0u32, 1, 64, 65, 65_535 * 64, 65_535 * 64 + 1, 4_903_287, u32::MAX] {
            let [x, y, z] = linear_workgroups(n);
            let dim = 1..=LINEAR_GROUPS_X;
            assert!(dim.contains(&x) && dim.contains(&y) && z == 1, "{n}: {x} {y}");
            let covered = u64::from(x) * u64::from(y) * u64::from(LINEAR_GROUP_SIZE);
            assert!(covered >= u64::from(n), "{n}: {covered}");
            // No whole row of groups beyond the count.
            assert!(
                y == 1 || (u64::from(y) - 1) * u64::from(x) * 64 < u64::from(n),
                "{n}: {x} {y}"
            );
        }
    }
}
