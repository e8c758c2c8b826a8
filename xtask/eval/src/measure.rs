//! Plays an archive with `prm_play::Renderer`: frame time at 1024×768 and the errors against the references.

use anyhow::{bail, Context, Result};
use glam::Vec3;
use prm_play::{FrameInput, Mode, PlayOptions, Renderer};
use prm_scene::{Camera, Light};

use super::reference::Reference;

/// Frame time is measured at this size (the README's reference frame).
pub const FRAME_SIZE: (u32, u32) = (1024, 768);

/// Error metrics of one frame against its references.
#[derive(Clone, Copy, Debug, Default)]
pub struct Errors {
    /// ‖PRM − ref‖₂ / ‖ref‖₂ of the indirect irradiance over the covered texels (RGB).
    pub lightmap: f64,
    /// The reference's own noise on the same scale: √(Σ variance) / ‖ref‖₂.
    pub lightmap_noise: f64,
    /// Same for the indirect-only image (radiance).
    pub image: f64,
    pub image_noise: f64,
    /// Mean FLIP (LDR, nv-flip) of the final tone-mapped image against the reference.
    pub flip: f64,
}

/// The references of one light, and what the frame compares against.
pub struct LightRefs<'a> {
    pub light: Light,
    pub lightmap: &'a Reference,
    /// Texel index of every exit point (the lightmap reference is per exit point).
    pub texels: &'a [u32],
    pub image_indirect: &'a Reference,
    pub image_direct: &'a Reference,
}

/// ‖a − b‖ / ‖b‖ and √(Σ var)/‖b‖ over paired values.
fn rel_rmse(pairs: impl Iterator<Item = (Vec3, Vec3, Vec3)>) -> (f64, f64) {
    let (mut d2, mut r2, mut v) = (0.0f64, 0.0f64, 0.0f64);
    for (a, b, var) in pairs {
        d2 += (a - b).length_squared() as f64;
        r2 += b.length_squared() as f64;
        v += (var.x + var.y + var.z) as f64;
    }
    if r2 <= 0.0 {
        return (f64::NAN, f64::NAN);
    }
    ((d2 / r2).sqrt(), (v / r2).sqrt())
}

fn srgb8(x: f32) -> u8 {
    let x = x.clamp(0.0, 1.0);
    let s = if x <= 0.003_130_8 {
        12.92 * x
    } else {
        1.055 * x.powf(1.0 / 2.4) - 0.055
    };
    (s * 255.0 + 0.5) as u8
}

/// Exposure that maps the reference's 99th-percentile luminance to 1 (images differ a lot in scale).
fn exposure(reference: &[Vec3]) -> f32 {
    let mut l: Vec<f32> = reference
        .iter()
        .map(|c| 0.2126 * c.x + 0.7152 * c.y + 0.0722 * c.z)
        .filter(|l| *l > 0.0)
        .collect();
    if l.is_empty() {
        return 1.0;
    }
    let i = ((l.len() - 1) as f32 * 0.99) as usize;
    let (_, p, _) = l.select_nth_unstable_by(i, |a, b| a.total_cmp(b));
    1.0 / p.max(1e-12)
}

fn tone_map(rgb: &[Vec3], e: f32) -> Vec<u8> {
    rgb.iter()
        .flat_map(|c| [srgb8(c.x * e), srgb8(c.y * e), srgb8(c.z * e)])
        .collect()
}

/// Mean LDR-FLIP of `test` against `reference` (both linear radiance), tone-mapped alike.
pub fn flip(reference: &[Vec3], test: &[Vec3], size: (u32, u32)) -> f64 {
    let e = exposure(reference);
    let r = nv_flip::FlipImageRgb8::with_data(size.0, size.1, &tone_map(reference, e));
    let t = nv_flip::FlipImageRgb8::with_data(size.0, size.1, &tone_map(test, e));
    let map = nv_flip::flip(r, t, nv_flip::DEFAULT_PIXELS_PER_DEGREE);
    nv_flip::FlipPool::from_image(&map).mean() as f64
}

fn to_vec3(v: &[[f32; 3]]) -> Vec<Vec3> {
    v.iter().map(|c| Vec3::from_array(*c)).collect()
}

/// Median CPU-observed frame time (ms) of `frames` `gi` frames at [`FRAME_SIZE`] after one warm-up.
pub fn frame_time(r: &mut Renderer, camera: Camera, lights: &[Light], frames: usize) -> Result<f64> {
    r.resize(FRAME_SIZE.0, FRAME_SIZE.1);
    let input = FrameInput {
        camera,
        lights,
        mode: Mode::Gi,
    };
    r.render(&input)?;
    let mut t = Vec::with_capacity(frames);
    for _ in 0..frames {
        t.push(r.render(&input)?.cpu_ms);
    }
    t.sort_by(f64::total_cmp);
    Ok(t[t.len() / 2])
}

/// The errors of one light's frame at `size` (lightmap, indirect image, final image).
pub fn errors(r: &mut Renderer, camera: Camera, size: (u32, u32), refs: &LightRefs) -> Result<Errors> {
    r.resize(size.0, size.1);
    let lights = [refs.light];
    r.render(&FrameInput {
        camera,
        lights: &lights,
        mode: Mode::Gi,
    })?;
    let full = to_vec3(&r.read_image()?.rgb);
    let lightmap = r.read_lightmap()?;
    r.render(&FrameInput {
        camera,
        lights: &lights,
        mode: Mode::Indirect,
    })?;
    let indirect = to_vec3(&r.read_image()?.rgb);
    let n = (size.0 * size.1) as usize;
    if full.len() != n || indirect.len() != n || refs.image_indirect.mean.len() != n {
        bail!("image sizes differ from {}x{}", size.0, size.1);
    }
    if refs.texels.len() != refs.lightmap.mean.len() {
        bail!("the lightmap reference does not match the atlas");
    }
    let (lm, lm_noise) = rel_rmse(refs.texels.iter().enumerate().map(|(i, &t)| {
        (
            Vec3::from_array(lightmap[t as usize]),
            refs.lightmap.mean[i],
            refs.lightmap.variance[i],
        )
    }));
    let (img, img_noise) = rel_rmse(
        indirect
            .iter()
            .zip(&refs.image_indirect.mean)
            .zip(&refs.image_indirect.variance)
            .map(|((a, b), v)| (*a, *b, *v)),
    );
    let reference_full: Vec<Vec3> = refs
        .image_indirect
        .mean
        .iter()
        .zip(&refs.image_direct.mean)
        .map(|(i, d)| *i + *d)
        .collect();
    let f = flip(&reference_full, &full, size);
    Ok(Errors {
        lightmap: lm,
        lightmap_noise: lm_noise,
        image: img,
        image_noise: img_noise,
        flip: f,
    })
}

/// Opens a renderer for `archive` on a fresh Vulkan device, its emitters (if any) at scale 0.
pub fn renderer(
    archive: &std::path::Path,
    scene_path: &std::path::Path,
    top_k: u32,
) -> Result<(Renderer, prm_scene::Scene)> {
    let runtime = prm_play::RuntimeOptions {
        top_k,
        ..Default::default()
    };
    renderer_with(archive, scene_path, runtime)
}

/// Every frame the eval times computes the indirect light again, as a frame whose lights move
/// does, whatever else `options` asks.
fn every_frame(options: prm_play::RuntimeOptions) -> prm_play::RuntimeOptions {
    prm_play::RuntimeOptions {
        gi_update: prm_play::GiUpdate::EveryFrame,
        ..options
    }
}

/// [`renderer`] with these run-time options.
pub fn renderer_with(
    archive: &std::path::Path,
    scene_path: &std::path::Path,
    runtime: prm_play::RuntimeOptions,
) -> Result<(Renderer, prm_scene::Scene)> {
    let (mut a, scene) =
        prm_play::open(archive, Some(scene_path)).with_context(|| format!("opening {}", archive.display()))?;
    let ctx = prm_play::open_vulkan().context("opening a Vulkan device (lavapipe is enough)")?;
    let opts = PlayOptions {
        width: FRAME_SIZE.0,
        height: FRAME_SIZE.1,
        runtime: every_frame(runtime),
        ..PlayOptions::default()
    };
    let mut r = Renderer::new(ctx, &scene, &mut a, opts).context("creating the renderer")?;
    // Lit by the lights alone, as every reference the eval compares with is: an archive of a
    // scene with emissive materials (McGuire's boxes) plays its emitters at scale 1 by default,
    // which added the lamp's light to CornellBox-Sphere's played side only (energy 1.11).
    let off = vec![[0.0; 3]; r.runtime().emitters().len()];
    r.set_emitter_scales(&off).context("turning the emitters off")?;
    Ok((r, scene))
}

/// What a baked light's change costs a frame, on one renderer of `archive` (`frames` timed after
/// two warm-up frames each, at the scene's default camera, one shadow-mapped point light):
/// mean frame ms with `change(renderer, frame)` applied before every frame, mean frame ms with
/// the point light moving every frame instead, and the mean ms of `change` alone. The two series
/// run twice, interleaved (moved, changed, moved, changed), so that neither gains from going
/// second on a warmed-up device.
pub fn change_costs(
    archive: &std::path::Path,
    scene_path: &std::path::Path,
    frames: usize,
    change: &mut dyn FnMut(&mut Renderer, usize),
) -> Result<(f64, f64, f64)> {
    let (mut r, scene) = renderer(archive, scene_path, 32)?;
    let camera = prm_play::default_camera(&scene);
    let b = scene.bounds();
    let light_at = |i: usize| Light::Point {
        position: b.min + b.extent() * Vec3::new(0.2 + 0.6 * (i % 7) as f32 / 6.0, 0.7, 0.5),
        intensity: Vec3::splat(0.05 * b.diagonal() * b.diagonal()),
    };
    let time = |r: &mut Renderer, f: &mut dyn FnMut(&mut Renderer, usize) -> Vec<Light>| -> Result<f64> {
        let mut total = 0.0;
        for i in 0..frames + 2 {
            let t = std::time::Instant::now();
            let lights = f(r, i);
            r.render(&FrameInput {
                camera,
                lights: &lights,
                mode: Mode::Gi,
            })?;
            if i >= 2 {
                total += t.elapsed().as_secs_f64();
            }
        }
        Ok(total * 1e3 / frames as f64)
    };
    let (mut alone, mut changed, mut moved) = (0.0, 0.0, 0.0);
    for _ in 0..2 {
        moved += time(&mut r, &mut |_, i| vec![light_at(i)])? / 2.0;
        changed += time(&mut r, &mut |r, i| {
            let t = std::time::Instant::now();
            change(r, i);
            if i >= 2 {
                alone += t.elapsed().as_secs_f64();
            }
            vec![light_at(0)]
        })? / 2.0;
    }
    Ok((changed, moved, alone * 1e3 / (2 * frames) as f64))
}
