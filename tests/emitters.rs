//! Emissive surfaces end to end: `scenes/cornell-box-lamps` (the Cornell box lit by two small
//! ceiling lamps of different colours, two emitter groups) is baked through the library and played with no
//! punctual light at several group scales, both ways a group's indirect light can go: its traced
//! indirect lightmap (what the bake writes for atlases of this size), and, with the same archive
//! rewritten without those lightmaps, the panes lit by its entry irradiance. Checked: the run
//! time's lightmap and cluster weights against the CPU's sums of the archive's own arrays, its
//! linearity in the scales, and the indirect and full irradiance against the reference path
//! tracer lighting the scene with the same lamps.

use glam::Vec3;
use prm_format::{Archive, ArchiveWriter, Cluster};
use prm_runtime::{Runtime, RuntimeOptions};
use prm_scene::{AtlasParams, Sizing};
use prm_tests::{baked, channel_sum as sum, gpu, reference_indirect, rel_error, sized, unlit_frame, At};
use prm_trace::{Bvh, BvhParams, Emitters, Lighting, ReferenceTracer};

/// Atlas side of the test bake.
const RESOLUTION: u32 = 64;

/// `src` rewritten into `dst` with every emitter group's traced indirect lightmap dropped, so
/// that the run time sends the groups' light through the panes.
fn without_traced_indirect(src: &std::path::Path, dst: &std::path::Path) {
    let a = Archive::open(src).unwrap();
    let clusters: Vec<Cluster> = a
        .clusters()
        .iter()
        .map(|c| Cluster::new(c.first, c.count, c.centroid, c.mean_normal))
        .collect();
    let mut w = ArchiveWriter::create(dst, a.metadata().clone(), a.atlas(), a.entries(), &clusters).unwrap();
    w.set_entry_energy(a.entry_energy().unwrap().to_vec()).unwrap();
    let mut groups = a.emitters().to_vec();
    groups.iter_mut().for_each(|g| g.indirect = None);
    w.set_emitters(groups).unwrap();
    for p in 0..a.pane_count() {
        w.add_pane(&a.read_pane(p).unwrap()).unwrap();
    }
    w.finish().unwrap();
}

/// One frame at `scales` without punctual lights: the indirect lightmap, the full irradiance
/// lightmap and the cluster weights.
fn frame(
    ctx: &prm_gpu_kit::GpuContext,
    rt: &mut Runtime,
    scales: [[f32; 3]; 2],
) -> (Vec<Vec3>, Vec<Vec3>, Vec<prm_runtime::ClusterWeight>) {
    rt.set_emitter_scales(&scales).unwrap();
    let (lightmap, full) = unlit_frame(ctx, rt);
    (lightmap, full, rt.read_weights().unwrap())
}

#[test]
fn two_emitter_groups_bake_scale_and_match_the_reference() {
    let config = prm_bake::BakeConfig {
        paths_per_entry: Some(16),
        // No near field (1.7): this test is of the emitters' own sections.
        near_rays: Some(0),
        ..sized(2048, 128, RESOLUTION, 3)
    };
    let (scene, traced_path) = baked(
        "emitters",
        "scenes/cornell-box-lamps/cornell-box-lamps.obj",
        "lamps.prm",
        &config,
    );
    let panes_path = traced_path.with_file_name("lamps-panes.prm");
    without_traced_indirect(&traced_path, &panes_path);

    let mut traced = Archive::open(&traced_path).unwrap();
    assert_eq!((traced.info().major, traced.info().minor), (2, 1));
    let names: Vec<&str> = traced.emitters().iter().map(|g| g.name.as_str()).collect();
    assert_eq!(names, ["lamp_warm", "lamp_blue"]);
    let groups = traced.emitters().to_vec();
    assert!(
        groups.iter().all(|g| g.indirect.is_some()),
        "a 64² atlas traces its emitters' indirect light"
    );
    let energy = traced.entry_energy().unwrap().to_vec();
    let clusters = traced.clusters().to_vec();
    let mut through_panes = Archive::open(&panes_path).unwrap();

    let ctx = gpu();
    let options = RuntimeOptions {
        top_k: clusters.len() as u32,
        ..RuntimeOptions::for_archive(&traced)
    };
    let mut rt = Runtime::new(&ctx.device, &ctx.queue, &mut traced, &scene, options.clone()).unwrap();
    let mut rt_panes = Runtime::new(&ctx.device, &ctx.queue, &mut through_panes, &scene, options).unwrap();
    assert_eq!(rt.emitters().len(), 2);
    assert!(rt.set_emitter_scales(&[[1.0; 3]]).is_err(), "one scale for two groups");
    assert!(
        rt.set_emitter_scales(&[[1.0; 3], [-1.0, 0.0, 0.0]]).is_err(),
        "a negative scale"
    );

    // 1. GPU against CPU on the archive's own arrays. Traced: the lightmap is lampA's indirect
    //    lightmap × its scale. Through the panes: the weights are the CPU's Σ E_i e_i / Σ e_i.
    let scale_a = [0.5, 1.0, 2.0];
    let (a, _, weights) = frame(&ctx, &mut rt, [scale_a, [0.0; 3]]);
    let cpu: Vec<Vec3> = groups[0]
        .indirect
        .as_ref()
        .unwrap()
        .iter()
        .map(|v| Vec3::from(*v) * Vec3::from(scale_a))
        .collect();
    assert!(
        rel_error(&a, &cpu) < 1e-5,
        "traced lightmap {:.2e} from the CPU's",
        rel_error(&a, &cpu)
    );
    assert!(
        weights.iter().all(|w| w.weight == [0.0; 3]),
        "traced groups do not light the entries"
    );
    let (_, _, weights) = frame(&ctx, &mut rt_panes, [[1.0; 3], [0.0; 3]]);
    let mut worst = 0.0f64;
    for (c, w) in clusters.iter().zip(&weights) {
        let (mut num, mut den) = (Vec3::ZERO, Vec3::ZERO);
        for i in c.members() {
            let e = Vec3::from(energy[i]);
            num += Vec3::from(groups[0].entry_irradiance[i]) * e;
            den += e;
        }
        let cpu = num / den.max(Vec3::splat(1e-30));
        let gpu = Vec3::from(w.weight);
        worst = worst.max(((gpu - cpu).length() / cpu.length().max(1e-6)) as f64);
    }
    assert!(worst < 1e-4, "GPU weights differ from the CPU's by {worst:.2e}");

    // 2. Linear in the scales: A + B = both, and doubling A doubles its light (both paths).
    for rt in [&mut rt, &mut rt_panes] {
        let (a, _, _) = frame(&ctx, rt, [[1.0; 3], [0.0; 3]]);
        let (b, _, _) = frame(&ctx, rt, [[0.0; 3], [1.0; 3]]);
        let (both, _, _) = frame(&ctx, rt, [[1.0; 3], [1.0; 3]]);
        let (a2, _, _) = frame(&ctx, rt, [[2.0; 3], [0.0; 3]]);
        let a_plus_b: Vec<Vec3> = a.iter().zip(&b).map(|(x, y)| *x + *y).collect();
        let doubled: Vec<Vec3> = a.iter().map(|x| *x * 2.0).collect();
        assert!(sum(&a) > 0.0 && sum(&b) > 0.0, "both lamps light the box");
        assert!(rel_error(&both, &a_plus_b) < 1e-4, "{}", rel_error(&both, &a_plus_b));
        assert!(rel_error(&a2, &doubled) < 1e-4, "{}", rel_error(&a2, &doubled));
        let (off, _, _) = frame(&ctx, rt, [[0.0; 3], [0.0; 3]]);
        assert_eq!(sum(&off), 0.0, "no light with both groups off");
    }

    // 3. Against the reference tracer with both lamps, at the exit points.
    let bvh = Bvh::build(&scene, &BvhParams::DEFAULT).unwrap();
    let atlas = prm_trace::bake_atlas(&scene, &bvh, &AtlasParams::with_sizing(Sizing::Resolution(RESOLUTION))).unwrap();
    let emitters = Emitters::from_scene(&scene);
    let tracer = ReferenceTracer::new(&scene, &bvh, Lighting::Lights(&[])).with_emitters(&emitters);
    let indirect = reference_indirect(&tracer, At::Exits(&atlas.exits), 1024, 17);
    // The tracer's direct light with 16× its own emitter samples: at 256 (its default, one
    // sample of either lamp at a time) its noise alone is 5% per texel here, twice the bake's
    // (256 samples of each group).
    let direct: Vec<Vec3> = atlas
        .exits
        .iter()
        .enumerate()
        .map(|(i, x)| {
            let mut rng = prm_trace::Rng::new(9, i as u64, 0);
            let ng = bvh.geometric_normal(x.triangle);
            emitters.irradiance(&scene, &bvh, x.position, ng, x.normal, x.triangle, 4096, &mut rng)
        })
        .collect();
    let at = |m: &[Vec3]| -> Vec<Vec3> { atlas.exits.iter().map(|x| m[x.texel as usize]).collect() };
    let reference_full: Vec<Vec3> = direct.iter().zip(&indirect).map(|(d, i)| *d + *i).collect();
    // Measured: traced indirect TRACED_IND (energy TRACED_ENERGY), through the panes 10.1%
    // (energy 0.986: walk noise and clustering at these small settings); direct 3.0% (sampling
    // noise of both sides); full irradiance TRACED_FULL traced, 4.3% through the panes.
    for (name, rt, max_bias, max_indirect, max_full) in [
        ("traced", &mut rt, 0.03, 0.14, 0.06),
        ("panes", &mut rt_panes, 0.07, 0.15, 0.06),
    ] {
        let (both, full, _) = frame(&ctx, rt, [[1.0; 3], [1.0; 3]]);
        let (ind, full) = (at(&both), at(&full));
        let (e_ind, e_full) = (rel_error(&ind, &indirect), rel_error(&full, &reference_full));
        let energy = sum(&ind) / sum(&indirect);
        let played_direct: Vec<Vec3> = full.iter().zip(&ind).map(|(f, i)| *f - *i).collect();
        let e_direct = rel_error(&played_direct, &direct);
        println!(
            "{name}: indirect error {e_ind:.4}, energy {energy:.4}; direct {e_direct:.4}; full irradiance {e_full:.4}"
        );
        assert!(
            (energy - 1.0).abs() < max_bias,
            "{name}: indirect energy {energy:.3} of the reference's"
        );
        assert!(e_ind < max_indirect, "{name}: indirect error {e_ind:.3}");
        assert!(
            e_direct < 0.045,
            "{name}: emitters' direct irradiance error {e_direct:.3}"
        );
        assert!(e_full < max_full, "{name}: full irradiance error {e_full:.3}");
    }
}
