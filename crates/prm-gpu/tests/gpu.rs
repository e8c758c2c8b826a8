//! Integration tests of the GPU passes on the Vulkan backend (lavapipe on machines without a GPU).

use prm_gpu::{Backend, GpuContext};

/// Vulkan explicitly, so that a missing driver fails loudly instead of falling back to GL.
fn vulkan() -> GpuContext {
    match GpuContext::new(Backend::Vulkan) {
        Ok(ctx) => ctx,
        Err(e) => panic!("{e}"),
    }
}

#[test]
fn smoke_pass_computes_on_vulkan() {
    let ctx = vulkan();
    eprintln!("adapter: {}", ctx.describe());
    assert_eq!(ctx.info.backend, wgpu::Backend::Vulkan);
    let xs: Vec<f32> = (0..1000).map(|i| i as f32 * 0.5 - 17.0).collect();
    let ys = prm_gpu::smoke::run(&ctx, 3.0, -2.0, &xs).expect("smoke pass");
    assert_eq!(ys.len(), xs.len());
    for (x, y) in xs.iter().zip(&ys) {
        assert_eq!(*y, 3.0 * x - 2.0, "x = {x}");
    }
}

#[test]
fn missing_adapter_error_names_the_fix() {
    let e = prm_gpu::GpuError::NoAdapter {
        backend: Backend::Vulkan,
    }
    .to_string();
    assert!(e.contains("mesa-vulkan-drivers"), "{e}");
}

mod panes {
    use super::vulkan;
    use prm_gpu::PaneRenderParams;
    use prm_scene::{Atlas, AtlasParams, Sizing};
    use prm_trace::{Bvh, BvhParams, ClusterParams, Clustering, EntryParams, PaneParams, WalkParams};
    use std::path::Path;

    /// Relative RMSE of `gpu` against `cpu` over all texels and channels, normalised by the
    /// RMS of `cpu`.
    fn relative_rmse(gpu: &[glam::Vec3], cpu: &[glam::Vec3]) -> f64 {
        let (mut err, mut norm) = (0.0f64, 0.0f64);
        for (g, c) in gpu.iter().zip(cpu) {
            err += (*g - *c).length_squared() as f64;
            norm += c.length_squared() as f64;
        }
        (err / norm.max(1e-30)).sqrt()
    }

    #[test]
    fn gpu_panes_match_cpu_evaluator_on_cornell_box() {
        let ctx = vulkan();
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes/cornell-box/cornell-box.obj");
        let scene = prm_scene::load(&path).unwrap();
        let atlas = Atlas::build(&scene, &AtlasParams::with_sizing(Sizing::Resolution(64))).unwrap();
        let bvh = Bvh::build(&scene, &BvhParams::DEFAULT).unwrap();
        let entries = prm_trace::sample_surface(&scene, &EntryParams { count: 256, seed: 7 }).unwrap();
        let vpls = prm_trace::trace_walks(
            &scene,
            &bvh,
            &entries,
            &WalkParams {
                walks_per_entry: 2,
                ..WalkParams::PREVIEW
            },
        )
        .unwrap();
        let clustering =
            Clustering::kmeans(&entries, scene.bounds().diagonal(), &ClusterParams::with_clusters(16)).unwrap();
        let cpu = prm_trace::evaluate_panes(&bvh, &vpls, &clustering, &atlas.exits, &PaneParams::DEFAULT).unwrap();
        let params = PaneRenderParams {
            face_resolution: 256,
            vpls_per_batch: 128,
            ..PaneRenderParams::DEFAULT
        };
        let (gpu, stats) =
            prm_gpu::render_panes(&ctx, &scene, &atlas.exits, &vpls, &clustering, &params).expect("GPU panes");
        assert_eq!(stats.vpls as usize, vpls.vpls.len());
        assert!(stats.batches > 1, "several batches exercised");
        let all = relative_rmse(&gpu.data, &cpu.data);
        let mut sum_gpu = glam::Vec3::ZERO;
        let mut sum_cpu = glam::Vec3::ZERO;
        for (g, c) in gpu.data.iter().zip(&cpu.data) {
            sum_gpu += *g;
            sum_cpu += *c;
        }
        eprintln!(
            "GPU vs CPU panes: relative RMSE {:.4}, energy ratio {:?}, {} VPLs, {} exits",
            all,
            sum_gpu / sum_cpu,
            vpls.vpls.len(),
            atlas.exits.len()
        );
        assert!(gpu.data.iter().all(|v| v.is_finite()));
        // The sum over clusters (the unclustered irradiance field) is what the player shows.
        let total = |p: &prm_trace::Panes| p.combine(&vec![glam::Vec3::ONE; p.clusters]);
        let summed = relative_rmse(&total(&gpu), &total(&cpu));
        eprintln!("summed over clusters: relative RMSE {summed:.4}");
        if std::env::var_os("PRM_DEBUG").is_some() {
            let (tg, tc) = (total(&gpu), total(&cpu));
            let mut idx: Vec<usize> = (0..tg.len()).collect();
            idx.sort_by(|&a, &b| (tg[b] - tc[b]).length().total_cmp(&(tg[a] - tc[a]).length()));
            for &i in idx.iter().take(12) {
                let e = &atlas.exits[i];
                eprintln!(
                    "{i}: pos {:?} n {:?} gpu {:?} cpu {:?} cov {}",
                    e.position, e.normal, tg[i], tc[i], e.coverage
                );
            }
        }
        assert!(summed < 0.02, "GPU vs CPU relative RMSE {summed}");
    }
}
