//! Scenes with known answers, built in code: the closed box of the white-furnace test.

use glam::{Vec2, Vec3};
use std::path::PathBuf;

use crate::scene::{LoadReport, Material, Scene, Triangle};

/// The unit cube `[0, 1]³` seen from inside: six inward-facing faces, each split into
/// `subdivisions²` quads of two triangles, one grey material of the given albedo.
///
/// With direct irradiance `E0` everywhere its indirect irradiance is `ρ·E0/(1−ρ)` at every point
/// (the white furnace).
pub fn furnace_box(subdivisions: u32, albedo: f32) -> Scene {
    let s = subdivisions.max(1);
    let mut triangles = Vec::new();
    // (origin, u axis, v axis) with u × v pointing into the box.
    let faces = [
        (Vec3::ZERO, Vec3::Z, Vec3::X), // floor y=0, normal +Y
        (Vec3::Y, Vec3::X, Vec3::Z),    // ceiling y=1, normal -Y
        (Vec3::ZERO, Vec3::X, Vec3::Y), // z=0, normal +Z
        (Vec3::Z, Vec3::Y, Vec3::X),    // z=1, normal -Z
        (Vec3::ZERO, Vec3::Y, Vec3::Z), // x=0, normal +X
        (Vec3::X, Vec3::Z, Vec3::Y),    // x=1, normal -X
    ];
    for (o, u, v) in faces {
        let n = u.cross(v);
        for i in 0..s {
            for j in 0..s {
                let p = |a: u32, b: u32| o + u * (a as f32 / s as f32) + v * (b as f32 / s as f32);
                let (a, b, c, d) = (p(i, j), p(i + 1, j), p(i + 1, j + 1), p(i, j + 1));
                for positions in [[a, b, c], [a, c, d]] {
                    triangles.push(Triangle {
                        positions,
                        normals: [n; 3],
                        uvs: [Vec2::ZERO; 3],
                        material: 0,
                    });
                }
            }
        }
    }
    Scene {
        source: PathBuf::from("furnace"),
        triangles,
        lightmap_uvs: None,
        materials: vec![Material {
            name: "grey".into(),
            albedo: Vec3::splat(albedo),
            texture: None,
            emission: Vec3::ZERO,
        }],
        textures: vec![],
        lights: vec![],
        cameras: vec![],
        report: LoadReport::default(),
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn furnace_box_is_closed_and_faces_inward() {
        let b = super::furnace_box(3, 0.5);
        assert_eq!(b.triangles.len(), 6 * 9 * 2);
        assert!((b.area() - 6.0).abs() < 1e-5);
        let centre = glam::Vec3::splat(0.5);
        assert!(b
            .triangles
            .iter()
            .all(|t| t.normal().dot(centre - t.positions[0]) > 0.0));
    }
}
