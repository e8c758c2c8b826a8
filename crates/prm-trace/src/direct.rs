//! Direct irradiance from punctual lights, with shadow rays.
//!
//! Point: `E = I · cos θ / d² · V` (I in W/sr). Spot: the same inside the cone
//! (angle between the light's axis and the direction to the point ≤ half angle), zero outside: a
//! hard-edged cone with no falloff. Rectangular spot: the same inside its frustum
//! ([`Light::emits_towards`]). Directional: `E = E⊥ · cos θ · V` with `E⊥` the irradiance on a
//! surface facing the light, shadow ray to infinity.

use glam::Vec3;
use prm_scene::Light;
use prm_scene::ENTRY_DISK;
use rayon::prelude::*;

use crate::bvh::Bvh;
use crate::sampling::SurfaceSample;

/// Direct irradiance (W/m²) at `p` on triangle `tri` with unit geometric normal `ng`, using `n`
/// (unit) as the receiving normal.
pub fn direct_irradiance(bvh: &Bvh, lights: &[Light], p: Vec3, ng: Vec3, n: Vec3, tri: u32) -> Vec3 {
    bounded_irradiance(bvh, lights, p, ng, n, tri, 0.0)
}

/// [`direct_irradiance`] at a point standing for a disk of radius² `disk`: the inverse square of
/// point and spot lights becomes `1 / (d² + disk)` (0: the plain point value).
///
/// A light counts only if it is above both the shading normal `n` and the geometric normal `ng`:
/// below the geometric plane it lies behind the surface itself. The GPU twin is
/// `light_irradiance_ng` in `shaders/runtime/lights.wgsl` (tested function against function
/// in `tests/estimators.rs`, the shadows left out).
pub fn bounded_irradiance(bvh: &Bvh, lights: &[Light], p: Vec3, ng: Vec3, n: Vec3, tri: u32, disk: f32) -> Vec3 {
    let mut e = Vec3::ZERO;
    for light in lights {
        let (to_light, dist, radiometric) = match *light {
            Light::Point { position, intensity }
            | Light::Spot {
                position, intensity, ..
            }
            | Light::Rect {
                position, intensity, ..
            } => {
                let d = position - p;
                let r = d.length();
                let l = d / r;
                if !light.emits_towards(-l) {
                    continue;
                }
                (l, r, intensity / (r * r + disk))
            }
            Light::Directional { direction, irradiance } => (-direction, f32::INFINITY, irradiance),
        };
        if !to_light.is_finite() {
            continue;
        }
        let cos = n.dot(to_light);
        if cos <= 0.0 || ng.dot(to_light) <= 0.0 {
            continue;
        }
        let o = bvh.spawn(p, ng, to_light);
        let tmax = if dist.is_finite() {
            (dist - bvh.epsilon()).max(0.0)
        } else {
            f32::INFINITY
        };
        if !bvh.occluded(o, to_light, tmax, [tri, u32::MAX]) {
            e += radiometric * cos;
        }
    }
    e
}

/// Direct irradiance at every entry point (the run-time weights before cluster averaging),
/// bounded like a VPL: an entry point stands for a small disk, so a point or spot light at
/// distance `r` gives `I cos θ / (r² + ENTRY_DISK · A/(Nπ))` instead of `I cos θ / r²`.
///
/// Without the bound, a light closer to a surface than the entry points' spacing puts an
/// irradiance peak between them that a cluster's mean catches at full height or misses: with a
/// light 1% of the scene's size from the Cornell box's back wall, the indirect light was off by
/// 102% (relative RMSE; the reference's own noise 28%). The bound trades that variance for a
/// bias near lights: the disk of the whole area (`ENTRY_DISK` = 1) gave 47% there but raised
/// the error with a light 5 cm from a wall from 24% to 27%; a quarter of it gives 45% and 25%.
/// The run time computes the same bound on the GPU (prm-runtime's `weights.wgsl`) for archives
/// without entry cells; with them it takes each cell's light ([`crate::cell_irradiance`]).
pub fn entry_irradiance(bvh: &Bvh, lights: &[Light], entries: &[SurfaceSample]) -> Vec<Vec3> {
    entries
        .par_iter()
        .map(|e| {
            let disk = ENTRY_DISK * e.weight / std::f32::consts::PI;
            bounded_irradiance(bvh, lights, e.position, e.normal, e.normal, e.triangle, disk)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::BvhParams;
    use prm_scene::{Material, Scene, Triangle};

    /// A floor 20 × 20 at y = 0, facing up.
    fn floor() -> Scene {
        let (a, b, c, d) = (
            Vec3::new(-10.0, 0.0, -10.0),
            Vec3::new(10.0, 0.0, -10.0),
            Vec3::new(10.0, 0.0, 10.0),
            Vec3::new(-10.0, 0.0, 10.0),
        );
        Scene::from_parts(
            vec![Triangle::flat([a, d, c], 0), Triangle::flat([a, c, b], 0)],
            vec![Material::diffuse("m", Vec3::splat(0.5))],
        )
    }

    #[test]
    fn a_rectangular_spot_lights_its_footprint_only() {
        let scene = floor();
        let bvh = Bvh::build(&scene, &BvhParams::DEFAULT).unwrap();
        // A projector 2 above the floor looking down with up = −Z, so its horizontal is
        // (−Y) × (−Z) = +X: 30° half angle along x, 10° along z.
        let light = Light::Rect {
            position: Vec3::new(0.0, 2.0, 0.0),
            direction: Vec3::NEG_Y,
            up: Vec3::NEG_Z,
            half_angles: [30f32.to_radians(), 10f32.to_radians()],
            intensity: Vec3::new(4.0, 2.0, 1.0),
        };
        let e = |x: f32, z: f32| direct_irradiance(&bvh, &[light], Vec3::new(x, 0.0, z), Vec3::Y, Vec3::Y, u32::MAX);
        let (hx, hz) = (2.0 * 30f32.to_radians().tan(), 2.0 * 10f32.to_radians().tan());
        // Inside: E = I cos θ / d² with cos θ = 2 / d.
        for (x, z) in [(0.0, 0.0), (0.95 * hx, 0.0), (0.0, -0.95 * hz), (-0.95 * hx, 0.95 * hz)] {
            let d2 = x * x + z * z + 4.0;
            let expected = Vec3::new(4.0, 2.0, 1.0) * (2.0 / d2.sqrt()) / d2;
            assert!(
                (e(x, z) - expected).abs().max_element() < 1e-5,
                "({x}, {z}): {} vs {expected}",
                e(x, z)
            );
        }
        // Outside each side, a corner, and where the swapped angles would light it.
        for (x, z) in [
            (1.05 * hx, 0.0),
            (0.0, 1.05 * hz),
            (-1.05 * hx, -1.05 * hz),
            (0.0, 0.8 * hx),
        ] {
            assert_eq!(e(x, z), Vec3::ZERO, "({x}, {z})");
        }
        // The reference tracer's next-event estimation goes through the same function: a light
        // facing away lights nothing.
        let away = Light::Rect {
            position: Vec3::new(0.0, 2.0, 0.0),
            direction: Vec3::Y,
            up: Vec3::Z,
            half_angles: [30f32.to_radians(), 10f32.to_radians()],
            intensity: Vec3::ONE,
        };
        assert_eq!(
            direct_irradiance(&bvh, &[away], Vec3::ZERO, Vec3::Y, Vec3::Y, u32::MAX),
            Vec3::ZERO
        );
    }
}
