//! `prm-bake bake`: arguments → parameters → backend → [`prm_bake::bake`] → summary and report.

use anyhow::{Context, Result};
use prm_bake::params::plural;
use prm_bake::{AtlasSize, BakeConfig, BakeJob, BakeParams, Plan, Preset, Renderer, Shard};
use prm_gpu::{Backend, GpuContext};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

use crate::progress::Progress;

/// Named parameter sets (the command line's names for [`Preset`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum PresetArg {
    /// Small and fast: 1024 entries, 64 clusters, 128² panes.
    Preview,
    /// Sizes derived from the scene and the budgets.
    Default,
    /// The paper's marble chamber: 4096 entries, 256 clusters, 256² panes, 32 clusters at run time.
    Paper,
    /// 16384 entries, 1024 clusters, 512² panes.
    High,
}

impl From<PresetArg> for Preset {
    fn from(p: PresetArg) -> Preset {
        match p {
            PresetArg::Preview => Preset::Preview,
            PresetArg::Default => Preset::Default,
            PresetArg::Paper => Preset::Paper,
            PresetArg::High => Preset::High,
        }
    }
}

/// Where panes are rendered.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum BackendArg {
    /// A hardware GPU (Vulkan, else OpenGL) if there is one; else the native CPU evaluator, which
    /// is faster than a software rasterizer (lavapipe, llvmpipe). Says which and why.
    Auto,
    /// Vulkan (lavapipe on machines without a GPU).
    Vulkan,
    /// OpenGL (llvmpipe on machines without a GPU).
    Gl,
    /// No GPU: the native CPU evaluator, ray-cast visibility shared between neighbouring texels.
    Cpu,
    /// No GPU: one shadow ray per exit point and VPL (the exact yardstick; slower).
    CpuExact,
}

/// Arguments of `prm-bake bake`.
#[derive(clap::Args, Debug)]
pub struct BakeArgs {
    /// Scene file: .obj (with its .mtl), .gltf or .glb.
    pub scene: PathBuf,
    /// The archive to write (replaced atomically; nothing is left behind on failure; missing
    /// directories are created). An existing file that is not an archive (the scene, say) is
    /// not replaced.
    #[arg(short, long, value_name = "OUT.prm")]
    pub output: PathBuf,
    /// Named parameter set; `default` derives sizes from the scene and the budgets.
    #[arg(long, value_enum)]
    pub preset: Option<PresetArg>,
    /// Entry points sampled on the surfaces (at least 1).
    #[arg(long, value_parser = at_least_one())]
    pub entries: Option<usize>,
    /// Clusters of entry points, one pane each (equal to --entries: no clustering).
    #[arg(long, value_parser = at_least_one())]
    pub clusters: Option<usize>,
    /// Atlas and pane resolution (texels on a side, 8 to 8192).
    #[arg(long, conflicts_with = "texel_size", value_parser = clap::value_parser!(u32).range(8..=8192))]
    pub resolution: Option<u32>,
    /// Atlas texel size in scene units (instead of --resolution).
    #[arg(long)]
    pub texel_size: Option<f32>,
    /// Random walks from every entry point (at least 1).
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..))]
    pub paths_per_entry: Option<u32>,
    /// Seed of every random choice; the same seed gives the same archive.
    #[arg(long)]
    pub seed: Option<u64>,
    /// Clusters blended per frame at run time (recorded in the archive for the player). Default:
    /// as many as 192 panes of 256² texels a frame allow, less the residual groups (64 at most),
    /// at least 32; K = 128 at 256²
    #[arg(long, value_parser = at_least_one())]
    pub top_k: Option<usize>,
    /// Longest bake, in seconds, that the automatic sizes (preset `default`) may plan for; they
    /// shrink to fit it (default 600). Explicit sizes are never changed.
    #[arg(long, value_name = "SECONDS")]
    pub time_budget: Option<f64>,
    /// Also bake the sky's transfer (visibility and interreflection in order-2 spherical
    /// harmonics at every texel), so that the player can light the scene with any sky
    /// (`prm-play --sky`), turned and scaled at run time.
    #[arg(long)]
    pub sky: bool,
    /// Paths per texel of the sky's transfer (default: 256, doubled up to 1024 while the
    /// planned bake and the sky step fit the time budget; more: less noise, longer bake).
    #[arg(long, value_name = "PATHS", requires = "sky")]
    pub sky_paths: Option<u32>,
    /// Also place irradiance probes for moving objects: a grid of at most CELLS cells over the
    /// scene (default 512), a probe at every cell centre not inside geometry, each lit by the
    /// same panes' clusters so the run-time weights light it (`prm-play --probe-sphere`).
    #[arg(long, value_name = "CELLS", num_args = 0..=1, default_missing_value = "512")]
    pub probes: Option<u32>,
    /// Rays per probe that find the surfaces the player gathers the probes' light from, each
    /// frame, through the lightmap (default 1024; 0: none, the probes are lit through the panes'
    /// VPLs instead, and the VPL disks stay three entry-point radii).
    #[arg(long, value_name = "RAYS", requires = "probes")]
    pub probe_rays: Option<u32>,
    /// Cosine rays per exit point that find the surfaces close enough for the VPL bound to
    /// have removed their light (default 32; 0: none). The player gathers it back each frame
    /// from their light, mostly at inner edges and contacts. With it the
    /// VPL disks are eight times their entry point's radius where atlas texels × near rays fit
    /// 2^24 hits (a 724² atlas at 32 rays), else three (`vpl_disk_scale` in --config); without
    /// it once.
    #[arg(long, value_name = "RAYS")]
    pub near_rays: Option<u32>,
    /// After the panes, estimate the archive's accuracy: its indirect light against a
    /// reference path tracer over N patches of 3×3 texels (default 2048, drawn by surface
    /// area) for four point lights placed in the scene (one close to a surface), played as
    /// prm-play plays it (top K, residual groups, the near field's gathers), printed, recorded
    /// in the archive and shown by `dump`. 0 skips it. A few seconds of a default bake; shards
    /// skip it.
    #[arg(long, value_name = "N")]
    pub accuracy_points: Option<u32>,
    /// Reference paths per checked point and light (default 512), shared by its texels: the
    /// reference's noise is removed from the estimate, more paths only narrow its spread.
    #[arg(long, value_name = "PATHS")]
    pub accuracy_paths: Option<u32>,
    /// TOML file with any of the parameters above (and budgets); the command line wins.
    #[arg(long, value_name = "FILE.toml")]
    pub config: Option<PathBuf>,
    /// Where panes are rendered.
    #[arg(long, value_enum, default_value = "auto")]
    pub backend: BackendArg,
    /// Also write the parameters, counts and timings as JSON here (checked before the bake;
    /// not the archive's own path).
    #[arg(long, value_name = "FILE.json")]
    pub report: Option<PathBuf>,
    /// Print nothing but warnings and errors.
    #[arg(long)]
    pub quiet: bool,
    /// Only print the parameters the bake would use, why, and the time it expects (and write them
    /// to --report); no archive is written.
    #[arg(long)]
    pub plan: bool,
    /// Bake only shard I of N (cluster c belongs to shard c mod N) into a partial archive; join
    /// the N parts with `prm-bake merge`. Every shard needs the same scene, parameters and
    /// backend. Example: --shard 0/4 on the first of four machines.
    #[arg(long, value_name = "I/N", value_parser = parse_shard)]
    pub shard: Option<Shard>,
}

/// A count of at least 1 (`--entries`, `--clusters`, `--top-k`).
fn at_least_one() -> clap::builder::RangedU64ValueParser<usize> {
    clap::builder::RangedU64ValueParser::new().range(1..)
}

fn parse_shard(s: &str) -> Result<Shard, String> {
    s.parse()
}

impl BakeArgs {
    pub(crate) fn config(&self) -> BakeConfig {
        BakeConfig {
            preset: self.preset.map(Preset::from),
            entries: self.entries,
            clusters: self.clusters,
            resolution: self.resolution,
            texel_size: self.texel_size,
            paths_per_entry: self.paths_per_entry,
            seed: self.seed,
            top_k: self.top_k,
            time_budget_s: self.time_budget,
            sky: self.sky.then_some(true),
            sky_paths: self.sky_paths,
            probes: self.probes,
            probe_rays: self.probe_rays,
            near_rays: self.near_rays,
            accuracy_points: self.accuracy_points,
            accuracy_paths: self.accuracy_paths,
            ..Default::default()
        }
    }
}

/// What [`open_backend`] chose.
enum Chosen {
    Gpu(Box<GpuContext>),
    Cpu,
    CpuExact,
}

/// Opens the device the panes are rendered on, checked to run the pane passes
/// ([`prm_gpu::check_support`]). `auto` takes the first hardware adapter of Vulkan, then OpenGL,
/// and otherwise the native CPU evaluator, saying why it passed over each backend: on a software
/// rasterizer (lavapipe, llvmpipe) the CPU evaluator bakes the bundled Cornell box about ten
/// times as fast (`cargo xtask bench-bake`). An explicit GPU backend that cannot bake is an error.
fn open_backend(arg: BackendArg, progress: &Progress) -> Result<Chosen> {
    let open = |b: Backend| -> Result<GpuContext, prm_gpu::GpuError> {
        let ctx = GpuContext::new(b)?;
        prm_gpu::check_support(&ctx)?;
        Ok(ctx)
    };
    let explicit = match arg {
        BackendArg::Cpu => return Ok(Chosen::Cpu),
        BackendArg::CpuExact => return Ok(Chosen::CpuExact),
        BackendArg::Vulkan => Backend::Vulkan,
        BackendArg::Gl => Backend::Gl,
        BackendArg::Auto => {
            for b in [Backend::Vulkan, Backend::Gl] {
                match open(b) {
                    Ok(ctx) if ctx.is_software() => {
                        progress.say(&format!(
                            "  backend auto: {b} has only the software rasterizer {}, which the CPU \
                             evaluator outruns; baking on the CPU (--backend {} to use it anyway)",
                            ctx.info.name, b
                        ));
                        return Ok(Chosen::Cpu);
                    }
                    Ok(ctx) => return Ok(Chosen::Gpu(Box::new(ctx))),
                    Err(e) => progress.warn(&format!("backend auto: passing over {b}: {e}")),
                }
            }
            progress.warn("backend auto: no GPU backend can render panes, baking on the CPU");
            return Ok(Chosen::Cpu);
        }
    };
    open(explicit).map(|ctx| Chosen::Gpu(Box::new(ctx))).with_context(|| {
        format!(
            "the {explicit} backend cannot render panes (use --backend auto, or --backend cpu to bake without a GPU)"
        )
    })
}

/// Everything the bake measured, for the summary and `--report`.
#[derive(serde::Serialize)]
struct Report {
    scene: PathBuf,
    output: PathBuf,
    backend: String,
    /// `"I/N"` for a shard of a bake.
    shard: Option<String>,
    params: BakeParams,
    atlas: prm_scene::AtlasStats,
    triangles: usize,
    entries: usize,
    clusters: usize,
    walks: u64,
    vpls: usize,
    rays: u64,
    archive_bytes: u64,
    /// Peak resident memory of the process, bytes (Linux; absent elsewhere).
    peak_rss_bytes: Option<u64>,
    timings: BTreeMap<String, f64>,
    /// The accuracy check's estimate (absent: not checked).
    accuracy: Option<prm_format::Accuracy>,
}

/// The process's peak resident set size (`VmHWM` in `/proc/self/status`), where there is one.
fn peak_rss_bytes() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib * 1024)
}

/// `prm-bake bake`: plans, bakes through [`prm_bake::bake`], prints the summary and writes the
/// report.
pub fn run(args: &BakeArgs) -> Result<()> {
    // Before any work: refuse an unusable -o (a directory, a device, a directory where no file
    // can be created), follow a symlink to the file it names, and have SIGINT, SIGTERM and
    // SIGHUP remove the bake's temporary file.
    if !args.plan {
        crate::signals::install(prm_scene::check_destination(&args.output)?);
    }
    if let Some(report) = &args.report {
        check_report(report, (!args.plan).then_some(args.output.as_path()), &args.scene)?;
    }
    let mut progress = Progress::new(args.quiet);
    let started = Instant::now();

    let file_config = match &args.config {
        Some(p) => BakeConfig::load(p)?,
        None => BakeConfig::default(),
    };
    let config = file_config.overridden_by(&args.config());

    let t = Instant::now();
    let scene = prm_scene::load(&args.scene).context("loading the scene")?;
    for w in &scene.report.warnings {
        progress.warn(w);
    }
    let emissive = scene.emissive_materials();
    if !emissive.is_empty() {
        progress.say(&format!(
            "  emitters: {} (one group per emissive material; `prm-play --emitter NAME=SCALE` scales them)",
            emissive.join(", ")
        ));
    }
    let load_s = t.elapsed().as_secs_f64();

    // Open the device first: the plan's time budget is the renderer's, and a missing driver
    // fails before any long work.
    let chosen = open_backend(args.backend, &progress)?;
    let renderer = match &chosen {
        Chosen::Gpu(ctx) => {
            progress.say(&format!("  device: {}", ctx.describe()));
            Renderer::Gpu(ctx)
        }
        Chosen::Cpu => Renderer::Cpu,
        Chosen::CpuExact => Renderer::CpuExact,
    };
    let plan = Plan::for_renderer(&config, &scene, &renderer)?;
    print_plan(&plan.params, &progress);
    if let Some(shard) = args.shard.filter(|s| s.index as usize >= plan.params.clusters) {
        progress.warn(&format!(
            "shard {shard} holds no clusters: the plan has {} cluster{}, so shards {}..{} are empty \
             (a part without panes; use at most --shard I/{})",
            plan.params.clusters,
            plural(plan.params.clusters),
            plan.params.clusters,
            shard.count,
            plan.params.clusters
        ));
    }
    if args.plan {
        if let Some(path) = &args.report {
            // The same shape as a bake's report, which nests them under "params".
            write_report(path, &serde_json::json!({ "params": plan.params }))?;
        }
        return Ok(());
    }

    if let (Some(shard), Renderer::Gpu(_)) = (args.shard, renderer) {
        progress.warn(&format!(
            "shard {shard} on a GPU: batches of VPLs differ between shards, so the merged panes \
             match a single bake's to float rounding, not byte for byte (--backend cpu shards \
             merge into exactly the single bake's bytes)"
        ));
    }
    let job = BakeJob {
        scene: &scene,
        scene_path: &args.scene,
        plan: &plan,
        output: &args.output,
        shard: args.shard,
    };
    let baked = prm_bake::bake(&job, renderer, &mut progress)?;

    let mut timings = baked.timings;
    timings.insert("load".to_string(), load_s);
    timings.insert("total".to_string(), started.elapsed().as_secs_f64());
    let report = Report {
        scene: args.scene.clone(),
        output: args.output.clone(),
        backend: baked.backend,
        shard: args.shard.map(|s| s.to_string()),
        params: plan.params,
        atlas: baked.atlas,
        triangles: baked.triangles,
        entries: baked.entries,
        clusters: baked.clusters,
        walks: baked.walks,
        vpls: baked.vpls,
        rays: baked.rays,
        archive_bytes: baked.archive_bytes,
        peak_rss_bytes: peak_rss_bytes(),
        timings,
        accuracy: baked.accuracy,
    };
    if !args.quiet {
        print_summary(&report);
    }
    if let Some(path) = &args.report {
        write_report(path, &report)?;
    }
    Ok(())
}

/// Refuses, before any work, a `--report` path that names the archive being written, the scene,
/// an existing archive, a directory, or a file in a directory where none can be created
/// (missing directories are created, as for the archive).
fn check_report(report: &Path, archive: Option<&Path>, scene: &Path) -> Result<()> {
    if archive.is_some_and(|a| prm_scene::same_destination(a, report)) {
        crate::refuse!(
            "--report {}: it is the archive the bake writes (-o); name another file",
            report.display()
        );
    }
    if prm_scene::same_destination(scene, report) {
        crate::refuse!("--report {}: it is the scene; name another file", report.display());
    }
    let is_archive = || {
        use std::io::Read;
        let mut head = [0u8; prm_format::MAGIC.len()];
        std::fs::File::open(report)
            .and_then(|mut f| f.read_exact(&mut head))
            .is_ok()
            && head == prm_format::MAGIC
    };
    if std::fs::metadata(report).is_ok_and(|m| m.is_file()) && is_archive() {
        crate::refuse!("--report {}: it is a .prm archive; name another file", report.display());
    }
    prm_scene::check_output_path(report)
        .map_err(|why| anyhow::Error::new(crate::Refused(format!("--report {}: {why}", report.display()))))
}

/// Writes the report as JSON, creating missing directories.
fn write_report(path: &Path, report: &impl serde::Serialize) -> Result<()> {
    if let Some(dir) = path.parent().filter(|p| !p.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    std::fs::write(path, serde_json::to_string_pretty(report)?).with_context(|| format!("writing {}", path.display()))
}

/// The parameters the bake will use, why, and the time it expects.
fn print_plan(params: &BakeParams, progress: &Progress) {
    progress.say(&format!(
        "bake: {} entries, {} clusters, atlas {}, {} walk{} per entry, seed {}, top-k {} ({:?} preset)",
        params.entries,
        params.clusters,
        match params.atlas {
            AtlasSize::Resolution(r) => format!("{r}²"),
            AtlasSize::TexelSize(s) => format!("texel {s}"),
        },
        params.paths_per_entry,
        plural(params.paths_per_entry as usize),
        params.seed,
        params.top_k,
        params.preset
    ));
    for r in &params.reasons {
        progress.say(&format!("  auto: {r}"));
    }
    progress.say(&format!(
        "  expected: about {:.0} s on the reference machine with this renderer (time budget {:.0} s)",
        params.estimated_seconds, params.time_budget_s
    ));
    if let AtlasSize::Resolution(r) = params.atlas {
        let groups = prm_format::residual_group_count(params.clusters, prm_format::RESIDUAL_GROUPS);
        let mib = prm_bake::params::resident_pane_bytes(params.clusters, r) as f64 / (1024.0 * 1024.0);
        progress.say(&format!(
            "  footprint: panes at most {mib:.1} MiB resident on the GPU ({} clusters + {groups} residual groups, \
             {r}² texels, every tile at rank {}; the archive's own: `prm-bake dump`)",
            params.clusters,
            prm_format::MAX_PANE_RANK
        ));
    }
}

/// The summary on stdout: the archive and the timing breakdown.
fn print_summary(r: &Report) {
    outln!(
        "wrote {} ({:.2} MiB)",
        r.output.display(),
        r.archive_bytes as f64 / (1024.0 * 1024.0)
    );
    outln!("timing breakdown:");
    for (name, key) in [
        ("scene load", "load"),
        ("atlas", "atlas"),
        ("BVH build", "bvh"),
        ("light tracing", "light_tracing"),
        ("clustering", "clustering"),
        ("emitters", "emitters"),
        ("sky", "sky"),
        ("pane rendering", "pane_rendering"),
        ("near field", "near_field"),
        ("probes", "probes"),
        ("accuracy check", "accuracy_check"),
        ("compression + write", "compression_write"),
        ("total", "total"),
    ] {
        if matches!(key, "emitters" | "sky" | "near_field" | "probes" | "accuracy_check")
            && !r.timings.contains_key(key)
        {
            continue;
        }
        outln!("  {name:<20} {:>9.3} s", r.timings.get(key).copied().unwrap_or(0.0));
    }
    if let Some(b) = r.peak_rss_bytes {
        outln!("peak memory: {:.0} MiB", b as f64 / (1024.0 * 1024.0));
    }
    if let Some(a) = &r.accuracy {
        outln!("estimated accuracy: {}", prm_bake::accuracy_line(a));
    }
}
