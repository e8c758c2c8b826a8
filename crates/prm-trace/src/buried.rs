//! Exit points buried under other geometry, moved to the part of their texel that can see, or to a neighbour's point.
//!
//! An exit point is the centroid of the part of its texel that its triangle covers
//! ([`prm_scene::Atlas`]); the atlas knows nothing of the rest of the scene. Where a box stands
//! on a floor, the floor's texels along the contact line have their centre under the box half the
//! time: such a point sees only the box's inside, so its pane is dark, and, worse, it is the gather
//! point of the near field ([`crate::near_field`]) for every ray that ends on the visible part of
//! that texel. The box's foot, which gathers most of its light from those texels at close range,
//! then shows dark blotches one floor texel wide (the local error the eval's `--targets` mode
//! measures).
//!
//! A point is buried when at least [`BURIED_BACK_FRACTION`] of [`BURIED_RAYS`] cosine rays from
//! it meet a back face first (at any distance: inside a closed box every face is a back face).
//! A buried exit moves to the nearest of a `SUB`² grid of points of its texel on its own
//! triangle that is not buried; it stays where it is when there is none (a texel wholly under
//! the box, which nothing sees).
//!
//! Measured on McGuire's CornellBox-Original (`Ke` = 0, the default bake, seed 0; image space as
//! `cargo xtask eval --targets` measures it, 4×4 error and full resolution, the light under the
//! ceiling and the light near the red wall): without the move 3.46% / 5.20% and 3.40% / 5.37%,
//! with it 3.41% / 5.13% and **3.05% / 4.67%**. 1496 of the box's 43 k exit points are buried
//! (the floor under the blocks) and 91 move; the test costs 16 rays per exit point (0.1 s there).
//! Its share of back faces and ray count are not tuned: inside a closed box the share is 1.
//!
//! An exit no point of whose texel is free stays buried with a dark pane. No pixel shows it, but
//! the bilinear lookups of the visible pixels beside it fetch it: a dark seam along every contact
//! (a window frame on a wall, a sofa on the floor). When it is shut in, every one of its rays
//! meeting a back face, it takes the point (normal, albedo, triangle) of the nearest exit of its
//! chart within `NEIGHBOUR_REACH` texels that is not buried, faces within `NEIGHBOUR_COS` and
//! stands within `NEIGHBOUR_PLANE` texels of its plane, and so holds that neighbour's light,
//! as a gutter texel holds its source's. Measured on the fireplace room (image space as
//! `cargo xtask eval --targets` measures it, the default bake's sizes, seed 0): of 120,695 exit
//! points 10,631 are buried, 1,071 move within their texel and 2,315 take a neighbour's point;
//! the indirect light 8.68% off (9.30% without the move; full resolution 14.51%, energy 0.994),
//! the local error 4.1× in the same window. With normals within 0.9 and no plane test
//! 5,051 took one, 8.61%, but so did leaves of the room's plant: single-sided, a visible leaf can
//! face only other leaves' backs, and those texels showed their lit neighbours' light (a window
//! at 1.8 times the reference, local error 5.8×). McGuire's boxes, CornellBox-Sphere and chairs
//! stay within 0.01 points (the eval's targets table, README). The cost is at thin slivers: our
//! two-lamp Cornell box is 4.15% off instead of 3.86% (`cargo xtask eval --emitters`), its lamps' rims
//! against the ceiling, texels mostly inside it, taking points up to two texels farther from the
//! ceiling than the sliver the camera sees. A reach of one texel is not measured.

use glam::{Vec2, Vec3};
use prm_scene::{Atlas, AtlasParams, Scene, SceneError};
use rayon::prelude::*;

use crate::bvh::Bvh;
use crate::sampling::{cosine_hemisphere, sobol2};

/// Rays that decide whether a point is buried.
pub const BURIED_RAYS: u32 = 16;
/// The share of back-face hits from which a point counts as buried.
pub const BURIED_BACK_FRACTION: f32 = 0.5;
/// Candidate points per texel side when a buried exit looks for a place to move to.
const SUB: u32 = 4;
/// How many texels away a buried exit that cannot move looks for an exit of its chart to copy:
/// a visible pixel's bilinear lookup reaches one texel from the texel it falls on, which may be
/// buried at its centre too.
const NEIGHBOUR_REACH: i64 = 2;
/// The least cosine between the normals of a buried exit and the exit it copies.
const NEIGHBOUR_COS: f32 = 0.99;
/// How far, in texel sizes, the exit a buried one copies may stand off its plane.
const NEIGHBOUR_PLANE: f32 = 0.25;
/// Scrambling seed of the rays (fixed: the test is a property of the scene, not of a bake).
const RAY_SEED: u32 = 0x6275_7279;

/// What [`unbury_exits`] found.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Unburied {
    /// Exit points that were buried.
    pub buried: u32,
    /// Those of them moved to a point of their texel that is not.
    pub moved: u32,
    /// Those of them that took the point of a neighbouring exit of their chart instead (no
    /// point of their texel sees the scene).
    pub copied: u32,
}

/// For each of the [`BURIED_RAYS`] cosine rays from the point `p` of triangle `tri` (shading
/// normal `n`), lazily: whether it meets a back face first.
fn back_face_rays(bvh: &Bvh, p: Vec3, n: Vec3, tri: u32) -> impl Iterator<Item = bool> + '_ {
    let ng = bvh.geometric_normal(tri);
    (0..BURIED_RAYS).map(move |i| {
        let d = cosine_hemisphere(sobol2(i, RAY_SEED), n);
        bvh.closest_hit(bvh.spawn(p, ng, d), d, f32::INFINITY, tri)
            .is_some_and(|h| !h.front)
    })
}

/// Whether the point `p` of triangle `tri` (shading normal `n`) sees mostly back faces.
pub fn is_buried(bvh: &Bvh, p: Vec3, n: Vec3, tri: u32) -> bool {
    let limit = (BURIED_BACK_FRACTION * BURIED_RAYS as f32).ceil() as usize;
    back_face_rays(bvh, p, n, tri).filter(|&back| back).take(limit).count() == limit
}

/// Whether every one of the [`BURIED_RAYS`] cosine rays from `p` meets a back face first: the
/// point is shut in (under a box, behind a frame on a wall), not merely among single-sided
/// surfaces seen from behind (a plant's leaves, where about half the rays do).
fn is_enclosed(bvh: &Bvh, p: Vec3, n: Vec3, tri: u32) -> bool {
    back_face_rays(bvh, p, n, tri).all(|back| back)
}

/// The atlas of `params` with the exit points the bake traces from: [`Atlas::build`], then
/// [`unbury_exits`]. Whatever compares with a bake at its exit points (the reference's
/// lightmaps, tests, the eval) builds its atlas here.
pub fn bake_atlas(scene: &Scene, bvh: &Bvh, params: &AtlasParams) -> Result<Atlas, SceneError> {
    let mut atlas = Atlas::build(scene, params)?;
    unbury_exits(scene, bvh, &mut atlas);
    Ok(atlas)
}

/// Moves every buried exit point of `atlas` to the nearest point of its texel, on its own
/// triangle, that is not buried, or, when there is none, to the nearest exit point of its chart
/// nearby that is not (see the module docs).
pub fn unbury_exits(scene: &Scene, bvh: &Bvh, atlas: &mut Atlas) -> Unburied {
    let res = atlas.resolution;
    let rf = res as f32;
    let uvs = &atlas.uvs;
    let moves: Vec<Option<Option<(f32, f32)>>> = atlas
        .exits
        .par_iter()
        .map(|x| {
            if !is_buried(bvh, x.position, x.normal, x.triangle) {
                return None;
            }
            let tex = uvs[x.triangle as usize].map(|u| u * rf);
            let (tx, ty) = ((x.texel % res) as f32, (x.texel / res) as f32);
            let centre = Vec2::new(tx + 0.5, ty + 0.5);
            let mut candidates: Vec<(f32, f32, f32)> = (0..SUB * SUB)
                .filter_map(|s| {
                    let p = Vec2::new(
                        tx + ((s % SUB) as f32 + 0.5) / SUB as f32,
                        ty + ((s / SUB) as f32 + 0.5) / SUB as f32,
                    );
                    let (b0, b1, b2) = prm_scene::barycentric(&tex, p)?;
                    (b0 >= 0.0 && b1 >= 0.0 && b2 >= 0.0).then_some((p.distance_squared(centre), b1, b2))
                })
                .collect();
            candidates.sort_by(|a, b| a.0.total_cmp(&b.0));
            let tri = &scene.triangles[x.triangle as usize];
            Some(
                candidates
                    .into_iter()
                    .find(|&(_, b1, b2)| !is_buried(bvh, tri.point(b1, b2), tri.shading_normal(b1, b2), x.triangle))
                    .map(|(_, b1, b2)| (b1, b2)),
            )
        })
        .collect();
    let mut found = Unburied::default();
    for (x, m) in atlas.exits.iter_mut().zip(&moves) {
        let Some(m) = m else { continue };
        found.buried += 1;
        if let Some((b1, b2)) = *m {
            let tri = &scene.triangles[x.triangle as usize];
            x.position = tri.point(b1, b2);
            x.normal = tri.shading_normal(b1, b2);
            x.albedo = scene.albedo(x.triangle as usize, b1, b2);
            found.moved += 1;
        }
    }
    // The exits no point of whose texel sees the scene, shut in (every ray from the exit meets
    // a back face), take the point of the nearest exit of their chart that does, within
    // NEIGHBOUR_REACH texels, facing within NEIGHBOUR_COS and within NEIGHBOUR_PLANE texels of
    // their plane: such a texel shows nowhere itself, but the bilinear lookups of the visible
    // texels beside it fetch it, and its own pane is dark.
    let still: Vec<bool> = moves.iter().map(|m| matches!(m, Some(None))).collect();
    let texel_size = atlas.stats.texel_size;
    let exits = &atlas.exits;
    let sources: Vec<Option<usize>> = (0..exits.len())
        .into_par_iter()
        .map(|i| {
            let x = &exits[i];
            if !still[i] || !is_enclosed(bvh, x.position, x.normal, x.triangle) {
                return None;
            }
            let chart = atlas.chart_of_triangle[x.triangle as usize];
            let (tx, ty) = ((x.texel % res) as i64, (x.texel / res) as i64);
            let mut best: Option<(i64, usize)> = None;
            for dy in -NEIGHBOUR_REACH..=NEIGHBOUR_REACH {
                for dx in -NEIGHBOUR_REACH..=NEIGHBOUR_REACH {
                    let (nx, ny) = (tx + dx, ty + dy);
                    if nx < 0 || ny < 0 || nx >= res as i64 || ny >= res as i64 {
                        continue;
                    }
                    let e = atlas.texel_exit[(ny * res as i64 + nx) as usize];
                    if e == prm_scene::EMPTY_TEXEL || still[e as usize] {
                        continue;
                    }
                    let n = &exits[e as usize];
                    let d = dx * dx + dy * dy;
                    if atlas.chart_of_triangle[n.triangle as usize] == chart
                        && n.normal.dot(x.normal) >= NEIGHBOUR_COS
                        && (n.position - x.position).dot(x.normal).abs() <= NEIGHBOUR_PLANE * texel_size
                        && best.is_none_or(|(bd, _)| d < bd)
                    {
                        best = Some((d, e as usize));
                    }
                }
            }
            best.map(|(_, e)| e)
        })
        .collect();
    for (i, src) in sources.into_iter().enumerate() {
        if let Some(src) = src {
            // All of it but the texel and its coverage: the triangle goes with the point (the
            // rays from it skip that triangle and spawn off its geometric normal).
            let s = atlas.exits[src];
            let x = &mut atlas.exits[i];
            (x.position, x.normal, x.albedo, x.triangle) = (s.position, s.normal, s.albedo, s.triangle);
            found.copied += 1;
        }
    }
    found
}

#[cfg(test)]
mod tests {
    use super::*;
    use prm_scene::{AtlasParams, ExitPoint, Sizing};

    /// The cube's extent on x and z: its sides cut through floor texels.
    const LO: f32 = 0.55;
    const HI: f32 = 1.45;

    /// A floor `[0, 2]²` at y = 0 under a closed cube standing on `[LO, HI]²`.
    fn box_on_floor() -> Scene {
        let v = |x: f32, y: f32, z: f32| Vec3::new(x, y, z);
        let (lo, hi) = (LO, HI);
        crate::grey_quads(&[
            [v(0., 0., 0.), v(0., 0., 2.), v(2., 0., 2.), v(2., 0., 0.)],
            // Outward faces of the cube (counter-clockwise seen from outside).
            [v(lo, 1., lo), v(lo, 1., hi), v(hi, 1., hi), v(hi, 1., lo)],
            [v(lo, 0., lo), v(hi, 0., lo), v(hi, 0., hi), v(lo, 0., hi)],
            [v(lo, 0., lo), v(lo, 1., lo), v(hi, 1., lo), v(hi, 0., lo)],
            [v(lo, 0., hi), v(hi, 0., hi), v(hi, 1., hi), v(lo, 1., hi)],
            [v(lo, 0., lo), v(lo, 0., hi), v(lo, 1., hi), v(lo, 1., lo)],
            [v(hi, 0., lo), v(hi, 1., lo), v(hi, 1., hi), v(hi, 0., hi)],
        ])
    }

    #[test]
    fn floor_points_under_the_box_are_buried_and_the_others_not() {
        let scene = box_on_floor();
        let bvh = Bvh::build(&scene, &crate::BvhParams::DEFAULT).unwrap();
        let up = Vec3::Y;
        assert!(is_buried(&bvh, Vec3::new(1.0, 0.0, 1.0), up, 0));
        for p in [
            Vec3::new(0.2, 0.0, 0.2),
            Vec3::new(0.45, 0.0, 1.0),
            Vec3::new(1.0, 0.0, 1.7),
        ] {
            assert!(!is_buried(&bvh, p, up, 0) && !is_buried(&bvh, p, up, 1), "{p}");
        }
    }

    /// The texel under the point `p` of triangle `tri`.
    fn texel_of(scene: &Scene, atlas: &Atlas, tri: u32, p: Vec3) -> u32 {
        let [a, b, c] = scene.triangles[tri as usize].positions;
        let (v0, v1, v2) = (b - a, c - a, p - a);
        let (d00, d01, d11) = (v0.dot(v0), v0.dot(v1), v1.dot(v1));
        let (d20, d21) = (v2.dot(v0), v2.dot(v1));
        let det = d00 * d11 - d01 * d01;
        let (v, w) = ((d11 * d20 - d01 * d21) / det, (d00 * d21 - d01 * d20) / det);
        let [ua, ub, uc] = atlas.uvs[tri as usize];
        let uv = (ua * (1.0 - v - w) + ub * v + uc * w) * atlas.resolution as f32;
        uv.y as u32 * atlas.resolution + uv.x as u32
    }

    #[test]
    fn buried_exits_move_into_the_visible_part_of_their_texel_or_a_neighbours() {
        let scene = box_on_floor();
        let bvh = Bvh::build(&scene, &crate::BvhParams::DEFAULT).unwrap();
        let mut atlas = Atlas::build(&scene, &AtlasParams::with_sizing(Sizing::Resolution(64))).unwrap();
        let before = atlas.exits.clone();
        let found = unbury_exits(&scene, &bvh, &mut atlas);
        // Some move within their texel, some (wholly under the box, near its edge) take a
        // neighbour's point, and those deep under the box stay: nothing there sees.
        assert!(
            found.moved > 0 && found.copied > 0 && found.moved + found.copied < found.buried,
            "{found:?}"
        );
        let ts = atlas.stats.texel_size;
        let under = |p: Vec3| (LO..=HI).contains(&p.x) && (LO..=HI).contains(&p.z);
        let (mut moved, mut copied) = (0, 0);
        for (a, b) in before.iter().zip(&atlas.exits) {
            assert_eq!(a.texel, b.texel);
            if a.position == b.position {
                continue;
            }
            assert!(is_buried(&bvh, a.position, a.normal, a.triangle));
            assert!(!is_buried(&bvh, b.position, b.normal, b.triangle));
            // Still on the floor, and out from under the box.
            assert!(a.normal.y > 0.9 && b.position.y.abs() < 1e-5 && b.normal.y > 0.9);
            assert!(
                under(a.position) && !under(b.position),
                "{} → {}",
                a.position,
                b.position
            );
            let chart = |x: &ExitPoint| atlas.chart_of_triangle[x.triangle as usize];
            assert_eq!(chart(a), chart(b));
            if texel_of(&scene, &atlas, b.triangle, b.position) != b.texel {
                // A neighbour's point: within NEIGHBOUR_REACH texels (and its own texel).
                copied += 1;
                let reach = (NEIGHBOUR_REACH as f32 + 1.0) * std::f32::consts::SQRT_2;
                assert!(a.position.distance(b.position) < reach * ts);
            } else {
                // Within its texel, on its triangle.
                moved += 1;
                assert_eq!(a.triangle, b.triangle);
                assert!(a.position.distance(b.position) < 2.0 * ts);
            }
        }
        assert_eq!((moved, copied), (found.moved, found.copied));
    }
}
