//! Experiment: where a lamp's indirect light goes wrong, by distance from it.
//!
//! `cargo xtask eval experiment lamp_distance SCENE ARCHIVE.prm LIGHT`
//!
//! `LIGHT` a point light as `prm-play` takes it. Exit points of the archive's atlas are binned
//! by their distance from the light (at most 400 a bin, evenly spread over the atlas's order).
//!
//! The first table gives each bin, as shares of the reference's indirect light there (`SPP`
//! paths per point, default 1024): the reference's single-bounce part, and the archive's
//! lightmap as the CPU player plays it with the panes alone, with the near field's direct share
//! added, and whole (the deeper share's gathers and series too).
//!
//! The second splits the single bounce where the panes' kernel and the near field's weights
//! split it (`VplBound::Near`), in the same shares. The reference's pane part (`SPLIT_RAYS`
//! cosine rays per point, default 1024, each weighed by the kernel's share at its hit's
//! distance) stands beside the entry points' depth-0 VPLs summed on the CPU, each entry point
//! lit by its own cell and, as the panes play them, by its cluster's energy weight; the
//! reference's near part stands beside the near field's direct share as played. An entry
//! point's albedo is the surface's under it.

use anyhow::{bail, Context, Result};
use glam::Vec3;
use prm_format::Archive;
use prm_scene::{ExitPoint, Light, Scene};
use prm_trace::{Bvh, BvhParams, Lighting, ReferenceParams, ReferenceTracer};
use rayon::prelude::*;
use std::path::Path;

use super::common::{archive_atlas, cpu_options, env_or};

/// Bin edges, metres from the light.
const BINS: [f32; 9] = [0.0, 1.0, 2.0, 3.0, 4.5, 6.0, 9.0, 13.0, f32::INFINITY];
/// Most exit points a bin.
const PER_BIN: usize = 400;

pub fn run(args: Vec<String>) -> Result<()> {
    let [scene_path, archive_path, light] = &args[..] else {
        bail!("usage: lamp_distance SCENE ARCHIVE.prm LIGHT");
    };
    let (mut archive, scene) = prm_play::open(Path::new(archive_path), Some(Path::new(scene_path)))?;
    let light = prm_scene::parse_light(light)?;
    let Light::Point { position: lamp, .. } = light else {
        bail!("lamp_distance takes a point light");
    };
    let lights = [light];
    let atlas = archive_atlas(&scene, &archive).with_context(|| archive_path.clone())?;
    // Panes alone; with the near field's direct share; whole.
    let mut played = Vec::new();
    for (near_field, near_bounces) in [(false, 0), (true, 0), (true, prm_trace::NEAR_GATHERS)] {
        let options = cpu_options(&archive, near_field, near_bounces);
        let model = prm_play::cpu::CpuArchive::load(&mut archive, &scene, &options)?;
        let player = prm_play::cpu::CpuPlayer::new(&scene, &model, options)?;
        played.push(player.indirect_lightmap(&lights));
    }
    let bins: Vec<Vec<usize>> = BINS
        .windows(2)
        .map(|w| {
            let inside: Vec<usize> = (0..atlas.exits.len())
                .filter(|&i| (w[0]..w[1]).contains(&atlas.exits[i].position.distance(lamp)))
                .collect();
            let step = (inside.len() / PER_BIN).max(1);
            inside.into_iter().step_by(step).take(PER_BIN).collect()
        })
        .collect();
    let exits: Vec<_> = bins.iter().flatten().map(|&i| atlas.exits[i]).collect();
    let bvh = Bvh::build(&scene, &BvhParams::DEFAULT)?;
    let tracer = ReferenceTracer::new(&scene, &bvh, Lighting::Lights(&lights));
    let paths = ReferenceParams::with_spp(env_or("SPP", 1024));
    let all = tracer.indirect_at_exits(&exits, &paths, &mut |_, _| {})?;
    let single = ReferenceParams {
        max_bounces: 1,
        ..paths
    };
    let once = tracer.indirect_at_exits(&exits, &single, &mut |_, _| {})?;
    let disk = match archive.near_field() {
        Some(near) if near.complement => near.indirect_disk,
        _ => bail!("{archive_path} has no near field completing the panes' kernel"),
    };
    let split = split_single_bounce(&scene, &bvh, &lights, &exits, disk, env_or("SPLIT_RAYS", 1024));
    let entries = EntryVpls::from_archive(&scene, &bvh, &lights, &archive)?;
    let depth0 = entries.first_bounce(&bvh, &exits, disk);

    let sum = |v: &mut dyn Iterator<Item = Vec3>| v.map(|x| f64::from(x.element_sum())).sum::<f64>();
    let mut start = 0;
    let mut rows = Vec::new();
    for bin in &bins {
        let range = start..start + bin.len();
        start = range.end;
        let reference = sum(&mut all.mean[range.clone()].iter().copied());
        let share = |map: &[Vec3]| sum(&mut bin.iter().map(|&i| map[atlas.exits[i].texel as usize])) / reference;
        let part = |f: &dyn Fn(usize) -> Vec3| sum(&mut range.clone().map(f)) / reference;
        rows.push([
            part(&|i| once.mean[i]),
            share(&played[0]),
            share(&played[1]),
            share(&played[2]),
            part(&|i| split[i].0),
            part(&|i| depth0[i].0),
            part(&|i| depth0[i].1),
            part(&|i| split[i].1),
            share(&played[1]) - share(&played[0]),
        ]);
    }
    let label = |w: &[f32]| format!("{:>4}–{:<4}", w[0], w[1]);
    println!("metres   exits | single bounce | panes | + direct share | whole  (shares of the reference)");
    for ((w, bin), r) in BINS.windows(2).zip(&bins).zip(&rows) {
        println!(
            "{} {:5} | {:13.3} | {:5.3} | {:14.3} | {:5.3}",
            label(w),
            bin.len(),
            r[0],
            r[1],
            r[2],
            r[3]
        );
    }
    println!("\nsingle bounce, split by the panes' kernel (shares of the reference)");
    println!(
        "metres    | pane part: reference | depth-0 VPLs, own cells | by clusters | near part: reference | near field"
    );
    for (w, r) in BINS.windows(2).zip(&rows) {
        println!(
            "{}  | {:20.3} | {:23.3} | {:11.3} | {:20.3} | {:10.3}",
            label(w),
            r[4],
            r[5],
            r[6],
            r[7],
            r[8]
        );
    }
    Ok(())
}

/// The share of `1/r²` the panes' kernel keeps at distance² `r2` for a VPL disk of radius²
/// `disk` (`VplBound::Near`); the near field's weights carry the rest.
fn pane_share(r2: f32, disk: f32) -> f32 {
    r2 / r2.max((1.0 - prm_format::NEAR_MIN_WEIGHT) * (r2 + disk))
}

/// The reference's single bounce at every exit point, `(pane part, near part)`: `rays` cosine
/// rays each, the light reflected at a hit weighed by [`pane_share`] at its distance.
fn split_single_bounce(
    scene: &Scene,
    bvh: &Bvh,
    lights: &[Light],
    exits: &[ExitPoint],
    disk: f32,
    rays: u32,
) -> Vec<(Vec3, Vec3)> {
    exits
        .par_iter()
        .enumerate()
        .map(|(i, x)| {
            let scramble = prm_trace::Rng::new(0x5b1, 0, i as u64).next_u32();
            let ng = bvh.geometric_normal(x.triangle);
            let (mut pane, mut near) = (Vec3::ZERO, Vec3::ZERO);
            for j in 0..rays {
                let d = prm_trace::cosine_hemisphere(prm_trace::sobol2(j, scramble), x.normal);
                let Some(h) = bvh.closest_hit(bvh.spawn(x.position, ng, d), d, f32::INFINITY, x.triangle) else {
                    continue;
                };
                if !h.front {
                    continue;
                }
                let t = &scene.triangles[h.triangle as usize];
                let y = t.point(h.b1, h.b2);
                let e =
                    prm_trace::direct_irradiance(bvh, lights, y, t.normal(), t.shading_normal(h.b1, h.b2), h.triangle);
                // A cosine ray's irradiance estimate is π L = ρ E.
                let reflected = e * scene.albedo(h.triangle as usize, h.b1, h.b2);
                let f = pane_share(h.t * h.t, disk);
                pane += reflected * f;
                near += reflected * (1.0 - f);
            }
            (pane / rays as f32, near / rays as f32)
        })
        .collect()
}

/// The archive's entry points as depth-0 VPLs under the lights.
struct EntryVpls {
    positions: Vec<Vec3>,
    normals: Vec<Vec3>,
    /// Albedo and triangle of the surface under each.
    surfaces: Vec<(Vec3, u32)>,
    /// Each one's irradiance from its own cell.
    own: Vec<Vec3>,
    /// Each one's cluster's energy weight, as the panes play it.
    clustered: Vec<Vec3>,
    /// The area each stands for, `A/N`.
    area: f32,
}

impl EntryVpls {
    fn from_archive<R: std::io::Read + std::io::Seek>(
        scene: &Scene,
        bvh: &Bvh,
        lights: &[Light],
        archive: &Archive<R>,
    ) -> Result<EntryVpls> {
        let entries = archive.entries();
        let n = entries.len();
        let Some(cells) = archive.entry_cells() else {
            bail!("the archive has no entry cells");
        };
        let area = (scene.area() / n.max(1) as f64) as f32;
        let positions: Vec<Vec3> = entries.iter().map(|e| Vec3::from(e.position)).collect();
        let normals: Vec<Vec3> = entries.iter().map(|e| Vec3::from(e.normal)).collect();
        let energy: Vec<Vec3> = match archive.entry_energy() {
            Some(e) => e.iter().map(|v| Vec3::from(*v)).collect(),
            None => vec![Vec3::ONE; n],
        };
        let own = prm_trace::cell_irradiance(bvh, lights, &positions, &normals, cells, prm_trace::cell_reach2(area));
        let mut clustered = vec![Vec3::ZERO; n];
        for c in archive.clusters() {
            let w = prm_trace::energy_weight(c.members(), &own, &energy);
            clustered[c.members()].fill(w);
        }
        // The archive keeps no triangle: the surface a short ray down the normal meets.
        let lift = 20.0 * bvh.epsilon();
        let surfaces = (0..n)
            .into_par_iter()
            .map(
                |k| match bvh.closest_hit(positions[k] + normals[k] * lift, -normals[k], 2.0 * lift, u32::MAX) {
                    Some(h) => (scene.albedo(h.triangle as usize, h.b1, h.b2), h.triangle),
                    None => (Vec3::ZERO, u32::MAX),
                },
            )
            .collect();
        Ok(EntryVpls {
            positions,
            normals,
            surfaces,
            own,
            clustered,
            area,
        })
    }

    /// Their irradiance at every exit point through the panes' kernel, with shadow rays:
    /// `(each lit by its own cell, each by its cluster's weight)`.
    fn first_bounce(&self, bvh: &Bvh, exits: &[ExitPoint], disk: f32) -> Vec<(Vec3, Vec3)> {
        let lit: Vec<usize> = (0..self.positions.len())
            .filter(|&k| self.own[k] != Vec3::ZERO || self.clustered[k] != Vec3::ZERO)
            .collect();
        exits
            .par_iter()
            .map(|x| {
                let ng = bvh.geometric_normal(x.triangle);
                let (mut own, mut clustered) = (Vec3::ZERO, Vec3::ZERO);
                for &k in &lit {
                    let d = self.positions[k] - x.position;
                    let r2 = d.length_squared();
                    let r = r2.sqrt();
                    let (cx, cv) = (x.normal.dot(d) / r, -self.normals[k].dot(d) / r);
                    if cx <= 0.0 || cv <= 0.0 {
                        continue;
                    }
                    let dir = d / r;
                    let blocked = [x.triangle, self.surfaces[k].1];
                    if bvh.occluded(bvh.spawn(x.position, ng, dir), dir, r - 2.0 * bvh.epsilon(), blocked) {
                        continue;
                    }
                    // The pane of a depth-0 VPL of power ρ A/N, through the kernel's share.
                    let f = self.surfaces[k].0
                        * (self.area * std::f32::consts::FRAC_1_PI * cx * cv / r2)
                        * pane_share(r2, disk);
                    own += self.own[k] * f;
                    clustered += self.clustered[k] * f;
                }
                (own, clustered)
            })
            .collect()
    }
}
