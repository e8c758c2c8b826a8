//! The near field (`prm_format::NearField`): short cosine rays from every exit
//! point, kept where they end close enough for the VPL disk bound ([`crate::VplBound`]) to
//! have removed light, so that the run time gathers that light back from the surfaces' direct
//! light of the frame.
//!
//! The bound loses most at inner edges and contacts (exit points on a concave edge get about half
//! of what they should). The depth-0 VPLs, one per entry point standing for the area `A/N`, carry
//! the entry points' direct light; what the disk `R² = A/(N·π)` removes around them is
//! `∫ L_direct(ω) · R²/(r² + R²) cos θ dω`, which the run time knows at every texel each frame.
//! Rays are kept while `R²/(r² + R²) ≥ prm_format::NEAR_MIN_WEIGHT`, so they are at most
//! `R·√15 ≈ 3.9 R` long and cheap: 0.17 s for the 43k exits of the Cornell box at [`NEAR_RAYS`].
//! The deeper VPLs take their entry point's disk ([`crate::DeepDisk::Entry`]), so one set of rays
//! gathers both shares: the player adds `π/M · Σ I_g · R²/(r² + R²)` for the radiance `I_g` of the
//! lightmap's indirect light at the gather point. Beyond the cut the panes keep `1/r²`
//! (`VplBound::Near`) and the section's weights are rescaled to match (`NearField::complement`),
//! so the two sum to `1/r²` and no light is lost at any disk size.
//!
//! An exit point's rays are one Owen-scrambled Sobol set ([`sobol2`], scrambled per exit point),
//! stratified over the hemisphere, and leave from just off the surface ([`Bvh::spawn`]), so that a
//! coplanar copy of the exit's triangle is not met at once as a back face. Gather points stay at
//! their texel's exit point.
//!
//! Measured by `cargo xtask eval --targets` (indirect light, 4×4 error): the fireplace room's
//! default bake under its lamp is 5.5% and 6.3% off at seeds 0 and 1; per exit point on the CPU,
//! `cargo xtask eval experiment near_field SCENE ARCHIVE FX FY FZ`.

use glam::Vec3;
use prm_format::{NearExit, NearField, NearHit, NEAR_MIN_WEIGHT};
use prm_scene::{Atlas, Scene, EMPTY_TEXEL};
use rayon::prelude::*;

use crate::bvh::Bvh;
use crate::probes::{gather_points, HitTexels};
use crate::rng::Rng;
use crate::sampling::{cosine_hemisphere, sobol2};

/// Default rays per exit point. Measured against the reference tracer in image space (4×4
/// error; McGuire's box and the fireplace room as `cargo xtask eval --targets` lights and views
/// them, `--near-rays` on their default and `--time-budget 120` bakes): 64 rays 2.14% / 1.81%
/// (box, ceiling light / red wall light) and 4.59% (fireplace), 32 rays 2.17% / 1.89% and
/// 4.78%, 16 rays 2.23% / 2.25%. Each halving halves the near field in the archive, on the GPU
/// and in every gather: on the box 18.0 → 13.4 → 10.9 MiB of archive.
pub const NEAR_RAYS: u32 = 32;
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
    let mut near = NearField {
        rays_per_exit: rays,
        disk,
        indirect_disk: 0.0,
        complement: false,
        points,
        exits,
        hits,
    };
    near.round_to_stored();
    near
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::BvhParams;
    use prm_scene::{AtlasParams, Sizing, Triangle};

    /// A floor and a wall meeting at a right angle along x = 0.
    fn corner() -> Scene {
        let v = Vec3::new;
        crate::grey_quads(&[
            [v(0.0, 0.0, 0.0), v(0.0, 0.0, 1.0), v(1.0, 0.0, 1.0), v(1.0, 0.0, 0.0)],
            [v(0.0, 0.0, 0.0), v(0.0, 1.0, 0.0), v(0.0, 1.0, 1.0), v(0.0, 0.0, 1.0)],
        ])
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
