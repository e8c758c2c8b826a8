//! `cargo xtask eval --probes`: the irradiance probes against the reference tracer at the probe
//! positions (the target: within 10%), at default bake settings and beside a larger
//! bake, and what the probes cost the bake and a frame.
//!
//! Each case is baked with `prm-bake bake SCENE --probes` (the default 512-cell budget), played
//! for one frame with one point light (or, for the courtyard, a uniform sky and no light, and
//! for McGuire's CornellBox-Original its own lamp and no light; their references then add the
//! sky's or the lamp's direct light) in-process (`prm_play::Renderer`, the run time's probes
//! pass), and each probe's irradiance is taken at the six axis normals from its coefficients
//! (negative values clamped, as `probe_volume.wgsl` does). The reference is
//! `prm_trace::ReferenceTracer::indirect_at_points` at the same points and normals, twice with
//! different seeds for its own noise. Error = ‖t − r‖/‖r‖ over every probe, normal and channel;
//! energy = Σt/Σr; shape = the error after the best global scale (metrics.md's split). The
//! panes' column is of a second bake with `--probe-rays 0`, the probes played through the panes.

use anyhow::{Context, Result};
use glam::Vec3;
use std::fmt::Write as _;
use std::path::Path;

use crate::plan::{self, SceneSpec};
use prm_play::{FrameInput, Mode};
use prm_scene::Light;
use prm_trace::{Bvh, BvhParams, Lighting, ReferenceParams, ReferenceTracer};

/// Reference paths per probe and normal: its noise stays under a fifth of the errors measured.
const SPP: u32 = 16384;
/// Frames timed with and without the probes pass.
const FRAMES: usize = 24;

fn rel(t: &[Vec3], r: &[Vec3]) -> f64 {
    let num: f64 = t.iter().zip(r).map(|(a, b)| (*a - *b).length_squared() as f64).sum();
    let den: f64 = r.iter().map(|b| b.length_squared() as f64).sum();
    (num / den).sqrt()
}

fn sum(v: &[Vec3]) -> f64 {
    v.iter().map(|x| x.element_sum() as f64).sum()
}

/// How a case is lit.
#[derive(Clone, Copy)]
enum Lit {
    /// One point light at this fraction of the bounds.
    Point([f32; 3]),
    /// A uniform blue sky, no light (the reference adds the sky's direct light, which the
    /// probes hold).
    Sky,
    /// The scene's own emissive surfaces at scale 1, no light (the reference adds their direct
    /// light, which the probes hold).
    Lamps,
}

/// A case: name, scene (from the repository's root), extra bake arguments, lighting.
type Case = (&'static str, &'static str, &'static [&'static str], Lit);

/// Rays per probe the cases bake with: the bake's default (`prm_bake::PROBE_RAYS`, which this
/// package does not link), given explicitly so that the bakes' cache keys name it.
const PROBE_RAYS: &str = "1024";

/// Runs the probe cases; returns the Markdown table.
pub fn run(bake_bin: &Path, cache: &Path, root: &Path) -> Result<String> {
    let cases: [Case; 5] = [
        (
            "Cornell box, default bake",
            "scenes/cornell-box/cornell-box.obj",
            &[],
            Lit::Point([0.36, 0.82, 0.54]),
        ),
        (
            "Cornell box, 8192 entries, 256 clusters",
            "scenes/cornell-box/cornell-box.obj",
            &["--entries", "8192", "--clusters", "256"],
            Lit::Point([0.36, 0.82, 0.54]),
        ),
        (
            "two rooms, default bake",
            "scenes/two-rooms/two-rooms.obj",
            &[],
            Lit::Point([0.25, 0.8, 0.5]),
        ),
        (
            "CornellBox-Original, default bake, its own lamp",
            "../shared/scenes/cornell-box/CornellBox-Original.obj",
            &[],
            Lit::Lamps,
        ),
        (
            "courtyard, default bake --sky, blue sky",
            "scenes/courtyard/courtyard.obj",
            &["--sky"],
            Lit::Sky,
        ),
    ];
    let mut md = String::from(
        "| case | probes | error along the rays | energy | shape | error through the panes (energy) | reference noise | probes bake s | frame ms: with probes / without |\n| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |\n",
    );
    for (name, scene_rel, extra, lit) in cases {
        let scene_path = root.join(scene_rel);
        if !scene_path.exists() {
            println!("probes: {name}: skipped, {} is not there", scene_path.display());
            continue;
        }
        let spec = SceneSpec::new(
            &name.replace([' ', ','], "-"),
            scene_path.clone(),
            vec![],
            Default::default(),
            64,
        );
        let args: Vec<String> = ["--probes", "--probe-rays", PROBE_RAYS]
            .into_iter()
            .chain(extra.iter().copied())
            .map(String::from)
            .collect();
        let plain_args: Vec<String> = extra.iter().map(|a| a.to_string()).collect();
        let baked = plan::bake(bake_bin, cache, &spec, &args, None, false)?;
        let probe_s = baked.report["timings"]["probes"].as_f64().unwrap_or(f64::NAN);
        let archive = prm_format::Archive::open(&baked.archive)
            .with_context(|| format!("opening {}", baked.archive.display()))?;
        let probes = archive.probes().context("the bake placed no probes")?.clone();
        let (mut r, scene) = crate::measure::renderer(&baked.archive, &scene_path, 32)?;
        let b = scene.bounds();
        let lights: Vec<Light> = match lit {
            Lit::Point(f) => vec![Light::Point {
                position: b.min + b.extent() * Vec3::from(f),
                intensity: Vec3::splat(0.8 * b.diagonal() * b.diagonal()),
            }],
            Lit::Sky | Lit::Lamps => Vec::new(),
        };
        let sky = matches!(lit, Lit::Sky).then(|| prm_scene::Sky::uniform(Vec3::new(0.4, 0.6, 1.0)));
        // `measure::renderer` turns the emitters off; the lamp case turns them on again.
        let lamps = vec![[1.0f32; 3]; r.runtime().emitters().len()];
        let light_up = |r: &mut prm_play::Renderer| -> Result<()> {
            if let Some(s) = &sky {
                r.set_sky(s)?;
            }
            if matches!(lit, Lit::Lamps) {
                r.set_emitter_scales(&lamps)?;
            }
            Ok(())
        };
        light_up(&mut r)?;
        let camera = prm_play::default_camera(&scene);
        let input = FrameInput {
            camera,
            lights: &lights,
            mode: Mode::Gi,
        };
        let read = |r: &prm_play::Renderer| -> Result<Vec<Vec3>> {
            Ok(prm_trace::probes::axis_irradiance(&r.runtime().read_probes()?))
        };
        r.render(&input)?;
        let played = read(&r)?;
        // The probes lit through the panes, without probe rays: the bake a user makes for
        // that, `--probe-rays 0` (whose plan keeps the smaller VPL disks), at the same probes.
        let panes_args: Vec<String> = ["--probes", "--probe-rays", "0"]
            .into_iter()
            .chain(extra.iter().copied())
            .map(String::from)
            .collect();
        let panes_baked = plan::bake(bake_bin, cache, &spec, &panes_args, None, false)?;
        let panes_probes = prm_format::Archive::open(&panes_baked.archive)
            .with_context(|| format!("opening {}", panes_baked.archive.display()))?
            .probes()
            .map(|p| p.positions.clone());
        anyhow::ensure!(
            panes_probes.as_ref() == Some(&probes.positions),
            "{name}: the --probe-rays 0 bake placed other probes"
        );
        let panes_played = {
            let options = prm_play::RuntimeOptions {
                top_k: 32,
                probe_light: prm_play::ProbeLight::Panes,
                ..Default::default()
            };
            let (mut p, _) = crate::measure::renderer_with(&panes_baked.archive, &scene_path, options)?;
            light_up(&mut p)?;
            p.render(&input)?;
            read(&p)?
        };
        let rays = r.runtime().probes_gather_rays();
        // Frame cost: the same bake without probes (the same archive but for the section),
        // timed alternately with this one.
        let plain = plan::bake(bake_bin, cache, &spec, &plain_args, None, false)?;
        let (mut without, _) = crate::measure::renderer(&plain.archive, &scene_path, 32)?;
        light_up(&mut without)?;
        let (mut with_ms, mut without_ms) = (0.0, 0.0);
        for _ in 0..2 {
            for (renderer, total) in [(&mut r, &mut with_ms), (&mut without, &mut without_ms)] {
                for i in 0..FRAMES / 2 + 2 {
                    let t = std::time::Instant::now();
                    renderer.render(&input)?;
                    if i >= 2 {
                        *total += t.elapsed().as_secs_f64();
                    }
                }
            }
        }
        let per_frame = |total: f64| total * 1e3 / FRAMES as f64;
        let (with_ms, without_ms) = (per_frame(with_ms), per_frame(without_ms));

        let bvh = Bvh::build(&scene, &BvhParams::DEFAULT)?;
        let points = prm_trace::probes::axis_points(&probes.positions);
        let emitters = prm_trace::Emitters::from_scene(&scene);
        let mut tracer = ReferenceTracer::new(&scene, &bvh, Lighting::Lights(&lights));
        if let Some(s) = &sky {
            tracer = tracer.with_sky(s);
        }
        if matches!(lit, Lit::Lamps) {
            tracer = tracer.with_emitters(&emitters);
        }
        // With a sky or lamps the probes hold their direct light too.
        let direct = match lit {
            Lit::Sky => tracer.sky_direct_at_points(&points, SPP),
            Lit::Lamps => emitters.direct_at_points(&scene, &bvh, &points, SPP, 47),
            Lit::Point(_) => vec![Vec3::ZERO; points.len()],
        };
        let reference = |seed| -> Result<Vec<Vec3>> {
            let params = ReferenceParams {
                seed,
                ..ReferenceParams::with_spp(SPP)
            };
            let indirect = tracer.indirect_at_points(&points, &params, &mut |_, _| {})?.mean;
            Ok(indirect.iter().zip(&direct).map(|(i, d)| *i + *d).collect())
        };
        let (r1, r2) = (reference(41)?, reference(43)?);
        let error = rel(&played, &r1);
        let energy = sum(&played) / sum(&r1);
        let panes_error = rel(&panes_played, &r1);
        let panes_energy = sum(&panes_played) / sum(&r1);
        let dot: f64 = played.iter().zip(&r1).map(|(a, b)| a.dot(*b) as f64).sum();
        let tt: f64 = played.iter().map(|a| a.length_squared() as f64).sum();
        let scale = (dot / tt.max(1e-30)) as f32;
        let scaled: Vec<Vec3> = played.iter().map(|a| *a * scale).collect();
        let shape = rel(&scaled, &r1);
        let noise = rel(&r2, &r1) / 2f64.sqrt();
        anyhow::ensure!(rays, "{name}: the bake traced no probe rays");
        println!(
            "probes: {name}: {} probes, along the rays error {:.2}%, energy {energy:.3}, shape {:.2}%; through the panes {:.2}% ({panes_energy:.3}); reference noise {:.2}%",
            probes.len(),
            100.0 * error,
            100.0 * shape,
            100.0 * panes_error,
            100.0 * noise
        );
        writeln!(
            md,
            "| {name} | {} | **{:.1}%** | {energy:.3} | {:.1}% | {:.1}% ({panes_energy:.3}) | {:.1}% | {probe_s:.2} | {with_ms:.1} / {without_ms:.1} |",
            probes.len(),
            100.0 * error,
            100.0 * shape,
            100.0 * panes_error,
            100.0 * noise
        )?;
    }
    Ok(md)
}
