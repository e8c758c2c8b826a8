//! The bake's accuracy check models the player: `prm_trace::check`'s selections, fed the weights
//! the run time's weights pass computed on lavapipe, give the effective weights its rank and
//! select passes chose, cluster for cluster, with the run time's default fade band: with
//! residual groups (the default; `select_with_residuals`, the groups' weights too) and without
//! (`select_top_k`). Its near field's series takes the player's gathers and tail
//! (`tests/near_field.rs` compares the two lightmaps).

use glam::Vec3;
use prm_runtime::synthetic::{cornell_box_path, write_archive, SyntheticParams};
use prm_runtime::{Runtime, RuntimeOptions, Shadows};
use prm_scene::Light;
use prm_tests::{gpu, temp_dir};
use prm_trace::check::{select_top_k, select_with_residuals, FADE_BAND};

/// Clusters kept, of the synthetic archive's 48.
const TOP_K: u32 = 8;

/// The energy of every residual group's pane as the run time takes it: its members' recorded
/// energies summed.
fn group_energies(energy: &[Vec3], of: &[u32], groups: usize) -> Vec<Vec3> {
    let mut sums = vec![Vec3::ZERO; groups];
    if groups > 0 {
        for (e, &g) in energy.iter().zip(of) {
            sums[g as usize] += *e;
        }
    }
    sums
}

#[test]
fn the_check_selects_the_clusters_the_player_selects() {
    assert_eq!(
        RuntimeOptions::default().fade_band,
        FADE_BAND,
        "the check's fade band is the player's"
    );
    assert_eq!(
        (
            RuntimeOptions::default().near_bounces,
            RuntimeOptions::default().near_tail
        ),
        (prm_trace::NEAR_GATHERS, prm_runtime::NearTail::Extrapolated),
        "the check's near series is the player's"
    );
    let ctx = gpu();
    let scene_path = cornell_box_path();
    let scene = prm_scene::load(&scene_path).unwrap();
    let out = temp_dir("check").join("cornell.prm");
    write_archive(&scene, &scene_path, &out, SyntheticParams::default()).unwrap();
    for residual_groups in [prm_format::RESIDUAL_GROUPS, 0] {
        let mut archive = prm_format::Archive::open(&out).unwrap();
        let energy: Vec<Vec3> = archive.clusters().iter().map(|c| Vec3::from(c.energy)).collect();
        assert!(energy.len() > TOP_K as usize);
        let formed = prm_format::residual_group_count(energy.len(), residual_groups);
        let of = prm_format::residual_groups(archive.clusters(), formed);
        let group_energy = group_energies(&energy, &of, formed as usize);
        let options = RuntimeOptions {
            top_k: TOP_K,
            residual_groups,
            ..RuntimeOptions::default()
        };
        let mut rt = Runtime::new(&ctx.device, &ctx.queue, &mut archive, &scene, options).unwrap();
        assert_eq!(rt.group_count(), formed);
        let b = scene.bounds();
        let mut lit_groups = 0;
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
            let gpu_groups = rt.read_group_weights().unwrap();
            let weights: Vec<Vec3> = gpu.iter().map(|w| Vec3::from(w.weight)).collect();
            let (cpu, cpu_groups) = if residual_groups > 0 {
                select_with_residuals(&weights, &energy, TOP_K as usize, FADE_BAND, &of, &group_energy)
            } else {
                (select_top_k(&weights, &energy, TOP_K as usize, FADE_BAND), Vec::new())
            };
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
                    "groups {residual_groups}, light {f:?}, cluster {c} (rank {}): GPU effective weight {:?} \
                     against the check's {e}",
                    g.rank,
                    g.effective
                );
            }
            assert_eq!(gpu.iter().filter(|w| w.rank < TOP_K).count(), TOP_K as usize);
            assert_eq!(gpu_groups.len(), cpu_groups.len());
            let group_peak = cpu_groups.iter().map(|g| g.max_element()).fold(0f32, f32::max);
            lit_groups += usize::from(group_peak > 0.0);
            for (g, (a, b)) in gpu_groups.iter().zip(&cpu_groups).enumerate() {
                let err = (Vec3::from(*a) - *b).abs().max_element();
                assert!(
                    err <= 1e-4 * group_peak,
                    "light {f:?}, group {g}: GPU weight {a:?} against the check's {b}"
                );
            }
        }
        if residual_groups > 0 {
            assert!(
                lit_groups >= 2,
                "the dropped clusters' light reaches the groups under most lights"
            );
        }
    }
}
