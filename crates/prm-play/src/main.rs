//! `prm-play`: plays a baked `.prm` archive, in a window (orbit camera) or headless to EXR/PNG.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use clap::Parser;
use prm_play::animation::Animation;
use prm_play::{output, FrameInput, Mode, PlayOptions, Renderer, RuntimeOptions};

/// Real-time global illumination from a Precomputed Radiance Map.
#[derive(Parser, Debug)]
#[command(name = "prm-play", version, after_help = prm_play::window::CONTROLS)]
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
    #[arg(long, default_value = "1024x768")]
    size: String,
    /// Camera `EX,EY,EZ:TX,TY,TZ:FOV_DEG` (default: the scene's first, or a view into its bounds
    /// from the side it is open on, from inside when it is closed all round).
    #[arg(long)]
    camera: Option<String>,
    /// Light spec, repeatable: `point:X,Y,Z:R,G,B` (W/sr), `spot:X,Y,Z:DX,DY,DZ:ANGLE_DEG:R,G,B`
    /// (cone half angle), `rect:X,Y,Z:DX,DY,DZ:UX,UY,UZ:HALF_X_DEG,HALF_Y_DEG:R,G,B` (a
    /// rectangular spot along D with vertical U), `dir:DX,DY,DZ:R,G,B` (W/m²). Default: the
    /// scene's lights.
    #[arg(long = "light")]
    lights: Vec<String>,
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
    /// The near field of archives of format 1.7 and later (the light the panes' VPL bound removes
    /// next to other surfaces, gathered each frame): `gather`, or `off` to play the panes alone
    /// (darker than they should be at edges, from 1.8 everywhere a little).
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
    /// Write per-pass GPU times and frame times as JSON (headless only; with a still light, add
    /// `--gi-update every-frame` to time the indirect light's passes on every frame).
    #[arg(long, value_name = "FILE.json")]
    timings: Option<PathBuf>,
    /// Shadow-map resolution per view.
    #[arg(long, default_value_t = 512)]
    shadow_resolution: u32,
    /// A directional light's shadow map is this many tiles on a side, each a view of
    /// --shadow-resolution² texels over the scene's bounding sphere (1 to 8)
    #[arg(long, default_value_t = prm_play::RuntimeOptions::DEFAULT_SUN_TILES)]
    sun_tiles: u32,
    /// Fade band: kept clusters scoring within (1 + band) × the first dropped cluster's score are
    /// faded by a smoothstep (0: hard cut).
    #[arg(long, default_value_t = 0.25, value_parser = non_negative, allow_negative_numbers = true)]
    fade_band: f32,
    /// Write static lightmaps for the first frame's lights into this directory and exit (no
    /// window): indirect.exr and irradiance.exr (direct + indirect, W/m² per lightmap texel) and
    /// scene.gltf + scene.bin with the lightmap UVs as TEXCOORD_1, for engines that take only
    /// baked lightmaps.
    #[arg(long, value_name = "DIR", conflicts_with_all = ["screenshot", "timings", "frames", "out", "probe_sphere"])]
    export: Option<PathBuf>,
    /// Exposure of the tone-mapped PNG (multiplies radiance before clamping and sRGB).
    #[arg(long, default_value_t = 1.0, value_parser = non_negative, allow_negative_numbers = true)]
    exposure: f32,
}

/// A finite number >= 0, for `--exposure` and `--fade-band`.
fn non_negative(s: &str) -> Result<f32, String> {
    match s.trim().parse::<f32>() {
        Ok(v) if v.is_finite() && v >= 0.0 => Ok(v),
        Ok(v) => Err(format!("{v} is not a finite number >= 0")),
        Err(e) => Err(format!("{s:?} is not a number: {e}")),
    }
}

/// Prints an error as `error: ` and its chain on one line, exit 1 (as `prm-bake` does), rather
/// than `main`'s default `Error: ` debug dump with a backtrace.
fn main() -> std::process::ExitCode {
    match run() {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            std::process::ExitCode::FAILURE
        }
    }
}

fn run() -> Result<()> {
    let mut args = Args::parse();
    if args.timings.is_some() && !args.headless {
        bail!("--timings needs --headless: a window records no timings");
    }
    if let Some(p) = args
        .screenshot
        .as_ref()
        .filter(|p| !p.extension().is_some_and(|e| e.eq_ignore_ascii_case("png")))
    {
        bail!(
            "--screenshot {}: the screenshot is a PNG; name it FILE.png",
            p.display()
        );
    }
    args.headless |= args.export.is_some();
    if args.headless {
        prm_gpu_kit::silence_wayland_probe();
    }
    let (width, height) = prm_scene::parse_size(&args.size)?;
    let (mut archive, scene) = prm_play::open(&args.archive, args.scene.as_deref())?;
    if let Some(w) = prm_play::materials_warning(&archive, &scene) {
        eprintln!("warning: {w}");
    }
    // Before any frame: no output may be the archive or the scene, nor lie below a file.
    let inputs = [args.archive.as_path(), scene.source.as_path()];
    for (flag, path) in [("--timings", &args.timings), ("--screenshot", &args.screenshot)] {
        if let Some(path) = path {
            check_output(flag, path, &inputs)?;
        }
    }
    if let Some(dir) = &args.export {
        if dir.exists() && !dir.is_dir() {
            bail!("--export {}: it exists and is not a directory", dir.display());
        }
        for name in prm_play::export::FILES {
            check_output("--export", &dir.join(name), &inputs)?;
        }
    }
    let top_k = args.top_k.unwrap_or_else(|| prm_play::archive_top_k(&archive));
    let base_camera = match &args.camera {
        Some(s) => prm_scene::parse_camera(s)?,
        None => prm_play::viewer_camera(&scene),
    };
    let base_lights = if args.lights.is_empty() {
        scene.lights.clone()
    } else {
        args.lights
            .iter()
            .map(|s| prm_scene::parse_light(s))
            .collect::<Result<Vec<_>, _>>()?
    };
    let animation = args.animation.as_deref().map(Animation::load).transpose()?;
    let emitter_infos: Vec<prm_runtime::EmitterInfo> = archive.emitters().iter().map(Into::into).collect();
    let emitter_scales = prm_play::emitter_scales(&emitter_infos, &args.emitters).map_err(anyhow::Error::msg)?;
    let sky = prm_play::sky(
        args.sky.as_deref(),
        args.sky_intensity,
        args.sky_rotation,
        archive.sky().is_some(),
    )
    .map_err(anyhow::Error::msg)?;
    if let Some(w) = sky.as_ref().and_then(prm_play::sky_ringing) {
        eprintln!("warning: {w}");
    }
    if sky.is_none() && animation.as_ref().is_some_and(|a| !a.sky.is_empty()) {
        bail!("the animation has sky keys, which animate a --sky: give one");
    }
    let lit_by_emitters = emitter_scales.iter().flatten().any(|&s| s > 0.0) || sky.is_some();
    let base_lights =
        if base_lights.is_empty() && !lit_by_emitters && animation.as_ref().is_none_or(|a| a.lights.is_empty()) {
            // A black frame helps nobody: light the scene, and say where and how to choose.
            let light = prm_play::default_light(&scene);
            eprintln!(
                "warning: the scene has no lights of its own and no --light was given; placing {} \
             (pass --light SPEC to choose, e.g. --light {}; in a window, arrows and PageUp/PageDown move it)",
                prm_play::describe_light(&light),
                prm_play::light_spec(&light)
            );
            vec![light]
        } else {
            base_lights
        };
    let runtime = RuntimeOptions {
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
    };
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
            camera: base_camera,
            lights: base_lights,
            animation,
            mode: args.mode,
            exposure: args.exposure,
            frames: args.frames,
            screenshot: args.screenshot,
            emitter_scales,
            sky,
            probe_sphere: args.probe_sphere,
        })
        .with_context(|| format!("playing {} in a window", args.archive.display()));
    }
    let ctx = prm_play::open_vulkan()?;
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
    let animated_emitters = animation.as_ref().is_some_and(|a| !a.emitters.is_empty());
    if let Some(a) = animation.as_ref().filter(|_| animated_emitters) {
        // Names checked before any frame.
        a.emitter_scales_at(&emitter_names, &emitter_scales, 0.0)
            .map_err(anyhow::Error::msg)
            .with_context(|| format!("in {}", args.animation.clone().unwrap_or_default().display()))?;
    }
    if !emitter_scales.is_empty() {
        renderer.set_emitter_scales(&emitter_scales)?;
    }
    if let Some(sky) = &sky {
        renderer.set_sky(sky)?;
    }
    if args.timings.is_some() && !renderer.has_timestamps() {
        eprintln!("note: this device has no timestamp queries; --timings records CPU frame times only");
    }
    if let Some(dir) = &args.export {
        let lights = match &animation {
            Some(a) if !a.lights.is_empty() => a.lights_at(a.time(0)),
            _ => base_lights.clone(),
        };
        let e = prm_play::export::export(&mut renderer, &scene, &lights, dir)
            .with_context(|| format!("exporting lightmaps to {}", dir.display()))?;
        for p in [&e.indirect, &e.irradiance, &e.gltf] {
            eprintln!("wrote {}", p.display());
        }
        return Ok(());
    }
    if args.out.exists() && !args.out.is_dir() {
        anyhow::bail!(
            "--out {}: it exists and is not a directory (--out names the directory the frames go to)",
            args.out.display()
        );
    }
    std::fs::create_dir_all(&args.out).with_context(|| format!("creating {}", args.out.display()))?;
    let mut frames = Vec::new();
    let frame_count = args.frames.unwrap_or(1);
    for i in 0..frame_count {
        let (camera, lights) = match &animation {
            Some(a) => {
                let t = a.time(i);
                let lights = if a.lights.is_empty() {
                    base_lights.clone()
                } else {
                    a.lights_at(t)
                };
                (a.camera_at(t).unwrap_or(base_camera), lights)
            }
            None => (base_camera, base_lights.clone()),
        };
        if let Some(a) = animation.as_ref().filter(|_| animated_emitters) {
            let scales = a
                .emitter_scales_at(&emitter_names, &emitter_scales, a.time(i))
                .map_err(anyhow::Error::msg)?;
            renderer.set_emitter_scales(&scales)?;
        }
        if let Some(s) = animation
            .as_ref()
            .zip(sky.as_ref())
            .and_then(|(a, s)| a.sky_state_at(s, a.time(i)))
        {
            renderer.set_sky(&s)?;
        }
        if args.probe_sphere {
            let t = animation.as_ref().map_or(i as f32 / 30.0, |a| a.time(i));
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
                    "rendering frame {i} at {width}x{height} with {} light(s), shadow maps of {}² texels \
                     (--shadow-resolution), a sun's in {}² tiles (--sun-tiles)",
                    lights.len(),
                    args.shadow_resolution,
                    args.sun_tiles
                )
            })?;
        let image = renderer.read_image()?;
        let bad = image.rgb.iter().filter(|p| !p.iter().all(|v| v.is_finite())).count();
        if bad > 0 {
            eprintln!(
                "warning: frame {i}: {bad} of {} pixels are not finite: a light's intensity or an \
                 emitter's scale is beyond what 32-bit floats hold",
                image.rgb.len()
            );
        }
        let stem = args.out.join(format!("frame{i:04}"));
        output::write_exr(&stem.with_extension("exr"), &image)?;
        output::write_png(&stem.with_extension("png"), &image, args.exposure)?;
        if let (Some(path), true) = (&args.screenshot, i + 1 == frame_count) {
            create_parent(path)?;
            output::write_png(path, &image, args.exposure)?;
        }
        eprintln!("frame {i}: {:.2} ms", t.cpu_ms);
        frames.push(t);
    }
    if let Some(path) = &args.timings {
        let json = serde_json::json!({
            "gpu_timestamps": renderer.has_timestamps(),
            "note": if renderer.has_timestamps() {
                "gpu_ms: per-pass GPU time from timestamp queries; cpu_ms: wall time from recording to GPU completion"
            } else {
                "no timestamp queries on this device: cpu_ms only (wall time from recording to GPU completion)"
            },
            "size": [width, height],
            "mode": format!("{:?}", args.mode).to_lowercase(),
            // The clusters blended: K, or every cluster when K is larger.
            "top_k": top_k.min(renderer.cluster_count()),
            "top_k_requested": top_k,
            "residual_groups": renderer.runtime().group_count(),
            "clusters": renderer.cluster_count(),
            "frames": frames.iter().map(|f| serde_json::json!({
                "cpu_ms": f.cpu_ms,
                "gpu_ms": f.gpu_ms.iter().map(|(k, v)| ((*k).to_string(), serde_json::json!(v))).collect::<serde_json::Map<_, _>>(),
            })).collect::<Vec<_>>(),
        });
        create_parent(path)?;
        std::fs::write(path, serde_json::to_string_pretty(&json)?)
            .with_context(|| format!("writing {}", path.display()))?;
    }
    Ok(())
}

/// Refuses an output `path` (of option `flag`) that names one of `inputs` (the archive, the
/// scene), is not a regular file, or lies below a file; a missing directory is created when
/// writing.
fn check_output(flag: &str, path: &Path, inputs: &[&Path]) -> Result<()> {
    if let Some(input) = inputs.iter().find(|i| prm_format::same_destination(i, path)) {
        bail!(
            "{flag} {}: it is {}, which the player reads; name another file",
            path.display(),
            input.display()
        );
    }
    prm_format::check_output_path(path).map_err(|why| anyhow::anyhow!("{flag} {}: {why}", path.display()))
}

/// Creates `path`'s missing directories.
fn create_parent(path: &Path) -> Result<()> {
    match path.parent().filter(|d| !d.as_os_str().is_empty()) {
        Some(dir) => std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display())),
        None => Ok(()),
    }
}
