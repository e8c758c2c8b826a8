//! Experiment: where a lamp's indirect light goes wrong, by distance from it.
//!
//! `cargo xtask eval experiment lamp_distance SCENE ARCHIVE.prm LIGHT`
//!
//! `LIGHT` a point light as `prm-play` takes it. Exit points of the archive's atlas are binned
//! by their distance from the light (at most 400 a bin, evenly spread over the atlas's order);
//! each bin prints, as shares of the reference's indirect light there (`SPP` paths per point,
//! default 1024): the reference's single-bounce part, and the archive's lightmap as the CPU
//! player plays it with the panes alone, with the near field's direct share added, and whole
//! (the deeper share's gathers and series too).

use anyhow::{bail, Context, Result};
use glam::Vec3;
use prm_scene::Light;
use prm_trace::{Bvh, BvhParams, Lighting, ReferenceParams, ReferenceTracer};
use std::path::Path;

use super::common::{archive_atlas, cpu_options, env_or};

/// Bin edges, metres from the light.
const BINS: [f32; 9] = [0.0, 1.0, 2.0, 3.0, 4.5, 6.0, 9.0, 13.0, f32::INFINITY];
/// Most exit points a bin.
const PER_BIN: usize = 400;

pub fn run(args: Vec<String>) -> Result<()> {
    let [scene_path, archive_path, light] = &args[..] else {
        bail!("usage: lamp_distance SCENE ARCHIVE.prm LIGHT");
    };
    let (mut archive, scene) = prm_play::open(Path::new(archive_path), Some(Path::new(scene_path)))?;
    let light = prm_scene::parse_light(light)?;
    let Light::Point { position: lamp, .. } = light else {
        bail!("lamp_distance takes a point light");
    };
    let lights = [light];
    let atlas = archive_atlas(&scene, &archive).with_context(|| archive_path.clone())?;
    // Panes alone; with the near field's direct share; whole.
    let mut played = Vec::new();
    for (near_field, near_bounces) in [(false, 0), (true, 0), (true, prm_trace::NEAR_GATHERS)] {
        let options = cpu_options(&archive, near_field, near_bounces);
        let model = prm_play::cpu::CpuArchive::load(&mut archive, &scene, &options)?;
        let player = prm_play::cpu::CpuPlayer::new(&scene, &model, options)?;
        played.push(player.indirect_lightmap(&lights));
    }
    let bins: Vec<Vec<usize>> = BINS
        .windows(2)
        .map(|w| {
            let inside: Vec<usize> = (0..atlas.exits.len())
                .filter(|&i| (w[0]..w[1]).contains(&atlas.exits[i].position.distance(lamp)))
                .collect();
            let step = (inside.len() / PER_BIN).max(1);
            inside.into_iter().step_by(step).take(PER_BIN).collect()
        })
        .collect();
    let exits: Vec<_> = bins.iter().flatten().map(|&i| atlas.exits[i]).collect();
    let bvh = Bvh::build(&scene, &BvhParams::DEFAULT)?;
    let tracer = ReferenceTracer::new(&scene, &bvh, Lighting::Lights(&lights));
    let paths = ReferenceParams::with_spp(env_or("SPP", 1024));
    let all = tracer.indirect_at_exits(&exits, &paths, &mut |_, _| {})?;
    let single = ReferenceParams {
        max_bounces: 1,
        ..paths
    };
    let once = tracer.indirect_at_exits(&exits, &single, &mut |_, _| {})?;

    let sum = |v: &mut dyn Iterator<Item = Vec3>| v.map(|x| f64::from(x.element_sum())).sum::<f64>();
    println!("metres   exits | single bounce | panes | + direct share | whole  (shares of the reference)");
    let mut start = 0;
    for (w, bin) in BINS.windows(2).zip(&bins) {
        let range = start..start + bin.len();
        start = range.end;
        let reference = sum(&mut all.mean[range.clone()].iter().copied());
        let share = |map: &[Vec3]| sum(&mut bin.iter().map(|&i| map[atlas.exits[i].texel as usize])) / reference;
        println!(
            "{:>4}–{:<4} {:5} | {:13.3} | {:5.3} | {:14.3} | {:5.3}",
            w[0],
            w[1],
            bin.len(),
            sum(&mut once.mean[range].iter().copied()) / reference,
            share(&played[0]),
            share(&played[1]),
            share(&played[2])
        );
    }
    Ok(())
}
