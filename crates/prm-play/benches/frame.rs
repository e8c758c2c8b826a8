//! Frame time of `gi` vs `direct` at 1024×768 on baked archives of three scenes, on Vulkan.
//!
//! `cargo bench -p prm-play --bench frame [-- FRAMES]` (default 20 frames per mode and scene):
//! for the Cornell box (`scenes/cornell-box/cornell-box.gltf`), the dining room
//! (`scenes/chairs/chairs.gltf`) and `../shared/scenes/cornell-box/CornellBox-Sphere.obj`
//! (skipped, with a message, when `../shared/scenes` is absent) it prints the median and minimum
//! wall time per frame (recording to GPU completion; measured without timestamp queries, which
//! are synchronisation points on lavapipe), then the mean GPU time per pass (timestamp queries),
//! and the gi/direct ratios of the frame times and of the summed GPU pass times. The modes are
//! interleaved frame by frame so that load from other processes hits both alike; with 2 shared
//! cores the wall-time ratio still swings by several per cent from run to run.
//!
//! Then it attributes the gi frame's added wall time to its parts, from gi frames interleaved
//! with those of two more players of the same archive: one without the near field
//! (`--near-field off`), and one without it blending 8 panes and no residual groups (`--top-k 8
//! --residual-groups 0`). The three differences (against the direct frame's median) are the
//! weights, ranking and a minimal blend; the other panes and groups; the near field's gathers.
//! On lavapipe this is the only account of the compute passes: their timestamps read near zero,
//! since lavapipe does a dispatch's work outside the pass's timestamp pair.
//!
//! Archives: `target/prm-bench/NAME-PRESET.prm`, baked once with `prm-bake bake SCENE -o OUT
//! --preset PRESET` (`PRM_BENCH_PRESET`, `preview` by default; `cargo run --release -p prm-bake`,
//! or the binary `$PRM_BAKE` names) and reused while they open, match their scene and the plan
//! `prm-bake bake --plan` prints now (kept beside each as `NAME-PRESET.plan`). Scenes without
//! lights (the OBJ Cornell box: its lamp is an emissive quad) get a point light just below the
//! middle of the ceiling.

use std::path::{Path, PathBuf};
use std::process::Command;

use prm_play::{FrameInput, FrameTimings, Mode, PlayOptions, Renderer, PASS_NAMES};
use prm_scene::{Light, Scene};

type Result<T> = std::result::Result<T, Box<dyn std::error::Error>>;

/// Wall times of a series of frames, or their mean GPU time per pass.
struct Stats {
    median_ms: f64,
    min_ms: f64,
    passes: Vec<(&'static str, f64)>,
}

impl Stats {
    fn of(t: &[FrameTimings]) -> Stats {
        let mut ms: Vec<f64> = t.iter().map(|f| f.cpu_ms).collect();
        ms.sort_by(f64::total_cmp);
        let passes = PASS_NAMES
            .iter()
            .filter_map(|&p| {
                let v: Vec<f64> = t
                    .iter()
                    .flat_map(|f| f.gpu_ms.iter().filter(|(q, _)| *q == p).map(|(_, v)| *v))
                    .collect();
                (!v.is_empty()).then(|| (p, v.iter().sum::<f64>() / v.len() as f64))
            })
            .collect();
        Stats {
            median_ms: ms.get(ms.len() / 2).copied().unwrap_or(f64::NAN),
            min_ms: ms.first().copied().unwrap_or(f64::NAN),
            passes,
        }
    }

    fn gpu_total(&self) -> f64 {
        self.passes.iter().map(|(_, v)| v).sum()
    }

    fn print_passes(&self, name: &str) {
        print!("  {name:>6} GPU ms/frame:");
        for (p, v) in &self.passes {
            print!(" {p} {v:.2}");
        }
        println!(" = {:.2}", self.gpu_total());
    }
}

/// Renders `frames` frames of each mode, interleaved (after 3 of warm-up).
fn run(
    r: &mut Renderer,
    camera: prm_scene::Camera,
    lights: &[Light],
    frames: usize,
) -> Result<(Vec<FrameTimings>, Vec<FrameTimings>)> {
    let (mut direct, mut gi) = (Vec::new(), Vec::new());
    for i in 0..frames + 3 {
        for (mode, out) in [(Mode::Direct, &mut direct), (Mode::Gi, &mut gi)] {
            let t = r.render(&FrameInput { camera, lights, mode })?;
            if i >= 3 {
                out.push(t);
            }
        }
    }
    Ok((direct, gi))
}

fn workspace() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// The bake preset of the benchmarked archives: `$PRM_BENCH_PRESET`, or `preview`.
fn preset() -> String {
    std::env::var("PRM_BENCH_PRESET").unwrap_or_else(|_| "preview".into())
}

/// `prm-bake bake SCENE -o ARCHIVE --preset PRESET` ([`preset`]), to which the caller adds.
fn prm_bake(scene: &Path, archive: &Path) -> Command {
    let mut cmd = match std::env::var_os("PRM_BAKE") {
        Some(bin) => Command::new(bin),
        None => {
            let mut c = Command::new(std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into()));
            c.current_dir(workspace())
                .args(["run", "--quiet", "--release", "-p", "prm-bake", "--"]);
            c
        }
    };
    cmd.arg("bake")
        .arg(scene)
        .arg("-o")
        .arg(archive)
        .args(["--preset", &preset()]);
    cmd
}

/// The sizes the planner chooses for `scene` now: the `bake:` line of `prm-bake bake --plan`.
fn plan(scene: &Path, archive: &Path) -> Result<String> {
    let out = prm_bake(scene, archive).arg("--plan").output()?;
    if !out.status.success() {
        return Err(format!("prm-bake bake {} --plan failed ({})", scene.display(), out.status).into());
    }
    let text = String::from_utf8_lossy(&out.stderr);
    Ok(text
        .lines()
        .find(|l| l.starts_with("bake:"))
        .unwrap_or_default()
        .to_string())
}

/// Bakes `scene` into `archive` with [`preset`].
fn bake(scene: &Path, archive: &Path) -> Result<()> {
    println!("baking {} -> {} ...", scene.display(), archive.display());
    let status = prm_bake(scene, archive).arg("--quiet").status()?;
    if !status.success() {
        return Err(format!("prm-bake bake {} failed ({status})", scene.display()).into());
    }
    Ok(())
}

/// The scene and its archive, baked unless one exists that opens, matches its scene and was
/// baked to the plan the planner chooses now (kept beside it as `.plan`).
fn open(scene_path: &Path, archive: &Path) -> Result<(prm_play::FileArchive, Scene)> {
    let planned = plan(scene_path, archive)?;
    let plan_file = archive.with_extension("plan");
    if archive.exists() {
        let baked = std::fs::read_to_string(&plan_file).unwrap_or_default();
        match prm_play::open(archive, Some(scene_path)) {
            Ok(r) if baked == planned => return Ok(r),
            Ok(_) if baked.is_empty() => println!("re-baking: no plan beside the archive"),
            Ok(_) => println!("re-baking: the plan is now `{planned}`, the archive's `{baked}`"),
            Err(e) => println!("re-baking: {e}"),
        }
    }
    if let Some(dir) = archive.parent() {
        std::fs::create_dir_all(dir)?;
    }
    bake(scene_path, archive)?;
    std::fs::write(&plan_file, &planned)?;
    Ok(prm_play::open(archive, Some(scene_path))?)
}

/// The scene's lights, or a point light just below the middle of the ceiling.
fn lights(scene: &Scene) -> Vec<Light> {
    if !scene.lights.is_empty() {
        return scene.lights.clone();
    }
    let b = scene.bounds();
    let e = b.extent();
    let c = (b.min + b.max) * 0.5;
    vec![Light::Point {
        position: glam::Vec3::new(c.x, b.min.y + 0.95 * e.y, c.z),
        intensity: glam::Vec3::splat(0.75 * e.y * e.y),
    }]
}

/// Benchmarks one scene; returns (median ratio, GPU ratio).
fn bench(name: &str, scene_path: &Path, frames: usize) -> Result<(f64, f64)> {
    let archive_path = workspace()
        .join("target/prm-bench")
        .join(format!("{name}-{}.prm", preset()));
    let (mut archive, scene) = open(scene_path, &archive_path)?;
    let ctx = prm_play::open_vulkan()?;
    let opts = PlayOptions {
        width: 1024,
        height: 768,
        runtime: prm_play::RuntimeOptions {
            top_k: prm_play::archive_top_k(&archive),
            // The cost of a frame whose lights move: the bench's light stands still.
            gi_update: prm_play::GiUpdate::EveryFrame,
            ..Default::default()
        },
        timestamps: true,
    };
    let lights = lights(&scene);
    let res = archive.atlas().resolution;
    let mut r = Renderer::new(ctx, &scene, &mut archive, opts.clone())?;
    println!(
        "{name}: {} triangles, {} light(s), atlas/panes {res}², {} clusters, top K {}, shadow maps {}²",
        scene.triangles.len(),
        lights.len(),
        r.cluster_count(),
        opts.runtime.top_k,
        opts.runtime.shadow_resolution
    );
    if !r.has_timestamps() {
        println!("  (no timestamp queries on this device: wall times only)");
    }
    let camera = prm_play::default_camera(&scene);
    // Frame times without timestamp queries (on lavapipe each one is a synchronisation point),
    // then per-pass GPU times with them.
    r.set_timing(false);
    let (direct, gi) = run(&mut r, camera, &lights, frames)?;
    let (d, g) = (Stats::of(&direct), Stats::of(&gi));
    println!(
        "  frame time (median, min): direct {:.2} ms, {:.2} ms; gi {:.2} ms, {:.2} ms",
        d.median_ms, d.min_ms, g.median_ms, g.min_ms
    );
    r.set_timing(true);
    let (direct, gi) = run(&mut r, camera, &lights, frames)?;
    let (dt, gt) = (Stats::of(&direct), Stats::of(&gi));
    dt.print_passes("direct");
    gt.print_passes("gi");
    // The last frame (gi) for a look: target/prm-bench/NAME-gi.png.
    let png = archive_path.with_file_name(format!("{name}-{}-gi.png", preset()));
    prm_play::output::write_png(&png, &r.read_image()?, 1.0)?;
    let ratio = g.median_ms / d.median_ms;
    let gpu_ratio = gt.gpu_total() / dt.gpu_total();
    println!(
        "  gi / direct: frame time (median) {ratio:.3}, GPU time {gpu_ratio:.3}   [{}]",
        png.display()
    );
    r.set_timing(false);
    attribute(
        &mut r,
        &mut archive,
        &scene,
        &opts,
        camera,
        &lights,
        frames,
        d.median_ms,
    )?;
    Ok((ratio, gpu_ratio))
}

/// Prints where the gi frame's added wall time goes (see the module doc): gi frames of `base`
/// interleaved with those of a player without the near field, and of one without the near field
/// blending 8 panes, so that the differences telescope to the whole added time.
#[allow(clippy::too_many_arguments)]
fn attribute(
    base: &mut Renderer,
    archive: &mut prm_play::FileArchive,
    scene: &Scene,
    opts: &PlayOptions,
    camera: prm_scene::Camera,
    lights: &[Light],
    frames: usize,
    direct_ms: f64,
) -> Result<()> {
    let no_near = prm_play::RuntimeOptions {
        near_light: prm_play::NearLight::Off,
        ..opts.runtime.clone()
    };
    let few = prm_play::RuntimeOptions {
        top_k: 8.min(opts.runtime.top_k),
        residual_groups: 0,
        ..no_near.clone()
    };
    let mut player = |runtime| {
        let opts = PlayOptions {
            runtime,
            timestamps: false,
            ..opts.clone()
        };
        Renderer::new(prm_play::open_vulkan()?, scene, archive, opts)
    };
    let (mut no_near, mut few) = (player(no_near)?, player(few)?);
    let mut times = [Vec::new(), Vec::new(), Vec::new()];
    for i in 0..frames + 3 {
        for (r, out) in [&mut *base, &mut no_near, &mut few].into_iter().zip(times.iter_mut()) {
            let t = r.render(&FrameInput {
                camera,
                lights,
                mode: Mode::Gi,
            })?;
            if i >= 3 {
                out.push(t);
            }
        }
    }
    let [gi, no_near, few] = times.map(|t| Stats::of(&t).median_ms);
    println!(
        "  gi's added {:.1} ms: weights, ranking and 8 panes {:.1} ms, the other panes and groups {:.1} ms, \
         near field {:.1} ms",
        gi - direct_ms,
        few - direct_ms,
        no_near - few,
        gi - no_near
    );
    Ok(())
}

fn main() {
    let frames: usize = std::env::args().skip(1).find_map(|a| a.parse().ok()).unwrap_or(20);
    let root = workspace();
    let shared = root.join("../shared/scenes");
    let mut scenes = vec![
        ("cornell-box", root.join("scenes/cornell-box/cornell-box.gltf")),
        ("chairs", root.join("scenes/chairs/chairs.gltf")),
    ];
    if shared.is_dir() {
        scenes.push(("CornellBox-Sphere", shared.join("cornell-box/CornellBox-Sphere.obj")));
    } else {
        println!("skipping CornellBox-Sphere: {} is absent", shared.display());
    }
    match prm_play::open_vulkan() {
        Ok(ctx) => println!("GPU: {}", ctx.describe()),
        Err(e) => {
            eprintln!("error: {e}");
            std::process::exit(1);
        }
    }
    println!(
        "1024x768; modes interleaved; 3 warm-up + {frames} frames per mode for frame times (no timestamp \
         queries), then as many with them for GPU times per pass\n"
    );
    let mut summary = Vec::new();
    let mut failed = false;
    for (name, path) in &scenes {
        match bench(name, path, frames) {
            Ok(r) => summary.push((name, r)),
            Err(e) => {
                eprintln!("error: {name}: {e}");
                failed = true;
            }
        }
        println!();
    }
    println!("summary, gi / direct (target <= 1.10):");
    for (name, (ratio, gpu)) in &summary {
        println!("  {name:>18}: frame time {ratio:.3}, GPU time {gpu:.3}");
    }
    if failed {
        std::process::exit(1);
    }
}
