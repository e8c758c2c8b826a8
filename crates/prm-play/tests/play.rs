//! Integration tests of the player on Vulkan (lavapipe): GPU blend vs CPU, mode consistency,
//!
//! Long on purpose: one test per behaviour of the player, each with its own setup spelled out.
//! golden Cornell box frame, top-K selection, fingerprint check, multi-light animation, CLI,
//! window mode under Xvfb.

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use glam::Vec3;
use prm_format::Archive;
use prm_play::animation::Animation;
use prm_play::synthetic::{cornell_box_path, write_archive, SyntheticParams};
use prm_play::{output, FrameInput, Image, Mode, PlayError, PlayOptions, Renderer, RuntimeOptions};
use prm_scene::{Light, Scene};

fn out_dir(name: &str) -> PathBuf {
    let d = Path::new(env!("CARGO_TARGET_TMPDIR")).join("prm-play").join(name);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// The synthetic Cornell box archive (written once per test run; see `prm_play::synthetic`).
fn cornell_archive() -> &'static Path {
    static PATH: OnceLock<PathBuf> = OnceLock::new();
    PATH.get_or_init(|| {
        let scene_path = cornell_box_path();
        let scene = prm_scene::load(&scene_path).unwrap();
        let path = out_dir("archive").join("cornell-synthetic.prm");
        write_archive(&scene, &scene_path, &path, SyntheticParams::default()).unwrap();
        path
    })
}

fn renderer(opts: PlayOptions) -> (Renderer, Scene) {
    let (mut archive, scene) = prm_play::open(cornell_archive(), None).unwrap();
    // Vulkan explicitly: a missing driver fails loudly here.
    let ctx = prm_play::open_vulkan().expect("a Vulkan device (install mesa-vulkan-drivers for lavapipe)");
    let r = Renderer::new(ctx, &scene, &mut archive, opts).unwrap();
    (r, scene)
}

/// The full image of `scene` from its default camera, under its own lights.
fn gi_image(r: &mut Renderer, scene: &Scene) -> Image {
    r.render(&FrameInput {
        camera: prm_play::default_camera(scene),
        lights: &scene.lights,
        mode: Mode::Gi,
    })
    .unwrap();
    r.read_image().unwrap()
}

fn small(top_k: u32) -> PlayOptions {
    PlayOptions {
        width: 96,
        height: 96,
        runtime: RuntimeOptions {
            top_k,
            shadow_resolution: 256,
            ..Default::default()
        },
        ..Default::default()
    }
}

fn cornell_lights(scene: &Scene) -> Vec<Light> {
    let mut l = scene.lights.clone();
    // Add one of each other kind so all paths are exercised.
    let b = scene.bounds();
    let c = (b.min + b.max) * 0.5;
    let h = b.extent();
    l.push(Light::Spot {
        position: c + Vec3::new(0.3 * h.x, 0.4 * h.y, 0.3 * h.z),
        direction: Vec3::new(-0.3, -1.0, -0.2).normalize(),
        angle: 35f32.to_radians(),
        intensity: Vec3::new(0.05, 0.1, 0.2),
    });
    let direction = Vec3::new(0.2, -1.0, 0.3).normalize();
    l.push(Light::Rect {
        position: c + Vec3::new(-0.3 * h.x, 0.4 * h.y, -0.2 * h.z),
        direction,
        up: direction.cross(Vec3::X).normalize(),
        half_angles: [40f32.to_radians(), 15f32.to_radians()],
        intensity: Vec3::new(0.15, 0.05, 0.1),
    });
    l.push(Light::Directional {
        direction: Vec3::new(0.2, -1.0, -0.4).normalize(),
        irradiance: Vec3::new(0.3, 0.2, 0.1),
    });
    l
}

/// With K = all clusters, the GPU lightmap is Σ weight × pane blended on the CPU from the
/// archive's basis (with the GPU's weights, read back) within 1 %, and near the sum of the
/// decoded panes; the GPU weights themselves match
/// weights from ray-traced visibility (shadow maps differ only near shadow edges).
#[test]
fn lightmap_equals_cpu_blend_with_all_clusters() {
    let (mut r, scene) = renderer(small(u32::MAX));
    let lights = cornell_lights(&scene);
    let camera = prm_play::default_camera(&scene);
    r.render(&FrameInput {
        camera,
        lights: &lights,
        mode: Mode::Gi,
    })
    .unwrap();
    let gpu = r.read_lightmap().unwrap();
    let weights = r.read_weights().unwrap();
    let archive = Archive::open(cornell_archive()).unwrap();
    let n = archive.clusters().len();
    assert_eq!(weights.len(), n);
    for (c, w) in weights.iter().enumerate() {
        assert_eq!(w.effective, w.weight, "K = all: nothing fades (cluster {c})");
    }
    // The CPU blend from the archive's basis, and the sum of the decoded panes it stands for.
    let blended = archive
        .pane_basis()
        .blend(&weights.iter().map(|w| w.weight).collect::<Vec<_>>());
    let mut cpu = vec![[0f64; 3]; gpu.len()];
    for (c, w) in weights.iter().enumerate() {
        let pane = archive.read_pane(c).unwrap();
        for (acc, t) in cpu.iter_mut().zip(&pane) {
            for k in 0..3 {
                acc[k] += w.weight[k] as f64 * t[k] as f64;
            }
        }
    }
    let peak = cpu.iter().flat_map(|p| *p).fold(0f64, f64::max);
    assert!(peak > 0.0, "the lightmap is not black");
    let mut worst = 0f64;
    let (mut diff2, mut norm2) = (0f64, 0f64);
    for ((g, b), c) in gpu.iter().zip(&blended).zip(&cpu) {
        for k in 0..3 {
            // The tolerance of `assert_matches_cpu_sum`: 1% of the value, at least 2·10⁻³ of
            // the peak.
            let tolerance = (0.01 * c[k].abs()).max(peak * 2e-3);
            worst = worst.max((g[k] as f64 - b[k] as f64).abs() / tolerance);
            diff2 += (g[k] as f64 - c[k]).powi(2);
            norm2 += c[k].powi(2);
        }
    }
    assert!(worst < 1.0, "GPU lightmap vs CPU blend: {worst} times the tolerance");
    // Against the decoded panes, which the decoder clamps one by one where the approximation
    // dips below zero: close as a whole (relative RMSE).
    let rmse = (diff2 / norm2).sqrt();
    assert!(
        rmse < 0.01,
        "GPU lightmap vs the decoded panes' sum: relative RMSE {rmse}"
    );

    // GPU weights vs ray-traced weights.
    let entries = archive.entries().to_vec();
    let clusters = archive.clusters().to_vec();
    let wmax = weights.iter().flat_map(|w| w.weight).fold(0f32, f32::max);
    let mut bad = 0;
    let mut sum_err = 0.0;
    let energy = archive
        .entry_energy()
        .expect("the synthetic archive records entry energies");
    // Exact (ray-traced) irradiance at the entry points.
    let bvh = prm_trace::Bvh::build(&scene, &prm_trace::BvhParams::DEFAULT).unwrap();
    let cpu_irradiance = |p: Vec3, n: Vec3| prm_trace::direct_irradiance(&bvh, &lights, p, n, n, u32::MAX);
    for (c, cl) in clusters.iter().enumerate() {
        // The members' irradiance weighed by their pane energy.
        let (mut e, mut sum) = (Vec3::ZERO, Vec3::ZERO);
        let range = cl.first as usize..(cl.first + cl.count) as usize;
        for (en, w) in entries[range.clone()].iter().zip(&energy[range]) {
            e += cpu_irradiance(Vec3::from(en.position), Vec3::from(en.normal)) * Vec3::from(*w);
            sum += Vec3::from(*w);
        }
        let e = e / sum.max(Vec3::splat(1e-30));
        let g = Vec3::from(weights[c].weight);
        let err = (g - e).abs().max_element() / wmax;
        sum_err += err;
        if err > 0.1 {
            bad += 1;
        }
    }
    let mean = sum_err / clusters.len() as f32;
    assert!(mean < 0.01, "mean weight error {mean} of the largest weight");
    assert!(
        bad * 20 <= clusters.len(),
        "{bad} of {} clusters off by >10 % of the largest weight",
        clusters.len()
    );
}

/// `gi` = `direct` + `indirect`, per pixel.
#[test]
fn gi_is_direct_plus_indirect() {
    let (mut r, scene) = renderer(small(16));
    let lights = cornell_lights(&scene);
    let camera = prm_play::default_camera(&scene);
    let mut frame = |mode| {
        r.render(&FrameInput {
            camera,
            lights: &lights,
            mode,
        })
        .unwrap();
        r.read_image().unwrap()
    };
    let gi = frame(Mode::Gi);
    let direct = frame(Mode::Direct);
    let indirect = frame(Mode::Indirect);
    let split = frame(Mode::Split);
    let peak = gi.rgb.iter().flatten().fold(0f32, |a, b| a.max(*b));
    assert!(peak > 0.0);
    let ind_peak = indirect.rgb.iter().flatten().fold(0f32, |a, b| a.max(*b));
    assert!(ind_peak > 0.0, "indirect light is visible");
    for i in 0..gi.rgb.len() {
        for k in 0..3 {
            let sum = direct.rgb[i][k] + indirect.rgb[i][k];
            assert!(
                (gi.rgb[i][k] - sum).abs() <= 1e-5 * peak + 1e-5 * gi.rgb[i][k].abs(),
                "pixel {i} channel {k}: gi {} vs direct + indirect {sum}",
                gi.rgb[i][k]
            );
        }
        // Split: left half direct, right half gi.
        let x = i as u32 % gi.width;
        let want = if x < gi.width / 2 { direct.rgb[i] } else { gi.rgb[i] };
        assert_eq!(split.rgb[i], want, "split pixel {i}");
    }
}

fn mean_rel_and_outliers(a: &Image, b: &Image) -> (f32, f32) {
    let peak = b.rgb.iter().flatten().fold(0f32, |m, v| m.max(*v));
    let floor = peak * 0.01;
    let mut sum = 0.0;
    let mut outliers = 0;
    for (p, q) in a.rgb.iter().zip(&b.rgb) {
        let e = (0..3)
            .map(|k| (p[k] - q[k]).abs() / q[k].abs().max(floor))
            .fold(0f32, f32::max);
        sum += e;
        if e > 0.05 {
            outliers += 1;
        }
    }
    (sum / a.rgb.len() as f32, outliers as f32 / a.rgb.len() as f32)
}

/// A headless Cornell box frame (its light and camera, K = 32, synthetic archive) against the
/// golden EXR in `tests/golden/`. `PRM_UPDATE_GOLDEN=1` rewrites the golden.
///
/// Thresholds: mean per-pixel relative error (max over channels, floor 1 % of the peak) below
/// 0.5 %, and at most 0.5 % of the pixels off by more than 5 %: room for rasterisation and
/// shadow-edge differences between drivers, far below any change of the lighting model.
#[test]
fn cornell_box_matches_golden() {
    let (mut r, scene) = renderer(PlayOptions {
        width: 128,
        height: 128,
        runtime: RuntimeOptions {
            top_k: 32,
            shadow_resolution: 512,
            ..Default::default()
        },
        ..Default::default()
    });
    let image = gi_image(&mut r, &scene);
    let golden_path = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/golden/cornell-box-gi.exr");
    if std::env::var_os("PRM_UPDATE_GOLDEN").is_some() {
        output::write_exr_compact(&golden_path, &image).unwrap();
        output::write_png(&golden_path.with_extension("png"), &image, 1.0).unwrap();
    }
    let golden = output::read_exr(&golden_path).expect("golden image (PRM_UPDATE_GOLDEN=1 creates it)");
    assert_eq!((golden.width, golden.height), (image.width, image.height));
    let (mean, outliers) = mean_rel_and_outliers(&image, &golden);
    if mean >= 0.005 || outliers > 0.005 {
        let dir = out_dir("golden");
        output::write_exr(&dir.join("actual.exr"), &image).unwrap();
        output::write_png(&dir.join("actual.png"), &image, 1.0).unwrap();
        let diff = Image {
            width: image.width,
            height: image.height,
            rgb: image
                .rgb
                .iter()
                .zip(&golden.rgb)
                .map(|(a, b)| [0, 1, 2].map(|k| (a[k] - b[k]).abs()))
                .collect(),
        };
        output::write_exr(&dir.join("diff.exr"), &diff).unwrap();
        output::write_png(&dir.join("diff.png"), &diff, 10.0).unwrap();
        panic!(
            "Cornell box differs from the golden: mean relative error {mean}, {outliers} of pixels > 5 %; \
             see {}",
            dir.display()
        );
    }
}

/// One indirect-light frame under [`cornell_lights`], from the default camera.
fn render_indirect(r: &mut Renderer, scene: &Scene) {
    let lights = cornell_lights(scene);
    r.render(&FrameInput {
        camera: prm_play::default_camera(scene),
        lights: &lights,
        mode: Mode::Indirect,
    })
    .unwrap();
}

/// K < C without residual groups: exactly the top K clusters contribute, ranks are a
/// permutation, the kept clusters carry the expected energy (score) of all of them, faded ones
/// less than the best one's share, and the lightmap is Σ effective weight × pane.
#[test]
fn top_k_keeps_the_strongest_clusters() {
    let k = 8;
    let mut options = small(k);
    options.runtime.residual_groups = 0;
    let (mut r, scene) = renderer(options);
    render_indirect(&mut r, &scene);
    let w = r.read_weights().unwrap();
    let mut ranks: Vec<u32> = w.iter().map(|c| c.rank).collect();
    ranks.sort();
    assert_eq!(ranks, (0..w.len() as u32).collect::<Vec<_>>());
    let mut by_score: Vec<usize> = (0..w.len()).collect();
    by_score.sort_by(|&a, &b| w[b].score.total_cmp(&w[a].score).then(a.cmp(&b)));
    // Effective = weight × fade × factor, factor = Σ_all score / Σ_kept score × fade; the best
    // cluster is far above the threshold (fade 1), so its ratio is the factor itself.
    let best = &w[by_score[0]];
    let factor = best.effective[0] / best.weight[0];
    assert!(
        factor > 1.0,
        "dropping clusters must hand their energy to the kept ones"
    );
    let (mut all, mut kept) = (0f64, 0f64);
    for (rank, &c) in by_score.iter().enumerate() {
        assert_eq!(w[c].rank, rank as u32);
        all += w[c].score as f64;
        for ch in 0..3 {
            if rank as u32 >= k {
                assert_eq!(w[c].effective[ch], 0.0);
            } else {
                assert!(w[c].effective[ch] <= w[c].weight[ch] * factor * (1.0 + 1e-5));
            }
        }
        if (rank as u32) < k {
            kept += (w[c].score * w[c].effective[0] / w[c].weight[0]) as f64;
        }
    }
    assert!((kept / all - 1.0).abs() < 1e-4, "kept energy {kept} vs all {all}");
    let gpu = r.read_lightmap().unwrap();
    let archive = Archive::open(cornell_archive()).unwrap();
    let effective: Vec<[f32; 3]> = w.iter().map(|c| c.effective).collect();
    let cpu = archive.pane_basis().blend(&effective);
    assert_matches_cpu_sum(&gpu, &cpu);
}

/// Every texel of the GPU's lightmap `gpu` within 1% of the CPU's sum `cpu`, or within 2·10⁻³
/// of the sum's peak where that is larger: the GPU mixes each rank's three coefficients with 8
/// significant bits of the largest (a shared exponent), and the CPU in `f32`, so a texel whose
/// rank terms mostly cancel keeps the terms' absolute error, up to 8·10⁻⁴ of the peak on the
/// Cornell box (a wrong block or index is off by its whole value).
fn assert_matches_cpu_sum(gpu: &[[f32; 3]], cpu: &[[f32; 3]]) {
    let peak = cpu.iter().flatten().fold(0f32, |a, b| a.max(*b));
    for (g, c) in gpu.iter().zip(cpu) {
        for ch in 0..3 {
            let tolerance = (0.01 * c[ch].abs()).max(2e-3 * peak);
            assert!((g[ch] - c[ch]).abs() <= tolerance, "{g:?} against {c:?}, peak {peak}");
        }
    }
}

/// K < C with residual groups (the default): the top K keep their faded weights unscaled, the
/// groups' weights carry the rest of every cluster's energy (score), and the lightmap is Σ
/// effective weight × pane + Σ group weight × the group's summed pane, blended from the basis.
#[test]
fn residual_groups_carry_the_dropped_clusters() {
    let k = 8;
    let (mut r, scene) = renderer(small(k));
    let groups = r.runtime().group_count();
    let clusters = Archive::open(cornell_archive()).unwrap().clusters().len();
    assert_eq!(
        groups,
        prm_format::residual_group_count(clusters, prm_format::RESIDUAL_GROUPS)
    );
    assert!(groups > 1, "{groups} groups of {clusters} clusters");
    render_indirect(&mut r, &scene);
    let w = r.read_weights().unwrap();
    let gw = r.runtime().read_group_weights().unwrap();
    assert_eq!(gw.len(), groups as usize);
    let archive = Archive::open(cornell_archive()).unwrap();
    let of = prm_format::residual_groups(archive.clusters(), groups);
    let (mut all, mut played) = (0f64, 0f64);
    let mut blended = Vec::with_capacity(w.len());
    for (c, cw) in w.iter().enumerate() {
        all += f64::from(cw.score);
        let energy = archive.clusters()[c].energy;
        let group = gw[of[c] as usize];
        for ch in 0..3 {
            assert!(
                cw.effective[ch] <= cw.weight[ch] * (1.0 + 1e-6),
                "cluster {c}: not scaled up"
            );
            if cw.rank >= k {
                assert_eq!(cw.effective[ch], 0.0);
            }
            // A group's pane is its members' summed, its energy theirs.
            played += f64::from((cw.effective[ch] + group[ch]) * energy[ch]);
        }
        blended.push(std::array::from_fn(|ch| cw.effective[ch] + group[ch]));
    }
    assert!(
        gw.iter().flatten().any(|&v| v > 0.0),
        "the dropped clusters' light reaches a group"
    );
    assert!((played / all - 1.0).abs() < 1e-3, "played energy {played} vs all {all}");
    let cpu = archive.pane_basis().blend(&blended);
    let gpu = r.read_lightmap().unwrap();
    assert_matches_cpu_sum(&gpu, &cpu);
}

/// An archive baked for other geometry is refused with a fingerprint error.
#[test]
fn refuses_archive_of_other_geometry() {
    let other = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes/two-rooms");
    let other_scene = std::fs::read_dir(&other)
        .unwrap()
        .map(|e| e.unwrap().path())
        .find(|p| p.extension().is_some_and(|e| e == "obj" || e == "gltf"))
        .expect("a two-rooms scene file");
    let Err(err) = prm_play::open(cornell_archive(), Some(&other_scene)) else {
        panic!("an archive of the Cornell box opened with {}", other_scene.display());
    };
    assert!(matches!(err, PlayError::FingerprintMismatch { .. }), "{err}");
    assert!(err.to_string().contains("baked for another scene"), "{err}");
}

/// The synthetic archive again, with eight probes (a 2×2×2 grid over the box) whose transfer
/// from every cluster is uniform: `E(n) = Σ_c w_c ⊙ (1, 0.5, 0.25)` for every normal.
fn archive_with_uniform_probes() -> PathBuf {
    let a = Archive::open(cornell_archive()).unwrap();
    let path = out_dir("probes").join("cornell-probes.prm");
    let clusters: Vec<prm_format::Cluster> = a
        .clusters()
        .iter()
        .map(|c| prm_format::Cluster::new(c.first, c.count, c.centroid, c.mean_normal))
        .collect();
    let atlas = a.atlas().clone();
    let entries = a.entries().to_vec();
    let mut w = prm_format::ArchiveWriter::create(&path, a.metadata().clone(), &atlas, &entries, &clusters).unwrap();
    if let Some(e) = a.entry_energy() {
        w.set_entry_energy(e.to_vec()).unwrap();
    }
    let scene = prm_scene::load(&cornell_box_path()).unwrap();
    let b = scene.bounds();
    let grid = prm_format::ProbeGrid {
        dims: [2, 2, 2],
        origin: b.min.to_array(),
        spacing: b.extent().max_element() / 2.0,
    };
    let y00 = prm_format::sh_basis([0.0, 1.0, 0.0])[0];
    let mut uniform = [[0.0f32; 3]; prm_format::SH_COEFFS];
    uniform[0] = [1.0 / y00, 0.5 / y00, 0.25 / y00];
    w.set_probes(prm_format::Probes {
        grid,
        cells: (0..8).collect(),
        positions: (0..8).map(|c| grid.cell_centre(c)).collect(),
        transfer: vec![uniform; 8 * clusters.len()],
        sky: None,
    })
    .unwrap();
    for c in 0..clusters.len() {
        w.add_pane(&a.read_pane(c).unwrap()).unwrap();
    }
    w.finish().unwrap();
    path
}

/// The probe sphere is lit by the probe volume: in the indirect image every pixel it covers is
/// albedo/π × the probes' irradiance (uniform here, so one value), the rest of the frame is
/// unchanged, and an archive without probes refuses a sphere.
#[test]
fn probe_sphere_is_lit_by_the_probes() {
    let (mut plain, _) = renderer(small(64));
    let sphere = prm_play::ProbeSphere {
        centre: Vec3::new(0.2, 0.42, 0.35),
        radius: 0.06,
        albedo: Vec3::new(0.8, 0.6, 0.4),
    };
    assert!(
        plain.set_probe_sphere(Some(sphere)).is_err(),
        "no probes in the archive"
    );

    let path = archive_with_uniform_probes();
    let (mut archive, scene) = prm_play::open(&path, None).unwrap();
    let ctx = prm_play::open_vulkan().expect("a Vulkan device (install mesa-vulkan-drivers for lavapipe)");
    let mut r = Renderer::new(ctx, &scene, &mut archive, small(64)).unwrap();
    let lights = cornell_lights(&scene);
    let input = FrameInput {
        camera: prm_play::default_camera(&scene),
        lights: &lights,
        mode: Mode::Indirect,
    };
    r.render(&input).unwrap();
    let without = r.read_image().unwrap();
    r.set_probe_sphere(Some(sphere)).unwrap();
    r.render(&input).unwrap();
    let with = r.read_image().unwrap();
    let weights = r.read_weights().unwrap();
    let e: Vec3 = weights
        .iter()
        .map(|w| Vec3::from(w.weight) * Vec3::new(1.0, 0.5, 0.25))
        .sum();
    let expected = sphere.albedo / std::f32::consts::PI * e;
    let mut covered = 0;
    for (a, b) in with.rgb.iter().zip(&without.rgb) {
        if a != b {
            covered += 1;
            let d = (Vec3::from(*a) - expected).abs().max_element();
            assert!(
                d <= 1e-4 * expected.max_element(),
                "sphere pixel {a:?}, expected {expected}"
            );
        }
    }
    assert!(covered > 20, "the sphere covers {covered} pixels");
}

const EIGHT_LIGHTS: &str = include_str!("../examples/eight-lights.toml");

/// Eight coloured, moving lights of all three kinds, from an animation.
#[test]
fn eight_moving_lights_of_all_kinds() {
    let anim = Animation::parse(EIGHT_LIGHTS).unwrap();
    assert_eq!(anim.lights.len(), 8);
    let (mut r, _scene) = renderer(small(32));
    let mut images = Vec::new();
    for i in [0, 5, 10] {
        let t = anim.time(i);
        let lights = anim.lights_at(t);
        r.render(&FrameInput {
            camera: anim.camera_at(t).unwrap(),
            lights: &lights,
            mode: Mode::Gi,
        })
        .unwrap();
        let img = r.read_image().unwrap();
        assert!(img.rgb.iter().flatten().all(|v| v.is_finite() && *v >= 0.0));
        assert!(img.rgb.iter().flatten().any(|v| *v > 0.0));
        images.push(img);
    }
    assert_ne!(images[0].rgb, images[1].rgb, "the lights move");
    let mid = anim.lights_at(0.5);
    match (mid[0], anim.lights[0][0].1, anim.lights[0][1].1) {
        (Light::Point { position, .. }, Light::Point { position: a, .. }, Light::Point { position: b, .. }) => {
            assert!((position - (a + b) * 0.5).length() < 1e-3)
        }
        _ => panic!("light 0 is a point light"),
    }
}

/// The CLI renders headless frames to EXR and PNG and writes timings.
#[test]
fn cli_headless_writes_images_and_timings() {
    let dir = out_dir("cli");
    let timings = dir.join("timings.json");
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_prm-play"))
        .arg(cornell_archive())
        .args([
            "--headless",
            "--frames",
            "2",
            "--size",
            "64x48",
            "--mode",
            "split",
            "--top-k",
            "8",
        ])
        .arg("--animation")
        .arg(Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/eight-lights.toml"))
        .arg("--out")
        .arg(&dir)
        .arg("--timings")
        .arg(&timings)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    for f in ["frame0000.exr", "frame0000.png", "frame0001.exr", "frame0001.png"] {
        assert!(dir.join(f).exists(), "{f}");
    }
    let json: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&timings).unwrap()).unwrap();
    assert_eq!(json["frames"].as_array().unwrap().len(), 2);
    assert_eq!(json["top_k"], 8);
    let img = output::read_exr(&dir.join("frame0000.exr")).unwrap();
    assert_eq!((img.width, img.height), (64, 48));
    // Without --headless and without a display: a clear message, non-zero exit.
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_prm-play"))
        .arg(cornell_archive())
        .env_remove("DISPLAY")
        .env_remove("WAYLAND_DISPLAY")
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("--headless"));
}

/// Animation files: interpolation between keys, holding outside them, and clear errors.
#[test]
fn animation_interpolates_and_validates() {
    let a = Animation::parse(
        r#"
fps = 4.0
[[camera]]
t = 0.0
spec = "0,0,1:0,0,0:40"
[[camera]]
t = 1.0
spec = "2,0,1:0,0,0:60"
[[light]]
keys = [ { t = 0.5, spec = "spot:0,1,0:0,-1,0:20:1,1,1" }, { t = 1.5, spec = "spot:0,1,0:1,0,0:40:3,1,1" } ]
[[light]]
keys = [ { t = 0.0, spec = "rect:0,1,0:0,-1,0:0,0,1:20,10:1,1,1" }, { t = 2.0, spec = "rect:2,1,0:1,-1,0:0,1,0:40,30:1,1,1" } ]
"#,
    )
    .unwrap();
    assert_eq!(a.time(2), 0.5);
    let c = a.camera_at(0.5).unwrap();
    assert!((c.eye - Vec3::new(1.0, 0.0, 1.0)).length() < 1e-6 && (c.fov_y_deg - 50.0).abs() < 1e-4);
    assert_eq!(a.camera_at(-1.0).unwrap().eye, Vec3::new(0.0, 0.0, 1.0));
    match a.lights_at(1.0)[0] {
        Light::Spot {
            direction,
            angle,
            intensity,
            ..
        } => {
            assert!((direction.length() - 1.0).abs() < 1e-5);
            assert!((angle.to_degrees() - 30.0).abs() < 1e-3);
            assert!((intensity - Vec3::new(2.0, 1.0, 1.0)).length() < 1e-5);
        }
        l => panic!("{l:?}"),
    }
    assert!(matches!(a.lights_at(9.0)[0], Light::Spot { angle, .. } if (angle.to_degrees() - 40.0).abs() < 1e-3));
    match a.lights_at(1.0)[1] {
        Light::Rect {
            position,
            direction,
            up,
            half_angles,
            ..
        } => {
            assert!((position - Vec3::new(1.0, 1.0, 0.0)).length() < 1e-5);
            assert!((direction.length() - 1.0).abs() < 1e-5 && (up.length() - 1.0).abs() < 1e-5);
            assert!(
                up.dot(direction).abs() < 1e-5,
                "up {up} not perpendicular to {direction}"
            );
            assert!((half_angles[0].to_degrees() - 30.0).abs() < 1e-3);
            assert!((half_angles[1].to_degrees() - 20.0).abs() < 1e-3);
        }
        l => panic!("{l:?}"),
    }
    for (bad, says) in [
        ("fps = 0.0", "fps"),
        ("[[light]]\nkeys = []", "no keys"),
        (
            "[[light]]\nkeys = [ { t = 1.0, spec = \"point:0,0,0:1,1,1\" }, { t = 0.0, spec = \"point:0,0,0:1,1,1\" } ]",
            "increasing",
        ),
        (
            "[[light]]\nkeys = [ { t = 0.0, spec = \"point:0,0,0:1,1,1\" }, { t = 1.0, spec = \"dir:0,-1,0:1,1,1\" } ]",
            "same kind",
        ),
        ("[[light]]\nkeys = [ { t = 0.0, spec = \"lamp:0,0,0\" } ]", "light 0"),
        ("colour = 1", "unknown field"),
        ("[[emitter]]\nname = \"light\"\nkeys = []", "emitter \"light\""),
        ("[[emitter]]\nname = \"light\"\nkeys = [ { t = 0.0, spec = \"-1\" } ]", "negative"),
        ("[[sky]]\nt = 1.0\n[[sky]]\nt = 0.0", "increasing"),
        ("[[sky]]\nt = 0.0\nintensity = -1.0", "intensity"),
        ("[[sky]]\nt = 0.0\nturn = 1.0", "unknown field"),
    ] {
        let e = Animation::parse(bad).unwrap_err();
        assert!(e.contains(says), "{bad:?} gave {e:?}");
    }
    // Emitter scales: the animated group interpolates, the others keep their base scale.
    let e = Animation::parse(
        "[[emitter]]\nname = \"lamp\"\nkeys = [ { t = 0.0, spec = \"1\" }, { t = 2.0, spec = \"0,0.5,3\" } ]",
    )
    .unwrap();
    let base = [[2.0; 3], [1.0; 3]];
    assert_eq!(
        e.emitter_scales_at(&["ceiling", "lamp"], &base, 1.0).unwrap(),
        [[2.0; 3], [0.5, 0.75, 2.0]]
    );
    assert_eq!(
        e.emitter_scales_at(&["ceiling", "lamp"], &base, 5.0).unwrap()[1],
        [0.0, 0.5, 3.0]
    );
    let missing = e.emitter_scales_at(&["ceiling"], &base[..1], 0.0).unwrap_err();
    assert!(missing.contains("\"lamp\"") && missing.contains("ceiling"), "{missing}");
    // Sky keys: intensity and rotation interpolate, defaults 1 and 0; none without keys.
    let s = Animation::parse("[[sky]]\nt = 0.0\nintensity = 2.0\n[[sky]]\nt = 2.0\nrotation = 90.0").unwrap();
    assert_eq!(s.sky_at(1.0), Some([1.5, 45.0]));
    assert_eq!(s.sky_at(3.0), Some([1.0, 90.0]));
    assert_eq!(e.sky_at(1.0), None);
    let sky = s.sky_state_at(&prm_scene::Sky::uniform(Vec3::ONE), 1.0).unwrap();
    assert!((sky.intensity - 1.5).abs() < 1e-6 && (sky.rotation - 45f32.to_radians()).abs() < 1e-6);
}

/// Window mode's present pass (run offscreen: no display here): the tone-mapped frame equals the
/// PNG tone mapping of the linear image, within one 8-bit step.
#[test]
fn present_pass_matches_png_tone_mapping() {
    let (mut r, scene) = renderer(small(16));
    let image = gi_image(&mut r, &scene);
    let exposure = 2.0;
    let format = wgpu::TextureFormat::Rgba8Unorm;
    let mut presenter = prm_play::present::Presenter::new(r.context(), format, exposure);
    presenter.bind(&r);
    let ctx = r.context();
    let (w, h) = (image.width, image.height);
    let target = prm_gpu_kit::pipeline::texture(
        &ctx.device,
        "present test",
        [w, h, 1],
        format,
        wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
    );
    let mut enc = ctx.device.create_command_encoder(&Default::default());
    presenter.draw(&mut enc, &target.create_view(&Default::default()));
    ctx.queue.submit([enc.finish()]);
    let bytes = prm_gpu_kit::readback::read_texture(&ctx.device, &ctx.queue, &target, 0).unwrap();
    let padded = w * 4;
    for y in 0..h as usize {
        for x in 0..w as usize {
            let p = image.rgb[y * w as usize + x];
            for k in 0..3 {
                let got = bytes[y * padded as usize + x * 4 + k] as i32;
                let want = output::tone_map(p[k], exposure) as i32;
                assert!((got - want).abs() <= 1, "pixel ({x}, {y}) channel {k}: {got} vs {want}");
            }
        }
    }
}

/// Runs `cmd`, killing it after `limit` (a hung window must not hang the test run).
fn output_within(mut cmd: std::process::Command, limit: std::time::Duration) -> std::process::Output {
    use std::process::Stdio;
    let mut child = cmd.stdout(Stdio::piped()).stderr(Stdio::piped()).spawn().unwrap();
    let start = std::time::Instant::now();
    while child.try_wait().unwrap().is_none() {
        if start.elapsed() > limit {
            let _ = child.kill();
            let out = child.wait_with_output().unwrap();
            panic!(
                "still running after {limit:?}, killed; stderr:\n{}",
                String::from_utf8_lossy(&out.stderr)
            );
        }
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
    child.wait_with_output().unwrap()
}

/// Window mode under Xvfb on lavapipe (Vulkan): the window opens, presents `--frames` frames,
/// quits by itself and saves the last presented frame (read back from the swapchain), which is
/// not blank and equals the headless PNG of the same frame.
#[test]
fn window_mode_under_xvfb_presents_frames() {
    let on_path =
        std::env::var_os("PATH").is_some_and(|p| std::env::split_paths(&p).any(|d| d.join("xvfb-run").is_file()));
    assert!(
        on_path,
        "xvfb-run not found: the window-mode test needs a virtual X server (apt-get install xvfb xauth)"
    );
    let dir = out_dir("window");
    let shot = dir.join("window.png");
    let _ = std::fs::remove_file(&shot);
    let common = ["--size", "160x120", "--mode", "split", "--top-k", "8"];
    let mut cmd = std::process::Command::new("xvfb-run");
    cmd.args(["-a", "-s", "-screen 0 640x480x24"])
        .arg(env!("CARGO_BIN_EXE_prm-play"))
        .arg(cornell_archive())
        .args(common)
        .args(["--frames", "3", "--screenshot"])
        .arg(&shot);
    let out = output_within(cmd, std::time::Duration::from_secs(180));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        out.status.success(),
        "prm-play in a window under xvfb-run failed:\n{stderr}"
    );
    assert!(stderr.contains("3 frames presented"), "{stderr}");
    let img = image::open(&shot)
        .unwrap_or_else(|e| panic!("screenshot {}: {e}\n{stderr}", shot.display()))
        .to_rgb8();
    assert_eq!(img.dimensions(), (160, 120));
    let v: Vec<f64> = img.as_raw().iter().map(|&b| f64::from(b)).collect();
    let mean = v.iter().sum::<f64>() / v.len() as f64;
    let var = v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / v.len() as f64;
    assert!(
        mean > 20.0 && mean < 235.0 && var > 100.0,
        "blank screenshot: mean {mean:.1}, variance {var:.1}"
    );
    // The same frame headless: the presented image is the tone-mapped frame, within one step.
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_prm-play"))
        .arg(cornell_archive())
        .args(common)
        .arg("--headless")
        .arg("--out")
        .arg(&dir)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let headless = image::open(dir.join("frame0000.png")).unwrap().to_rgb8();
    let worst = img
        .as_raw()
        .iter()
        .zip(headless.as_raw())
        .map(|(&a, &b)| (i32::from(a) - i32::from(b)).abs())
        .max()
        .unwrap_or(0);
    assert!(
        worst <= 1,
        "window frame differs from the headless PNG by up to {worst} steps"
    );
}

/// The process whose command line holds `marker` (a path unique to one run), once it exists.
fn pid_with_arg(marker: &Path, limit: std::time::Duration) -> u32 {
    let started = std::time::Instant::now();
    let marker = marker.to_str().unwrap().as_bytes();
    loop {
        for entry in std::fs::read_dir("/proc").unwrap().flatten() {
            let Ok(pid) = entry.file_name().to_string_lossy().parse::<u32>() else {
                continue;
            };
            let cmdline = std::fs::read(entry.path().join("cmdline")).unwrap_or_default();
            let exe_is_player = cmdline
                .split(|&b| b == 0)
                .next()
                .is_some_and(|a| a.ends_with(b"prm-play"));
            if exe_is_player && cmdline.windows(marker.len()).any(|w| w == marker) {
                return pid;
            }
        }
        assert!(started.elapsed() < limit, "no prm-play process after {limit:?}");
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
}

/// Whether process `pid` has a handler for `signal` (its bit in `SigCgt` of `/proc/PID/status`).
fn catches(pid: u32, signal: u32) -> bool {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).unwrap_or_default();
    status
        .lines()
        .find_map(|l| l.strip_prefix("SigCgt:"))
        .and_then(|mask| u64::from_str_radix(mask.trim(), 16).ok())
        .is_some_and(|mask| mask & (1 << (signal - 1)) != 0)
}

/// SIGINT, SIGTERM and SIGHUP close the window as its close button does: the last presented
/// frame is saved to `--screenshot` and the player exits 0.
#[test]
fn window_keeps_the_screenshot_on_signals() {
    let dir = out_dir("window-signals");
    for (name, signal) in [("INT", 2), ("TERM", 15), ("HUP", 1)] {
        let shot = dir.join(format!("signal-{name}.png"));
        let _ = std::fs::remove_file(&shot);
        let mut cmd = std::process::Command::new("xvfb-run");
        cmd.args(["-a", "-s", "-screen 0 640x480x24"])
            .arg(env!("CARGO_BIN_EXE_prm-play"))
            .arg(cornell_archive())
            .args(["--size", "96x72", "--top-k", "8", "--screenshot"])
            .arg(&shot);
        let mut child = cmd
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::piped())
            .spawn()
            .expect("xvfb-run (apt-get install xvfb xauth)");
        let limit = std::time::Duration::from_secs(120);
        let pid = pid_with_arg(&shot, limit);
        let started = std::time::Instant::now();
        while !catches(pid, signal) {
            assert!(started.elapsed() < limit, "prm-play never handles SIG{name}");
            std::thread::sleep(std::time::Duration::from_millis(50));
        }
        let killed = std::process::Command::new("kill")
            .args([format!("-{name}"), pid.to_string()])
            .status()
            .unwrap();
        assert!(killed.success());
        let closed = std::time::Instant::now();
        let status = loop {
            if let Some(status) = child.try_wait().unwrap() {
                break status;
            }
            if closed.elapsed() > limit {
                let _ = child.kill();
                panic!("SIG{name}: the window did not close within {limit:?}");
            }
            std::thread::sleep(std::time::Duration::from_millis(50));
        };
        let mut stderr = String::new();
        std::io::Read::read_to_string(&mut child.stderr.take().unwrap(), &mut stderr).unwrap();
        assert!(status.success(), "SIG{name}: {status:?}\n{stderr}");
        let img = image::open(&shot)
            .unwrap_or_else(|e| panic!("SIG{name}: screenshot {}: {e}\n{stderr}", shot.display()))
            .to_rgb8();
        assert_eq!(img.dimensions(), (96, 72));
        assert!(img.as_raw().iter().any(|&b| b > 20), "SIG{name}: a blank screenshot");
    }
}

/// Window keys move the selected light relative to the view; a directional light turns.
#[test]
fn light_keys_move_and_turn_lights() {
    use prm_play::window::{nudge_light, LIGHT_TURN_DEG};
    let camera = prm_scene::Camera {
        eye: Vec3::new(0.0, 1.0, 3.0),
        target: Vec3::new(0.0, 0.5, 0.0),
        fov_y_deg: 40.0,
    };
    let mut l = Light::Point {
        position: Vec3::ZERO,
        intensity: Vec3::ONE,
    };
    nudge_light(&mut l, &camera, 1.0, 0.0, 0.0, 0.5);
    nudge_light(&mut l, &camera, 0.0, 1.0, 0.0, 0.5);
    nudge_light(&mut l, &camera, 0.0, 0.0, -1.0, 0.5);
    match l {
        // Right is +X, forward (flattened) is -Z, up is +Y for this camera.
        Light::Point { position, .. } => assert!((position - Vec3::new(0.5, -0.5, -0.5)).length() < 1e-5, "{position}"),
        _ => unreachable!(),
    }
    let start = Vec3::new(0.0, -1.0, -1.0).normalize();
    let mut d = Light::Directional {
        direction: start,
        irradiance: Vec3::ONE,
    };
    nudge_light(&mut d, &camera, 1.0, 0.0, 0.0, 0.5);
    nudge_light(&mut d, &camera, 0.0, 1.0, 0.0, 0.5);
    match d {
        Light::Directional { direction, .. } => {
            assert!((direction.length() - 1.0).abs() < 1e-5);
            let angle = direction.dot(start).clamp(-1.0, 1.0).acos().to_degrees();
            assert!(angle > 0.5 * LIGHT_TURN_DEG && angle < 2.5 * LIGHT_TURN_DEG, "{angle}");
        }
        _ => unreachable!(),
    }
    // Straight down (the usual sun) still tilts, and never flips over the vertical.
    let mut sun = Light::Directional {
        direction: Vec3::NEG_Y,
        irradiance: Vec3::ONE,
    };
    nudge_light(&mut sun, &camera, 0.0, 1.0, 0.0, 0.5);
    let Light::Directional { direction, .. } = sun else {
        unreachable!()
    };
    let angle = direction.dot(Vec3::NEG_Y).clamp(-1.0, 1.0).acos().to_degrees();
    assert!((angle - LIGHT_TURN_DEG).abs() < 1e-2, "{angle}");
    for _ in 0..100 {
        nudge_light(&mut sun, &camera, 0.0, -1.0, 0.0, 0.5);
    }
    let Light::Directional { direction, .. } = sun else {
        unreachable!()
    };
    assert!(
        direction.is_finite() && (direction.length() - 1.0).abs() < 1e-4,
        "{direction}"
    );
}

/// Runs the `prm-play` binary headless on the synthetic archive with `args` into `dir`.
fn play_cli(dir: &Path, args: &[&str]) -> std::process::Output {
    std::process::Command::new(env!("CARGO_BIN_EXE_prm-play"))
        .arg(cornell_archive())
        .arg("--headless")
        .arg("--out")
        .arg(dir)
        .args(args)
        .output()
        .unwrap()
}

/// Options out of range, or beyond the device, are refused before any GPU allocation with a
/// message naming the option (and, for sizes, the device limit), exit 2, never a panic inside
/// wgpu (which is exit 101).
#[test]
fn cli_refuses_hostile_options_naming_them() {
    let dir = out_dir("hostile-options");
    // (option, values refused, the name and the limit the message must give)
    let cases: &[(&str, &[&str], &str, &str)] = &[
        (
            "--size",
            &["16384x16384", "12000x12000", "16384x8192"],
            "--size",
            "max_buffer_size",
        ),
        ("--size", &["0x10"], "size", "1..=16384"),
        (
            "--shadow-resolution",
            &["16384", "0", "100000"],
            "--shadow-resolution",
            "16..=",
        ),
        ("--sun-tiles", &["0", "9"], "--sun-tiles", "1..=8"),
        ("--top-k", &["0"], "--top-k", "0"),
        ("--exposure", &["nan"], "--exposure", "finite"),
        ("--fade-band", &["nan"], "--fade-band", "finite"),
        ("--fade-band", &["-1"], "--fade-band", ">= 0"),
    ];
    for &(option, values, named, limit) in cases {
        for &value in values {
            let args = [option, value];
            let out = play_cli(&dir, &args);
            let stderr = String::from_utf8_lossy(&out.stderr);
            assert_eq!(out.status.code(), Some(2), "{args:?}: not refused up front:\n{stderr}");
            assert!(!stderr.contains("panicked"), "{args:?} panicked:\n{stderr}");
            assert!(
                stderr.contains(named) && stderr.contains(limit),
                "{args:?}: the message should name {named} and {limit}:\n{stderr}"
            );
        }
    }
}

/// No output option may replace the archive or the scene the player reads (not `--timings`, not
/// `--export`, and not with exit 0), and options that cannot apply are
/// refused: `--timings` in a window, `--export` with per-frame outputs.
#[test]
fn cli_outputs_never_replace_the_archive_or_the_scene() {
    let dir = out_dir("outputs-vs-inputs");
    let archive = dir.join("copy.prm");
    std::fs::copy(cornell_archive(), &archive).unwrap();
    let obj = dir.join("cornell-box.obj");
    std::fs::copy(cornell_box_path().with_extension("obj"), &obj).unwrap();
    std::fs::copy(cornell_box_path().with_extension("mtl"), obj.with_extension("mtl")).unwrap();
    let export_dir = dir.join("exported");
    std::fs::create_dir_all(&export_dir).unwrap();
    let gltf = export_dir.join("scene.gltf");
    let (a, o, g) = (archive.to_str().unwrap(), obj.to_str().unwrap(), gltf.to_str().unwrap());
    let before = |p: &Path| std::fs::read(p).unwrap();
    let (archive_bytes, obj_bytes) = (before(&archive), before(&obj));
    let play = |args: &[&str]| {
        std::process::Command::new(env!("CARGO_BIN_EXE_prm-play"))
            .args(args)
            .output()
            .unwrap()
    };
    let cases: &[(&[&str], &str)] = &[
        (
            &[a, "--scene", o, "--headless", "--timings", a],
            "which the player reads",
        ),
        (
            &[a, "--scene", o, "--headless", "--timings", o],
            "which the player reads",
        ),
        (&[a, "--scene", o, "--headless", "--screenshot", o], "name it FILE.png"),
        (
            &[a, "--scene", g, "--export", export_dir.to_str().unwrap()],
            "which the player reads",
        ),
        (&[a, "--scene", o, "--timings", "t.json"], "--timings needs --headless"),
    ];
    // The glTF scene of the export case: the export writes scene.gltf into its directory.
    std::fs::copy(cornell_box_path(), &gltf).unwrap();
    let gltf_bytes = before(&gltf);
    for (args, expected) in cases {
        let out = play(args);
        let stderr = String::from_utf8_lossy(&out.stderr);
        // Refused before any frame: exit status 2.
        assert_eq!(out.status.code(), Some(2), "{args:?}:\n{stderr}");
        assert!(
            stderr.contains(expected),
            "{args:?}: expected `{expected}` in:\n{stderr}"
        );
    }
    let out = play(&[
        a,
        "--scene",
        o,
        "--export",
        export_dir.to_str().unwrap(),
        "--frames",
        "2",
    ]);
    assert_eq!(
        out.status.code(),
        Some(2),
        "--export with --frames: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert_eq!(before(&archive), archive_bytes, "the archive was replaced");
    assert_eq!(before(&obj), obj_bytes, "the scene was replaced");
    assert_eq!(before(&gltf), gltf_bytes, "the glTF scene was replaced");
}

/// A scene without lights (the OBJ Cornell box carries none) is not played black in silence:
/// the player warns, says how to add a light, and places one.
#[test]
fn cli_lights_a_scene_without_lights_and_says_so() {
    let dir = out_dir("no-lights");
    let obj = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes/cornell-box/cornell-box.obj");
    let out = play_cli(&dir, &["--scene", obj.to_str().unwrap(), "--size", "64x48"]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    assert!(
        stderr.contains("no lights") && stderr.contains("--light point:"),
        "{stderr}"
    );
    let img = output::read_exr(&dir.join("frame0000.exr")).unwrap();
    let sum: f64 = img.rgb.iter().map(|p| (p[0] + p[1] + p[2]) as f64).sum();
    assert!(sum > 0.0, "the frame is black");
}

/// A damaged archive's error names the file, not a generic `(archive)`.
#[test]
fn cli_names_a_damaged_archive() {
    let dir = out_dir("damaged");
    let mut damaged = std::fs::read(cornell_archive()).unwrap();
    // Damage the last stored tile, so that the header and tables still read and the damage
    // shows when the panes are uploaded.
    let a = Archive::open(cornell_archive()).unwrap();
    let panes = a.info().sections.iter().find(|s| s.name == "panes").unwrap();
    let at = (panes.offset + panes.stored_size - 3) as usize;
    damaged[at] ^= 0x40;
    let path = dir.join("damaged.prm");
    std::fs::write(&path, &damaged).unwrap();
    let scene = cornell_box_path();
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_prm-play"))
        .arg(&path)
        .args(["--headless", "--size", "32x32", "--scene"])
        .arg(&scene)
        .arg("--out")
        .arg(&dir)
        // One clear message whatever the environment asks of panics.
        .env("RUST_BACKTRACE", "1")
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "a damaged archive played:\n{stderr}");
    assert!(
        !stderr.contains("backtrace") && !stderr.contains("panicked"),
        "{stderr}"
    );
    assert_eq!(
        stderr.lines().filter(|l| l.starts_with("error:")).count(),
        1,
        "{stderr}"
    );
    assert!(
        stderr.contains("damaged.prm"),
        "the error should name the file:\n{stderr}"
    );
    assert!(!stderr.contains("(archive)"), "{stderr}");
}

/// Other albedos on the same geometry play the old archive with a warning (the geometry
/// fingerprint still refuses other geometry; see `refuses_archive_of_other_geometry`).
#[test]
fn cli_warns_when_materials_changed_since_the_bake() {
    let dir = out_dir("materials");
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes/cornell-box");
    let obj = std::fs::read_to_string(src.join("cornell-box.obj")).unwrap();
    let mtl = std::fs::read_to_string(src.join("cornell-box.mtl")).unwrap();
    std::fs::write(dir.join("cornell-box.obj"), obj).unwrap();
    std::fs::write(dir.join("cornell-box.mtl"), &mtl).unwrap();
    let scene = dir.join("cornell-box.obj");
    let play = || play_cli(&dir, &["--scene", scene.to_str().unwrap(), "--size", "16x16"]);
    let same = play();
    let stderr = String::from_utf8_lossy(&same.stderr);
    assert!(same.status.success(), "{stderr}");
    assert!(!stderr.contains("materials differ"), "same materials warned:\n{stderr}");
    std::fs::write(
        dir.join("cornell-box.mtl"),
        mtl.replace("Kd 0.7378 0.7361 0.7374", "Kd 0.2 0.2 0.2"),
    )
    .unwrap();
    let changed = play();
    let stderr = String::from_utf8_lossy(&changed.stderr);
    assert!(changed.status.success(), "{stderr}");
    assert!(
        stderr.contains("materials differ"),
        "no warning for changed albedo:\n{stderr}"
    );
}

/// The player's albedo textures read as `prm_scene::Texture::sample` reads them (the baker's and
/// the reference's): v = 0 at the bottom row, each texture at its own size in a layer that a
/// larger texture sizes. The back wall gets a 1 × 2 texture, red on top and blue below, with
/// v = 1 at the ceiling; the floor an 8 × 8 one, so the wall's texture fills only a corner of
/// its layer. A texture sampled upside down, or a smaller texture stretched to the largest one's
/// size, would fail here (and shows in `cargo xtask eval --targets` on the fireplace room's floor
/// planks).
#[test]
fn textures_read_as_the_baker_reads_them() {
    let dir = out_dir("textures");
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes/cornell-box");
    let obj = std::fs::read_to_string(src.join("cornell-box.obj")).unwrap();
    let obj = obj
        .replace(
            "o floor\nusemtl white\nf 1 2 3 4",
            "vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\no floor\nusemtl checks\nf 1/1 2/2 3/3 4/4",
        )
        .replace(
            "o back\nusemtl white\nf 4 3 7 6",
            "o back\nusemtl stripes\nf 4/1 3/2 7/3 6/4",
        );
    assert!(
        obj.contains("usemtl stripes") && obj.contains("usemtl checks"),
        "the OBJ's layout changed"
    );
    std::fs::write(dir.join("cornell-box.obj"), obj).unwrap();
    let mtl = std::fs::read_to_string(src.join("cornell-box.mtl")).unwrap()
        + "\nnewmtl stripes\nKd 1 1 1\nmap_Kd stripes.png\n\nnewmtl checks\nKd 1 1 1\nmap_Kd checks.png\n";
    std::fs::write(dir.join("cornell-box.mtl"), mtl).unwrap();
    let stripes = image::RgbImage::from_fn(1, 2, |_, y| image::Rgb(if y == 0 { [255, 0, 0] } else { [0, 0, 255] }));
    stripes.save(dir.join("stripes.png")).unwrap();
    let checks = image::RgbImage::from_fn(8, 8, |x, y| {
        image::Rgb(if (x + y) % 2 == 0 { [200; 3] } else { [60; 3] })
    });
    checks.save(dir.join("checks.png")).unwrap();

    let scene_path = dir.join("cornell-box.obj");
    let (mut archive, scene) = prm_play::open(cornell_archive(), Some(&scene_path)).unwrap();
    assert_eq!(scene.textures.len(), 2, "both textures load");
    let ctx = prm_play::open_vulkan().expect("a Vulkan device (install mesa-vulkan-drivers for lavapipe)");
    let mut r = Renderer::new(ctx, &scene, &mut archive, small(16)).unwrap();
    let lights = cornell_lights(&scene);
    r.render(&FrameInput {
        camera: prm_play::default_camera(&scene),
        lights: &lights,
        mode: Mode::Direct,
    })
    .unwrap();
    let img = r.read_image().unwrap();
    // The back wall's pixels are the only ones without green; rows from the top.
    let (mut red_rows, mut blue_rows) = (vec![], vec![]);
    for (i, p) in img.rgb.iter().enumerate() {
        if p[1] == 0.0 && p[0] + p[2] > 0.0 {
            let row = (i as u32 / img.width) as f32;
            if p[0] > 4.0 * p[2] {
                red_rows.push(row);
            } else if p[2] > 4.0 * p[0] {
                blue_rows.push(row);
            }
        }
    }
    let mean = |v: &[f32]| v.iter().sum::<f32>() / v.len().max(1) as f32;
    assert!(
        red_rows.len() > 20 && blue_rows.len() > 20,
        "the back wall shows its stripes: {} red and {} blue pixels (white means the texture was read outside its corner)",
        red_rows.len(),
        blue_rows.len()
    );
    assert!(
        mean(&red_rows) + 5.0 < mean(&blue_rows),
        "red (the texture's top row) must be at the top of the wall: mean row {} against blue's {}",
        mean(&red_rows),
        mean(&blue_rows)
    );
}
