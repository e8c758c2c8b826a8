//! CPU light transport for PRM: ray casting, entry points, random walks, clustering, panes, reference.
//!
//! Flow of a bake: [`Bvh::build`] → [`sample_surface`] (entry points) → [`trace_walks`] (VPLs per
//! entry point) → [`Clustering::kmeans`] → [`evaluate_panes`] (indirect irradiance per cluster at
//! every exit point of the atlas). At run time `E_ind(x) = Σ_c weight_c · pane_c(x)` where
//! `weight_c` is the cluster's members' direct irradiance weighed by their pane energy
//! ([`entry_irradiance`], [`Clustering::weights_by_energy`], [`Panes::combine`]). The estimator and its
//! units are written out in [`walk`]. [`ReferenceTracer`] is the ground truth it is tested against;
//! [`sky_transfer_at_exits`] bakes the sky's spherical-harmonic transfer with its estimator;
//! [`check_accuracy`] is the bake's estimate of its own error against it.
//!
//! Every random decision draws from a stream keyed by `(seed, item, sub-item)` ([`Rng`]), and
//! every parallel loop writes per-item results in order, so outputs are identical for any number
//! of threads.

#![warn(missing_docs)]

pub mod buried;
pub mod bvh;
pub mod cells;
pub mod check;
pub mod cluster;
pub mod direct;
pub mod emitters;
mod error;
mod isa;
pub mod near;
pub mod near_play;
pub mod pane;
pub mod probes;
pub mod reference;
pub mod rng;
pub mod sampling;
pub mod sky;
pub mod vpl;
pub mod walk;

pub use buried::{bake_atlas, is_buried, unbury_exits, Unburied};
pub use bvh::{BuildQuality, Bvh, BvhKind, BvhParams, Hit, NO_OCCLUDER};
pub use cells::{cell_irradiance, entry_cells, reorder_cells, CELL_CANDIDATES, CELL_POINTS_PER_ENTRY};
pub use check::{area_exits, check_accuracy, check_exits, check_lights, CheckParams, CheckPoints, CheckedArchive};
pub use cluster::{archive_weights, energy_weight, ClusterParams, Clustering};
pub use direct::{bounded_irradiance, direct_irradiance, entry_irradiance};
pub use emitters::{EmitterGroup, Emitters, Receiver};
pub use error::TraceError;
pub use near::{near_disk, near_field, NEAR_RAYS};
pub use near_play::{NearPlay, NEAR_GATHERS};
pub use pane::{evaluate_atlas_panes, evaluate_panes, Lattice, PaneParams, Panes};
pub use prm_scene::{cell_reach2, parse_camera, parse_light, parse_size, SpecError, CELL_NEAR_RADII, ENTRY_DISK};
pub use probes::{place_probes, probe_rays, probe_transfer, ProbeLayout};
pub use reference::{Estimate, ImageMode, Lighting, ReferenceParams, ReferenceTracer, SKY_DIRECT_SAMPLES};
pub use rng::Rng;
pub use sampling::{cosine_hemisphere, sample_surface, sobol2, EntryParams, SurfaceSample};
pub use sky::sky_transfer_at_exits;
pub use vpl::VplBound;
pub use walk::{trace_walks, DeepDisk, Roulette, Vpl, VplSet, WalkParams, WalkStats};

/// For tests: a grey (albedo 0.5) scene of quads `[a, b, c, d]`, each split into the triangles
/// `abc` and `acd`.
#[cfg(test)]
pub(crate) fn grey_quads(quads: &[[glam::Vec3; 4]]) -> prm_scene::Scene {
    use prm_scene::{Material, Triangle};
    let tris = quads
        .iter()
        .flat_map(|&[a, b, c, d]| [Triangle::flat([a, b, c], 0), Triangle::flat([a, c, d], 0)])
        .collect();
    prm_scene::Scene::from_parts(tris, vec![Material::diffuse("grey", glam::Vec3::splat(0.5))])
}
