//! CPU pane evaluator: the pane of every cluster at every exit point, by brute force.
//!
//! `pane_c(x) = Σ_{k ∈ c} Σ_{v ∈ VPLs of k} Φ_v/π · cos θ_x · cos θ_v · b(r², v) · V(x, v)` where
//! `b` is the bounded `1/r²` ([`VplBound`]) and `V` is a shadow ray ([`Bvh::visible`]); `cos θ_x`
//! uses the exit point's (shading) normal, `cos θ_v` the VPL's geometric normal. Values are
//! indirect irradiance in W/m² per W/m² of entry irradiance. At run time
//! `E_ind(x) = Σ_c weight_c · pane_c(x)` with `weight_c` the direct irradiance of the cluster's
//! members weighed by their pane energy ([`crate::Clustering::weights_by_energy`],
//! [`Panes::combine`]).
//!
//! Work is parallel over exit points; each exit point sums its VPLs in a fixed order, so the
//! result does not depend on the thread count. This is the exact yardstick for a GPU renderer.

use glam::Vec3;
use prm_scene::ExitPoint;
use rayon::prelude::*;

use crate::bvh::Bvh;
use crate::cluster::Clustering;
use crate::vpl::VplBound;
use crate::walk::VplSet;
use crate::TraceError;

/// Pane evaluation parameters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PaneParams {
    /// Singularity bound.
    pub bound: VplBound,
}

impl PaneParams {
    /// [`VplBound::DEFAULT`].
    pub const DEFAULT: PaneParams = PaneParams {
        bound: VplBound::DEFAULT,
    };
}

impl Default for PaneParams {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// The panes of all clusters over a list of exit points.
#[derive(Clone, Debug, PartialEq)]
pub struct Panes {
    /// Number of clusters.
    pub clusters: usize,
    /// Number of exit points.
    pub exits: usize,
    /// Cluster-major: `data[c * exits + i]` is cluster `c`'s pane at exit point `i`.
    pub data: Vec<Vec3>,
    /// Shadow rays cast.
    pub rays: u64,
    /// Every entry point's pane energy: the sum over `exits` of the indirect irradiance its own
    /// VPLs give (RGB), which the player weighs a cluster's members by (formats/prm.md §5.1).
    /// Empty when the producer did not compute it.
    pub entry_energy: Vec<Vec3>,
}

impl Panes {
    /// Cluster `c`'s pane, one value per exit point.
    pub fn pane(&self, c: usize) -> &[Vec3] {
        &self.data[c * self.exits..(c + 1) * self.exits]
    }

    /// `Σ_c weights[c] · pane_c` at every exit point (component-wise product).
    pub fn combine(&self, weights: &[Vec3]) -> Vec<Vec3> {
        assert_eq!(weights.len(), self.clusters, "one weight per cluster");
        (0..self.exits)
            .map(|i| {
                (0..self.clusters)
                    .map(|c| weights[c] * self.data[c * self.exits + i])
                    .sum()
            })
            .collect()
    }
}

/// Work items of [`evaluate_panes`]: the exits are cut into this many chunks (of 64 to 4096
/// exits), each keeping one energy per entry point, so the bookkeeping stays at most 256 ×
/// entries × 12 bytes while 2 cores still get 128 items each. Fixed by the exit count alone, so
/// the sums' order, hence the result, does not depend on the thread count.
const WORK_ITEMS: usize = 256;

/// Evaluates every cluster's pane at every exit point in `exits`, and every entry point's pane
/// energy.
pub fn evaluate_panes(
    bvh: &Bvh,
    vpls: &VplSet,
    clustering: &Clustering,
    exits: &[ExitPoint],
    params: &PaneParams,
) -> Result<Panes, TraceError> {
    if clustering.of_entry.len() != vpls.entries() {
        return Err(TraceError::InvalidParameter(format!(
            "clustering covers {} entry points, the VPL set {}",
            clustering.of_entry.len(),
            vpls.entries()
        )));
    }
    let c = clustering.len();
    let cluster_of_vpl: Vec<u32> = vpls
        .vpls
        .iter()
        .map(|v| clustering.of_entry[v.entry as usize])
        .collect();
    // Exits in fixed chunks, each summing its VPLs' energy too; the chunks' sums are added in
    // order, so the energies do not depend on the thread count either.
    let chunk_len = exits.len().div_ceil(WORK_ITEMS).clamp(64, 4096);
    let per_chunk: Vec<(Vec<Vec<Vec3>>, Vec<Vec3>, u64)> = exits
        .par_chunks(chunk_len)
        .map(|chunk| {
            let mut entry_energy = vec![Vec3::ZERO; vpls.entries()];
            let mut rays = 0u64;
            let accs = chunk
                .iter()
                .map(|x| {
                    let mut acc = vec![Vec3::ZERO; c];
                    let ng = bvh.geometric_normal(x.triangle);
                    for (v, &cl) in vpls.vpls.iter().zip(&cluster_of_vpl) {
                        let e = params.bound.irradiance(v, x.position, x.normal);
                        if e == Vec3::ZERO || v.position.distance_squared(x.position) == 0.0 {
                            continue;
                        }
                        rays += 1;
                        if bvh.visible(x.position, ng, x.triangle, v.position, v.normal, v.triangle) {
                            acc[cl as usize] += e;
                            entry_energy[v.entry as usize] += e;
                        }
                    }
                    acc
                })
                .collect();
            (accs, entry_energy, rays)
        })
        .collect();
    let n = exits.len();
    let mut data = vec![Vec3::ZERO; c * n];
    let mut rays = 0;
    let mut entry_energy = vec![Vec3::ZERO; vpls.entries()];
    let mut i = 0;
    for (accs, energy, r) in per_chunk {
        rays += r;
        for (total, e) in entry_energy.iter_mut().zip(energy) {
            *total += e;
        }
        for acc in accs {
            for (cl, v) in acc.into_iter().enumerate() {
                data[cl * n + i] = v;
            }
            i += 1;
        }
    }
    Ok(Panes {
        clusters: c,
        exits: n,
        data,
        rays,
        entry_energy,
    })
}
