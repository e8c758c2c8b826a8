//! Experiment: what the run time's top-K should do with the clusters it drops.
//!
//! `cargo xtask eval experiment residual_panes SCENE ARCHIVE.prm [K] [GROUPS]`
//!
//! The archive's panes (as stored) are blended on the CPU at a random sample of exit points
//! (`POINTS`, 2048) for the bake check's test lights, with ray-cast, disk-bounded entry
//! irradiance and energy weights as the player computes them, and compared with the reference
//! (`REFSPP` paths, 256; its noise removed from both sums as `prm_trace::check` does) for:
//! - `top-K`: the run time's selection (`select_top_k`: the K highest scores kept, faded, and
//!   scaled up by the dropped clusters' score), K from the archive or the command line;
//! - `top-(K+G)`: the same with G more panes, the cost of the next two;
//! - `K + 1 residual`: the top K faded but not scaled; what the others (and the fade) leave out,
//!   `Σ w_c ⊙ e_c` per channel, carried by one extra pane, the sum of all panes, scaled to that
//!   energy;
//! - `K + G residuals`: the same per group of clusters (the run time's groups,
//!   `prm_format::residual_groups`), each group's residual carried by the sum of its own panes;
//! - `all`: every cluster, the target.
//!
//! Measured on default bakes (release `prm-bake bake SCENE`, seed 0): chairs (240 clusters,
//! K = 32, G = 4) top-K 23.7%, top-36 22.3%, 32 + 1 residual 15.2%, 32 + 4 residuals 12.3%, all
//! 10.4% (energy 0.95–0.96 throughout); the bundled Cornell box (64 clusters) 14.3%, 13.6%,
//! 14.1%, 13.6%, 13.2%; CornellBox-Sphere 12.8%, 12.0%, 12.1%, 11.9%, 11.0%. This chose the
//! run time's residual groups (`prm_format::residual_groups`, 4 by default).

use glam::Vec3;

use super::common::{denoised_error, entry_energy, env_or};
use prm_scene::{Atlas, AtlasParams, Light, Sizing};
use prm_trace::check::{check_exits, check_lights, select_top_k, select_with_residuals, FADE_BAND};
use prm_trace::{Bvh, BvhParams, Lighting, ReferenceParams, ReferenceTracer};
use std::path::Path;

pub fn run(args: Vec<String>) {
    let scene_path = Path::new(&args[0]);
    let archive_path = Path::new(&args[1]);
    let scene = prm_scene::load(scene_path).unwrap();
    let bvh = Bvh::build(&scene, &BvhParams::DEFAULT).unwrap();
    let archive = prm_format::Archive::open(archive_path).unwrap();
    let k: usize = args.get(2).map_or_else(
        || archive.metadata().params["top_k"].as_u64().unwrap() as usize,
        |s| s.parse().unwrap(),
    );
    let groups: usize = args.get(3).map_or(16, |s| s.parse().unwrap());
    let res = archive.atlas().resolution;
    let atlas = Atlas::build(&scene, &AtlasParams::with_sizing(Sizing::Resolution(res))).unwrap();
    let sample = check_exits(atlas.exits.len(), env_or("POINTS", 2048), 1);
    let exits: Vec<_> = sample.iter().map(|&i| atlas.exits[i]).collect();
    let clusters = archive.clusters().to_vec();
    let entries = archive.entries().to_vec();
    let entry_energy = entry_energy(&archive);
    let energy: Vec<Vec3> = clusters.iter().map(|c| Vec3::from_array(c.energy)).collect();
    let panes: Vec<Vec<Vec3>> = (0..clusters.len())
        .map(|c| {
            let p = archive.read_pane(c).unwrap();
            exits.iter().map(|x| Vec3::from_array(p[x.texel as usize])).collect()
        })
        .collect();
    let sizes: &[usize] = if groups > 1 { &[1, groups] } else { &[1] };
    let group_sets: Vec<(usize, Vec<u32>)> = sizes
        .iter()
        .map(|&g| {
            let of = prm_format::residual_groups(&clusters, g as u32);
            (g, of)
        })
        .collect();
    let area: f32 = scene.triangles.iter().map(|t| t.area()).sum();
    let disk = prm_scene::ENTRY_DISK * area / (entries.len() as f32 * std::f32::consts::PI);
    let d = scene.bounds().diagonal();
    let refspp = env_or("REFSPP", 256);
    println!(
        "{}: {} clusters, K = {k}, {groups} groups, {} points, {refspp} paths",
        scene_path.display(),
        clusters.len(),
        exits.len()
    );
    let blend = |w: &[Vec3], extra: &[(Vec3, &Vec<Vec3>)]| -> Vec<Vec3> {
        let mut out = vec![Vec3::ZERO; exits.len()];
        for (wc, p) in w.iter().zip(&panes) {
            if *wc != Vec3::ZERO {
                for (o, v) in out.iter_mut().zip(p) {
                    *o += *wc * *v;
                }
            }
        }
        for (a, p) in extra {
            for (o, v) in out.iter_mut().zip(p.iter()) {
                *o += *a * *v;
            }
        }
        out
    };
    let mut totals: Vec<(String, f64, f64)> = Vec::new();
    let test_lights = check_lights(&scene, &bvh);
    for (li, &position) in test_lights.iter().enumerate() {
        let light = Light::Point {
            position,
            intensity: Vec3::splat(d * d),
        };
        let lights = [light];
        let tracer = ReferenceTracer::new(&scene, &bvh, Lighting::Lights(&lights));
        let reference = ReferenceParams {
            seed: 77 + li as u64,
            ..ReferenceParams::with_spp(refspp)
        };
        let r = tracer.indirect_at_exits(&exits, &reference, &mut |_, _| {}).unwrap();
        let weights = prm_trace::archive_weights(
            &bvh,
            &lights,
            &entries,
            &entry_energy,
            &clusters,
            disk,
            archive.entry_cells(),
        );
        let mut rows: Vec<(String, Vec<Vec3>)> = vec![
            (
                format!("top-{k}"),
                blend(&select_top_k(&weights, &energy, k, FADE_BAND), &[]),
            ),
            (
                format!("top-{}", k + groups),
                blend(&select_top_k(&weights, &energy, k + groups, FADE_BAND), &[]),
            ),
        ];
        for (g, of) in &group_sets {
            let mut sums = vec![vec![Vec3::ZERO; exits.len()]; *g];
            let mut genergy = vec![Vec3::ZERO; *g];
            for (c, p) in panes.iter().enumerate() {
                genergy[of[c] as usize] += energy[c];
                for (s, v) in sums[of[c] as usize].iter_mut().zip(p) {
                    *s += *v;
                }
            }
            let (kept, alpha) = select_with_residuals(&weights, &energy, k, FADE_BAND, of, &genergy);
            let extra: Vec<(Vec3, &Vec<Vec3>)> = alpha.iter().copied().zip(sums.iter()).collect();
            rows.push((format!("{k} + {g} residual"), blend(&kept, &extra)));
        }
        rows.push(("all".into(), blend(&weights, &[])));
        println!("light {li} at {position:.3}:");
        for (name, v) in &rows {
            let (err, en) = denoised_error(v, &r.mean, &r.variance, |_| true);
            println!("  {name:<20} {:6.2}%  energy {en:.3}", 100.0 * err);
            match totals.iter_mut().find(|t| &t.0 == name) {
                Some(t) => {
                    t.1 += err;
                    t.2 += en;
                }
                None => totals.push((name.clone(), err, en)),
            }
        }
    }
    let n = test_lights.len() as f64;
    println!("mean over the lights:");
    for (name, err, en) in totals {
        println!("  {name:<20} {:6.2}%  energy {:.3}", 100.0 * err / n, en / n);
    }
}
