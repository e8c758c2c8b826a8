//! Bake parameters: presets, a TOML config file, command-line overrides, and the automatic
//! choice of sizes from the scene and budgets ("bake no more than the scene needs").

use prm_scene::{Atlas, Scene};
use serde::{Deserialize, Serialize};
use std::path::Path;

use crate::BakeError;

/// Returns [`BakeError::InvalidParams`] with a formatted message.
macro_rules! invalid {
    ($($arg:tt)*) => {
        return Err(BakeError::InvalidParams(format!($($arg)*)))
    };
}

/// Returns [`BakeError::OverLimit`] with a formatted message.
macro_rules! over_limit {
    ($($arg:tt)*) => {
        return Err(BakeError::OverLimit(format!($($arg)*)))
    };
}

/// Named parameter sets.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Preset {
    /// Small and fast: 1024 entries, 64 clusters, 128² panes.
    Preview,
    /// Sizes derived from the scene and the budgets.
    Default,
    /// The paper's marble chamber: 4096 entries, 256 clusters, 256² panes, 32 clusters at run time.
    Paper,
    /// 16384 entries, 1024 clusters, 512² panes.
    High,
}

/// Every bake parameter, all optional: a TOML config file holds these keys, the command line
/// overrides them, and what is still unset follows from the preset (or, for `default`, from the
/// scene and the budgets).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BakeConfig {
    /// Named parameter set (default: `default`).
    pub preset: Option<Preset>,
    /// Entry points.
    pub entries: Option<usize>,
    /// Clusters of entry points (= panes).
    pub clusters: Option<usize>,
    /// Atlas (and pane) resolution.
    pub resolution: Option<u32>,
    /// Atlas texel size in scene units (instead of `resolution`).
    pub texel_size: Option<f32>,
    /// Random walks per entry point.
    pub paths_per_entry: Option<u32>,
    /// Seed of every random choice.
    pub seed: Option<u64>,
    /// Clusters blended per frame at run time (recorded for the player).
    pub top_k: Option<usize>,
    /// Texels on a side of each VPL hemicube face.
    pub face_resolution: Option<u32>,
    /// VPL bound: radius multiplier of the disk each VPL stands for (0 = no bound; unset:
    /// [`NEAR_FIELD_DISK_SCALE`] with the near field, else 1).
    pub vpl_disk_scale: Option<f32>,
    /// Largest archive, MiB (automatic sizing keeps under it).
    pub archive_budget_mib: Option<f64>,
    /// Largest run-time pane memory (all panes resident as RGB9E5), MiB.
    pub memory_budget_mib: Option<f64>,
    /// Longest bake the automatic sizes may plan for, seconds (by [`CostModel`]).
    pub time_budget_s: Option<f64>,
    /// Bake the sky's transfer (also when `sky_paths` is set), its paths per texel from the time
    /// budget unless `sky_paths` gives them ([`BakeParams::sky_paths`]).
    pub sky: Option<bool>,
    /// Bake the sky's transfer with this many paths per texel (unset: no sky in the archive
    /// unless `sky`).
    pub sky_paths: Option<u32>,
    /// Place irradiance probes on a grid of at most this many cells (unset: no probes).
    pub probes: Option<u32>,
    /// Rays per probe that find the surfaces the run time gathers the probes' light from
    /// (0: none, the probes are lit through the panes; default [`crate::PROBE_RAYS`]).
    pub probe_rays: Option<u32>,
    /// Near rays per exit point that gather back what the VPL bound removes (0: none;
    /// default [`prm_trace::NEAR_RAYS`]).
    pub near_rays: Option<u32>,
    /// Points (3×3-texel patches) of the bake's accuracy check (0: no check; default
    /// [`crate::ACCURACY_POINTS`]).
    pub accuracy_points: Option<u32>,
    /// Reference paths per checked exit point and light (default [`crate::ACCURACY_PATHS`]).
    pub accuracy_paths: Option<u32>,
}

impl BakeConfig {
    /// Reads a TOML config file.
    pub fn load(path: &Path) -> Result<BakeConfig, BakeError> {
        let text = std::fs::read_to_string(path).map_err(|source| BakeError::ConfigRead {
            path: path.to_path_buf(),
            source,
        })?;
        toml::from_str(&text).map_err(|source| BakeError::ConfigParse {
            path: path.to_path_buf(),
            source: Box::new(source),
        })
    }

    /// `self` with every field that `over` sets replaced.
    pub fn overridden_by(self, over: &BakeConfig) -> BakeConfig {
        BakeConfig {
            preset: over.preset.or(self.preset),
            entries: over.entries.or(self.entries),
            clusters: over.clusters.or(self.clusters),
            resolution: over.resolution.or(self.resolution),
            texel_size: over.texel_size.or(self.texel_size),
            paths_per_entry: over.paths_per_entry.or(self.paths_per_entry),
            seed: over.seed.or(self.seed),
            top_k: over.top_k.or(self.top_k),
            face_resolution: over.face_resolution.or(self.face_resolution),
            vpl_disk_scale: over.vpl_disk_scale.or(self.vpl_disk_scale),
            archive_budget_mib: over.archive_budget_mib.or(self.archive_budget_mib),
            memory_budget_mib: over.memory_budget_mib.or(self.memory_budget_mib),
            time_budget_s: over.time_budget_s.or(self.time_budget_s),
            sky: over.sky.or(self.sky),
            sky_paths: over.sky_paths.or(self.sky_paths),
            probes: over.probes.or(self.probes),
            probe_rays: over.probe_rays.or(self.probe_rays),
            near_rays: over.near_rays.or(self.near_rays),
            accuracy_points: over.accuracy_points.or(self.accuracy_points),
            accuracy_paths: over.accuracy_paths.or(self.accuracy_paths),
        }
    }
}

/// How the atlas is sized.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub enum AtlasSize {
    /// Texels on a side.
    Resolution(u32),
    /// Texel size in scene units.
    TexelSize(f32),
}

impl From<AtlasSize> for prm_scene::Sizing {
    fn from(a: AtlasSize) -> prm_scene::Sizing {
        match a {
            AtlasSize::Resolution(r) => prm_scene::Sizing::Resolution(r),
            AtlasSize::TexelSize(s) => prm_scene::Sizing::TexelSize(s),
        }
    }
}

/// Fully resolved parameters of one bake, and why each automatic value was chosen.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct BakeParams {
    /// The preset they started from.
    pub preset: Preset,
    /// Entry points.
    pub entries: usize,
    /// Clusters (panes); equal to `entries` means no clustering.
    pub clusters: usize,
    /// Atlas size.
    pub atlas: AtlasSize,
    /// Walks per entry point.
    pub paths_per_entry: u32,
    /// Seed.
    pub seed: u64,
    /// Clusters blended per frame at run time.
    pub top_k: usize,
    /// Hemicube face resolution.
    pub face_resolution: u32,
    /// VPL disk radius multiplier (0: plain 1/r²; by default [`NEAR_FIELD_DISK_SCALE`] where
    /// the near field is traced, else 1).
    pub vpl_disk_scale: f32,
    /// Archive budget, MiB.
    pub archive_budget_mib: f64,
    /// Run-time pane memory budget, MiB.
    pub memory_budget_mib: f64,
    /// Bake time budget of the automatic sizes, seconds.
    pub time_budget_s: f64,
    /// Paths per texel of the sky's transfer, when the archive holds one: as given, else
    /// [`crate::SKY_PATHS`] doubled up to [`MAX_AUTO_SKY_PATHS`] while the planned bake and the
    /// sky step (by [`SKY_PATH_SECONDS`]) stay within the time budget.
    pub sky_paths: Option<u32>,
    /// Most grid cells of the irradiance probes, when the archive holds them
    /// ([`crate::PROBE_CELLS`] is the command line's default).
    pub probes: Option<u32>,
    /// Rays per probe of the probe rays section (0: none).
    pub probe_rays: u32,
    /// Near rays per exit point of the near field section (0: none).
    pub near_rays: u32,
    /// Points (3×3-texel patches) of the accuracy check after the panes (0: none; a shard never
    /// checks).
    /// Not in the archive's `params`: the check changes no pane, and its own record (the
    /// metadata's `accuracy`) says how large it was, so a merge of shards is the single bake's
    /// archive whatever the shards were told.
    #[serde(skip)]
    pub accuracy_points: u32,
    /// Reference paths per checked exit point and light (not in `params`, as above).
    #[serde(skip)]
    pub accuracy_paths: u32,
    /// What [`CostModel`] expects these parameters to cost, seconds (without the emitter, sky,
    /// probe and accuracy-check steps).
    pub estimated_seconds: f64,
    /// One line per automatic choice.
    pub reasons: Vec<String>,
}

struct PresetValues {
    entries: usize,
    clusters: usize,
    resolution: u32,
    paths: u32,
    top_k: usize,
    face: u32,
}

fn preset_values(p: Preset) -> Option<PresetValues> {
    match p {
        Preset::Preview => Some(PresetValues {
            entries: 1024,
            clusters: 64,
            resolution: 128,
            paths: 1,
            top_k: 16,
            face: 64,
        }),
        Preset::Paper => Some(PresetValues {
            entries: 4096,
            clusters: 256,
            resolution: 256,
            paths: 1,
            top_k: 32,
            face: 128,
        }),
        Preset::High => Some(PresetValues {
            entries: 16384,
            clusters: 1024,
            resolution: 512,
            paths: 2,
            top_k: 64,
            face: 256,
        }),
        Preset::Default => None,
    }
}

/// The most texels a pane may have: an 8192² atlas.
const MAX_ATLAS_TEXELS: f64 = 8192.0 * 8192.0;

/// Default budgets.
pub const DEFAULT_ARCHIVE_BUDGET_MIB: f64 = 512.0;
/// Default run-time pane memory budget.
pub const DEFAULT_MEMORY_BUDGET_MIB: f64 = 256.0;
/// Default bake time budget: ten minutes.
pub const DEFAULT_TIME_BUDGET_S: f64 = 600.0;

/// What a bake costs on the reference machine (2 cores): the pane rendering dominates, so each
/// model counts what it spends its time on. [`Renderer::cost_model`](crate::Renderer) picks the
/// one of the renderer the bake runs on.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub enum CostModel {
    /// The GPU pane passes (measured on lavapipe).
    Gpu(GpuCost),
    /// The CPU pane renderers.
    Cpu(CpuCost),
}

/// The GPU model: hemicube faces, the triangles they draw after culling, and VPL × exit point
/// evaluations.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct GpuCost {
    /// Fixed cost of one hemicube face, seconds.
    pub face_seconds: f64,
    /// Cost of one triangle drawn into a face, seconds.
    pub triangle_seconds: f64,
    /// Fraction of the scene's triangles a face draws after chunk culling.
    pub drawn_fraction: f64,
    /// VPL × exit point evaluations per second in the gather pass.
    pub evaluations_per_second: f64,
    /// VPLs traced per second (walks, on the CPU).
    pub vpls_per_second: f64,
}

/// The CPU model: every VPL × exit point pair costs `pair_seconds × triangles^triangle_exponent`
/// (its share of the shadow rays, which grow with the BVH's depth, plus the unoccluded term).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct CpuCost {
    /// Seconds per VPL × exit point pair in a one-triangle scene.
    pub pair_seconds: f64,
    /// How the cost per pair grows with the scene's triangle count.
    pub triangle_exponent: f64,
    /// VPLs traced per second (walks).
    pub vpls_per_second: f64,
}

impl CostModel {
    /// Lavapipe, measured with `cargo run --release -p prm-gpu --example bench_panes` on the
    /// reference machine while it was shared (the job got about 60% of its two cores), so on a
    /// quiet one bakes take about half the estimate: Sibenik's default bake, expected 510 s, took
    /// 246 s quiet and 606 s shared.
    pub const GPU: CostModel = CostModel::Gpu(GpuCost {
        face_seconds: 1.0e-4,
        triangle_seconds: 3.0e-7,
        drawn_fraction: 0.2,
        evaluations_per_second: 12.0e6,
        vpls_per_second: 1.0e6,
    });

    /// `--backend cpu` (shared visibility), fitted to the pane rendering time per pair of four
    /// bakes (`cargo xtask bench-bake`, quiet machine, AVX2 variants): the Cornell box's default
    /// (30 triangles, 4.7 ns per pair), chairs with the paper preset (2,910, 15.8 ns) and
    /// Sibenik at 5120 and 2048 entries (75,277, 29.6 and 34.4 ns). The per-pair cost grows as
    /// T^0.26 between the first two and T^0.22 between chairs and Sibenik; T^0.24 with 2.2 ns
    /// fits all within 10 %. (Before the AVX2 variants: 8.3, 26.4 and 53.5 ns, 3.7 ns × T^0.24,
    /// measured on a busier machine; before the lattice was anchored per chart: 11.7, 33.3 and
    /// 80.5 ns.)
    pub const CPU: CostModel = CostModel::Cpu(CpuCost {
        pair_seconds: 2.2e-9,
        triangle_exponent: 0.24,
        vpls_per_second: 1.0e6,
    });

    /// `--backend cpu-exact`: 50.9 ns per pair on the Cornell box and 72.7 ns on chairs (paper
    /// preset), T^0.078; not measured on larger scenes.
    pub const CPU_EXACT: CostModel = CostModel::Cpu(CpuCost {
        pair_seconds: 39.6e-9,
        triangle_exponent: 0.078,
        vpls_per_second: 1.0e6,
    });

    /// Expected seconds for `entries` entry points with `paths` walks each, `bounces_per_walk`
    /// VPLs per walk besides each entry point's own, over `exits` exit points in a scene of
    /// `triangles`.
    pub fn bake_seconds(&self, entries: usize, paths: u32, bounces_per_walk: f64, exits: f64, triangles: f64) -> f64 {
        let vpls = entries as f64 * (1.0 + paths as f64 * bounces_per_walk);
        self.seconds(vpls, exits, triangles)
    }

    /// Expected seconds for `vpls` VPLs over `exits` exit points in a scene of `triangles`.
    pub fn seconds(&self, vpls: f64, exits: f64, triangles: f64) -> f64 {
        match self {
            CostModel::Gpu(g) => {
                let faces = 5.0 * vpls;
                faces * (g.face_seconds + g.triangle_seconds * g.drawn_fraction * triangles)
                    + vpls * exits / g.evaluations_per_second
                    + vpls / g.vpls_per_second
            }
            CostModel::Cpu(c) => {
                vpls * exits * c.pair_seconds * triangles.max(1.0).powf(c.triangle_exponent) + vpls / c.vpls_per_second
            }
        }
    }
}

/// Most entry points the doublings reach, but for the lamps' ([`MAX_DOUBLED_ENTRIES`]).
const MAX_AUTO_ENTRIES: usize = 16384;

/// Most entry points the chart rule ([`ENTRIES_PER_CHART`]) asks for:
/// [`MANY_CHARTS_ENTRIES_PER_CLUSTER`] for each of the [`MAX_AUTO_CLUSTERS`]. Where the charts
/// ask this many, the doublings ([`MAX_DOUBLINGS`]) add none: a cluster's pane spreads its
/// members' light over the area they cover, which a lamp close to a surface shows most, and
/// more entry points share the same walks. Measured under six lamp positions 0.4 m from a
/// ceiling and six 0.4 m from a wall in each scene (`cargo xtask eval --lamps`: the `--targets`
/// lamps and views, moved by 0.2–0.4 m; 4×4 image error against 256-path references, mean over
/// positions, 512² atlas, 65536 walks). In 2048 clusters: Sponza 15.6% / 17.1% at 8192 entry
/// points (energy 0.98 / 1.04) against 15.3% / 18.2% at 16384 (1.04 / 0.92), Sibenik 18.3% /
/// 16.3% (1.04 / 0.98) against 17.8% / 16.1% (0.91 / 0.96). In 1024 clusters, played by the
/// entry points' own irradiance: Sponza 20.7% / 18.9% at 8192 against 24.5% / 18.5% at 16384
/// (28.8% / 18.7% at 32768, 28.1% / 26.8% at 4096), Sibenik 21.8% / 21.6% against 31.4% /
/// 21.6%, the ceiling lamps' energy 0.92 / 0.91 against 0.86 / 0.75.
const MAX_CHART_ENTRIES: usize = MANY_CHARTS_ENTRIES_PER_CLUSTER * MAX_AUTO_CLUSTERS;

/// Most paths per texel the time budget gives the sky's transfer (from [`crate::SKY_PATHS`],
/// doubled). Measured on Dabrovic Sponza (`cargo xtask eval --sky`, its default plan of about
/// 200 s): 256 paths take the sky step 28.5 s for 9.20% under a uniform sky, 1024 take 120 s
/// for 6.24%; the error falls about as `1/√paths` (the texels' noise), and beyond 1024 the 512²
/// texels themselves are most of what is left (15.4% at full resolution, 17.5% at 256 paths).
pub const MAX_AUTO_SKY_PATHS: u32 = 1024;

/// Seconds per path of the sky's transfer on the reference machine (two cores), for the plan:
/// Sponza's sky step, 26.3 M paths (256 per texel) in 28.5 s and 105 M in 120 s (1.08 and 1.14
/// µs). Simpler scenes go faster (our courtyard about 0.2 µs), so the estimate errs long.
pub const SKY_PATH_SECONDS: f64 = 1.14e-6;

/// Panes the automatic atlas leaves room for in the run-time memory budget at the largest rank
/// ([`pane_memory_bound`]): the atlas shrinks (in steps of 64 texels a side) until this many
/// fit, and until the near field's hits fit [`AUTO_ATLAS_NEAR_HITS`], which keeps the larger VPL
/// disks ([`NEAR_FIELD_DISK_SCALE`]). Measured on the fireplace
/// room at the default time budget (`cargo xtask eval --targets`'s lamp, 4×4 error): a 704²
/// atlas with 108 clusters, 18.4% (a 70 s bake); 512² with 205 clusters, 14.6% (115 s). The
/// reference's own lightmap at 512², shaded in place of the played one, is 6.1% off: the
/// coarser atlas costs little beside the clusters it buys.
const AUTO_ATLAS_PANES: usize = 256;

/// Bytes of coefficients the run time's mix pass may read a frame, at the largest rank in every
/// tile ([`MIX_BYTES_PER_TEXEL`]; real bakes keep a third to nearly all of that rank), from
/// which the automatic top K follows (less the residual groups, `prm_format::RESIDUAL_GROUPS`):
/// every cluster of a 256² atlas (4002 panes), 1000 panes at 512², 250 at 1024². The more
/// clusters a frame blends the better: on McGuire's box baked with 4096 entry points and 16
/// walks each (512 clusters; `cargo xtask eval --targets`'s lights, 4×4 error, ceiling light /
/// red wall light), K = 32 with 16 groups 8.1% / 6.5%, K = 64 with 32 groups 6.2% / 5.0%, K =
/// 128 with 64 groups 4.3% / 4.6%, every cluster 3.4% / 4.7%. The mix reads 4 bytes per rank
/// and tile of a kept pane, and the blend's work per texel does not grow with K: on lavapipe
/// at 1024×768 the frame bench (`cargo bench -p prm-play --bench frame`,
/// `PRM_BENCH_PRESET=default`) puts the Cornell box's 504 clusters beyond the first 8 at −3.0
/// to 4.1 ms of a frame whose lights move (two runs, within their noise), chairs' 1912 at
/// 12.3–17.1 ms.
const MIX_BYTES: f64 = 32.0 * 1024.0 * 1024.0;

/// Coefficient bytes per texel of a pane at the largest rank in 64² tiles, the bound
/// [`MIX_BYTES`] counts with: a pane's block in a tile (an 8-byte scale word and 4 bytes a rank
/// for its three channels) and its 4-byte entry in the tile's index
/// (`(8·(1 + 2·128/4) + 4) / 64²`, about 0.13). Real bakes keep far lower ranks, and the run
/// time does not keep the blocks that are zero.
const MIX_BYTES_PER_TEXEL: f64 = (8.0 * (1.0 + 2.0 * prm_format::MAX_PANE_RANK as f64 / 4.0) + 4.0) / 4096.0;

/// The automatic top K at least, however large the atlas.
const MIN_AUTO_TOP_K: usize = 32;

/// How many times the automatic entry points double where the time budget allows (below):
/// McGuire's box low near the red wall wants 4096 entry points (4.7%, 7.0% with 2048, every
/// cluster blended), four times its charts' 1024.
const MAX_DOUBLINGS: usize = 2;

/// Entry-point spacing, `√(A/N)` in scene units (metres), above which the automatic entry
/// points double once more ([`MAX_DOUBLINGS`] + 1) where the time budget allows. A lamp within
/// half a metre of a ceiling or wall, common in game levels, puts an irradiance peak about that
/// wide on it, which entry points farther apart than that sample with one or two. In the modern
/// hall (`cargo xtask eval --targets`, 4×4 image error, lamps 0.4 m from a surface), 18432 entry
/// points 0.24 m apart at 4 walks each read 4.1% (energy 0.987) under the ceiling lamp and 11.5%
/// (0.983) by the wall, against 5.0% (1.015) and 11.9% (0.960) at 9216 entry points 0.34 m apart
/// with 8 walks, for a bake of 228 s instead of 202 s: the walks in all, and so the VPLs to
/// render, stay the same.
const LAMP_ENTRY_SPACING: f64 = 0.2;

/// Most entry points the doublings reach ([`MAX_DOUBLINGS`]).
const MAX_DOUBLED_ENTRIES: usize = 32768;

/// The largest `vpl_disk_scale`: at the fewest entry points (1024) a scene is about
/// √1024 = 32 entry-point radii across, so a disk of 1000 radii already covers any scene many
/// times over; larger values only overflow the near field's disk (1e30 would fail after the
/// panes with an infinite disk).
pub const MAX_VPL_DISK_SCALE: f32 = 1000.0;

/// The VPL disk's radius multiplier (`vpl_disk_scale`) where the bake traces the near field and
/// its hits fit [`NEAR_HIT_BUDGET`]: the panes bound each VPL by a disk this many times the
/// radius of its entry point's area `A/N`, and the near field gathers back what the disk
/// removes, so a larger disk moves light from the entry points' point samples to the gather.
/// Measured by `cargo xtask eval --targets` (default bakes, 4×4 error): the fireplace room 6.06%
/// at 8 against 6.76% at 4 and 7.08% at 3, McGuire's box 2.65% / 2.43%; past 8 the
/// full-resolution error grows. Without the near field (`--near-rays 0`) the scale is 1.
pub const NEAR_FIELD_DISK_SCALE: f32 = 8.0;

/// The scale where the near field's hits could pass [`NEAR_HIT_BUDGET`], whose smaller reach
/// keeps fewer hits (a 1024² fireplace room plays at 3). Also the scale of a bake whose probes are lit through the panes (`--probe-rays 0`): a probe has no
/// near field, and the disks take its light (`cargo xtask eval --probes`, the panes' column,
/// default Cornell box: 23.2%, energy 0.881, at 3; 45.9%, 0.681, at 8).
pub const NEAR_FIELD_DISK_SCALE_LARGE: f32 = 3.0;

/// Most near hits (texels times near rays) of the automatic atlas: 512² at the default 32 near
/// rays ([`prm_trace::NEAR_RAYS`]), the atlas the large scenes' memory, bake time and accuracy
/// were measured at (the fireplace room, Sibenik, the modern hall). Half of [`NEAR_HIT_BUDGET`],
/// so the automatic atlas always keeps [`NEAR_FIELD_DISK_SCALE`].
pub const AUTO_ATLAS_NEAR_HITS: u64 = NEAR_HIT_BUDGET / 2;

/// Most near hits (the atlas's texels times the near rays each, before merging) for which the
/// bake takes [`NEAR_FIELD_DISK_SCALE`]: 2²⁴ hits of 8 bytes fill one 128 MiB storage binding,
/// lavapipe's limit and wgpu's default, so the player can hold them even unmerged (724² texels
/// at the default 32 rays). The bake holds the traced near field's merged hits to it as well,
/// halving the rays per exit point until they fit (pipeline.rs, `fit_near_field`): an atlas set
/// by hand passes it even at [`NEAR_FIELD_DISK_SCALE_LARGE`].
pub const NEAR_HIT_BUDGET: u64 = 1 << 24;

/// Entry points per cluster of the automatic cluster count. Measured by `cargo xtask eval
/// --targets` (4×4 error, every cluster blended): McGuire's box with 2048 entry points, light
/// under the ceiling / low near the red wall, 6.9% / 21.3% at 32 per cluster (a cluster's lit and
/// shadowed members share one weight), 5.2% / 9.2% at 8 and 5.4% / 7.1% at 2. The bake's time
/// follows the VPL count, not the clusters; the panes' memory and archive and the bytes a
/// frame reads follow the clusters (the budgets cap them): the Cornell box's default bake in
/// 1024 clusters instead of 512 reads 2.6% / 2.1% instead of 2.7% / 2.6% against the reference,
/// but its GI passes read 9.0 MB an update instead of 7.8 (`prm-play --timings`).
const ENTRIES_PER_CLUSTER: usize = 8;

/// Entry points per cluster where the chart rule asks the most automatic entry points
/// ([`MAX_CHART_ENTRIES`]): such a scene's entry points do not double, so its clusters take the
/// bytes instead. Measured by `cargo xtask eval --lamps` (six positions of a lamp 0.4 m under a
/// ceiling / from a wall, 4×4 error, mean): Sponza's 8192 entry points in 2048 clusters read
/// 15.6% / 17.1% (energy 0.976 / 1.042) against 17.6% / 17.3% (1.051 / 1.042) in 1024,
/// Sibenik's 18.3% / 16.3% (1.036 / 0.980) against 19.3% / 18.4% (0.993 / 0.969).
const MANY_CHARTS_ENTRIES_PER_CLUSTER: usize = 4;

/// Walks in all that the automatic walks per entry point aim at. Measured by `cargo xtask eval
/// --targets` (4×4 error, every cluster blended, 8 entry points per cluster): McGuire's box under
/// the ceiling light, 2048 entry points with 8, 16, 32 and 64 walks each, 5.1%, 4.4%, 3.9% and
/// 3.4%; CornellBox-Sphere at 4096 × 16 2.8% (4.5% at 2048 × 8), chairs at 7680 × 8 4.1% (5.5%
/// at 7680 × 3). The bake's time follows the walks: 24 s on McGuire's box, 33 s on
/// CornellBox-Sphere, 89 s on chairs.
const WALKS_IN_ALL: usize = 65536;

/// Most walks per entry point where the cluster cap cuts the automatic entry points (below):
/// those it keeps walk towards twice `WALKS_IN_ALL` in all, up to this many each, as far as the
/// time budget allows (where the budgets allow few clusters, walk noise is the largest share of
/// the error). Measured by `cargo xtask eval --targets` on the fireplace room planned with 205
/// clusters, which keep 3072 of its 15360 entry points (4×4 error, seeds 0 / 1 / 2): 5.32% /
/// 5.75% / 5.98% with a 208 s bake, against 5.58% / 6.32% / 6.29% and 110 s at 16; 32 is the
/// first count tried under 6% at all three seeds. Sponza does not gain (`cargo xtask eval --sky`, sky and sun).
const CAPPED_WALKS: u32 = 32;

/// Bytes an atlas texel's basis row takes resident at most: the largest rank, 128, in `f16`.
const BASIS_BYTES_PER_TEXEL: f64 = 2.0 * prm_format::MAX_PANE_RANK as f64;

/// The most bytes the run time keeps resident for `panes` panes (clusters and residual groups)
/// of `texels` texels: every 64² tile at the largest rank, its basis rows and every pane's
/// coefficients. Real bakes keep from a third of that rank to nearly all of it
/// (`prm-bake dump`): 3.5 MiB of the 5.2 MiB bound on the Cornell box's default bake, 97.2
/// of 131.5 MiB on Sibenik's. The memory budget counts with it.
fn pane_memory_bound(panes: f64, texels: f64) -> f64 {
    texels * (BASIS_BYTES_PER_TEXEL + panes * MIX_BYTES_PER_TEXEL)
}

/// Bytes an atlas texel of a pane takes in the archive budget's estimate: the whole archive
/// over its atlas's texels and its clusters. Measured on the default bakes of the `cargo xtask
/// eval --targets` cases (`prm-bake dump`): 0.56 on the Cornell box (128², 512 clusters), where
/// the fixed sections weigh most, 0.41 on CornellBox-Sphere, 0.35 on chairs, 0.22–0.32 on the
/// fireplace room, 0.24 on Sponza, 0.26 on Sibenik and 0.15 on the modern hall (512², 1024
/// clusters), 0.18 on Sponza in 2048 clusters; 1.0 leaves a margin for panes less alike.
const ARCHIVE_BYTES_PER_TEXEL: f64 = 1.0;

/// The smallest side, texels, the time budget shrinks an automatic atlas to (more where its
/// charts need more).
const MIN_AUTO_ATLAS: u32 = 128;

/// Texels a side the automatic atlas loses at each step while [`AUTO_ATLAS_PANES`] panes do not
/// fit the memory budget.
const ATLAS_MEMORY_STEP: u32 = 64;

/// Automatic atlas sides are whole multiples of this many texels.
const ATLAS_STEP: u32 = 32;

/// Automatic entry points per chart of the scene (charts are its distinct flat pieces).
const ENTRIES_PER_CHART: usize = 4;

/// Automatic entry-point counts are whole multiples of this.
const ENTRY_STEP: usize = 256;

/// Fewest entry points the automatic rules choose, and the time budget and the cluster cap leave.
const MIN_AUTO_ENTRIES: usize = 1024;

/// Most automatic entry points per cluster the bake can have. Where the budgets cap the
/// clusters, more entry points only crowd them: Sibenik's own error estimate
/// (`--accuracy-points`, three lights) is the same at 2048 and 16384 entries, for three times the
/// bake.
const MAX_ENTRIES_PER_CLUSTER: usize = 16;

/// Most automatic walks per entry point ([`auto_walks_per_entry`]).
const MAX_AUTO_WALKS: usize = 16;

/// Fewest automatic clusters (fewer where there are fewer entry points).
const MIN_AUTO_CLUSTERS: usize = 32;

/// Most automatic clusters before the memory and archive budgets cap them: the 8192 entry
/// points of a large scene ([`MAX_CHART_ENTRIES`]) at [`MANY_CHARTS_ENTRIES_PER_CLUSTER`] each.
/// Baked so (512² atlas), Sponza keeps 107.2 MiB resident on the GPU and Sibenik 115.5 MiB
/// (`prm-bake dump`), within the 128 MiB a large scene may take, in bakes of 285 s and 296 s
/// (`cargo xtask eval --targets`).
const MAX_AUTO_CLUSTERS: usize = 2048;

/// Share of an atlas given by resolution or texel size that the first time estimate takes to be
/// exit points, before that atlas is built ([`Plan::for_renderer`](crate::Plan) then builds it
/// and estimates again).
const GUESSED_UTILIZATION: f64 = 0.5;

/// The pane passes' cube-face resolution without a preset or `--face-resolution`.
const DEFAULT_FACE_RESOLUTION: u32 = 128;

/// The most bytes the run time keeps resident for the panes of `clusters` clusters and their
/// residual groups in a `resolution`² atlas: every 64² tile at the largest rank, 256 bytes of
/// `f16` basis per texel and about 0.13 bytes of coefficients per texel and pane. Bakes keep
/// well under it (the tolerance sets the ranks): `prm-bake dump` prints an archive's own.
pub fn resident_pane_bytes(clusters: usize, resolution: u32) -> u64 {
    let groups = prm_format::residual_group_count(clusters, prm_format::RESIDUAL_GROUPS) as usize;
    pane_memory_bound((clusters + groups) as f64, f64::from(resolution).powi(2)) as u64
}

/// The smallest automatic atlas side that holds `charts` charts: every chart needs a texel and
/// its gutters, a 3×3 block at the least, in whole steps of [`ATLAS_STEP`] texels.
fn atlas_floor(charts: usize) -> u32 {
    ((3.0 * (charts as f64).sqrt() / ATLAS_STEP as f64).ceil() as u32 * ATLAS_STEP).max(ATLAS_STEP)
}

/// Why the automatic top K is `k`: every cluster, or the panes a frame mixes less the residual
/// groups, with the arithmetic only where it holds (when the groups take every pane, the floor
/// decides).
fn top_k_reason(k: usize, panes: usize, groups: usize, clusters: usize) -> String {
    let mib = MIX_BYTES / (1024.0 * 1024.0);
    let frame = format!(
        "the coefficients of {panes} pane{} fit {mib:.0} MiB a frame",
        plural(panes)
    );
    if k == clusters && (k <= panes || k < MIN_AUTO_TOP_K) {
        format!("top K {k}: every cluster ({frame})")
    } else if panes >= groups + MIN_AUTO_TOP_K {
        format!("top K {k}: {frame}, less {groups} residual groups")
    } else {
        format!(
            "top K {k}: at least {MIN_AUTO_TOP_K} ({frame}: {} beside {groups} residual groups)",
            panes.saturating_sub(groups)
        )
    }
}

/// The automatic walks per entry point: enough for about `WALKS_IN_ALL`, 1 to [`MAX_AUTO_WALKS`].
fn auto_walks_per_entry(entries: usize) -> u32 {
    WALKS_IN_ALL.div_ceil(entries.max(1)).clamp(1, MAX_AUTO_WALKS) as u32
}

/// "s" unless `n` is one.
pub fn plural(n: usize) -> &'static str {
    if n == 1 {
        ""
    } else {
        "s"
    }
}

/// Expected VPLs per walk beyond the entry point's own (which every entry point has once, however
/// many walks leave it) in a closed scene: a walk stores a VPL per bounce and survives a bounce
/// with the roulette's probability q̄ (area-weighted), so q̄ / (1 − q̄) on average. Walks that
/// escape make fewer: [`Plan::new`](crate::Plan) measures the count instead.
#[cfg(test)]
pub(crate) fn bounces_per_walk(scene: &Scene) -> f64 {
    let roulette = prm_trace::Roulette::DEFAULT;
    let (mut q, mut area) = (0.0f64, 0.0f64);
    for (i, t) in scene.triangles.iter().enumerate() {
        let a = t.area() as f64;
        q += a * roulette.survival(scene.albedo(i, 1.0 / 3.0, 1.0 / 3.0)) as f64;
        area += a;
    }
    let q = (q / area.max(1e-30)).min(0.95);
    q / (1.0 - q)
}

/// The bake's budgets, and the panes they allow.
struct Budgets {
    /// The archive's size, MiB.
    archive_mib: f64,
    /// The run-time pane memory, MiB.
    memory_mib: f64,
    /// The bake's time, seconds.
    time_s: f64,
}

impl Budgets {
    /// The config's budgets, else the defaults; all positive.
    fn resolve(config: &BakeConfig) -> Result<Budgets, BakeError> {
        let archive_budget_mib = config.archive_budget_mib.unwrap_or(DEFAULT_ARCHIVE_BUDGET_MIB);
        let memory_budget_mib = config.memory_budget_mib.unwrap_or(DEFAULT_MEMORY_BUDGET_MIB);
        let time_budget_s = config.time_budget_s.unwrap_or(DEFAULT_TIME_BUDGET_S);
        if !(archive_budget_mib > 0.0 && memory_budget_mib > 0.0 && time_budget_s > 0.0) {
            invalid!(
                "budgets must be positive (archive {archive_budget_mib} MiB, memory {memory_budget_mib} MiB, \
                 time {time_budget_s} s)"
            );
        }
        Ok(Budgets {
            archive_mib: archive_budget_mib,
            memory_mib: memory_budget_mib,
            time_s: time_budget_s,
        })
    }

    /// The most panes of `texels_per_pane` the memory budget holds ([`pane_memory_bound`])
    /// beside the residual groups' (up to one group per `CLUSTERS_PER_GROUP` clusters, at most
    /// `RESIDUAL_GROUPS`).
    fn by_memory(&self, texels_per_pane: f64) -> usize {
        let budget = self.memory_mib * 1024.0 * 1024.0;
        let basis = pane_memory_bound(0.0, texels_per_pane);
        let panes = ((budget - basis).max(0.0) / (pane_memory_bound(1.0, texels_per_pane) - basis)) as usize;
        let per = prm_format::CLUSTERS_PER_GROUP as usize;
        let groups = (panes / (per + 1)).min(prm_format::RESIDUAL_GROUPS as usize);
        panes - groups
    }

    /// The most panes of `texels_per_pane` the archive budget holds.
    fn by_archive(&self, texels_per_pane: f64) -> usize {
        (self.archive_mib * 1024.0 * 1024.0 / (ARCHIVE_BYTES_PER_TEXEL * texels_per_pane)) as usize
    }

    /// The most panes of `texels_per_pane` that both budgets allow, at least one.
    fn clusters_allowed(&self, texels_per_pane: f64) -> usize {
        self.by_memory(texels_per_pane)
            .min(self.by_archive(texels_per_pane))
            .max(1)
    }
}

/// A size a rule settled, and whether the planner chose it (the later rules change only those).
#[derive(Clone, Copy)]
struct Choice<T> {
    value: T,
    auto: bool,
}

/// The atlas a rule settled.
#[derive(Clone, Copy)]
struct AtlasChoice {
    size: AtlasSize,
    /// The automatic atlas's side as first chosen (`None`: the atlas is given).
    auto_resolution: Option<u32>,
    /// The smallest side the time budget may shrink an automatic atlas to.
    smallest: u32,
}

/// The sizes the rules settle in turn, and the time the bake is expected to take at them.
struct Draft {
    atlas: AtlasChoice,
    entries: Choice<usize>,
    walks: Choice<u32>,
    /// Share of the atlas's texels the time estimate counts as exit points.
    utilization: f64,
    /// Expected seconds at the sizes first chosen.
    planned_seconds: f64,
    /// Expected seconds at the current sizes.
    estimated_seconds: f64,
    /// Whether the cluster cap cut the entry points.
    capped: bool,
    /// Whether the chart rule asked the most automatic entry points, [`MAX_CHART_ENTRIES`]: the
    /// doublings add none and the clusters take [`MANY_CHARTS_ENTRIES_PER_CLUSTER`].
    many_charts: bool,
}

/// What the planner's rules read: the config, its preset's values, the scene, the budgets and
/// the cost model.
struct Planner<'a> {
    config: &'a BakeConfig,
    fixed: Option<PresetValues>,
    scene: &'a Scene,
    budgets: Budgets,
    cost: &'a CostModel,
    /// VPLs per walk beyond the entry point's own.
    bounces_per_walk: f64,
}

impl Planner<'_> {
    /// Texels of a pane of `atlas`: the side squared, or for a texel size twice the scene's area
    /// in texels.
    fn texels(&self, atlas: AtlasSize) -> f64 {
        match atlas {
            AtlasSize::Resolution(r) => (r as f64).powi(2),
            AtlasSize::TexelSize(s) => self.scene.area() / (s as f64).powi(2) * 2.0,
        }
    }

    /// The seconds the cost model expects of `entries` entry points with `walks` walks each in
    /// `atlas`, of which the share `utilization` of texels are exit points.
    fn seconds(&self, utilization: f64, entries: usize, walks: u32, atlas: AtlasSize) -> f64 {
        let exits = utilization * self.texels(atlas);
        let triangles = self.scene.triangles.len() as f64;
        self.cost
            .bake_seconds(entries, walks, self.bounces_per_walk, exits, triangles)
    }

    /// The atlas: given (resolution, texel size or preset), else the atlas's own automatic size
    /// (about 12 texels per triangle or 64 per chart) shrunk until [`AUTO_ATLAS_PANES`] panes fit the memory
    /// budget, never below what its charts need.
    fn atlas_rule(
        &self,
        probe: &dyn Fn() -> Result<Atlas, BakeError>,
        reasons: &mut Vec<String>,
    ) -> Result<AtlasChoice, BakeError> {
        let given = |size| AtlasChoice {
            size,
            auto_resolution: None,
            smallest: MIN_AUTO_ATLAS,
        };
        let auto = match (self.config.resolution, self.config.texel_size, &self.fixed) {
            (Some(r), _, _) => return Ok(given(AtlasSize::Resolution(r))),
            (None, Some(s), _) => return Ok(given(AtlasSize::TexelSize(s))),
            (None, None, Some(v)) => return Ok(given(AtlasSize::Resolution(v.resolution))),
            (None, None, None) => probe()?,
        };
        let mut r = auto.resolution;
        let budget = self.budgets.memory_mib * 1024.0 * 1024.0;
        let over_memory = |r: u32| pane_memory_bound(AUTO_ATLAS_PANES as f64, f64::from(r).powi(2)) > budget;
        // The near field's hits within the budget that keeps the larger VPL disks.
        let near_rays = u64::from(self.near_rays_rule());
        let keeps_disks = self.config.vpl_disk_scale.is_none() && near_rays > 0;
        let over_near = |r: u32| keeps_disks && u64::from(r).pow(2) * near_rays > AUTO_ATLAS_NEAR_HITS;
        // Never below what the charts need: the bake would refuse that atlas.
        let floor = atlas_floor(auto.stats.charts as usize).min(auto.resolution);
        while r > floor.max(ATLAS_MEMORY_STEP) && (over_memory(r) || over_near(r)) {
            r = (r - ATLAS_MEMORY_STEP).max(floor);
        }
        let why = if r == auto.resolution {
            String::new()
        } else if over_near(auto.resolution) && !over_memory(r + ATLAS_MEMORY_STEP) {
            format!(", shrunk so its {near_rays} near rays a texel keep within {AUTO_ATLAS_NEAR_HITS} hits")
        } else {
            ", shrunk so 256 panes fit the memory budget".to_string()
        };
        reasons.push(format!(
            "atlas {r}² texels: {} triangles want about 12 texels each, {} charts 64{why}",
            self.scene.triangles.len(),
            auto.stats.charts,
        ));
        Ok(AtlasChoice {
            size: AtlasSize::Resolution(r),
            auto_resolution: Some(r),
            smallest: floor.max(MIN_AUTO_ATLAS).min(r),
        })
    }

    /// The entry points: given, else [`ENTRIES_PER_CHART`] per chart, [`MIN_AUTO_ENTRIES`] to
    /// [`MAX_CHART_ENTRIES`], a multiple of [`ENTRY_STEP`].
    fn entries_rule(
        &self,
        probe: &dyn Fn() -> Result<Atlas, BakeError>,
        reasons: &mut Vec<String>,
    ) -> Result<Choice<usize>, BakeError> {
        let given = |value| Ok(Choice { value, auto: false });
        match (self.config.entries, &self.fixed) {
            (Some(n), _) => given(n),
            (None, Some(v)) => given(v.entries),
            (None, None) => {
                let charts = probe()?.stats.charts as usize;
                let n = (ENTRIES_PER_CHART * charts)
                    .div_ceil(ENTRY_STEP)
                    .clamp(MIN_AUTO_ENTRIES / ENTRY_STEP, MAX_CHART_ENTRIES / ENTRY_STEP)
                    * ENTRY_STEP;
                reasons.push(format!(
                    "{n} entry points: 4 per chart of the scene's {charts} charts, \
                     {MIN_AUTO_ENTRIES}..{MAX_CHART_ENTRIES} ({MANY_CHARTS_ENTRIES_PER_CLUSTER} for each of at most \
                     {MAX_AUTO_CLUSTERS} clusters)"
                ));
                Ok(Choice { value: n, auto: true })
            }
        }
    }

    /// The walks per entry point: given, else enough for about [`WALKS_IN_ALL`] in all
    /// ([`auto_walks_per_entry`]).
    fn walks_rule(&self, entries: usize, reasons: &mut Vec<String>) -> Choice<u32> {
        let given = |value| Choice { value, auto: false };
        match (self.config.paths_per_entry, &self.fixed) {
            (Some(m), _) => given(m),
            (None, Some(v)) => given(v.paths),
            (None, None) => {
                let m = auto_walks_per_entry(entries);
                reasons.push(format!(
                    "{m} walk{} per entry point: about {WALKS_IN_ALL} walks in all",
                    plural(m as usize)
                ));
                Choice { value: m, auto: true }
            }
        }
    }

    /// The draft of the sizes chosen so far, with the time the bake is expected to take at them:
    /// the automatic atlas's own share of exit points, else [`GUESSED_UTILIZATION`].
    fn draft(
        &self,
        atlas: AtlasChoice,
        entries: Choice<usize>,
        walks: Choice<u32>,
        probe: &dyn Fn() -> Result<Atlas, BakeError>,
    ) -> Result<Draft, BakeError> {
        let utilization = match atlas.auto_resolution {
            Some(_) => probe()?.stats.utilization as f64,
            None => GUESSED_UTILIZATION,
        };
        let planned_seconds = self.seconds(utilization, entries.value, walks.value, atlas.size);
        Ok(Draft {
            atlas,
            entries,
            walks,
            utilization,
            planned_seconds,
            estimated_seconds: planned_seconds,
            capped: false,
            many_charts: entries.auto && entries.value >= MAX_CHART_ENTRIES,
        })
    }

    /// The time budget: while the bake is expected to take longer, fewer walks, fewer entry
    /// points (down to [`MIN_AUTO_ENTRIES`]) or a smaller atlas (down to its smallest), among the
    /// automatic sizes, whichever saves the most time.
    fn fit_time_budget(&self, draft: &mut Draft, reasons: &mut Vec<String>) {
        let time_budget_s = self.budgets.time_s;
        let estimate = |entries, walks, atlas| self.seconds(draft.utilization, entries, walks, atlas);
        let (mut entries, mut walks, mut atlas) = (draft.entries.value, draft.walks.value, draft.atlas.size);
        let mut estimated_seconds = draft.estimated_seconds;
        while estimated_seconds > time_budget_s {
            // Each step drops about a quarter of one size; take the one that saves the most time.
            let fewer_walks = (draft.walks.auto && walks > 1).then(|| (entries, walks - 1, atlas));
            let fewer_entries = (draft.entries.auto && entries > MIN_AUTO_ENTRIES).then(|| {
                (
                    ((entries * 3 / 4) / ENTRY_STEP * ENTRY_STEP).max(MIN_AUTO_ENTRIES),
                    walks,
                    atlas,
                )
            });
            let smallest = draft.atlas.smallest;
            let smaller_atlas = match atlas {
                AtlasSize::Resolution(r) if draft.atlas.auto_resolution.is_some() && r > smallest => Some((
                    entries,
                    walks,
                    AtlasSize::Resolution(((r * 7 / 8) / ATLAS_STEP * ATLAS_STEP).max(smallest)),
                )),
                _ => None,
            };
            let Some((e, m, a, t)) = [fewer_walks, fewer_entries, smaller_atlas]
                .into_iter()
                .flatten()
                .map(|(e, m, a)| (e, m, a, estimate(e, m, a)))
                .min_by(|x, y| x.3.total_cmp(&y.3))
            else {
                break;
            };
            (entries, walks, atlas, estimated_seconds) = (e, m, a, t);
        }
        let planned = draft.planned_seconds;
        if estimated_seconds < planned {
            reasons.push(format!(
                "shrunk to fit the {time_budget_s:.0} s time budget: {planned:.0} s expected at the sizes above, \
                 {estimated_seconds:.0} s with {entries} entries, {walks} walk{} each{}",
                plural(walks as usize),
                match atlas {
                    AtlasSize::Resolution(r) => format!(", atlas {r}²"),
                    AtlasSize::TexelSize(_) => String::new(),
                }
            ));
        }
        (draft.entries.value, draft.walks.value, draft.atlas.size) = (entries, walks, atlas);
        draft.estimated_seconds = estimated_seconds;
    }

    /// The cluster cap: no more automatic entry points than [`MAX_ENTRIES_PER_CLUSTER`] per
    /// cluster the bake can have (given, or the most the budgets allow at the atlas the time
    /// budget left); the automatic walks per entry then rise towards twice [`WALKS_IN_ALL`], at
    /// most [`CAPPED_WALKS`] each, as far as the time budget allows. Applied after the time
    /// budget's shrinking: before, it would let Sponza under a 60 s budget trade clusters for
    /// atlas (52.3 % from the reference instead of 42.4 %, `cargo xtask eval --budget`).
    fn cap_entries(&self, draft: &mut Draft, reasons: &mut Vec<String>) {
        if !draft.entries.auto {
            return;
        }
        let atlas = draft.atlas.size;
        let (clusters, which) = match self.config.clusters {
            Some(c) => (c, "given"),
            None => (self.budgets.clusters_allowed(self.texels(atlas)), "the budgets allow"),
        };
        let cap = (clusters.saturating_mul(MAX_ENTRIES_PER_CLUSTER) / ENTRY_STEP * ENTRY_STEP).max(MIN_AUTO_ENTRIES);
        if draft.entries.value <= cap {
            return;
        }
        let entries = cap;
        draft.entries.value = entries;
        draft.capped = true;
        let estimate = |walks| self.seconds(draft.utilization, entries, walks, atlas);
        let mut walks = draft.walks.value;
        if draft.walks.auto {
            let wanted = (2 * WALKS_IN_ALL).div_ceil(entries).clamp(1, CAPPED_WALKS as usize) as u32;
            while walks < wanted && estimate(walks + 1) <= self.budgets.time_s {
                walks += 1;
            }
        }
        draft.walks.value = walks;
        draft.estimated_seconds = estimate(walks);
        reasons.push(format!(
            "{entries} entry points, {walks} walk{} each: at most 16 for each of the {clusters} \
             clusters {which}",
            plural(walks as usize)
        ));
    }

    /// Twice the automatic entry points (and so clusters), up to [`MAX_DOUBLINGS`] times (once
    /// more while they are over [`LAMP_ENTRY_SPACING`] apart), where the charts asked fewer
    /// than [`MAX_CHART_ENTRIES`], neither the time budget nor the cluster cap cut anything and
    /// the time budget allows it: at
    /// most [`MAX_DOUBLED_ENTRIES`] and [`MAX_ENTRIES_PER_CLUSTER`] per cluster the budgets allow
    /// (beyond, more entry points only crowd the clusters), the automatic walks per entry falling
    /// to keep about [`WALKS_IN_ALL`].
    fn double_entries(&self, draft: &mut Draft, reasons: &mut Vec<String>) {
        let uncut = draft.estimated_seconds >= draft.planned_seconds && !draft.capped;
        if !(draft.entries.auto && uncut) || draft.many_charts {
            return;
        }
        let atlas = draft.atlas.size;
        let allowed = self.budgets.clusters_allowed(self.texels(atlas));
        for doubling in 0..=MAX_DOUBLINGS {
            // The last doubling, for lamps near surfaces, may crowd the clusters more.
            let lamps = doubling == MAX_DOUBLINGS;
            let spacing = (self.scene.area() / draft.entries.value as f64).sqrt();
            if lamps && spacing <= LAMP_ENTRY_SPACING {
                break;
            }
            let most = match lamps {
                false => MAX_AUTO_ENTRIES.min(ENTRIES_PER_CLUSTER * allowed),
                true => MAX_DOUBLED_ENTRIES.min(MAX_ENTRIES_PER_CLUSTER * allowed),
            };
            let more = draft.entries.value * 2;
            let walks = if draft.walks.auto {
                auto_walks_per_entry(more)
            } else {
                draft.walks.value
            };
            let doubled = self.seconds(draft.utilization, more, walks, atlas);
            if more > most || doubled > self.budgets.time_s {
                break;
            }
            (draft.entries.value, draft.walks.value, draft.estimated_seconds) = (more, walks, doubled);
            let why = match lamps {
                false => String::new(),
                true => format!(", for lamps near surfaces ({spacing:.2} apart, over {LAMP_ENTRY_SPACING})"),
            };
            reasons.push(format!(
                "{more} entry points, {walks} walk{} each: twice as many, as the time budget allows{why}",
                plural(walks as usize)
            ));
        }
    }

    /// The clusters: given (a preset's at most one per entry point), else entries /
    /// [`ENTRIES_PER_CLUSTER`] ([`MANY_CHARTS_ENTRIES_PER_CLUSTER`] where the chart rule asked
    /// the most), [`MIN_AUTO_CLUSTERS`] to [`MAX_AUTO_CLUSTERS`], then as many as
    /// the memory and archive budgets allow.
    fn clusters_rule(&self, draft: &Draft, reasons: &mut Vec<String>) -> usize {
        let entries = draft.entries.value;
        match (self.config.clusters, &self.fixed) {
            (Some(c), _) => c,
            (None, Some(v)) => v.clusters.min(entries),
            (None, None) => {
                let texels_per_pane = self.texels(draft.atlas.size);
                let per = match draft.many_charts {
                    true => MANY_CHARTS_ENTRIES_PER_CLUSTER,
                    false => ENTRIES_PER_CLUSTER,
                };
                let per_entries = entries / per;
                let wanted = per_entries.clamp(MIN_AUTO_CLUSTERS, MAX_AUTO_CLUSTERS).min(entries);
                let (by_memory, by_archive) = (
                    self.budgets.by_memory(texels_per_pane),
                    self.budgets.by_archive(texels_per_pane),
                );
                let c = wanted.min(self.budgets.clusters_allowed(texels_per_pane));
                reasons.push(format!(
                    "{c} clusters: entries/{per} = {per_entries} ({MIN_AUTO_CLUSTERS}..{MAX_AUTO_CLUSTERS}), \
                     memory budget allows {by_memory}, archive budget {by_archive}"
                ));
                c
            }
        }
    }

    /// The top K: given, else the panes whose coefficients fit [`MIX_BYTES`] a frame less the
    /// residual groups (every cluster when they all fit), at least [`MIN_AUTO_TOP_K`]; never
    /// more than the clusters.
    fn top_k_rule(&self, clusters: usize, texels_per_pane: f64, reasons: &mut Vec<String>) -> usize {
        match self.config.top_k.or(self.fixed.as_ref().map(|v| v.top_k)) {
            Some(k) => k,
            None => {
                let groups = prm_format::residual_group_count(clusters, prm_format::RESIDUAL_GROUPS) as usize;
                let panes = (MIX_BYTES / (MIX_BYTES_PER_TEXEL * texels_per_pane)) as usize;
                let k = if panes >= clusters {
                    clusters
                } else {
                    panes.saturating_sub(groups).max(MIN_AUTO_TOP_K)
                };
                reasons.push(top_k_reason(k.min(clusters), panes, groups, clusters));
                k
            }
        }
        .min(clusters)
    }

    /// The pane passes' cube-face resolution: given, else the preset's, else
    /// [`DEFAULT_FACE_RESOLUTION`].
    fn face_resolution_rule(&self) -> u32 {
        self.config
            .face_resolution
            .or(self.fixed.as_ref().map(|v| v.face))
            .unwrap_or(DEFAULT_FACE_RESOLUTION)
    }

    /// The sky's paths per texel: given, else with `--sky` [`crate::SKY_PATHS`], doubled up to
    /// [`MAX_AUTO_SKY_PATHS`] while the planned bake and the sky step fit the time budget; none
    /// without the sky.
    fn sky_paths_rule(&self, draft: &Draft, reasons: &mut Vec<String>) -> Result<Option<u32>, BakeError> {
        match (self.config.sky_paths, self.config.sky) {
            (Some(paths), Some(false)) => {
                invalid!("sky_paths = {paths} asks for the sky, which sky = false turns off: drop one of them")
            }
            (Some(paths), _) => Ok(Some(paths)),
            (None, Some(true)) => {
                let exits = draft.utilization * self.texels(draft.atlas.size);
                let step = |paths: u32| exits * paths as f64 * SKY_PATH_SECONDS;
                let mut paths = crate::SKY_PATHS;
                while paths < MAX_AUTO_SKY_PATHS && draft.estimated_seconds + step(2 * paths) <= self.budgets.time_s {
                    paths *= 2;
                }
                reasons.push(format!(
                    "sky: {paths} paths per texel, a sky step of about {:.0} s{}",
                    step(paths),
                    if paths > crate::SKY_PATHS {
                        " within what the time budget leaves"
                    } else {
                        ""
                    }
                ));
                Ok(Some(paths))
            }
            _ => Ok(None),
        }
    }

    /// The near rays per exit point: given, else [`prm_trace::NEAR_RAYS`]; none without the VPL
    /// bound, since nothing is missing near the exit points then.
    fn near_rays_rule(&self) -> u32 {
        if self.config.vpl_disk_scale == Some(0.0) {
            0
        } else {
            self.config.near_rays.unwrap_or(prm_trace::NEAR_RAYS)
        }
    }

    /// The VPL disks' scale: given; else 1 without the near field; else
    /// [`NEAR_FIELD_DISK_SCALE_LARGE`] for probes lit through the panes, which have no near
    /// field to give back what a disk takes, or where the near hits could pass
    /// [`NEAR_HIT_BUDGET`]; else [`NEAR_FIELD_DISK_SCALE`].
    fn vpl_disk_scale_rule(&self, atlas: AtlasSize, near_rays: u32, reasons: &mut Vec<String>) -> f32 {
        let config = self.config;
        match config.vpl_disk_scale {
            Some(scale) => scale,
            None if near_rays == 0 => 1.0,
            None if config.probes.is_some() && config.probe_rays == Some(0) => {
                reasons.push(format!(
                    "VPL disks {NEAR_FIELD_DISK_SCALE_LARGE} times the entry points' radius: the probes are \
                     lit through the panes (--probe-rays 0), which larger disks would take light from"
                ));
                NEAR_FIELD_DISK_SCALE_LARGE
            }
            None => {
                let texels = self.texels(atlas);
                let fits = texels * near_rays as f64 <= NEAR_HIT_BUDGET as f64;
                let scale = if fits {
                    NEAR_FIELD_DISK_SCALE
                } else {
                    NEAR_FIELD_DISK_SCALE_LARGE
                };
                reasons.push(format!(
                    "VPL disks {scale} times the entry points' radius: {near_rays} near rays from each of about \
                     {texels:.0} texels, {} {NEAR_HIT_BUDGET} hits",
                    if fits { "at most" } else { "possibly over" }
                ));
                scale
            }
        }
    }
}

impl BakeParams {
    /// Resolves `config` for `scene`; `probe` builds the automatic atlas when one is needed, and
    /// `cost` estimates the bake's time from the VPL count: one per entry point and
    /// `bounces_per_walk` per walk.
    ///
    /// Automatic rules (preset `default`, each overridable):
    /// - atlas: the atlas's own automatic size (about 12 texels per triangle or 64 per chart,
    ///   128 to 4096 a side),
    ///   shrunk until `AUTO_ATLAS_PANES` (256) panes fit the run-time memory budget;
    /// - entries: 4 per chart (charts are the scene's distinct flat pieces), 1024 to 8192 (4 for
    ///   each of at most 2048 clusters, `MAX_CHART_ENTRIES`), a multiple of 256, and no more
    ///   than 16 per cluster the bake can have (`--clusters`, or the most the memory and
    ///   archive budgets allow; not below 1024), applied after the time budget below, at the atlas it leaves, the walks per entry then rising towards twice
    ///   `WALKS_IN_ALL`, at most `CAPPED_WALKS` (32) each, as far as the budget allows. Where the
    ///   budgets cap the clusters, more entry points only crowd them: Sibenik's own error estimate
    ///   (`--accuracy-points`, three lights) is the same at 2048 and 16384 entries, for three
    ///   times the bake; applied before the time budget's shrinking, the cap would let Sponza
    ///   under a 60 s budget trade clusters for atlas (52.3 % from the reference instead of
    ///   42.4 %, `cargo xtask eval --budget`);
    /// - walks per entry: enough for about `WALKS_IN_ALL` (65536) walks in all, 1 to 16;
    /// - then, while `cost` expects the bake to take longer than the time budget,
    ///   fewer walks, fewer entries (down to 1024) or a smaller atlas (down to 128²), whichever is
    ///   furthest above its floor;
    /// - then, where the charts asked fewer than 8192, neither the time budget nor the cap cut
    ///   anything and the budget allows it,
    ///   twice the entry points, up to `MAX_DOUBLINGS` (2) times and once more while they are
    ///   over `LAMP_ENTRY_SPACING` (0.2 m) apart, at most 32768 and at most
    ///   `MAX_ENTRIES_PER_CLUSTER` (16) per cluster the budgets allow, the walks per entry falling to
    ///   keep about `WALKS_IN_ALL`. One doubling is the largest step down the
    ///   accuracy-against-speed front (`cargo xtask eval --full`, lightmap error, mean of three
    ///   lights): the Cornell box 0.111 for a bake of 4.4 s (0.131, 2.7 s undoubled),
    ///   CornellBox-Sphere 0.114, 13.7 s (0.125, 9.5 s), chairs 0.107, 24.3 s (0.120, 13.6 s);
    ///   where the budgets cap the clusters more entries only crowd them (above);
    /// - clusters: entries / `ENTRIES_PER_CLUSTER` (8; 4 where the charts asked 8192), 32 to
    ///   2048, then as many as the
    ///   memory budget (the clusters' panes and the residual groups' summed ones, up to one per
    ///   4 clusters, at most `prm_format::RESIDUAL_GROUPS`) and the archive budget allow
    ///   (archive estimate: 1.0 byte per atlas texel per pane, `ARCHIVE_BYTES_PER_TEXEL`, about
    ///   twice the most measured).
    pub fn resolve(
        config: &BakeConfig,
        scene: &Scene,
        cost: &CostModel,
        bounces_per_walk: f64,
        probe: impl Fn() -> Result<Atlas, BakeError>,
    ) -> Result<BakeParams, BakeError> {
        let preset = config.preset.unwrap_or(Preset::Default);
        let fixed = preset_values(preset);
        let budgets = Budgets::resolve(config)?;
        let planner = Planner {
            config,
            fixed,
            scene,
            budgets,
            cost,
            bounces_per_walk,
        };
        let mut reasons = Vec::new();
        let atlas = planner.atlas_rule(&probe, &mut reasons)?;
        let entries = planner.entries_rule(&probe, &mut reasons)?;
        let walks = planner.walks_rule(entries.value, &mut reasons);
        let mut draft = planner.draft(atlas, entries, walks, &probe)?;
        planner.fit_time_budget(&mut draft, &mut reasons);
        planner.cap_entries(&mut draft, &mut reasons);
        planner.double_entries(&mut draft, &mut reasons);
        let clusters = planner.clusters_rule(&draft, &mut reasons);
        let texels_per_pane = planner.texels(draft.atlas.size);
        let top_k = planner.top_k_rule(clusters, texels_per_pane, &mut reasons);
        let face_resolution = planner.face_resolution_rule();
        let sky_paths = planner.sky_paths_rule(&draft, &mut reasons)?;
        let near_rays = planner.near_rays_rule();
        let vpl_disk_scale = planner.vpl_disk_scale_rule(draft.atlas.size, near_rays, &mut reasons);

        let Budgets {
            archive_mib,
            memory_mib,
            time_s,
        } = planner.budgets;
        let params = BakeParams {
            preset,
            entries: draft.entries.value,
            clusters,
            atlas: draft.atlas.size,
            paths_per_entry: draft.walks.value,
            seed: config.seed.unwrap_or(0),
            top_k,
            face_resolution,
            vpl_disk_scale,
            archive_budget_mib: archive_mib,
            memory_budget_mib: memory_mib,
            time_budget_s: time_s,
            sky_paths,
            probes: config.probes,
            probe_rays: config.probe_rays.unwrap_or(crate::PROBE_RAYS),
            near_rays,
            accuracy_points: config.accuracy_points.unwrap_or(crate::ACCURACY_POINTS),
            accuracy_paths: config.accuracy_paths.unwrap_or(crate::ACCURACY_PATHS),
            estimated_seconds: draft.estimated_seconds,
            reasons,
        };
        params.validate(texels_per_pane)?;
        Ok(params)
    }

    /// Rejects impossible combinations before any work.
    fn validate(&self, texels_per_pane: f64) -> Result<(), BakeError> {
        if self.entries == 0 {
            invalid!("--entries must be at least 1");
        }
        if self.clusters == 0 {
            invalid!("--clusters must be at least 1");
        }
        if self.entries as u64 > prm_format::limits::MAX_ENTRIES {
            over_limit!(
                "--entries {} is over the archive format's limit of {} entry points",
                self.entries,
                prm_format::limits::MAX_ENTRIES
            );
        }
        if self.clusters as u64 > prm_format::limits::MAX_CLUSTERS {
            over_limit!(
                "--clusters {} is over the archive format's limit of {} clusters",
                self.clusters,
                prm_format::limits::MAX_CLUSTERS
            );
        }
        if self.top_k == 0 {
            invalid!("--top-k must be at least 1 (the clusters blended per frame)");
        }
        if self.clusters > self.entries {
            invalid!(
                "{} clusters for {} entry points: there cannot be more clusters than entries",
                self.clusters,
                self.entries
            );
        }
        if self.paths_per_entry == 0 {
            invalid!("--paths-per-entry must be at least 1");
        }
        if self.accuracy_paths < 2 {
            // One pass gives the reference no variance to remove from the estimate.
            invalid!("--accuracy-paths must be at least 2");
        }
        if self.sky_paths == Some(0) {
            invalid!("--sky-paths must be at least 1");
        }
        if let Some(p) = self.probes {
            if p == 0 || p > prm_format::MAX_PROBES {
                invalid!("--probes {p} is outside 1..={} grid cells", prm_format::MAX_PROBES);
            }
        }
        if self.probe_rays > prm_format::MAX_PROBE_RAYS {
            invalid!(
                "--probe-rays {} is more than {} rays per probe",
                self.probe_rays,
                prm_format::MAX_PROBE_RAYS
            );
        }
        if self.near_rays > prm_format::MAX_NEAR_RAYS {
            invalid!(
                "--near-rays {} is more than {} rays per exit point",
                self.near_rays,
                prm_format::MAX_NEAR_RAYS
            );
        }
        if let AtlasSize::Resolution(r) = self.atlas {
            if !(8..=8192).contains(&r) {
                invalid!("resolution {r} is outside 8..=8192");
            }
        }
        if let AtlasSize::TexelSize(s) = self.atlas {
            if !(s.is_finite() && s > 0.0) {
                invalid!("--texel-size {s} must be a positive number");
            }
            if texels_per_pane > MAX_ATLAS_TEXELS {
                over_limit!(
                    "--texel-size {s} gives about {texels_per_pane:.3e} texels, more than an 8192² atlas holds; \
                     use a larger --texel-size"
                );
            }
        }
        if !(8..=2048).contains(&self.face_resolution) {
            invalid!("face resolution {} is outside 8..=2048", self.face_resolution);
        }
        if !(0.0..=MAX_VPL_DISK_SCALE).contains(&self.vpl_disk_scale) {
            invalid!(
                "vpl_disk_scale {} is outside 0..={MAX_VPL_DISK_SCALE} (entry-point radii)",
                self.vpl_disk_scale
            );
        }
        let memory_mib = pane_memory_bound(self.clusters as f64, texels_per_pane) / (1024.0 * 1024.0);
        if memory_mib > self.memory_budget_mib {
            over_limit!(
                "{} panes of {:.0} texels may need {memory_mib:.0} MiB at run time (rank 128 in every tile), over \
                 the {:.0} MiB memory budget; \
                 use fewer --clusters, {}, or raise memory_budget_mib",
                self.clusters,
                texels_per_pane,
                self.memory_budget_mib,
                match self.atlas {
                    AtlasSize::Resolution(_) => "a lower --resolution",
                    AtlasSize::TexelSize(_) => "a larger --texel-size",
                }
            );
        }
        Ok(())
    }

    /// The VPL bound these parameters ask for: the disk, or where the bake traces the near
    /// field, the kernel that completes its cut weights (`VplBound::Near`).
    pub fn bound(&self) -> prm_trace::VplBound {
        if self.vpl_disk_scale > 0.0 && self.near_rays > 0 {
            prm_trace::VplBound::Near {
                scale: self.vpl_disk_scale,
            }
        } else if self.vpl_disk_scale > 0.0 {
            prm_trace::VplBound::Disk {
                scale: self.vpl_disk_scale,
            }
        } else {
            prm_trace::VplBound::None
        }
    }
}

#[cfg(test)]
mod tests;
