//! Integration tests: white furnace, PRM panes vs the reference on the Cornell box, thread
//! independence. Measured numbers are printed (run with `--nocapture` to see them).

use std::path::PathBuf;

use glam::Vec3;
use prm_scene::{Atlas, AtlasParams, ExitPoint, Scene, Sizing};
use prm_trace::{
    entry_irradiance, evaluate_atlas_panes, evaluate_panes, parse_light, sample_surface, trace_walks, Bvh, BvhParams,
    ClusterParams, Clustering, Emitters, EntryParams, ImageMode, Lattice, Lighting, PaneParams, ReferenceParams,
    ReferenceTracer, SurfaceSample, VplBound, VplSet, WalkParams,
};

use prm_scene::analytic::furnace_box;

fn scene_path(rel: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..").join(rel)
}

/// (mean relative error, max relative error) of `values` (channel mean) against `expected`.
fn errors(values: &[Vec3], expected: &[Vec3]) -> (f64, f64) {
    let mut sum = 0.0;
    let mut max = 0.0f64;
    for (v, e) in values.iter().zip(expected) {
        let r = ((v.element_sum() / e.element_sum()) as f64 - 1.0).abs();
        sum += r;
        max = max.max(r);
    }
    (sum / values.len() as f64, max)
}

/// The preview walks from `entries`, seeded with `seed`.
fn preview_walks(scene: &Scene, bvh: &Bvh, entries: &[SurfaceSample], seed: u64) -> VplSet {
    trace_walks(
        scene,
        bvh,
        entries,
        &WalkParams {
            seed,
            ..WalkParams::PREVIEW
        },
    )
    .unwrap()
}

/// A reference of `passes` × `samples_per_pass` paths per exit point, seeded with `seed`.
fn reference_params(passes: u32, samples_per_pass: u32, seed: u64) -> ReferenceParams {
    ReferenceParams {
        passes,
        samples_per_pass,
        seed,
        ..ReferenceParams::PREVIEW
    }
}

fn mean_ratio(values: &[Vec3], expected: &[Vec3]) -> f64 {
    let a: f64 = values.iter().map(|v| v.element_sum() as f64).sum();
    let b: f64 = expected.iter().map(|v| v.element_sum() as f64).sum();
    a / b
}

/// Distance from `p` to the nearest edge of the unit cube (second smallest distance to a face plane).
fn edge_distance(p: Vec3) -> f32 {
    let mut d = [p.x, 1.0 - p.x, p.y, 1.0 - p.y, p.z, 1.0 - p.z];
    d.sort_by(|a, b| a.total_cmp(b));
    d[1]
}

/// Exit points closer than this to a box edge lie on it (the atlas puts the exit points of
/// partially covered border texels on the triangle's boundary); they are reported, not asserted.
const EDGE_MARGIN: f32 = 0.05;

fn split_report(label: &str, exits: &[ExitPoint], values: &[Vec3]) -> (f64, f64) {
    let (mut inner, mut inner_ref, mut edge, mut edge_ref) = (vec![], vec![], vec![], vec![]);
    for (x, v) in exits.iter().zip(values) {
        if edge_distance(x.position) >= EDGE_MARGIN {
            inner.push(*v);
            inner_ref.push(Vec3::ONE);
        } else {
            edge.push(*v);
            edge_ref.push(Vec3::ONE);
        }
    }
    let (mean, max) = errors(&inner, &inner_ref);
    let (emean, emax) = errors(&edge, &edge_ref);
    eprintln!(
        "{label}: {} exits off the edges: mean |err| {mean:.4}, max |err| {max:.4}, bias {:+.4}; \
         {} exits on box edges: mean |err| {emean:.4}, max {emax:.4}, bias {:+.4}",
        inner.len(),
        mean_ratio(&inner, &inner_ref) - 1.0,
        edge.len(),
        mean_ratio(&edge, &edge_ref) - 1.0,
    );
    (mean, max)
}

#[test]
fn furnace_panes_and_reference() {
    let scene = furnace_box(3, 0.5);
    let atlas = Atlas::build(&scene, &AtlasParams::with_sizing(Sizing::Resolution(32))).unwrap();
    let exits: &[ExitPoint] = &atlas.exits;
    let bvh = Bvh::build(&scene, &BvhParams::DEFAULT).unwrap();
    let entries = sample_surface(&scene, &EntryParams { count: 4096, seed: 1 }).unwrap();
    let walks = preview_walks(&scene, &bvh, &entries, 1);
    eprintln!(
        "furnace: {} exits, {} entries, {} VPLs, walk stats {:?}",
        exits.len(),
        entries.len(),
        walks.vpls.len(),
        walks.stats
    );
    assert_eq!(walks.stats.escaped, 0, "rays leaked out of the closed box");
    let diag = scene.bounds().diagonal();
    for (name, clustering) in [
        ("identity", Clustering::identity(&entries)),
        (
            "kmeans-64",
            Clustering::kmeans(&entries, diag, &ClusterParams::with_clusters(64)).unwrap(),
        ),
    ] {
        let panes = evaluate_panes(&bvh, &walks, &clustering, exits, &PaneParams::DEFAULT).unwrap();
        let weights = clustering.weights(&vec![Vec3::ONE; entries.len()]);
        let e = panes.combine(&weights);
        let (mean, max) = split_report(
            &format!("furnace panes, {name} ({} clusters)", clustering.len()),
            exits,
            &e,
        );
        assert!(mean < 0.02, "{name}: mean error {mean}");
        assert!(max < 0.10, "{name}: max error {max}");
        // The shared-visibility evaluator on the same walks: inside a closed box every VPL facing
        // an exit point is visible, so the lattice corners always agree.
        let shared = shared_panes(&bvh, &walks, &clustering, &atlas, &Lattice::DEFAULT);
        let (mean, max) = split_report(
            &format!("furnace, shared visibility, {name}"),
            exits,
            &shared.combine(&weights),
        );
        assert!(mean < 0.02, "{name}, shared visibility: mean error {mean}");
        assert!(max < 0.10, "{name}, shared visibility: max error {max}");
        // Measured 37 % of the rays: at 32² each face is a small chart, so many points lie at
        // chart borders (and tile edges), where every ray is cast.
        assert!(
            shared.rays * 2 < panes.rays,
            "{name}: {} of {} rays",
            shared.rays,
            panes.rays
        );
    }
    let reference = ReferenceTracer::new(&scene, &bvh, Lighting::UniformIrradiance(Vec3::ONE));
    // Per-path standard deviation here is about 0.7 (a geometric number of 0.5 terms): 2048 paths
    // give a standard error of 1.6 %.
    let params = reference_params(8, 256, 3);
    let est = reference.indirect_at_exits(exits, &params, &mut |_, _| {}).unwrap();
    let (mean, max) = split_report("furnace reference", exits, &est.mean);
    assert!(mean < 0.02 && max < 0.10);
}

struct CornellSetup {
    atlas_resolution: u32,
    entries: usize,
    clusters: usize,
    reference: ReferenceParams,
}

/// Cornell box with its README point light: PRM (direct irradiance at entry points × panes)
/// against the reference path tracer at the exit points. Returns (bias, relative RMSE, reference
/// relative noise) of the clustered PRM.
fn cornell_comparison(setup: &CornellSetup) -> (Vec<Clustered>, f64) {
    let scene = prm_scene::load(&scene_path("scenes/cornell-box/cornell-box.obj")).unwrap();
    let light = parse_light("point:0.278,0.5,0.2795:0.2347,0.1566,0.0418").unwrap();
    let atlas = Atlas::build(
        &scene,
        &AtlasParams::with_sizing(Sizing::Resolution(setup.atlas_resolution)),
    )
    .unwrap();
    let exits: &[ExitPoint] = &atlas.exits;
    let bvh = Bvh::build(&scene, &BvhParams::DEFAULT).unwrap();
    let entries = sample_surface(
        &scene,
        &EntryParams {
            count: setup.entries,
            seed: 7,
        },
    )
    .unwrap();
    let walks = preview_walks(&scene, &bvh, &entries, 7);
    let irradiance = entry_irradiance(&bvh, &[light], &entries);
    let reference = ReferenceTracer::new(&scene, &bvh, Lighting::Lights(std::slice::from_ref(&light)));
    let est = reference
        .indirect_at_exits(exits, &setup.reference, &mut |_, _| {})
        .unwrap();
    let n = exits.len() as f64;
    let ref_mean: f64 = est.mean.iter().map(|v| v.element_sum() as f64).sum::<f64>() / n;
    // Standard error of the reference (channel sums), RMS over exits, relative to the mean.
    let ref_noise = (est.variance.iter().map(|v| v.element_sum() as f64).sum::<f64>() / n).sqrt() / ref_mean;
    let diag = scene.bounds().diagonal();
    // Energy the default bound removes: the same panes without any bound.
    let unbounded = evaluate_panes(
        &bvh,
        &walks,
        &Clustering::identity(&entries),
        exits,
        &PaneParams { bound: VplBound::None },
    )
    .unwrap()
    .combine(&irradiance);
    let mut result = Vec::new();
    for (name, clustering) in [
        ("identity", Clustering::identity(&entries)),
        (
            "kmeans",
            Clustering::kmeans(&entries, diag, &ClusterParams::with_clusters(setup.clusters)).unwrap(),
        ),
    ] {
        let panes = evaluate_panes(&bvh, &walks, &clustering, exits, &PaneParams::DEFAULT).unwrap();
        let prm = panes.combine(&clustering.weights(&irradiance));
        let bias = mean_ratio(&prm, &est.mean) - 1.0;
        eprintln!(
            "cornell {name}: the default VPL bound keeps {:.4} of the unbounded estimate's energy \
             (unbounded vs reference: {:+.4})",
            mean_ratio(&prm, &unbounded),
            mean_ratio(&unbounded, &est.mean) - 1.0
        );
        let sq = |f: f64| {
            (prm.iter()
                .zip(&est.mean)
                .map(|(a, b)| (a.element_sum() as f64 / f - b.element_sum() as f64).powi(2))
                .sum::<f64>()
                / n)
                .sqrt()
                / ref_mean
        };
        let (rel_rmse, debiased) = (sq(1.0), sq(1.0 + bias));
        // Fully covered texels only: partially covered border texels put their exit point on the
        // triangle's boundary, where the VPL estimate is degenerate at concave edges.
        let inner: Vec<usize> = (0..exits.len()).filter(|&i| exits[i].coverage >= 0.999).collect();
        let inner_mean: f64 = inner.iter().map(|&i| est.mean[i].element_sum() as f64).sum::<f64>() / inner.len() as f64;
        let inner_bias = inner.iter().map(|&i| prm[i].element_sum() as f64).sum::<f64>()
            / inner.iter().map(|&i| est.mean[i].element_sum() as f64).sum::<f64>()
            - 1.0;
        let inner_rmse = (inner
            .iter()
            .map(|&i| ((prm[i].element_sum() - est.mean[i].element_sum()) as f64).powi(2))
            .sum::<f64>()
            / inner.len() as f64)
            .sqrt()
            / inner_mean;
        let inner_noise =
            (inner.iter().map(|&i| est.variance[i].element_sum() as f64).sum::<f64>() / inner.len() as f64).sqrt()
                / inner_mean;
        eprintln!(
            "cornell {name}: {} fully covered exits: bias {inner_bias:+.4}, relative RMSE {inner_rmse:.4}, reference noise {inner_noise:.4}",
            inner.len()
        );
        // What is left once the reference's own noise is taken out (in quadrature).
        let excess = (debiased * debiased - ref_noise * ref_noise).max(0.0).sqrt();
        eprintln!(
            "cornell {name} ({} clusters): {} exits, {} VPLs, reference {}x{} paths: mean bias {bias:+.4}, \
             relative RMSE {rel_rmse:.4} ({debiased:.4} without the bias), reference relative noise \
             {ref_noise:.4}, PRM error beyond the reference noise {excess:.4}",
            clustering.len(),
            exits.len(),
            walks.vpls.len(),
            setup.reference.passes,
            setup.reference.samples_per_pass,
        );
        result.push(Clustered {
            name,
            bias,
            rmse: rel_rmse,
        });
    }
    (result, ref_noise)
}

/// One clustering's result in [`cornell_comparison`]: the mean bias and the relative RMSE
/// against the reference.
struct Clustered {
    name: &'static str,
    bias: f64,
    rmse: f64,
}

/// Runs [`cornell_comparison`] (4096 entries, 256 clusters, a reference of `passes` ×
/// `samples_per_pass` paths) and checks the bias against `max_bias` and that the RMSE is at most
/// the reference's noise plus `prm_error` in quadrature (PRM's own error: VPL noise, the bound,
/// degenerate exit points on chart borders).
fn check_cornell(atlas_resolution: u32, passes: u32, samples_per_pass: u32, max_bias: f64, prm_error: f64) {
    let (results, noise) = cornell_comparison(&CornellSetup {
        atlas_resolution,
        entries: 4096,
        clusters: 256,
        reference: reference_params(passes, samples_per_pass, 11),
    });
    assert_eq!(results.len(), 2, "identity and k-means clusterings");
    for Clustered { name, bias, rmse } in results {
        assert!(bias.abs() < max_bias, "{name}: bias {bias}");
        assert!(
            rmse * rmse < noise * noise + prm_error * prm_error,
            "{name}: relative RMSE {rmse} vs reference noise {noise}"
        );
    }
}

/// Measured (seeded, so the same on every machine): bias +0.0089 (identity) and +0.0071
/// (k-means); error beyond the reference's 9.3% noise 0.118 and 0.115. The bounds sit just above.
#[test]
fn cornell_panes_match_reference() {
    check_cornell(32, 4, 128, 0.015, 0.13);
}

/// The same comparison at higher sample counts (about 15 s in release).
#[test]
#[ignore]
fn cornell_panes_match_reference_heavy() {
    check_cornell(48, 16, 256, 0.03, 0.11);
}

/// Same seed, same output with 1 and 2 threads: entry points, walks, clustering, panes, reference.
#[test]
fn results_do_not_depend_on_thread_count() {
    let scene = prm_scene::load(&scene_path("scenes/cornell-box/cornell-box.obj")).unwrap();
    let light = parse_light("point:0.278,0.5,0.2795:0.2347,0.1566,0.0418").unwrap();
    let atlas = Atlas::build(&scene, &AtlasParams::with_sizing(Sizing::Resolution(16))).unwrap();
    let run = || {
        let bvh = Bvh::build(&scene, &BvhParams::DEFAULT).unwrap();
        let entries = sample_surface(&scene, &EntryParams { count: 256, seed: 5 }).unwrap();
        let walks = preview_walks(&scene, &bvh, &entries, 5);
        let clustering = Clustering::kmeans(
            &entries,
            scene.bounds().diagonal(),
            &ClusterParams {
                clusters: 32,
                seed: 5,
                ..ClusterParams::PAPER
            },
        )
        .unwrap();
        let panes = evaluate_panes(&bvh, &walks, &clustering, &atlas.exits, &PaneParams::DEFAULT).unwrap();
        let shared = shared_panes(&bvh, &walks, &clustering, &atlas, &Lattice::DEFAULT);
        let reference = ReferenceTracer::new(&scene, &bvh, Lighting::Lights(std::slice::from_ref(&light)));
        let params = reference_params(2, 4, 5);
        let est = reference
            .indirect_at_exits(&atlas.exits, &params, &mut |_, _| {})
            .unwrap();
        let camera = scene
            .cameras
            .first()
            .copied()
            .unwrap_or(prm_trace::parse_camera("0.278,0.273,-0.8:0.278,0.273,0:39.3076").unwrap());
        let image = reference
            .render(&camera, 16, 16, prm_trace::ImageMode::Full, &params, &mut |_, _| {})
            .unwrap();
        (entries, walks, clustering, panes, shared, est, image)
    };
    let pool = |n| rayon::ThreadPoolBuilder::new().num_threads(n).build().unwrap();
    let one = pool(1).install(run);
    let two = pool(2).install(run);
    assert!(one == two, "results differ between 1 and 2 threads");
}

/// The atlas evaluator with the default bound and no progress.
fn shared_panes(
    bvh: &Bvh,
    walks: &VplSet,
    clustering: &Clustering,
    atlas: &Atlas,
    lattice: &Lattice,
) -> prm_trace::Panes {
    evaluate_atlas_panes(
        bvh,
        walks,
        clustering,
        atlas,
        &PaneParams::DEFAULT,
        lattice,
        &mut |_| {},
    )
    .unwrap()
}

/// The relative L2 difference of `a` from `b` over every value, and the energy ratio Σa / Σb.
fn relative_difference(a: &[Vec3], b: &[Vec3]) -> (f64, f64) {
    let (mut d2, mut r2) = (0.0f64, 0.0f64);
    for (x, y) in a.iter().zip(b) {
        d2 += (*x - *y).as_dvec3().length_squared();
        r2 += y.as_dvec3().length_squared();
    }
    ((d2 / r2).sqrt(), mean_ratio(a, b))
}

/// The Cornell box's walks and k-means clusters at an atlas of `resolution`².
fn cornell_walks(resolution: u32) -> (Scene, Atlas, Bvh, VplSet, Clustering) {
    let scene = prm_scene::load(&scene_path("scenes/cornell-box/cornell-box.obj")).unwrap();
    let atlas = Atlas::build(&scene, &AtlasParams::with_sizing(Sizing::Resolution(resolution))).unwrap();
    let bvh = Bvh::build(&scene, &BvhParams::DEFAULT).unwrap();
    let entries = sample_surface(&scene, &EntryParams { count: 256, seed: 3 }).unwrap();
    let walks = preview_walks(&scene, &bvh, &entries, 3);
    let clustering =
        Clustering::kmeans(&entries, scene.bounds().diagonal(), &ClusterParams::with_clusters(16)).unwrap();
    (scene, atlas, bvh, walks, clustering)
}

/// With step 1 the atlas evaluator casts every ray and gives the list evaluator's panes exactly
/// (the entry energies are summed in another order, so they agree to rounding).
#[test]
fn exact_lattice_is_the_list_evaluator() {
    let (_, atlas, bvh, walks, clustering) = cornell_walks(32);
    let list = evaluate_panes(&bvh, &walks, &clustering, &atlas.exits, &PaneParams::DEFAULT).unwrap();
    let mut calls = Vec::new();
    let tiled = evaluate_atlas_panes(
        &bvh,
        &walks,
        &clustering,
        &atlas,
        &PaneParams::DEFAULT,
        &Lattice::EXACT,
        &mut |done| calls.push(done),
    )
    .unwrap();
    assert!(tiled.data == list.data, "panes differ");
    assert_eq!(tiled.rays, list.rays);
    let (diff, energy) = relative_difference(&tiled.entry_energy, &list.entry_energy);
    assert!(
        diff < 1e-5 && (energy - 1.0).abs() < 1e-6,
        "entry energies: {diff} {energy}"
    );
    assert_eq!(
        calls.last().copied(),
        Some(atlas.exits.len() as u64),
        "progress ends at every exit point"
    );
    assert!(calls.windows(2).all(|w| w[0] < w[1]), "progress only grows: {calls:?}");
}

/// Sharing the shadow rays of a lattice keeps the panes close to exact while casting far fewer
/// rays. On the default bake (256², 10,668 VPLs) the measured difference is 0.57 % (relative L2
/// over all pane values, step 4) with 15 % of the exact rays; this 64² atlas has coarser texels,
/// so more of them lie at shadow edges and chart borders.
#[test]
fn shared_visibility_stays_close_to_exact() {
    let (_, atlas, bvh, walks, clustering) = cornell_walks(64);
    let run = |lattice: &Lattice| {
        evaluate_atlas_panes(
            &bvh,
            &walks,
            &clustering,
            &atlas,
            &PaneParams::DEFAULT,
            lattice,
            &mut |_| {},
        )
        .unwrap()
    };
    let exact = run(&Lattice::EXACT);
    for step in [2, 4, 8] {
        let shared = run(&Lattice { step });
        let (diff, energy) = relative_difference(&shared.data, &exact.data);
        let rays = shared.rays as f64 / exact.rays as f64;
        eprintln!("lattice step {step}: difference {diff:.4}, energy {energy:.5}, rays {rays:.3} of exact");
        assert!(diff < 0.02, "step {step}: panes differ from exact by {diff}");
        assert!((energy - 1.0).abs() < 0.005, "step {step}: energy {energy}");
        assert!(rays < 0.6, "step {step}: {rays} of the exact rays");
    }
    let e = evaluate_atlas_panes(
        &bvh,
        &walks,
        &clustering,
        &atlas,
        &PaneParams::DEFAULT,
        &Lattice { step: 3 },
        &mut |_| {},
    );
    assert!(
        matches!(e, Err(prm_trace::TraceError::InvalidParameter(_))),
        "step 3 accepted"
    );
}

/// The emissive furnace's albedo and emitted radiance.
const FURNACE_RHO: f32 = 0.6;
const FURNACE_LE: Vec3 = Vec3::new(1.0, 0.5, 0.25);

/// The emissive furnace: a closed box whose every surface emits `L_e` and reflects `ρ`
/// ([`FURNACE_LE`], [`FURNACE_RHO`]), with its BVH and emitters. Radiance is `L = L_e / (1 − ρ)`
/// everywhere, so at every point the emitters' direct irradiance is `π L_e`, the indirect
/// irradiance `π (L − L_e) = π L_e ρ / (1 − ρ)`, and an image shows `L`.
fn emissive_furnace() -> (Scene, Bvh, Emitters) {
    let mut scene = furnace_box(2, FURNACE_RHO);
    scene.materials[0].emission = FURNACE_LE;
    let bvh = Bvh::build(&scene, &BvhParams::DEFAULT).unwrap();
    let emitters = Emitters::from_scene(&scene);
    (scene, bvh, emitters)
}

#[test]
fn emissive_furnace_matches_the_closed_form() {
    let (rho, le) = (FURNACE_RHO, FURNACE_LE);
    let (scene, bvh, emitters) = emissive_furnace();
    let atlas = Atlas::build(&scene, &AtlasParams::with_sizing(Sizing::Resolution(16))).unwrap();
    assert_eq!(emitters.groups.len(), 1);
    assert_eq!(emitters.groups[0].triangles as usize, scene.triangles.len());
    let tracer = ReferenceTracer::new(&scene, &bvh, Lighting::Lights(&[])).with_emitters(&emitters);
    let pi = std::f32::consts::PI;

    let direct = tracer.direct_at_exits(&atlas.exits);
    let expected_direct = vec![le * pi; direct.len()];
    let ratio = mean_ratio(&direct, &expected_direct);
    let (mean, max) = errors(&direct, &expected_direct);
    eprintln!("emissive furnace: direct energy {ratio:.4}, mean error {mean:.4}, max {max:.4}");
    assert!((ratio - 1.0).abs() < 0.01, "direct energy {ratio}");
    assert!(mean < 0.05, "direct mean error {mean}");

    let est = tracer
        .indirect_at_exits(&atlas.exits, &reference_params(16, 64, 3), &mut |_, _| {})
        .unwrap();
    let expected = vec![le * pi * rho / (1.0 - rho); est.mean.len()];
    let ratio = mean_ratio(&est.mean, &expected);
    let (mean, max) = errors(&est.mean, &expected);
    eprintln!("emissive furnace: indirect energy {ratio:.4}, mean error {mean:.4}, max {max:.4}");
    assert!((ratio - 1.0).abs() < 0.01, "indirect energy {ratio}");
    assert!(mean < 0.05, "indirect mean error {mean}");

    let camera = prm_scene::Camera {
        eye: scene.bounds().min + scene.bounds().extent() * Vec3::new(0.5, 0.5, 0.9),
        target: scene.bounds().min + scene.bounds().extent() * Vec3::new(0.5, 0.5, 0.0),
        fov_y_deg: 60.0,
    };
    let img = tracer
        .render(
            &camera,
            16,
            16,
            ImageMode::Full,
            &reference_params(4, 32, 5),
            &mut |_, _| {},
        )
        .unwrap();
    let expected = vec![le / (1.0 - rho); img.mean.len()];
    let ratio = mean_ratio(&img.mean, &expected);
    eprintln!("emissive furnace: image energy {ratio:.4}");
    assert!((ratio - 1.0).abs() < 0.01, "image energy {ratio}");
}

/// Pixel centres that meet the edge where two surfaces join (a camera looking square at a box's
/// floor–wall edge puts a whole row of them on it) see the same radiance as their neighbours:
/// in the emissive furnace every pixel shows `L_e / (1 − ρ)`.
#[test]
fn pixels_on_an_edge_between_two_surfaces_are_not_dark() {
    let (scene, bvh, emitters) = emissive_furnace();
    let tracer = ReferenceTracer::new(&scene, &bvh, Lighting::Lights(&[])).with_emitters(&emitters);
    // Looking from the centre at the middle of the floor's edge with the wall z = 0: the edge
    // is the image's middle row (9 rows, row 4 on the optical axis).
    let camera = prm_scene::Camera {
        eye: Vec3::splat(0.5),
        target: Vec3::new(0.5, 0.0, 0.0),
        fov_y_deg: 40.0,
    };
    let (w, h) = (9usize, 9usize);
    let img = tracer
        .render(
            &camera,
            w as u32,
            h as u32,
            ImageMode::Full,
            &reference_params(4, 64, 7),
            &mut |_, _| {},
        )
        .unwrap();
    let expected = (FURNACE_LE / (1.0 - FURNACE_RHO)).element_sum();
    let row_mean = |y: usize| {
        img.mean[y * w..(y + 1) * w]
            .iter()
            .map(|v| v.element_sum())
            .sum::<f32>()
            / (w as f32 * expected)
    };
    let rows: Vec<f32> = (0..h).map(row_mean).collect();
    eprintln!("row means over L: {rows:?}");
    for (y, r) in rows.iter().enumerate() {
        assert!((r - 1.0).abs() < 0.03, "row {y}: {r} of L");
    }
}

/// A pixel's visible point takes its light about its shading normal, as an exit point does and
/// as the player shades it: a floor whose vertex normals lean 16.7° off its plane's, under a
/// point light straight above the pixel, sends albedo/π × I cos θ / d² with θ the shading
/// normal's (0.958), not the plane's (1).
#[test]
fn a_pixel_takes_its_light_about_its_shading_normal() {
    let lean = Vec3::new(0.3, 1.0, 0.0).normalize();
    let corners = [
        Vec3::new(-1.0, 0.0, -1.0),
        Vec3::new(1.0, 0.0, -1.0),
        Vec3::new(1.0, 0.0, 1.0),
        Vec3::new(-1.0, 0.0, 1.0),
    ];
    let triangles = [[0, 2, 1], [0, 3, 2]]
        .iter()
        .map(|ix| {
            let mut t = prm_scene::Triangle::flat(ix.map(|i| corners[i]), 0);
            t.normals = [lean; 3];
            t
        })
        .collect();
    let albedo = Vec3::splat(0.5);
    let scene = Scene::from_parts(triangles, vec![prm_scene::Material::diffuse("floor", albedo)]);
    let bvh = Bvh::build(&scene, &BvhParams::DEFAULT).unwrap();
    let intensity = Vec3::splat(2.0);
    let lights = [prm_scene::Light::Point {
        position: Vec3::new(0.0, 1.0, 0.0),
        intensity,
    }];
    let tracer = ReferenceTracer::new(&scene, &bvh, Lighting::Lights(&lights));
    let camera = prm_scene::Camera {
        eye: Vec3::new(0.0, 0.5, 0.0) + Vec3::new(0.0, 0.0, 0.01),
        target: Vec3::ZERO,
        fov_y_deg: 10.0,
    };
    let img = tracer
        .render(
            &camera,
            1,
            1,
            ImageMode::Full,
            &reference_params(1, 1, 3),
            &mut |_, _| {},
        )
        .unwrap();
    // The point seen is within 0.2 mm of the origin, 1 below the light.
    let expected = albedo * std::f32::consts::FRAC_1_PI * intensity * lean.dot(Vec3::Y);
    let ratio = img.mean[0] / expected;
    eprintln!("pixel over albedo/π × I cos θ_shading: {ratio}");
    assert!((ratio - Vec3::ONE).abs().max_element() < 0.002, "{ratio}");
}
