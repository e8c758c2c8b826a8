//! The passes after the weights, each a WGSL file after [`crate::SHARED_WGSL`] on the shared
//! buffers: rank (`shaders/runtime/rank.wgsl`), every cluster's rank by score and the score of
//! the first cluster dropped (rank K) as the fade threshold; select
//! (`shaders/runtime/select.wgsl`), the top K clusters with their weights faded near the
//! threshold, written by rank for the blend, then the residual groups' weights that carry the
//! dropped clusters' light (or, without groups, the kept weights scaled to keep it); blend
//! (`shaders/runtime/blend.wgsl`), the indirect-irradiance lightmap, Σ over the kept clusters
//! and the residual groups of effective weight × pane. Rank and select run one invocation per cluster, blend
//! one per lit atlas texel (a list built at load: 70% of the Cornell box's 256² atlas, the rest
//! gutters no pane lights).

use prm_gpu_kit::{linear_workgroups, pipeline, ComputePass, PassTimer};

use crate::Buffers;

/// Ranks the clusters, keeps the top K and blends their panes into the lightmap.
pub(crate) struct TopKPasses {
    rank: ComputePass,
    select: ComputePass,
    blend: ComputePass,
    /// The lit texels' row-major indices, which the blend pass reads (kept alive here).
    _lit: wgpu::Buffer,
}

impl TopKPasses {
    /// The passes on `b`, blending the pane array `panes` into `lightmap`, plus the emitters'
    /// traced indirect lightmap `emitted` and the near field's lightmap `near` (each used only
    /// when it has the lightmap's size), at the `lit` texels (row-major indices).
    pub fn new(
        device: &wgpu::Device,
        b: &Buffers,
        panes: &wgpu::TextureView,
        lightmap: &wgpu::TextureView,
        emitted: &wgpu::TextureView,
        near: &wgpu::TextureView,
        lit: &[u32],
    ) -> TopKPasses {
        let lit = pipeline::buffer_init(
            device,
            "prm lit texels",
            bytemuck::cast_slice(lit),
            wgpu::BufferUsages::STORAGE,
        );
        let pass = |name, wgsl, resources: &[wgpu::BindingResource]| {
            ComputePass::new(device, name, &[crate::SHARED_WGSL, wgsl], resources)
        };
        let ranked = [
            b.frame.as_entire_binding(),
            b.weights.as_entire_binding(),
            b.ranks.as_entire_binding(),
            b.threshold.as_entire_binding(),
        ];
        let selected = [
            b.selected.as_entire_binding(),
            b.effective.as_entire_binding(),
            b.clusters.as_entire_binding(),
            b.group_energy.as_entire_binding(),
        ];
        TopKPasses {
            rank: pass("rank", include_str!("../../../shaders/runtime/rank.wgsl"), &ranked),
            select: pass(
                "select",
                include_str!("../../../shaders/runtime/select.wgsl"),
                &[ranked.as_slice(), &selected].concat(),
            ),
            blend: pass(
                "blend",
                include_str!("../../../shaders/runtime/blend.wgsl"),
                &[
                    b.frame.as_entire_binding(),
                    b.selected.as_entire_binding(),
                    wgpu::BindingResource::TextureView(panes),
                    wgpu::BindingResource::TextureView(lightmap),
                    wgpu::BindingResource::TextureView(emitted),
                    wgpu::BindingResource::TextureView(near),
                    lit.as_entire_binding(),
                ],
            ),
            _lit: lit,
        }
    }

    /// Rank and select over `clusters` (workgroups of 64), then blend the `lit` texels
    /// (workgroups of 64 in rows).
    pub fn encode(&self, encoder: &mut wgpu::CommandEncoder, clusters: u32, lit: u32, timer: Option<&PassTimer>) {
        let per_cluster = [clusters.div_ceil(64), 1, 1];
        self.rank.encode(encoder, per_cluster, timer);
        self.select.encode(encoder, per_cluster, timer);
        self.blend.encode(encoder, linear_workgroups(lit), timer);
    }
}
