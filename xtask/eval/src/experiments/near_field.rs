//! Experiment: gathering back what the VPL disk bound removes, from the lightmap's own light.
//!
//! `cargo xtask eval experiment near_field SCENE ARCHIVE.prm FX FY FZ`
//!
//! A VPL of area `a` at distance `r` gives `1/(r² + a/π)` instead of `1/r²`: what is missing is,
//! in expectation over the VPLs, `∫ L(y) · R²/(r² + R²) cos θ dω` with `R² = a/π`, the near
//! field's radiance seen from the exit point. `L(y)` is what the run time knows at every texel:
//! `ρ/π` times the direct irradiance (carried by depth-0 VPLs of area `A/N`) and the played
//! indirect irradiance (carried by deeper VPLs of the archive's `indirect_disk`, or of area
//! `A/(N·M)` without one). This estimates it with
//! cosine rays from a sample of exit points and compares played, played + near field (the
//! direct part alone, both parts, both twice) and a whole final gather with the reference.
//! `RAYS` (default 256) sets the rays per exit point, `MINW` (default 1024) the cut-off weight
//! `1/MINW`, `POINTS` and `REFSPP` the sample and the reference's paths. The measurements are in
//! `prm_trace::near`; the bake ships both parts at 32 rays and `1/16`.

use glam::Vec3;

use super::common::{denoised_error, entry_energy};
use prm_scene::{Atlas, AtlasParams, Light, Sizing};
use prm_trace::check::check_exits;
use prm_trace::{cosine_hemisphere, Bvh, BvhParams, Lighting, ReferenceParams, ReferenceTracer, Rng};
use std::path::Path;

fn env_or(name: &str, default: u32) -> u32 {
    std::env::var(name).ok().map_or(default, |s| s.parse().unwrap())
}

pub fn run(args: Vec<String>) {
    let scene = prm_scene::load(Path::new(&args[0])).unwrap();
    let bvh = Bvh::build(&scene, &BvhParams::DEFAULT).unwrap();
    let archive = prm_format::Archive::open(Path::new(&args[1])).unwrap();
    let frac = Vec3::new(
        args[2].parse().unwrap(),
        args[3].parse().unwrap(),
        args[4].parse().unwrap(),
    );
    let res = archive.atlas().resolution;
    let atlas = Atlas::build(&scene, &AtlasParams::with_sizing(Sizing::Resolution(res))).unwrap();
    let params = archive.metadata().params.clone();
    let walks = params
        .get("paths_per_entry")
        .and_then(|v| v.as_u64())
        .unwrap_or_else(|| panic!("no paths_per_entry in {params:?}")) as f32;
    let clusters = archive.clusters().to_vec();
    let entries = archive.entries().to_vec();
    let entry_energy = entry_energy(&archive);
    let panes: Vec<Vec<[f32; 3]>> = (0..clusters.len()).map(|c| archive.read_pane(c).unwrap()).collect();
    let area: f32 = scene.triangles.iter().map(|t| t.area()).sum();
    let n = entries.len() as f32;
    let disk = prm_scene::ENTRY_DISK * area / (n * std::f32::consts::PI);
    let r0 = area / (n * std::f32::consts::PI);
    // The deeper VPLs' disk: the archive's `indirect_disk`, else the area one walk stands for.
    let r1 = match archive.near_field() {
        Some(n) if n.indirect_disk > 0.0 => r0 * n.indirect_disk / n.disk,
        _ => r0 / walks,
    };
    let b = scene.bounds();
    let light = Light::Point {
        position: b.min + frac * (b.max - b.min),
        intensity: Vec3::splat(b.diagonal() * b.diagonal()),
    };
    let lights = [light];
    // Played, K = all: every texel's indirect and direct irradiance.
    let weights = prm_trace::archive_weights(
        &bvh,
        &lights,
        &entries,
        &entry_energy,
        &clusters,
        disk,
        archive.entry_cells(),
    );
    let exits = &atlas.exits;
    let played: Vec<Vec3> = exits
        .iter()
        .map(|x| {
            weights
                .iter()
                .zip(&panes)
                .map(|(w, p)| *w * Vec3::from_array(p[x.texel as usize]))
                .sum()
        })
        .collect();
    let direct: Vec<Vec3> = exits
        .iter()
        .map(|x| prm_trace::direct_irradiance(&bvh, &lights, x.position, x.normal, x.normal, x.triangle))
        .collect();
    let texels = prm_trace::probes::HitTexels::new(&atlas);
    let exit_at = |tri: u32, b1: f32, b2: f32| texels.exit(tri, b1, b2);
    let rays = env_or("RAYS", 256);
    let minw = 1.0 / env_or("MINW", 1024) as f32;
    let tmax = (r0 * (1.0 / minw - 1.0)).sqrt();
    // The near field at every exit point: (direct part, indirect part).
    let near = |i: usize, ind: &[Vec3]| -> Vec3 {
        let x = &exits[i];
        let mut rng = Rng::new(5, i as u64, 0);
        let mut s = Vec3::ZERO;
        for _ in 0..rays {
            let d = cosine_hemisphere(rng.next_vec2(), x.normal);
            let Some(h) = bvh.closest_hit(x.position, d, tmax, x.triangle) else {
                continue;
            };
            if !h.front {
                continue;
            }
            let Some(y) = exit_at(h.triangle, h.b1, h.b2) else {
                continue;
            };
            let r2 = h.t * h.t;
            let y = y as usize;
            let w0 = r0 / (r2 + r0);
            if w0 < minw {
                continue;
            }
            let w1 = r1 / (r2 + r1);
            s += exits[y].albedo * (direct[y] * w0 + ind[y] * w1);
        }
        // (π/M) Σ ρ/π (…) = Σ ρ (…) / M
        s / rays as f32
    };
    // A whole final gather: every ray, unweighted, `fg` rays.
    let gather = |i: usize, ind: &[Vec3], fg: u32| -> Vec3 {
        let x = &exits[i];
        let mut rng = Rng::new(6, i as u64, 0);
        let mut s = Vec3::ZERO;
        for _ in 0..fg {
            let d = cosine_hemisphere(rng.next_vec2(), x.normal);
            let Some(h) = bvh.closest_hit(x.position, d, f32::INFINITY, x.triangle) else {
                continue;
            };
            if !h.front {
                continue;
            }
            let Some(y) = exit_at(h.triangle, h.b1, h.b2) else {
                continue;
            };
            let y = y as usize;
            s += exits[y].albedo * (direct[y] + ind[y]);
        }
        s / fg as f32
    };
    let all: Vec<usize> = (0..exits.len()).collect();
    let sample = check_exits(exits.len(), env_or("POINTS", 2048), 1);
    let sx: Vec<_> = sample.iter().map(|&i| exits[i]).collect();
    // Once with the played indirect, then once more over the compensated lightmap.
    let t0 = std::time::Instant::now();
    let comp1: Vec<Vec3> = {
        use rayon::prelude::*;
        all.par_iter().map(|&i| near(i, &played)).collect()
    };
    println!(
        "near field at {} exits, {rays} rays: {:.2} s",
        exits.len(),
        t0.elapsed().as_secs_f32()
    );
    let once: Vec<Vec3> = played.iter().zip(&comp1).map(|(p, c)| *p + *c).collect();
    let comp2: Vec<Vec3> = {
        use rayon::prelude::*;
        sample.par_iter().map(|&i| near(i, &once)).collect()
    };
    let tracer = ReferenceTracer::new(&scene, &bvh, Lighting::Lights(&lights));
    let refp = ReferenceParams {
        seed: 77,
        ..ReferenceParams::with_spp(env_or("REFSPP", 1024))
    };
    let r = tracer.indirect_at_exits(&sx, &refp, &mut |_, _| {}).unwrap();
    // Exit points near an edge: a cosine ray hits within 1.5 texels.
    let texel = (area / exits.len() as f32).sqrt();
    let edge: Vec<bool> = sample
        .iter()
        .map(|&i| {
            let x = &exits[i];
            let mut rng = Rng::new(9, i as u64, 0);
            (0..64).any(|_| {
                let d = cosine_hemisphere(rng.next_vec2(), x.normal);
                bvh.closest_hit(x.position, d, 1.5 * texel, x.triangle).is_some()
            })
        })
        .collect();
    let mut rows: Vec<(String, Vec<Vec3>)> = Vec::new();
    for fg in [16u32, 64, 256] {
        use rayon::prelude::*;
        let v: Vec<Vec3> = sample.par_iter().map(|&i| gather(i, &played, fg)).collect();
        rows.push((format!("final gather {fg} over played"), v));
        let v: Vec<Vec3> = sample.par_iter().map(|&i| gather(i, &once, fg)).collect();
        rows.push((format!("final gather {fg} over +near"), v));
    }
    let rows2: [(&str, Vec<Vec3>); 4] = [
        ("played (K = all)", sample.iter().map(|&i| played[i]).collect()),
        ("+ near field (direct only)", {
            let walks_off: Vec<Vec3> = vec![Vec3::ZERO; exits.len()];
            let c: Vec<Vec3> = {
                use rayon::prelude::*;
                sample.par_iter().map(|&i| near(i, &walks_off)).collect()
            };
            sample.iter().zip(c).map(|(&i, c)| played[i] + c).collect()
        }),
        ("+ near field", sample.iter().map(|&i| once[i]).collect()),
        (
            "+ near field, twice",
            sample.iter().zip(&comp2).map(|(&i, c)| played[i] + *c).collect(),
        ),
    ];
    println!(
        "R0 = {:.4}, R1 = {:.4}, texel {:.4}, {} of {} sampled exits near an edge",
        r0.sqrt(),
        r1.sqrt(),
        texel,
        edge.iter().filter(|e| **e).count(),
        sample.len()
    );
    rows.extend(rows2.into_iter().map(|(n, v)| (n.to_string(), v)));
    for (name, v) in &rows {
        let (err, en) = denoised_error(v, &r.mean, &r.variance, |_| true);
        let (ee, _) = denoised_error(v, &r.mean, &r.variance, |i| edge[i]);
        let (ei, _) = denoised_error(v, &r.mean, &r.variance, |i| !edge[i]);
        println!(
            "{name:<28} {:6.2}%  energy {en:.3}   at edges {:6.2}%  away {:6.2}%",
            100.0 * err,
            100.0 * ee,
            100.0 * ei
        );
    }
}
