//! Experiment: the near field's direct share with each hit's own radiance against its gather
//! texel's (the exit point of the texel the hit lands in) and against the hit nearest the
//! weighted centroid of its gather texel's hits, all ray-cast, for one light (the measurement in
//! `prm_trace::near`'s module docs).
//!
//! `cargo run --release -p prm-trace --example near_hits -- SCENE RESOLUTION ENTRIES LIGHT OUT.bin`
//!
//! Writes, for every exit point, `texel: u32`, then the sums with the hit point's radiance, the
//! gather texel's and the gather texel's hits' weighted medoid's, `[f32; 3]` each
//! (π/M × Σ weight × albedo/π × E, M = 64 rays, the bake's disk at scale 3 for ENTRIES).

use glam::Vec3;
use prm_scene::{AtlasParams, Sizing};
use prm_trace::probes::HitTexels;
use prm_trace::{cosine_hemisphere, Bvh, BvhParams, Rng};
use rayon::prelude::*;
use std::io::Write;
use std::path::Path;

fn main() {
    let a: Vec<String> = std::env::args().skip(1).collect();
    let scene = prm_scene::load(Path::new(&a[0])).unwrap();
    let res: u32 = a[1].parse().unwrap();
    let entries: f32 = a[2].parse().unwrap();
    let lights = [prm_scene::parse_light(&a[3]).unwrap()];
    let bvh = Bvh::build(&scene, &BvhParams::DEFAULT).unwrap();
    let atlas = prm_trace::bake_atlas(&scene, &bvh, &AtlasParams::with_sizing(Sizing::Resolution(res))).unwrap();
    let area: f32 = scene.triangles.iter().map(|t| t.area()).sum();
    let disk = prm_trace::near_disk(area / entries, 3.0);
    let w0 = 1.0 / 16.0;
    let tmax = (disk * (1.0 / w0 - 1.0)).sqrt();
    let texels = HitTexels::new(&atlas);
    let rays = 64;
    // Every kept hit: exit, gather exit, weight, point, triangle, barycentrics.
    struct Hit {
        gather: u32,
        w: f32,
        y: Vec3,
        tri: u32,
        b: (f32, f32),
    }
    let hits: Vec<Vec<Hit>> = atlas
        .exits
        .par_iter()
        .enumerate()
        .map(|(i, x)| {
            let mut rng = Rng::new(7, 0x4e48, i as u64);
            let ng = bvh.geometric_normal(x.triangle);
            let mut out = Vec::new();
            for _ in 0..rays {
                let d = cosine_hemisphere(rng.next_vec2(), x.normal);
                let o = bvh.spawn(x.position, ng, d);
                let Some(h) = bvh.closest_hit(o, d, tmax, x.triangle) else {
                    continue;
                };
                let w = disk / (h.t * h.t + disk);
                if !h.front || w < w0 {
                    continue;
                }
                let Some(e) = texels.exit(h.triangle, h.b1, h.b2) else {
                    continue;
                };
                out.push(Hit {
                    gather: e,
                    w: (w - w0) / (1.0 - w0) / rays as f32,
                    y: o + d * h.t,
                    tri: h.triangle,
                    b: (h.b1, h.b2),
                });
            }
            out
        })
        .collect();
    let radiance_at = |tri: u32, b: (f32, f32), y: Vec3| -> Vec3 {
        let t = &scene.triangles[tri as usize];
        scene.albedo(tri as usize, b.0, b.1)
            * prm_trace::direct_irradiance(
                &bvh,
                &lights,
                y,
                bvh.geometric_normal(tri),
                t.shading_normal(b.0, b.1),
                tri,
            )
    };
    // Per gather exit: the weighted centroid of its hits, then the hit nearest to it.
    let n = atlas.exits.len();
    let mut sum = vec![(Vec3::ZERO, 0f32); n];
    for h in hits.iter().flatten() {
        let s = &mut sum[h.gather as usize];
        s.0 += h.y * h.w;
        s.1 += h.w;
    }
    /// A gather exit's hit nearest its centroid so far: distance, triangle, barycentrics, point.
    type Nearest = Option<(f32, u32, (f32, f32), Vec3)>;
    let mut rep: Vec<Nearest> = vec![None; n];
    for h in hits.iter().flatten() {
        let (c, w) = sum[h.gather as usize];
        let d = h.y.distance(c / w);
        let r = &mut rep[h.gather as usize];
        if r.is_none_or(|r| d < r.0) {
            *r = Some((d, h.tri, h.b, h.y));
        }
    }
    let at_rep: Vec<Vec3> = rep
        .par_iter()
        .map(|r| r.map_or(Vec3::ZERO, |(_, tri, b, y)| radiance_at(tri, b, y)))
        .collect();
    let rows: Vec<(u32, Vec3, Vec3, Vec3)> = atlas
        .exits
        .par_iter()
        .zip(&hits)
        .map(|(x, hs)| {
            let (mut at_hit, mut at_gather, mut at_medoid) = (Vec3::ZERO, Vec3::ZERO, Vec3::ZERO);
            for h in hs {
                at_hit += h.w * radiance_at(h.tri, h.b, h.y);
                let g = &atlas.exits[h.gather as usize];
                let gg = bvh.geometric_normal(g.triangle);
                at_gather +=
                    h.w * g.albedo * prm_trace::direct_irradiance(&bvh, &lights, g.position, gg, g.normal, g.triangle);
                at_medoid += h.w * at_rep[h.gather as usize];
            }
            (x.texel, at_hit, at_gather, at_medoid)
        })
        .collect();
    let mut f = std::io::BufWriter::new(std::fs::File::create(&a[4]).unwrap());
    for (t, h, g, m) in &rows {
        f.write_all(&t.to_le_bytes()).unwrap();
        for v in [h.x, h.y, h.z, g.x, g.y, g.z, m.x, m.y, m.z] {
            f.write_all(&v.to_le_bytes()).unwrap();
        }
    }
    let sum3 = |k: usize| -> f64 { rows.iter().map(|r| [r.1, r.2, r.3][k].element_sum() as f64).sum() };
    let (sh, sg, sm) = (sum3(0), sum3(1), sum3(2));
    println!(
        "{} exits: hit-point sum {sh:.1}, gather-texel sum {sg:.1} ({:.4}), medoid sum {sm:.1} ({:.4})",
        rows.len(),
        sg / sh,
        sm / sh
    );
}
