//! `prm-bake reference`: ground-truth images and lightmaps from the reference path tracer.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, Result};
use glam::Vec3;
use prm_scene::{AtlasParams, Light, Sizing};
use prm_trace::{
    parse_camera, parse_light, parse_size, Bvh, BvhParams, Emitters, ImageMode, Lighting, ReferenceParams,
    ReferenceTracer,
};

/// Arguments of `prm-bake reference`.
#[derive(clap::Args, Debug, Clone)]
pub struct ReferenceArgs {
    /// Scene file (OBJ or glTF).
    pub scene: PathBuf,
    /// A light: `point:X,Y,Z:R,G,B` (W/sr), `spot:X,Y,Z:DX,DY,DZ:ANGLE_DEG:R,G,B` (W/sr inside
    /// the cone of that half angle), `rect:X,Y,Z:DX,DY,DZ:UX,UY,UZ:HALF_X_DEG,HALF_Y_DEG:R,G,B`
    /// (W/sr inside a rectangular frustum along D with vertical U, half angles about D × U and
    /// U) or `dir:DX,DY,DZ:R,G,B` (W/m² on a surface facing the light).
    /// Repeatable; defaults to the scene's own lights.
    #[arg(long = "light", value_name = "SPEC", value_parser = parse_light, allow_hyphen_values = true)]
    pub lights: Vec<Light>,
    /// Light the scene with its emissive surfaces too (OBJ `Ke`, glTF `emissiveFactor` ×
    /// `KHR_materials_emissive_strength`): area lights at their own radiance, one group per
    /// emissive material; the full image shows the emitters themselves. With it, the scene's
    /// punctual lights are used only if it has some or `--light` gives them.
    #[arg(long)]
    pub emitters: bool,
    /// Scale an emitter group (an emissive material): `NAME=S` or `NAME=R,G,B`, repeatable, `*`
    /// for every group; as `prm-play --emitter`, so that both render the same lighting. Needs
    /// `--emitters`.
    #[arg(long = "emitter", value_name = "NAME=SCALE", requires = "emitters")]
    pub emitter_scales: Vec<String>,
    /// Light the scene with a sky too, as `prm-play --sky`: `R,G,B` (uniform radiance) or an
    /// equirectangular `.hdr`/`.exr` map. Rays that leave the scene see it; the camera's stay
    /// black.
    #[arg(long, value_name = "R,G,B|FILE")]
    pub sky: Option<String>,
    /// Multiplies the sky's radiance, as `prm-play --sky-intensity`.
    #[arg(long, default_value_t = 1.0, requires = "sky")]
    pub sky_intensity: f32,
    /// Turns the sky about +Y, degrees, as `prm-play --sky-rotation`.
    #[arg(long, default_value_t = 0.0, requires = "sky", allow_negative_numbers = true)]
    pub sky_rotation: f32,
    /// Camera `EX,EY,EZ:TX,TY,TZ:FOV_DEG` (eye, target, vertical FOV; +Y up). Defaults to the
    /// scene's first camera.
    #[arg(long, value_name = "SPEC", conflicts_with = "lightmap", value_parser = parse_camera,
          allow_hyphen_values = true)]
    pub camera: Option<prm_scene::Camera>,
    /// Image size for the camera, `WxH`.
    #[arg(long, value_name = "WxH", default_value = "512x512", conflicts_with = "lightmap", value_parser = parse_size,
          allow_hyphen_values = true)]
    pub size: (u32, u32),
    /// Write the irradiance at the exit points of the scene's lightmap atlas instead of a camera
    /// image (atlas-sized image, texel (x, y) at row y; gutter texels copy their source).
    #[arg(long)]
    pub lightmap: bool,
    /// Atlas resolution for --lightmap (default: automatic, as `prm-bake atlas`).
    #[arg(long, value_name = "TEXELS", requires = "lightmap")]
    pub resolution: Option<u32>,
    /// Paths per pixel/texel in total (split into progressive passes).
    #[arg(long, default_value_t = 256, value_parser = clap::value_parser!(u32).range(1..))]
    pub spp: u32,
    /// Only the indirect part: radiance ρ/π·E_ind (camera) or irradiance E_ind (lightmap).
    #[arg(long)]
    pub indirect_only: bool,
    /// Seed of the path tracer.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Output EXR (linear radiance W/(m²·sr) for images, irradiance W/m² for lightmaps).
    #[arg(short, long, value_name = "FILE.exr")]
    pub output: PathBuf,
}

/// Largest image the reference renders: its mean and variance estimates take 24 bytes a pixel,
/// 1.5 GiB at this size, so a mistyped size fails at once instead of aborting on allocation.
const MAX_PIXELS: u64 = 8192 * 8192;

/// Runs `prm-bake reference`.
pub fn run(args: &ReferenceArgs) -> Result<()> {
    let start = Instant::now();
    // Refused before any tracing: an image named `.png` that holds an EXR misleads every viewer.
    let is_exr = args.output.extension().is_some_and(|e| e.eq_ignore_ascii_case("exr"));
    if !is_exr {
        crate::refuse!(
            "--output {}: the reference is written as OpenEXR (linear radiance); name it FILE.exr",
            args.output.display()
        );
    }
    // Also before any tracing: the output's directory (created if missing) and the file.
    check_output(&args.output)?;
    let scene = prm_scene::load(&args.scene).with_context(|| format!("cannot load scene {}", args.scene.display()))?;
    for w in &scene.report.warnings {
        eprintln!("warning: {w}");
    }
    let lights: Vec<Light> = if args.lights.is_empty() {
        scene.lights.clone()
    } else {
        args.lights.clone()
    };
    let emitters = if args.emitters {
        let e = Emitters::from_scene(&scene);
        let names: Vec<&str> = e.groups.iter().map(|g| g.name.as_str()).collect();
        let scales: Vec<glam::Vec3> = prm_scene::resolve_emitter_scales(&names, &args.emitter_scales)
            .map_err(anyhow::Error::msg)?
            .into_iter()
            .map(glam::Vec3::from)
            .collect();
        let unscaled = e.groups.len();
        let e = Emitters::with_scales(&scene, &scales)?;
        if unscaled == 0 {
            crate::refuse!(
                "--emitters: {} has no emissive material (OBJ Ke, glTF emissiveFactor)",
                args.scene.display()
            );
        }
        for g in &e.groups {
            eprintln!(
                "emitter group {:?}: {} triangles, {:.4} m², radiance {:.3} {:.3} {:.3}",
                g.name, g.triangles, g.area, g.radiance.x, g.radiance.y, g.radiance.z
            );
        }
        e
    } else {
        Emitters::default()
    };
    let sky = match &args.sky {
        None => None,
        Some(spec) => {
            if !(args.sky_intensity.is_finite() && args.sky_intensity >= 0.0 && args.sky_rotation.is_finite()) {
                crate::refuse!("--sky-intensity must be finite and ≥ 0 and --sky-rotation finite");
            }
            let mut sky = prm_scene::Sky::parse(spec).with_context(|| format!("bad --sky {spec:?}"))?;
            sky.intensity = args.sky_intensity;
            sky.rotation = args.sky_rotation.to_radians();
            Some(sky)
        }
    };
    if lights.is_empty() && emitters.is_empty() && sky.is_none() {
        let emissive = Emitters::from_scene(&scene).groups.len();
        crate::refuse!(
            "{} has no lights of its own; give at least one --light SPEC or a --sky{}",
            args.scene.display(),
            if emissive > 0 {
                format!(", or --emitters for its {emissive} emissive material(s)")
            } else {
                String::new()
            }
        );
    }
    let bvh = Bvh::build(&scene, &BvhParams::DEFAULT).context("cannot build the BVH")?;
    eprintln!(
        "{}: {} triangles, {} lights, BVH in {:.2?}",
        args.scene.display(),
        scene.triangles.len(),
        lights.len(),
        bvh.build_time()
    );
    let tracer = ReferenceTracer::new(&scene, &bvh, Lighting::Lights(&lights)).with_emitters(&emitters);
    let tracer = match &sky {
        Some(s) => tracer.with_sky(s),
        None => tracer,
    };
    let params = ReferenceParams {
        seed: args.seed,
        ..ReferenceParams::with_spp(args.spp)
    };
    let mut progress = |pass: u32, passes: u32| {
        eprintln!("pass {pass}/{passes} ({:.1?})", start.elapsed());
    };
    let (width, height, pixels) = if args.lightmap {
        trace_lightmap(args, &scene, &bvh, &tracer, &params, &mut progress)?
    } else {
        render_image(args, &scene, &tracer, &params, &mut progress)?
    };
    if let Some(dir) = args.output.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    let rgb: Vec<[f32; 3]> = pixels.iter().map(|v| v.to_array()).collect();
    prm_scene::write_exr_rgb(&args.output, width, height, &rgb)?;
    eprintln!(
        "wrote {} ({width}x{height}) in {:.1?}",
        args.output.display(),
        start.elapsed()
    );
    Ok(())
}

/// `--lightmap`: the irradiance at every exit point of the scene's atlas, gutters filled from
/// their sources; returns the image's size and texels.
fn trace_lightmap(
    args: &ReferenceArgs,
    scene: &prm_scene::Scene,
    bvh: &Bvh,
    tracer: &ReferenceTracer,
    params: &ReferenceParams,
    progress: &mut dyn FnMut(u32, u32),
) -> Result<(usize, usize, Vec<Vec3>)> {
    let sizing = match args.resolution {
        Some(r) => Sizing::Resolution(r),
        None => Sizing::Auto,
    };
    let atlas =
        prm_trace::bake_atlas(scene, bvh, &AtlasParams::with_sizing(sizing)).context("cannot build the atlas")?;
    eprintln!(
        "atlas {0}x{0}, {1} exit points; {2} passes x {3} paths",
        atlas.resolution,
        atlas.exits.len(),
        params.passes,
        params.samples_per_pass
    );
    let est = tracer
        .indirect_at_exits(&atlas.exits, params, progress)
        .context("reference tracing failed")?;
    let mut values = est.mean;
    if !args.indirect_only {
        for (v, d) in values.iter_mut().zip(tracer.direct_at_exits(&atlas.exits)) {
            *v += d;
        }
    }
    let r = atlas.resolution as usize;
    let mut img = vec![Vec3::ZERO; r * r];
    for (x, v) in atlas.exits.iter().zip(&values) {
        img[x.texel as usize] = *v;
    }
    for &(gutter, source) in &atlas.dilation {
        img[gutter as usize] = img[source as usize];
    }
    report_noise(&est.variance, &values, args.spp);
    Ok((r, r, img))
}

/// The camera image (`--camera`, else the scene's first camera); returns its size and pixels.
fn render_image(
    args: &ReferenceArgs,
    scene: &prm_scene::Scene,
    tracer: &ReferenceTracer,
    params: &ReferenceParams,
    progress: &mut dyn FnMut(u32, u32),
) -> Result<(usize, usize, Vec<Vec3>)> {
    let camera = match args.camera {
        Some(c) => c,
        None => match scene.cameras.first() {
            Some(c) => *c,
            None => crate::refuse!("{} has no camera; give --camera SPEC", args.scene.display()),
        },
    };
    let (w, h) = args.size;
    if w as u64 * h as u64 > MAX_PIXELS {
        crate::refuse!(
            "--size {w}x{h} is {} pixels; the reference tracer renders at most {MAX_PIXELS} \
             (8192x8192): it keeps a mean and a variance per pixel",
            w as u64 * h as u64
        );
    }
    let mode = if args.indirect_only {
        ImageMode::IndirectOnly
    } else {
        ImageMode::Full
    };
    eprintln!(
        "image {w}x{h}; {} passes x {} paths",
        params.passes, params.samples_per_pass
    );
    let est = tracer
        .render(&camera, w, h, mode, params, progress)
        .context("reference rendering failed")?;
    report_noise(&est.variance, &est.mean, args.spp);
    Ok((w as usize, h as usize, est.mean))
}

/// Refuses an output that cannot be written, before the long work: an existing directory or
/// other non-file, or a path below a file. Missing directories are created when writing.
fn check_output(output: &std::path::Path) -> Result<()> {
    prm_scene::check_output_path(output)
        .map_err(|why| anyhow::Error::new(crate::Refused(format!("--output {}: {why}", output.display()))))
}

/// Prints the RMS standard error relative to the mean value.
fn report_noise(variance: &[Vec3], mean: &[Vec3], spp: u32) {
    let n = mean.len().max(1) as f64;
    let m = mean.iter().map(|v| v.element_sum() as f64).sum::<f64>() / n;
    let s = (variance.iter().map(|v| v.element_sum() as f64).sum::<f64>() / n).sqrt();
    if m > 0.0 && spp < 2 {
        eprintln!("mean value {m:.5} (channel sum); one sample per pixel gives no standard error (--spp 2 or more)");
    } else if m > 0.0 {
        eprintln!(
            "mean value {:.5} (channel sum), RMS standard error {:.2}% of it",
            m,
            100.0 * s / m
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// What the long render cannot write is refused before it: a directory, a path below a
    /// file; a missing directory is created when writing, so it passes.
    #[test]
    fn unwritable_outputs_are_refused_before_rendering() {
        let dir = std::env::temp_dir().join(format!("prm-bake-reference-output-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(dir.join("sub")).unwrap();
        std::fs::write(dir.join("file"), b"x").unwrap();
        let err = check_output(&dir.join("sub")).unwrap_err().to_string();
        assert!(err.contains("not a regular file"), "{err}");
        let err = check_output(&dir.join("file/a/b.exr")).unwrap_err().to_string();
        assert!(err.contains("file is a regular file, not a directory"), "{err}");
        check_output(&dir.join("new/deeper/ref.exr")).unwrap();
        check_output(&dir.join("ref.exr")).unwrap();
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
