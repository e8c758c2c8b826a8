//! `prm-play`: plays a baked `.prm` archive, in a window (orbit camera) or headless to EXR/PNG.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use clap::Parser;
use prm_play::animation::Animation;
use prm_play::{output, FrameInput, Mode, PlayOptions, Renderer, RuntimeOptions};

/// The exit statuses, as `--help` states them.
const EXIT_STATUS: &str = "Exit status: 0 success; 2 the command was refused before any frame (a wrong argument, an \
output that may not be written, an option beyond the device's limits); 1 a failure during the work (an unreadable \
or damaged archive or scene, the GPU, writing a frame).";

/// Real-time global illumination from a Precomputed Radiance Map.
#[derive(Parser, Debug)]
#[command(name = "prm-play", version, after_help = prm_play::window::CONTROLS)]
#[command(after_long_help = EXIT_STATUS)]
struct Args {
    /// The baked archive.
    archive: PathBuf,
    /// Scene file (default: the archive's `source_scene`, relative to the archive).
    #[arg(long)]
    scene: Option<PathBuf>,
    /// Render `--frames` frames to `--out` without a window (default: open a window; its mouse
    /// and keys are listed below).
    #[arg(long)]
    headless: bool,
    /// Image size, WxH.
    #[arg(long, default_value = "1024x768", value_name = "WxH", value_parser = prm_scene::parse_size,
          allow_hyphen_values = true)]
    size: (u32, u32),
    /// Camera `EX,EY,EZ:TX,TY,TZ:FOV_DEG` (default: the scene's first, or a view into its bounds
    /// from the side it is open on, from inside when it is closed all round).
    #[arg(long, value_name = "SPEC", value_parser = prm_scene::parse_camera, allow_hyphen_values = true)]
    camera: Option<prm_scene::Camera>,
    /// Light spec, repeatable: `point:X,Y,Z:R,G,B` (W/sr), `spot:X,Y,Z:DX,DY,DZ:ANGLE_DEG:R,G,B`
    /// (cone half angle), `rect:X,Y,Z:DX,DY,DZ:UX,UY,UZ:HALF_X_DEG,HALF_Y_DEG:R,G,B` (a
    /// rectangular spot along D with vertical U), `dir:DX,DY,DZ:R,G,B` (W/m²). Default: the
    /// scene's lights.
    #[arg(long = "light", value_name = "SPEC", value_parser = prm_scene::parse_light, allow_hyphen_values = true)]
    lights: Vec<prm_scene::Light>,
    /// Scale an emitter group (one per emissive material of the bake, listed by `prm-bake dump`):
    /// `NAME=S` or `NAME=R,G,B`, repeatable, `*` for every group; 0 turns a group off. Default: 1.
    #[arg(long = "emitter", value_name = "NAME=SCALE")]
    emitters: Vec<String>,
    /// Light the scene with a sky (archives baked with `prm-bake bake --sky`): `R,G,B` for a
    /// uniform radiance (W/(m²·sr)) or an equirectangular `.hdr`/`.exr` map (row 0 the zenith,
    /// +Y up, the map's centre column facing -Z). Add the sun with `--light dir:...`.
    #[arg(long, value_name = "R,G,B|FILE")]
    sky: Option<String>,
    /// Multiplies the sky's radiance.
    #[arg(long, default_value_t = 1.0, requires = "sky")]
    sky_intensity: f32,
    /// Turns the sky about the vertical (+Y) axis, degrees (+Z towards +X).
    #[arg(long, default_value_t = 0.0, requires = "sky", allow_negative_numbers = true)]
    sky_rotation: f32,
    /// Show a moving sphere lit by the archive's irradiance probes (archives baked with
    /// `prm-bake bake --probes`) and by the lights: it circles the scene's vertical axis at a
    /// third of its height, one turn every 8 s (headless: frame i at the animation's time, or
    /// i/30 s).
    #[arg(long)]
    probe_sphere: bool,
    /// gi, direct, indirect or split (left direct, right gi).
    #[arg(long, default_value = "gi")]
    mode: Mode,
    /// Clusters kept per frame (default: the archive's params.top_k, else 32).
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..))]
    top_k: Option<u32>,
    /// Residual groups: when the top K drops clusters, their light goes through this many
    /// groups' summed panes (up to K + G panes a frame); 0 scales the kept clusters up instead.
    #[arg(long, value_name = "G", default_value_t = prm_format::RESIDUAL_GROUPS)]
    residual_groups: u32,
    /// The archive's near field (the light the panes' VPL bound removes next to other surfaces,
    /// gathered each frame): `gather`, or `off` to play the panes alone (darker than they should
    /// be, most at edges and contacts).
    #[arg(long, value_name = "gather|off", default_value = "gather", value_parser = ["gather", "off"])]
    near_field: String,
    /// How many times the near field's deeper share is gathered after the blend, each from the
    /// lightmap the previous gather completed: light passing back and forth between close
    /// surfaces (0 leaves that share out; each gather costs a pass over the near field).
    #[arg(long, value_name = "N", default_value_t = prm_play::RuntimeOptions::DEFAULT_NEAR_BOUNCES,
          value_parser = clap::value_parser!(u32).range(0..=prm_play::MAX_NEAR_BOUNCES as i64))]
    near_bounces: u32,
    /// After the last gather: `extrapolate` the rest of the light passed back and forth, from
    /// the last gather's share and each exit point's ratio for uniform light, or `off` to stop at
    /// the gathers.
    #[arg(long, value_name = "extrapolate|off", default_value = "extrapolate", value_parser = ["extrapolate", "off"])]
    near_tail: String,
    /// When the indirect light is computed again: `on-change` (when the lights, K, an emitter's
    /// scale or the sky change; frames whose lights stand still cost their direct light alone)
    /// or `every-frame` (what a frame whose lights move costs: time GI with it).
    #[arg(long, value_name = "on-change|every-frame", default_value = "on-change", value_parser = ["on-change", "every-frame"])]
    gi_update: String,
    /// Frames to render (headless: default 1). In a window: quit after this many presented
    /// frames (default: run until closed).
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..))]
    frames: Option<u32>,
    /// Keyframed lights, camera, emitter scales and sky (TOML; see the prm_play::animation docs).
    #[arg(long)]
    animation: Option<PathBuf>,
    /// Output directory (headless).
    #[arg(long, default_value = "out")]
    out: PathBuf,
    /// Also save the last frame as a PNG here: in a window, the last presented frame (read back
    /// from the swapchain) when the window closes; headless, a copy of the last frame's PNG.
    #[arg(long, value_name = "FILE.png")]
    screenshot: Option<PathBuf>,
    /// Write per-pass GPU times, frame times, the resident memory after each frame, the run
    /// time's GPU memory by part and the bytes its passes read an update, in all and by part,
    /// as JSON (headless only; with a still light, add `--gi-update every-frame` to time the
    /// indirect light's passes on every frame).
    #[arg(long, value_name = "FILE.json")]
    timings: Option<PathBuf>,
    /// Shadow-map resolution per view (16 to 8192, and at most the device's largest texture).
    #[arg(long, default_value_t = 512,
          value_parser = clap::value_parser!(u32).range(16..=prm_runtime::MAX_SHADOW_RESOLUTION as i64))]
    shadow_resolution: u32,
    /// A directional light's shadow map is this many tiles on a side, each a view of
    /// --shadow-resolution² texels over the scene's bounding sphere (1 to 8)
    #[arg(long, default_value_t = prm_play::RuntimeOptions::DEFAULT_SUN_TILES,
          value_parser = clap::value_parser!(u32).range(1..=prm_runtime::MAX_SUN_TILES as i64))]
    sun_tiles: u32,
    /// Fade band: kept clusters scoring within (1 + band) × the first dropped cluster's score are
    /// faded by a smoothstep (0: hard cut).
    #[arg(long, default_value_t = 0.25, value_parser = non_negative, allow_negative_numbers = true)]
    fade_band: f32,
    /// Write static lightmaps for the first frame's lights into this directory and exit (no
    /// window): indirect.exr and irradiance.exr (direct + indirect, W/m² per lightmap texel), the
    /// same as indirect.ktx2 and irradiance.ktx2 (RGB9E5, Zstandard; Bevy loads them directly),
    /// and scene.gltf + scene.bin with the lightmap UVs as TEXCOORD_1, for engines that take only
    /// baked lightmaps.
    #[arg(long, value_name = "DIR", conflicts_with_all = ["screenshot", "timings", "frames", "out", "probe_sphere"])]
    export: Option<PathBuf>,
    /// Exposure of the tone-mapped PNG (multiplies radiance before clamping and sRGB).
    #[arg(long, default_value_t = 1.0, value_parser = non_negative, allow_negative_numbers = true)]
    exposure: f32,
    /// Where headless frames are rendered: `vulkan` (a GPU, or Mesa's lavapipe), `cpu`
    /// (ray-traced on the CPU, no GPU driver needed: punctual lights only, no sky, emitters,
    /// probes, export or GPU timings), or `auto`: Vulkan when an adapter exists, else the CPU,
    /// with a note.
    #[arg(long, value_name = "auto|vulkan|cpu", default_value = "auto", value_parser = ["auto", "vulkan", "cpu"])]
    backend: String,
}

/// A finite number >= 0, for `--exposure` and `--fade-band`.
fn non_negative(s: &str) -> Result<f32, String> {
    match s.trim().parse::<f32>() {
        Ok(v) if v.is_finite() && v >= 0.0 => Ok(v),
        Ok(v) => Err(format!("{v} is not a finite number >= 0")),
        Err(e) => Err(format!("{s:?} is not a number: {e}")),
    }
}

/// Prints an error as `error: ` and its chain on one line (as `prm-bake` does), rather than
/// `main`'s default `Error: ` debug dump with a backtrace, and exits with [`exit_status`].
fn main() -> std::process::ExitCode {
    match run() {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            std::process::ExitCode::from(exit_status(&e))
        }
    }
}

/// An argument refused before any work: exit status 2.
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
struct Refused(String);

/// Returns early with a [`Refused`] error (exit status 2) from a `format!` message.
macro_rules! refuse {
    ($($arg:tt)*) => {
        return Err(refused(format!($($arg)*)))
    };
}

/// The exit status of a failed run: 2 when it was refused before any frame (a wrong argument,
/// an output that may not be written, an option beyond the device's limits, an animation file
/// that does not parse), 1 when the work failed (an unreadable or damaged archive or scene, the
/// GPU, writing a frame). Clap's own refusals exit 2 as well.
fn exit_status(e: &anyhow::Error) -> u8 {
    use prm_play::PlayError;
    let refused = e.chain().any(|c| {
        c.is::<Refused>()
            || matches!(
                c.downcast_ref::<PlayError>(),
                Some(PlayError::Option { .. } | PlayError::Animation { .. })
            )
            || matches!(
                c.downcast_ref::<prm_runtime::RuntimeError>(),
                Some(prm_runtime::RuntimeError::Option { .. } | prm_runtime::RuntimeError::TooManyLights { .. })
            )
    });
    if refused {
        2
    } else {
        1
    }
}

fn run() -> Result<()> {
    let mut args = Args::parse();
    check_arguments(&args)?;
    args.headless |= args.export.is_some();
    if args.headless {
        prm_gpu_kit::silence_wayland_probe();
    }
    let (mut archive, scene) = prm_play::open(&args.archive, args.scene.as_deref())?;
    if let Some(w) = prm_play::materials_warning(&archive, &scene) {
        eprintln!("warning: {w}");
    }
    check_outputs(&args, &scene.source)?;
    let animation = args.animation.as_deref().map(Animation::load).transpose()?;
    let emitter_infos: Vec<prm_runtime::EmitterInfo> = archive.emitters().iter().map(Into::into).collect();
    let emitter_scales = prm_play::emitter_scales(&emitter_infos, &args.emitters).map_err(refused)?;
    let sky = prm_play::sky(
        args.sky.as_deref(),
        args.sky_intensity,
        args.sky_rotation,
        archive.sky().is_some(),
    )
    .map_err(refused)?;
    if let Some(w) = sky.as_ref().and_then(prm_play::sky_ringing) {
        eprintln!("warning: {w}");
    }
    if sky.is_none() && animation.as_ref().is_some_and(|a| !a.sky.is_empty()) {
        refuse!("the animation has sky keys, which animate a --sky: give one");
    }
    let lit_by_emitters = emitter_scales.iter().flatten().any(|&s| s > 0.0) || sky.is_some();
    let play = Play {
        camera: args.camera.unwrap_or_else(|| prm_play::viewer_camera(&scene)),
        lights: base_lights(&args, &scene, lit_by_emitters, animation.as_ref()),
        top_k: args.top_k.unwrap_or_else(|| prm_play::archive_top_k(&archive)),
        animation,
        emitter_scales,
        sky,
    };
    let runtime = runtime_options(&args, play.top_k);
    let (width, height) = args.size;
    if !args.headless {
        return prm_play::window::run(prm_play::window::WindowConfig {
            scene,
            archive,
            options: PlayOptions {
                width,
                height,
                runtime,
                timestamps: false,
            },
            camera: play.camera,
            lights: play.lights,
            animation: play.animation,
            mode: args.mode,
            exposure: args.exposure,
            frames: args.frames,
            screenshot: args.screenshot,
            emitter_scales: play.emitter_scales,
            sky: play.sky,
            probe_sphere: args.probe_sphere,
        })
        .with_context(|| format!("playing {} in a window", args.archive.display()));
    }
    let Some(ctx) = open_gpu(&args.backend)? else {
        return play_cpu(&args, &play, &scene, &mut archive);
    };
    eprintln!("GPU: {}", ctx.describe());
    let opts = PlayOptions {
        width,
        height,
        runtime,
        timestamps: args.timings.is_some(),
    };
    let mut renderer = Renderer::new(ctx, &scene, &mut archive, opts)
        .with_context(|| format!("playing {}", args.archive.display()))?;
    let emitter_names: Vec<&str> = emitter_infos.iter().map(|g| g.name.as_str()).collect();
    if let Some(a) = play.animation.as_ref().filter(|a| !a.emitters.is_empty()) {
        // Names checked before any frame.
        a.emitter_scales_at(&emitter_names, &play.emitter_scales, 0.0)
            .map_err(refused)
            .with_context(|| format!("in {}", args.animation.clone().unwrap_or_default().display()))?;
    }
    if !play.emitter_scales.is_empty() {
        renderer.set_emitter_scales(&play.emitter_scales)?;
    }
    if let Some(sky) = &play.sky {
        renderer.set_sky(sky)?;
    }
    if let Some(dir) = &args.export {
        let lights = match &play.animation {
            Some(a) if !a.lights.is_empty() => a.lights_at(a.time(0)),
            _ => play.lights.clone(),
        };
        let e = prm_play::export::export(&mut renderer, &scene, &lights, dir)
            .with_context(|| format!("exporting lightmaps to {}", dir.display()))?;
        for p in [
            &e.indirect,
            &e.irradiance,
            &e.indirect_ktx2,
            &e.irradiance_ktx2,
            &e.gltf,
        ] {
            eprintln!("wrote {}", p.display());
        }
        return Ok(());
    }
    if args.timings.is_some() && !renderer.has_timestamps() {
        eprintln!("note: this device has no timestamp queries; --timings records CPU frame times only");
    }
    let frames = play_headless(&args, &play, &scene, &emitter_names, &mut renderer)?;
    if let Some(path) = &args.timings {
        write_timings(path, &args, &renderer, play.top_k, &frames)?;
    }
    Ok(())
}

/// The Vulkan device headless frames are rendered on, or `None` for the CPU player: with
/// `--backend cpu`, or with `auto` when no Vulkan adapter exists (said in a note).
fn open_gpu(backend: &str) -> Result<Option<prm_gpu_kit::GpuContext>> {
    if backend == "cpu" {
        return Ok(None);
    }
    match prm_play::open_vulkan() {
        Ok(ctx) => Ok(Some(ctx)),
        Err(e @ prm_gpu_kit::GpuError::NoAdapter { .. }) if backend == "auto" => {
            eprintln!("note: {e}\nnote: rendering on the CPU instead (--backend cpu: punctual lights only)");
            Ok(None)
        }
        Err(e) => Err(e.into()),
    }
}

/// Refuses what the CPU player does not play, before any frame.
fn check_cpu_options(args: &Args, play: &Play) -> Result<()> {
    let unsupported = [
        (args.export.is_some(), "--export"),
        (args.timings.is_some(), "--timings"),
        (args.probe_sphere, "--probe-sphere"),
        (play.sky.is_some(), "--sky"),
        (!args.emitters.is_empty(), "--emitter"),
        (args.near_tail == "off", "--near-tail off"),
        (
            play.animation.as_ref().is_some_and(|a| !a.emitters.is_empty()),
            "an animation of emitter scales",
        ),
    ];
    if let Some((_, what)) = unsupported.iter().find(|(given, _)| *given) {
        refuse!("{what} needs the GPU player, and the CPU player renders these frames (no Vulkan adapter, or --backend cpu)");
    }
    Ok(())
}

/// Plays the frames on the CPU ([`prm_play::cpu`]) and writes them as the GPU player does.
fn play_cpu(args: &Args, play: &Play, scene: &prm_scene::Scene, archive: &mut prm_play::FileArchive) -> Result<()> {
    check_cpu_options(args, play)?;
    if !archive.emitters().is_empty() || archive.sky().is_some() {
        eprintln!("note: the CPU player plays punctual lights only: this archive's emitters and sky stay dark");
    }
    let options = prm_play::cpu::CpuOptions {
        top_k: play.top_k,
        residual_groups: args.residual_groups,
        fade_band: args.fade_band,
        near_field: args.near_field == "gather",
        near_bounces: args.near_bounces,
    };
    let started = std::time::Instant::now();
    let model = prm_play::cpu::CpuArchive::load(archive, scene, &options)
        .with_context(|| format!("playing {} on the CPU", args.archive.display()))?;
    let player = prm_play::cpu::CpuPlayer::new(scene, &model, options)?;
    eprintln!(
        "CPU: {} threads, loaded in {:.2} s",
        rayon::current_num_threads(),
        started.elapsed().as_secs_f64()
    );
    std::fs::create_dir_all(&args.out).with_context(|| format!("creating {}", args.out.display()))?;
    let frame_count = args.frames.unwrap_or(1);
    for i in 0..frame_count {
        let (camera, lights) = frame_view(play, i);
        let start = std::time::Instant::now();
        let input = FrameInput {
            camera,
            lights: &lights,
            mode: args.mode,
        };
        let image = player.render(&input, args.size.0, args.size.1);
        write_frame(args, i, i + 1 == frame_count, &image)?;
        eprintln!("frame {i}: {:.2} ms (CPU)", start.elapsed().as_secs_f64() * 1e3);
    }
    Ok(())
}

/// Frame `i`'s camera and lights: the animation's where it drives them, else the fixed ones.
fn frame_view(play: &Play, i: u32) -> (prm_scene::Camera, Vec<prm_scene::Light>) {
    match play.animation.as_ref() {
        Some(a) => {
            let t = a.time(i);
            let lights = if a.lights.is_empty() {
                play.lights.clone()
            } else {
                a.lights_at(t)
            };
            (a.camera_at(t).unwrap_or(play.camera), lights)
        }
        None => (play.camera, play.lights.clone()),
    }
}

/// What the frames play, from the arguments and the scene: the camera and lights when the
/// animation does not drive them, K, the animation, the emitter scales and the sky.
struct Play {
    camera: prm_scene::Camera,
    lights: Vec<prm_scene::Light>,
    top_k: u32,
    animation: Option<Animation>,
    emitter_scales: Vec<[f32; 3]>,
    sky: Option<prm_scene::Sky>,
}

/// A `refuse!` from a message: an argument refused before any frame (exit status 2).
fn refused(message: String) -> anyhow::Error {
    anyhow::Error::new(Refused(message))
}

/// The checks of the arguments alone, before any file is read.
fn check_arguments(args: &Args) -> Result<()> {
    if args.timings.is_some() && !args.headless {
        refuse!("--timings needs --headless: a window records no timings");
    }
    if args.backend == "cpu" && !args.headless && args.export.is_none() {
        refuse!("--backend cpu renders headless frames only: add --headless");
    }
    if let Some(p) = args
        .screenshot
        .as_ref()
        .filter(|p| !p.extension().is_some_and(|e| e.eq_ignore_ascii_case("png")))
    {
        refuse!(
            "--screenshot {}: the screenshot is a PNG; name it FILE.png",
            p.display()
        );
    }
    if args.headless && args.export.is_none() && args.out.exists() && !args.out.is_dir() {
        refuse!(
            "--out {}: it exists and is not a directory (--out names the directory the frames go to)",
            args.out.display()
        );
    }
    Ok(())
}

/// Before any frame: no output may be the archive or the scene (`scene`), nor lie below a file.
fn check_outputs(args: &Args, scene: &Path) -> Result<()> {
    let inputs = [args.archive.as_path(), scene];
    for (flag, path) in [("--timings", &args.timings), ("--screenshot", &args.screenshot)] {
        if let Some(path) = path {
            check_output(flag, path, &inputs)?;
        }
    }
    if let Some(dir) = &args.export {
        if dir.exists() && !dir.is_dir() {
            refuse!("--export {}: it exists and is not a directory", dir.display());
        }
        for name in prm_play::export::FILES {
            check_output("--export", &dir.join(name), &inputs)?;
        }
    }
    Ok(())
}

/// The lights of frames the animation does not light: `--light`, else the scene's, else (when
/// nothing else lights the scene) a placed light, with a warning that says where.
fn base_lights(
    args: &Args,
    scene: &prm_scene::Scene,
    lit_by_emitters: bool,
    animation: Option<&Animation>,
) -> Vec<prm_scene::Light> {
    let lights = if args.lights.is_empty() {
        scene.lights.clone()
    } else {
        args.lights.clone()
    };
    if !lights.is_empty() || lit_by_emitters || animation.is_some_and(|a| !a.lights.is_empty()) {
        return lights;
    }
    // A black frame helps nobody: light the scene, and say where and how to choose.
    let light = prm_play::default_light(scene);
    eprintln!(
        "warning: the scene has no lights of its own and no --light was given; placing {} \
         (pass --light SPEC to choose, e.g. --light {}; in a window, arrows and PageUp/PageDown move it)",
        prm_play::describe_light(&light),
        prm_play::light_spec(&light)
    );
    vec![light]
}

/// The run time's options from the arguments.
fn runtime_options(args: &Args, top_k: u32) -> RuntimeOptions {
    RuntimeOptions {
        top_k,
        residual_groups: args.residual_groups,
        shadow_resolution: args.shadow_resolution,
        sun_tiles: args.sun_tiles,
        fade_band: args.fade_band,
        near_bounces: args.near_bounces,
        near_tail: if args.near_tail == "off" {
            prm_play::NearTail::Off
        } else {
            prm_play::NearTail::Extrapolated
        },
        near_light: if args.near_field == "off" {
            prm_play::NearLight::Off
        } else {
            prm_play::NearLight::Gather
        },
        gi_update: if args.gi_update == "every-frame" {
            prm_play::GiUpdate::EveryFrame
        } else {
            prm_play::GiUpdate::OnChange
        },
        ..Default::default()
    }
}

/// Renders `--frames` frames into `--out` (and the last one to `--screenshot`); returns each
/// frame's timings and the resident memory after it.
fn play_headless(
    args: &Args,
    play: &Play,
    scene: &prm_scene::Scene,
    emitter_names: &[&str],
    renderer: &mut Renderer,
) -> Result<Vec<(prm_play::FrameTimings, Option<u64>)>> {
    std::fs::create_dir_all(&args.out).with_context(|| format!("creating {}", args.out.display()))?;
    let mut frames = Vec::new();
    let frame_count = args.frames.unwrap_or(1);
    let animation = play.animation.as_ref();
    for i in 0..frame_count {
        let (camera, lights) = frame_view(play, i);
        if let Some(a) = animation.filter(|a| !a.emitters.is_empty()) {
            let scales = a
                .emitter_scales_at(emitter_names, &play.emitter_scales, a.time(i))
                .map_err(anyhow::Error::msg)?;
            renderer.set_emitter_scales(&scales)?;
        }
        if let Some(s) = animation
            .zip(play.sky.as_ref())
            .and_then(|(a, s)| a.sky_state_at(s, a.time(i)))
        {
            renderer.set_sky(&s)?;
        }
        if args.probe_sphere {
            let t = animation.map_or(i as f32 / 30.0, |a| a.time(i));
            renderer.set_probe_sphere(Some(prm_play::ProbeSphere::orbit(&scene.bounds(), t)))?;
        }
        let t = renderer
            .render(&FrameInput {
                camera,
                lights: &lights,
                mode: args.mode,
            })
            .with_context(|| {
                format!(
                    "rendering frame {i} at {}x{} with {} light(s), shadow maps of {}² texels \
                     (--shadow-resolution), a sun's in {}² tiles (--sun-tiles)",
                    args.size.0,
                    args.size.1,
                    lights.len(),
                    args.shadow_resolution,
                    args.sun_tiles
                )
            })?;
        let image = renderer.read_image()?;
        write_frame(args, i, i + 1 == frame_count, &image)?;
        eprintln!("frame {i}: {:.2} ms", t.cpu_ms);
        // Read only for --timings: a file read on every frame otherwise.
        let resident = args.timings.as_ref().and_then(|_| resident_bytes());
        frames.push((t, resident));
    }
    Ok(frames)
}

/// Writes frame `i` as EXR and PNG into `--out`, and the last one to `--screenshot`; warns of
/// pixels that are not finite.
fn write_frame(args: &Args, i: u32, last: bool, image: &prm_play::Image) -> Result<()> {
    let bad = image.rgb.iter().filter(|p| !p.iter().all(|v| v.is_finite())).count();
    if bad > 0 {
        eprintln!(
            "warning: frame {i}: {bad} of {} pixels are not finite: a light's intensity or an \
             emitter's scale is beyond what 32-bit floats hold",
            image.rgb.len()
        );
    }
    let stem = args.out.join(format!("frame{i:04}"));
    output::write_exr(&stem.with_extension("exr"), image)?;
    output::write_png(&stem.with_extension("png"), image, args.exposure)?;
    if let (Some(path), true) = (&args.screenshot, last) {
        create_parent(path)?;
        output::write_png(path, image, args.exposure)?;
    }
    Ok(())
}

/// Writes `--timings`: per-pass GPU times, frame times and the resident memory after each frame,
/// the run time's GPU memory by part and the bytes its indirect-light passes read an update.
fn write_timings(
    path: &Path,
    args: &Args,
    renderer: &Renderer,
    top_k: u32,
    frames: &[(prm_play::FrameTimings, Option<u64>)],
) -> Result<()> {
    let json = serde_json::json!({
        "gpu_timestamps": renderer.has_timestamps(),
        "note": if renderer.has_timestamps() {
            "gpu_ms: per-pass GPU time from timestamp queries; cpu_ms: wall time from recording to GPU completion"
        } else {
            "no timestamp queries on this device: cpu_ms only (wall time from recording to GPU completion)"
        },
        "size": [args.size.0, args.size.1],
        "mode": format!("{:?}", args.mode).to_lowercase(),
        // The clusters blended: K, or every cluster when K is larger.
        "top_k": top_k.min(renderer.cluster_count()),
        "top_k_requested": top_k,
        "residual_groups": renderer.runtime().group_count(),
        "clusters": renderer.cluster_count(),
        // The run time's GPU memory by part (bytes, from the allocator's report), and what its
        // indirect-light passes read on every update.
        "gpu_memory": renderer.runtime().gpu_memory().map(|parts| {
            parts.iter().map(|p| (p.name.to_string(), serde_json::json!(p.bytes))).collect::<serde_json::Map<_, _>>()
        }),
        "gi_bytes_read_per_update": renderer.runtime().gi_bytes_read(),
        "gi_bytes_read_by_part": renderer.runtime().gi_bytes_read_by_part().iter()
            .map(|p| (p.name.to_string(), serde_json::json!(p.bytes)))
            .collect::<serde_json::Map<_, _>>(),
        "frames": frames.iter().map(|(f, rss)| serde_json::json!({
            "cpu_ms": f.cpu_ms,
            "gpu_ms": f.gpu_ms.iter().map(|(k, v)| ((*k).to_string(), serde_json::json!(v))).collect::<serde_json::Map<_, _>>(),
            "rss_bytes": rss,
        })).collect::<Vec<_>>(),
    });
    create_parent(path)?;
    std::fs::write(path, serde_json::to_string_pretty(&json)?).with_context(|| format!("writing {}", path.display()))
}

/// Refuses an output `path` (of option `flag`) that names one of `inputs` (the archive, the
/// scene), is not a regular file, or lies below a file; a missing directory is created when
/// writing.
fn check_output(flag: &str, path: &Path, inputs: &[&Path]) -> Result<()> {
    if let Some(input) = inputs.iter().find(|i| prm_scene::same_destination(i, path)) {
        refuse!(
            "{flag} {}: it is {}, which the player reads; name another file",
            path.display(),
            input.display()
        );
    }
    prm_scene::check_output_path(path).map_err(|why| refused(format!("{flag} {}: {why}", path.display())))
}

/// The process's resident memory after a frame (`VmRSS` in `/proc/self/status`; Linux only),
/// recorded per frame by `--timings`.
fn resident_bytes() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmRSS:"))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib * 1024)
}

/// Creates `path`'s missing directories.
fn create_parent(path: &Path) -> Result<()> {
    match path.parent().filter(|d| !d.as_os_str().is_empty()) {
        Some(dir) => std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display())),
        None => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(args: &[&str]) -> Result<Args, clap::Error> {
        Args::try_parse_from([&["prm-play", "a.prm"][..], args].concat())
    }

    /// Values that start with a minus sign (most scenes need negative coordinates) are values,
    /// not unknown options; a negative size is refused as a size.
    #[test]
    fn negative_numbers_are_values() {
        let a = parse(&[
            "--camera",
            "-1.5,1.2,2.5:-0.5,0,0:40",
            "--light",
            "point:-1,2,-3:1,1,1",
            "--light",
            "dir:-0.3,-1,0.2:2,2,2",
        ])
        .unwrap();
        assert_eq!(a.camera.unwrap().eye, glam::Vec3::new(-1.5, 1.2, 2.5));
        assert_eq!(a.lights.len(), 2);
        let e = parse(&["--size", "-5x5"]).unwrap_err().to_string();
        assert!(e.contains("--size") && !e.contains("unexpected argument"), "{e}");
    }

    /// Every value refused before any work exits 2 with clap's message naming the option;
    /// among them values that the GPU would otherwise meet only after it had started.
    #[test]
    fn bad_values_are_refused_up_front_with_status_2() {
        for args in [
            &["--size", "0x0"][..],
            &["--shadow-resolution", "8"],
            &["--sun-tiles", "0"],
            &["--frames", "0"],
            &["--top-k", "0"],
            &["--exposure", "-1"],
            &["--near-bounces", "1000"],
            &["--camera", "0,0,0:0,0,0:40"],
            &["--light", "point:0,0,0"],
        ] {
            let e = parse(args).map(|_| ()).unwrap_err();
            assert_eq!(e.exit_code(), 2, "{args:?}: {e}");
            assert!(e.to_string().contains(args[0]), "{args:?} names the option: {e}");
        }
    }

    /// Refusals raised while checking the arguments exit 2; failures during the work exit 1.
    #[test]
    fn exit_status_tells_refusals_from_failures() {
        assert_eq!(exit_status(&anyhow::Error::new(Refused("bad".into()))), 2);
        let option = prm_play::PlayError::Option {
            option: "--shadow-resolution",
            message: "too large".into(),
        };
        assert_eq!(exit_status(&anyhow::Error::new(option).context("playing")), 2);
        let failed = prm_play::PlayError::Window("lost".into());
        assert_eq!(exit_status(&anyhow::Error::new(failed)), 1);
    }
}
