//! Frame time of `gi` vs `direct` at 1024×768 on the Cornell box (synthetic archive), on Vulkan.
//!
//! `cargo bench -p prm-play --bench frame [-- FRAMES]`: prints mean and median wall time per
//! frame (recording to GPU completion) and mean GPU time per pass, then the gi/direct ratio.

use prm_play::synthetic::{cornell_box_path, write_archive, SyntheticParams};
use prm_play::{FrameInput, FrameTimings, Mode, PlayOptions, Renderer};

fn stats(name: &str, t: &[FrameTimings]) -> f64 {
    let mut ms: Vec<f64> = t.iter().map(|f| f.cpu_ms).collect();
    ms.sort_by(f64::total_cmp);
    let mean = ms.iter().sum::<f64>() / ms.len() as f64;
    let median = ms[ms.len() / 2];
    print!("{name:>8}: mean {mean:7.2} ms, median {median:7.2} ms;");
    let mut passes: Vec<(&str, f64)> = Vec::new();
    for f in t {
        for (p, v) in &f.gpu_ms {
            match passes.iter_mut().find(|(q, _)| q == p) {
                Some(e) => e.1 += v,
                None => passes.push((p, *v)),
            }
        }
    }
    for (p, v) in passes {
        print!(" {p} {:.2}", v / t.len() as f64);
    }
    println!(" (GPU ms/frame)");
    median
}

fn main() {
    let frames: usize = std::env::args().skip(1).find_map(|a| a.parse().ok()).unwrap_or(20);
    let scene_path = cornell_box_path();
    let scene = prm_scene::load(&scene_path).expect("Cornell box");
    let dir = std::env::temp_dir().join(format!("prm-play-bench-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let archive_path = dir.join("cornell-bench.prm");
    let params = SyntheticParams {
        resolution: 128,
        clusters: 256,
        entries_per_cluster: 16,
        seed: 7,
    };
    write_archive(&scene, &scene_path, &archive_path, params).unwrap();
    let (mut archive, scene) = prm_play::open(&archive_path, None).unwrap();
    let ctx = prm_play::open_vulkan().expect("a Vulkan device");
    println!("GPU: {}", ctx.describe());
    let opts = PlayOptions {
        width: 1024,
        height: 768,
        top_k: 32,
        timestamps: true,
        ..Default::default()
    };
    println!(
        "1024x768, atlas {}², {} clusters, top K {}, shadow maps {}², {frames} frames per mode",
        params.resolution, params.clusters, opts.top_k, opts.shadow_resolution
    );
    let mut r = Renderer::new(ctx, &scene, &mut archive, opts).unwrap();
    let camera = prm_play::default_camera(&scene);
    // Modes interleaved frame by frame, so that load from other processes hits both alike.
    let mut direct = Vec::new();
    let mut gi = Vec::new();
    for i in 0..frames + 3 {
        for (mode, out) in [(Mode::Direct, &mut direct), (Mode::Gi, &mut gi)] {
            let t = r
                .render(&FrameInput {
                    camera,
                    lights: &scene.lights,
                    mode,
                })
                .unwrap();
            if i >= 3 {
                out.push(t);
            }
        }
    }
    let d = stats("direct", &direct);
    let g = stats("gi", &gi);
    println!("gi / direct frame time (median): {:.3}", g / d);
    let _ = std::fs::remove_dir_all(&dir);
}
