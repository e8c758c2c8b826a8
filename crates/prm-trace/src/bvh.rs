//! Ray casting against the scene's triangles with obvhs: closest hit and occlusion.
//!
//! Self-intersection: rays leaving a surface start at the surface point pushed along the
//! triangle's *geometric* normal, towards the side the ray leaves to, by [`Bvh::epsilon`]
//! (`offset_scale` × scene diagonal plus a few ulps of the largest coordinate), and the triangle
//! they leave from is ignored during traversal. Shadow rays are shortened by the same epsilon at
//! the far end and ignore the far triangle too. The offset is far below the thickness of any wall
//! in our scenes, so it does not leak through them.
//!
//! Both obvhs layouts are available ([`BvhKind`]); the default is the compressed wide BVH8
//! (CWBVH). In `cargo xtask eval experiment bench_trace` (release, 2 cores shared with other jobs) it traced
//! incoherent rays 10–20 % faster than BVH2 on the largest scene, sibenik (75k triangles: closest
//! hit 0.98 vs 0.84 Mrays/s, shadow rays 1.09 vs 0.90, walks 0.54 vs 0.40 M/s), and was
//! equal or faster on cornell-box and chairs within run-to-run noise; BVH2 builds about 30 %
//! faster (49 vs 68 ms on sibenik), which does not matter next to tracing. Hence
//! CWBVH. Its node test has an absolute `1e-4` distance clamp, worked around by building in a
//! rescaled frame ([`BVH_SPACE_DIAGONAL`]).

use std::time::{Duration, Instant};

use glam::{UVec2, Vec3, Vec3A};
use obvhs::bvh2::builder::build_bvh2_from_tris;
use obvhs::bvh2::Bvh2;
use obvhs::cwbvh::builder::build_cwbvh_from_tris;
use obvhs::cwbvh::CwBvh;
use obvhs::ray::{Ray, RayHit};
use obvhs::triangle::Triangle as RtTriangle;
use obvhs::BvhBuildParams;
use prm_scene::Scene;

use crate::TraceError;

/// Which obvhs acceleration structure to build.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BvhKind {
    /// Compressed 8-wide BVH (Ylitie et al.), traversed 4 nodes at a time with SIMD.
    Cwbvh,
    /// Binary BVH.
    Bvh2,
}

/// How hard the builder tries (obvhs presets).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BuildQuality {
    /// `BvhBuildParams::fast_build`.
    Fast,
    /// `BvhBuildParams::medium_build`.
    Medium,
    /// `BvhBuildParams::slow_build` (spatial pre-splits).
    Slow,
}

/// BVH construction parameters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BvhParams {
    /// Layout.
    pub kind: BvhKind,
    /// Builder preset.
    pub quality: BuildQuality,
    /// Ray origin offset as a fraction of the scene diagonal.
    pub offset_scale: f32,
}

impl BvhParams {
    /// CWBVH, medium build, offset 1e-5 of the diagonal.
    pub const DEFAULT: BvhParams = BvhParams {
        kind: BvhKind::Cwbvh,
        quality: BuildQuality::Medium,
        offset_scale: 1e-5,
    };
    /// BVH2 with the default settings otherwise.
    pub const BVH2: BvhParams = BvhParams {
        kind: BvhKind::Bvh2,
        ..Self::DEFAULT
    };
}

impl Default for BvhParams {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// A ray–triangle hit.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    /// Scene triangle index.
    pub triangle: u32,
    /// Distance along the (unit) ray direction.
    pub t: f32,
    /// Barycentric `(b1, b2)` (weights of corners 1 and 2).
    pub b1: f32,
    /// See `b1`.
    pub b2: f32,
    /// Whether the ray hit the side the geometric normal points to.
    pub front: bool,
}

enum Accel {
    Cw(CwBvh),
    Two(Bvh2),
}

/// A ray-casting structure over a scene's triangles.
pub struct Bvh {
    accel: Accel,
    /// Triangles in BVH primitive order.
    tris: Vec<RtTriangle>,
    /// Scene triangle of every BVH primitive.
    ids: Vec<u32>,
    /// Unit geometric normal of every scene triangle.
    normals: Vec<Vec3>,
    epsilon: f32,
    /// Scene-to-BVH scale (see [`BVH_SPACE_DIAGONAL`]).
    scale: f32,
    build_time: Duration,
}

/// The BVH is built over the scene scaled so that its diagonal is this long. obvhs's CWBVH node
/// test clamps the entry distance to an absolute `1e-4` (`cwbvh::node::EPSILON`), so hits nearer
/// than that are lost and rays leak through nearby walls (seen in a unit box near its edges).
/// In this frame the clamp is `1e-8` of the diagonal, below the self-intersection offset.
pub const BVH_SPACE_DIAGONAL: f32 = 1e4;

impl Bvh {
    /// Builds the structure for `scene`.
    pub fn build(scene: &Scene, params: &BvhParams) -> Result<Bvh, TraceError> {
        if scene.triangles.is_empty() {
            return Err(TraceError::EmptyScene);
        }
        if !(params.offset_scale >= 0.0 && params.offset_scale < 0.01) {
            return Err(TraceError::InvalidParameter(format!(
                "offset_scale {} is outside [0, 0.01)",
                params.offset_scale
            )));
        }
        let start = Instant::now();
        let bounds = scene.bounds();
        let diagonal = bounds.diagonal();
        if !(diagonal > 0.0 && diagonal.is_finite()) {
            return Err(TraceError::EmptyScene);
        }
        let scale = BVH_SPACE_DIAGONAL / diagonal;
        let input: Vec<RtTriangle> = scene
            .triangles
            .iter()
            .map(|t| RtTriangle {
                v0: (t.positions[0] * scale).into(),
                v1: (t.positions[1] * scale).into(),
                v2: (t.positions[2] * scale).into(),
            })
            .collect();
        let config = match params.quality {
            BuildQuality::Fast => BvhBuildParams::fast_build(),
            BuildQuality::Medium => BvhBuildParams::medium_build(),
            BuildQuality::Slow => BvhBuildParams::slow_build(),
        };
        let mut core = Duration::ZERO;
        let (accel, indices) = match params.kind {
            BvhKind::Cwbvh => {
                let b = build_cwbvh_from_tris(&input, config, &mut core);
                let i = b.primitive_indices.clone();
                (Accel::Cw(b), i)
            }
            BvhKind::Bvh2 => {
                let b = build_bvh2_from_tris(&input, config, &mut core);
                let i = b.primitive_indices.clone();
                (Accel::Two(b), i)
            }
        };
        let tris = indices.iter().map(|&i| input[i as usize]).collect();
        let max_abs = bounds.min.abs().max(bounds.max.abs()).max_element();
        let epsilon = params.offset_scale * bounds.diagonal() + 8.0 * f32::EPSILON * max_abs;
        Ok(Bvh {
            accel,
            tris,
            ids: indices,
            normals: scene.triangles.iter().map(|t| t.normal()).collect(),
            epsilon,
            scale,
            build_time: start.elapsed(),
        })
    }

    /// Wall-clock build time (including triangle conversion).
    pub fn build_time(&self) -> Duration {
        self.build_time
    }

    /// Origin offset used against self-intersection, scene units.
    pub fn epsilon(&self) -> f32 {
        self.epsilon
    }

    /// Unit geometric normal of scene triangle `tri`.
    pub fn geometric_normal(&self, tri: u32) -> Vec3 {
        self.normals[tri as usize]
    }

    /// Origin for a ray leaving point `p` of a surface with geometric normal `ng` along `dir`:
    /// `p` pushed by [`Bvh::epsilon`] along `ng` to the side `dir` goes to.
    pub fn spawn(&self, p: Vec3, ng: Vec3, dir: Vec3) -> Vec3 {
        if ng.dot(dir) >= 0.0 {
            p + ng * self.epsilon
        } else {
            p - ng * self.epsilon
        }
    }

    /// The ray `origin + t·dir`, `tmin ≤ t ≤ tmax`, in the BVH's units.
    ///
    /// A `-0.0` component of `dir` (`-Vec3::Y` has two) becomes `+0.0`: obvhs inverts it to a
    /// negative slope but orders the node's slabs as for a positive one, and the ray then misses
    /// every box.
    #[inline(always)]
    fn scaled_ray(&self, origin: Vec3, dir: Vec3, tmin: f32, tmax: f32) -> Ray {
        Ray::new(
            (origin * self.scale).into(),
            (dir + Vec3::ZERO).into(),
            tmin * self.scale,
            tmax * self.scale,
        )
    }

    /// Closest hit of the ray `origin + t·dir` (`dir` unit), `t < tmax`, ignoring triangle `ignore`
    /// (pass `u32::MAX` to ignore none).
    pub fn closest_hit(&self, origin: Vec3, dir: Vec3, tmax: f32, ignore: u32) -> Option<Hit> {
        #[cfg(target_arch = "x86_64")]
        if crate::isa::avx2() {
            // SAFETY: `isa::avx2` checked that the CPU has every feature the variant is built for.
            return unsafe { self.closest_hit_avx2(origin, dir, tmax, ignore) };
        }
        self.closest_hit_inline(origin, dir, tmax, ignore)
    }

    /// [`Bvh::closest_hit`] built for AVX2 and FMA ([`crate::isa`]).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma,bmi1,bmi2,lzcnt")]
    fn closest_hit_avx2(&self, origin: Vec3, dir: Vec3, tmax: f32, ignore: u32) -> Option<Hit> {
        self.closest_hit_inline(origin, dir, tmax, ignore)
    }

    /// The body of [`Bvh::closest_hit`], inlined into each instruction-set variant.
    #[inline(always)]
    fn closest_hit_inline(&self, origin: Vec3, dir: Vec3, tmax: f32, ignore: u32) -> Option<Hit> {
        let o = origin * self.scale;
        let ray = self.scaled_ray(origin, dir, 0.0, tmax);
        let mut hit = RayHit::none();
        let f = |r: &Ray, i: usize| {
            if self.ids[i] == ignore {
                f32::INFINITY
            } else {
                intersect(&self.tris[i], r)
            }
        };
        let found = match &self.accel {
            Accel::Cw(b) => cw_closest(b, ray, &mut hit, f),
            Accel::Two(b) => b.ray_traverse(ray, &mut hit, f),
        };
        if !found {
            return None;
        }
        let tri = &self.tris[hit.primitive_id as usize];
        let triangle = self.ids[hit.primitive_id as usize];
        let (b1, b2) = barycentric(tri, o + dir * hit.t);
        Some(Hit {
            triangle,
            t: hit.t / self.scale,
            b1,
            b2,
            front: self.normals[triangle as usize].dot(dir) < 0.0,
        })
    }

    /// Whether anything blocks `origin + t·dir` for `t < tmax`, ignoring the triangles in `ignore`.
    pub fn occluded(&self, origin: Vec3, dir: Vec3, tmax: f32, ignore: [u32; 2]) -> bool {
        self.occluded_between(origin, dir, 0.0, tmax, ignore)
    }

    /// Whether anything blocks `origin + t·dir` for `tmin ≤ t < tmax`, ignoring `ignore`.
    pub fn occluded_between(&self, origin: Vec3, dir: Vec3, tmin: f32, tmax: f32, ignore: [u32; 2]) -> bool {
        self.occluded_cached(origin, dir, tmin, tmax, ignore, &mut { NO_OCCLUDER })
    }

    /// [`Bvh::occluded_between`] that first tests the occluder in `cache` (from an earlier ray,
    /// or [`NO_OCCLUDER`]) and leaves the occluder it finds there: neighbouring shadow rays
    /// towards one light are mostly blocked by the same triangle, which is then one triangle
    /// test instead of a traversal. The answer is the traversal's either way (the cached
    /// triangle counts under the same test, `t < tmax`).
    pub fn occluded_cached(
        &self,
        origin: Vec3,
        dir: Vec3,
        tmin: f32,
        tmax: f32,
        ignore: [u32; 2],
        cache: &mut u32,
    ) -> bool {
        let ray = self.scaled_ray(origin, dir, tmin, tmax);
        #[cfg(target_arch = "x86_64")]
        if crate::isa::avx2() {
            // SAFETY: `isa::avx2` checked that the CPU has every feature the variant is built for.
            return unsafe { self.occluded_cached_avx2(&ray, ignore, cache) };
        }
        self.occluded_cached_inline(&ray, ignore, cache)
    }

    /// [`Bvh::occluded_cached`] built for AVX2 and FMA ([`crate::isa`]), on the ray in BVH units.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma,bmi1,bmi2,lzcnt")]
    fn occluded_cached_avx2(&self, ray: &Ray, ignore: [u32; 2], cache: &mut u32) -> bool {
        self.occluded_cached_inline(ray, ignore, cache)
    }

    /// The body of [`Bvh::occluded_cached`], inlined into each instruction-set variant.
    #[inline(always)]
    fn occluded_cached_inline(&self, ray: &Ray, ignore: [u32; 2], cache: &mut u32) -> bool {
        let ray = *ray;
        let blocks = |r: &Ray, i: usize| {
            let id = self.ids[i];
            if id == ignore[0] || id == ignore[1] {
                f32::INFINITY
            } else {
                intersect(&self.tris[i], r)
            }
        };
        if *cache != NO_OCCLUDER && blocks(&ray, *cache as usize) < ray.tmax {
            return true;
        }
        let mut found = NO_OCCLUDER;
        let f = |r: &Ray, i: usize| {
            let t = blocks(r, i);
            if t < r.tmax {
                found = i as u32;
            }
            t
        };
        let miss = match &self.accel {
            Accel::Cw(b) => cw_miss(b, ray, f),
            Accel::Two(b) => b.ray_traverse_miss(ray, f),
        };
        if !miss {
            *cache = found;
        }
        !miss
    }

    /// Mutual visibility of two surface points `a` (on triangle `ta`, geometric normal `na`) and
    /// `b`: both ends are offset along their normals towards each other and the segment is tested
    /// with both triangles ignored, skipping the first [`Bvh::epsilon`] of it (so that a receiver
    /// lying exactly on a concave edge is not shadowed by the neighbouring face it touches).
    pub fn visible(&self, a: Vec3, na: Vec3, ta: u32, b: Vec3, nb: Vec3, tb: u32) -> bool {
        self.visible_cached(a, na, ta, b, nb, tb, &mut { NO_OCCLUDER })
    }

    /// [`Bvh::visible`] with an occluder cache ([`Bvh::occluded_cached`]).
    #[allow(clippy::too_many_arguments)]
    pub fn visible_cached(&self, a: Vec3, na: Vec3, ta: u32, b: Vec3, nb: Vec3, tb: u32, cache: &mut u32) -> bool {
        let d = b - a;
        let o = self.spawn(a, na, d);
        let target = self.spawn(b, nb, -d);
        let v = target - o;
        let len = v.length();
        if len.is_nan() || len <= 0.0 {
            return true;
        }
        !self.occluded_cached(o, v / len, self.epsilon.min(0.5 * len), len, [ta, tb], cache)
    }
}

/// `CwBvh::ray_traverse` written with obvhs's `traverse!` macro, so that the traversal is
/// expanded (and compiled) inside each instruction-set variant of the query ([`crate::isa`]):
/// obvhs's own method is a separate function built for the baseline, which the AVX2 variant
/// would call.
#[inline(always)]
fn cw_closest(b: &CwBvh, ray: Ray, hit: &mut RayHit, mut f: impl FnMut(&Ray, usize) -> f32) -> bool {
    let mut r = ray;
    let mut state = b.new_traversal(ray.direction);
    let mut node;
    obvhs::traverse!(b, node, state, node.intersect_ray(&r, state.oct_inv4), {
        let t = f(&r, state.primitive_id as usize);
        if t < r.tmax {
            hit.primitive_id = state.primitive_id;
            hit.t = t;
            r.tmax = t;
        }
    });
    hit.t < ray.tmax
}

/// `CwBvh::ray_traverse_miss` the same way as [`cw_closest`]: true if nothing blocks `ray`.
#[inline(always)]
fn cw_miss(b: &CwBvh, ray: Ray, mut f: impl FnMut(&Ray, usize) -> f32) -> bool {
    let mut state = b.new_traversal(ray.direction);
    let mut node;
    let mut miss = true;
    'outer: {
        obvhs::traverse!(b, node, state, node.intersect_ray(&ray, state.oct_inv4), {
            if f(&ray, state.primitive_id as usize) < ray.tmax {
                miss = false;
                break 'outer;
            }
        });
    }
    miss
}

/// An empty occluder cache ([`Bvh::occluded_cached`]).
pub const NO_OCCLUDER: u32 = u32::MAX;

/// Relative tolerance on the barycentric edge tests: rays through a shared edge or vertex hit
/// both neighbours instead of slipping between them (obvhs's own test rejects `-0.0`).
const EDGE_TOLERANCE: f32 = 1e-6;

/// Möller–Trumbore with slightly inclusive edges; `t` in `[tmin, tmax]` or infinity.
#[inline(always)]
fn intersect(tri: &RtTriangle, ray: &Ray) -> f32 {
    let e1 = tri.v1 - tri.v0;
    let e2 = tri.v2 - tri.v0;
    let pv = ray.direction.cross(e2);
    let det = e1.dot(pv);
    if det == 0.0 || !det.is_finite() {
        return f32::INFINITY;
    }
    let inv = 1.0 / det;
    let tv = ray.origin - tri.v0;
    let u = tv.dot(pv) * inv;
    if !(-EDGE_TOLERANCE..=1.0 + EDGE_TOLERANCE).contains(&u) {
        return f32::INFINITY;
    }
    let qv = tv.cross(e1);
    let v = ray.direction.dot(qv) * inv;
    if v < -EDGE_TOLERANCE || u + v > 1.0 + EDGE_TOLERANCE {
        return f32::INFINITY;
    }
    let t = e2.dot(qv) * inv;
    if t >= ray.tmin && t <= ray.tmax {
        t
    } else {
        f32::INFINITY
    }
}

/// Barycentric `(b1, b2)` of point `p` (on the triangle's plane) in triangle `t`.
fn barycentric(t: &RtTriangle, p: Vec3) -> (f32, f32) {
    let (a, b, c) = (t.v0, t.v1, t.v2);
    let p = Vec3A::from(p);
    let (e1, e2, ep) = (b - a, c - a, p - a);
    let (d11, d12, d22) = (e1.dot(e1), e1.dot(e2), e2.dot(e2));
    let (dp1, dp2) = (ep.dot(e1), ep.dot(e2));
    let den = d11 * d22 - d12 * d12;
    if den.is_nan() || den == 0.0 {
        return (1.0 / 3.0, 1.0 / 3.0);
    }
    let b1 = (d22 * dp1 - d12 * dp2) / den;
    let b2 = (d11 * dp2 - d12 * dp1) / den;
    let b1 = b1.clamp(0.0, 1.0);
    let b2 = b2.clamp(0.0, 1.0 - b1);
    (b1, b2)
}

#[cfg(test)]
mod tests {
    use super::*;
    use prm_scene::{Material, Triangle};

    fn quad_scene() -> Scene {
        // Two unit squares: floor y=0 facing up and ceiling y=1 facing down.
        let tri = |p: [Vec3; 3]| Triangle::flat(p, 0);
        let (a, b, c, d) = (
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(1.0, 0.0, 0.0),
            Vec3::new(1.0, 0.0, 1.0),
            Vec3::new(0.0, 0.0, 1.0),
        );
        let up = Vec3::Y;
        Scene::from_parts(
            vec![
                tri([a, d, c]),
                tri([a, c, b]),
                tri([a + up, b + up, c + up]),
                tri([a + up, c + up, d + up]),
            ],
            vec![Material::diffuse("m", Vec3::splat(0.5))],
        )
    }

    /// The AVX2 variants of the queries give the portable ones' answers, bit for bit
    /// ([`crate::isa`]), on random rays through the bundled Cornell box, in both layouts.
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn instruction_set_variants_agree() {
        let Some(scene) = crate::isa::variant_test_scene() else {
            return;
        };
        for params in [BvhParams::DEFAULT, BvhParams::BVH2] {
            let bvh = Bvh::build(&scene, &params).unwrap();
            let b = scene.bounds();
            let mut rng = crate::Rng::new(7, 0, 0);
            let (mut hits, mut blocked) = (0, 0);
            // Each variant keeps its own occluder cache from ray to ray, as the pane kernel does.
            let (mut c1, mut c2) = (NO_OCCLUDER, NO_OCCLUDER);
            for i in 0..20_000u32 {
                let o = b.min + (b.max - b.min) * Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32());
                let d = (Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) - 0.5).normalize_or(Vec3::X);
                let tmax = rng.next_f32() * b.diagonal();
                let ignore = i % scene.triangles.len() as u32;
                let far = if i % 2 == 0 { f32::INFINITY } else { tmax };
                let portable = bvh.closest_hit_inline(o, d, far, ignore);
                // SAFETY: `isa::avx2` said the CPU runs the variant.
                let avx2 = unsafe { bvh.closest_hit_avx2(o, d, far, ignore) };
                assert_eq!(portable, avx2);
                hits += usize::from(portable.is_some());
                let ray = bvh.scaled_ray(o, d, 0.0, tmax);
                let portable = bvh.occluded_cached_inline(&ray, [ignore, u32::MAX], &mut c1);
                // SAFETY: as above.
                let avx2 = unsafe { bvh.occluded_cached_avx2(&ray, [ignore, u32::MAX], &mut c2) };
                assert_eq!((portable, c1), (avx2, c2));
                blocked += usize::from(portable);
            }
            assert!(
                hits > 5_000 && blocked > 1_000 && blocked < 19_000,
                "{hits} hits, {blocked} blocked"
            );
        }
    }

    #[test]
    fn closest_hit_and_occlusion_both_layouts() {
        let s = quad_scene();
        for params in [BvhParams::DEFAULT, BvhParams::BVH2] {
            let bvh = Bvh::build(&s, &params).unwrap();
            assert!(bvh.geometric_normal(0).dot(Vec3::Y) > 0.99);
            let h = bvh
                .closest_hit(Vec3::new(0.3, 0.5, 0.6), Vec3::Y, f32::INFINITY, u32::MAX)
                .unwrap();
            assert!((h.t - 0.5).abs() < 1e-6 && h.front && h.triangle >= 2);
            let p = s.triangles[h.triangle as usize].point(h.b1, h.b2);
            assert!((p - Vec3::new(0.3, 1.0, 0.6)).length() < 1e-5);
            let down = bvh.closest_hit(Vec3::new(0.3, 0.5, 0.6), -Vec3::Y, 0.4, u32::MAX);
            assert!(down.is_none(), "tmax respected");
            // From the floor straight up: no self hit, ceiling visible.
            let o = bvh.spawn(Vec3::new(0.5, 0.0, 0.5), Vec3::Y, Vec3::Y);
            let h = bvh.closest_hit(o, Vec3::Y, f32::INFINITY, 0).unwrap();
            assert!(h.triangle >= 2);
            assert!(bvh.visible(
                Vec3::new(0.2, 0.0, 0.7),
                Vec3::Y,
                0,
                Vec3::new(0.9, 1.0, 0.1),
                -Vec3::Y,
                2
            ));
            assert!(bvh.occluded(Vec3::new(0.5, -1.0, 0.5), Vec3::Y, 10.0, [u32::MAX; 2]));
            assert!(!bvh.occluded(Vec3::new(0.5, -1.0, 0.5), Vec3::Y, 0.9, [u32::MAX; 2]));
            // Straight down, `-Vec3::Y` is (-0, -1, -0): it meets the ceiling's back, then the floor.
            let h = bvh.closest_hit(Vec3::new(0.3, 1.5, 0.6), -Vec3::Y, f32::INFINITY, u32::MAX);
            assert!(h.is_some_and(|h| (h.t - 0.5).abs() < 1e-6 && !h.front), "{h:?}");
            assert!(bvh.occluded(Vec3::new(0.3, 0.5, 0.6), -Vec3::Y, 1.0, [u32::MAX; 2]));
            assert!(bvh.occluded(Vec3::new(0.3, 0.5, 0.6), Vec3::new(-0.0, 1.0, 0.0), 1.0, [u32::MAX; 2]));
            // Grazing shots along the floor do not hit it from a spawned origin.
            let o = bvh.spawn(Vec3::new(0.5, 0.0, 0.5), Vec3::Y, Vec3::X);
            assert!(bvh.closest_hit(o, Vec3::X, f32::INFINITY, u32::MAX).is_none());
        }
    }
}
