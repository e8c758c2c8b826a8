//! Experiment: what the bake's check weighs against what an image weighs.
//!
//! `cargo xtask eval experiment check_weights SCENE ARCHIVE.prm LIGHT CAMERA WxH`
//!
//! The check (`prm_trace::check`) compares the played indirect irradiance with the reference at
//! exit points drawn by surface area; an image weighs surfaces by the pixels they cover
//! and shows outgoing radiance. This plays the archive's lightmap on the CPU player, traces the
//! reference at `POINTS` exit points (default 2048) drawn evenly over the texels (`SPP` paths
//! each, default 1024), and gives the noise-corrected error under each weighting: even (the
//! draw's), albedo² (radiance), the area each texel stands for (the check's), the camera's pixels (in its frustum, seen, `cos θ / d²` over
//! `cos³` of the angle off its axis), and `VIEWS` (default 32) random viewpoints clear of every
//! surface by the check's clearance (`cos θ / d²` summed where seen). The last table splits the
//! even and the camera's squared error and squared reference by distance from the light.

use anyhow::{bail, Context, Result};
use glam::Vec3;
use prm_scene::{Camera, ExitPoint, Light};
use prm_trace::{Bvh, BvhParams, Lighting, ReferenceParams, ReferenceTracer};
use rayon::prelude::*;
use std::path::Path;

use super::common::{archive_atlas, cpu_options, denoised_error, env_or};

/// Bin edges, metres from the light.
const BINS: [f32; 7] = [0.0, 1.0, 2.0, 4.0, 8.0, 16.0, f32::INFINITY];

pub fn run(args: Vec<String>) -> Result<()> {
    let [scene_path, archive_path, light, camera, size] = &args[..] else {
        bail!("usage: check_weights SCENE ARCHIVE.prm LIGHT CAMERA WxH");
    };
    let (mut archive, scene) = prm_play::open(Path::new(archive_path), Some(Path::new(scene_path)))?;
    let light = prm_scene::parse_light(light)?;
    let Light::Point { position: lamp, .. } = light else {
        bail!("check_weights takes a point light");
    };
    let camera = match camera.as_str() {
        "-" => prm_play::default_camera(&scene),
        c => prm_scene::parse_camera(c)?,
    };
    let (w, h) = size.split_once('x').context("size as WxH")?;
    let aspect = w.parse::<f32>()? / h.parse::<f32>()?;
    let lights = [light];
    let mut atlas = archive_atlas(&scene, &archive).with_context(|| archive_path.clone())?;
    let options = cpu_options(&archive, true, prm_trace::NEAR_GATHERS);
    let model = prm_play::cpu::CpuArchive::load(&mut archive, &scene, &options)?;
    let player = prm_play::cpu::CpuPlayer::new(&scene, &model, options)?;
    let played_map = player.indirect_lightmap(&lights);
    let bvh = Bvh::build(&scene, &BvhParams::DEFAULT)?;
    // The check's exit points: the buried ones moved out, as the bake moves them.
    prm_trace::unbury_exits(&scene, &bvh, &mut atlas);
    let checked = prm_trace::check_exits(atlas.exits.len(), env_or("POINTS", 2048), u64::from(env_or("SEED", 0)));
    let exits: Vec<ExitPoint> = checked.iter().map(|&i| atlas.exits[i]).collect();
    let tracer = ReferenceTracer::new(&scene, &bvh, Lighting::Lights(&lights));
    let paths = ReferenceParams::with_spp(env_or("SPP", 1024));
    let r = tracer.indirect_at_exits(&exits, &paths, &mut |_, _| {})?;
    let played: Vec<Vec3> = exits.iter().map(|e| played_map[e.texel as usize]).collect();

    let even = vec![1.0f32; exits.len()];
    let albedo: Vec<f32> = exits.iter().map(|e| e.albedo.length_squared() / 3.0).collect();
    let seen = camera_weights(&bvh, &camera, aspect, &exits);
    let exit_areas = atlas.exit_areas(&scene);
    let area: Vec<f32> = checked.iter().map(|&i| exit_areas[i]).collect();
    let views = viewpoints(&scene, &bvh, env_or("VIEWS", 32));
    let viewed = viewpoint_weights(&bvh, &views, &exits);
    let error = |wt: &[f32], only: &dyn Fn(usize) -> bool| {
        let s = |v: &[Vec3], p: f32| -> Vec<Vec3> { v.iter().zip(wt).map(|(x, w)| *x * w.powf(p)).collect() };
        denoised_error(&s(&played, 0.5), &s(&r.mean, 0.5), &s(&r.variance, 1.0), only)
    };
    let all = |_: usize| true;
    println!(
        "{} exit points, {} seen by the camera, {} viewpoints",
        exits.len(),
        seen.iter().filter(|&&x| x > 0.0).count(),
        views.len()
    );
    for (name, wt) in [
        ("even", &even),
        ("albedo²", &albedo),
        ("texel area (the check)", &area),
        ("camera", &seen),
        ("viewpoints", &viewed),
    ] {
        let (e, energy) = error(wt, &all);
        println!("{name:18} error {:6.2}%  energy {energy:.3}", 100.0 * e);
    }
    let radiance_view: Vec<f32> = viewed.iter().zip(&albedo).map(|(a, b)| a * b).collect();
    let (e, energy) = error(&radiance_view, &all);
    println!(
        "{:18} error {:6.2}%  energy {energy:.3}",
        "viewpoints·albedo²",
        100.0 * e
    );
    by_distance(&exits, lamp, &played, &r.mean, &even, &seen);
    patches(
        &atlas,
        &checked,
        &tracer,
        &played_map,
        &[("camera", &seen), ("viewpoints", &viewed), ("texel area", &area)],
    )?;
    Ok(())
}

/// The even and the camera's error over 3×3-texel patches around the checked exit points (the
/// exit points among a texel's eight neighbours that face its way and lie within two texels of
/// it), the reference traced at every one of them.
fn patches(
    atlas: &prm_scene::Atlas,
    checked: &[usize],
    tracer: &ReferenceTracer,
    played_map: &[Vec3],
    weighings: &[(&str, &[f32])],
) -> Result<()> {
    let side = atlas.resolution as i64;
    let mut at = vec![u32::MAX; (side * side) as usize];
    for (k, e) in atlas.exits.iter().enumerate() {
        at[e.texel as usize] = k as u32;
    }
    let step = |e: &ExitPoint| {
        let (x, y) = (i64::from(e.texel) % side, i64::from(e.texel) / side);
        let mut near = Vec::new();
        for (dx, dy) in [(-1, 0), (1, 0), (0, -1), (0, 1)] {
            let (u, v) = (x + dx, y + dy);
            if (0..side).contains(&u) && (0..side).contains(&v) && at[(v * side + u) as usize] != u32::MAX {
                near.push(
                    atlas.exits[at[(v * side + u) as usize] as usize]
                        .position
                        .distance(e.position),
                );
            }
        }
        near.into_iter().fold(f32::INFINITY, f32::min)
    };
    let mut steps: Vec<f32> = checked
        .iter()
        .map(|&i| step(&atlas.exits[i]))
        .filter(|s| s.is_finite())
        .collect();
    steps.sort_by(f32::total_cmp);
    let texel = steps[steps.len() / 2];
    let groups: Vec<Vec<usize>> = checked
        .iter()
        .map(|&i| {
            let e = &atlas.exits[i];
            let (x, y) = (i64::from(e.texel) % side, i64::from(e.texel) / side);
            let mut g = vec![i];
            for dy in -1..=1 {
                for dx in -1..=1 {
                    let (u, v) = (x + dx, y + dy);
                    if (dx, dy) == (0, 0) || !(0..side).contains(&u) || !(0..side).contains(&v) {
                        continue;
                    }
                    let k = at[(v * side + u) as usize];
                    if k == u32::MAX {
                        continue;
                    }
                    let n = &atlas.exits[k as usize];
                    if n.normal.dot(e.normal) > 0.9 && n.position.distance(e.position) < 3.0 * texel {
                        g.push(k as usize);
                    }
                }
            }
            g
        })
        .collect();
    let all: Vec<ExitPoint> = groups.iter().flatten().map(|&k| atlas.exits[k]).collect();
    let paths = ReferenceParams::with_spp(env_or("PATCH_SPP", 256));
    let r = tracer.indirect_at_exits(&all, &paths, &mut |_, _| {})?;
    let (mut p, mut m, mut v) = (Vec::new(), Vec::new(), Vec::new());
    let mut start = 0;
    for g in &groups {
        let n = g.len() as f32;
        p.push(
            g.iter()
                .map(|&k| played_map[atlas.exits[k].texel as usize])
                .sum::<Vec3>()
                / n,
        );
        m.push(r.mean[start..start + g.len()].iter().sum::<Vec3>() / n);
        v.push(r.variance[start..start + g.len()].iter().sum::<Vec3>() / (n * n));
        start += g.len();
    }
    let mean_size = all.len() as f64 / groups.len() as f64;
    let (e, energy) = denoised_error(&p, &m, &v, |_| true);
    println!(
        "3×3 patches (texel {texel:.3}, {mean_size:.1} exit points each): even error {:6.2}%  energy {energy:.3}",
        100.0 * e
    );
    for (name, seen) in weighings {
        let sq = |x: &[Vec3], pw: f32| -> Vec<Vec3> { x.iter().zip(*seen).map(|(a, w)| *a * w.powf(pw)).collect() };
        let (e, _) = denoised_error(&sq(&p, 0.5), &sq(&m, 0.5), &sq(&v, 1.0), |_| true);
        println!("3×3 patches, {name}: error {:6.2}%", 100.0 * e);
    }
    Ok(())
}

/// Each exit point's share of the camera's pixels: in its frustum, facing it and unoccluded,
/// `cos θ / d²` over `cos³` of the angle off its axis.
fn camera_weights(bvh: &Bvh, camera: &Camera, aspect: f32, exits: &[ExitPoint]) -> Vec<f32> {
    let forward = (camera.target - camera.eye).normalize();
    let right = forward.cross(Vec3::Y).normalize();
    let up = right.cross(forward);
    let t = (camera.fov_y_deg.to_radians() / 2.0).tan();
    exits
        .par_iter()
        .map(|e| {
            let d = e.position - camera.eye;
            let dist = d.length();
            let z = d.dot(forward);
            if z <= 0.0 || (d.dot(up) / z).abs() > t || (d.dot(right) / z).abs() > t * aspect {
                return 0.0;
            }
            seen_from(bvh, camera.eye, e).map_or(0.0, |c| c / (dist * dist) / (z / dist).powi(3))
        })
        .collect()
}

/// `cos θ` at `e` towards `eye` when `e` faces it unoccluded.
fn seen_from(bvh: &Bvh, eye: Vec3, e: &ExitPoint) -> Option<f32> {
    let d = e.position - eye;
    let dist = d.length();
    let cos = -d.dot(e.normal) / dist;
    (cos > 0.0 && !bvh.occluded(eye, d / dist, dist * (1.0 - 1e-3), [u32::MAX, e.triangle])).then_some(cos)
}

/// Up to `count` seeded random points in the scene's bounds, outside geometry and clear of
/// every surface by the check's clearance.
fn viewpoints(scene: &prm_scene::Scene, bvh: &Bvh, count: u32) -> Vec<Vec3> {
    let b = scene.bounds();
    let clearance = prm_trace::check::CLEARANCE * b.diagonal();
    let mut out = Vec::new();
    let mut state = 0x9e3779b97f4a7c15u64;
    let mut next = || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 40) as f32 / (1u64 << 24) as f32
    };
    for _ in 0..100 * count {
        if out.len() as u32 == count {
            break;
        }
        let p = b.min + (b.max - b.min) * Vec3::new(next(), next(), next());
        let clear = (0..64).all(|i| {
            let z = 1.0 - (2 * i + 1) as f32 / 64.0;
            let phi = i as f32 * 2.399_963;
            let s = (1.0 - z * z).sqrt();
            let d = Vec3::new(s * phi.cos(), z, s * phi.sin());
            bvh.closest_hit(p, d, clearance, u32::MAX).is_none()
        });
        if clear && !prm_trace::probes::is_inside(bvh, p) {
            out.push(p);
        }
    }
    out
}

/// Each exit point's `Σ cos θ / d²` over the viewpoints that see it.
fn viewpoint_weights(bvh: &Bvh, views: &[Vec3], exits: &[ExitPoint]) -> Vec<f32> {
    exits
        .par_iter()
        .map(|e| {
            views
                .iter()
                .filter_map(|&v| seen_from(bvh, v, e).map(|c| c / v.distance_squared(e.position)))
                .sum()
        })
        .collect()
}

/// Shares of the squared error and the squared reference by distance from the lamp, evenly
/// and as the camera weighs them.
fn by_distance(exits: &[ExitPoint], lamp: Vec3, played: &[Vec3], reference: &[Vec3], even: &[f32], seen: &[f32]) {
    println!("metres    | even: points, err² share, ref² share | camera: err² share, ref² share");
    let share = |wt: &[f32], f: &dyn Fn(usize) -> f64, bin: &dyn Fn(usize) -> bool| {
        let total: f64 = (0..exits.len()).map(|i| f64::from(wt[i]) * f(i)).sum();
        (0..exits.len())
            .filter(|&i| bin(i))
            .map(|i| f64::from(wt[i]) * f(i))
            .sum::<f64>()
            / total.max(1e-30)
    };
    let err = |i: usize| f64::from((played[i] - reference[i]).length_squared());
    let refn = |i: usize| f64::from(reference[i].length_squared());
    for w in BINS.windows(2) {
        let bin = |i: usize| (w[0]..w[1]).contains(&exits[i].position.distance(lamp));
        let n = (0..exits.len()).filter(|&i| bin(i)).count();
        println!(
            "{:>4}–{:<4} | {n:5} {:6.3} {:6.3} | {:6.3} {:6.3}",
            w[0],
            w[1],
            share(even, &err, &bin),
            share(even, &refn, &bin),
            share(seen, &err, &bin),
            share(seen, &refn, &bin)
        );
    }
}
