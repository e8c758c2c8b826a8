//! Ray-casting benchmark: BVH build time, walks/s and rays/s on our scenes (run with --release).
//!
//! `cargo xtask eval experiment bench_trace`

use std::path::{Path, PathBuf};
use std::time::Instant;

use prm_trace::sampling::{cosine_hemisphere, sobol2};
use prm_trace::{sample_surface, trace_walks, Bvh, BvhKind, BvhParams, EntryParams, WalkParams};
use rayon::prelude::*;

fn bench(path: &Path) {
    if !path.exists() {
        println!("{}: absent, skipped", path.display());
        return;
    }
    let t = Instant::now();
    let scene = match prm_scene::load(path) {
        Ok(s) => s,
        Err(e) => {
            println!("{}: cannot load ({e}), skipped", path.display());
            return;
        }
    };
    println!(
        "{}: {} triangles, loaded in {:.2?}, {} threads",
        path.display(),
        scene.triangles.len(),
        t.elapsed(),
        rayon::current_num_threads()
    );
    let entries = sample_surface(&scene, &EntryParams::PAPER).unwrap();
    for params in [BvhParams::DEFAULT, BvhParams::BVH2] {
        let name = match params.kind {
            BvhKind::Cwbvh => "CWBVH",
            BvhKind::Bvh2 => "BVH2 ",
        };
        let bvh = Bvh::build(&scene, &params).unwrap();
        let build = bvh.build_time();
        // Incoherent closest-hit rays: 16 cosine directions from each entry point.
        let rays_per_entry = 16u32;
        let t = Instant::now();
        let hits: usize = entries
            .par_iter()
            .map(|e| {
                (0..rays_per_entry)
                    .filter(|&i| {
                        let d = cosine_hemisphere(sobol2(i, e.triangle), e.normal);
                        bvh.closest_hit(bvh.spawn(e.position, e.normal, d), d, f32::INFINITY, e.triangle)
                            .is_some()
                    })
                    .count()
            })
            .sum();
        let closest = t.elapsed();
        let n_rays = entries.len() as f64 * rays_per_entry as f64;
        // Shadow rays between pairs of entry points.
        let t = Instant::now();
        let pairs = 64usize;
        let visible: usize = entries
            .par_iter()
            .enumerate()
            .map(|(k, e)| {
                (1..=pairs)
                    .filter(|&j| {
                        let o = &entries[(k * 7919 + j * 104_729) % entries.len()];
                        bvh.visible(e.position, e.normal, e.triangle, o.position, o.normal, o.triangle)
                    })
                    .count()
            })
            .sum();
        let shadow = t.elapsed();
        let n_shadow = (entries.len() * pairs) as f64;
        // Walks.
        let t = Instant::now();
        let walks = trace_walks(&scene, &bvh, &entries, &WalkParams::STANDARD).unwrap();
        let wt = t.elapsed();
        println!(
            "  {name} build {:>8.2?} | closest hit {:>6.2} Mrays/s ({:.0}% hit) | shadow {:>6.2} Mrays/s ({:.0}% visible) | \
             walks {:>6.2} M/s, {:>5.2} Mrays/s ({} walks, {} VPLs, {:.1} rays/walk)",
            build,
            n_rays / closest.as_secs_f64() / 1e6,
            100.0 * hits as f64 / n_rays,
            n_shadow / shadow.as_secs_f64() / 1e6,
            100.0 * visible as f64 / n_shadow,
            walks.stats.walks as f64 / wt.as_secs_f64() / 1e6,
            walks.stats.rays as f64 / wt.as_secs_f64() / 1e6,
            walks.stats.walks,
            walks.vpls.len(),
            walks.stats.rays as f64 / walks.stats.walks as f64,
        );
        println!(
            "        walk rays: {:.1}% escaped, {:.1}% hit a back face",
            100.0 * walks.stats.escaped as f64 / walks.stats.rays as f64,
            100.0 * walks.stats.back_faces as f64 / walks.stats.rays as f64
        );
    }
}

pub fn run(_args: Vec<String>) {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..");
    for rel in ["scenes/cornell-box/cornell-box.obj", "scenes/chairs/chairs.obj"] {
        bench(&root.join(rel));
    }
    bench(&root.join("../shared/scenes/sibenik/sibenik.obj"));
}
