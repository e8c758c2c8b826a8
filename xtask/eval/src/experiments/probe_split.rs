//! Splits the probes' error against the reference, as `probes.rs` records: the order-2
//! truncation of the spherical harmonics, and the VPL estimator itself.
//!
//! `cargo xtask eval experiment probe_split SCENE ENTRIES WALKS DISK`
//!
//! Places probes as `prm-bake bake --probes` does (512 cells), samples ENTRIES entry points
//! (seed 1), traces WALKS walks from each, lights them with one point light at (0.36, 0.82,
//! 0.54) of the bounds, and compares at every probe and axis normal, without clustering: the
//! probes' SH irradiance against the exact VPL sum (one shadow ray per VPL and normal, the
//! panes' disk bound scaled by DISK), and both against `ReferenceTracer::indirect_at_points`
//! (16384 paths).

use glam::Vec3;
use prm_scene::Light;
use prm_trace::{
    entry_irradiance, probes, sample_surface, trace_walks, Bvh, BvhParams, Clustering, EntryParams, Lighting,
    ReferenceParams, ReferenceTracer, VplBound, WalkParams,
};

fn rel(t: &[Vec3], r: &[Vec3]) -> f64 {
    let num: f64 = t.iter().zip(r).map(|(a, b)| (*a - *b).length_squared() as f64).sum();
    let den: f64 = r.iter().map(|b| b.length_squared() as f64).sum();
    (num / den).sqrt()
}

fn energy(t: &[Vec3], r: &[Vec3]) -> f64 {
    let s = |v: &[Vec3]| v.iter().map(|x| x.element_sum() as f64).sum::<f64>();
    s(t) / s(r)
}

pub fn run(args: Vec<String>) -> Result<(), Box<dyn std::error::Error>> {
    if args.len() != 4 {
        return Err("usage: probe_split SCENE ENTRIES WALKS DISK".into());
    }
    let scene = prm_scene::load(std::path::Path::new(&args[0]))?;
    let (entries_n, walks, disk): (usize, u32, f32) = (args[1].parse()?, args[2].parse()?, args[3].parse()?);
    let bvh = Bvh::build(&scene, &BvhParams::DEFAULT)?;
    let entries = sample_surface(
        &scene,
        &EntryParams {
            count: entries_n,
            seed: 1,
        },
    )?;
    let walk = WalkParams {
        walks_per_entry: walks,
        seed: 1,
        ..WalkParams::PREVIEW
    };
    let vpls = trace_walks(&scene, &bvh, &entries, &walk)?;
    let b = scene.bounds();
    let lights = [Light::Point {
        position: b.min + b.extent() * Vec3::new(0.36, 0.82, 0.54),
        intensity: Vec3::splat(0.8 * b.diagonal() * b.diagonal()),
    }];
    let e_in = entry_irradiance(&bvh, &lights, &entries);
    let layout = probes::place_probes(&scene, &bvh, 512)?;
    let clustering = Clustering::identity(&entries);
    let bound = VplBound::Disk { scale: disk };
    let (transfer, _) = probes::probe_transfer(&bvh, &vpls, &clustering, &layout.positions, bound, &mut |_| {})?;
    let set = prm_format::Probes {
        grid: layout.grid,
        cells: layout.cells.clone(),
        positions: layout.positions.iter().map(|p| p.to_array()).collect(),
        transfer,
        sky: None,
    };
    let w: Vec<[f32; 3]> = clustering
        .members
        .iter()
        .map(|m| e_in[m[0] as usize].to_array())
        .collect();
    let sh = probes::axis_irradiance(&set.irradiance_sh(&w));
    let points = probes::axis_points(&set.positions);
    let exact: Vec<Vec3> = points
        .iter()
        .map(|&(p, n)| {
            vpls.vpls
                .iter()
                .map(|v| {
                    let e = bound.irradiance(v, p, n);
                    let seen = e != Vec3::ZERO
                        && bvh.visible(
                            p,
                            (v.position - p).normalize(),
                            u32::MAX,
                            v.position,
                            v.normal,
                            v.triangle,
                        );
                    if seen {
                        e * e_in[v.entry as usize]
                    } else {
                        Vec3::ZERO
                    }
                })
                .sum()
        })
        .collect();
    let params = ReferenceParams {
        seed: 41,
        ..ReferenceParams::with_spp(16384)
    };
    let reference = ReferenceTracer::new(&scene, &bvh, Lighting::Lights(&lights))
        .indirect_at_points(&points, &params, &mut |_, _| {})?
        .mean;
    println!(
        "{entries_n} entries, {walks} walks, disk {disk}: {} probes, {} VPLs",
        layout.positions.len(),
        vpls.vpls.len()
    );
    println!("SH against the exact VPL sum: {:.2}%", 100.0 * rel(&sh, &exact));
    println!(
        "exact VPL sum against the reference: {:.2}% (energy {:.3})",
        100.0 * rel(&exact, &reference),
        energy(&exact, &reference)
    );
    println!(
        "SH against the reference: {:.2}% (energy {:.3})",
        100.0 * rel(&sh, &reference),
        energy(&sh, &reference)
    );
    Ok(())
}
