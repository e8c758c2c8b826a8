//! Probes end to end: our Cornell box is baked through the library with probes and their rays,
//! and played with a point light, both ways the run time can light them. Checked: through the
//! panes, the run time's coefficients against the CPU's sum of the archive's transfer under the
//! same cluster weights; along the rays, the gather points' radiance against the CPU's (ray-cast
//! direct light plus the frame's lightmap) and the coefficients against the CPU's sum of that
//! radiance along the rays; the placement (none inside the blocks); and both against the
//! reference path tracer at the probe positions, for the six axis normals.

use glam::Vec3;
use prm_format::Archive;
use prm_runtime::{ProbeLight, Runtime, RuntimeOptions, Shadows};
use prm_scene::Light;
use prm_tests::{assert_close, baked, gather_radiance, gpu, reference_indirect, rel_error, sized, At};
use prm_trace::{Bvh, BvhParams, Lighting, ReferenceTracer};

use prm_trace::probes::{axis_irradiance, axis_points};

fn flat(c: &[[[f32; 3]; 9]]) -> Vec<Vec3> {
    c.iter().flatten().map(|v| Vec3::from(*v)).collect()
}

#[test]
fn probes_bake_play_and_match_the_reference() {
    let config = prm_bake::BakeConfig {
        // Measured (this light, 61 probes, reference noise 2.9%), through the panes: 2048
        // entries in 64 clusters 21.7% (energy 0.934), 8192 in 256 8.2% (1.007), 8192 in 1024
        // 5.7% (1.008): the entries' point sampling of the direct light, as on the surfaces.
        // Along the rays the lightmap's light matters instead.
        probes: Some(64),
        // VPL disks of three entry-point radii, not the plan's eight (its rule for a 64² atlas):
        // probes lit through the panes have no near field to give back what a disk takes, and
        // with eight radii (7 cm, half a probe cell) they measured 27.5%, energy 0.828.
        vpl_disk_scale: Some(prm_bake::params::NEAR_FIELD_DISK_SCALE_LARGE),
        ..sized(8192, 256, 64, 3)
    };
    let (scene, path) = baked("probes", "scenes/cornell-box/cornell-box.obj", "box.prm", &config);
    let archive = Archive::open(&path).unwrap();
    assert_eq!((archive.info().major, archive.info().minor), (2, 1));
    let probes = archive.probes().expect("the bake placed probes").clone();
    let rays = archive.probe_rays().expect("the bake traced the probes' rays").clone();
    assert_eq!(rays.rays_per_probe, prm_bake::PROBE_RAYS);
    assert_eq!(rays.probes(), probes.len());
    assert!(probes.grid.cells() <= 64);
    assert!(probes.len() >= 32, "{} probes", probes.len());
    // The tall block spans x 0.265..0.472, y 0..0.33, z 0.247..0.456: no probe inside it.
    for p in &probes.positions {
        let inside = (0.27..0.46).contains(&p[0]) && p[1] < 0.32 && (0.26..0.44).contains(&p[2]);
        assert!(!inside, "probe at {p:?} is inside the tall block");
    }
    // The box is open at the front only: a ray leaves through it now and then, one meets a
    // back face (or a surface without a texel) rarely, most reach a texel.
    let count = |v: u32| rays.hits.iter().filter(|&&h| h == v).count() as f64 / rays.hits.len() as f64;
    let (sky, blocked) = (count(prm_format::RAY_SKY), count(prm_format::RAY_BLOCKED));
    println!(
        "probes: {:.1}% of the rays leave the box, {:.2}% are blocked",
        100.0 * sky,
        100.0 * blocked
    );
    assert!(
        sky > 0.0 && sky < 0.4 && blocked < 0.01,
        "sky {sky:.3}, blocked {blocked:.4}"
    );

    let ctx = gpu();
    let light = Light::Point {
        position: Vec3::new(0.2, 0.45, 0.3),
        intensity: Vec3::splat(0.25),
    };
    let play = |probe_light: ProbeLight| {
        let options = RuntimeOptions {
            probe_light,
            ..RuntimeOptions::for_archive(&archive)
        };
        let mut archive = Archive::open(&path).unwrap();
        let mut rt = Runtime::new(&ctx.device, &ctx.queue, &mut archive, &scene, options).unwrap();
        assert_eq!(rt.probes().map(|v| v.positions.len()), Some(probes.len()));
        assert_eq!(rt.probes_gather_rays(), probe_light == ProbeLight::Rays);
        rt.update(&[light]).unwrap();
        let mut enc = ctx.device.create_command_encoder(&Default::default());
        rt.encode(&mut enc, Shadows::Own, None);
        ctx.queue.submit([enc.finish()]);
        rt
    };

    // 1. Through the panes: GPU against CPU on the archive's transfer and the frame's weights.
    let rt = play(ProbeLight::Panes);
    let panes = rt.read_probes().unwrap();
    let w: Vec<[f32; 3]> = rt.read_weights().unwrap().iter().map(|w| w.weight).collect();
    let e = rel_error(&flat(&panes), &flat(&probes.irradiance_sh(&w)));
    assert!(e < 1e-5, "probe coefficients {e:.2e} from the CPU's");
    assert!(rt.read_probe_radiance().unwrap().is_empty());
    drop(rt);

    // 2. Along the rays: the gather points' radiance against the CPU's, ray-cast direct light
    // (the GPU's is shadow-mapped) plus the frame's lightmap; the coefficients against the CPU's
    // sum of the GPU's radiance.
    let rt = play(ProbeLight::Rays);
    let gathered = rt.read_probes().unwrap();
    let radiance: Vec<[f32; 3]> = rt.read_probe_radiance().unwrap()[..rays.points.len()].to_vec();
    let lightmap = rt.read_lightmap().unwrap();
    let bvh = Bvh::build(&scene, &BvhParams::DEFAULT).unwrap();
    let lights = [light];
    let cpu_radiance = gather_radiance(&bvh, &lights, &rays.points, |g| Vec3::from(lightmap[g.texel as usize]));
    let gpu_radiance: Vec<Vec3> = radiance.iter().map(|v| Vec3::from(*v)).collect();
    let e = rel_error(&gpu_radiance, &cpu_radiance);
    println!("probes: gather point radiance {e:.4} from the CPU's ray-cast direct light");
    assert!(e < 0.05, "gather point radiance {e:.3} from the CPU's");
    let e = rel_error(&flat(&gathered), &flat(&rays.irradiance_sh(&radiance)));
    assert!(e < 1e-4, "probe coefficients {e:.2e} from the CPU's sum along the rays");

    // 3. Both against the reference tracer at the probe positions.
    let points = axis_points(&probes.positions);
    let tracer = ReferenceTracer::new(&scene, &bvh, Lighting::Lights(&lights));
    let reference = reference_indirect(&tracer, At::Points(&points), 4096, 29);
    for (name, coeffs, max_error) in [("panes", &panes, 0.11), ("rays", &gathered, 0.06)] {
        let what = format!("probes through the {name}, {} probes", probes.len());
        assert_close(&what, &axis_irradiance(coeffs), &reference, max_error, 0.04);
    }
}

/// Our Cornell box lit by its two lamps alone (`scenes/cornell-box-lamps`), with probes: the
/// rays find the lamps (gather points of both groups, carrying their emission), the probes'
/// light is linear in the groups' scales, and it matches the reference, the lamps' direct light
/// at the probes included.
#[test]
fn emissive_surfaces_light_the_probes() {
    let config = prm_bake::BakeConfig {
        probes: Some(64),
        ..sized(1024, 64, 48, 5)
    };
    let (scene, path) = baked(
        "probes-lamps",
        "scenes/cornell-box-lamps/cornell-box-lamps.obj",
        "lamps.prm",
        &config,
    );
    let mut archive = Archive::open(&path).unwrap();
    let probes = archive.probes().expect("the bake placed probes").clone();
    let rays = archive.probe_rays().expect("the bake traced the probes' rays").clone();
    for g in 0..2u32 {
        let lamp = rays
            .points
            .iter()
            .find(|p| p.emitter == g)
            .expect("a ray reaches each lamp");
        assert!(lamp.emission.iter().all(|&e| e > 0.0), "{lamp:?}");
    }
    assert!(rays
        .points
        .iter()
        .all(|p| (p.emitter == prm_format::NO_EMITTER) == (p.emission == [0.0; 3])));

    let ctx = gpu();
    let options = RuntimeOptions::for_archive(&archive);
    let mut rt = Runtime::new(&ctx.device, &ctx.queue, &mut archive, &scene, options).unwrap();
    let mut play = |scales: [[f32; 3]; 2]| {
        rt.set_emitter_scales(&scales).unwrap();
        rt.update(&[]).unwrap();
        let mut enc = ctx.device.create_command_encoder(&Default::default());
        rt.encode(&mut enc, Shadows::Own, None);
        ctx.queue.submit([enc.finish()]);
        flat(&rt.read_probes().unwrap())
    };
    let a = play([[1.0; 3], [0.0; 3]]);
    let b = play([[0.0; 3], [0.5, 1.0, 2.0]]);
    let both = play([[1.0; 3], [0.5, 1.0, 2.0]]);
    let ab: Vec<Vec3> = a.iter().zip(&b).map(|(x, y)| *x + *y).collect();
    let e = rel_error(&both, &ab);
    assert!(e < 1e-4, "the probes' light is not linear in the scales: {e:.2e}");
    assert!(rel_error(&a, &b) > 0.1, "the two lamps light the probes alike");

    // Against the reference, both lamps at scale 1: indirect light plus the lamps' direct light.
    let played = play([[1.0; 3], [1.0; 3]]);
    let played = axis_irradiance(
        &played
            .chunks_exact(9)
            .map(|c| std::array::from_fn(|i| c[i].to_array()))
            .collect::<Vec<_>>(),
    );
    let bvh = Bvh::build(&scene, &BvhParams::DEFAULT).unwrap();
    let points = axis_points(&probes.positions);
    let emitters = prm_trace::Emitters::from_scene(&scene);
    let tracer = ReferenceTracer::new(&scene, &bvh, Lighting::Lights(&[])).with_emitters(&emitters);
    let indirect = reference_indirect(&tracer, At::Points(&points), 4096, 31);
    let direct = emitters.direct_at_points(&scene, &bvh, &points, 4096, 37);
    let reference: Vec<Vec3> = indirect.iter().zip(&direct).map(|(i, d)| *i + *d).collect();
    // Measured: 61 probes, 7.2% (energy 0.982).
    let what = format!("probes by the lamps, {} probes", probes.len());
    assert_close(&what, &played, &reference, 0.11, 0.05);
}
