//! `prm-bake bake`: scene → atlas → entry points → walks → clusters → panes → `.prm` archive.

use anyhow::{bail, Context, Result};
use glam::Vec3;
use prm_format::{ArchiveWriter, AtlasSection, Cluster, Entry, Metadata};
use prm_gpu::{Backend, GpuContext, PaneOutput, PaneRenderParams};
use prm_scene::{Atlas, AtlasParams, Sizing};
use prm_trace::{Bvh, BvhParams, ClusterParams, Clustering, EntryParams, PaneParams, WalkParams};
use std::cell::OnceCell;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

use crate::params::{AtlasSize, BakeConfig, BakeParams, Preset};
use crate::progress::Progress;

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
    pub preset: Option<Preset>,
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
            preset: self.preset,
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

/// Everything the bake measured, for the summary, the archive and `--report`.
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

/// Largest tile size (64 at most) that divides `resolution`.
fn tile_size(resolution: u32) -> u32 {
    [64, 32, 16, 8, 4, 2, 1]
        .into_iter()
        .find(|&t| resolution.is_multiple_of(t))
        .unwrap_or(1)
}

/// Directories a bake created for its output; those still empty are removed again when the bake
/// fails (the guard drops without [`MadeDirs::keep`]), so a failed bake leaves nothing behind.
struct MadeDirs(Vec<PathBuf>);

impl MadeDirs {
    fn create(dir: &Path) -> Result<MadeDirs> {
        let mut missing = Vec::new();
        let mut d = Some(dir);
        while let Some(p) = d.filter(|p| !p.as_os_str().is_empty() && !p.exists()) {
            missing.push(p.to_path_buf());
            d = p.parent();
        }
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
        Ok(MadeDirs(missing))
    }

    fn keep(mut self) {
        self.0.clear();
    }
}

impl Drop for MadeDirs {
    fn drop(&mut self) {
        // Innermost first; remove_dir refuses non-empty directories.
        for d in &self.0 {
            let _ = std::fs::remove_dir(d);
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

/// `to` relative to directory `from`, with `/` separators (absolute when they share no root).
fn relative_path(from: &Path, to: &Path) -> String {
    let (Ok(from), Ok(to)) = (from.canonicalize(), to.canonicalize()) else {
        return to.to_string_lossy().replace('\\', "/");
    };
    let (f, t): (Vec<_>, Vec<_>) = (from.components().collect(), to.components().collect());
    let common = f.iter().zip(&t).take_while(|(a, b)| a == b).count();
    if common == 0 {
        return to.to_string_lossy().replace('\\', "/");
    }
    let mut parts: Vec<String> = std::iter::repeat_n("..".to_string(), f.len() - common).collect();
    parts.extend(t[common..].iter().map(|c| c.as_os_str().to_string_lossy().into_owned()));
    parts.join("/")
}

pub fn run(args: &BakeArgs) -> Result<()> {
    // Before any work: refuse an unusable -o (a directory, a device, a directory where no file
    // can be created), follow a symlink to the file it names, and have SIGINT, SIGTERM and
    // SIGHUP remove the bake's temporary file.
    let destination = if args.plan {
        args.output.clone()
    } else {
        let d = prm_format::check_destination(&args.output)?;
        crate::signals::install(d.clone());
        d
    };
    let progress = Progress::new(args.quiet);
    let started = Instant::now();
    let mut timings = BTreeMap::new();

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
    timings.insert("load".to_string(), t.elapsed().as_secs_f64());

    // The automatic atlas is built at most once, only if the parameters need it.
    let auto_atlas: OnceCell<Atlas> = OnceCell::new();
    let probe = || -> Result<Atlas> {
        if let Some(a) = auto_atlas.get() {
            return Ok(a.clone());
        }
        let a = Atlas::build(&scene, &AtlasParams::DEFAULT).context("building the automatic atlas")?;
        Ok(auto_atlas.get_or_init(|| a).clone())
    };
    let params = BakeParams::resolve(&config, &scene, probe)?;
    progress.say(&format!(
        "bake: {} entries, {} clusters, atlas {}, {} walk{} per entry, seed {}, top-k {} ({:?} preset)",
        params.entries,
        params.clusters,
        match params.atlas {
            AtlasSize::Resolution(r) => format!("{r}²"),
            AtlasSize::TexelSize(s) => format!("texel {s}"),
        },
        params.paths_per_entry,
        crate::params::plural(params.paths_per_entry as usize),
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
    if args.plan {
        if let Some(path) = &args.report {
            // The same shape as a bake's report, which nests them under "params".
            std::fs::write(
                path,
                serde_json::to_string_pretty(&serde_json::json!({ "params": params }))?,
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
    let backend_name = gpu.as_ref().map_or_else(|| "cpu".to_string(), |g| g.describe());

    let t = Instant::now();
    let sizing = match params.atlas {
        AtlasSize::Resolution(r) => Sizing::Resolution(r),
        AtlasSize::TexelSize(s) => Sizing::TexelSize(s),
    };
    let atlas = match (auto_atlas.get(), sizing) {
        (Some(a), Sizing::Resolution(r)) if a.resolution == r => a.clone(),
        _ => Atlas::build(&scene, &AtlasParams::with_sizing(sizing)).context("building the lightmap atlas")?,
    };
    if atlas.resolution > 8192 {
        bail!(
            "the atlas needs {}² texels, over the archive's 8192 limit; choose a larger --texel-size",
            atlas.resolution
        );
    }
    timings.insert("atlas".to_string(), t.elapsed().as_secs_f64());
    progress.say(&format!(
        "{:>16}: {r}x{r}, {} charts, {} exit points ({:.2} s)",
        "atlas",
        atlas.stats.charts,
        atlas.exits.len(),
        timings["atlas"],
        r = atlas.resolution
    ));

    let phase = progress.phase("bvh", 1);
    let bvh = Bvh::build(&scene, &BvhParams::DEFAULT).context("building the BVH")?;
    timings.insert(
        "bvh".to_string(),
        phase.finish(&format!("{} triangles", scene.triangles.len())),
    );

    let phase = progress.phase("light tracing", 1);
    let entries = prm_trace::sample_surface(
        &scene,
        &EntryParams {
            count: params.entries,
            seed: params.seed,
        },
    )
    .context("sampling entry points")?;
    let walk_params = WalkParams {
        walks_per_entry: params.paths_per_entry,
        seed: params.seed,
        ..WalkParams::PREVIEW
    };
    let vpls = prm_trace::trace_walks(&scene, &bvh, &entries, &walk_params).context("tracing walks")?;
    timings.insert(
        "light_tracing".to_string(),
        phase.finish(&format!(
            "{} entries, {} walks, {} VPLs, {} rays",
            entries.len(),
            vpls.stats.walks,
            vpls.vpls.len(),
            vpls.stats.rays
        )),
    );

    let phase = progress.phase("clustering", 1);
    let clustering = if params.clusters == entries.len() {
        Clustering::identity(&entries)
    } else {
        let cp = ClusterParams {
            seed: params.seed,
            ..ClusterParams::with_clusters(params.clusters)
        };
        Clustering::kmeans(&entries, scene.bounds().diagonal(), &cp)
            .context("clustering entry points")?
            .separate_by_visibility(&entries, &bvh)
    };
    timings.insert(
        "clustering".to_string(),
        phase.finish(&format!("{} clusters", clustering.len())),
    );

    // Archive tables: entries in cluster order, cluster ranges over them.
    let mut table_entries = Vec::with_capacity(entries.len());
    let mut table_clusters = Vec::with_capacity(clustering.len());
    for (c, members) in clustering.members.iter().enumerate() {
        table_clusters.push(Cluster::new(
            table_entries.len() as u32,
            members.len() as u32,
            clustering.centroids[c].to_array(),
            clustering.normals[c].to_array(),
        ));
        for &k in members {
            let e = &entries[k as usize];
            table_entries.push(Entry {
                position: e.position.to_array(),
                normal: e.normal.to_array(),
                cluster: c as u32,
            });
        }
    }
    let mut atlas_section = AtlasSection::new(atlas.resolution, tile_size(atlas.resolution));
    atlas_section.triangle_uvs = atlas.uvs.iter().map(|t| t.map(|uv| uv.to_array())).collect();
    for e in &atlas.exits {
        atlas_section.set_covered(e.texel % atlas.resolution, e.texel / atlas.resolution, true);
    }
    let mut metadata = Metadata::new("prm-bake", env!("CARGO_PKG_VERSION"));
    metadata.seed = params.seed;
    metadata.scene_fingerprint = scene.fingerprint();
    let out_dir = destination
        .parent()
        .filter(|d| !d.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    let made = MadeDirs::create(out_dir)?;
    metadata.source_scene = relative_path(out_dir, &args.scene);
    if let serde_json::Value::Object(map) = serde_json::to_value(&params)? {
        metadata.params = map;
    }
    metadata
        .params
        .insert("atlas_stats".into(), serde_json::to_value(&atlas.stats)?);
    metadata.params.insert("backend".into(), backend_name.clone().into());
    // The player refuses other geometry (scene_fingerprint) but only warns about other albedos.
    metadata.params.insert(
        "materials_fingerprint".into(),
        format!("{:016x}", scene.materials_fingerprint()).into(),
    );
    let mut writer = ArchiveWriter::create(&args.output, metadata, &atlas_section, &table_entries, &table_clusters)
        .with_context(|| format!("starting {}", args.output.display()))?;

    // Panes: render (GPU or CPU), fill the atlas image, dilate into the gutters, write.
    let mut write_s = 0.0;
    let mut image = vec![[0f32; 3]; (atlas.resolution * atlas.resolution) as usize];
    let mut emit = |pane: &[Vec3], writer: &mut ArchiveWriter| -> Result<()> {
        let t = Instant::now();
        image.fill([0.0; 3]);
        for (e, v) in atlas.exits.iter().zip(pane) {
            image[e.texel as usize] = v.to_array();
        }
        for &(dst, src) in &atlas.dilation {
            image[dst as usize] = image[src as usize];
        }
        writer.add_pane(&image).context("writing a pane")?;
        write_s += t.elapsed().as_secs_f64();
        Ok(())
    };
    let t = Instant::now();
    // Entry indices in the archive's order (cluster by cluster), and their pane energies.
    let order: Vec<u32> = clustering.members.iter().flatten().copied().collect();
    let mut entry_energy = vec![[0f32; 3]; entries.len()];
    let mut entry_energy_known = true;
    let shadow_rays;
    let phase = match &gpu {
        Some(ctx) => {
            let rp = PaneRenderParams {
                bound: params.bound(),
                face_resolution: params.face_resolution,
                ..PaneRenderParams::DEFAULT
            };
            // Progress counts VPLs: a group of panes can take minutes on a big scene.
            let mut phase = progress.phase("pane rendering", vpls.vpls.len() as u64);
            let mut at = 0;
            let mut energies_complete = true;
            let stats = prm_gpu::render_panes_with(ctx, &scene, &atlas.exits, &vpls, &clustering, &rp, |out| {
                match out {
                    PaneOutput::Pane {
                        cluster,
                        irradiance,
                        member_energy,
                    } => {
                        // Members arrive cluster by cluster: the archive's entry order.
                        energies_complete &= member_energy.len() == clustering.members[cluster].len();
                        for e in member_energy {
                            entry_energy[at] = e.to_array();
                            at += 1;
                        }
                        emit(irradiance, &mut writer)?
                    }
                    PaneOutput::Progress(s) => phase.inc(s.vpls - phase.done()),
                }
                Ok::<(), anyhow::Error>(())
            })
            .context("rendering panes on the GPU")?;
            progress.say(&format!(
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
                entry_energy_known = false;
                progress.say(&format!(
                    "  no entry energies: their read-back would take {:.1} GiB, over the {:.1} GiB \
                     budget, so the panes were rendered per cluster and the player weighs \
                     members equally (the archive stays format 1.0)",
                    prm_gpu::pane::member_readback_bytes(entries.len(), atlas.exits.len()) as f64 / (1u64 << 30) as f64,
                    rp.member_energy_bytes as f64 / (1u64 << 30) as f64
                ));
            }
            timings.insert("pane_depth_maps".to_string(), stats.depth_seconds);
            timings.insert("pane_gather".to_string(), stats.gather_seconds);
            shadow_rays = 0;
            phase
        }
        None => {
            let panes = prm_trace::evaluate_panes(
                &bvh,
                &vpls,
                &clustering,
                &atlas.exits,
                &PaneParams { bound: params.bound() },
            )
            .context("evaluating panes on the CPU")?;
            shadow_rays = panes.rays;
            for (j, &k) in order.iter().enumerate() {
                entry_energy[j] = panes.entry_energy[k as usize].to_array();
            }
            let mut phase = progress.phase("pane rendering", panes.clusters as u64);
            for c in 0..panes.clusters {
                emit(panes.pane(c), &mut writer)?;
                phase.inc(1);
            }
            phase
        }
    };
    if entry_energy_known {
        writer
            .set_entry_energy(entry_energy)
            .context("recording the entry energies")?;
    }
    let render_s = t.elapsed().as_secs_f64() - write_s;
    phase.finish(&format!(
        "{} panes, {} VPLs on {}",
        clustering.len(),
        vpls.vpls.len(),
        backend_name
    ));
    timings.insert("pane_rendering".to_string(), render_s);

    // Timings go to stdout and --report only: the archive's bytes depend on nothing but the
    // scene, the parameters and the backend, so caches and content-addressed pipelines can key
    // on them (tested by `bake_is_byte_identical_across_runs_and_threads`).
    let t = Instant::now();
    let bytes = writer
        .finish()
        .with_context(|| format!("finishing {}", args.output.display()))?;
    made.keep();
    timings.insert("compression_write".to_string(), write_s + t.elapsed().as_secs_f64());
    timings.insert("total".to_string(), started.elapsed().as_secs_f64());

    let report = Report {
        scene: args.scene.clone(),
        output: args.output.clone(),
        backend: backend_name,
        params,
        atlas: atlas.stats.clone(),
        triangles: scene.triangles.len(),
        entries: entries.len(),
        clusters: clustering.len(),
        walks: vpls.stats.walks,
        vpls: vpls.vpls.len(),
        rays: vpls.stats.rays + shadow_rays,
        archive_bytes: bytes,
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn relative_paths() {
        let dir = std::env::temp_dir().join("prm-relpath-test/a/b");
        std::fs::create_dir_all(&dir).unwrap();
        let target = std::env::temp_dir().join("prm-relpath-test/c.obj");
        std::fs::write(&target, "").unwrap();
        assert_eq!(relative_path(&dir, &target), "../../c.obj");
    }

    #[test]
    fn tile_sizes_divide() {
        assert_eq!(tile_size(256), 64);
        assert_eq!(tile_size(96), 32);
        assert_eq!(tile_size(200), 8);
        assert_eq!(tile_size(7), 1);
    }
}
