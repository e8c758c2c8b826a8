//! `prm-play`: a viewer of baked PRM archives over [`prm_runtime`].
//!
//! Per frame, without a CPU–GPU round trip, the run time makes the indirect-irradiance lightmap
//! (shadow maps, entry irradiance and cluster weights, rank, top-K selection with fade, blend of
//! the kept panes), and [`shade`] shades every pixel as albedo/π × (direct + indirect)
//! irradiance, in linear HDR. See [`Renderer`].
//!
//! [`export`] writes static lightmaps and the scene for engines that take only those.
//! [`open`] loads an archive and its scene (refusing an archive baked for other geometry),
//! [`window`] presents frames in a window (winit, orbit camera),
//! [`animation`] reads keyframed light and camera paths, [`output`] writes EXR and PNG images.

mod error;
mod gpu;
mod renderer;
pub mod shade;
pub mod sphere;

pub mod animation;
pub mod cpu;
pub mod export;
pub mod output;
pub mod present;

pub mod window;

pub use error::PlayError;
pub use gpu::{open_vulkan, open_vulkan_for, vulkan_instance};
pub use prm_runtime::{
    archive_top_k, synthetic, ClusterWeight, GiUpdate, NearLight, NearTail, ProbeLight, RuntimeOptions,
    MAX_NEAR_BOUNCES,
};
pub use renderer::{FrameInput, FrameTimings, Image, Mode, PlayOptions, Renderer, MAX_LIGHTS, PASS_NAMES};
pub use sphere::ProbeSphere;

use std::path::{Path, PathBuf};

use prm_format::Archive;
use prm_scene::{Camera, Light, Scene};

/// The archive type [`open`] returns.
pub type FileArchive = Archive<std::io::BufReader<std::fs::File>>;

/// The sky of `--sky SPEC` ([`prm_scene::Sky::parse`]) at `intensity` and turned by
/// `rotation_deg` about +Y; `None` without a spec. An archive without the sky's transfer
/// (`has_transfer` false) cannot take one: the error says how to bake it.
pub fn sky(
    spec: Option<&str>,
    intensity: f32,
    rotation_deg: f32,
    has_transfer: bool,
) -> Result<Option<prm_scene::Sky>, String> {
    let Some(spec) = spec else {
        return Ok(None);
    };
    if !has_transfer {
        return Err(format!(
            "--sky {spec}: the archive has no sky transfer; bake it with `prm-bake bake --sky`"
        ));
    }
    if !(intensity.is_finite() && intensity >= 0.0) {
        return Err(format!("--sky-intensity {intensity} must be finite and ≥ 0"));
    }
    if !rotation_deg.is_finite() {
        return Err(format!("--sky-rotation {rotation_deg} must be finite"));
    }
    let mut sky = prm_scene::Sky::parse(spec).map_err(|e| format!("--sky: {e}"))?;
    sky.intensity = intensity;
    sky.rotation = rotation_deg.to_radians();
    Ok(Some(sky))
}

/// A warning when `sky`'s order-2 projection rings: its irradiance on a surface facing some
/// direction goes below zero (a map with a small bright spot, a sun painted into it). The run
/// time clamps that light at zero; the warning says so and suggests the remedy. Sampled at 256
/// directions (a Fibonacci sphere); `None` when the smallest irradiance is not below −0.1% of
/// the largest.
pub fn sky_ringing(sky: &prm_scene::Sky) -> Option<String> {
    let sh = sky.sh();
    let n = 256;
    let (mut lo, mut hi) = (f32::INFINITY, 0.0f32);
    for i in 0..n {
        let y = 1.0 - 2.0 * (i as f32 + 0.5) / n as f32;
        let r = (1.0 - y * y).max(0.0).sqrt();
        let phi = i as f32 * std::f32::consts::PI * (3.0 - 5f32.sqrt());
        let basis = prm_format::sh_basis([r * phi.cos(), y, r * phi.sin()]);
        let e: [f32; 3] = std::array::from_fn(|k| {
            (0..prm_format::SH_COEFFS)
                .map(|c| prm_format::SH_COSINE_LOBE[c] * sh[c][k] * basis[c])
                .sum()
        });
        for v in e {
            lo = lo.min(v);
            hi = hi.max(v);
        }
    }
    (lo < -1e-3 * hi).then(|| {
        format!(
            "the sky's order-2 projection rings: facing away from its brightest part, its \
             irradiance would be {:.1}% of the largest, negative; the player clamps it at zero. A \
             sun painted into the map is better given as --light dir:... beside a sky without it",
            100.0 * lo / hi
        )
    })
}

/// The scales of `groups` (the archive's emitter groups, [`prm_runtime::Runtime::emitters`])
/// from `--emitter` specs ([`prm_scene::resolve_emitter_scales`]: `NAME=S` or `NAME=R,G,B`, `*`
/// for every group), applied in order. Groups no spec names keep scale 1.
pub fn emitter_scales(groups: &[prm_runtime::EmitterInfo], specs: &[String]) -> Result<Vec<[f32; 3]>, String> {
    let names: Vec<&str> = groups.iter().map(|g| g.name.as_str()).collect();
    prm_scene::resolve_emitter_scales(&names, specs)
}

/// Top K when neither `--top-k` nor the archive's `params.top_k` says otherwise.
pub const DEFAULT_TOP_K: u32 = prm_runtime::RuntimeOptions::DEFAULT_TOP_K;

/// Opens `archive` and loads its scene: `scene` if given, else the archive's `source_scene`
/// (relative to the archive's directory). Fails if the scene's fingerprint differs from the one
/// the archive was baked for.
pub fn open(archive: &Path, scene: Option<&Path>) -> Result<(FileArchive, Scene), PlayError> {
    let a = Archive::open(archive).map_err(|source| PlayError::Archive {
        path: archive.to_path_buf(),
        source,
    })?;
    let scene_path: PathBuf = match scene {
        Some(p) => p.to_path_buf(),
        None => {
            let rel = &a.metadata().source_scene;
            if rel.is_empty() {
                return Err(PlayError::NoSourceScene(archive.to_path_buf()));
            }
            // Relative to the directory the archive really is in: a bake through a symlink
            // writes the file where the link points and records the path from there.
            let real = std::fs::canonicalize(archive).unwrap_or_else(|_| archive.to_path_buf());
            real.parent().unwrap_or(Path::new(".")).join(rel)
        }
    };
    let s = prm_scene::load(&scene_path).map_err(|source| match source {
        prm_scene::SceneError::NotFound(_) if scene.is_none() => PlayError::SceneMoved {
            archive: archive.to_path_buf(),
            path: scene_path.clone(),
            source,
        },
        source => PlayError::Scene {
            path: scene_path.clone(),
            source,
        },
    })?;
    let expected = a.metadata().scene_fingerprint;
    let found = s.fingerprint();
    if expected != found || a.atlas().triangle_uvs.len() != s.triangles.len() {
        return Err(PlayError::FingerprintMismatch {
            archive: archive.to_path_buf(),
            scene: scene_path,
            expected,
            found,
        });
    }
    Ok((a, s))
}

/// A warning when `scene`'s materials differ from those `archive` was baked with (its
/// `params.materials_fingerprint`): the panes then hold another albedo's indirect light, which
/// plays but is no longer right. Geometry must match ([`open`] refuses otherwise); materials
/// only warn, so an artist can preview a colour change before re-baking. `None` when they match
/// or the archive records no materials fingerprint (bakes before it existed).
pub fn materials_warning<R: std::io::Read + std::io::Seek>(archive: &Archive<R>, scene: &Scene) -> Option<String> {
    let recorded = archive.metadata().params.get("materials_fingerprint")?.as_str()?;
    let found = format!("{:016x}", scene.materials_fingerprint());
    (recorded != found).then(|| {
        format!(
            "the scene's materials differ from those the archive was baked with (materials \
             fingerprint {found}, baked {recorded}): the indirect light is that of the old \
             albedos until you re-bake"
        )
    })
}

/// The light the player places in a scene that has none: a white point light on the vertical
/// axis of the bounds, a quarter of the height below the top, bright enough (intensity = the
/// squared half-diagonal, in W/sr) for about 1 W/m² at half the diagonal's distance.
///
/// A flat scene (a ground plane, a wall, a single triangle) has no inside to light: the light
/// stands half the half-diagonal off its plane, on the side its surfaces face.
pub fn default_light(scene: &Scene) -> Light {
    let b = scene.bounds();
    let centre = (b.min + b.max) * 0.5;
    let half = (b.diagonal() * 0.5).max(1e-3);
    let position = match flat_side(scene) {
        Some(n) => centre + n * (0.5 * half),
        None => glam::Vec3::new(centre.x, b.max.y - 0.25 * b.extent().y, centre.z),
    };
    Light::Point {
        position,
        intensity: glam::Vec3::splat(half * half),
    }
}

/// For a flat scene (its bounds thinner than a thousandth of their diagonal along an axis), the
/// unit axis on the side its surfaces face (area-weighted normals; +axis when they cancel).
fn flat_side(scene: &Scene) -> Option<glam::Vec3> {
    let b = scene.bounds();
    let e = b.extent();
    let axis = if e.x <= e.y && e.x <= e.z {
        glam::Vec3::X
    } else if e.y <= e.z {
        glam::Vec3::Y
    } else {
        glam::Vec3::Z
    };
    if e.dot(axis) > 1e-3 * b.diagonal() {
        return None;
    }
    let facing: f32 = scene.triangles.iter().map(|t| t.area() * t.normal().dot(axis)).sum();
    Some(if facing < 0.0 { -axis } else { axis })
}

/// `light` as a `--light` spec.
pub fn light_spec(light: &Light) -> String {
    let v = |v: glam::Vec3| format!("{},{},{}", v.x, v.y, v.z);
    match *light {
        Light::Point { position, intensity } => format!("point:{}:{}", v(position), v(intensity)),
        Light::Spot {
            position,
            direction,
            angle,
            intensity,
        } => format!(
            "spot:{}:{}:{}:{}",
            v(position),
            v(direction),
            angle.to_degrees(),
            v(intensity)
        ),
        Light::Rect {
            position,
            direction,
            up,
            half_angles,
            intensity,
        } => format!(
            "rect:{}:{}:{}:{},{}:{}",
            v(position),
            v(direction),
            v(up),
            half_angles[0].to_degrees(),
            half_angles[1].to_degrees(),
            v(intensity)
        ),
        Light::Directional { direction, irradiance } => format!("dir:{}:{}", v(direction), v(irradiance)),
    }
}

/// `light` in words, for messages.
pub fn describe_light(light: &Light) -> String {
    match *light {
        Light::Point { position, intensity } => format!(
            "a point light at ({:.3}, {:.3}, {:.3}) of {:.3} W/sr",
            position.x, position.y, position.z, intensity.x
        ),
        Light::Spot { position, .. } => format!(
            "a spot light at ({:.3}, {:.3}, {:.3})",
            position.x, position.y, position.z
        ),
        Light::Rect { position, .. } => format!(
            "a rectangular spot light at ({:.3}, {:.3}, {:.3})",
            position.x, position.y, position.z
        ),
        Light::Directional { direction, .. } => format!(
            "a directional light along ({:.3}, {:.3}, {:.3})",
            direction.x, direction.y, direction.z
        ),
    }
}

/// The scene's first camera, or a view of its bounds from +Z.
pub fn default_camera(scene: &Scene) -> Camera {
    if let Some(c) = scene.cameras.first() {
        return *c;
    }
    let b = scene.bounds();
    let centre = (b.min + b.max) * 0.5;
    let fov: f32 = 45.0;
    let radius = b.diagonal() * 0.5;
    let dist = radius / (fov.to_radians() * 0.5).tan() * 1.1;
    Camera {
        eye: centre + glam::Vec3::new(0.0, 0.0, dist + b.extent().z * 0.5),
        target: centre,
        fov_y_deg: fov,
    }
}

/// The scene's first camera, or a view of its bounds from the side it is open on: what
/// `prm-play` shows when neither the scene nor `--camera` gives one.
///
/// Each vertical side of the bounds (+Z, −Z, +X, −X, in that order of preference) is scored by
/// how much of it a wall covers: the area of the triangles lying within 2% of the extent from
/// that side's plane and facing along its axis, over the side's area. From outside the least
/// covered side, when less than half of it is covered, the camera sees in: a Cornell box from
/// its open front, any object or open scene from +Z as [`default_camera`] does (a fixed +Z view
/// sees the Cornell box OBJ from behind its back wall). A scene closed on every side (a room) is seen from
/// inside, just within its least covered side.
///
/// [`default_camera`] stays the fixed view from +Z that the eval's and the tests' measurements
/// were taken from.
pub fn viewer_camera(scene: &Scene) -> Camera {
    if let Some(c) = scene.cameras.first() {
        return *c;
    }
    let b = scene.bounds();
    let (centre, extent) = ((b.min + b.max) * 0.5, b.extent());
    // From outside: far enough that a 45° view holds the bounding sphere.
    let fov: f32 = 45.0;
    let dist = b.diagonal() * 0.5 / (fov.to_radians() * 0.5).tan() * 1.1;
    if let Some(n) = flat_side(scene) {
        // A flat scene is seen from the side its surfaces face, tilted a little (edge-on it
        // would cover no pixel).
        let tilt = if n.y.abs() > 0.5 { glam::Vec3::Z } else { glam::Vec3::Y };
        return Camera {
            eye: centre + (2.0 * n + tilt).normalize() * dist,
            target: centre,
            fov_y_deg: fov,
        };
    }
    let sides = [glam::Vec3::Z, glam::Vec3::NEG_Z, glam::Vec3::X, glam::Vec3::NEG_X];
    // A side's area: the product of the other two extents (zero for a flat scene's edges).
    let face = |a: glam::Vec3| {
        if a.x > 0.0 {
            extent.y * extent.z
        } else if a.y > 0.0 {
            extent.x * extent.z
        } else {
            extent.x * extent.y
        }
    };
    let covered = |axis: glam::Vec3| -> f32 {
        let a = axis.abs();
        let plane = centre.dot(a) + axis.dot(a) * extent.dot(a) * 0.5;
        let near = |p: glam::Vec3| (p.dot(a) - plane).abs() <= 0.02 * extent.dot(a);
        let area: f32 = scene
            .triangles
            .iter()
            .filter(|t| t.positions.iter().all(|&p| near(p)) && t.normal().dot(a).abs() > 0.9)
            .map(|t| t.area())
            .sum();
        area / face(a)
    };
    let (side, cover) = sides
        .iter()
        .filter(|s| face(s.abs()) > 0.0)
        .map(|&s| (s, covered(s)))
        .fold((glam::Vec3::Z, f32::INFINITY), |best, c| {
            if c.1 < best.1 - 1e-3 {
                c
            } else {
                best
            }
        });
    let depth = side.abs().dot(extent);
    if cover < 0.5 || depth <= 1e-6 * b.diagonal() {
        return Camera {
            eye: centre + side * (dist + depth * 0.5),
            target: centre,
            fov_y_deg: fov,
        };
    }
    Camera {
        eye: centre + side * (0.45 * depth),
        target: centre,
        fov_y_deg: 70.0,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The viewer's camera looks into a Cornell box through its open front (−Z), at an open
    /// scene from +Z, and at a closed room from inside.
    #[test]
    fn the_viewer_camera_sees_into_the_scene() {
        let load =
            |rel: &str| prm_scene::load(&Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes").join(rel)).unwrap();
        let mut cornell = load("cornell-box/cornell-box.obj");
        cornell.cameras.clear();
        let c = viewer_camera(&cornell);
        let b = cornell.bounds();
        assert!(c.eye.z < b.min.z, "outside the open front: {c:?}");
        // Closed: add the front wall.
        let corner = |x: f32, y: f32| glam::Vec3::new(x, y, b.min.z);
        let (lo, hi) = (b.min, b.max);
        cornell.triangles.push(prm_scene::Triangle::flat(
            [corner(lo.x, lo.y), corner(hi.x, lo.y), corner(hi.x, hi.y)],
            0,
        ));
        cornell.triangles.push(prm_scene::Triangle::flat(
            [corner(lo.x, lo.y), corner(hi.x, hi.y), corner(lo.x, hi.y)],
            0,
        ));
        let c = viewer_camera(&cornell);
        let b = cornell.bounds();
        assert!(
            c.eye.cmpgt(b.min).all() && c.eye.cmplt(b.max).all(),
            "inside a closed room: {c:?}"
        );
        // A single triangle in the XY plane (no walls): from +Z, as before.
        let mut one = cornell.clone();
        one.triangles = vec![prm_scene::Triangle::flat(
            [glam::Vec3::ZERO, glam::Vec3::X, glam::Vec3::Y],
            0,
        )];
        assert!(viewer_camera(&one).eye.z > 0.0);
    }

    /// A flat scene without lights or camera (a floor quad at y = 0, one triangle in z = 0, one
    /// facing -X) is seen from the side it faces, not edge-on, and the placed light stands off
    /// its plane on that side, so the first frame is lit and visible.
    #[test]
    fn a_flat_scene_is_seen_and_lit_from_the_side_it_faces() {
        let v = glam::Vec3::new;
        let load =
            |rel: &str| prm_scene::load(&Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes").join(rel)).unwrap();
        let mut base = load("cornell-box/cornell-box.obj");
        base.cameras.clear();
        base.lights.clear();
        let floor = [
            prm_scene::Triangle::flat([v(-1.0, 0.0, -1.0), v(-1.0, 0.0, 1.0), v(1.0, 0.0, 1.0)], 0),
            prm_scene::Triangle::flat([v(-1.0, 0.0, -1.0), v(1.0, 0.0, 1.0), v(1.0, 0.0, -1.0)], 0),
        ];
        let upright = [prm_scene::Triangle::flat(
            [v(0.0, 0.0, 0.0), v(1.0, 0.0, 0.0), v(0.0, 1.0, 0.0)],
            0,
        )];
        let facing_back = [prm_scene::Triangle::flat(
            [v(0.0, 0.0, 0.0), v(0.0, 0.0, 1.0), v(0.0, 1.0, 0.0)],
            0,
        )];
        for triangles in [&floor[..], &upright[..], &facing_back[..]] {
            let mut scene = base.clone();
            scene.triangles = triangles.to_vec();
            let n = triangles[0].normal();
            let centre = {
                let b = scene.bounds();
                (b.min + b.max) * 0.5
            };
            let c = viewer_camera(&scene);
            let forward = (c.target - c.eye).normalize();
            assert!(
                forward.dot(n) < -0.5,
                "not edge-on, from the front: {c:?} for normal {n}"
            );
            let Light::Point { position, .. } = default_light(&scene) else {
                panic!("a point light")
            };
            assert!(
                (position - centre).dot(n) > 0.1,
                "off the plane, in front: {position} for normal {n}"
            );
        }
    }

    /// A uniform sky does not ring; a map dark but for a small bright patch (a sun painted in)
    /// does, and is warned of (the run time clamps its negative light).
    #[test]
    fn a_sky_with_a_bright_spot_is_warned_of() {
        assert_eq!(sky_ringing(&prm_scene::Sky::uniform(glam::Vec3::ONE)), None);
        let spot = prm_scene::SkyMap::from_fn(64, 32, |d| {
            if d.dot(glam::Vec3::new(0.0, 0.5, 0.866)) > 0.99 {
                glam::Vec3::splat(50.0)
            } else {
                glam::Vec3::ZERO
            }
        });
        let w = sky_ringing(&prm_scene::Sky::from_map(spot)).expect("a warning");
        assert!(w.contains("rings") && w.contains("negative"), "{w}");
    }
}
