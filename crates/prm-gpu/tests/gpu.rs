//! Integration tests of the GPU passes on the Vulkan backend (lavapipe on machines without a GPU).

use prm_gpu::{Backend, GpuContext};

/// Vulkan explicitly, so that a missing driver fails loudly instead of falling back to GL.
fn vulkan() -> GpuContext {
    match GpuContext::new(Backend::Vulkan) {
        Ok(ctx) => ctx,
        Err(e) => panic!("{e}"),
    }
}

/// The atlas (`resolution`² texels), BVH, entry points and light walks of `scene`.
fn trace_scene(
    scene: &prm_scene::Scene,
    resolution: u32,
    entries: prm_trace::EntryParams,
    walks: prm_trace::WalkParams,
) -> (
    prm_scene::Atlas,
    prm_trace::Bvh,
    Vec<prm_trace::SurfaceSample>,
    prm_trace::VplSet,
) {
    use prm_scene::{Atlas, AtlasParams, Sizing};
    let atlas = Atlas::build(scene, &AtlasParams::with_sizing(Sizing::Resolution(resolution))).unwrap();
    let bvh = prm_trace::Bvh::build(scene, &prm_trace::BvhParams::DEFAULT).unwrap();
    let entries = prm_trace::sample_surface(scene, &entries).unwrap();
    let walks = prm_trace::trace_walks(scene, &bvh, &entries, &walks).unwrap();
    (atlas, bvh, entries, walks)
}

/// Relative RMSE of `gpu` against `cpu` over all texels and channels, normalised by the RMS of
/// `cpu`.
fn relative_rmse(gpu: &[glam::Vec3], cpu: &[glam::Vec3]) -> f64 {
    let (mut err, mut norm) = (0.0f64, 0.0f64);
    for (g, c) in gpu.iter().zip(cpu) {
        err += (*g - *c).length_squared() as f64;
        norm += c.length_squared() as f64;
    }
    (err / norm.max(1e-30)).sqrt()
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
    use super::{relative_rmse, trace_scene, vulkan};
    use prm_gpu::{PaneInputs, PaneRenderParams};
    use prm_trace::{ClusterParams, Clustering, EntryParams, PaneParams, WalkParams};
    use std::path::Path;

    #[test]
    fn gpu_panes_match_cpu_evaluator_on_cornell_box() {
        let ctx = vulkan();
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes/cornell-box/cornell-box.obj");
        let scene = prm_scene::load(&path).unwrap();
        let walks = WalkParams {
            walks_per_entry: 2,
            ..WalkParams::PREVIEW
        };
        let (atlas, bvh, entries, vpls) = trace_scene(&scene, 64, EntryParams { count: 256, seed: 7 }, walks);
        let clustering =
            Clustering::kmeans(&entries, scene.bounds().diagonal(), &ClusterParams::with_clusters(16)).unwrap();
        let inputs = PaneInputs {
            scene: &scene,
            exits: &atlas.exits,
            vpls: &vpls,
            clustering: &clustering,
        };
        let cpu = prm_trace::evaluate_panes(&bvh, &vpls, &clustering, &atlas.exits, &PaneParams::DEFAULT).unwrap();
        let params = PaneRenderParams {
            face_resolution: 256,
            vpls_per_batch: 128,
            ..PaneRenderParams::DEFAULT
        };
        let (gpu, stats) = prm_gpu::render_panes(&ctx, &inputs, &params).expect("GPU panes");
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
        // Measured: per-cluster relative RMSE 0.0125, energy ratio 0.9992–0.9993.
        assert!(all < 0.016, "GPU vs CPU per-cluster relative RMSE {all}");
        let ratio = sum_gpu / sum_cpu;
        assert!(
            (ratio - glam::Vec3::ONE).abs().max_element() < 0.002,
            "GPU / CPU energy {ratio}"
        );
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
        // Measured 0.0108.
        assert!(summed < 0.014, "GPU vs CPU relative RMSE {summed}");

        // Entry energies: in entry order on both sides, and each cluster's members sum to its
        // pane's energy.
        assert_eq!(gpu.entry_energy.len(), entries.len());
        let energy_err = relative_rmse(&gpu.entry_energy, &cpu.entry_energy);
        eprintln!("entry energies, GPU vs CPU: relative RMSE {energy_err:.4}");
        // Measured 0.0014.
        assert!(
            energy_err < 0.003,
            "entry energies GPU vs CPU: relative RMSE {energy_err}"
        );
        for (c, members) in clustering.members.iter().enumerate() {
            let pane: glam::Vec3 = gpu.pane(c).iter().sum();
            let members: glam::Vec3 = members.iter().map(|&k| gpu.entry_energy[k as usize]).sum();
            assert!(
                (pane - members).abs().max_element() <= 1e-3 * pane.max_element().max(1e-12),
                "cluster {c}: pane energy {pane} but its members' sum {members}"
            );
        }
        // Above the read-back budget the clusters are rendered directly, with the same panes
        // and no energies.
        let direct = PaneRenderParams {
            member_energy_bytes: 0,
            ..params
        };
        let (per_cluster, _) = prm_gpu::render_panes(&ctx, &inputs, &direct).expect("GPU panes");
        assert!(per_cluster.entry_energy.is_empty());
        let same = relative_rmse(&per_cluster.data, &gpu.data);
        assert!(
            same < 1e-4,
            "per-cluster against per-entry rendering: relative RMSE {same}"
        );
    }
}

/// The white furnace through the GPU pane renderer: a closed box of albedo ρ = 0.5 with unit
/// irradiance at every entry point has indirect irradiance ρ/(1−ρ) = 1 everywhere.
mod furnace {
    use super::{relative_rmse, trace_scene, vulkan};
    use glam::Vec3;
    use prm_gpu::{PaneInputs, PaneRenderParams};
    use prm_scene::ExitPoint;
    use prm_trace::{ClusterParams, Clustering, EntryParams, PaneParams, WalkParams};

    use prm_scene::analytic::furnace_box;

    /// Distance from `p` to the nearest edge of the unit cube (second smallest distance to a
    /// face plane).
    fn edge_distance(p: Vec3) -> f32 {
        let mut d = [p.x, 1.0 - p.x, p.y, 1.0 - p.y, p.z, 1.0 - p.z];
        d.sort_by(|a, b| a.total_cmp(b));
        d[1]
    }

    /// Exit points closer than this to a box edge are reported, not asserted: the same rule
    /// (and margin) as prm-trace's furnace test.
    ///
    /// Is it principled? Only partly. The furnace identity E_ind = ρ/(1−ρ) holds at *every* point,
    /// edges and corners included, so nothing physical happens at the edges; what fails there is
    /// the estimator, for two reasons:
    /// - an exit point lying *exactly* on a concave edge (an atlas that put the exit points of
    ///   partially covered border texels on the triangle's boundary would make them) sees the adjacent wall
    ///   edge-on: every VPL there has cos θ_v = 0, so half of the hemisphere (a third in a corner)
    ///   contributes nothing and the sum is about 0.42 instead of 1 (measured: 96 such exits at
    ///   32², mean 0.42). That is a degenerate sample position, and excluding it is right;
    /// - an exit point at distance d from the edge gets a large share of its irradiance from the
    ///   adjacent wall within distance ~d, where the VPL bound (a disk of radius
    ///   R = sqrt(A/(πN)): 1/(r² + R²)) removes energy and the VPL spacing (~R) cannot resolve
    ///   the 1/r² kernel. This bias is a property of the bound, and the margin that excludes it
    ///   should scale with R (0.031 for the 2048 entries here, 0.061 for 512), not be a fixed
    ///   0.05. With 512 entries the exits at 0.05..0.1 from an edge are still 4 % low (up to
    ///   16 %), which is why this test uses 2048 entries (the CPU evaluator gives the same
    ///   numbers: it is the estimator, not the GPU).
    ///
    /// The fixed margin is kept for comparability with the CPU test; the errors by distance to
    /// the edges are printed so the edge bias stays visible.
    const EDGE_MARGIN: f32 = 0.05;

    struct Stats {
        mean: f64,
        max: f64,
        bias: f64,
        count: usize,
    }

    /// |value − 1| statistics (value: channel mean) over the exits whose distance to the nearest
    /// box edge lies in `lo..hi`.
    fn stats(exits: &[ExitPoint], values: &[Vec3], lo: f32, hi: f32) -> Stats {
        let (mut sum, mut max, mut total, mut count) = (0.0f64, 0.0f64, 0.0f64, 0usize);
        for (x, v) in exits.iter().zip(values) {
            if !(lo..hi).contains(&edge_distance(x.position)) {
                continue;
            }
            let value = v.element_sum() as f64 / 3.0;
            sum += (value - 1.0).abs();
            max = max.max((value - 1.0).abs());
            total += value;
            count += 1;
        }
        let n = count.max(1) as f64;
        Stats {
            mean: sum / n,
            max,
            bias: total / n - 1.0,
            count,
        }
    }

    fn describe(s: &Stats) -> String {
        format!(
            "{} exits: mean |err| {:.4}, max |err| {:.4}, bias {:+.4}",
            s.count, s.mean, s.max, s.bias
        )
    }

    /// About 18 s in the test profile on lavapipe: 2048 entries (512 are too few for the 2 % /
    /// 10 % bounds with the edge rule below, see [`EDGE_MARGIN`]), 4 walks each, 64² faces.
    #[test]
    fn furnace_sums_to_one_on_the_gpu() {
        let ctx = vulkan();
        let scene = furnace_box(3, 0.5);
        let walk_params = WalkParams {
            seed: 1,
            ..WalkParams::PREVIEW
        };
        let (atlas, bvh, entries, walks) = trace_scene(&scene, 32, EntryParams { count: 2048, seed: 1 }, walk_params);
        let exits: &[ExitPoint] = &atlas.exits;
        assert_eq!(walks.stats.escaped, 0, "rays leaked out of the closed box");
        eprintln!(
            "GPU furnace: {} exits, {} entries, {} VPLs",
            exits.len(),
            entries.len(),
            walks.vpls.len()
        );
        let params = PaneRenderParams {
            face_resolution: 64,
            ..PaneRenderParams::DEFAULT
        };
        let off_edges: Vec<usize> = (0..exits.len())
            .filter(|&i| edge_distance(exits[i].position) >= EDGE_MARGIN)
            .collect();
        assert!(off_edges.len() > exits.len() / 2, "most exit points are off the edges");
        let pick = |v: &[Vec3]| off_edges.iter().map(|&i| v[i]).collect::<Vec<_>>();
        let diag = scene.bounds().diagonal();
        for (name, clustering) in [
            ("identity", Clustering::identity(&entries)),
            (
                "kmeans-32",
                Clustering::kmeans(&entries, diag, &ClusterParams::with_clusters(32)).unwrap(),
            ),
        ] {
            let t = std::time::Instant::now();
            let inputs = PaneInputs {
                scene: &scene,
                exits,
                vpls: &walks,
                clustering: &clustering,
            };
            let (gpu, render) = prm_gpu::render_panes(&ctx, &inputs, &params).expect("GPU panes");
            let gpu_s = t.elapsed().as_secs_f64();
            assert_eq!(render.vpls as usize, walks.vpls.len());
            assert!(gpu.data.iter().all(|v| v.is_finite()));
            // Unit irradiance at every entry point: every cluster's weight is 1.
            let weights = clustering.weights(&vec![Vec3::ONE; entries.len()]);
            assert!(weights.iter().all(|w| *w == Vec3::ONE));
            let sum = gpu.combine(&weights);
            let t = std::time::Instant::now();
            let cpu = prm_trace::evaluate_panes(&bvh, &walks, &clustering, exits, &PaneParams::DEFAULT).unwrap();
            let cpu_s = t.elapsed().as_secs_f64();
            let cpu_sum = cpu.combine(&weights);
            let inner = stats(exits, &sum, EDGE_MARGIN, f32::INFINITY);
            let edge = stats(exits, &sum, 0.0, EDGE_MARGIN);
            let cpu_inner = stats(exits, &cpu_sum, EDGE_MARGIN, f32::INFINITY);
            let (rmse_panes, rmse_sum, rmse_sum_inner) = (
                relative_rmse(&gpu.data, &cpu.data),
                relative_rmse(&sum, &cpu_sum),
                relative_rmse(&pick(&sum), &pick(&cpu_sum)),
            );
            eprintln!(
                "GPU furnace, {name} ({} clusters; GPU {gpu_s:.2} s, CPU {cpu_s:.2} s):\n  \
                 GPU off the edges: {}\n  GPU on the edges (< {EDGE_MARGIN}): {}\n  \
                 CPU off the edges: {}\n  \
                 GPU vs CPU relative RMSE: per-cluster panes {rmse_panes:.4}, summed {rmse_sum:.4}, \
                 summed off the edges {rmse_sum_inner:.4}",
                clustering.len(),
                describe(&inner),
                describe(&edge),
                describe(&cpu_inner),
            );
            for (lo, hi) in [
                (0.0, 1e-4),
                (1e-4, 0.02),
                (0.02, 0.05),
                (0.05, 0.1),
                (0.1, 0.2),
                (0.2, 1.0),
            ] {
                let s = stats(exits, &sum, lo, hi);
                if s.count > 0 {
                    eprintln!("    distance to an edge {lo}..{hi}: {}", describe(&s));
                }
            }
            assert!(inner.mean < 0.02, "{name}: mean error {}", inner.mean);
            assert!(inner.max < 0.10, "{name}: max error {}", inner.max);
            // Same estimator, same VPL bound; only the visibility differs (depth maps vs shadow
            // rays), and in a convex box everything is visible.
            // Measured 0.0033 / 0.0009 per cluster and 0.0004 summed (identity / k-means).
            assert!(
                rmse_sum_inner < 0.002,
                "{name}: GPU vs CPU relative RMSE {rmse_sum_inner}"
            );
            assert!(
                rmse_panes < 0.005,
                "{name}: GPU vs CPU per-cluster relative RMSE {rmse_panes}"
            );
        }
    }
}

/// OpenGL (llvmpipe): plain compute works, the pane passes are refused with the backend's own
/// reason (GLSL has no `textureLoad` of depth textures) instead of wgpu's panic, which is what
/// lets `prm-bake bake --backend auto` pass over GL. CI installs the GL driver (`.ci/run`:
/// libegl1, libgl1-mesa-dri), so there a missing adapter fails; elsewhere it is reported.
#[test]
fn gl_runs_compute_and_refuses_the_pane_passes_cleanly() {
    let ctx = match GpuContext::new(Backend::Gl) {
        Ok(ctx) => ctx,
        Err(e) if std::env::var_os("CI").is_none() => {
            eprintln!("no OpenGL adapter here ({e}); not tested (apt-get install libegl1 libgl1-mesa-dri)");
            return;
        }
        Err(e) => panic!("CI installs the GL driver: {e}"),
    };
    eprintln!("adapter: {}", ctx.describe());
    assert_eq!(ctx.info.backend, wgpu::Backend::Gl);
    let xs: Vec<f32> = (0..64).map(|i| i as f32).collect();
    let ys = prm_gpu::smoke::run(&ctx, 2.0, 1.0, &xs).expect("compute on GL");
    assert!(xs.iter().zip(&ys).all(|(x, y)| *y == 2.0 * x + 1.0));
    let err = prm_gpu::check_support(&ctx).expect_err(
        "the pane passes now run on GL: make prm-bake's auto backend use it and test GL panes against the CPU",
    );
    assert!(err.to_string().contains("textureLoad"), "{err}");
    // The device is still usable after the refused pipeline.
    assert_eq!(prm_gpu::smoke::run(&ctx, 1.0, 0.0, &xs).unwrap(), xs);
}

/// On Vulkan the pane passes are supported.
#[test]
fn vulkan_supports_the_pane_passes() {
    prm_gpu::check_support(&vulkan()).expect("pane passes on Vulkan");
}
