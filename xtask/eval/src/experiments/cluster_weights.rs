//! Experiment: how a cluster's run-time weight should combine its members' entry irradiance.
//!
//! `cargo xtask eval experiment cluster_weights [SCENE] [ENTRIES] [CLUSTERS] [RES]`
//!
//! Everything on the CPU with exact visibility, so only the representation differs: per-entry
//! panes `P_i` (the identity clustering), their sums per k-means cluster `P_c = Σ_{i∈c} P_i`,
//! and for each light the indirect irradiance at the exit points as
//! - `unclustered`: `Σ_i E_i P_i`, the target of any compression of the panes;
//! - `mean`: `Σ_c mean_{i∈c}(E_i) P_c`, the paper's (and the player's) cluster weight;
//! - `energy`: `Σ_c (Σ_{i∈c} E_i e_i / Σ_{i∈c} e_i) P_c` with `e_i = Σ_x P_i(x)` per channel,
//!   which gives every cluster exactly the indirect energy its members would give unclustered;
//! - `lsq`: `P_i ≈ α_i P_c / |c|` with the least-squares `α_i`, weight `Σ α_i E_i / |c|`,
//!
//! - `region`: the entry irradiance replaced by the direct light integrated over each entry's
//!   own cell (the area samples nearest to it on its own plane), unclustered and by energy;
//! - `filter K`: the result filtered over each exit's `(2K+1)²` atlas neighbours on its own
//!   chart and plane (geometry-only weights, so the same as filtering every pane),
//!
//! each against the reference path tracer (relative RMSE over exits, and energy ratio).
//!
//! Knobs (environment): `WALKS` (walks per entry, 8), `BOUND` (`none` or the VPL disk scale),
//! `REFSPP` (reference paths per exit, 1024), `AREA` (area samples of the region weights);
//! `DIAG=1` splits the unclustered error by the distance to the nearest edge of the geometry;
//! `CORRECT=1` compensates the VPL disk bound per exit (first-bounce and deeper VPLs divided by
//! their own `1 − D(x)`, `D` the expected share the bound removes under uniform radiance, from
//! `RAYS` cosine rays), `SINGLE=1` with one factor mixed by the first bounce's energy share.
//! Measured on the bundled Cornell box (128², 1024 entries, 8 walks, `REFSPP=4096`, reference
//! noise 2.4–3.5%), light under the ceiling / near the red wall / low in a corner:
//! unclustered 9.9% / 11.8% / 22.2% (energy 0.955 / 0.955 / 0.889), with 74% / 82% / 63% of
//! the squared error at exits within 1.5 texels of an edge (error there 20–34%, energy
//! 0.78–0.90; 4–5% away from edges); `CORRECT=1`: 9.3% / 10.1% / 16.6% (energy 0.987 / 0.990 /
//! 0.933), the edge energy restored (1.00–1.02 for the first two) but not the edge error
//! (18–19%); `SINGLE=1`: 9.8% / 10.7% / 17.7%.

use glam::Vec3;
use prm_scene::{Atlas, AtlasParams, Light, Sizing};
use prm_trace::{
    Bvh, BvhParams, Clustering, EntryParams, Lighting, PaneParams, ReferenceParams, ReferenceTracer, WalkParams,
};

use super::common::{env_or, rel_rmse};

pub fn run(args: Vec<String>) {
    let scene_path = args
        .first()
        .cloned()
        .unwrap_or_else(|| concat!(env!("CARGO_MANIFEST_DIR"), "/../../scenes/cornell-box/cornell-box.obj").into());
    let n_entries: usize = args.get(1).map_or(1024, |s| s.parse().unwrap());
    let n_clusters: usize = args.get(2).map_or(64, |s| s.parse().unwrap());
    let res: u32 = args.get(3).map_or(128, |s| s.parse().unwrap());
    let scene = prm_scene::load(std::path::Path::new(&scene_path)).unwrap();
    let atlas = Atlas::build(&scene, &AtlasParams::with_sizing(Sizing::Resolution(res))).unwrap();
    let bvh = Bvh::build(&scene, &BvhParams::DEFAULT).unwrap();
    let entries = prm_trace::sample_surface(
        &scene,
        &EntryParams {
            count: n_entries,
            seed: 1,
        },
    )
    .unwrap();
    let walks = WalkParams {
        walks_per_entry: env_or("WALKS", 8),
        seed: 1,
        ..WalkParams::PREVIEW
    };
    let vpls = prm_trace::trace_walks(&scene, &bvh, &entries, &walks).unwrap();
    let pane_params = match std::env::var("BOUND").ok().as_deref() {
        Some("none") => PaneParams {
            bound: prm_trace::VplBound::None,
        },
        Some(s) => PaneParams {
            bound: prm_trace::VplBound::Disk {
                scale: s.parse().unwrap(),
            },
        },
        None => PaneParams::DEFAULT,
    };
    let t = std::time::Instant::now();
    let identity = Clustering::identity(&entries);
    let mut per_entry = prm_trace::evaluate_panes(&bvh, &vpls, &identity, &atlas.exits, &pane_params).unwrap();
    if std::env::var_os("CORRECT").is_some() {
        // Bound compensation: under uniform radiance the disk bound keeps `1 − D(x)` of an exit
        // point's irradiance, `D(x) = E_cos[R² / (t² + R²)]` over cosine-distributed rays that hit
        // at distance t; the panes of first-bounce VPLs (R² = A/(Nπ)) and of deeper ones
        // (A/(NMπ)) are divided by their own `1 − D`.
        let scale2 = match pane_params.bound {
            prm_trace::VplBound::Disk { scale } => scale * scale,
            _ => 0.0,
        };
        let split = |keep: &dyn Fn(&prm_trace::Vpl) -> bool| {
            let mut set = prm_trace::VplSet {
                vpls: Vec::new(),
                offsets: vec![0],
                stats: vpls.stats,
            };
            for k in 0..vpls.entries() {
                set.vpls
                    .extend(vpls.vpls[vpls.range(k)].iter().filter(|v| keep(v)).copied());
                set.offsets.push(set.vpls.len() as u32);
            }
            prm_trace::evaluate_panes(&bvh, &set, &identity, &atlas.exits, &pane_params).unwrap()
        };
        let first = split(&|v| v.depth == 0);
        let deeper = split(&|v| v.depth > 0);
        let mean_area = |d0: bool| {
            let a: Vec<f32> = vpls
                .vpls
                .iter()
                .filter(|v| (v.depth == 0) == d0)
                .map(|v| v.area)
                .collect();
            a.iter().sum::<f32>() / a.len().max(1) as f32
        };
        let (r0, r1) = (
            scale2 * mean_area(true) * std::f32::consts::FRAC_1_PI,
            scale2 * mean_area(false) * std::f32::consts::FRAC_1_PI,
        );
        let rays: u32 = env_or("RAYS", 256);
        let lost: Vec<(f32, f32)> = {
            use rayon::prelude::*;
            atlas
                .exits
                .par_iter()
                .map(|x| {
                    let ng = bvh.geometric_normal(x.triangle);
                    let (mut d0, mut d1) = (0.0f32, 0.0f32);
                    for i in 0..rays {
                        let dir = prm_trace::cosine_hemisphere(prm_trace::sobol2(i, x.texel), x.normal);
                        let o = bvh.spawn(x.position, ng, dir);
                        if let Some(h) = bvh.closest_hit(o, dir, f32::INFINITY, x.triangle) {
                            let t2 = h.t * h.t;
                            d0 += r0 / (t2 + r0);
                            d1 += r1 / (t2 + r1);
                        }
                    }
                    (d0 / rays as f32, d1 / rays as f32)
                })
                .collect()
        };
        let m = atlas.exits.len();
        let total = |p: &prm_trace::Panes| p.data.iter().map(|v| v.element_sum() as f64).sum::<f64>();
        let f0 = (total(&first) / (total(&first) + total(&deeper))) as f32;
        let single = std::env::var_os("SINGLE").is_some();
        eprintln!("first-bounce share of the pane energy {f0:.3}; single factor: {single}");
        for k in 0..per_entry.clusters {
            for (i, (d0, d1)) in lost.iter().enumerate() {
                per_entry.data[k * m + i] = if single {
                    (first.data[k * m + i] + deeper.data[k * m + i]) / (1.0 - f0 * d0 - (1.0 - f0) * d1).max(0.25)
                } else {
                    first.data[k * m + i] / (1.0 - d0).max(0.25) + deeper.data[k * m + i] / (1.0 - d1).max(0.25)
                };
            }
        }
        let mean: f32 = lost.iter().map(|l| l.0).sum::<f32>() / m as f32;
        eprintln!("bound compensation: R0² {r0:.2e}, R1² {r1:.2e}, mean D0 {mean:.4}");
    }
    eprintln!(
        "{} entries, {} VPLs, {} exits: per-entry panes in {:.1} s",
        entries.len(),
        vpls.vpls.len(),
        atlas.exits.len(),
        t.elapsed().as_secs_f64()
    );
    let clustering = Clustering::kmeans_separated(&entries, &bvh, scene.bounds().diagonal(), n_clusters, 1).unwrap();
    let m = atlas.exits.len();
    let energy: Vec<Vec3> = (0..entries.len()).map(|i| per_entry.pane(i).iter().sum()).collect();
    let mut cluster_pane = vec![vec![Vec3::ZERO; m]; clustering.len()];
    for (c, members) in clustering.members.iter().enumerate() {
        for &k in members {
            for (acc, v) in cluster_pane[c].iter_mut().zip(per_entry.pane(k as usize)) {
                *acc += *v;
            }
        }
    }
    // Least-squares scale of each member against its cluster's mean shape (luminance).
    let lum = |v: Vec3| v.dot(Vec3::new(0.2126, 0.7152, 0.0722)) as f64;
    let alpha: Vec<f64> = (0..entries.len())
        .map(|k| {
            let c = clustering.of_entry[k] as usize;
            let size = clustering.members[c].len() as f64;
            let (mut num, mut den) = (0.0, 0.0);
            for (p, q) in per_entry.pane(k).iter().zip(&cluster_pane[c]) {
                let q = lum(*q) / size;
                num += lum(*p) * q;
                den += q * q;
            }
            num / den.max(1e-30)
        })
        .collect();

    // Area samples for the region weights, each given to the nearest entry on its own plane.
    let n_area: usize = std::env::var("AREA").ok().map_or(262_144, |s| s.parse().unwrap());
    let area = prm_trace::sample_surface(&scene, &EntryParams { count: n_area, seed: 7 }).unwrap();
    let cell: Vec<u32> = {
        use rayon::prelude::*;
        let eps = 1e-3 * scene.bounds().diagonal();
        area.par_iter()
            .map(|s| {
                let mut best = (f32::INFINITY, 0u32);
                let mut any = (f32::INFINITY, 0u32);
                for (i, e) in entries.iter().enumerate() {
                    let d = (e.position - s.position).length_squared();
                    if d < any.0 {
                        any = (d, i as u32);
                    }
                    if d < best.0 && e.normal.dot(s.normal) > 0.99 && e.normal.dot(s.position - e.position).abs() < eps
                    {
                        best = (d, i as u32);
                    }
                }
                if best.0.is_finite() {
                    best.1
                } else {
                    any.1
                }
            })
            .collect()
    };
    let diag = std::env::var_os("DIAG").is_some();
    // Only for DIAG: every exit against every other.
    let edge_distance: Vec<f32> = if !diag {
        Vec::new()
    } else {
        use rayon::prelude::*;
        let exits = &atlas.exits;
        exits
            .par_iter()
            .map(|x| {
                exits
                    .iter()
                    .filter(|y| y.normal.dot(x.normal) < 0.5)
                    .map(|y| (y.position - x.position).length_squared())
                    .fold(f32::INFINITY, f32::min)
                    .sqrt()
            })
            .collect()
    };
    let b = scene.bounds();
    let at = |fx: f32, fy: f32, fz: f32| b.min + (b.max - b.min) * Vec3::new(fx, fy, fz);
    let lights = [
        ("under the ceiling", at(0.5, 0.85, 0.5)),
        ("near the red wall", at(0.12, 0.35, 0.5)),
        ("low in a corner", at(0.15, 0.12, 0.2)),
    ];
    println!("| light | representation | rel. RMSE | energy |\n| --- | --- | ---: | ---: |");
    for (name, p) in lights {
        let light = [Light::Point {
            position: p,
            intensity: Vec3::ONE,
        }];
        let e = prm_trace::entry_irradiance(&bvh, &light, &entries);
        let tracer = ReferenceTracer::new(&scene, &bvh, Lighting::Lights(&light));
        let reference = tracer
            .indirect_at_exits(
                &atlas.exits,
                &ReferenceParams::with_spp(env_or("REFSPP", 1024)),
                &mut |_, _| {},
            )
            .unwrap();
        let noise = {
            let v: f64 = reference.variance.iter().map(|v| v.element_sum() as f64).sum();
            let n: f64 = reference.mean.iter().map(|v| v.length_squared() as f64).sum();
            (v / n).sqrt()
        };
        let entry_panes: Vec<&[Vec3]> = (0..entries.len()).map(|i| per_entry.pane(i)).collect();
        let cluster_panes: Vec<&[Vec3]> = cluster_pane.iter().map(Vec::as_slice).collect();
        let combine = |w: &dyn Fn(usize) -> Vec3, panes: &[&[Vec3]]| -> Vec<Vec3> {
            let mut out = vec![Vec3::ZERO; m];
            for (c, pane) in panes.iter().enumerate() {
                let wc = w(c);
                for (o, v) in out.iter_mut().zip(pane.iter()) {
                    *o += wc * *v;
                }
            }
            out
        };
        let unclustered = combine(&|i| e[i], &entry_panes);
        let mean = combine(
            &|c| {
                let mm = &clustering.members[c];
                mm.iter().map(|&k| e[k as usize]).sum::<Vec3>() / mm.len() as f32
            },
            &cluster_panes,
        );
        let by_energy = clustering.weights_by_energy(&e, &energy);
        let energy_w = combine(&|c| by_energy[c], &cluster_panes);
        // Region weights: the direct light integrated over each entry's own cell (the area
        // samples nearest to it on its own plane), per unit of its nominal area `A/N`.
        let e_area = prm_trace::entry_irradiance(&bvh, &light, &area);
        let mut region = vec![Vec3::ZERO; entries.len()];
        for ((s, &i), ea) in area.iter().zip(&cell).zip(&e_area) {
            let en = &entries[i as usize];
            region[i as usize] += *ea * (s.albedo / en.albedo.max(Vec3::splat(1e-6))) * (s.weight / en.weight);
        }
        let region_un = combine(&|i| region[i], &entry_panes);
        let region_by_energy = clustering.weights_by_energy(&region, &energy);
        let region_energy = combine(&|c| region_by_energy[c], &cluster_panes);
        let lsq = combine(
            &|c| {
                let mm = &clustering.members[c];
                mm.iter()
                    .map(|&k| e[k as usize] * alpha[k as usize] as f32)
                    .sum::<Vec3>()
                    / mm.len() as f32
            },
            &cluster_panes,
        );
        // A linear filter over each exit's atlas neighbours on its own chart and plane: weights
        // from geometry only, so filtering the result equals filtering every pane at bake time.
        let res = atlas.resolution as i32;
        let filter = |v: &[Vec3], k: i32| -> Vec<Vec3> {
            let sigma2 = (k as f32 * 0.5).max(0.5).powi(2);
            atlas
                .exits
                .iter()
                .map(|x| {
                    let (tx, ty) = ((x.texel as i32) % res, (x.texel as i32) / res);
                    let chart = atlas.texel_chart[x.texel as usize];
                    let (mut acc, mut wsum) = (Vec3::ZERO, 0.0f32);
                    for dy in -k..=k {
                        for dx in -k..=k {
                            let (ux, uy) = (tx + dx, ty + dy);
                            if ux < 0 || uy < 0 || ux >= res || uy >= res {
                                continue;
                            }
                            let t = (uy * res + ux) as usize;
                            let j = atlas.texel_exit[t];
                            if j == prm_scene::EMPTY_TEXEL || atlas.texel_chart[t] != chart {
                                continue;
                            }
                            let y = &atlas.exits[j as usize];
                            if y.normal.dot(x.normal) < 0.95 {
                                continue;
                            }
                            let w = (-((dx * dx + dy * dy) as f32) / (2.0 * sigma2)).exp() * y.coverage;
                            acc += w * v[j as usize];
                            wsum += w;
                        }
                    }
                    acc / wsum.max(1e-30)
                })
                .collect()
        };
        let f1 = filter(&unclustered, 1);
        let f2 = filter(&unclustered, 2);
        let f3 = filter(&unclustered, 3);
        let fe2 = filter(&energy_w, 2);
        let fr2 = filter(&region_un, 2);
        let fre2 = filter(&region_energy, 2);
        for (label, est) in [
            ("unclustered, filter 1", &f1),
            ("unclustered, filter 2", &f2),
            ("unclustered, filter 3", &f3),
            ("energy, filter 2", &fe2),
            ("region unclustered, filter 2", &fr2),
            ("region energy, filter 2", &fre2),
            ("unclustered", &unclustered),
            ("mean", &mean),
            ("energy", &energy_w),
            ("lsq", &lsq),
            ("region, unclustered", &region_un),
            ("region, energy", &region_energy),
        ] {
            let (err, en) = rel_rmse(est, &reference.mean);
            println!("| {name} | {label} | {:.1}% | {en:.3} |", 100.0 * err);
        }
        println!("| {name} | (reference noise) | {:.1}% | |", 100.0 * noise);
        if diag {
            // Where the unclustered error lies: by the distance to the nearest exit point on a
            // surface facing another way (a concave or convex edge), in texels.
            let texel = atlas.stats.texel_size;
            let bins = [0.0f32, 1.5, 4.0, 10.0, 30.0, f32::INFINITY];
            let (mut r2, mut d2, mut st, mut sr, mut count) =
                ([0.0f64; 5], [0.0f64; 5], [0.0f64; 5], [0.0f64; 5], [0usize; 5]);
            for (i, d) in edge_distance.iter().enumerate() {
                let b = bins
                    .windows(2)
                    .position(|w| *d / texel >= w[0] && *d / texel < w[1])
                    .unwrap_or(4);
                r2[b] += reference.mean[i].length_squared() as f64;
                d2[b] += (unclustered[i] - reference.mean[i]).length_squared() as f64;
                st[b] += unclustered[i].element_sum() as f64;
                sr[b] += reference.mean[i].element_sum() as f64;
                count[b] += 1;
            }
            let (tr, td): (f64, f64) = (r2.iter().sum(), d2.iter().sum());
            for b in 0..5 {
                println!(
                    "| {name} | edge distance {}–{} texels: {} exits, {:.1}% of ref², {:.1}% of error², rel. {:.1}%, energy {:.3} |",
                    bins[b], bins[b + 1], count[b], 100.0 * r2[b] / tr, 100.0 * d2[b] / td,
                    100.0 * (d2[b] / r2[b].max(1e-30)).sqrt(), st[b] / sr[b].max(1e-30)
                );
            }
        }
    }
}
