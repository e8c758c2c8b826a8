//! `prm_bake`: the Precomputed Radiance Maps bake as a library call (the `prm-bake` binary is one
//! caller).
//!
//! A bake gives every surface of a static scene a lightmap atlas whose texel centres are the exit
//! points, traces random walks from sampled entry points, clusters the entry points and stores,
//! per cluster, the indirect irradiance that unit irradiance on the cluster causes at every exit
//! point, in a `.prm` archive ([`prm_format`]).
//!
//! 1. Load the scene ([`prm_scene::load`]).
//! 2. Plan: [`Plan::new`] resolves a [`BakeConfig`] (preset, sizes, budgets; every field
//!    optional) into [`BakeParams`], deriving what is unset from the scene and the budgets.
//! 3. Choose a [`Renderer`]: the CPU evaluator or an opened [`prm_gpu::GpuContext`].
//! 4. [`bake`] writes the archive atomically (nothing is left behind on failure) and returns the
//!    counts and timings ([`Baked`]), reporting its phases to a [`ProgressSink`].
//!
//! A bake can be split over machines: each runs [`bake`] with [`BakeJob::shard`] set to its
//! [`Shard`], and [`merge`] joins the partial archives into the single bake's archive.
//!
//! ```no_run
//! use std::path::Path;
//! use prm_bake::{BakeConfig, BakeJob, NoProgress, Plan, Preset, Renderer};
//!
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! let scene_path = Path::new("scenes/cornell-box/cornell-box.obj");
//! let scene = prm_scene::load(scene_path)?;
//! let config = BakeConfig {
//!     preset: Some(Preset::Preview),
//!     seed: Some(1),
//!     ..Default::default()
//! };
//! let plan = Plan::new(&config, &scene)?;
//! let job = BakeJob {
//!     scene: &scene,
//!     scene_path,
//!     plan: &plan,
//!     output: Path::new("out/cornell-box.prm"),
//!     shard: None,
//! };
//! let baked = prm_bake::bake(&job, Renderer::Cpu, &mut NoProgress)?;
//! println!("{} clusters, {} bytes", baked.clusters, baked.archive_bytes);
//! # Ok(())
//! # }
//! ```

mod archive;
mod error;
mod estimate;
pub mod params;
mod pipeline;
mod shard;
mod sink;

pub use error::BakeError;
pub use estimate::{estimate_accuracy, EstimateSize};
pub use params::{AtlasSize, BakeConfig, BakeParams, CostModel, Preset};
pub use pipeline::{
    accuracy_line, bake, BakeJob, Baked, Plan, Renderer, ACCURACY_PATHS, ACCURACY_POINTS, PROBE_CELLS, PROBE_RAYS,
    SKY_PATHS,
};
pub use shard::{merge, merge_checked, Merged, Shard};
pub use sink::{NoProgress, Phase, ProgressSink};
