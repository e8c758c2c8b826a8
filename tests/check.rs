//! The bake's accuracy check models the player: `prm_trace::check::select_top_k`, fed the
//! weights the run time's weights pass computed on lavapipe, gives the effective weights its rank
//! and select passes chose, cluster for cluster, with the run time's default fade band.

use glam::Vec3;
use prm_runtime::synthetic::{cornell_box_path, write_archive, SyntheticParams};
use prm_runtime::{Runtime, RuntimeOptions, Shadows};
use prm_scene::Light;
use prm_tests::{gpu, temp_dir};
use prm_trace::check::{select_top_k, FADE_BAND};

/// Clusters kept, of the synthetic archive's 48.
const TOP_K: u32 = 8;

#[test]
fn the_check_selects_the_clusters_the_player_selects() {
    assert_eq!(
        RuntimeOptions::default().fade_band,
        FADE_BAND,
        "the check's fade band is the player's"
    );
    let ctx = gpu();
    let scene_path = cornell_box_path();
    let scene = prm_scene::load(&scene_path).unwrap();
    let out = temp_dir("check").join("cornell.prm");
    write_archive(&scene, &scene_path, &out, SyntheticParams::default()).unwrap();
    let mut archive = prm_format::Archive::open(&out).unwrap();
    let energy: Vec<Vec3> = archive.clusters().iter().map(|c| Vec3::from(c.energy)).collect();
    assert!(energy.len() > TOP_K as usize);
    let options = RuntimeOptions {
        top_k: TOP_K,
        ..RuntimeOptions::default()
    };
    let mut rt = Runtime::new(&ctx.device, &ctx.queue, &mut archive, &scene, options).unwrap();
    let b = scene.bounds();
    for f in [[0.5, 0.8, 0.5], [0.25, 0.4, 0.3], [0.75, 0.3, 0.7], [0.1, 0.9, 0.9]] {
        let light = Light::Point {
            position: b.min + b.extent() * Vec3::from_array(f),
            intensity: Vec3::splat(0.3),
        };
        rt.update(&[light]).unwrap();
        let mut enc = ctx.device.create_command_encoder(&Default::default());
        rt.encode(&mut enc, Shadows::Own, None);
        ctx.queue.submit([enc.finish()]);
        ctx.wait().unwrap();
        let gpu = rt.read_weights().unwrap();
        let weights: Vec<Vec3> = gpu.iter().map(|w| Vec3::from(w.weight)).collect();
        let cpu = select_top_k(&weights, &energy, TOP_K as usize, FADE_BAND);
        let peak = gpu.iter().flat_map(|w| w.effective).fold(0f32, f32::max);
        assert!(peak > 0.0, "light {f:?} lights some cluster");
        for (c, (g, e)) in gpu.iter().zip(&cpu).enumerate() {
            let score = weights[c].dot(energy[c]);
            assert!(
                (g.score - score).abs() <= 1e-4 * score.abs().max(1e-30) + 1e-30,
                "light {f:?}, cluster {c}: GPU score {} against weight · energy {score}",
                g.score
            );
            let err = (Vec3::from(g.effective) - *e).abs().max_element();
            assert!(
                err <= 1e-4 * peak,
                "light {f:?}, cluster {c} (rank {}): GPU effective weight {:?} against the check's {e}",
                g.rank,
                g.effective
            );
        }
        assert_eq!(gpu.iter().filter(|w| w.rank < TOP_K).count(), TOP_K as usize);
    }
}
