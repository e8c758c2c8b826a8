//! Direct irradiance from punctual lights, with shadow rays.
//!
//! Point: `E = I · cos θ / d² · V` (I in W/sr). Spot: the same inside the cone
//! (angle between the light's axis and the direction to the point ≤ half angle), zero outside: a
//! hard-edged cone with no falloff. Directional: `E = E⊥ · cos θ · V` with `E⊥` the irradiance on a
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
            Light::Point { position, intensity } => {
                let d = position - p;
                let r = d.length();
                (d / r, r, intensity / (r * r + disk))
            }
            Light::Spot {
                position,
                direction,
                angle,
                intensity,
            } => {
                let d = position - p;
                let r = d.length();
                let l = d / r;
                if (-l).dot(direction) < angle.cos() {
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
/// The run time computes the same bound on the GPU (prm-runtime's `weights.wgsl`).
pub fn entry_irradiance(bvh: &Bvh, lights: &[Light], entries: &[SurfaceSample]) -> Vec<Vec3> {
    entries
        .par_iter()
        .map(|e| {
            let disk = ENTRY_DISK * e.weight / std::f32::consts::PI;
            bounded_irradiance(bvh, lights, e.position, e.normal, e.normal, e.triangle, disk)
        })
        .collect()
}
