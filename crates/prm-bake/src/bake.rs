//! `prm-bake bake`: arguments → parameters → backend → [`prm_bake::bake`] → summary and report.

use anyhow::{Context, Result};
use prm_bake::params::plural;
use prm_bake::{AtlasSize, BakeConfig, BakeJob, BakeParams, Plan, Preset, Renderer};
use prm_gpu::{Backend, GpuContext};
use std::collections::BTreeMap;
use std::path::PathBuf;
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
    /// Vulkan if there is an adapter, else OpenGL.
    Auto,
    /// Vulkan (lavapipe on machines without a GPU).
    Vulkan,
    /// OpenGL (llvmpipe on machines without a GPU).
    Gl,
    /// No GPU: the CPU pane evaluator, with exact ray-cast visibility (slow; a yardstick).
    Cpu,
}

/// Arguments of `prm-bake bake`.
#[derive(clap::Args, Debug)]
pub struct BakeArgs {
    /// Scene file: .obj (with its .mtl), .gltf or .glb.
    pub scene: PathBuf,
    /// The archive to write (replaced atomically; nothing is left behind on failure).
    #[arg(short, long, value_name = "OUT.prm")]
    pub output: PathBuf,
    /// Named parameter set; `default` derives sizes from the scene and the budgets.
    #[arg(long, value_enum)]
    pub preset: Option<PresetArg>,
    /// Entry points sampled on the surfaces.
    #[arg(long)]
    pub entries: Option<usize>,
    /// Clusters of entry points, one pane each (equal to --entries: no clustering).
    #[arg(long)]
    pub clusters: Option<usize>,
    /// Atlas and pane resolution (texels on a side).
    #[arg(long, conflicts_with = "texel_size")]
    pub resolution: Option<u32>,
    /// Atlas texel size in scene units (instead of --resolution).
    #[arg(long)]
    pub texel_size: Option<f32>,
    /// Random walks from every entry point.
    #[arg(long)]
    pub paths_per_entry: Option<u32>,
    /// Seed of every random choice; the same seed gives the same archive.
    #[arg(long)]
    pub seed: Option<u64>,
    /// Clusters blended per frame at run time (recorded in the archive for the player).
    #[arg(long)]
    pub top_k: Option<usize>,
    /// Longest bake, in seconds, that the automatic sizes (preset `default`) may plan for; they
    /// shrink to fit it (default 600). Explicit sizes are never changed.
    #[arg(long, value_name = "SECONDS")]
    pub time_budget: Option<f64>,
    /// TOML file with any of the parameters above (and budgets); the command line wins.
    #[arg(long, value_name = "FILE.toml")]
    pub config: Option<PathBuf>,
    /// Where panes are rendered.
    #[arg(long, value_enum, default_value = "auto")]
    pub backend: BackendArg,
    /// Also write the parameters, counts and timings as JSON here.
    #[arg(long, value_name = "FILE.json")]
    pub report: Option<PathBuf>,
    /// Print nothing but warnings and errors.
    #[arg(long)]
    pub quiet: bool,
    /// Only print the parameters the bake would use, why, and the time it expects (and write them
    /// to --report); no archive is written.
    #[arg(long)]
    pub plan: bool,
}

impl BakeArgs {
    fn config(&self) -> BakeConfig {
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
            ..Default::default()
        }
    }
}

/// Opens the device the panes are rendered on, checked to run the pane passes
/// ([`prm_gpu::check_support`]). `auto` tries Vulkan, then OpenGL, then bakes on the CPU, and
/// says why it passed over each; an explicit GPU backend that cannot bake is an error.
fn open_backend(arg: BackendArg, progress: &Progress) -> Result<Option<GpuContext>> {
    let open = |b: Backend| -> Result<GpuContext, prm_gpu::GpuError> {
        let ctx = GpuContext::new(b)?;
        prm_gpu::check_support(&ctx)?;
        Ok(ctx)
    };
    let explicit = match arg {
        BackendArg::Cpu => return Ok(None),
        BackendArg::Vulkan => Backend::Vulkan,
        BackendArg::Gl => Backend::Gl,
        BackendArg::Auto => {
            for b in [Backend::Vulkan, Backend::Gl] {
                match open(b) {
                    Ok(ctx) => return Ok(Some(ctx)),
                    Err(e) => progress.warn(&format!("backend auto: passing over {b}: {e}")),
                }
            }
            progress.warn(
                "backend auto: no GPU backend can render panes, baking on the CPU (exact ray-cast \
                 visibility; slower). For the GPU path on a machine without a GPU: \
                 `apt-get install mesa-vulkan-drivers`",
            );
            return Ok(None);
        }
    };
    open(explicit).map(Some).with_context(|| {
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
    params: BakeParams,
    atlas: prm_scene::AtlasStats,
    triangles: usize,
    entries: usize,
    clusters: usize,
    walks: u64,
    vpls: usize,
    rays: u64,
    archive_bytes: u64,
    timings: BTreeMap<String, f64>,
}

/// `prm-bake bake`: plans, bakes through [`prm_bake::bake`], prints the summary and writes the
/// report.
pub fn run(args: &BakeArgs) -> Result<()> {
    // Before any work: refuse an unusable -o (a directory, a device, a directory where no file
    // can be created), follow a symlink to the file it names, and have SIGINT, SIGTERM and
    // SIGHUP remove the bake's temporary file.
    if !args.plan {
        crate::signals::install(prm_format::check_destination(&args.output)?);
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
    let load_s = t.elapsed().as_secs_f64();

    let plan = Plan::new(&config, &scene)?;
    print_plan(&plan.params, &progress);
    if args.plan {
        if let Some(path) = &args.report {
            // The same shape as a bake's report, which nests them under "params".
            std::fs::write(
                path,
                serde_json::to_string_pretty(&serde_json::json!({ "params": plan.params }))?,
            )
            .with_context(|| format!("writing {}", path.display()))?;
        }
        return Ok(());
    }

    // Open the device before the long CPU work, so a missing driver fails at once.
    let gpu = open_backend(args.backend, &progress)?;
    if let Some(ctx) = &gpu {
        progress.say(&format!("  device: {}", ctx.describe()));
    }
    let job = BakeJob {
        scene: &scene,
        scene_path: &args.scene,
        plan: &plan,
        output: &args.output,
    };
    let baked = prm_bake::bake(&job, gpu.as_ref().map_or(Renderer::Cpu, Renderer::Gpu), &mut progress)?;

    let mut timings = baked.timings;
    timings.insert("load".to_string(), load_s);
    timings.insert("total".to_string(), started.elapsed().as_secs_f64());
    let report = Report {
        scene: args.scene.clone(),
        output: args.output.clone(),
        backend: baked.backend,
        params: plan.params,
        atlas: baked.atlas,
        triangles: baked.triangles,
        entries: baked.entries,
        clusters: baked.clusters,
        walks: baked.walks,
        vpls: baked.vpls,
        rays: baked.rays,
        archive_bytes: baked.archive_bytes,
        timings,
    };
    if !args.quiet {
        print_summary(&report);
    }
    if let Some(path) = &args.report {
        std::fs::write(path, serde_json::to_string_pretty(&report)?)
            .with_context(|| format!("writing {}", path.display()))?;
    }
    Ok(())
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
        "  expected: about {:.0} s on the reference machine (time budget {:.0} s)",
        params.estimated_seconds, params.time_budget_s
    ));
}

/// The summary on stdout: the archive and the timing breakdown.
fn print_summary(r: &Report) {
    println!(
        "wrote {} ({:.2} MiB)",
        r.output.display(),
        r.archive_bytes as f64 / (1024.0 * 1024.0)
    );
    println!("timing breakdown:");
    for (name, key) in [
        ("scene load", "load"),
        ("atlas", "atlas"),
        ("BVH build", "bvh"),
        ("light tracing", "light_tracing"),
        ("clustering", "clustering"),
        ("pane rendering", "pane_rendering"),
        ("compression + write", "compression_write"),
        ("total", "total"),
    ] {
        println!("  {name:<20} {:>9.3} s", r.timings.get(key).copied().unwrap_or(0.0));
    }
}
