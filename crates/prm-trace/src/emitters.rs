//! Emissive surfaces as area lights: their groups, and the direct irradiance they give a point by
//! sampling them (next-event estimation), for the reference tracer.
//!
//! An emitter is a triangle whose material has a non-zero [`prm_scene::Material::emission`]
//! `L_e` (W/(m²·sr), Lambertian, from its front face only: surfaces are one-sided, as everywhere
//! in the tracer). Triangles are grouped by material, one [`EmitterGroup`] per emissive material,
//! listed by name; each group's radiance can be scaled ([`Emitters::with_scales`]).
//!
//! Direct irradiance at `x` (normal `n`) from the emitters,
//! `E(x) = Σ_e ∫_e L_e · cos θ_x · cos θ_y / r² · V(x, y) dA(y)`, is estimated two ways and the
//! two combined by multiple importance sampling (balance heuristic), which keeps it unbiased:
//! * **emitter sampling**: a triangle with probability proportional to its power (area × the sum
//!   of its RGB radiance), a point uniformly on it: `L_e cos θ_x cos θ_y V / (r² p)` with
//!   `p = P(triangle) / area`. Good far from the emitters; next to a large one (a point by the
//!   edge of an emitting wall) `1/r²` gives it a heavy tail: in the emissive furnace, 256
//!   samples per point left a mean error of 9.8% and 2.2% too much energy;
//! * **cosine sampling**: a direction with pdf `cos θ_x / π`, `π L_e` if it meets an emitter's
//!   front. Good where the emitter fills much of the hemisphere.
//!
//! The weights need the emitter-sampling pdf of a direction, in solid angle:
//! `P(triangle) r² / (area cos θ_y)`. In a path ([`crate::ReferenceTracer`]) the cosine sample
//! is the path's own next segment, so only the emitter sample costs a ray.

use glam::{Vec2, Vec3};
use prm_scene::{ExitPoint, Scene};

use crate::bvh::{Bvh, Hit};
use crate::rng::Rng;
use crate::TraceError;

/// The emissive triangles of one material.
#[derive(Clone, Debug, PartialEq)]
pub struct EmitterGroup {
    /// The material's name.
    pub name: String,
    /// Index into [`Scene::materials`].
    pub material: u32,
    /// Emissive triangles.
    pub triangles: u32,
    /// Their total area.
    pub area: f32,
    /// Radiance as scaled (W/(m²·sr), RGB).
    pub radiance: Vec3,
}

/// The emissive triangles of a scene, ready to be sampled.
#[derive(Clone, Debug, Default)]
pub struct Emitters {
    /// One group per emissive material, in material order.
    pub groups: Vec<EmitterGroup>,
    /// Scene triangle of every emitter.
    triangle: Vec<u32>,
    /// Its radiance (scaled).
    radiance: Vec<Vec3>,
    /// Cumulative power weights, ending at 1.
    cdf: Vec<f32>,
    /// Probability of each emitter.
    pick: Vec<f32>,
    /// Emitter index of every scene triangle ([`NOT_EMITTER`] for the others).
    of_triangle: Vec<u32>,
}

/// How an emitter sample is weighed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Strategy {
    /// Against cosine sampling (multiple importance sampling).
    Weighted,
    /// Alone: the whole estimate (the tests hold the weighted pair to it).
    #[cfg_attr(not(test), allow(dead_code))]
    Alone,
}

/// [`Emitters`]' index of a triangle that does not emit.
const NOT_EMITTER: u32 = u32::MAX;

/// Balance-heuristic weight of the strategy with pdf `a` against one with pdf `b`.
fn balance(a: f32, b: f32) -> f32 {
    if a + b > 0.0 {
        a / (a + b)
    } else {
        0.0
    }
}

impl Emitters {
    /// Every emissive material of `scene` as one group, at its own radiance.
    pub fn from_scene(scene: &Scene) -> Emitters {
        let scales: Vec<Vec3> = Self::group_materials(scene).iter().map(|_| Vec3::ONE).collect();
        Self::build(scene, &scales)
    }

    /// [`Emitters::from_scene`] with group `g`'s radiance multiplied by `scales[g]` (per
    /// channel); `scales` has one entry per group, in the order [`Emitters::from_scene`] lists
    /// them.
    pub fn with_scales(scene: &Scene, scales: &[Vec3]) -> Result<Emitters, TraceError> {
        let groups = Self::group_materials(scene).len();
        if scales.len() != groups {
            return Err(TraceError::InvalidParameter(format!(
                "{} emitter scales for {groups} emitter groups",
                scales.len()
            )));
        }
        if let Some(s) = scales.iter().find(|s| !s.is_finite() || s.min_element() < 0.0) {
            return Err(TraceError::InvalidParameter(format!(
                "emitter scale {s} is negative or not finite"
            )));
        }
        Ok(Self::build(scene, scales))
    }

    /// Group `g` alone at its own radiance, the other groups dark: what a bake stores per group
    /// at unit scale. `g` must be a group index.
    pub fn alone(scene: &Scene, g: usize) -> Emitters {
        let scales: Vec<Vec3> = (0..Self::group_materials(scene).len())
            .map(|k| if k == g { Vec3::ONE } else { Vec3::ZERO })
            .collect();
        Self::build(scene, &scales)
    }

    /// The emissive materials, in order.
    fn group_materials(scene: &Scene) -> Vec<u32> {
        (0..scene.materials.len() as u32)
            .filter(|&m| scene.materials[m as usize].emission.max_element() > 0.0)
            .collect()
    }

    fn build(scene: &Scene, scales: &[Vec3]) -> Emitters {
        let materials = Self::group_materials(scene);
        let mut groups: Vec<EmitterGroup> = materials
            .iter()
            .zip(scales)
            .map(|(&m, &s)| EmitterGroup {
                name: scene.materials[m as usize].name.clone(),
                material: m,
                triangles: 0,
                area: 0.0,
                radiance: scene.materials[m as usize].emission * s,
            })
            .collect();
        let (mut triangle, mut radiance, mut weight) = (Vec::new(), Vec::new(), Vec::new());
        let mut of_triangle = vec![NOT_EMITTER; scene.triangles.len()];
        for (i, t) in scene.triangles.iter().enumerate() {
            let Some(g) = materials.iter().position(|&m| m == t.material) else {
                continue;
            };
            let area = t.area();
            groups[g].triangles += 1;
            groups[g].area += area;
            let l = groups[g].radiance;
            if area > 0.0 && l.max_element() > 0.0 {
                of_triangle[i] = triangle.len() as u32;
                triangle.push(i as u32);
                radiance.push(l);
                weight.push(area as f64 * l.element_sum() as f64);
            }
        }
        let total: f64 = weight.iter().sum();
        let mut acc = 0.0f64;
        let cdf = weight
            .iter()
            .map(|w| {
                acc += w;
                (acc / total) as f32
            })
            .collect();
        let pick = weight.iter().map(|w| (w / total) as f32).collect();
        Emitters {
            groups,
            triangle,
            radiance,
            cdf,
            pick,
            of_triangle,
        }
    }

    /// Whether nothing emits (no emissive triangle, or every scale zero).
    pub fn is_empty(&self) -> bool {
        self.triangle.is_empty()
    }

    /// The emitter-sampling pdf (solid angle) of the direction from a point to `y` on scene
    /// triangle `e`, `r²` away, seen there at cosine `cos_e`: zero if `e` does not emit.
    pub fn pdf(&self, scene: &Scene, e: u32, r2: f32, cos_e: f32) -> f32 {
        let k = self.of_triangle.get(e as usize).copied().unwrap_or(NOT_EMITTER);
        if k == NOT_EMITTER || cos_e <= 0.0 {
            return 0.0;
        }
        self.pick[k as usize] * r2 / (scene.triangles[e as usize].area() * cos_e)
    }

    /// Radiance the front of scene triangle `e` emits (zero for non-emitters).
    pub fn emission(&self, e: u32) -> Vec3 {
        match self.of_triangle.get(e as usize).copied().unwrap_or(NOT_EMITTER) {
            NOT_EMITTER => Vec3::ZERO,
            k => self.radiance[k as usize],
        }
    }

    /// The emitter-sampling half of the estimate at receiver `r`, with a shadow ray, weighed against cosine sampling: the
    /// caller adds the other half ([`Emitters::cosine_hit`] of its cosine sample).
    pub fn sample_weighted(&self, scene: &Scene, bvh: &Bvh, r: &Receiver, rng: &mut Rng) -> Vec3 {
        self.sample(scene, bvh, r, rng, Strategy::Weighted)
    }

    /// The cosine half of the estimate: what the cosine-sampled direction `dir` (receiving
    /// cosine `cos_x`) that met `hit` adds, `π L_e` weighed against emitter sampling, zero
    /// unless it met an emitter's front.
    pub fn cosine_hit(&self, scene: &Scene, bvh: &Bvh, hit: &Hit, dir: Vec3, cos_x: f32) -> Vec3 {
        let le = self.emission(hit.triangle);
        if !hit.front || le.max_element() <= 0.0 {
            return Vec3::ZERO;
        }
        let ce = -bvh.geometric_normal(hit.triangle).dot(dir);
        let w = balance(
            cos_x * std::f32::consts::FRAC_1_PI,
            self.pdf(scene, hit.triangle, hit.t * hit.t, ce),
        );
        le * (std::f32::consts::PI * w)
    }

    /// One emitter sample at receiver `r`, weighed by `strategy`.
    fn sample(&self, scene: &Scene, bvh: &Bvh, r: &Receiver, rng: &mut Rng, strategy: Strategy) -> Vec3 {
        if self.is_empty() {
            return Vec3::ZERO;
        }
        let (p, ng, n, tri) = (r.position, r.ng, r.n, r.triangle);
        let u = rng.next_f32();
        let k = self.cdf.partition_point(|&c| c <= u).min(self.cdf.len() - 1);
        let e = self.triangle[k];
        let t = &scene.triangles[e as usize];
        let Vec2 { x: mut b1, y: mut b2 } = rng.next_vec2();
        if b1 + b2 > 1.0 {
            (b1, b2) = (1.0 - b1, 1.0 - b2);
        }
        let y = t.point(b1, b2);
        let ne = bvh.geometric_normal(e);
        let d = y - p;
        let r2 = d.length_squared();
        if r2 <= 0.0 || e == tri {
            return Vec3::ZERO;
        }
        let w = d / r2.sqrt();
        let (cx, ce) = (n.dot(w), -ne.dot(w));
        if cx <= 0.0 || ng.dot(w) <= 0.0 || ce <= 0.0 {
            return Vec3::ZERO;
        }
        if !bvh.visible(p, ng, tri, y, ne, e) {
            return Vec3::ZERO;
        }
        let weight = match strategy {
            Strategy::Weighted => balance(self.pick[k] * r2 / (t.area() * ce), cx * std::f32::consts::FRAC_1_PI),
            Strategy::Alone => 1.0,
        };
        self.radiance[k] * (weight * cx * ce * t.area() / (r2 * self.pick[k]))
    }

    /// One two-strategy estimate (module docs) of the direct irradiance at receiver `r`: an
    /// emitter sample and a cosine sample (a closest-hit ray), weighed.
    pub fn sample_both(&self, scene: &Scene, bvh: &Bvh, r: &Receiver, rng: &mut Rng) -> Vec3 {
        if self.is_empty() {
            return Vec3::ZERO;
        }
        let (p, ng, n, tri) = (r.position, r.ng, r.n, r.triangle);
        let mut e = self.sample_weighted(scene, bvh, r, rng);
        let dir = crate::sampling::cosine_hemisphere(rng.next_vec2(), n);
        if dir.dot(ng) > 0.0 {
            if let Some(hit) = bvh.closest_hit(bvh.spawn(p, ng, dir), dir, f32::INFINITY, tri) {
                e += self.cosine_hit(scene, bvh, &hit, dir, n.dot(dir));
            }
        }
        e
    }

    /// Mean of `samples` two-strategy estimates ([`Emitters::sample_both`]) at `p` on triangle
    /// `tri` (geometric normal `ng`, receiving normal `n`): [`Emitters::irradiance_at`] by parts.
    #[allow(clippy::too_many_arguments)]
    pub fn irradiance(
        &self,
        scene: &Scene,
        bvh: &Bvh,
        p: Vec3,
        ng: Vec3,
        n: Vec3,
        tri: u32,
        samples: u32,
        rng: &mut Rng,
    ) -> Vec3 {
        let r = Receiver {
            position: p,
            ng,
            n,
            triangle: tri,
        };
        self.irradiance_at(scene, bvh, &r, samples, rng)
    }

    /// Mean of `samples` two-strategy estimates ([`Emitters::sample_both`]) at receiver `r`.
    pub fn irradiance_at(&self, scene: &Scene, bvh: &Bvh, r: &Receiver, samples: u32, rng: &mut Rng) -> Vec3 {
        if self.is_empty() || samples == 0 {
            return Vec3::ZERO;
        }
        let s: Vec3 = (0..samples).map(|_| self.sample_both(scene, bvh, r, rng)).sum();
        s / samples as f32
    }

    /// Each group's direct irradiance at each receiver at unit scale, what a bake stores for
    /// the run time to scale: `out[g][i]` for group `g` (in [`Emitters::groups`] order) and
    /// receiver `i`, the mean of `samples` two-strategy estimates ([`Emitters::irradiance`])
    /// with only that group emitting. Each receiver and group has its own random stream (from
    /// `seed`), so the result does not depend on the thread count.
    pub fn group_irradiance(
        &self,
        scene: &Scene,
        bvh: &Bvh,
        receivers: &[Receiver],
        samples: u32,
        seed: u64,
    ) -> Vec<Vec<Vec3>> {
        use rayon::prelude::*;
        (0..self.groups.len())
            .map(|g| {
                let alone = Self::alone(scene, g);
                receivers
                    .par_iter()
                    .enumerate()
                    .map(|(i, r)| {
                        let mut rng = Rng::new(seed, i as u64, g as u64);
                        alone.irradiance_at(scene, bvh, r, samples, &mut rng)
                    })
                    .collect()
            })
            .collect()
    }

    /// The direct irradiance all groups, each at unit scale, give points of empty space, each
    /// `(position, unit normal)` a surface element on no triangle (a probe's): the sum over
    /// groups of [`Emitters::group_irradiance`].
    pub fn direct_at_points(
        &self,
        scene: &Scene,
        bvh: &Bvh,
        points: &[(Vec3, Vec3)],
        samples: u32,
        seed: u64,
    ) -> Vec<Vec3> {
        let receivers: Vec<Receiver> = points
            .iter()
            .map(|&(position, n)| Receiver {
                position,
                ng: n,
                n,
                triangle: u32::MAX,
            })
            .collect();
        let per_group = self.group_irradiance(scene, bvh, &receivers, samples, seed);
        (0..points.len())
            .map(|i| per_group.iter().map(|g| g[i]).sum())
            .collect()
    }
}

/// A surface point that receives light ([`Emitters::group_irradiance`]), or a point of empty
/// space with `triangle` `u32::MAX`.
#[derive(Clone, Copy, Debug)]
pub struct Receiver {
    /// World position.
    pub position: Vec3,
    /// Unit geometric normal of its triangle (its front).
    pub ng: Vec3,
    /// Unit shading normal the irradiance is measured with.
    pub n: Vec3,
    /// Its triangle (skipped by its own rays).
    pub triangle: u32,
}

impl Receiver {
    /// Exit point `x`, receiving with its shading normal.
    pub fn at_exit(bvh: &Bvh, x: &ExitPoint) -> Receiver {
        Receiver {
            position: x.position,
            ng: bvh.geometric_normal(x.triangle),
            n: x.normal,
            triangle: x.triangle,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::BvhParams;
    use prm_scene::{Material, Triangle};

    /// A receiving floor at y = 0 (20 × 20) and an emitting `a × b` rectangle at height `c`
    /// centred above the origin, facing down.
    fn lamp_over_floor(a: f32, b: f32, c: f32, le: Vec3) -> Scene {
        let quad = |p: [Vec3; 4], m: u32| {
            [
                Triangle::flat([p[0], p[1], p[2]], m),
                Triangle::flat([p[0], p[2], p[3]], m),
            ]
        };
        let f = 10.0;
        let floor = quad(
            [
                Vec3::new(-f, 0.0, -f),
                Vec3::new(-f, 0.0, f),
                Vec3::new(f, 0.0, f),
                Vec3::new(f, 0.0, -f),
            ],
            0,
        );
        let (x, z) = (a / 2.0, b / 2.0);
        let lamp = quad(
            [
                Vec3::new(-x, c, -z),
                Vec3::new(x, c, -z),
                Vec3::new(x, c, z),
                Vec3::new(-x, c, z),
            ],
            1,
        );
        let lamp_material = Material {
            emission: le,
            ..Material::diffuse("lamp", Vec3::splat(0.5))
        };
        Scene::from_parts(
            floor.into_iter().chain(lamp).collect(),
            vec![Material::diffuse("floor", Vec3::splat(0.5)), lamp_material],
        )
    }

    /// Form factor from a point to a parallel `x × y` rectangle `c` above it, the point under
    /// one of its corners.
    fn corner_form_factor(x: f32, y: f32, c: f32) -> f32 {
        let (a, b) = ((x / c) as f64, (y / c) as f64);
        let (sa, sb) = ((1.0 + a * a).sqrt(), (1.0 + b * b).sqrt());
        ((a / sa * (b / sa).atan() + b / sb * (a / sb).atan()) / (2.0 * std::f64::consts::PI)) as f32
    }

    #[test]
    fn a_rectangular_lamp_gives_its_form_factor() {
        let le = Vec3::new(3.0, 2.0, 1.0);
        let (a, b, c) = (0.6f32, 0.3f32, 0.4f32);
        let scene = lamp_over_floor(a, b, c, le);
        let bvh = Bvh::build(&scene, &BvhParams::DEFAULT).unwrap();
        let e = Emitters::from_scene(&scene);
        assert_eq!(e.groups.len(), 1);
        assert_eq!(e.groups[0].name, "lamp");
        assert!((e.groups[0].area - a * b).abs() < 1e-6);
        let mut rng = Rng::new(1, 2, 3);
        // Under the centre (four corner rectangles) and under a corner (one rectangle a × b).
        for (p, exact) in [
            (Vec3::ZERO, 4.0 * corner_form_factor(a / 2.0, b / 2.0, c)),
            (Vec3::new(a / 2.0, 0.0, b / 2.0), corner_form_factor(a, b, c)),
        ] {
            let exact = le * std::f32::consts::PI * exact;
            let r = Receiver {
                position: p,
                ng: Vec3::Y,
                n: Vec3::Y,
                triangle: 0,
            };
            let both = e.irradiance_at(&scene, &bvh, &r, 1 << 16, &mut rng);
            let alone: Vec3 = (0..1 << 16)
                .map(|_| e.sample(&scene, &bvh, &r, &mut rng, Strategy::Alone))
                .sum::<Vec3>()
                / (1 << 16) as f32;
            for (name, v) in [("both strategies", both), ("emitter sampling", alone)] {
                let err = ((v - exact) / exact).abs().max_element();
                assert!(err < 0.01, "{name} at {p}: {v} against {exact}");
            }
        }
        // Scaled, and refused when the scales do not fit.
        let scaled = Emitters::with_scales(&scene, &[Vec3::new(2.0, 0.0, 1.0)]).unwrap();
        assert_eq!(scaled.groups[0].radiance, Vec3::new(6.0, 0.0, 1.0));
        assert!(Emitters::with_scales(&scene, &[]).is_err());
        assert!(Emitters::with_scales(&scene, &[Vec3::splat(-1.0)]).is_err());
        assert!(Emitters::with_scales(&scene, &[Vec3::ZERO]).unwrap().is_empty());
    }
}
