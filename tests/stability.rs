//! Stability where the method is known to fail (end to end: bakes through `prm_bake::bake`,
//! playback through `prm_play::Renderer`, ground truth from `prm_trace::ReferenceTracer`): VPL spikes, flicker under a moving light, a light
//! touching a wall, leaks through a shut door, shadow edges and corners inside clusters, and
//! degenerate or extreme inputs. Each test prints what it measured (`--nocapture`) and asserts a
//! threshold set from that measurement with a margin, so it fails when the method gets worse.

use std::path::{Path, PathBuf};

use glam::Vec3;
use prm_gpu::{GpuContext, PaneInputs, PaneRenderParams};
use prm_scene::{Atlas, AtlasParams, Light, Scene, Sizing};
use prm_trace::{
    Bvh, BvhParams, Clustering, EntryParams, Lighting, Panes, ReferenceParams, ReferenceTracer, SurfaceSample,
    VplBound, WalkParams,
};

use prm_tests::{gpu, repo};

/// A bake done through the libraries, kept in memory: what the archive would hold, unquantised.
struct Bake {
    scene: Scene,
    bvh: Bvh,
    atlas: Atlas,
    entries: Vec<SurfaceSample>,
    clustering: Clustering,
    panes: Panes,
}

struct Sizes {
    resolution: u32,
    entries: usize,
    /// `None`: one cluster per entry point (unclustered).
    clusters: Option<usize>,
    walks: u32,
    bound: VplBound,
}

const SMALL: Sizes = Sizes {
    resolution: 64,
    entries: 1024,
    clusters: Some(64),
    walks: 2,
    bound: VplBound::DEFAULT,
};

impl Bake {
    fn new(ctx: &GpuContext, scene: Scene, s: &Sizes) -> Bake {
        let atlas = Atlas::build(&scene, &AtlasParams::with_sizing(Sizing::Resolution(s.resolution))).unwrap();
        let bvh = Bvh::build(&scene, &BvhParams::DEFAULT).unwrap();
        let entries = prm_trace::sample_surface(
            &scene,
            &EntryParams {
                count: s.entries,
                seed: 3,
            },
        )
        .unwrap();
        let vpls = prm_trace::trace_walks(
            &scene,
            &bvh,
            &entries,
            &WalkParams {
                walks_per_entry: s.walks,
                seed: 3,
                ..WalkParams::PREVIEW
            },
        )
        .unwrap();
        let clustering = match s.clusters {
            None => Clustering::identity(&entries),
            Some(c) => Clustering::kmeans_separated(&entries, &bvh, scene.bounds().diagonal(), c, 3).unwrap(),
        };
        let params = PaneRenderParams {
            bound: s.bound,
            face_resolution: 128,
            ..PaneRenderParams::DEFAULT
        };
        let inputs = PaneInputs {
            scene: &scene,
            exits: &atlas.exits,
            vpls: &vpls,
            clustering: &clustering,
        };
        let (panes, _) = prm_gpu::render_panes(ctx, &inputs, &params).unwrap();
        Bake {
            scene,
            bvh,
            atlas,
            entries,
            clustering,
            panes,
        }
    }

    /// Indirect irradiance at the exit points with every cluster kept (weights: the members'
    /// entry irradiance weighed by their pane energy, as the player computes them).
    fn indirect(&self, lights: &[Light]) -> Vec<Vec3> {
        let irradiance = prm_trace::entry_irradiance(&self.bvh, lights, &self.entries);
        self.panes
            .combine(&self.clustering.weights_by_energy(&irradiance, &self.panes.entry_energy))
    }

    /// The path tracer's indirect irradiance at the same exit points, and its relative noise.
    fn reference(&self, lights: &[Light], spp: u32, seed: u64) -> (Vec<Vec3>, f64) {
        let tracer = ReferenceTracer::new(&self.scene, &self.bvh, Lighting::Lights(lights));
        let params = ReferenceParams {
            seed,
            ..ReferenceParams::with_spp(spp)
        };
        let e = tracer
            .indirect_at_exits(&self.atlas.exits, &params, &mut |_, _| {})
            .unwrap();
        let noise = (e.variance.iter().map(|v| v.element_sum() as f64).sum::<f64>()
            / e.mean
                .iter()
                .map(|m| m.length_squared() as f64)
                .sum::<f64>()
                .max(1e-300))
        .sqrt();
        (e.mean, noise)
    }
}

fn point(position: Vec3, intensity: f32) -> Light {
    Light::Point {
        position,
        intensity: Vec3::splat(intensity),
    }
}

/// sqrt(Σ|a − b|² / Σ|b|²).
fn rel_rmse(a: &[Vec3], b: &[Vec3]) -> f64 {
    let (mut e, mut n) = (0.0f64, 0.0f64);
    for (x, y) in a.iter().zip(b) {
        e += (*x - *y).length_squared() as f64;
        n += y.length_squared() as f64;
    }
    (e / n.max(1e-300)).sqrt()
}

fn luminance(v: Vec3) -> f64 {
    (0.2126 * v.x + 0.7152 * v.y + 0.0722 * v.z) as f64
}

/// Largest over mean luminance.
fn peak_to_mean(v: &[Vec3]) -> f64 {
    let max = v.iter().map(|x| luminance(*x)).fold(0.0, f64::max);
    let mean = v.iter().map(|x| luminance(*x)).sum::<f64>() / v.len().max(1) as f64;
    max / mean.max(1e-300)
}

fn all_finite(v: &[Vec3]) -> bool {
    v.iter().all(|x| x.is_finite())
}

fn cornell() -> Scene {
    prm_scene::load(&repo("scenes/cornell-box/cornell-box.obj")).unwrap()
}

/// 1. VPLs in corners and narrow gaps: a light low in a corner puts most VPLs next to the two
///    walls and the floor that meet there, where an unbounded 1/r² blows up.
#[test]
fn spikes_near_corner_vpls_are_bounded() {
    let ctx = gpu();
    let b = cornell().bounds();
    let light = [point(b.min + (b.max - b.min) * Vec3::new(0.08, 0.08, 0.5), 0.1)];
    let mut ratios = Vec::new();
    let mut reference = None;
    for bound in [VplBound::DEFAULT, VplBound::None] {
        let bake = Bake::new(
            &ctx,
            cornell(),
            &Sizes {
                bound,
                clusters: None,
                ..SMALL
            },
        );
        let prm = bake.indirect(&light);
        assert!(all_finite(&prm), "{bound:?}: non-finite indirect light");
        let (r, noise) = reference.get_or_insert_with(|| bake.reference(&light, 1024, 7)).clone();
        let (p, q) = (peak_to_mean(&prm), peak_to_mean(&r));
        eprintln!(
            "spikes {bound:?}: peak/mean PRM {p:.2}, reference {q:.2} (noise {noise:.3}); rel. RMSE {:.3}",
            rel_rmse(&prm, &r)
        );
        ratios.push(p / q);
    }
    // Measured: bounded 0.86x, unbounded 1.8x the reference's peak-to-mean.
    assert!(ratios[0] < 1.5, "bounded VPLs spike {:.2}x the reference", ratios[0]);
    assert!(
        ratios[1] > ratios[0],
        "without the bound the spikes should be worse ({ratios:?}); is the bound still applied?"
    );
}

/// 3. A light 1% of the scene's size away from the back wall: the entry irradiance under it is
///    extreme, the cluster means are dominated by a few entries.
#[test]
fn light_touching_a_wall_stays_finite_and_bounded() {
    let ctx = gpu();
    let scene = cornell();
    let b = scene.bounds();
    let diagonal = b.diagonal();
    // The back wall is the far side along +z (the camera looks +z through the open front).
    let at = Vec3::new(
        (b.min.x + b.max.x) / 2.0,
        (b.min.y + b.max.y) / 2.0,
        b.max.z - 0.01 * diagonal,
    );
    let light = [point(at, 0.05)];
    let bake = Bake::new(&ctx, scene, &SMALL);
    let prm = bake.indirect(&light);
    assert!(all_finite(&prm), "non-finite indirect light");
    let (r, noise) = bake.reference(&light, 1024, 11);
    let e = rel_rmse(&prm, &r);
    eprintln!("light at 1% of the diagonal from a wall: rel. RMSE {e:.3} (reference noise {noise:.3})");
    // Measured 0.45, the reference's own noise being 0.28; 1.02 before entry irradiance was
    // bounded (prm_trace::entry_irradiance): the irradiance peak under the light is ~1 cm wide,
    // the entry points ~4 cm apart, so a cluster's mean caught the peak at full height or missed.
    assert!(e < 0.6, "error {e:.3} with the light against the wall");
}

/// 4. Leaks: light in room A of `two-rooms-closed`; room B can only be lit through the walls.
#[test]
fn no_light_leaks_through_a_shut_door() {
    let ctx = gpu();
    let scene = prm_scene::load(&repo("scenes/two-rooms/two-rooms-closed.obj")).unwrap();
    let light = [point(Vec3::new(1.5, 2.2, 3.5), 5.0)];
    let bake = Bake::new(
        &ctx,
        scene,
        &Sizes {
            resolution: 96,
            ..SMALL
        },
    );
    let prm = bake.indirect(&light);
    let (mut a, mut na, mut bsum, mut nb) = (0.0, 0, 0.0, 0);
    for (e, v) in bake.atlas.exits.iter().zip(&prm) {
        // Room A: x < 4 m; room B: x > 4.05 m (the wall between).
        if e.position.x < 3.99 {
            a += luminance(*v);
            na += 1;
        } else if e.position.x > 4.06 {
            bsum += luminance(*v);
            nb += 1;
        }
    }
    let (a, bmean) = (a / na as f64, bsum / nb as f64);
    eprintln!(
        "leaks: mean indirect room A {a:.4}, room B {bmean:.2e} ({:.4}%)",
        100.0 * bmean / a
    );
    assert!(na > 0 && nb > 0);
    // Measured 0.38% (1.27% if k-means puts the floors on both sides of the wall into one
    // cluster, which splitting clusters by visibility prevents). The bound is 1%.
    assert!(
        bmean <= 0.01 * a,
        "room B gets {:.3}% of room A's indirect light",
        100.0 * bmean / a
    );
}

/// 5a. Clusters that straddle a corner would blend light from surfaces facing apart: k-means on
///     position and normal keeps every cluster on one side of the Cornell box's corners.
/// 5b. A hard shadow edge through a cluster: the tall block's shadow on the floor. The cluster's
///     weight averages lit and shadowed entries; the error against the reference, clustered and
///     unclustered, shows what that costs.
#[test]
fn corners_split_clusters_and_shadow_edges_cost_little() {
    let ctx = gpu();
    let clustered = Bake::new(&ctx, cornell(), &SMALL);
    let mut worst = 0.0f32;
    for (c, members) in clustered.clustering.members.iter().enumerate() {
        let n = clustered.clustering.normals[c];
        for &k in members {
            worst = worst.max(clustered.entries[k as usize].normal.angle_between(n).to_degrees());
        }
    }
    eprintln!("corners: widest angle between an entry and its cluster's normal {worst:.1}°");
    assert!(worst < 45.0, "a cluster straddles a corner ({worst:.1}°)");

    // A light low and to the side, so the blocks cast long shadows across the floor.
    let b = clustered.scene.bounds();
    let light = [point(b.min + (b.max - b.min) * Vec3::new(0.9, 0.35, 0.5), 0.1)];
    let unclustered = Bake::new(
        &ctx,
        cornell(),
        &Sizes {
            clusters: None,
            ..SMALL
        },
    );
    let (r, noise) = clustered.reference(&light, 1024, 5);
    let (ec, eu) = (
        rel_rmse(&clustered.indirect(&light), &r),
        rel_rmse(&unclustered.indirect(&light), &r),
    );
    eprintln!("shadow edge: rel. RMSE clustered (64) {ec:.3}, unclustered (1024) {eu:.3}, reference noise {noise:.3}");
    // Measured 0.25 and 0.17 (reference noise 0.06): a cluster's weight averages lit and
    // shadowed entry points, so its pane lights both sides of the edge alike; 64 clusters cost
    // 1.6x the unclustered error here. Clustering by position and normal cannot see shadows (they
    // move with the light); more clusters, or a larger K at run time, is the remedy.
    assert!(ec < 0.35 && eu < 0.22, "clustered {ec:.3}, unclustered {eu:.3}");
    assert!(ec < eu * 2.0, "clustering costs {:.2}x the unclustered error", ec / eu);
}

/// Writes `scene` as OBJ + MTL into `dir` with every vertex scaled by `scale` and every albedo
/// replaced by `albedo` (when given); returns the OBJ's path.
fn variant(dir: &Path, name: &str, scale: f32, albedo: Option<f32>) -> PathBuf {
    let src = std::fs::read_to_string(repo("scenes/cornell-box/cornell-box.obj")).unwrap();
    let mtl = std::fs::read_to_string(repo("scenes/cornell-box/cornell-box.mtl")).unwrap();
    let obj: String = src
        .lines()
        .map(|l| match l.strip_prefix("v ") {
            Some(rest) => {
                let v: Vec<f32> = rest.split_whitespace().map(|x| x.parse().unwrap()).collect();
                format!("v {} {} {}\n", v[0] * scale, v[1] * scale, v[2] * scale)
            }
            None if l.starts_with("mtllib") => format!("mtllib {name}.mtl\n"),
            None => format!("{l}\n"),
        })
        .collect();
    let mtl: String = mtl
        .lines()
        .map(|l| match (l.starts_with("Kd "), albedo) {
            (true, Some(a)) => format!("Kd {a} {a} {a}\n"),
            _ => format!("{l}\n"),
        })
        .collect();
    std::fs::write(dir.join(format!("{name}.mtl")), mtl).unwrap();
    let path = dir.join(format!("{name}.obj"));
    std::fs::write(&path, obj).unwrap();
    path
}

/// Bakes `scene` through the library (`prm_bake::bake`, on Vulkan) at 32² and seed 2 into
/// `dir/NAME.prm` (NAME: the scene's stem), as `prm-bake bake --resolution 32 --seed 2` does.
fn bake_small(dir: &Path, scene: &Path, entries: &str, clusters: &str, walks: &str) -> PathBuf {
    let out = dir.join(format!("{}.prm", scene.file_stem().unwrap().to_string_lossy()));
    let loaded = prm_scene::load(scene).unwrap();
    let config = prm_bake::BakeConfig {
        entries: Some(entries.parse().unwrap()),
        clusters: Some(clusters.parse().unwrap()),
        resolution: Some(32),
        paths_per_entry: Some(walks.parse().unwrap()),
        seed: Some(2),
        ..Default::default()
    };
    let plan = prm_bake::Plan::new(&config, &loaded).unwrap();
    let job = prm_bake::BakeJob {
        scene: &loaded,
        scene_path: scene,
        plan: &plan,
        output: &out,
        shard: None,
    };
    let ctx = gpu();
    if let Err(e) = prm_bake::bake(&job, prm_bake::Renderer::Gpu(&ctx), &mut prm_bake::NoProgress) {
        panic!("bake of {} failed: {e}", scene.display());
    }
    out
}

/// Bakes `scene` (see [`bake_small`], one walk per entry) and returns every pane, decoded.
fn bake_binary(dir: &Path, scene: &Path, entries: &str, clusters: &str) -> Vec<Vec<[f32; 3]>> {
    let mut a = prm_format::Archive::open(bake_small(dir, scene, entries, clusters, "1")).unwrap();
    a.verify().unwrap();
    (0..a.pane_count()).map(|p| a.read_pane(p).unwrap()).collect()
}

fn pane_sum(panes: &[Vec<[f32; 3]>]) -> f64 {
    panes.iter().flatten().map(|t| (t[0] + t[1] + t[2]) as f64).sum()
}

/// 6. Degenerate and extreme inputs, end to end through the bake pipeline (`prm_bake::bake`).
#[test]
fn degenerate_and_extreme_inputs_bake_to_finite_archives() {
    let dir = prm_tests::temp_dir("stability-extreme");
    // One triangle: walks leave at once, no surface lights another; every pane is zero.
    let one = dir.join("one.obj");
    std::fs::write(&one, "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n").unwrap();
    let panes = bake_binary(&dir, &one, "16", "4");
    assert!(panes.iter().flatten().all(|t| t.iter().all(|x| *x == 0.0)));

    // Panes are irradiance per unit irradiance: dimensionless, so scaling the scene by 1e4 or
    // 1e-3 must not change them (only float rounding in the sampling).
    let base = pane_sum(&bake_binary(&dir, &variant(&dir, "unit", 1.0, None), "256", "16"));
    for scale in [1e4f32, 1e-3] {
        let s = pane_sum(&bake_binary(
            &dir,
            &variant(&dir, &format!("scaled-{scale}"), scale, None),
            "256",
            "16",
        ));
        eprintln!("scale {scale:e}: Σ panes {s:.4} against {base:.4} at scale 1");
        // Measured 0.02% at 1e4 and 1.8% at 1e-3 (some tolerance in the pipeline is not yet
        // relative to the scene's size).
        assert!(
            s.is_finite() && (s / base - 1.0).abs() < 0.03,
            "scale {scale:e}: Σ {s} vs {base}"
        );
    }

    // Very dark and very bright albedo: finite, and the bright box multiplies light many times
    // over (interreflection ∝ ρ / (1 − ρ)), the dark one barely at all.
    let dark = pane_sum(&bake_binary(&dir, &variant(&dir, "dark", 1.0, Some(0.01)), "256", "16"));
    let bright = pane_sum(&bake_binary(
        &dir,
        &variant(&dir, "bright", 1.0, Some(0.99)),
        "256",
        "16",
    ));
    eprintln!("albedo 0.01: Σ panes {dark:.4}; 0.99: {bright:.4}; 0.74 (white walls): {base:.4}");
    assert!(dark.is_finite() && bright.is_finite());
    assert!(
        dark > 0.0 && dark < 0.05 * base && bright > 2.0 * base,
        "dark {dark}, bright {bright}"
    );
}

/// Mean and largest relative frame-to-frame change Σ|L_t − L_{t−1}| / Σ|L_t| over a path, and
/// the step of the largest.
fn changes_at(frames: &[Vec<Vec3>]) -> (f64, f64, usize) {
    let d: Vec<f64> = frames
        .windows(2)
        .map(|w| {
            let diff: f64 = w[0]
                .iter()
                .zip(&w[1])
                .map(|(a, b)| (*a - *b).abs().element_sum() as f64)
                .sum();
            let size: f64 = w[1].iter().map(|b| b.element_sum() as f64).sum();
            diff / size.max(1e-300)
        })
        .collect();
    let (at, max) = d
        .iter()
        .copied()
        .enumerate()
        .fold((0, 0.0), |a, (i, x)| if x > a.1 { (i, x) } else { a });
    (d.iter().sum::<f64>() / d.len() as f64, max, at)
}

/// Mean and largest relative frame-to-frame change over a path.
fn changes(frames: &[Vec<Vec3>]) -> (f64, f64) {
    let (mean, max, _) = changes_at(frames);
    (mean, max)
}

/// 2. Flicker and popping: a light moving along a path in 120 small steps, played back by the
///    player (GPU weights, top-K with fade) from archives baked by `prm_bake::bake`; its frame-to-frame
///    change against the reference's own change for the same steps, clustered and unclustered,
///    several K.
#[test]
fn moving_light_does_not_flicker_or_pop() {
    use prm_play::{FrameInput, Mode, PlayOptions, Renderer};
    let dir = prm_tests::temp_dir("stability-flicker");
    let scene_path = repo("scenes/cornell-box/cornell-box.obj");
    let scene = prm_scene::load(&scene_path).unwrap();
    let b = scene.bounds();
    let steps = 120;
    let path: Vec<Vec<Light>> = (0..=steps)
        .map(|i| {
            let t = i as f32 / steps as f32;
            let at = b.min + (b.max - b.min) * Vec3::new(0.2 + 0.6 * t, 0.8, 0.3 + 0.4 * t);
            vec![point(at, 0.1)]
        })
        .collect();

    // The reference at every 8th step and the step after it (the same seed, so its own noise
    // mostly cancels in the difference).
    let atlas = Atlas::build(&scene, &AtlasParams::with_sizing(Sizing::Resolution(32))).unwrap();
    let bvh = Bvh::build(&scene, &BvhParams::DEFAULT).unwrap();
    let mut reference_pairs = Vec::new();
    for i in (0..steps).step_by(8) {
        let pair: Vec<Vec<Vec3>> = (i..i + 2)
            .map(|j| {
                let tracer = ReferenceTracer::new(&scene, &bvh, Lighting::Lights(&path[j]));
                let params = ReferenceParams {
                    seed: 9,
                    ..ReferenceParams::with_spp(64)
                };
                tracer
                    .indirect_at_exits(&atlas.exits, &params, &mut |_, _| {})
                    .unwrap()
                    .mean
            })
            .collect();
        reference_pairs.push(changes(&pair).0);
    }
    let reference = reference_pairs.iter().sum::<f64>() / reference_pairs.len() as f64;
    let reference_max = reference_pairs.iter().copied().fold(0.0, f64::max);
    eprintln!("flicker: reference change per step mean {reference:.4}, max {reference_max:.4}");

    for (name, entries, clusters, ks) in [
        ("clustered", "512", "64", vec![64u32, 16, 8]),
        ("unclustered", "512", "512", vec![512u32, 32]),
    ] {
        // Each variant in its own folder: bake_small names the archive after the scene.
        let variant_dir = dir.join(name);
        std::fs::create_dir_all(&variant_dir).unwrap();
        let archive = bake_small(&variant_dir, &scene_path, entries, clusters, "2");
        let (mut file, scene) = prm_play::open(&archive, None).unwrap();
        let ctx = prm_play::open_vulkan().expect("a Vulkan device (apt-get install mesa-vulkan-drivers)");
        let options = PlayOptions {
            width: 32,
            height: 32,
            runtime: prm_play::RuntimeOptions {
                shadow_resolution: 256,
                ..Default::default()
            },
            ..Default::default()
        };
        let mut r = Renderer::new(ctx, &scene, &mut file, options).unwrap();
        for k in ks {
            r.set_top_k(k);
            let camera = prm_play::default_camera(&scene);
            let frames: Vec<Vec<Vec3>> = path
                .iter()
                .map(|lights| {
                    r.render(&FrameInput {
                        camera,
                        lights,
                        mode: Mode::Indirect,
                    })
                    .unwrap();
                    let lightmap = r.read_lightmap().unwrap();
                    atlas
                        .exits
                        .iter()
                        .map(|e| Vec3::from(lightmap[e.texel as usize]))
                        .collect()
                })
                .collect();
            assert!(frames.iter().all(|f| all_finite(f)));
            let (mean, max, at) = changes_at(&frames);
            let energy = |f: &Vec<Vec3>| f.iter().map(|v| v.element_sum() as f64).sum::<f64>();
            eprintln!(
                "flicker {name} K={k}: change per step mean {mean:.4} ({:.2}x the reference), max {max:.4} ({:.2}x its max) at step {at}; energy first/last {:.3}/{:.3}",
                mean / reference,
                max / reference_max,
                energy(&frames[0]),
                energy(&frames[steps])
            );
            // Measured with the residual groups (4; seed 2): mean 0.77-0.90x the reference's
            // change, largest 1.20-2.31x its largest (K = 8 of 64 the most). With the kept
            // clusters scaled up to the dropped ones' energy instead (seeds 0 and 2): mean
            // 1.0-1.4x, largest 2.0-3.9x; dropping that energy (seed 0): K = 8 1.6x and 7.8x,
            // K = 16 1.2x and 4.6x.
            assert!(
                mean < 1.15 * reference,
                "{name} K={k}: mean change {mean:.4} vs {reference:.4}"
            );
            assert!(
                max < 3.0 * reference_max,
                "{name} K={k}: largest change {max:.4} vs {reference_max:.4}"
            );
        }
    }
}
