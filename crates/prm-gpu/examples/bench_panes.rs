//! Benchmark of GPU pane rendering: depth and gather time per variant, in one run, on one scene.
//!
//! `cargo run --release -p prm-gpu --example bench_panes -- SCENE [ENTRIES CLUSTERS RESOLUTION WALKS]`
//! (defaults: the paper's 4096 entries, 256 clusters, 256² panes, 1 walk per entry). Prints, for
//! every (filter, face resolution) variant, the wall time of the depth and gather passes, the
//! evaluation rate, and the relative RMSE of the summed panes against the Pcf2x2/256 variant.

use prm_gpu::{Backend, DepthFilter, GpuContext, PaneInputs, PaneRenderParams};
use prm_scene::{Atlas, AtlasParams, Sizing};
use prm_trace::{Bvh, BvhParams, ClusterParams, Clustering, EntryParams, WalkParams};
use std::time::Instant;

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let Some(scene_path) = args.first() else {
        anyhow::bail!("usage: bench_panes SCENE [ENTRIES CLUSTERS RESOLUTION WALKS]");
    };
    let num = |i: usize, d: usize| args.get(i).and_then(|s| s.parse().ok()).unwrap_or(d);
    let (entries, clusters, resolution, walks) = (num(1, 4096), num(2, 256), num(3, 256) as u32, num(4, 1) as u32);
    let scene = prm_scene::load(std::path::Path::new(scene_path))?;
    let atlas = Atlas::build(&scene, &AtlasParams::with_sizing(Sizing::Resolution(resolution)))?;
    let bvh = Bvh::build(&scene, &BvhParams::DEFAULT)?;
    let samples = prm_trace::sample_surface(
        &scene,
        &EntryParams {
            count: entries,
            seed: 1,
        },
    )?;
    let vpls = prm_trace::trace_walks(
        &scene,
        &bvh,
        &samples,
        &WalkParams {
            walks_per_entry: walks,
            ..WalkParams::PREVIEW
        },
    )?;
    let clustering = Clustering::kmeans(
        &samples,
        scene.bounds().diagonal(),
        &ClusterParams::with_clusters(clusters),
    )?;
    let ctx = GpuContext::new(Backend::Vulkan)?;
    println!(
        "{scene_path}: {} triangles, {} exits, {} VPLs, {} clusters on {}",
        scene.triangles.len(),
        atlas.exits.len(),
        vpls.vpls.len(),
        clustering.len(),
        ctx.describe()
    );
    let inputs = PaneInputs {
        scene: &scene,
        exits: &atlas.exits,
        vpls: &vpls,
        clustering: &clustering,
    };
    let sum = |p: &prm_trace::Panes| p.combine(&vec![glam::Vec3::ONE; p.clusters]);
    let mut reference: Option<Vec<glam::Vec3>> = None;
    for (filter, face, batch) in [
        (DepthFilter::Pcf2x2, 256, 256),
        (DepthFilter::Pcf2x2, 128, 256),
        (DepthFilter::Nearest, 128, 256),
        (DepthFilter::Pcf2x2, 128, 64),
        (DepthFilter::Pcf2x2, 64, 256),
    ] {
        let params = PaneRenderParams {
            filter,
            face_resolution: face,
            vpls_per_batch: batch,
            ..PaneRenderParams::DEFAULT
        };
        let t = Instant::now();
        let (panes, stats) = prm_gpu::render_panes(&ctx, &inputs, &params)?;
        let total = t.elapsed().as_secs_f64();
        let s = sum(&panes);
        let rmse = match &reference {
            None => {
                reference = Some(s);
                0.0
            }
            Some(r) => {
                let (mut e, mut n) = (0.0f64, 0.0f64);
                for (a, b) in s.iter().zip(r) {
                    e += (*a - *b).length_squared() as f64;
                    n += b.length_squared() as f64;
                }
                (e / n.max(1e-30)).sqrt()
            }
        };
        println!(
            "{filter:?}/{face}/batch {batch}: total {total:.2} s, depth {:.2} s ({} faces, {:.3} ms each, {:.0} triangles in {:.1} draws each), gather {:.2} s ({:.1} M eval/s), rel. RMSE vs Pcf2x2/256 {rmse:.4}",
            stats.depth_seconds,
            stats.faces,
            1e3 * stats.depth_seconds / stats.faces.max(1) as f64,
            stats.triangles as f64 / stats.faces.max(1) as f64,
            stats.draws as f64 / stats.faces.max(1) as f64,
            stats.gather_seconds,
            stats.evaluations as f64 / stats.gather_seconds.max(1e-9) / 1e6,
        );
    }
    Ok(())
}
