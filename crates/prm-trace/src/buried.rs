//! Exit points buried under other geometry, moved to the part of their texel that can see.
//!
//! An exit point is the centroid of the part of its texel that its triangle covers
//! ([`prm_scene::Atlas`]); the atlas knows nothing of the rest of the scene. Where a box stands
//! on a floor, the floor's texels along the contact line have their centre under the box half the
//! time: such a point sees only the box's inside, so its pane is dark, and, worse, it is the gather
//! point of the near field ([`crate::near_field`]) for every ray that ends on the visible part of
//! that texel. The box's foot, which gathers most of its light from those texels at close range,
//! then shows dark blotches one floor texel wide (issue #11's "local error").
//!
//! A point is buried when at least [`BURIED_BACK_FRACTION`] of [`BURIED_RAYS`] cosine rays from
//! it meet a back face first (at any distance: inside a closed box every face is a back face).
//! A buried exit moves to the nearest of a [`SUB`]² grid of points of its texel on its own
//! triangle that is not buried; it stays where it is when there is none (a texel wholly under
//! the box, which nothing sees).
//!
//! Measured on McGuire's CornellBox-Original (`Ke` = 0, the default bake, seed 0; image space as
//! `cargo xtask eval --targets` measures it, 4×4 error and full resolution, the light under the
//! ceiling and the light near the red wall): without the move 3.46% / 5.20% and 3.40% / 5.37%,
//! with it 3.41% / 5.13% and **3.05% / 4.67%**. 1496 of the box's 43 k exit points are buried
//! (the floor under the blocks) and 91 move; the test costs 16 rays per exit point (0.1 s there).
//! Its share of back faces and ray count are not tuned: inside a closed box the share is 1.

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
/// Scrambling seed of the rays (fixed: the test is a property of the scene, not of a bake).
const RAY_SEED: u32 = 0x6275_7279;

/// What [`unbury_exits`] found.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Unburied {
    /// Exit points that were buried.
    pub buried: u32,
    /// Those of them moved to a point of their texel that is not.
    pub moved: u32,
}

/// Whether the point `p` of triangle `tri` (shading normal `n`) sees mostly back faces.
pub fn is_buried(bvh: &Bvh, p: Vec3, n: Vec3, tri: u32) -> bool {
    let ng = bvh.geometric_normal(tri);
    let limit = (BURIED_BACK_FRACTION * BURIED_RAYS as f32).ceil() as u32;
    let mut back = 0;
    for i in 0..BURIED_RAYS {
        let d = cosine_hemisphere(sobol2(i, RAY_SEED), n);
        if let Some(h) = bvh.closest_hit(bvh.spawn(p, ng, d), d, f32::INFINITY, tri) {
            if !h.front {
                back += 1;
                if back >= limit {
                    return true;
                }
            }
        }
    }
    false
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
/// triangle, that is not buried (see the module docs).
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
    for (x, m) in atlas.exits.iter_mut().zip(moves) {
        let Some(m) = m else { continue };
        found.buried += 1;
        if let Some((b1, b2)) = m {
            let tri = &scene.triangles[x.triangle as usize];
            x.position = tri.point(b1, b2);
            x.normal = tri.shading_normal(b1, b2);
            x.albedo = scene.albedo(x.triangle as usize, b1, b2);
            found.moved += 1;
        }
    }
    found
}

#[cfg(test)]
mod tests {
    use super::*;
    use prm_scene::{AtlasParams, Material, Sizing, Triangle};

    /// The cube's extent on x and z: its sides cut through floor texels.
    const LO: f32 = 0.55;
    const HI: f32 = 1.45;

    /// A floor `[0, 2]²` at y = 0 under a closed cube standing on `[LO, HI]²`.
    fn box_on_floor() -> Scene {
        let v = |x: f32, y: f32, z: f32| Vec3::new(x, y, z);
        let quad = |a: Vec3, b: Vec3, c: Vec3, d: Vec3| [Triangle::flat([a, b, c], 0), Triangle::flat([a, c, d], 0)];
        let mut t = Vec::new();
        t.extend(quad(v(0., 0., 0.), v(0., 0., 2.), v(2., 0., 2.), v(2., 0., 0.)));
        let (lo, hi) = (LO, HI);
        // Outward faces of the cube (counter-clockwise seen from outside).
        t.extend(quad(v(lo, 1., lo), v(lo, 1., hi), v(hi, 1., hi), v(hi, 1., lo)));
        t.extend(quad(v(lo, 0., lo), v(hi, 0., lo), v(hi, 0., hi), v(lo, 0., hi)));
        t.extend(quad(v(lo, 0., lo), v(lo, 1., lo), v(hi, 1., lo), v(hi, 0., lo)));
        t.extend(quad(v(lo, 0., hi), v(hi, 0., hi), v(hi, 1., hi), v(lo, 1., hi)));
        t.extend(quad(v(lo, 0., lo), v(lo, 0., hi), v(lo, 1., hi), v(lo, 1., lo)));
        t.extend(quad(v(hi, 0., lo), v(hi, 1., lo), v(hi, 1., hi), v(hi, 0., hi)));
        Scene::from_parts(t, vec![Material::diffuse("m", Vec3::splat(0.5))])
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

    #[test]
    fn buried_exits_move_into_the_visible_part_of_their_texel() {
        let scene = box_on_floor();
        let bvh = Bvh::build(&scene, &crate::BvhParams::DEFAULT).unwrap();
        let mut atlas = Atlas::build(&scene, &AtlasParams::with_sizing(Sizing::Resolution(64))).unwrap();
        let before = atlas.exits.clone();
        let found = unbury_exits(&scene, &bvh, &mut atlas);
        assert!(
            found.buried > 0 && found.moved > 0 && found.moved < found.buried,
            "{found:?}"
        );
        let mut moved = 0;
        for (a, b) in before.iter().zip(&atlas.exits) {
            assert_eq!((a.texel, a.triangle), (b.texel, b.triangle));
            if a.position != b.position {
                moved += 1;
                assert!(is_buried(&bvh, a.position, a.normal, a.triangle));
                assert!(!is_buried(&bvh, b.position, b.normal, b.triangle));
                // Still on the floor, within a texel's reach of where it was.
                assert!(a.normal.y > 0.9 && b.position.y.abs() < 1e-5);
                assert!(a.position.distance(b.position) < 2.0 * atlas.stats.texel_size);
                // Moved out from under the box.
                let under = |p: Vec3| (LO..=HI).contains(&p.x) && (LO..=HI).contains(&p.z);
                assert!(
                    under(a.position) && !under(b.position),
                    "{} → {}",
                    a.position,
                    b.position
                );
            }
        }
        assert_eq!(moved, found.moved);
    }
}
