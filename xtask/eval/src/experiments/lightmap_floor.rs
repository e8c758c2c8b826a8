//! Experiment: how much of an archive's error in an image is its lightmap's resolution, and how
//! much the method's.
//!
//! `cargo xtask eval experiment lightmap_floor SCENE ARCHIVE.prm LIGHT CAMERA REFERENCE.exr OUT`
//!
//! `LIGHT` and `CAMERA` as `prm-play` takes them; `REFERENCE.exr` the indirect-only reference
//! image at that light and camera (`prm-bake reference --indirect-only`, the size it has). The
//! experiment renders two images on the CPU player ([`prm_play::cpu`]) into `OUT`:
//! `played.exr`, the archive as `prm-play --backend cpu` plays it, and `exact.exr`, the
//! reference path tracer's indirect irradiance at every exit point of the same atlas (`SPP`
//! paths each, default 1024, seeded by `SEED`; gutter texels copied from their sources) seen
//! through the same bilinear lookup. `exact` against the reference is the floor any lightmap of this atlas
//! reaches at this view (with its own paths' noise and the reference's); `played` against
//! `exact` is the method's own error, the atlas's resolution left out. The exact map is the
//! mean of two halves of the paths (`exact-a.exr`, `exact-b.exr`): half their difference is its
//! own noise, which the last line removes from the method's error.

use anyhow::{Context, Result};
use glam::Vec3;
use prm_trace::{Bvh, BvhParams, Lighting, ReferenceParams, ReferenceTracer};
use std::path::Path;

use super::common::{archive_atlas, cpu_options, env_or};
use crate::compare::compare_files;

pub fn run(args: Vec<String>) -> Result<()> {
    let [scene_path, archive_path, light, camera, reference, out] = &args[..] else {
        anyhow::bail!("usage: lightmap_floor SCENE ARCHIVE.prm LIGHT CAMERA REFERENCE.exr OUT");
    };
    let (mut archive, scene) = prm_play::open(Path::new(archive_path), Some(Path::new(scene_path)))?;
    let lights = [prm_scene::parse_light(light)?];
    let camera = prm_scene::parse_camera(camera)?;
    let size = prm_play::output::read_exr(Path::new(reference))?;
    let (width, height) = (size.width, size.height);

    let atlas = archive_atlas(&scene, &archive).with_context(|| archive_path.clone())?;
    let bvh = Bvh::build(&scene, &BvhParams::DEFAULT)?;
    let tracer = ReferenceTracer::new(&scene, &bvh, Lighting::Lights(&lights));
    let side = atlas.resolution as usize;
    // Two halves of the paths with their own seeds: their difference is the exact map's noise.
    let halves: Vec<Vec<Vec3>> = (0..2u64)
        .map(|half| -> Result<Vec<Vec3>> {
            let paths = ReferenceParams {
                seed: 2 * u64::from(env_or("SEED", 0)) + half,
                ..ReferenceParams::with_spp(env_or("SPP", 1024) / 2)
            };
            let at_exits = tracer.indirect_at_exits(&atlas.exits, &paths, &mut |_, _| {})?;
            let mut texels = vec![Vec3::ZERO; side * side];
            for (x, v) in atlas.exits.iter().zip(&at_exits.mean) {
                texels[x.texel as usize] = *v;
            }
            for &(texel, source) in &atlas.dilation {
                texels[texel as usize] = texels[source as usize];
            }
            Ok(texels)
        })
        .collect::<Result<_>>()?;
    let texels: Vec<Vec3> = halves[0].iter().zip(&halves[1]).map(|(a, b)| (*a + *b) * 0.5).collect();

    let options = cpu_options(&archive, true, prm_trace::NEAR_GATHERS);
    let model = prm_play::cpu::CpuArchive::load(&mut archive, &scene, &options)?;
    let player = prm_play::cpu::CpuPlayer::new(&scene, &model, options)?;
    let input = prm_play::FrameInput {
        camera,
        lights: &lights,
        mode: prm_play::Mode::Indirect,
    };
    let lightmap = |texels| prm_play::cpu::Lightmap {
        texels,
        resolution: side,
        uvs: &atlas.uvs,
    };
    let out = Path::new(out);
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let path = |name: &str| out.join(format!("{name}.exr"));
    prm_play::output::write_exr(&path("played"), &player.render(&input, width, height))?;
    for (name, texels) in [("exact", &texels), ("exact-a", &halves[0]), ("exact-b", &halves[1])] {
        let image = player.render_with(&input, width, height, &lightmap(texels));
        prm_play::output::write_exr(&path(name), &image)?;
    }
    // The mean of two halves has half the difference's noise.
    let noise = compare_files(&path("exact-a"), &path("exact-b"))?;
    let (noise, noise_full) = (noise.error / 2.0, noise.error_full / 2.0);
    let without = |e: f64, n: f64| (e * e - n * n).max(0.0).sqrt();

    println!("4x4 error, full resolution, energy, shape (metrics.md)");
    let reference = Path::new(reference);
    let mut against_exact = None;
    for (what, test, against) in [
        ("played against the reference", path("played"), reference),
        ("exact lightmap against the reference", path("exact"), reference),
        ("played against the exact lightmap", path("played"), &path("exact")),
    ] {
        let m = compare_files(&test, against)?;
        println!(
            "  {what:<40} {:5.1}% {:5.1}% {:.3} {:5.1}%",
            100.0 * m.error,
            100.0 * m.error_full,
            m.energy,
            100.0 * m.shape
        );
        against_exact = Some(m);
    }
    let m = against_exact.expect("three comparisons");
    println!(
        "  the exact lightmap's own noise           {:5.1}% {:5.1}%\n  played against it, that noise removed    {:5.1}% {:5.1}%",
        100.0 * noise,
        100.0 * noise_full,
        100.0 * without(m.error, noise),
        100.0 * without(m.error_full, noise_full)
    );
    Ok(())
}
