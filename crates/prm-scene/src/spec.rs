//! Text specs for lights, cameras and image sizes, shared with the `prm-bake` CLI.
//!
//! * `point:X,Y,Z:R,G,B` — point light, intensity in W/sr per channel;
//! * `spot:X,Y,Z:DX,DY,DZ:ANGLE_DEG:R,G,B` — spot light along `D` with cone half angle in
//!   degrees (0, 180), intensity W/sr inside the cone;
//! * `rect:X,Y,Z:DX,DY,DZ:UX,UY,UZ:HALF_X_DEG,HALF_Y_DEG:R,G,B` — rectangular spot light (a
//!   projector) along `D`, `U` its vertical (made perpendicular to `D`; not parallel to it),
//!   half angles in degrees (0, 85) about `D × U` and about `U`, intensity W/sr inside the
//!   frustum;
//! * `dir:DX,DY,DZ:R,G,B` — directional light travelling along `D`, irradiance in W/m² on a
//!   surface facing the light;
//! * camera `EX,EY,EZ:TX,TY,TZ:FOV_DEG` — eye, target, vertical field of view in degrees
//!   (right-handed, +Y up, pinhole);
//! * size `WxH`.

use crate::{Camera, Light};
use glam::Vec3;

use thiserror::Error;

/// A light, camera or image-size spec that could not be parsed.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum SpecError {
    /// The light kind before the first `:` is not `point`, `spot`, `rect` or `dir`.
    #[error("unknown light kind {kind:?} in {spec:?} (expected point, spot, rect or dir)")]
    UnknownLightKind {
        /// The whole spec.
        spec: String,
        /// The kind found.
        kind: String,
    },
    /// Wrong number of `:`-separated fields.
    #[error("{what} spec {spec:?} has {found} ':'-separated fields, expected {expected} ({format})")]
    FieldCount {
        /// What was being parsed.
        what: &'static str,
        /// The whole spec.
        spec: String,
        /// Fields found.
        found: usize,
        /// Fields expected.
        expected: usize,
        /// The expected format.
        format: &'static str,
    },
    /// A field is not a number or not a vector of the right length.
    #[error("bad {field} {value:?} in {spec:?}: {reason}")]
    BadField {
        /// The whole spec.
        spec: String,
        /// Which field.
        field: &'static str,
        /// Its text.
        value: String,
        /// What is wrong with it.
        reason: String,
    },
}

const POINT: &str = "point:X,Y,Z:R,G,B";
const SPOT: &str = "spot:X,Y,Z:DX,DY,DZ:ANGLE_DEG:R,G,B";
const RECT: &str = "rect:X,Y,Z:DX,DY,DZ:UX,UY,UZ:HALF_X_DEG,HALF_Y_DEG:R,G,B";
const DIR: &str = "dir:DX,DY,DZ:R,G,B";
const CAMERA: &str = "EX,EY,EZ:TX,TY,TZ:FOV_DEG";

fn bad(spec: &str, field: &'static str, value: &str, reason: impl Into<String>) -> SpecError {
    SpecError::BadField {
        spec: spec.into(),
        field,
        value: value.into(),
        reason: reason.into(),
    }
}

fn number(spec: &str, field: &'static str, s: &str) -> Result<f32, SpecError> {
    let v: f32 = s.trim().parse().map_err(|_| bad(spec, field, s, "not a number"))?;
    if v.is_finite() {
        Ok(v)
    } else {
        Err(bad(spec, field, s, "not finite"))
    }
}

fn vec3(spec: &str, field: &'static str, s: &str) -> Result<Vec3, SpecError> {
    let parts: Vec<&str> = s.split(',').collect();
    if parts.len() != 3 {
        return Err(bad(
            spec,
            field,
            s,
            format!("expected 3 comma-separated numbers, found {}", parts.len()),
        ));
    }
    Ok(Vec3::new(
        number(spec, field, parts[0])?,
        number(spec, field, parts[1])?,
        number(spec, field, parts[2])?,
    ))
}

fn direction(spec: &str, field: &'static str, s: &str) -> Result<Vec3, SpecError> {
    let d = vec3(spec, field, s)?;
    let n = d.normalize_or_zero();
    if n == Vec3::ZERO {
        return Err(bad(spec, field, s, "zero-length direction"));
    }
    Ok(n)
}

fn colour(spec: &str, field: &'static str, s: &str) -> Result<Vec3, SpecError> {
    let c = vec3(spec, field, s)?;
    if c.min_element() < 0.0 {
        return Err(bad(spec, field, s, "negative channel"));
    }
    Ok(c)
}

fn fields<'a>(
    spec: &'a str,
    what: &'static str,
    expected: usize,
    format: &'static str,
) -> Result<Vec<&'a str>, SpecError> {
    let f: Vec<&str> = spec.split(':').collect();
    if f.len() != expected {
        return Err(SpecError::FieldCount {
            what,
            spec: spec.into(),
            found: f.len(),
            expected,
            format,
        });
    }
    Ok(f)
}

/// Parses a light spec (see the module docs).
pub fn parse_light(spec: &str) -> Result<Light, SpecError> {
    let kind = spec.split(':').next().unwrap_or("").trim();
    match kind {
        "point" => {
            let f = fields(spec, "point light", 3, POINT)?;
            Ok(Light::Point {
                position: vec3(spec, "position", f[1])?,
                intensity: colour(spec, "intensity", f[2])?,
            })
        }
        "spot" => {
            let f = fields(spec, "spot light", 5, SPOT)?;
            let angle = number(spec, "cone half angle", f[3])?;
            if !(angle > 0.0 && angle < 180.0) {
                return Err(bad(spec, "cone half angle", f[3], "must be in (0, 180) degrees"));
            }
            Ok(Light::Spot {
                position: vec3(spec, "position", f[1])?,
                direction: direction(spec, "direction", f[2])?,
                angle: angle.to_radians(),
                intensity: colour(spec, "intensity", f[4])?,
            })
        }
        "rect" => {
            let f = fields(spec, "rectangular spot light", 6, RECT)?;
            let d = direction(spec, "direction", f[2])?;
            let u = vec3(spec, "up", f[3])?;
            let up = (u - u.dot(d) * d).normalize_or_zero();
            if u.length() == 0.0 || up.length() == 0.0 || up.cross(d).length() < 1e-3 * u.length() {
                return Err(bad(spec, "up", f[3], "zero or parallel to the direction"));
            }
            let parts: Vec<&str> = f[4].split(',').collect();
            if parts.len() != 2 {
                return Err(bad(
                    spec,
                    "half angles",
                    f[4],
                    format!("expected 2 comma-separated angles, found {}", parts.len()),
                ));
            }
            let mut half = [0.0f32; 2];
            for (h, p) in half.iter_mut().zip(&parts) {
                let a = number(spec, "half angle", p)?;
                if !(a > 0.0 && a < crate::RECT_MAX_HALF_ANGLE_DEG) {
                    return Err(bad(spec, "half angle", p, "must be in (0, 85) degrees"));
                }
                *h = a.to_radians();
            }
            Ok(Light::Rect {
                position: vec3(spec, "position", f[1])?,
                direction: d,
                up,
                half_angles: half,
                intensity: colour(spec, "intensity", f[5])?,
            })
        }
        "dir" => {
            let f = fields(spec, "directional light", 3, DIR)?;
            Ok(Light::Directional {
                direction: direction(spec, "direction", f[1])?,
                irradiance: colour(spec, "irradiance", f[2])?,
            })
        }
        _ => Err(SpecError::UnknownLightKind {
            spec: spec.into(),
            kind: kind.into(),
        }),
    }
}

/// Parses a camera spec `EX,EY,EZ:TX,TY,TZ:FOV_DEG`.
pub fn parse_camera(spec: &str) -> Result<Camera, SpecError> {
    let f = fields(spec, "camera", 3, CAMERA)?;
    let eye = vec3(spec, "eye", f[0])?;
    let target = vec3(spec, "target", f[1])?;
    if (target - eye).length_squared() == 0.0 {
        return Err(bad(spec, "target", f[1], "coincides with the eye"));
    }
    let fov = number(spec, "vertical field of view", f[2])?;
    if !(fov > 0.0 && fov < 180.0) {
        return Err(bad(spec, "vertical field of view", f[2], "must be in (0, 180) degrees"));
    }
    Ok(Camera {
        eye,
        target,
        fov_y_deg: fov,
    })
}

/// Parses an emitter scale spec `NAME=S` or `NAME=R,G,B` (finite, ≥ 0; `NAME` is an emitter
/// group's, i.e. an emissive material's, name, or `*` for all): `(NAME, [r, g, b])`.
pub fn parse_emitter_scale(spec: &str) -> Result<(String, [f32; 3]), SpecError> {
    let (name, value) = spec
        .rsplit_once('=')
        .ok_or_else(|| bad(spec, "emitter scale", spec, "expected NAME=SCALE or NAME=R,G,B"))?;
    if name.is_empty() {
        return Err(bad(spec, "emitter name", name, "empty (use * for every group)"));
    }
    let parts: Vec<&str> = value.split(',').collect();
    let s = match parts[..] {
        [v] => [number(spec, "emitter scale", v)?; 3],
        [_, _, _] => colour(spec, "emitter scale", value)?.to_array(),
        _ => return Err(bad(spec, "emitter scale", value, "give one scale or three (R,G,B)")),
    };
    if s.iter().any(|v| *v < 0.0) {
        return Err(bad(spec, "emitter scale", value, "negative"));
    }
    Ok((name.to_string(), s))
}

/// The scales of the emitter groups named `names` from `--emitter` specs
/// ([`parse_emitter_scale`]), applied in order, `*` naming every group; groups no spec names
/// keep scale 1. A spec that names no group is an error listing the groups.
pub fn resolve_emitter_scales(names: &[&str], specs: &[String]) -> Result<Vec<[f32; 3]>, String> {
    let mut scales = vec![[1.0f32; 3]; names.len()];
    for spec in specs {
        let (name, s) = parse_emitter_scale(spec).map_err(|e| format!("--emitter: {e}"))?;
        let mut found = false;
        for (g, n) in names.iter().enumerate() {
            if name == "*" || *n == name {
                scales[g] = s;
                found = true;
            }
        }
        if !found {
            return Err(if names.is_empty() {
                format!("--emitter {spec:?}: there are no emitter groups (emissive materials)")
            } else {
                format!(
                    "--emitter {spec:?}: no emitter group {name:?}; the groups are {}",
                    names.join(", ")
                )
            });
        }
    }
    Ok(scales)
}

/// Parses an image size `WxH` (both positive, at most 16384).
pub fn parse_size(spec: &str) -> Result<(u32, u32), SpecError> {
    let (w, h) = spec
        .split_once(['x', 'X'])
        .ok_or_else(|| bad(spec, "size", spec, "expected WxH, e.g. 512x512"))?;
    let p = |s: &str| -> Result<u32, SpecError> {
        let v: u32 = s
            .trim()
            .parse()
            .map_err(|_| bad(spec, "size", s, "not a positive integer"))?;
        if (1..=16384).contains(&v) {
            Ok(v)
        } else {
            Err(bad(spec, "size", s, "must be in 1..=16384"))
        }
    };
    Ok((p(w)?, p(h)?))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn emitter_specs_scale_named_groups_in_order() {
        let names = ["light", "lamp"];
        let spec = |v: &[&str]| v.iter().map(|s| s.to_string()).collect::<Vec<_>>();
        assert_eq!(resolve_emitter_scales(&names, &[]).unwrap(), [[1.0; 3]; 2]);
        assert_eq!(
            resolve_emitter_scales(&names, &spec(&["*=0", "lamp=1,0.5,0"])).unwrap(),
            [[0.0; 3], [1.0, 0.5, 0.0]]
        );
        assert_eq!(
            resolve_emitter_scales(&names, &spec(&["light=2"])).unwrap(),
            [[2.0; 3], [1.0; 3]]
        );
        for bad in ["nope=1", "light", "light=-1", "light=1,2", "light=x", "=1"] {
            let e = resolve_emitter_scales(&names, &spec(&[bad])).unwrap_err();
            assert!(e.contains("--emitter"), "{bad}: {e}");
        }
        assert!(resolve_emitter_scales(&names, &spec(&["nope=1"]))
            .unwrap_err()
            .contains("light, lamp"));
        assert!(resolve_emitter_scales(&[], &spec(&["*=1"]))
            .unwrap_err()
            .contains("no emitter groups"));
    }

    #[test]
    fn parses_the_readme_specs() {
        let l = parse_light("point:0.278,0.5,0.2795:0.2347,0.1566,0.0418").unwrap();
        assert_eq!(
            l,
            Light::Point {
                position: Vec3::new(0.278, 0.5, 0.2795),
                intensity: Vec3::new(0.2347, 0.1566, 0.0418)
            }
        );
        let c = parse_camera("0.278,0.273,-0.8:0.278,0.273,0:39.3076").unwrap();
        assert_eq!(c.eye, Vec3::new(0.278, 0.273, -0.8));
        assert_eq!(c.fov_y_deg, 39.3076);
        match parse_light("spot:0,2,0:0,-2,0:30:1,1,1").unwrap() {
            Light::Spot { direction, angle, .. } => {
                assert_eq!(direction, -Vec3::Y);
                assert!((angle - 30f32.to_radians()).abs() < 1e-6);
            }
            other => panic!("{other:?}"),
        }
        match parse_light("rect:0,2,0:0,-1,0:0,1,1:30,20:1,2,3").unwrap() {
            Light::Rect {
                direction,
                up,
                half_angles,
                intensity,
                ..
            } => {
                assert_eq!(direction, -Vec3::Y);
                assert!((up - Vec3::Z).length() < 1e-6, "up made perpendicular: {up}");
                assert!((half_angles[0] - 30f32.to_radians()).abs() < 1e-6);
                assert!((half_angles[1] - 20f32.to_radians()).abs() < 1e-6);
                assert_eq!(intensity, Vec3::new(1.0, 2.0, 3.0));
            }
            other => panic!("{other:?}"),
        }
        assert!(matches!(
            parse_light("dir:0,-1,0:3,3,3").unwrap(),
            Light::Directional { .. }
        ));
        assert_eq!(parse_size("640x480").unwrap(), (640, 480));
    }

    #[test]
    fn rejects_bad_specs_clearly() {
        for (spec, says) in [
            ("area:0,0,0:1,1,1", "unknown light kind"),
            ("point:0,0:1,1,1", "3 comma-separated"),
            ("point:0,0,0", "expected 3"),
            ("rect:0,0,0:0,-1,0:0,2,0:30,20:1,1,1", "parallel"),
            ("rect:0,0,0:0,-1,0:0,0,1:30:1,1,1", "2 comma-separated"),
            ("rect:0,0,0:0,-1,0:0,0,1:30,90:1,1,1", "(0, 85)"),
            ("rect:0,0,0:0,-1,0:30,20:1,1,1", "expected 6"),
        ] {
            let e = parse_light(spec).unwrap_err();
            assert!(e.to_string().contains(says), "{spec}: {e}");
        }
        for spec in [
            "spot:0,0,0:0,0,0:30:1,1,1",
            "spot:0,0,0:0,-1,0:0:1,1,1",
            "point:0,0,0:-1,1,1",
            "point:0,0,x:1,1,1",
        ] {
            assert!(parse_light(spec).is_err(), "{spec}");
        }
        assert!(parse_camera("0,0,0:0,0,0:40").is_err());
        assert!(parse_camera("0,0,0:0,0,1:0").is_err());
        assert!(parse_size("640").is_err());
        assert!(parse_size("0x4").is_err());
    }
}
