//! The sky end to end: `scenes/courtyard` (a yard open to the sky) is baked through the library
//! with the sky's transfer and played with no punctual light under a uniform sky and under a
//! turned environment map. Checked: the run time's lightmaps against the CPU's sums of the
//! archive's own transfer, their linearity in the sky's intensity, and the direct and indirect
//! irradiance against the reference path tracer lighting the scene with the same sky.

use glam::Vec3;
use prm_format::Archive;
use prm_runtime::{ProbeLight, Runtime, RuntimeOptions};
use prm_scene::{AtlasParams, Sizing, Sky, SkyMap};
use prm_tests::{assert_close, baked, channel_sum as sum, gpu, reference_indirect, rel_error, sized, unlit_frame, At};
use prm_trace::{Bvh, BvhParams, Lighting, ReferenceTracer};

/// Atlas side of the test bake.
const RESOLUTION: u32 = 48;

/// One frame under `sky` without punctual lights: the indirect lightmap and the full
/// irradiance lightmap.
fn frame(ctx: &prm_gpu_kit::GpuContext, rt: &mut Runtime, sky: &Sky) -> (Vec<Vec3>, Vec<Vec3>) {
    rt.set_sky(&sky.sh()).unwrap();
    unlit_frame(ctx, rt)
}

/// A smooth sky, bright towards +X and the zenith, dark below the horizon (no sun).
fn gradient_sky() -> Sky {
    let map = SkyMap::from_fn(64, 32, |d| {
        Vec3::new(0.3, 0.5, 0.9) * d.y.max(0.0) + Vec3::new(0.8, 0.6, 0.3) * (0.5 + 0.5 * d.x) * 0.5
    });
    let mut sky = Sky::from_map(map);
    sky.rotation = 40f32.to_radians();
    sky.intensity = 1.5;
    sky
}

#[test]
fn sky_bakes_plays_and_matches_the_reference() {
    let config = prm_bake::BakeConfig {
        paths_per_entry: Some(2),
        // More paths than the command line's default, so that the comparison with the reference
        // below measures more than the two sides' noise.
        sky_paths: Some(4 * prm_bake::SKY_PATHS),
        probes: Some(64),
        ..sized(256, 16, RESOLUTION, 5)
    };
    let (scene, path) = baked("sky", "scenes/courtyard/courtyard.obj", "yard.prm", &config);
    let mut archive = Archive::open(&path).unwrap();
    assert_eq!((archive.info().major, archive.info().minor), (2, 1));
    let probes = archive.probes().expect("the bake placed probes").clone();
    assert!(probes.sky.is_some(), "with the sky's transfer to them");
    let rays = archive.probe_rays().expect("the bake traced the probes' rays").clone();
    let transfer = archive.sky().expect("the bake wrote the sky's transfer").clone();

    let ctx = gpu();
    let options = RuntimeOptions::for_archive(&archive);
    let mut rt = Runtime::new(&ctx.device, &ctx.queue, &mut archive, &scene, options).unwrap();
    assert!(rt.has_sky());
    let mut nan = [[0.0f32; 3]; prm_format::SH_COEFFS];
    nan[3][1] = f32::NAN;
    assert!(rt.set_sky(&nan).is_err(), "coefficients that are not finite");

    // 1. GPU against CPU on the archive's own transfer, and linearity in the intensity.
    let uniform = Sky::uniform(Vec3::new(0.4, 0.6, 1.0));
    let (ind, full) = frame(&ctx, &mut rt, &uniform);
    let texels = transfer.direct.len();
    let (cpu_d, cpu_i): (Vec<Vec3>, Vec<Vec3>) = (0..texels)
        .map(|t| {
            let (d, i) = transfer.irradiance(t, &uniform.sh());
            (Vec3::from(d), Vec3::from(i))
        })
        .unzip();
    assert!(
        rel_error(&ind, &cpu_i) < 1e-5,
        "lightmap {:.2e} from the CPU's",
        rel_error(&ind, &cpu_i)
    );
    let direct: Vec<Vec3> = full.iter().zip(&ind).map(|(f, i)| *f - *i).collect();
    // The bake's exit points (buried ones moved, shut-in ones on a neighbour's point), where the
    // reference below is traced too.
    let bvh = Bvh::build(&scene, &BvhParams::DEFAULT).unwrap();
    let atlas = prm_trace::bake_atlas(&scene, &bvh, &AtlasParams::with_sizing(Sizing::Resolution(RESOLUTION))).unwrap();
    let at = |m: &[Vec3]| -> Vec<Vec3> { atlas.exits.iter().map(|x| m[x.texel as usize]).collect() };
    assert!(
        rel_error(&at(&direct), &at(&cpu_d)) < 1e-4,
        "direct {:.2e} from the CPU's",
        rel_error(&at(&direct), &at(&cpu_d))
    );
    let mut brighter = uniform.clone();
    brighter.intensity = 2.0;
    let (ind2, _) = frame(&ctx, &mut rt, &brighter);
    let doubled: Vec<Vec3> = ind.iter().map(|v| *v * 2.0).collect();
    assert!(rel_error(&ind2, &doubled) < 1e-5);
    rt.set_sky(&[[0.0; 3]; prm_format::SH_COEFFS]).unwrap();
    let (off, _) = frame(&ctx, &mut rt, &Sky::uniform(Vec3::ZERO));
    assert_eq!(sum(&off), 0.0, "no light without a sky");

    // 2. Against the reference tracer under the same skies, at the exit points.
    // Measured (1024 paths per texel, the indirect part smoothed, against 4096, both at the
    // bake's exit points): uniform indirect 5.4% per texel (energy 0.9985), direct 3.9% (0.999);
    // the turned map 5.7% (0.995) and 4.1% (0.997). The per-texel errors are mostly the two
    // sides' noise; the map's detail above order 2 costs it little. (Against an atlas without
    // the bake's moves of buried exit points: 10.4% and 10.6% for the uniform sky.)
    for (name, sky, max_bias, max_indirect, max_direct) in [
        ("uniform", uniform, 0.015, 0.08, 0.055),
        ("map", gradient_sky(), 0.02, 0.085, 0.06),
    ] {
        let tracer = ReferenceTracer::new(&scene, &bvh, Lighting::Lights(&[])).with_sky(&sky);
        let reference = reference_indirect(&tracer, At::Exits(&atlas.exits), 4096, 23);
        let reference_direct = tracer.sky_direct_at_exits(&atlas.exits, 1 << 14);
        let (ind, full) = frame(&ctx, &mut rt, &sky);
        let played_direct: Vec<Vec3> = full.iter().zip(&ind).map(|(f, i)| *f - *i).collect();
        let (ind, played_direct) = (at(&ind), at(&played_direct));
        let e_ind = rel_error(&ind, &reference);
        let energy = sum(&ind) / sum(&reference);
        let e_dir = rel_error(&played_direct, &reference_direct);
        let direct_energy = sum(&played_direct) / sum(&reference_direct);
        println!(
            "{name}: indirect error {e_ind:.4}, energy {energy:.4}; direct error {e_dir:.4}, energy {direct_energy:.4}"
        );
        assert!((energy - 1.0).abs() < max_bias, "{name}: indirect energy {energy:.3}");
        assert!(
            (direct_energy - 1.0).abs() < max_bias,
            "{name}: direct energy {direct_energy:.3}"
        );
        assert!(e_ind < max_indirect, "{name}: indirect error {e_ind:.3}");
        assert!(e_dir < max_direct, "{name}: direct error {e_dir:.3}");
    }

    // 3. The probes under the turned map, both ways the run time lights them. Along the rays:
    // the coefficients against the CPU's sum of the GPU's gather point radiance along the rays
    // plus the sky seen along the rays that leave the scene. Through the panes: against the
    // CPU's sum of the archive's sky transfer to them (no light, so the panes give nothing).
    // Both at the six axis normals against the reference's direct and indirect sky light at
    // the probe positions.
    let sky = gradient_sky();
    frame(&ctx, &mut rt, &sky);
    let gathered = rt.read_probes().unwrap();
    let radiance = rt.read_probe_radiance().unwrap()[..rays.points.len()].to_vec();
    let mut cpu = rays.irradiance_sh(&radiance);
    for (c, s) in cpu
        .iter_mut()
        .zip(prm_format::sky_irradiance_sh(&rays.sky_transfer(), &sky.sh()))
    {
        for (ci, si) in c.iter_mut().zip(s) {
            (0..3).for_each(|k| ci[k] += si[k]);
        }
    }
    let flat = |c: &[[[f32; 3]; 9]]| -> Vec<Vec3> { c.iter().flatten().map(|v| Vec3::from(*v)).collect() };
    let e = rel_error(&flat(&gathered), &flat(&cpu));
    assert!(e < 1e-4, "probe coefficients {e:.2e} from the CPU's sum along the rays");
    let mut panes_archive = Archive::open(&path).unwrap();
    let options = RuntimeOptions {
        probe_light: ProbeLight::Panes,
        ..RuntimeOptions::for_archive(&panes_archive)
    };
    let mut panes_rt = Runtime::new(&ctx.device, &ctx.queue, &mut panes_archive, &scene, options).unwrap();
    frame(&ctx, &mut panes_rt, &sky);
    let panes = panes_rt.read_probes().unwrap();
    let e = rel_error(&flat(&panes), &flat(&probes.sky_irradiance_sh(&sky.sh())));
    assert!(
        e < 1e-5,
        "probe coefficients {e:.2e} from the CPU's sum of the sky transfer"
    );
    let points = prm_trace::probes::axis_points(&probes.positions);
    let tracer = ReferenceTracer::new(&scene, &bvh, Lighting::Lights(&[])).with_sky(&sky);
    let indirect = reference_indirect(&tracer, At::Points(&points), 4096, 23);
    let direct = tracer.sky_direct_at_points(&points, 1 << 14);
    let reference: Vec<Vec3> = direct.iter().zip(&indirect).map(|(d, i)| *d + *i).collect();
    // Measured: 32 probes (the rest inside the walls), along the rays error 1.6% (energy
    // 0.997), through the panes 3.1% (0.999).
    for (name, played, max_error) in [("rays", &gathered, 0.03), ("panes", &panes, 0.06)] {
        let what = format!("probes under the map, through the {name}, {} probes", probes.len());
        assert_close(
            &what,
            &prm_trace::probes::axis_irradiance(played),
            &reference,
            max_error,
            0.02,
        );
    }
}
