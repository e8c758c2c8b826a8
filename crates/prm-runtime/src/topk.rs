//! The passes after the weights, each a WGSL file after [`crate::SHARED_WGSL`] on the shared
//! buffers: rank (`shaders/runtime/rank.wgsl`), every cluster's rank by score and the score of
//! the first cluster dropped (rank K) as the fade threshold; select
//! (`shaders/runtime/select.wgsl`), the top K clusters with their weights faded near the
//! threshold, written by rank for the blend (`blend.rs`), then the residual groups' weights that
//! carry the dropped clusters' light (or, without groups, the kept weights scaled to keep it).
//! Both run one invocation per cluster.

use prm_gpu_kit::{ComputePass, PassTimer};

use crate::Buffers;

/// Ranks the clusters and keeps the top K.
pub(crate) struct TopKPasses {
    rank: ComputePass,
    select: ComputePass,
}

impl TopKPasses {
    /// The passes on `b`.
    pub fn new(device: &wgpu::Device, b: &Buffers) -> TopKPasses {
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
        }
    }

    /// Rank and select over `clusters` (workgroups of 64).
    pub fn encode(&self, encoder: &mut wgpu::CommandEncoder, clusters: u32, timer: Option<&PassTimer>) {
        let per_cluster = [clusters.div_ceil(64), 1, 1];
        self.rank.encode(encoder, per_cluster, timer);
        self.select.encode(encoder, per_cluster, timer);
    }
}
