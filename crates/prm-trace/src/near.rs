//! The near field (format 1.7 to 1.9: `prm_format::NearField`): short cosine rays from every exit
//! point, kept where they end close enough for the VPL disk bound ([`crate::VplBound`]) to
//! have removed light, so that the run time gathers that light back from the surfaces' direct
//! light of the frame.
//!
//! The bound loses most at inner edges and contacts (`vpl.rs`: exit points on a concave edge
//! get about half of what they should). The depth-0 VPLs, one per entry point standing for the
//! area `A/N`, carry the entry points' direct light; what the disk `R² = A/(N·π)` removes
//! around them is `∫ L_direct(ω) · R²/(r² + R²) cos θ dω`, which the run time knows at every
//! texel each frame. Rays are kept while `R²/(r² + R²) ≥ prm_format::NEAR_MIN_WEIGHT`, so they
//! are at most `R·√15 ≈ 3.9 R` long and cheap: 0.17 s for the 43k exits of the Cornell box at
//! 64 rays.
//!
//! Measured (`RAYS=64 MINW=16 cargo run --release -p prm-trace --example near_field -- SCENE
//! ARCHIVE FX FY FZ`: default bakes, every cluster blended on the CPU with ray-cast entry
//! irradiance, 2048 exit points against the reference at 1024 paths with its noise removed;
//! "edges" are the exit points a cosine ray from which meets a surface within 1.5 texels):
//!
//! | case | played | + near field, direct | + direct and indirect | edges: played → direct |
//! | --- | ---: | ---: | ---: | ---: |
//! | Cornell box, light under the ceiling | 8.48% (energy 0.982) | **7.53%** (0.990) | 7.65% | 29.0 → 22.3% |
//! | Cornell box, light low near the red wall | 13.08% (0.954) | **10.53%** (0.967) | 10.13% | 33.8 → 20.0% |
//! | CornellBox-Sphere, under the ceiling | 8.60% (0.983) | **7.50%** (0.992) | 7.19% | 25.1 → 17.8% |
//! | chairs, above the chairs | 8.23% (0.993) | **7.52%** (1.000) | 8.67% | 21.2 → 18.9% |
//!
//! A cut-off of 1/1024 instead of `NEAR_MIN_WEIGHT` = 1/16 keeps six times the rays (1.9 M
//! against 243 k on the Cornell box) for 0.1–0.2 points (7.44%, 10.30%; 1/64: 7.54%, 10.40%).
//! 32, 64, 128 and 256 rays give the same errors within 0.1 point on the red-wall case, so the
//! default is [`NEAR_RAYS`] = 64. A whole final gather from the texels instead of the panes is
//! too noisy per texel at any affordable count (17% at 64 rays, 8.9% at 256 on the first case).
//!
//! The deeper VPLs (format 1.8). With the disk of the area one walk stands for, `A/(N·W)`,
//! gathering their share from the lightmap's indirect light helped the boxes a little and hurt
//! chairs by 1.2 points (the table's last column but one), and their small disks spiked (the
//! local error of issue #11). The bake now gives them their entry point's disk
//! ([`crate::DeepDisk::Entry`]), the same `R²`, so one set of rays gathers both shares and the
//! player adds `π/M · Σ I_g · R²/(r² + R²)` for the radiance `I_g` of the lightmap's indirect
//! light at the gather point. Measured on McGuire's CornellBox-Original (`Ke` = 0, today's
//! default bake; the same example at `0.5 0.865 0.5` and `0.1 0.2 0.5` of the bounds, played +
//! both shares): 3.86% → **3.29%** (energy 1.012 → 1.009) and 5.74% → **5.12%** (0.994 →
//! 0.990); in image space (`cargo xtask eval --targets`'s cases,
//! 4×4 error and local error) the boxes 4.1% / 4.6% → 3.6% / 4.2%, local 22× / 15× → 9× / 10×,
//! CornellBox-Sphere 3.7% → 3.4%, chairs 4.6% → 4.2%, the fireplace room's 120 s bake 14.5% →
//! 12.0% (energy 0.957 → 0.979, local 4.8× → 3.6×).
//!
//! The cut (format 1.9). Rays whose weight falls under `NEAR_MIN_WEIGHT` are not kept, so what
//! the disk removes beyond them was lost: up to a sixteenth of every VPL's light at those
//! distances, more of the whole the larger the disk (the fireplace room at four times the
//! radius: energy 0.964). The bake now renders the panes with `VplBound::Near`, which keeps
//! `1/r²` beyond the cut and `1/(r² + R²)` scaled by `1/(1 − w₀)` inside it, and the section's
//! weights are cut and rescaled to match (`NearField::complement`): the two sum to `1/r²`.
//! Measured in image space (seed 1, the fireplace room's 120 s sizes; McGuire's box): at the old
//! radius 12.27% → 12.57% (energy 0.993 → 1.000), at four times 11.40% → 10.81% (0.964 →
//! 0.988); McGuire's red-wall light at twice the radius 5.33% (energy 0.970, session 18, the
//! old kernel) → 3.98% (0.986). That freed the disk's size (`prm-bake`'s
//! `NEAR_FIELD_DISK_SCALE`, where the tables are: 3 from session 19, 8 since the player sums
//! the near field's series in session 25).
//!
//! An exit point's rays are one Owen-scrambled Sobol set ([`sobol2`], scrambled per exit
//! point), which stratifies them over the hemisphere; they were independent draws until session
//! 27. Where the disks are large the near field is most of a final gather (Sponza's 7 m disks
//! reach 27 m), and its noise was as large as the panes': between two seeds' default `--sky`
//! bakes of the Dabrovic Sponza under `cargo xtask eval --sky`'s sun, the near field's direct
//! share differed by 6.5% of the reference's norm (the panes by 5.9%, the deeper share by
//! 3.1%); stratified, 4.0% (deeper share 2.5%). Indirect error (4×4), seeds 0 and 1: Sponza's
//! sun 13.69% → 13.23% and 11.35% → 10.70%, sky and sun 10.70% → 10.36% and 9.06% → 8.58%;
//! the fireplace room's default bake (`--targets`' lamp) 6.04% → 5.52% and 6.68% → 6.25%
//! (`cargo xtask eval compare` of each archive played against the eval's reference).
//!
//! Rays leave from just off the surface ([`Bvh::spawn`]), as the walks' and the reference's do.
//! They used to leave from the exit point itself, ignoring its own triangle only, so a coplanar
//! copy of that triangle was met at once, as a back face, and every ray of the exit was lost:
//! McGuire's boxes list two faces twice (the tall block's front, which showed dark blotches
//! one texel wide at its foot), and a two-sided wall's far side would have been met as a front
//! face at distance zero. With this and the duplicates dropped at load
//! ([`prm_scene::LoadReport::duplicates_dropped`]), that box's two lights went from 3.60% /
//! 5.37% and 3.96% / 5.41% (4×4 and full resolution) to 3.41% / 5.13% and **3.05% / 4.67%**.
//!
//! Gather points stay at their texel's exit point, though the rays that reach a texel do not
//! end at its centre. Measured on Dabrovic Sponza under the eval's sun (`cargo run --release -p
//! prm-trace --example near_hits -- SCENE 512 2816 dir:-0.25,-0.9,0.35:6,5.6,5 OUT.bin`, every
//! exit's direct share ray-cast at each hit against at its gather point): the two agree over
//! the exits that take under half their light from the near field (0.991) but the gather points
//! give 5.5% and 11.6% more where it brings 70–90% and over 90% (the rays end in the corner of
//! the texel they reach, shadowed more than its centre). Moving every gather point to the hit
//! nearest its hits' weighted centroid brings those to 0.996 and 1.017 on the CPU (and the rest
//! to 0.953), but the played lightmap's near-dominated texels only from 1.10–1.13 to 1.06–1.11
//! of the reference and Sponza's image errors not at all (seeds 0–2: 23.18, 15.59, 21.83%
//! against 23.03, 15.67, 21.51%), so it was not kept.

use glam::Vec3;
use prm_format::{NearExit, NearField, NearHit, NEAR_MIN_WEIGHT};
use prm_scene::{Atlas, Scene, EMPTY_TEXEL};
use rayon::prelude::*;

use crate::bvh::Bvh;
use crate::probes::{gather_points, HitTexels};
use crate::rng::Rng;
use crate::sampling::{cosine_hemisphere, sobol2};

/// Default rays per exit point.
pub const NEAR_RAYS: u32 = 64;
/// Random stream of the near rays, apart from the walks', the check's and the sky's.
const NEAR_STREAM: u64 = 0x6e65_6172;

/// The depth-0 VPLs' disk `R² = scale² · a/π` for entry points standing for the area `a`
/// (`SurfaceSample::weight`, `A/N`) under `VplBound::Disk { scale }`.
pub fn near_disk(area_per_entry: f32, scale: f32) -> f32 {
    scale * scale * area_per_entry / std::f32::consts::PI
}

/// Traces `rays` cosine rays from every exit point of `atlas` (streams keyed by `seed`) and
/// keeps the ones that end on a front face, at an exit of the hit's chart, within the reach of
/// `disk` (`R²`, [`near_disk`]).
pub fn near_field(scene: &Scene, bvh: &Bvh, atlas: &Atlas, rays: u32, disk: f32, seed: u64) -> NearField {
    let emitters = crate::Emitters::from_scene(scene);
    let texels = HitTexels::new(atlas);
    let tmax = (disk * (1.0 / NEAR_MIN_WEIGHT - 1.0)).sqrt();
    let per_exit: Vec<Vec<(u32, f32)>> = atlas
        .exits
        .par_iter()
        .enumerate()
        .map(|(i, x)| {
            // One Owen-scrambled Sobol set per exit point: its rays stratify the hemisphere.
            let scramble = Rng::new(seed, NEAR_STREAM, i as u64).next_u32();
            let ng = bvh.geometric_normal(x.triangle);
            (0..rays)
                .filter_map(|j| {
                    let d: Vec3 = cosine_hemisphere(sobol2(j, scramble), x.normal);
                    // From just off the surface, as every other ray here: a ray from the surface
                    // itself meets a coplanar copy of its triangle at once.
                    let h = bvh.closest_hit(bvh.spawn(x.position, ng, d), d, tmax, x.triangle)?;
                    let r2 = h.t * h.t;
                    if !h.front || disk / (r2 + disk) < NEAR_MIN_WEIGHT {
                        return None;
                    }
                    Some((texels.exit(h.triangle, h.b1, h.b2)?, r2))
                })
                .collect()
        })
        .collect();
    let (index, points) = gather_points(scene, atlas, &emitters, per_exit.iter().flatten().map(|h| h.0));
    // Records in texel order: every exit with hits, and every gutter texel whose source has
    // them, with a copy of its source's, so that bilinear lookups at chart borders see them.
    let mut order: Vec<(u32, usize)> = (0..atlas.exits.len())
        .filter(|&i| !per_exit[i].is_empty())
        .map(|i| (atlas.exits[i].texel, i))
        .collect();
    for &(gutter, source) in &atlas.dilation {
        let e = atlas.texel_exit[source as usize];
        if e != EMPTY_TEXEL && !per_exit[e as usize].is_empty() {
            order.push((gutter, e as usize));
        }
    }
    order.sort_unstable_by_key(|r| r.0);
    let mut exits = Vec::with_capacity(order.len());
    let mut hits = Vec::new();
    for (texel, i) in order {
        hits.extend(per_exit[i].iter().map(|&(e, r2)| NearHit {
            point: index[e as usize],
            distance2: r2,
        }));
        exits.push(NearExit {
            texel,
            end: hits.len() as u32,
        });
    }
    NearField {
        rays_per_exit: rays,
        disk,
        indirect_disk: 0.0,
        complement: false,
        points,
        exits,
        hits,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::BvhParams;
    use prm_scene::{AtlasParams, Material, Sizing, Triangle};

    /// A floor and a wall meeting at a right angle along x = 0.
    fn corner() -> Scene {
        let mut tris = Vec::new();
        let mut quad = |a: Vec3, b: Vec3, c: Vec3, d: Vec3| {
            tris.push(Triangle::flat([a, b, c], 0));
            tris.push(Triangle::flat([a, c, d], 0));
        };
        quad(
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(0.0, 0.0, 1.0),
            Vec3::new(1.0, 0.0, 1.0),
            Vec3::new(1.0, 0.0, 0.0),
        );
        quad(
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(0.0, 1.0, 0.0),
            Vec3::new(0.0, 1.0, 1.0),
            Vec3::new(0.0, 0.0, 1.0),
        );
        Scene::from_parts(tris, vec![Material::diffuse("grey", Vec3::splat(0.5))])
    }

    #[test]
    fn exits_near_the_edge_keep_short_rays_on_the_other_face() {
        let scene = corner();
        let bvh = Bvh::build(&scene, &BvhParams::DEFAULT).unwrap();
        let atlas = Atlas::build(&scene, &AtlasParams::with_sizing(Sizing::Resolution(64))).unwrap();
        let disk = near_disk(2.0 / 256.0, 1.0);
        let near = near_field(&scene, &bvh, &atlas, 64, disk, 1);
        let reach = (disk * (1.0 / NEAR_MIN_WEIGHT - 1.0)).sqrt();
        assert!(!near.exits.is_empty() && near.exits.len() < atlas.exits.len());
        let by_texel: std::collections::HashMap<u32, &prm_scene::ExitPoint> =
            atlas.exits.iter().map(|x| (x.texel, x)).collect();
        let gutter: std::collections::HashMap<u32, u32> = atlas.dilation.iter().copied().collect();
        let mut start = 0;
        let mut copies = 0;
        for x in &near.exits {
            let Some(&exit) = by_texel.get(&x.texel) else {
                // A gutter texel: its source's hits.
                let source = gutter[&x.texel];
                assert!(near.exits.iter().any(|y| y.texel == source), "texel {}", x.texel);
                copies += 1;
                start = x.end as usize;
                continue;
            };
            // Only exits within reach of the edge (x = 0 on the floor, y = 0 on the wall).
            let to_edge = if exit.normal.y > 0.5 {
                exit.position.x
            } else {
                exit.position.y
            };
            assert!(
                to_edge <= reach * 1.01,
                "exit at {} is {to_edge} from the edge",
                exit.position
            );
            for h in &near.hits[start..x.end as usize] {
                let p = &near.points[h.point as usize];
                let other = Vec3::from(p.normal).dot(exit.normal) < 0.5;
                let d2 = (Vec3::from(p.position) - exit.position).length_squared();
                assert!(other, "a ray from the floor can only end on the wall");
                assert!(h.distance2 <= reach * reach * 1.01);
                // The stored distance is the hit's; the gather point is its texel's centre.
                assert!(
                    (d2.sqrt() - h.distance2.sqrt()).abs() < 3.0 / 64.0,
                    "{d2} against {}",
                    h.distance2
                );
            }
            start = x.end as usize;
        }
        assert!(copies > 0, "the gutter along the edge copies the near field");
        // The exits closest to the edge keep most of their rays (half the cosine lobe faces
        // the other face).
        let closest = near
            .exits
            .iter()
            .scan(0u32, |s, x| {
                let n = x.end - *s;
                *s = x.end;
                Some((by_texel.get(&x.texel).copied(), n))
            })
            .filter_map(|(e, n)| Some((e?, n)))
            .filter(|(e, _)| (if e.normal.y > 0.5 { e.position.x } else { e.position.y }) < 1.0 / 64.0)
            .map(|(_, n)| n)
            .min()
            .unwrap();
        assert!(closest >= 16, "{closest} of 64 rays kept at the edge");
    }

    #[test]
    fn a_coplanar_patch_over_the_floor_does_not_swallow_its_rays() {
        // The corner, plus a second floor patch lying on the first (same plane, same side, other
        // corners: a decal, or a face listed twice), all turned off the axes so that a ray from
        // the surface itself meets the other copy at a rounding error's distance, as a back face:
        // its exits kept no ray (McGuire's tall block).
        let mut scene = corner();
        let (a, b) = (Vec3::new(0.0, 0.0, 0.25), Vec3::new(0.5, 0.0, 0.75));
        scene
            .triangles
            .push(Triangle::flat([a, Vec3::new(a.x, 0.0, b.z), b], 0));
        scene
            .triangles
            .push(Triangle::flat([a, b, Vec3::new(b.x, 0.0, a.z)], 0));
        let turn = glam::Quat::from_axis_angle(Vec3::new(1.0, 2.0, 3.0).normalize(), 0.7);
        for t in &mut scene.triangles {
            *t = Triangle::flat(t.positions.map(|p| turn * p), 0);
        }
        let bvh = Bvh::build(&scene, &BvhParams::DEFAULT).unwrap();
        let atlas = Atlas::build(&scene, &AtlasParams::with_sizing(Sizing::Resolution(64))).unwrap();
        let disk = near_disk(2.0 / 256.0, 1.0);
        let near = near_field(&scene, &bvh, &atlas, 64, disk, 1);
        let kept: std::collections::HashSet<u32> = near.exits.iter().map(|x| x.texel).collect();
        // Every floor exit within a few texels of the wall, on either copy, keeps rays to it.
        let floor: Vec<_> = atlas
            .exits
            .iter()
            .filter(|x| {
                let (p, n) = (turn.inverse() * x.position, turn.inverse() * x.normal);
                n.y > 0.5 && p.x < 0.05 && p.z > 0.3 && p.z < 0.7
            })
            .collect();
        assert!(floor.iter().any(|x| x.triangle >= 4) && floor.iter().any(|x| x.triangle < 4));
        let lost = floor.iter().filter(|x| !kept.contains(&x.texel)).count();
        assert_eq!(lost, 0, "{lost} of {} exits by the wall kept no ray", floor.len());
    }
}
