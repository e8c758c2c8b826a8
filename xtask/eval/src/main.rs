//! `cargo xtask eval [--quick|--full] [--out DIR]`: accuracy against speed, a sweep of bake and run-time settings.
//!
//! A package of its own (`xtask-eval`), which `cargo xtask eval` runs, so that the light `xtask`
//! binary behind `cargo xtask demo` does not compile the player, the charts and FLIP first: the
//! README's main job builds wgpu once (release) instead of twice.
//!
//! For every scene: the automatic choice (`prm-bake bake --plan`), then one parameter at a time
//! around it (entries, clusters, run-time K, resolution, walks per entry, VPL bound) and the
//! presets. Every bake runs the `prm-bake` binary (cached under `target/eval/bakes` by its
//! arguments); every archive is played by `prm_play::Renderer` (frame time at 1024×768, `gi`) and
//! compared with `prm_trace::ReferenceTracer` (cached under `target/eval/refs`) under several
//! point lights: relative RMSE of the indirect light in lightmap space and in image space, and
//! mean LDR-FLIP (nv-flip) of the final image. Writes `eval.csv`, `summary.md` and one chart per
//! scene (SVG and PNG) to the output directory.

mod budget;
mod charts;
mod compare;
mod emitters;
mod experiments;
mod lamps;
mod measure;
mod plan;
mod probes;
mod reference;
mod sky;
mod targets;

use anyhow::{bail, Context, Result};
use plan::{Mode, Params, SceneSpec};
use std::collections::HashMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

/// One CSV row: a scene × setting with its cost and its errors (averaged over the lights).
#[derive(Clone, Debug, Default)]
pub struct Row {
    pub scene: String,
    pub label: String,
    pub group: String,
    pub is_auto: bool,
    pub preset: String,
    pub entries: u32,
    pub clusters: u32,
    pub resolution: u32,
    pub paths_per_entry: u32,
    pub walks: u64,
    pub vpls: u64,
    pub top_k: u32,
    pub vpl_disk_scale: f32,
    pub bake_s: f64,
    pub archive_bytes: u64,
    pub memory_bytes: u64,
    pub frame_ms: f64,
    pub lightmap_rel_rmse: f64,
    pub lightmap_ref_noise: f64,
    pub image_rel_rmse: f64,
    pub image_ref_noise: f64,
    pub flip: f64,
    pub lights: usize,
    pub lightmap_spp: u32,
    pub lightmap_texels: usize,
    pub image_spp: u32,
    pub image_size: String,
    pub note: String,
}

const CSV_HEADER: &str = "scene,setting,group,is_auto,preset,entries,clusters,resolution,paths_per_entry,walks,vpls,top_k,vpl_disk_scale,bake_s,archive_bytes,memory_bytes,frame_ms,lightmap_rel_rmse,lightmap_ref_noise,image_rel_rmse,image_ref_noise,flip_mean,lights,lightmap_ref_spp,lightmap_texels,image_ref_spp,image_size,note";

impl Row {
    fn csv(&self) -> String {
        format!(
            "{},{},{},{},{},{},{},{},{},{},{},{},{},{:.3},{},{},{:.3},{},{},{},{},{},{},\"{}\"",
            self.scene,
            self.label,
            self.group,
            self.is_auto,
            self.preset,
            self.entries,
            self.clusters,
            self.resolution,
            self.paths_per_entry,
            self.walks,
            self.vpls,
            self.top_k,
            self.vpl_disk_scale,
            self.bake_s,
            self.archive_bytes,
            self.memory_bytes,
            self.frame_ms,
            self.errors().map(|e| format!("{e:.5}")).join(","),
            self.lights,
            self.lightmap_spp,
            self.lightmap_texels,
            self.image_spp,
            self.image_size,
            self.note.replace('"', "'")
        )
    }

    /// The error measures, in the CSV's order (`lightmap_rel_rmse` .. `flip_mean`).
    fn errors(&self) -> [f64; 5] {
        [
            self.lightmap_rel_rmse,
            self.lightmap_ref_noise,
            self.image_rel_rmse,
            self.image_ref_noise,
            self.flip,
        ]
    }

    fn numbers(&self) -> impl Iterator<Item = f64> {
        [self.bake_s, self.frame_ms, self.vpl_disk_scale as f64]
            .into_iter()
            .chain(self.errors())
    }
}

/// The studies besides the sweep, by flag name (`--budget` …): each writes `NAME.md`.
const STUDIES: [&str; 6] = ["budget", "targets", "lamps", "emitters", "sky", "probes"];

fn usage() -> ! {
    eprintln!(
        "usage: cargo xtask eval [--quick|--full|--budget|--targets|--lamps|--emitters|--sky|--probes] [--out DIR] [--only CASE]\n       cargo xtask eval compare TEST.exr REFERENCE.exr [--diff OUT.png]   (error, energy, shape and local error as ../shared/notes/metrics.md defines them)\n       cargo xtask eval experiment NAME [ARGS]   (the experiments the crates' docs cite; without NAME, the list)\n\n  --quick   Cornell box, a handful of settings, small references (CI; dev-profile binaries); default\n  --full    all scenes and sweeps (release binaries; the README's charts)\n  --budget  the error budget of the default bake, one idealised stage at a time (release; the README's budget table)\n  --targets the accuracy targets as ../shared/notes/metrics.md measures them: default bakes of McGuire's boxes, chairs and the fireplace room against the reference in image space, bake time and the gi/direct frame ratio (release)\n  --lamps   the large scenes' lamps of --targets, each at six positions a fifth of a metre apart along its surface: the mean error and the energy's range (release; 256-path references)\n  --emitters emissive surfaces (McGuire's CornellBox-Original by its own lamp, two lamps in our Cornell box) against the reference, and the frame cost of a scale change (release)\n  --sky     the sky and a sun (our courtyard; Sponza) against the reference, and the frame cost of turning the sky (release)\n  --probes  irradiance probes (our Cornell box, two rooms) against the reference at the probe positions, and their cost (release)\n  --only CASE  with --targets or --lamps: only the cases whose name contains CASE (\"modern hall\", \"fireplace\")\n  --out DIR output directory (default target/eval-quick, eval-full, eval-budget, eval-targets, eval-lamps, eval-emitters, eval-sky or eval-probes)\n\nBakes and references are cached under target/eval/ (delete it to start over)."
    );
    std::process::exit(2);
}

fn target_dir(root: &Path) -> PathBuf {
    std::env::var_os("CARGO_TARGET_DIR")
        .map(PathBuf::from)
        .map(|p| if p.is_absolute() { p } else { root.join(p) })
        .unwrap_or_else(|| root.join("target"))
}

/// Exit status 0 on success, 2 for arguments it does not know (before any work), 1 when the
/// evaluation fails: one `error:` line with its causes, never a backtrace.
fn main() -> std::process::ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    match run(&args) {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            std::process::ExitCode::FAILURE
        }
    }
}

fn run(args: &[String]) -> Result<()> {
    if args.first().map(String::as_str) == Some("compare") {
        return compare::run(&args[1..]);
    }
    if args.first().map(String::as_str) == Some("experiment") {
        return experiments::run(&args[1..]);
    }
    let mut mode = Mode::Quick;
    // A study (`--budget`, `--targets`, …) writes one Markdown table instead of the sweep.
    let mut study: Option<&'static str> = None;
    let mut out = None;
    let mut only: Option<String> = None;
    let mut it = args.iter();
    while let Some(a) = it.next() {
        match a.as_str() {
            "--quick" => mode = Mode::Quick,
            "--full" => mode = Mode::Full,
            "--out" => out = Some(PathBuf::from(it.next().unwrap_or_else(|| usage()))),
            "--only" => only = Some(it.next().unwrap_or_else(|| usage()).clone()),
            flag => {
                let name = flag.strip_prefix("--").unwrap_or_else(|| usage());
                study = Some(STUDIES.into_iter().find(|s| *s == name).unwrap_or_else(|| usage()));
                mode = Mode::Full;
            }
        }
    }
    let root = Path::new(env!("CARGO_MANIFEST_DIR"))
        .ancestors()
        .nth(2)
        .context("xtask/eval has no workspace root above it")?
        .to_path_buf();
    let target = target_dir(&root);
    let out = out.map(|o| {
        if o.is_absolute() {
            o
        } else {
            std::env::current_dir().unwrap_or_default().join(o)
        }
    });
    std::env::set_current_dir(&root)?;
    // Before the run writes anything: its own output would count as a change to the tree.
    let measured = provenance();
    let out = out.unwrap_or_else(|| {
        target.join(match (study, mode) {
            (Some(study), _) => format!("eval-{study}"),
            (None, Mode::Quick) => "eval-quick".to_string(),
            (None, Mode::Full) => "eval-full".to_string(),
        })
    });
    std::fs::create_dir_all(&out)?;
    let cache = target.join("eval");

    // The binaries: dev profile for --quick, release for --full.
    let profile = if mode == Mode::Full { "release" } else { "debug" };
    let mut build = Command::new(env!("CARGO"));
    build.args(["build", "--quiet", "-p", "prm-bake", "-p", "prm-play"]);
    if mode == Mode::Full {
        build.arg("--release");
    }
    println!("eval: building prm-bake and prm-play ({profile})");
    if !build.status().context("starting cargo build")?.success() {
        bail!("cargo build of prm-bake/prm-play failed");
    }
    let bin = target
        .join(profile)
        .join(format!("prm-bake{}", std::env::consts::EXE_SUFFIX));

    let started = Instant::now();
    // A mode that makes one Markdown table: written to OUT/NAME.md and printed.
    let table = |name: &str, table: String| -> Result<()> {
        let path = out.join(format!("{name}.md"));
        std::fs::write(&path, &table).with_context(|| format!("writing {}", path.display()))?;
        println!(
            "\n{table}\n{name}: written to {} in {:.0} s",
            path.display(),
            started.elapsed().as_secs_f64()
        );
        Ok(())
    };
    if let Some(study) = study {
        let markdown = match study {
            "emitters" => emitters::run(&bin, &cache, &root, &out)?,
            "sky" => sky::run(&bin, &cache, &root, &out)?,
            "probes" => probes::run(&bin, &cache, &root)?,
            "targets" => targets::run(&bin, &cache, &root, &out, only.as_deref())?,
            "lamps" => lamps::run(&bin, &cache, &root, &out, only.as_deref())?,
            _ => budget::run(&bin, &cache, &root)?,
        };
        return table(study, markdown);
    }
    let scenes = plan::scenes(mode, &root);
    let mut rows: Vec<Row> = Vec::new();
    let csv = out.join("eval.csv");
    for scene in &scenes {
        let t = Instant::now();
        let scene_rows = evaluate_scene(mode, &bin, &cache, scene)
            .with_context(|| format!("evaluating {}", scene.path.display()))?;
        rows.extend(scene_rows);
        write_csv(&csv, &rows)?;
        println!(
            "eval: {} done in {:.0} s ({:.0} s so far)",
            scene.name,
            t.elapsed().as_secs_f64(),
            started.elapsed().as_secs_f64()
        );
    }
    let mut written = vec![csv.clone()];
    written.extend(charts::write_all(&rows, &out)?);
    let summary = summary(&rows, mode, started.elapsed().as_secs_f64(), &measured);
    let summary_path = out.join("summary.md");
    std::fs::write(&summary_path, &summary)?;
    written.push(summary_path);
    println!("\n{summary}");

    // Sanity: fail loudly when something is broken.
    let mut problems = Vec::new();
    for r in &rows {
        if r.numbers().any(|x| !x.is_finite()) {
            problems.push(format!("{} {}: NaN or Inf in the measurements", r.scene, r.label));
        }
        // The loose bound holds for the quick mode's Cornell box; the full mode's small-budget
        // bakes of large scenes may legitimately exceed it (reported, not failed).
        if mode == Mode::Quick && r.is_auto && r.lightmap_rel_rmse > 0.5 {
            problems.push(format!(
                "{} {}: lightmap relative RMSE {:.3} > 0.5 for the automatic choice",
                r.scene, r.label, r.lightmap_rel_rmse
            ));
        }
    }
    for s in &scenes {
        if !rows.iter().any(|r| r.scene == s.name && r.is_auto) {
            problems.push(format!("{}: no row for the automatic choice", s.name));
        }
    }
    for f in &written {
        if std::fs::metadata(f).map(|m| m.len() == 0).unwrap_or(true) {
            problems.push(format!("{} is missing or empty", f.display()));
        }
    }
    println!(
        "eval: {} rows, {} files in {} ({:.0} s without compilation)",
        rows.len(),
        written.len(),
        out.display(),
        started.elapsed().as_secs_f64()
    );
    if !problems.is_empty() {
        bail!("evaluation failed:\n  {}", problems.join("\n  "));
    }
    Ok(())
}

fn write_csv(path: &Path, rows: &[Row]) -> Result<()> {
    let mut s = String::from(CSV_HEADER);
    s.push('\n');
    for r in rows {
        s.push_str(&r.csv());
        s.push('\n');
    }
    std::fs::write(path, s).with_context(|| format!("writing {}", path.display()))
}

/// Bakes, plays and measures every setting of one scene.
fn evaluate_scene(mode: Mode, bin: &Path, cache: &Path, spec: &SceneSpec) -> Result<Vec<Row>> {
    println!("eval: scene {} ({})", spec.name, spec.path.display());
    let plan = plan::bake(bin, cache, spec, &spec.base_args, None, true)?;
    let auto = Params::from_report(&plan.report)?;
    println!(
        "eval:   automatic choice: {} entries, {} clusters, {}² atlas, {} walks/entry, K {}",
        auto.entries, auto.clusters, auto.resolution, auto.paths_per_entry, auto.top_k
    );
    let scene = prm_scene::load(&spec.path).with_context(|| format!("loading {}", spec.path.display()))?;
    let tracer = reference::Tracer::new(&scene, reference::scene_key(&spec.path, &scene), cache.join("refs"))?;
    let lights: Vec<(String, prm_scene::Light)> = spec
        .light_fractions
        .iter()
        .map(|f| plan::point_light(&scene, *f))
        .collect::<Result<_>>()?;
    let camera = match &spec.camera {
        Some(c) => prm_trace::parse_camera(c).map_err(|e| anyhow::anyhow!("camera {c}: {e}"))?,
        None => prm_play::default_camera(&scene),
    };
    let frames = if mode == Mode::Full { 10 } else { 5 };

    // Image references (independent of the bake).
    let mut image_refs = Vec::new();
    for (s, l) in &lights {
        let ind = tracer.image(&camera, spec.image_size, s, l, spec.image_spp, false)?;
        let dir = tracer.image(&camera, spec.image_size, s, l, 1, true)?;
        if ind.seconds > 0.0 {
            println!("eval:   image reference {s}: {:.1} s", ind.seconds);
        }
        image_refs.push((ind, dir));
    }

    let mut atlases: HashMap<u32, (Vec<u32>, Vec<prm_scene::ExitPoint>)> = HashMap::new();
    let mut lightmap_refs: HashMap<(u32, usize), reference::Reference> = HashMap::new();
    let mut rows = Vec::new();
    for b in plan::bakes(spec, &auto) {
        let baked = match plan::bake(bin, cache, spec, &b.args, b.config.as_deref(), false) {
            Ok(x) => x,
            // A setting the bake refuses (e.g. an atlas too small for the scene's charts) is
            // a result, not a broken tool: report it and go on. The automatic choice must bake.
            Err(e) if b.group != "auto" => {
                let msg = format!("{e:#}");
                let last = msg.lines().rev().find(|l| l.contains("error")).unwrap_or("failed");
                println!("eval:   {:<24} skipped: the bake refused it: {}", b.label, last.trim());
                continue;
            }
            Err(e) => return Err(e),
        };
        let p = Params::from_report(&baked.report)?;
        let r = &baked.report;
        let bake_s = r["timings"]["total"].as_f64().unwrap_or(f64::NAN);
        let archive_bytes = r["archive_bytes"].as_u64().unwrap_or(0);
        println!(
            "eval:   {:<24} {} entries, {} clusters, {}², {} walks/entry: bake {:.1} s, {:.2} MiB",
            b.label,
            p.entries,
            p.clusters,
            p.resolution,
            p.paths_per_entry,
            bake_s,
            archive_bytes as f64 / 1048576.0
        );

        // The atlas of this resolution, rebuilt (deterministic) and checked against the archive.
        if let std::collections::hash_map::Entry::Vacant(e) = atlases.entry(p.resolution) {
            let atlas = tracer.atlas(p.resolution)?;
            let all: Vec<u32> = atlas.exits.iter().map(|x| x.texel).collect();
            let stride = atlas.exits.len().div_ceil(spec.lightmap_texels.max(1)).max(1);
            let subset: Vec<prm_scene::ExitPoint> = atlas.exits.iter().step_by(stride).copied().collect();
            e.insert((all, subset));
        }
        let (all_texels, exits) = &atlases[&p.resolution];
        let texels: Vec<u32> = exits.iter().map(|x| x.texel).collect();
        {
            let a = prm_format::Archive::open(&baked.archive)?;
            let at = a.atlas();
            let covered = all_texels
                .iter()
                .all(|&t| at.is_covered(t % p.resolution, t / p.resolution));
            if at.resolution != p.resolution || !covered || at.covered_texels() != all_texels.len() as u64 {
                bail!(
                    "the rebuilt {}² atlas differs from the archive's ({} covered texels vs {})",
                    p.resolution,
                    all_texels.len(),
                    at.covered_texels()
                );
            }
        }
        for (li, (s, l)) in lights.iter().enumerate() {
            if let std::collections::hash_map::Entry::Vacant(e) = lightmap_refs.entry((p.resolution, li)) {
                let r = tracer.lightmap(p.resolution, exits, s, l, spec.lightmap_spp)?;
                if r.seconds > 0.0 {
                    println!("eval:   lightmap reference {}² {s}: {:.1} s", p.resolution, r.seconds);
                }
                e.insert(r);
            }
        }

        // Run-time K values: the archive's own, and for the automatic bake the K sweep.
        let mut ks = vec![(p.top_k.min(p.clusters), b.label.clone(), b.group)];
        if b.group == "auto" {
            for &k in &spec.sweep.top_k {
                let k = k.min(p.clusters);
                if !ks.iter().any(|(x, _, _)| *x == k) {
                    ks.push((k, format!("top_k={k}"), "top_k"));
                }
            }
        }
        let (mut renderer, _) = measure::renderer(&baked.archive, &spec.path, ks[0].0)?;
        // What the run time allocated on the GPU, every part (0 where the backend reports none).
        let memory_bytes = renderer
            .runtime()
            .gpu_memory()
            .map_or(0, |parts| parts.iter().map(|p| p.bytes).sum());
        for (k, label, group) in ks {
            renderer.set_top_k(k);
            let frame_ms = measure::frame_time(
                &mut renderer,
                camera,
                &lights.iter().map(|(_, l)| *l).collect::<Vec<_>>()[..1],
                frames,
            )?;
            let mut sum = measure::Errors::default();
            let mut used = 0;
            let mut notes = Vec::new();
            for (li, (s, l)) in lights.iter().enumerate() {
                let refs = measure::LightRefs {
                    light: *l,
                    lightmap: &lightmap_refs[&(p.resolution, li)],
                    texels: &texels,
                    image_indirect: &image_refs[li].0,
                    image_direct: &image_refs[li].1,
                };
                let e = measure::errors(&mut renderer, camera, spec.image_size, &refs)?;
                if !e.lightmap.is_finite() && !e.image.is_finite() && e.lightmap_noise.is_nan() {
                    notes.push(format!("light {s} gives no indirect light: skipped"));
                    continue;
                }
                used += 1;
                sum.lightmap += e.lightmap;
                sum.lightmap_noise += e.lightmap_noise;
                sum.image += e.image;
                sum.image_noise += e.image_noise;
                sum.flip += e.flip;
            }
            let n = used.max(1) as f64;
            let mut row = Row {
                scene: spec.name.clone(),
                label: label.clone(),
                group: group.to_string(),
                is_auto: group == "auto",
                preset: r["params"]["preset"].as_str().unwrap_or("").to_string(),
                entries: p.entries,
                clusters: p.clusters,
                resolution: p.resolution,
                paths_per_entry: p.paths_per_entry,
                walks: r["walks"].as_u64().unwrap_or(0),
                vpls: r["vpls"].as_u64().unwrap_or(0),
                top_k: k,
                vpl_disk_scale: p.vpl_disk_scale,
                bake_s,
                archive_bytes,
                memory_bytes,
                frame_ms,
                lightmap_rel_rmse: sum.lightmap / n,
                lightmap_ref_noise: sum.lightmap_noise / n,
                image_rel_rmse: sum.image / n,
                image_ref_noise: sum.image_noise / n,
                flip: sum.flip / n,
                lights: used,
                lightmap_spp: spec.lightmap_spp,
                lightmap_texels: texels.len(),
                image_spp: spec.image_spp,
                image_size: format!("{}x{}", spec.image_size.0, spec.image_size.1),
                note: String::new(),
            };
            if used == 0 {
                notes.push("no light gave indirect light".into());
                row.lightmap_rel_rmse = f64::NAN;
            }
            if row.lightmap_ref_noise > row.lightmap_rel_rmse / 3.0 {
                notes.push(format!(
                    "lightmap reference noise {:.3} is more than 1/3 of the error {:.3}",
                    row.lightmap_ref_noise, row.lightmap_rel_rmse
                ));
            }
            if row.image_ref_noise > row.image_rel_rmse / 3.0 {
                notes.push(format!(
                    "image reference noise {:.3} is more than 1/3 of the error {:.3}",
                    row.image_ref_noise, row.image_rel_rmse
                ));
            }
            for n in &notes {
                println!("eval:   warning: {} {label}: {n}", spec.name);
            }
            row.note = notes.join("; ");
            println!(
                "eval:   {:<24} K {:>4}: frame {:.2} ms, lightmap {:.4} (ref noise {:.4}), image {:.4} (ref noise {:.4}), FLIP {:.4}",
                label, k, row.frame_ms, row.lightmap_rel_rmse, row.lightmap_ref_noise, row.image_rel_rmse, row.image_ref_noise, row.flip
            );
            rows.push(row);
        }
    }
    Ok(rows)
}

/// The commit and the machine the figures are measured on, for the summary's head: the commit
/// (with `+changes` when the tree differs from it as the run starts), the CPU and its cores.
fn provenance() -> String {
    let git = |args: &[&str]| {
        std::process::Command::new("git")
            .args(args)
            .output()
            .ok()
            .filter(|o| o.status.success())
            .map(|o| String::from_utf8_lossy(&o.stdout).trim().to_string())
    };
    let commit = git(&["rev-parse", "--short=12", "HEAD"]).unwrap_or_else(|| "an unknown commit".into());
    let changed = git(&["status", "--porcelain", "--untracked-files=no"]).is_some_and(|s| !s.is_empty());
    let cpu = std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|c| {
            c.lines().find_map(|l| {
                l.strip_prefix("model name")
                    .map(|m| m.trim_start_matches([' ', '\t', ':']).to_string())
            })
        })
        .unwrap_or_else(|| "an unknown CPU".into());
    let cores = std::thread::available_parallelism().map_or(0, |n| n.get());
    format!(
        "Measured at commit `{commit}`{} on {cpu}, {cores} cores; frames on the Vulkan device the player found.",
        if changed { " (+changes)" } else { "" }
    )
}

/// The README material: presets table and the automatic choice against the Pareto fronts.
fn summary(rows: &[Row], mode: Mode, seconds: f64, measured: &str) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "# Evaluation summary ({} mode, {:.0} s without compilation)\n",
        if mode == Mode::Full { "full" } else { "quick" },
        seconds
    );
    let _ = writeln!(s, "{measured}\n");
    let mut scenes: Vec<&str> = Vec::new();
    for r in rows {
        if !scenes.contains(&r.scene.as_str()) {
            scenes.push(&r.scene);
        }
    }
    let _ = writeln!(s, "## Presets and the automatic choice\n");
    let _ = writeln!(s, "| scene | setting | entries | clusters | resolution | walks/entry | K | bake s | archive MiB | memory MiB | frame ms | lightmap rel. RMSE | image rel. RMSE | FLIP |");
    let _ = writeln!(
        s,
        "| --- | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |"
    );
    for r in rows.iter().filter(|r| r.group == "auto" || r.group == "preset") {
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} | {}² | {} | {} | {:.1} | {:.2} | {:.1} | {:.1} | {:.3} | {:.3} | {:.3} |",
            r.scene,
            r.label,
            r.entries,
            r.clusters,
            r.resolution,
            r.paths_per_entry,
            r.top_k,
            r.bake_s,
            r.archive_bytes as f64 / 1048576.0,
            r.memory_bytes as f64 / 1048576.0,
            r.frame_ms,
            r.lightmap_rel_rmse,
            r.image_rel_rmse,
            r.flip
        );
    }
    let _ = writeln!(
        s,
        "\n## The automatic choice against the Pareto front\n\nRatio = the automatic choice's error / the lowest error of any setting that costs no more (1.00 = on the front).\n"
    );
    let _ = writeln!(
        s,
        "| scene | error | cost | front (cost → error, setting) | auto ratio |"
    );
    let _ = writeln!(s, "| --- | --- | --- | --- | ---: |");
    for scene in &scenes {
        let rs: Vec<&Row> = rows.iter().filter(|r| r.scene == *scene).collect();
        for (ename, ef) in charts::ERRORS {
            for (cname, cf) in charts::COSTS {
                let pts: Vec<(f64, f64)> = rs.iter().map(|r| (cf(r), ef(r))).collect();
                let front = charts::pareto_front(&pts);
                let desc: Vec<String> = front
                    .iter()
                    .map(|&i| format!("{:.3} → {:.3} ({})", pts[i].0, pts[i].1, rs[i].label))
                    .collect();
                let ratio = rs
                    .iter()
                    .position(|r| r.is_auto)
                    .map(|a| charts::ratio_to_front(&pts, a))
                    .map(|x| format!("{x:.2}"))
                    .unwrap_or_else(|| "–".into());
                let _ = writeln!(s, "| {scene} | {ename} | {cname} | {} | {ratio} |", desc.join("; "));
            }
        }
    }
    s
}
