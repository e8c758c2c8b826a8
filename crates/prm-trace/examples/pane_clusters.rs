//! Experiment: clustering entry points by the shape of their panes instead of by position.
//!
//! `cargo run --release -p prm-trace --example pane_clusters -- SCENE ENTRIES CLUSTERS RES LIGHT...`
//!
//! With energy weights a cluster is exact, whatever the lighting, when its members' panes are
//! proportional (`P_i = α_i P̄`): `Σ E_i P_i = (Σ E_i e_i / Σ e_i) Σ P_i`. k-means on position and
//! normal assumes instead that members are lit alike, which a hard shadow across a cluster breaks.
//! Here every entry point's pane is evaluated (CPU, one shadow ray per VPL and exit) at two random
//! samples of exit points: `FEAT` (1024) give the feature, the pane's luminance over them scaled
//! to unit length; `EVAL` (4096) give the error against the reference (`REFSPP` paths, 512),
//! without the near field, for
//! - `unclustered`: `Σ_i E_i P_i`, the target;
//! - `position`: the bake's clustering (`Clustering::kmeans_separated`);
//! - `shape λ`: k-means++ and Lloyd on `(shape, λ·position feature)`, λ from `LAMBDAS`.
//!
//! Knobs (environment): `WALKS` (4), `SEED` (0), `FEAT`, `EVAL`, `REFSPP`, `LAMBDAS` (`0,0.5,1,2`).
//!
//! Measured (release, seed 0, lightmap space without the near field, so far from what is
//! played; the rows compare clusterings of the same VPLs):
//!
//! | case | unclustered | position | shape, λ = 0 | shape, λ = 0.5–2 |
//! | --- | ---: | ---: | ---: | ---: |
//! | McGuire's box (`Ke` = 0), 2048 entries, 256 clusters, 256², under the ceiling | 13.3% | 13.0% | 13.8% | 13.1–13.2% |
//! | the same, low near the red wall | 14.9% | 15.4% | 17.0% | 16.9–19.2% |
//! | Sponza, the sun of `cargo xtask eval --sky`, 2816 entries, 205 clusters, 512² | 60.8% (energy 0.618) | 64.7% | 61.4% | 61.3–61.9% |
//! | fireplace room, its lamp, 3072 entries, 205 clusters, 512² | 86.5% (0.586) | 86.7% | 86.6% | 86.6% |
//! | the same, 6144 entries (7 walks each) | 85.4% (0.594) | 85.5% | 85.9% | 85.9% |
//!
//! At the 8 to 16 entry points per cluster the planner allows, clustering costs 0.1–4 points and
//! a clustering by pane shape buys nothing: the error lies in the unclustered estimator (the
//! entry points' sampling of the direct light, and the VPL bound, which the near field gives
//! back when played). Not kept.

use glam::Vec3;
use prm_scene::{Atlas, AtlasParams, ExitPoint, Sizing};
use prm_trace::{
    Bvh, BvhParams, Clustering, DeepDisk, EntryParams, Lighting, PaneParams, ReferenceParams, ReferenceTracer, Rng,
    WalkParams,
};
use rayon::prelude::*;

mod common;
use common::{env_or, rel_rmse};

/// k-means++ then Lloyd on dense rows; returns one label per row.
fn kmeans(rows: &[Vec<f32>], k: usize, seed: u64) -> Vec<u32> {
    let n = rows.len();
    let dist = |a: &[f32], b: &[f32]| a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum::<f32>();
    let mut rng = Rng::new(seed, 0x5A, n as u64);
    let mut centres: Vec<Vec<f32>> = vec![rows[(rng.next_u32() as usize) % n].clone()];
    let mut d2: Vec<f32> = rows.par_iter().map(|r| dist(r, &centres[0])).collect();
    while centres.len() < k {
        let total: f64 = d2.iter().map(|&d| d as f64).sum();
        let target = rng.next_f32() as f64 * total;
        let (mut acc, mut pick) = (0.0, n - 1);
        for (i, &d) in d2.iter().enumerate() {
            acc += d as f64;
            if acc > target {
                pick = i;
                break;
            }
        }
        let c = rows[pick].clone();
        d2.par_iter_mut().zip(rows).for_each(|(d, r)| *d = d.min(dist(r, &c)));
        centres.push(c);
    }
    let assign = |centres: &[Vec<f32>]| -> Vec<u32> {
        rows.par_iter()
            .map(|r| {
                let mut best = (f32::INFINITY, 0u32);
                for (j, c) in centres.iter().enumerate() {
                    let d = dist(r, c);
                    if d < best.0 {
                        best = (d, j as u32);
                    }
                }
                best.1
            })
            .collect()
    };
    let mut labels = assign(&centres);
    for _ in 0..20 {
        let dim = rows[0].len();
        let mut sums = vec![vec![0.0f32; dim]; k];
        let mut counts = vec![0u32; k];
        for (r, &l) in rows.iter().zip(&labels) {
            for (s, x) in sums[l as usize].iter_mut().zip(r) {
                *s += x;
            }
            counts[l as usize] += 1;
        }
        for ((c, s), &m) in centres.iter_mut().zip(sums).zip(&counts) {
            if m > 0 {
                *c = s.into_iter().map(|x| x / m as f32).collect();
            }
        }
        let next = assign(&centres);
        if next == labels {
            break;
        }
        labels = next;
    }
    labels
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.len() < 5 {
        eprintln!("usage: pane_clusters SCENE ENTRIES CLUSTERS RES LIGHT...");
        std::process::exit(2);
    }
    let scene = prm_scene::load(std::path::Path::new(&args[0])).unwrap();
    let n_entries: usize = args[1].parse().unwrap();
    let n_clusters: usize = args[2].parse().unwrap();
    let res: u32 = args[3].parse().unwrap();
    let lights: Vec<prm_scene::Light> = args[4..].iter().map(|s| prm_trace::parse_light(s).unwrap()).collect();
    let seed = env_or("SEED", 0) as u64;
    let atlas = Atlas::build(&scene, &AtlasParams::with_sizing(Sizing::Resolution(res))).unwrap();
    let bvh = Bvh::build(&scene, &BvhParams::DEFAULT).unwrap();
    let entries = prm_trace::sample_surface(&scene, &EntryParams { count: n_entries, seed }).unwrap();
    let walks = WalkParams {
        walks_per_entry: env_or("WALKS", 4),
        seed,
        deep_disk: DeepDisk::Entry,
        ..WalkParams::PREVIEW
    };
    let vpls = prm_trace::trace_walks(&scene, &bvh, &entries, &walks).unwrap();
    let pick = |count: u32, stream: u64| -> Vec<ExitPoint> {
        prm_trace::check_exits(atlas.exits.len(), count, seed ^ stream)
            .into_iter()
            .map(|i| atlas.exits[i])
            .collect()
    };
    let feat_exits = pick(env_or("FEAT", 1024), 0x1111);
    let eval_exits = pick(env_or("EVAL", 4096), 0x2222);
    let identity = Clustering::identity(&entries);
    let t = std::time::Instant::now();
    let feat = prm_trace::evaluate_panes(&bvh, &vpls, &identity, &feat_exits, &PaneParams::DEFAULT).unwrap();
    let eval = prm_trace::evaluate_panes(&bvh, &vpls, &identity, &eval_exits, &PaneParams::DEFAULT).unwrap();
    eprintln!(
        "{} entries, {} VPLs, {} + {} exits of {}: panes in {:.1} s",
        entries.len(),
        vpls.vpls.len(),
        feat_exits.len(),
        eval_exits.len(),
        atlas.exits.len(),
        t.elapsed().as_secs_f64()
    );
    let lum = |v: Vec3| v.dot(Vec3::new(0.2126, 0.7152, 0.0722));
    let shape: Vec<Vec<f32>> = (0..entries.len())
        .map(|i| {
            let v: Vec<f32> = feat.pane(i).iter().map(|&p| lum(p)).collect();
            let norm = v.iter().map(|x| x * x).sum::<f32>().sqrt();
            if norm > 0.0 {
                v.into_iter().map(|x| x / norm).collect()
            } else {
                v
            }
        })
        .collect();
    let diagonal = scene.bounds().diagonal();
    let min = entries.iter().fold(Vec3::INFINITY, |m, e| m.min(e.position));
    let lambdas: Vec<f32> = std::env::var("LAMBDAS")
        .unwrap_or_else(|_| "0,0.5,1,2".into())
        .split(',')
        .map(|s| s.parse().unwrap())
        .collect();
    let mut clusterings: Vec<(String, Clustering)> = vec![(
        "position".into(),
        Clustering::kmeans_separated(&entries, &bvh, diagonal, n_clusters, seed).unwrap(),
    )];
    for &l in &lambdas {
        let t = std::time::Instant::now();
        let rows: Vec<Vec<f32>> = entries
            .iter()
            .zip(&shape)
            .map(|(e, s)| {
                let p = (e.position - min) / diagonal * l;
                let n = e.normal * 0.3 * l;
                let mut r = s.clone();
                r.extend_from_slice(&[p.x, p.y, p.z, n.x, n.y, n.z]);
                r
            })
            .collect();
        let labels = kmeans(&rows, n_clusters, seed);
        let c = Clustering::from_labels(&entries, &labels);
        eprintln!(
            "shape λ {l}: {} clusters in {:.1} s",
            c.len(),
            t.elapsed().as_secs_f64()
        );
        clusterings.push((format!("shape λ {l}"), c));
    }
    let m = eval_exits.len();
    let energy: Vec<Vec3> = (0..entries.len()).map(|i| eval.pane(i).iter().sum()).collect();
    println!("| light | clustering | rel. RMSE | energy |\n| --- | --- | ---: | ---: |");
    for (spec, light) in args[4..].iter().zip(&lights) {
        let light = [*light];
        let e = prm_trace::entry_irradiance(&bvh, &light, &entries);
        let reference = ReferenceTracer::new(&scene, &bvh, Lighting::Lights(&light))
            .indirect_at_exits(
                &eval_exits,
                &ReferenceParams::with_spp(env_or("REFSPP", 512)),
                &mut |_, _| {},
            )
            .unwrap();
        let mut unclustered = vec![Vec3::ZERO; m];
        for (i, ei) in e.iter().enumerate() {
            for (o, v) in unclustered.iter_mut().zip(eval.pane(i)) {
                *o += *ei * *v;
            }
        }
        let (err, en) = rel_rmse(&unclustered, &reference.mean);
        println!("| {spec} | unclustered | {:.1}% | {en:.3} |", 100.0 * err);
        for (name, c) in &clusterings {
            let w = c.weights_by_energy(&e, &energy);
            let mut out = vec![Vec3::ZERO; m];
            for (i, o) in out.iter_mut().enumerate() {
                for (k, cl) in c.of_entry.iter().enumerate() {
                    *o += w[*cl as usize] * eval.data[k * m + i];
                }
            }
            let (err, en) = rel_rmse(&out, &reference.mean);
            println!(
                "| {spec} | {name} ({} clusters) | {:.1}% | {en:.3} |",
                c.len(),
                100.0 * err
            );
        }
    }
}
