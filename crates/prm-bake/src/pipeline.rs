//! The bake pipeline: atlas → BVH → entry points → walks → clusters → panes → `.prm` archive.

use glam::Vec3;
use prm_format::ArchiveWriter;
use prm_gpu::{GpuContext, PaneInputs, PaneOutput, PaneRenderParams};
use prm_scene::{Atlas, AtlasParams, AtlasStats, MergeNearHits, Scene, Sizing};
use prm_trace::pane::Lattice;
use prm_trace::{
    Bvh, BvhParams, Clustering, DeepDisk, Emitters, EntryParams, Lighting, PaneParams, Receiver, ReferenceParams,
    ReferenceTracer, SurfaceSample, VplSet, WalkParams,
};
use std::cell::OnceCell;
use std::collections::BTreeMap;
use std::path::Path;
use std::time::Instant;

use rayon::prelude::*;

use crate::archive::{archive_tables, metadata, MadeDirs};
use crate::params::{AtlasSize, BakeConfig, BakeParams, CostModel};
use crate::shard::Shard;
use crate::sink::{Phase, ProgressSink};
use crate::BakeError;

/// Largest atlas the archive format holds, texels on a side.
const MAX_ATLAS_RESOLUTION: u32 = 8192;

/// Two-strategy emitter samples per entry point and exit point and emitter group
/// ([`Emitters::group_irradiance`]). With 256, the McGuire Cornell box's lamp-only direct
/// lightmap is 1.2% from the reference's (4× downsampled), and the bake spends 3.4 s on it (2 cores).
pub const EMITTER_SAMPLES: u32 = 256;

/// Paths per exit point of an emitter group's traced indirect lightmap (the reference tracer's
/// estimator, with only that group emitting). Measured (`cargo xtask eval --emitters`): McGuire's
/// CornellBox-Original by its own lamp, default bake, indirect image 3.7% from the reference
/// (energy 0.999) where the same group through the panes gave 11.4% (energy 1.000): the panes'
/// walk noise and clustering, at 8 walks per entry, cost more than 256 paths' noise once a
/// texel's is averaged over an image. The price is about 6 s per group on that 256² atlas (two
/// cores), against 2.5 s for its direct light.
pub const EMITTER_INDIRECT_SPP: u32 = 256;

/// Most paths (exit points × [`EMITTER_INDIRECT_SPP`]) an emitter group's indirect lightmap may
/// take, about 30 s per group on two cores; beyond, the group's indirect light comes from the
/// panes (through its entry irradiance), whose cost does not grow with the atlas.
pub const EMITTER_INDIRECT_MAX_PATHS: u64 = 1 << 26;

/// The fewest paths per texel the plan gives the sky's transfer (`prm-bake bake --sky` without
/// `--sky-paths`), doubled up to [`crate::params::MAX_AUTO_SKY_PATHS`] while the planned bake and
/// the sky step fit the time budget; its indirect part is then smoothed over 5 × 5 texels of its
/// chart ([`prm_trace::sky::smooth_transfer`]). Measured (`cargo xtask eval --sky`, two cores):
/// on the Dabrovic Sponza the sky step takes 21–29 s at 256 paths and its indirect image is
/// 9.2% from the reference under a uniform sky (11.2% smoothed over 3 × 3 texels); 1024 paths
/// take 91–123 s for 6.2%. On our courtyard the step takes 1.4–1.9 s for 3.3%. The plan does
/// not shrink the panes for the step (README, *Sky*: counting it at Sponza's 60 s budget shrank
/// the atlas to 224² or, at 512², the entry points to 1024); it only spends what they leave.
pub const SKY_PATHS: u32 = 256;

/// The command line's probe budget (`prm-bake bake --probes`), grid cells: on our Cornell box
/// (0.56 m) 8 × 8 × 8 cells of 7 cm, 473 probes (39 cells fall inside the blocks), whose
/// transfer takes 0.3 s (one shadow ray per probe and VPL, 4.4 M for its 10,668 VPLs).
pub const PROBE_CELLS: u32 = 512;

/// Paths per probe of the sky's transfer to the probes (bakes with `--sky` and `--probes`): 16
/// times a texel's [`SKY_PATHS`], since a probe gathers over the whole sphere and its 81
/// coefficients are not smoothed, while the probes are few (512 probes cost what 8192 texels
/// do). Measured (`cargo xtask eval --probes`): the courtyard's 488 probes take 1.5 s with it
/// (against 0.3–0.5 s without a sky elsewhere) and are 3.0% from the reference under a uniform
/// sky.
pub const PROBE_SKY_PATHS: u32 = 4096;

/// Rays per probe of the probe rays section (`--probe-rays`): the directions along which the
/// run time gathers each probe's light from the surfaces' radiance of the frame. Measured
/// (`cargo xtask eval --probes`, error against the reference at the probe positions, 2048 rays
/// in parentheses): Cornell box 2.95% (2.90%), with 8192 entries 3.01% (2.98%), two rooms 3.54%
/// (3.52%), courtyard under the sky 0.99% (0.94%); the hits take 4 bytes a ray (the default
/// Cornell box's section: 1.2 MB stored, 2.1 MB at 2048), and the gather points, which cost the frame,
/// stay about 42,000 either way.
pub const PROBE_RAYS: u32 = 1024;

/// Points of the bake's accuracy check by default (`--accuracy-points`), each a patch of 3×3
/// texels traced with [`ACCURACY_PATHS`] reference paths in all for each test light: three clear
/// of surfaces and one close under the ceiling ([`prm_trace::check`], which gives the
/// measurements: at 512 points the estimate moved by a factor of three between draws).
pub const ACCURACY_POINTS: u32 = prm_trace::CheckParams::DEFAULT.exit_points;

/// Reference paths per checked point (shared by its patch's texels) and light.
pub const ACCURACY_PATHS: u32 = prm_trace::CheckParams::DEFAULT.paths;

/// Where the panes are rendered.
#[derive(Clone, Copy)]
pub enum Renderer<'a> {
    /// The native CPU pane evaluator: ray-cast visibility shared between neighbouring texels
    /// ([`prm_trace::pane::Lattice::DEFAULT`]). Faster than lavapipe on machines without a GPU.
    Cpu,
    /// The CPU pane evaluator with one shadow ray per exit point and VPL: the exact yardstick.
    CpuExact,
    /// The GPU pane passes on an opened device (check it with [`prm_gpu::check_support`]).
    Gpu(&'a GpuContext),
}

impl std::fmt::Debug for Renderer<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Renderer::Cpu => f.write_str("Cpu"),
            Renderer::CpuExact => f.write_str("CpuExact"),
            Renderer::Gpu(ctx) => f.debug_tuple("Gpu").field(&ctx.describe()).finish(),
        }
    }
}

impl Renderer<'_> {
    /// "cpu", "cpu-exact", or the device's description; recorded in the archive's parameters as
    /// `backend`.
    pub fn name(&self) -> String {
        match self {
            Renderer::Cpu => "cpu".to_string(),
            Renderer::CpuExact => "cpu-exact".to_string(),
            Renderer::Gpu(ctx) => ctx.describe(),
        }
    }

    /// What the bake's time budget and expected time are computed with. A hardware GPU gets
    /// lavapipe's model, which overestimates it (none has been measured here).
    pub fn cost_model(&self) -> CostModel {
        match self {
            Renderer::Cpu => CostModel::CPU,
            Renderer::CpuExact => CostModel::CPU_EXACT,
            Renderer::Gpu(_) => CostModel::GPU,
        }
    }
}

/// Resolved parameters for one scene, with the automatic atlas if planning had to build it (the
/// bake then reuses it instead of building it again).
#[derive(Clone, Debug)]
pub struct Plan {
    /// The parameters the bake will use, and why.
    pub params: BakeParams,
    probed_atlas: Option<Atlas>,
}

impl Plan {
    /// Resolves `config` for `scene` ([`BakeParams::resolve`]) with the cost model of the CPU
    /// renderer, the default where there is no hardware GPU; [`Plan::for_renderer`] plans for
    /// another. Builds the automatic atlas at most once and only if the parameters need it.
    pub fn new(config: &BakeConfig, scene: &Scene) -> Result<Plan, BakeError> {
        Plan::for_renderer(config, scene, &Renderer::Cpu)
    }

    /// [`Plan::new`] with `renderer`'s cost model ([`Renderer::cost_model`]): the time budget
    /// and the expected time are those of the renderer the bake will run on.
    pub fn for_renderer(config: &BakeConfig, scene: &Scene, renderer: &Renderer<'_>) -> Result<Plan, BakeError> {
        let auto_atlas: OnceCell<Atlas> = OnceCell::new();
        let probe = || -> Result<Atlas, BakeError> {
            if let Some(a) = auto_atlas.get() {
                return Ok(a.clone());
            }
            let a = Atlas::build(scene, &AtlasParams::DEFAULT).map_err(|source| BakeError::Atlas {
                what: "building the automatic atlas",
                source,
            })?;
            Ok(auto_atlas.get_or_init(|| a).clone())
        };
        let cost = renderer.cost_model();
        let bounces = measured_bounces_per_walk(scene)?;
        let mut params = BakeParams::resolve(config, scene, &cost, bounces, probe)?;
        // An explicit resolution was estimated at half the atlas covered; build that atlas now
        // (the bake reuses it) and estimate with its exit points: Sibenik at 704² covers 34%,
        // and the guess made the plan 36% long.
        if let (None, AtlasSize::Resolution(r)) = (auto_atlas.get(), params.atlas) {
            let a = lightmap_atlas(scene, Sizing::Resolution(r))?;
            params.estimated_seconds = cost.bake_seconds(
                params.entries,
                params.paths_per_entry,
                bounces,
                a.exits.len() as f64,
                scene.triangles.len() as f64,
            );
            let _ = auto_atlas.set(a);
        }
        Ok(Plan {
            params,
            probed_atlas: auto_atlas.into_inner(),
        })
    }
}

/// Entry points and walks of [`measured_bounces_per_walk`]: 1024 walks, a few milliseconds.
const PROBE_ENTRIES: usize = 256;
const PROBE_WALKS: u32 = 4;

/// VPLs per walk beyond the entry points' own, measured on a few walks. In scenes open to the sky
/// walks escape, and a closed-scene expectation is 2.2× too high on the Cornell box, which would
/// make the plan expect twice the bake's time.
fn measured_bounces_per_walk(scene: &Scene) -> Result<f64, BakeError> {
    let bvh = scene_bvh(scene)?;
    let entries = sample_entries(scene, PROBE_ENTRIES, 0)?;
    let walks = WalkParams {
        walks_per_entry: PROBE_WALKS,
        seed: 0,
        ..WalkParams::PREVIEW
    };
    let vpls = prm_trace::trace_walks(scene, &bvh, &entries, &walks).map_err(trace("tracing walks"))?;
    let deeper = vpls.vpls.iter().filter(|v| v.depth > 0).count();
    Ok(deeper as f64 / vpls.stats.walks.max(1) as f64)
}

impl From<BakeParams> for Plan {
    /// A plan of parameters resolved elsewhere (the bake builds its atlas itself).
    fn from(params: BakeParams) -> Plan {
        Plan {
            params,
            probed_atlas: None,
        }
    }
}

/// What to bake and where to write it.
#[derive(Clone, Copy, Debug)]
pub struct BakeJob<'a> {
    /// The loaded scene.
    pub scene: &'a Scene,
    /// The file it was loaded from: recorded in the archive (relative to the archive's
    /// directory) so that the player can find it.
    pub scene_path: &'a Path,
    /// The parameters ([`Plan::new`]).
    pub plan: &'a Plan,
    /// The archive to write: replaced atomically, and nothing (no temporary file, no directory
    /// the bake created) is left behind when the bake fails.
    pub output: &'a Path,
    /// Render only this slice of the clusters into a partial archive, for [`crate::merge`]
    /// (`None`: the whole bake).
    pub shard: Option<Shard>,
}

/// What a finished bake measured, for a summary or a report. The archive is at
/// [`BakeJob::output`].
#[derive(Clone, Debug)]
#[non_exhaustive]
pub struct Baked {
    /// Where the panes were rendered ([`Renderer::name`]).
    pub backend: String,
    /// The atlas's statistics.
    pub atlas: AtlasStats,
    /// Triangles in the scene.
    pub triangles: usize,
    /// Entry points in the archive.
    pub entries: usize,
    /// Clusters (= panes) in the archive.
    pub clusters: usize,
    /// Random walks traced.
    pub walks: u64,
    /// VPLs the walks stored.
    pub vpls: usize,
    /// Rays cast: walk rays, plus shadow rays on the CPU renderer.
    pub rays: u64,
    /// Size of the archive written, bytes.
    pub archive_bytes: u64,
    /// Seconds per step: `atlas`, `bvh`, `light_tracing`, `clustering`, `emitters` (scenes with
    /// emissive materials), `pane_rendering`, `near_field` (with near rays), `accuracy_check`,
    /// `compression_write`, and on the GPU `pane_depth_maps` and `pane_gather`.
    pub timings: BTreeMap<String, f64>,
    /// The accuracy check's estimate, also recorded in the archive (`None`: not checked).
    pub accuracy: Option<prm_format::Accuracy>,
}

/// The sky section: the sky's transfer at every exit point, `paths` per texel, its indirect
/// part smoothed over each texel's neighbours on its chart, placed in the texels and dilated
/// into the gutters like a pane. Every shard of a sharded bake traces all of it.
fn sky_section(
    scene: &Scene,
    bvh: &Bvh,
    atlas: &Atlas,
    paths: u32,
    seed: u64,
    progress: &mut dyn ProgressSink,
) -> Result<prm_format::SkyTransfer, BakeError> {
    let params = ReferenceParams {
        seed,
        ..ReferenceParams::with_spp(paths)
    };
    progress.phase_start(Phase::Sky, u64::from(params.passes));
    let at_exits = prm_trace::sky_transfer_at_exits(scene, bvh, &atlas.exits, &params, &mut |pass, _| {
        progress.phase_advance(u64::from(pass))
    })
    .map_err(trace("tracing the sky's transfer"))?;
    let at_exits = prm_trace::sky::smooth_transfer(&at_exits, &atlas.exits, &atlas.chart_of_triangle, atlas.resolution);
    let mut out = prm_format::SkyTransfer::zeros((atlas.resolution * atlas.resolution) as usize);
    for (i, x) in atlas.exits.iter().enumerate() {
        out.direct[x.texel as usize] = at_exits.direct[i];
        out.indirect[x.texel as usize] = at_exits.indirect[i];
    }
    for &(dst, src) in &atlas.dilation {
        out.direct[dst as usize] = out.direct[src as usize];
        out.indirect[dst as usize] = out.indirect[src as usize];
    }
    Ok(out)
}

/// The probes section: probes placed on a grid of at most `cells` cells, and every cluster's
/// transfer to them from its VPLs (a shard's own clusters only; the others stay zero, and
/// `prm-bake merge` takes each cluster's from its shard).
fn probe_section(
    scene: &Scene,
    bvh: &Bvh,
    vpls: &prm_trace::VplSet,
    clustering: &Clustering,
    cells: u32,
    params: &BakeParams,
    progress: &mut dyn ProgressSink,
) -> Result<(prm_format::Probes, String), BakeError> {
    let bound = params.bound();
    let layout = prm_trace::place_probes(scene, bvh, cells).map_err(trace("placing probes"))?;
    progress.phase_start(Phase::Probes, layout.positions.len() as u64);
    let (transfer, rays) = prm_trace::probe_transfer(bvh, vpls, clustering, &layout.positions, bound, &mut |done| {
        progress.phase_advance(done)
    })
    .map_err(trace("the probes' transfer"))?;
    // With the sky: its transfer to the probes too (they are few: many paths each).
    let sky = match params.sky_paths {
        None => None,
        Some(_) => {
            let sky_params = ReferenceParams {
                seed: params.seed,
                ..ReferenceParams::with_spp(PROBE_SKY_PATHS)
            };
            Some(
                prm_trace::probes::sky_transfer_at_probes(scene, bvh, &layout.positions, &sky_params, &mut |_, _| {})
                    .map_err(trace("the sky's transfer to the probes"))?,
            )
        }
    };
    let g = layout.grid;
    let detail = format!(
        "{} probes on a {}×{}×{} grid of {:.3} ({} cells inside geometry), {rays} shadow rays{}",
        layout.positions.len(),
        g.dims[0],
        g.dims[1],
        g.dims[2],
        g.spacing,
        layout.inside,
        if sky.is_some() {
            format!("; the sky's transfer, {PROBE_SKY_PATHS} paths each")
        } else {
            String::new()
        }
    );
    let probes = prm_format::Probes {
        grid: g,
        cells: layout.cells,
        positions: layout.positions.iter().map(|p| p.to_array()).collect(),
        transfer,
        sky,
    };
    Ok((probes, detail))
}

/// The emitters section: each group's direct irradiance at the entry points (in the archive's
/// `order`) and at the atlas texels, and its indirect irradiance at the texels (traced, when it
/// fits [`EMITTER_INDIRECT_MAX_PATHS`]), at unit scale; texel images are dilated into the
/// gutters like a pane.
fn emitter_section(
    scene: &Scene,
    bvh: &Bvh,
    atlas: &Atlas,
    entries: &[SurfaceSample],
    order: &[u32],
    seed: u64,
    progress: &mut dyn ProgressSink,
) -> Result<Vec<prm_format::EmitterGroup>, BakeError> {
    let emitters = &Emitters::from_scene(scene);
    let trace_indirect = atlas.exits.len() as u64 * u64::from(EMITTER_INDIRECT_SPP) <= EMITTER_INDIRECT_MAX_PATHS;
    let params = ReferenceParams {
        seed,
        ..ReferenceParams::with_spp(EMITTER_INDIRECT_SPP)
    };
    // Steps: the direct light of every group, then each group's traced passes.
    let groups = emitters.groups.len() as u64;
    let passes = if trace_indirect { u64::from(params.passes) } else { 0 };
    progress.phase_start(Phase::Emitters, 1 + groups * passes);
    let at_entries: Vec<Receiver> = order
        .iter()
        .map(|&k| {
            let e = &entries[k as usize];
            Receiver {
                position: e.position,
                ng: e.normal,
                n: e.normal,
                triangle: e.triangle,
            }
        })
        .collect();
    let at_exits: Vec<Receiver> = atlas
        .exits
        .iter()
        .map(|x| Receiver {
            position: x.position,
            ng: bvh.geometric_normal(x.triangle),
            n: x.normal,
            triangle: x.triangle,
        })
        .collect();
    let to_entries = emitters.group_irradiance(scene, bvh, &at_entries, EMITTER_SAMPLES, seed);
    let to_exits = emitters.group_irradiance(scene, bvh, &at_exits, EMITTER_SAMPLES, !seed);
    progress.phase_advance(1);
    let image = |values: &[Vec3]| {
        let mut out = vec![[0f32; 3]; texel_count(atlas)];
        fill_texels(atlas, values, &mut out);
        out
    };
    let mut out = Vec::with_capacity(emitters.groups.len());
    for (g, (group, (te, tx))) in emitters
        .groups
        .iter()
        .zip(to_entries.into_iter().zip(to_exits))
        .enumerate()
    {
        let indirect = if trace_indirect {
            let alone = Emitters::alone(scene, g);
            let tracer = ReferenceTracer::new(scene, bvh, Lighting::Lights(&[])).with_emitters(&alone);
            let done = 1 + g as u64 * passes;
            let estimate = tracer
                .indirect_at_exits(&atlas.exits, &params, &mut |pass, _| {
                    progress.phase_advance(done + u64::from(pass))
                })
                .map_err(trace("tracing an emitter group's indirect light"))?;
            Some(image(&estimate.mean))
        } else {
            None
        };
        out.push(prm_format::EmitterGroup {
            name: truncate_name(&group.name),
            material: group.material,
            radiance: group.radiance.to_array(),
            entry_irradiance: te.iter().map(|v| v.to_array()).collect(),
            direct: image(&tx),
            indirect,
        });
    }
    Ok(out)
}

/// `name` cut to the archive's [`prm_format::EMITTER_NAME_BYTES`] at a character boundary.
fn truncate_name(name: &str) -> String {
    let mut end = name.len().min(prm_format::EMITTER_NAME_BYTES);
    while !name.is_char_boundary(end) {
        end -= 1;
    }
    name[..end].replace('\0', "")
}

/// The near field `trace(rays)` makes, with `rays` halved until its merged hits
/// ([`prm_scene::MergeNearHits::merged_hits`]) are at most `budget`, and the rays it took. The player
/// holds the merged hits in one storage binding (4 bytes each, so 2²⁴ take half of lavapipe's
/// and wgpu's default 128 MiB, leaving room for the deeper share's where its disk differs): the planner's rule (texels × rays before merging, `NEAR_HIT_BUDGET`) keeps
/// the default plans within it, but an atlas set by hand can pass it even at the smaller disks
/// (the Dabrovic Sponza at 1024² and 64 rays: 26.5 M merged hits, 202 MiB, which the player
/// refused).
fn fit_near_field(
    rays: u32,
    budget: u64,
    trace: impl Fn(u32) -> prm_format::NearField,
) -> (prm_format::NearField, u32) {
    let mut rays = rays;
    loop {
        let near = trace(rays);
        // Merging only lowers the count: the unmerged hits within the budget need no merge.
        if rays <= 1 || near.hits.len() as u64 <= budget || near.merged_hits().1.len() as u64 <= budget {
            return (near, rays);
        }
        rays /= 2;
    }
}

/// The bake's clusters of `entries`: each its own with as many clusters as entries, else
/// k-means kept apart by walls. [`crate::estimate_accuracy`] makes them again with this.
pub(crate) fn cluster_entries(
    scene: &Scene,
    bvh: &Bvh,
    entries: &[SurfaceSample],
    clusters: usize,
    seed: u64,
) -> Result<Clustering, BakeError> {
    if clusters == entries.len() {
        Ok(Clustering::identity(entries))
    } else {
        Clustering::kmeans_separated(entries, bvh, scene.bounds().diagonal(), clusters, seed)
            .map_err(trace("clustering entry points"))
    }
}

/// Builds `scene`'s lightmap atlas at `sizing`.
pub(crate) fn lightmap_atlas(scene: &Scene, sizing: Sizing) -> Result<Atlas, BakeError> {
    Atlas::build(scene, &AtlasParams::with_sizing(sizing)).map_err(|source| BakeError::Atlas {
        what: "building the lightmap atlas",
        source,
    })
}

/// Builds `scene`'s BVH.
pub(crate) fn scene_bvh(scene: &Scene) -> Result<Bvh, BakeError> {
    Bvh::build(scene, &BvhParams::DEFAULT).map_err(trace("building the BVH"))
}

/// Samples `count` entry points on `scene`'s surfaces with `seed`.
pub(crate) fn sample_entries(scene: &Scene, count: usize, seed: u64) -> Result<Vec<SurfaceSample>, BakeError> {
    prm_trace::sample_surface(scene, &EntryParams { count, seed }).map_err(trace("sampling entry points"))
}

/// The cells of the entry points `entries` on `scene` (its BVH `bvh`, [`prm_trace::entry_cells`]),
/// with a stream of `seed` apart from the entry points'.
pub(crate) fn sample_entry_cells(
    scene: &Scene,
    bvh: &Bvh,
    entries: &[SurfaceSample],
    seed: u64,
) -> Result<prm_format::EntryCells, BakeError> {
    prm_trace::entry_cells(scene, bvh, entries, seed ^ CELL_SEED).map_err(trace("sampling the entry cells"))
}

/// Keys the entry cells' points apart from the entry points of the same seed.
const CELL_SEED: u64 = 0xCE11_5EED_0000_0001;

/// Wraps a transport error with the step that failed.
pub(crate) fn trace(what: &'static str) -> impl FnOnce(prm_trace::TraceError) -> BakeError {
    move |source| BakeError::Trace { what, source }
}

/// Wraps an archive's error with the step that failed, e.g. "writing a pane".
pub(crate) fn archive_error(what: impl Into<String>) -> impl FnOnce(prm_format::Error) -> BakeError {
    let what = what.into();
    move |source| BakeError::Archive { what, source }
}

/// The bake's progress reports, and the seconds each finished step took ([`Baked::timings`]).
struct Steps<'p> {
    progress: &'p mut dyn ProgressSink,
    timings: BTreeMap<String, f64>,
}

impl Steps<'_> {
    /// Ends the step `phase` begun at `started`: its seconds go into the timings under `key` and,
    /// with `detail`, to the progress sink.
    fn finish(&mut self, phase: Phase, key: &str, started: Instant, detail: &str) {
        let secs = started.elapsed().as_secs_f64();
        self.timings.insert(key.to_string(), secs);
        self.progress.phase_finish(phase, detail, secs);
    }
}

/// What the transport phases made, which the later phases read.
struct Traced<'s> {
    scene: &'s Scene,
    params: &'s BakeParams,
    atlas: Atlas,
    bvh: Bvh,
    /// The entry points in sampling order.
    entries: Vec<SurfaceSample>,
    /// Their cells, in sampling order.
    cells: prm_format::EntryCells,
    /// The walks' VPLs (a shard's own clusters' only).
    vpls: VplSet,
    clustering: Clustering,
    /// Entry indices in the archive's order (cluster by cluster).
    order: Vec<u32>,
}

/// Bakes `job.scene` into the archive `job.output` with the panes rendered by `renderer`,
/// reporting to `progress`.
///
/// The destination is checked before any work ([`prm_scene::check_destination`]); missing
/// directories are created. The archive's bytes depend only on the scene, the scene path
/// relative to the archive, the parameters and the renderer: the same inputs give the same bytes.
pub fn bake(job: &BakeJob<'_>, renderer: Renderer<'_>, progress: &mut dyn ProgressSink) -> Result<Baked, BakeError> {
    let destination = prm_scene::check_destination(job.output).map_err(BakeError::Destination)?;
    let (scene, params) = (job.scene, &job.plan.params);
    let mut steps = Steps {
        progress,
        timings: BTreeMap::new(),
    };
    let backend_name = renderer.name();

    let mut atlas = build_atlas(job, &mut steps)?;
    let bvh = build_bvh(scene, &mut atlas, &mut steps)?;
    let (entries, mut vpls) = trace_walks(scene, &bvh, params, &mut steps)?;
    let cells = sample_entry_cells(scene, &bvh, &entries, params.seed)?;
    let clustering = cluster_vpls(job, &bvh, &entries, &mut vpls, &mut steps)?;
    let order: Vec<u32> = clustering.members.iter().flatten().copied().collect();
    let traced = Traced {
        scene,
        params,
        atlas,
        bvh,
        entries,
        cells,
        vpls,
        clustering,
        order,
    };

    let emitter_groups = trace_emitters(&traced, &mut steps)?;
    let sky = trace_sky(&traced, &mut steps)?;
    let (mut writer, made, residual_groups) = start_archive(job, &destination, &traced, &backend_name)?;
    writer
        .set_entry_cells(prm_trace::reorder_cells(&traced.cells, &traced.order))
        .map_err(archive_error("recording the entry cells"))?;

    // The accuracy check's exit points: a whole bake only (a shard holds some panes).
    let checked = if params.accuracy_points > 0 && job.shard.is_none() {
        prm_trace::CheckPoints::draw(traced.scene, &traced.atlas, params.accuracy_points, params.seed)
    } else {
        prm_trace::CheckPoints::default()
    };
    // Traced before the panes, so the accuracy check plays each pane's share of its series as it
    // comes.
    let near_field = trace_near_field(&traced, &mut steps);
    // The accuracy check's model of the player's near field, over the whole atlas.
    let near_play = near_field.as_ref().filter(|_| !checked.is_empty()).map(|n| {
        let texels: Vec<u32> = checked.exits.iter().map(|&i| traced.atlas.exits[i].texel).collect();
        prm_trace::NearPlay::new(n, &traced.atlas.texel_exit, &texels, prm_trace::NEAR_GATHERS)
    });
    let mut recorder = PaneRecorder {
        checked: &checked,
        near_play: near_play.as_ref(),
        image: vec![[0f32; 3]; texel_count(&traced.atlas)],
        words: Vec::new(),
        shard: job.shard.map(|s| (s, Vec::new())),
        checked_panes: Vec::new(),
        pane_energy: Vec::new(),
        write_s: 0.0,
    };

    if let Some(sky) = sky {
        writer.set_sky(sky).map_err(archive_error("recording the sky"))?;
    }
    if !emitter_groups.is_empty() {
        writer
            .set_emitters(emitter_groups)
            .map_err(archive_error("recording the emitters"))?;
    }
    let out = PaneSink {
        writer: &mut writer,
        recorder: &mut recorder,
        steps: &mut steps,
    };
    let panes = render_panes(renderer, &backend_name, &traced, out)?;
    recorder.compress(&traced.atlas, &mut writer, &mut steps)?;
    trace_probes(&traced, &mut writer, &mut steps)?;
    let write_s = recorder.write_s;
    let accuracy = check_accuracy(&traced, recorder, &residual_groups, panes.sampled_energy, &mut steps)?;
    writer.metadata_mut().accuracy = accuracy.clone();
    drop(near_play);
    if let Some(near) = near_field {
        writer
            .set_near_field(near)
            .map_err(archive_error("recording the near field"))?;
    }
    let archive_bytes = finish_archive(job.output, writer, made, write_s, &mut steps)?;

    Ok(Baked {
        backend: backend_name,
        atlas: traced.atlas.stats.clone(),
        triangles: scene.triangles.len(),
        entries: traced.entries.len(),
        clusters: traced.clustering.len(),
        walks: traced.vpls.stats.walks,
        vpls: traced.vpls.vpls.len(),
        rays: traced.vpls.stats.rays + panes.shadow_rays,
        archive_bytes,
        timings: steps.timings,
        accuracy,
    })
}

/// Builds the lightmap atlas, or takes the one planning built at the same resolution, and
/// refuses one over the archive's limit.
fn build_atlas(job: &BakeJob<'_>, steps: &mut Steps<'_>) -> Result<Atlas, BakeError> {
    let t = Instant::now();
    steps.progress.phase_start(Phase::Atlas, 1);
    let sizing = Sizing::from(job.plan.params.atlas);
    let atlas = match (&job.plan.probed_atlas, sizing) {
        (Some(a), Sizing::Resolution(r)) if a.resolution == r => a.clone(),
        _ => lightmap_atlas(job.scene, sizing)?,
    };
    if atlas.resolution > MAX_ATLAS_RESOLUTION {
        return Err(BakeError::OverLimit(format!(
            "the atlas needs {}² texels, over the archive's {MAX_ATLAS_RESOLUTION} limit; choose a larger --texel-size",
            atlas.resolution
        )));
    }
    let detail = format!(
        "{r}x{r}, {} charts, {} exit points",
        atlas.stats.charts,
        atlas.exits.len(),
        r = atlas.resolution
    );
    steps.finish(Phase::Atlas, "atlas", t, &detail);
    if let Some(w) = atlas.coverage_warning(job.scene.triangles.len()) {
        steps.progress.warn(&w);
    }
    Ok(atlas)
}

/// Builds the BVH, then moves the exit points under other geometry (a floor's texels half under
/// a box) to the part of their texel that sees the scene, before anything traces from them.
fn build_bvh(scene: &Scene, atlas: &mut Atlas, steps: &mut Steps<'_>) -> Result<Bvh, BakeError> {
    let t = Instant::now();
    steps.progress.phase_start(Phase::Bvh, 1);
    let bvh = scene_bvh(scene)?;
    let unburied = prm_trace::unbury_exits(scene, &bvh, atlas);
    let detail = format!(
        "{} triangles; {} exit points buried under other geometry, {} of them moved within their texel, {} to a neighbour's",
        scene.triangles.len(),
        unburied.buried,
        unburied.moved,
        unburied.copied
    );
    steps.finish(Phase::Bvh, "bvh", t, &detail);
    Ok(bvh)
}

/// Whether the bake traces the near field, whose deeper share the player gathers back from the
/// lightmap.
fn gathers_near(params: &BakeParams) -> bool {
    params.near_rays > 0 && params.vpl_disk_scale > 0.0
}

/// Samples the entry points and traces their random walks into VPLs.
fn trace_walks(
    scene: &Scene,
    bvh: &Bvh,
    params: &BakeParams,
    steps: &mut Steps<'_>,
) -> Result<(Vec<SurfaceSample>, VplSet), BakeError> {
    let t = Instant::now();
    steps.progress.phase_start(Phase::LightTracing, 1);
    let entries = sample_entries(scene, params.entries, params.seed)?;
    // With the near field the deeper VPLs take their entry point's disk, which tames their
    // spikes.
    let walk_params = WalkParams {
        walks_per_entry: params.paths_per_entry,
        seed: params.seed,
        deep_disk: if gathers_near(params) {
            DeepDisk::Entry
        } else {
            DeepDisk::Walk
        },
        ..WalkParams::PREVIEW
    };
    let vpls = prm_trace::trace_walks(scene, bvh, &entries, &walk_params).map_err(trace("tracing walks"))?;
    let detail = format!(
        "{} entries, {} walks, {} VPLs, {} rays",
        entries.len(),
        vpls.stats.walks,
        vpls.vpls.len(),
        vpls.stats.rays
    );
    steps.finish(Phase::LightTracing, "light_tracing", t, &detail);
    Ok((entries, vpls))
}

/// Clusters the entry points; a shard then keeps its own clusters' VPLs only, and the other
/// panes stay zero.
fn cluster_vpls(
    job: &BakeJob<'_>,
    bvh: &Bvh,
    entries: &[SurfaceSample],
    vpls: &mut VplSet,
    steps: &mut Steps<'_>,
) -> Result<Clustering, BakeError> {
    let params = &job.plan.params;
    let t = Instant::now();
    steps.progress.phase_start(Phase::Clustering, 1);
    let clustering = cluster_entries(job.scene, bvh, entries, params.clusters, params.seed)?;
    let detail = format!("{} clusters", clustering.len());
    steps.finish(Phase::Clustering, "clustering", t, &detail);
    if let Some(shard) = job.shard {
        vpls.vpls
            .retain(|v| shard.owns(clustering.of_entry[v.entry as usize] as usize));
        steps.progress.info(&format!(
            "  shard {shard}: {} of {} clusters, {} VPLs",
            (0..clustering.len()).filter(|&c| shard.owns(c)).count(),
            clustering.len(),
            vpls.vpls.len()
        ));
    }
    Ok(clustering)
}

/// The emitters section ([`emitter_section`]) of a scene with emissive materials; none without.
fn trace_emitters(traced: &Traced<'_>, steps: &mut Steps<'_>) -> Result<Vec<prm_format::EmitterGroup>, BakeError> {
    let (scene, atlas) = (traced.scene, &traced.atlas);
    if Emitters::from_scene(scene).is_empty() {
        return Ok(Vec::new());
    }
    let t = Instant::now();
    let groups = emitter_section(
        scene,
        &traced.bvh,
        atlas,
        &traced.entries,
        &traced.order,
        traced.params.seed,
        steps.progress,
    )?;
    let names: Vec<&str> = groups.iter().map(|g| g.name.as_str()).collect();
    let how = if groups.iter().all(|g| g.indirect.is_some()) {
        format!("indirect traced, {EMITTER_INDIRECT_SPP} paths per texel")
    } else {
        format!(
            "indirect through the panes: {} exit points × {EMITTER_INDIRECT_SPP} paths exceed {EMITTER_INDIRECT_MAX_PATHS}",
            atlas.exits.len()
        )
    };
    let detail = format!("{} group(s): {}; {how}", groups.len(), names.join(", "));
    steps.finish(Phase::Emitters, "emitters", t, &detail);
    Ok(groups)
}

/// The sky section ([`sky_section`]) of a bake with the sky; none without.
fn trace_sky(traced: &Traced<'_>, steps: &mut Steps<'_>) -> Result<Option<prm_format::SkyTransfer>, BakeError> {
    let Some(paths) = traced.params.sky_paths else {
        return Ok(None);
    };
    let t = Instant::now();
    let atlas = &traced.atlas;
    let sky = sky_section(
        traced.scene,
        &traced.bvh,
        atlas,
        paths,
        traced.params.seed,
        steps.progress,
    )?;
    let detail = format!("{} exit points × {paths} paths", atlas.exits.len());
    steps.finish(Phase::Sky, "sky", t, &detail);
    Ok(Some(sky))
}

/// Creates the output's missing directories and starts the archive with its metadata and its
/// atlas, entry and cluster tables. Also gives the player's residual groups, which the accuracy
/// check reads (a function of the cluster table).
fn start_archive(
    job: &BakeJob<'_>,
    destination: &Path,
    traced: &Traced<'_>,
    backend_name: &str,
) -> Result<(ArchiveWriter, MadeDirs, Vec<u32>), BakeError> {
    let (table_entries, table_clusters, atlas_section) =
        archive_tables(&traced.atlas, &traced.entries, &traced.clustering);
    let residual_groups = prm_format::residual_groups(
        &table_clusters,
        prm_format::residual_group_count(table_clusters.len(), prm_format::RESIDUAL_GROUPS),
    );
    let out_dir = destination
        .parent()
        .filter(|d| !d.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    let made = MadeDirs::create(out_dir)?;
    let mut metadata = metadata(
        traced.scene,
        job.scene_path,
        out_dir,
        traced.params,
        &traced.atlas,
        backend_name,
    )?;
    if let Some(shard) = job.shard {
        metadata.params.insert("shard".into(), shard.to_json());
    }
    let writer = ArchiveWriter::create(job.output, metadata, &atlas_section, &table_entries, &table_clusters)
        .map_err(archive_error(format!("starting {}", job.output.display())))?;
    Ok((writer, made, residual_groups))
}

/// The near field: what the VPL disk bound removes next to the exit points, with its rays cut
/// until its merged hits fit the player's storage binding ([`fit_near_field`]). `None` where the
/// bake does not gather it ([`gathers_near`]).
fn trace_near_field(traced: &Traced<'_>, steps: &mut Steps<'_>) -> Option<prm_format::NearField> {
    let params = traced.params;
    let e = traced.entries.first().filter(|_| gathers_near(params))?;
    let t = Instant::now();
    steps.progress.phase_start(Phase::NearField, 1);
    let disk = prm_trace::near_disk(e.weight, params.vpl_disk_scale);
    let (mut near, rays) = fit_near_field(params.near_rays, crate::params::NEAR_HIT_BUDGET, |rays| {
        prm_trace::near_field(traced.scene, &traced.bvh, &traced.atlas, rays, disk, params.seed)
    });
    if rays < params.near_rays {
        steps.progress.info(&format!(
            "  near field: {rays} rays per exit point instead of {}, so that its merged hits fit the player's storage binding ({} hits)",
            params.near_rays,
            crate::params::NEAR_HIT_BUDGET
        ));
    }
    // The deeper VPLs' disk is the entry point's too (`DeepDisk::Entry` in `trace_walks`), and
    // the panes' kernel completes the cut weights (`BakeParams::bound`).
    near.indirect_disk = disk;
    near.complement = matches!(params.bound(), prm_trace::VplBound::Near { .. });
    let detail = format!(
        "{} texels (exit points and their gutter copies) keep {} rays in all of {} per exit point, ending at {} gather points",
        near.exits.len(),
        near.hits.len(),
        rays,
        near.points.len(),
    );
    steps.finish(Phase::NearField, "near_field", t, &detail);
    Some(near)
}

/// Appends panes to the archive, and keeps what the accuracy check reads of them once compressed.
struct PaneRecorder<'a> {
    /// The accuracy check's exit points (none: no check).
    checked: &'a prm_trace::CheckPoints,
    /// The accuracy check's model of the player's near field.
    near_play: Option<&'a prm_trace::NearPlay<'a>>,
    /// The atlas image a pane is placed in, and its RGB9E5 words.
    image: Vec<[f32; 3]>,
    words: Vec<u32>,
    /// A shard's own panes ([`crate::shard::SHARD_PANES`]), its partial archive's panes being
    /// zero.
    shard: Option<(Shard, Vec<u32>)>,
    /// Every stored pane at the checked exit points ([`crate::estimate::checked_pane`]).
    checked_panes: Vec<Vec<Vec3>>,
    /// Every pane's energy, from the cluster table.
    pane_energy: Vec<Vec3>,
    /// Seconds spent placing, compressing and writing the panes.
    write_s: f64,
}

impl PaneRecorder<'_> {
    /// Appends a pane, one value per exit point: placed in its texels, dilated into the gutters
    /// and rounded to RGB9E5 (what a shard keeps, so that merged shards compress the same panes).
    fn add(&mut self, atlas: &Atlas, pane: &[Vec3], writer: &mut ArchiveWriter) -> Result<(), BakeError> {
        let t = Instant::now();
        let cluster = writer.clusters().len() - writer.panes_remaining();
        fill_texels(atlas, pane, &mut self.image);
        prm_format::encode_rgb9e5_slice(&self.image, &mut self.words);
        match &mut self.shard {
            Some((shard, own)) => {
                if shard.owns(cluster) {
                    own.extend_from_slice(&self.words);
                }
                self.image.fill([0.0; 3]);
            }
            None => {
                for (texel, &w) in self.image.iter_mut().zip(&self.words) {
                    *texel = prm_format::decode_rgb9e5(w);
                }
            }
        }
        writer.add_pane(&self.image).map_err(archive_error("writing a pane"))?;
        self.write_s += t.elapsed().as_secs_f64();
        Ok(())
    }

    /// Compresses the panes into the archive's low-rank basis, and keeps what the player will
    /// read of them for the accuracy check: every decoded pane at the checked exit points and
    /// every cluster's energy.
    fn compress(&mut self, atlas: &Atlas, writer: &mut ArchiveWriter, steps: &mut Steps<'_>) -> Result<(), BakeError> {
        let t = Instant::now();
        if let Some((_, own)) = self.shard.take() {
            let bytes = own.iter().flat_map(|w| w.to_le_bytes()).collect();
            writer
                .add_custom_section(crate::shard::SHARD_PANES, bytes)
                .map_err(archive_error("recording the shard's panes"))?;
        }
        let basis = writer
            .compress_panes()
            .map_err(archive_error("compressing the panes"))?;
        steps.progress.info(&format!(
            "  panes: a basis of mean rank {:.1} per {}² tile, {:.1} MiB",
            basis.ranks().iter().map(|&r| f64::from(r)).sum::<f64>() / basis.tile_count().max(1) as f64,
            basis.tile_size(),
            basis.byte_size() as f64 / f64::from(1 << 20)
        ));
        if !self.checked.is_empty() {
            let (near, checked) = (self.near_play, &self.checked.exits);
            self.checked_panes = (0..basis.pane_count())
                .into_par_iter()
                .map(|c| {
                    let pane = basis.decode_pane(c)?;
                    let at_exits: Vec<Vec3> = atlas.exits.iter().map(|e| Vec3::from(pane[e.texel as usize])).collect();
                    Ok(crate::estimate::checked_pane(near, checked, &at_exits))
                })
                .collect::<Result<_, prm_format::Error>>()
                .map_err(archive_error("decoding a pane"))?;
        }
        self.pane_energy = writer.clusters().iter().map(|c| Vec3::from(c.energy)).collect();
        self.write_s += t.elapsed().as_secs_f64();
        Ok(())
    }
}

/// Places `values`, one per exit point, in their texels of `image` (the atlas's size) and dilates
/// them into the gutters; the other texels are zero.
fn fill_texels(atlas: &Atlas, values: &[Vec3], image: &mut [[f32; 3]]) {
    image.fill([0.0; 3]);
    for (e, v) in atlas.exits.iter().zip(values) {
        image[e.texel as usize] = v.to_array();
    }
    for &(dst, src) in &atlas.dilation {
        image[dst as usize] = image[src as usize];
    }
}

/// Texels in the atlas's image.
fn texel_count(atlas: &Atlas) -> usize {
    (atlas.resolution * atlas.resolution) as usize
}

/// Where a renderer's panes go: the archive, what the accuracy check keeps of them, and the
/// bake's progress and timings.
struct PaneSink<'a, 'r, 'p> {
    writer: &'a mut ArchiveWriter,
    recorder: &'a mut PaneRecorder<'r>,
    steps: &'a mut Steps<'p>,
}

impl PaneSink<'_, '_, '_> {
    /// Begins the pane phase, `units` of progress long: the time it began.
    fn start(&mut self, units: u64) -> Instant {
        let started = Instant::now();
        self.steps.progress.phase_start(Phase::PaneRendering, units);
        started
    }
}

/// What a renderer left of the panes besides the archive's.
struct RenderedPanes {
    /// The entries' pane energies, in the archive's order.
    entry_energy: Vec<[f32; 3]>,
    /// Whether every entry's energy came back.
    entry_energy_known: bool,
    /// Shadow rays cast (the CPU renderer's).
    shadow_rays: u64,
    /// When the pane phase began.
    started: Instant,
}

/// What the pane phase leaves for the bake's summary and its accuracy check.
struct PaneSummary {
    /// Every entry's pane energy in sampling order (`None`: not all are known).
    sampled_energy: Option<Vec<Vec3>>,
    /// Shadow rays cast (the CPU renderer's).
    shadow_rays: u64,
}

/// Renders every pane with `renderer` and appends it to the archive (a fill of the atlas image,
/// dilated into the gutters, encoded), then records the entries' pane energies where all are
/// known.
fn render_panes(
    renderer: Renderer<'_>,
    backend_name: &str,
    traced: &Traced<'_>,
    mut out: PaneSink,
) -> Result<PaneSummary, BakeError> {
    let t = Instant::now();
    let rendered = match renderer {
        Renderer::Gpu(ctx) => render_panes_gpu(ctx, traced, &mut out)?,
        Renderer::Cpu => render_panes_cpu(&Lattice::DEFAULT, traced, &mut out)?,
        Renderer::CpuExact => render_panes_cpu(&Lattice::EXACT, traced, &mut out)?,
    };
    let PaneSink {
        writer,
        recorder,
        steps,
    } = out;
    // The entries' pane energies in sampling order, for the accuracy check.
    let sampled_energy =
        crate::estimate::in_sampling_order(&traced.order, &rendered.entry_energy, traced.entries.len());
    if rendered.entry_energy_known {
        writer
            .set_entry_energy(rendered.entry_energy)
            .map_err(archive_error("recording the entry energies"))?;
    }
    let render_s = t.elapsed().as_secs_f64() - recorder.write_s;
    steps.progress.phase_finish(
        Phase::PaneRendering,
        &format!(
            "{} panes, {} VPLs on {}",
            traced.clustering.len(),
            traced.vpls.vpls.len(),
            backend_name
        ),
        rendered.started.elapsed().as_secs_f64(),
    );
    steps.timings.insert("pane_rendering".to_string(), render_s);
    Ok(PaneSummary {
        sampled_energy: rendered.entry_energy_known.then_some(sampled_energy),
        shadow_rays: rendered.shadow_rays,
    })
}

/// Renders the panes on the GPU, appending each as it comes back.
fn render_panes_gpu(ctx: &GpuContext, traced: &Traced<'_>, out: &mut PaneSink) -> Result<RenderedPanes, BakeError> {
    let (atlas, clustering) = (&traced.atlas, &traced.clustering);
    let mut entry_energy = vec![[0f32; 3]; traced.entries.len()];
    let rp = PaneRenderParams {
        bound: traced.params.bound(),
        face_resolution: traced.params.face_resolution,
        ..PaneRenderParams::DEFAULT
    };
    let inputs = PaneInputs {
        scene: traced.scene,
        exits: &atlas.exits,
        vpls: &traced.vpls,
        clustering,
    };
    // Progress counts VPLs: a group of panes can take minutes on a big scene.
    let started = out.start(traced.vpls.vpls.len() as u64);
    let mut at = 0;
    let mut energies_complete = true;
    let progress = &mut *out.steps.progress;
    let stats = prm_gpu::render_panes_with(ctx, &inputs, &rp, |pane| {
        match pane {
            PaneOutput::Pane {
                cluster,
                irradiance,
                member_energy,
            } => {
                // Members arrive cluster by cluster: the archive's entry order.
                energies_complete &= member_energy.len() == clustering.members[cluster].len();
                for (slot, e) in entry_energy[at..].iter_mut().zip(member_energy) {
                    *slot = e.to_array();
                }
                at += member_energy.len();
                out.recorder.add(atlas, irradiance, out.writer)?;
            }
            PaneOutput::Progress(s) => progress.phase_advance(s.vpls),
        }
        Ok::<(), BakeError>(())
    })?;
    let steps = &mut *out.steps;
    steps.progress.info(&format!(
        "  GPU: {} batches, {} depth faces ({:.0} triangles each after culling) {:.2} s, {} evaluations {:.2} s ({:.0} M/s)",
        stats.batches,
        stats.faces,
        stats.triangles as f64 / stats.faces.max(1) as f64,
        stats.depth_seconds,
        stats.evaluations,
        stats.gather_seconds,
        stats.evaluations as f64 / stats.gather_seconds.max(1e-9) / 1e6
    ));
    if !energies_complete {
        steps.progress.info(&format!(
            "  no entry energies: their read-back would take {:.1} GiB, over the {:.1} GiB \
             budget, so the panes were rendered per cluster and the player weighs \
             members equally",
            prm_gpu::pane::member_readback_bytes(traced.entries.len(), atlas.exits.len()) as f64 / (1u64 << 30) as f64,
            rp.member_energy_bytes as f64 / (1u64 << 30) as f64
        ));
    }
    steps.timings.insert("pane_depth_maps".to_string(), stats.depth_seconds);
    steps.timings.insert("pane_gather".to_string(), stats.gather_seconds);
    Ok(RenderedPanes {
        entry_energy,
        entry_energy_known: energies_complete,
        shadow_rays: 0,
        started,
    })
}

/// Evaluates every pane on the CPU with `lattice`'s shared visibility, then appends them
/// ([`write_cpu_panes`]).
fn render_panes_cpu(lattice: &Lattice, traced: &Traced<'_>, out: &mut PaneSink) -> Result<RenderedPanes, BakeError> {
    let (atlas, vpls) = (&traced.atlas, &traced.vpls);
    let started = out.start(atlas.exits.len() as u64);
    let progress = &mut *out.steps.progress;
    let panes = prm_trace::evaluate_atlas_panes(
        &traced.bvh,
        vpls,
        &traced.clustering,
        atlas,
        &PaneParams {
            bound: traced.params.bound(),
        },
        lattice,
        &mut |done| progress.phase_advance(done),
    )
    .map_err(trace("evaluating panes on the CPU"))?;
    let mut entry_energy = vec![[0f32; 3]; traced.entries.len()];
    for (slot, &k) in entry_energy.iter_mut().zip(&traced.order) {
        *slot = panes
            .entry_energy
            .get(k as usize)
            .copied()
            .unwrap_or_default()
            .to_array();
    }
    out.steps.progress.info(&format!(
        "  CPU: {} shadow rays for {} VPL × exit point pairs ({:.0}%; lattice step {})",
        panes.rays,
        vpls.vpls.len() as u64 * atlas.exits.len() as u64,
        100.0 * panes.rays as f64 / (vpls.vpls.len() as f64 * atlas.exits.len() as f64).max(1.0),
        lattice.step
    ));
    write_cpu_panes(atlas, &panes, out.writer, out.recorder)?;
    Ok(RenderedPanes {
        entry_energy,
        entry_energy_known: panes.entry_energy.len() == traced.entries.len(),
        shadow_rays: panes.rays,
        started,
    })
}

/// Appends the CPU's panes, in cluster order.
fn write_cpu_panes(
    atlas: &Atlas,
    panes: &prm_trace::Panes,
    writer: &mut ArchiveWriter,
    recorder: &mut PaneRecorder<'_>,
) -> Result<(), BakeError> {
    (0..panes.clusters).try_for_each(|c| recorder.add(atlas, panes.pane(c), writer))
}

/// Records the probes section ([`probe_section`]) of a bake with probes, and their rays where
/// asked.
fn trace_probes(traced: &Traced<'_>, writer: &mut ArchiveWriter, steps: &mut Steps<'_>) -> Result<(), BakeError> {
    let (scene, params) = (traced.scene, traced.params);
    let Some(cells) = params.probes else {
        return Ok(());
    };
    let t = Instant::now();
    let (probes, mut detail) = probe_section(
        scene,
        &traced.bvh,
        &traced.vpls,
        &traced.clustering,
        cells,
        params,
        steps.progress,
    )?;
    let positions: Vec<glam::Vec3> = probes.positions.iter().map(|p| glam::Vec3::from(*p)).collect();
    writer
        .set_probes(probes)
        .map_err(archive_error("recording the probes"))?;
    if params.probe_rays > 0 {
        let rays = prm_trace::probe_rays(scene, &traced.bvh, &traced.atlas, &positions, params.probe_rays);
        detail += &format!(
            "; {} rays each, reaching {} texels",
            params.probe_rays,
            rays.points.len()
        );
        writer
            .set_probe_rays(rays)
            .map_err(archive_error("recording the probe rays"))?;
    }
    steps.finish(Phase::Probes, "probes", t, &detail);
    Ok(())
}

/// The accuracy check of a whole bake ([`crate::estimate::check`]) on the panes `recorder` kept;
/// `None` where nothing was checked, no test light found a place, or a value is not finite.
fn check_accuracy(
    traced: &Traced<'_>,
    recorder: PaneRecorder<'_>,
    residual_groups: &[u32],
    sampled_energy: Option<Vec<Vec3>>,
    steps: &mut Steps<'_>,
) -> Result<Option<prm_format::Accuracy>, BakeError> {
    if recorder.checked.is_empty() {
        return Ok(None);
    }
    let params = traced.params;
    let t = Instant::now();
    let inputs = crate::estimate::CheckInputs {
        scene: traced.scene,
        bvh: &traced.bvh,
        atlas: &traced.atlas,
        entries: &traced.entries,
        cells: Some(&traced.cells),
        clustering: &traced.clustering,
        entry_energy: sampled_energy.as_deref(),
        pane_energy: &recorder.pane_energy,
        groups: residual_groups,
        top_k: params.top_k,
        near: recorder.near_play,
    };
    let check = prm_trace::CheckParams {
        exit_points: params.accuracy_points,
        paths: params.accuracy_paths,
        seed: params.seed,
    };
    let accuracy = crate::estimate::check(
        &inputs,
        recorder.checked,
        &recorder.checked_panes,
        &check,
        None,
        steps.progress,
    )?;
    // A NaN in a pane or the reference must not cost the whole bake: no estimate then.
    let valid = accuracy.validate();
    let detail = match &valid {
        _ if accuracy.lights.is_empty() => "no free place for a test light: no estimate".to_string(),
        Err(e) => format!("no estimate: {e}"),
        Ok(()) => accuracy_line(&accuracy),
    };
    steps.finish(Phase::AccuracyCheck, "accuracy_check", t, &detail);
    Ok((!accuracy.lights.is_empty() && valid.is_ok()).then_some(accuracy))
}

/// Finishes the archive at `output` and keeps the directories made for it; its size in bytes.
///
/// Timings go to the caller only: the archive's bytes depend on nothing but the scene, the
/// parameters and the backend, so caches and content-addressed pipelines can key on them
/// (tested by `bake_is_byte_identical_across_runs_and_threads`).
fn finish_archive(
    output: &Path,
    writer: ArchiveWriter,
    made: MadeDirs,
    write_s: f64,
    steps: &mut Steps<'_>,
) -> Result<u64, BakeError> {
    let t = Instant::now();
    let archive_bytes = writer
        .finish()
        .map_err(archive_error(format!("finishing {}", output.display())))?;
    made.keep();
    steps
        .timings
        .insert("compression_write".to_string(), write_s + t.elapsed().as_secs_f64());
    Ok(archive_bytes)
}

/// One line for an accuracy estimate: the mean over its lights.
pub fn accuracy_line(a: &prm_format::Accuracy) -> String {
    format!(
        "indirect light {:.1}% ± {:.1} off the reference (K = all: {:.1}%), energy {:.3}; {} light{} × {} patches of 3×3 texels × {} paths, reference noise {:.1}% removed",
        100.0 * a.mean_error(),
        100.0 * a.mean_standard_error(),
        100.0 * a.mean_error_all_clusters(),
        a.mean_energy(),
        a.lights.len(),
        if a.lights.len() == 1 { "" } else { "s" },
        a.exit_points,
        a.paths,
        100.0 * a.mean_reference_noise()
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use prm_format::{GatherPoint, NearExit, NearField, NearHit};

    /// A near field of one exit whose `rays` rays end on `rays` different gather points.
    fn near(rays: u32) -> NearField {
        NearField {
            rays_per_exit: rays,
            disk: 1.0,
            indirect_disk: 1.0,
            complement: true,
            points: (0..rays).map(|_| GatherPoint::default()).collect(),
            exits: vec![NearExit { texel: 0, end: rays }],
            hits: (0..rays).map(|point| NearHit { point, distance2: 0.0 }).collect(),
        }
    }

    #[test]
    fn the_near_field_halves_its_rays_until_its_hits_fit() {
        let (n, rays) = fit_near_field(64, 10, near);
        assert_eq!((rays, n.rays_per_exit, n.hits.len()), (8, 8, 8));
        assert_eq!(fit_near_field(64, 64, near).1, 64, "fits at once");
        assert_eq!(fit_near_field(4, 0, near).1, 1, "one ray at least");
    }
}
