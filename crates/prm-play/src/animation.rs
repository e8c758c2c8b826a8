//! Keyframed light and camera paths (`--animation FILE.toml`).
//!
//! ```toml
//! fps = 24.0                # frame i is at time i / fps seconds (default 24)
//!
//! [[camera]]                # optional; keys in increasing time
//! t = 0.0
//! spec = "0,1,3.5:0,1,0:40" # as --camera
//! [[camera]]
//! t = 2.0
//! spec = "1,1,3.5:0,1,0:40"
//!
//! [[light]]                 # one table per light; replaces the scene's and --light lights
//! keys = [
//!   { t = 0.0, spec = "point:0,1.5,0:2,1,1" },   # as --light
//!   { t = 2.0, spec = "point:0.5,1.5,0:1,1,2" },
//! ]
//!
//! [[emitter]]               # one table per emitter group it scales (as --emitter NAME=SCALE)
//! name = "light"
//! keys = [
//!   { t = 0.0, spec = "1" },            # a scale, or R,G,B
//!   { t = 2.0, spec = "0.2,0.4,1" },
//! ]
//!
//! [[sky]]                   # optional keys of the --sky's intensity and rotation
//! t = 0.0
//! intensity = 1.0           # default 1
//! rotation = 0.0            # degrees about +Y, default 0
//! [[sky]]
//! t = 2.0
//! rotation = 90.0
//! ```
//!
//! Between keys every parameter is interpolated linearly (positions, intensities, cone and
//! frustum angles; directions are interpolated and renormalised, a rectangular spot's vertical
//! also made perpendicular to its axis again); before the first key and after the last the
//! end keys hold. The keys of one light must all be of the same kind. Emitter groups the
//! animation does not name keep their `--emitter` scale (1 by default). Sky keys need `--sky`;
//! they replace its `--sky-intensity` and `--sky-rotation`.

use std::path::Path;

use glam::Vec3;
use prm_scene::{Camera, Light};
use serde::Deserialize;

use crate::PlayError;

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct FileKey {
    t: f32,
    spec: String,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct FileLight {
    keys: Vec<FileKey>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct FileEmitter {
    name: String,
    keys: Vec<FileKey>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct FileSky {
    t: f32,
    intensity: Option<f32>,
    rotation: Option<f32>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct File {
    fps: Option<f32>,
    #[serde(default)]
    camera: Vec<FileKey>,
    #[serde(default)]
    light: Vec<FileLight>,
    #[serde(default)]
    emitter: Vec<FileEmitter>,
    #[serde(default)]
    sky: Vec<FileSky>,
}

/// An emitter scale key: time and RGB scale.
pub type ScaleKey = (f32, [f32; 3]);

/// A parsed animation.
#[derive(Clone, Debug, Default)]
pub struct Animation {
    /// Frames per second.
    pub fps: f32,
    /// Camera keys (time, camera).
    pub camera: Vec<(f32, Camera)>,
    /// Per light, its keys (time, light).
    pub lights: Vec<Vec<(f32, Light)>>,
    /// Per animated emitter group, its name and keys (time, RGB scale).
    pub emitters: Vec<(String, Vec<ScaleKey>)>,
    /// The sky's keys: time, (intensity, rotation in degrees).
    pub sky: Vec<(f32, [f32; 2])>,
}

/// The orientation (direction, vertical) a fraction `s` of the way between two rectangular
/// lights' orientations, turning at a constant rate about one axis: the vertical stays
/// perpendicular to the direction all the way, where interpolating the two vectors apart can
/// make them parallel (a frame with no light).
fn slerp_frame(a: (Vec3, Vec3), b: (Vec3, Vec3), s: f32) -> (Vec3, Vec3) {
    let rotation = |(d, u): (Vec3, Vec3)| {
        let d = d.normalize();
        let up = (u - u.dot(d) * d).normalize();
        glam::Quat::from_mat3(&glam::Mat3::from_cols(up.cross(d), up, d))
    };
    let q = rotation(a).slerp(rotation(b), s);
    (q * Vec3::Z, q * Vec3::Y)
}

fn lerp_light(a: &Light, b: &Light, s: f32) -> Light {
    let dir = |x: Vec3, y: Vec3| x.lerp(y, s).normalize_or(y);
    match (*a, *b) {
        (
            Light::Point {
                position: p0,
                intensity: i0,
            },
            Light::Point {
                position: p1,
                intensity: i1,
            },
        ) => Light::Point {
            position: p0.lerp(p1, s),
            intensity: i0.lerp(i1, s),
        },
        (
            Light::Spot {
                position: p0,
                direction: d0,
                angle: a0,
                intensity: i0,
            },
            Light::Spot {
                position: p1,
                direction: d1,
                angle: a1,
                intensity: i1,
            },
        ) => Light::Spot {
            position: p0.lerp(p1, s),
            direction: dir(d0, d1),
            angle: a0 + (a1 - a0) * s,
            intensity: i0.lerp(i1, s),
        },
        (
            Light::Rect {
                position: p0,
                direction: d0,
                up: u0,
                half_angles: h0,
                intensity: i0,
            },
            Light::Rect {
                position: p1,
                direction: d1,
                up: u1,
                half_angles: h1,
                intensity: i1,
            },
        ) => {
            let (direction, up) = slerp_frame((d0, u0), (d1, u1), s);
            Light::Rect {
                position: p0.lerp(p1, s),
                direction,
                up,
                half_angles: [h0[0] + (h1[0] - h0[0]) * s, h0[1] + (h1[1] - h0[1]) * s],
                intensity: i0.lerp(i1, s),
            }
        }
        (
            Light::Directional {
                direction: d0,
                irradiance: e0,
            },
            Light::Directional {
                direction: d1,
                irradiance: e1,
            },
        ) => Light::Directional {
            direction: dir(d0, d1),
            irradiance: e0.lerp(e1, s),
        },
        _ => *a,
    }
}

/// Index pair and blend factor of time `t` in sorted keys.
fn locate<T>(keys: &[(f32, T)], t: f32) -> (usize, usize, f32) {
    let last = keys.len() - 1;
    if t <= keys[0].0 {
        return (0, 0, 0.0);
    }
    if t >= keys[last].0 {
        return (last, last, 0.0);
    }
    let i = keys.iter().position(|k| k.0 > t).unwrap_or(last) - 1;
    let (t0, t1) = (keys[i].0, keys[i + 1].0);
    (i, i + 1, if t1 > t0 { (t - t0) / (t1 - t0) } else { 0.0 })
}

impl Animation {
    /// Reads and validates a TOML animation.
    pub fn load(path: &Path) -> Result<Animation, PlayError> {
        let err = |message: String| PlayError::Animation {
            path: path.to_path_buf(),
            message,
        };
        let text = std::fs::read_to_string(path).map_err(|e| err(e.to_string()))?;
        Self::parse(&text).map_err(err)
    }

    /// Parses TOML text (see the module docs).
    pub fn parse(text: &str) -> Result<Animation, String> {
        let f: File = toml::from_str(text).map_err(|e| e.to_string())?;
        let sorted = |v: &[(f32, String)]| v.windows(2).all(|w| w[0].0 <= w[1].0) && v.iter().all(|k| k.0.is_finite());
        let fps = f.fps.unwrap_or(24.0);
        if !(fps > 0.0 && fps.is_finite()) {
            return Err(format!("fps must be positive, got {fps}"));
        }
        let cam_keys: Vec<(f32, String)> = f.camera.iter().map(|k| (k.t, k.spec.clone())).collect();
        if !sorted(&cam_keys) {
            return Err("camera keys must be in increasing time".into());
        }
        let camera = cam_keys
            .iter()
            .map(|(t, s)| prm_scene::parse_camera(s).map(|c| (*t, c)).map_err(|e| e.to_string()))
            .collect::<Result<Vec<_>, _>>()?;
        let mut lights = Vec::new();
        for (i, l) in f.light.iter().enumerate() {
            let keys: Vec<(f32, String)> = l.keys.iter().map(|k| (k.t, k.spec.clone())).collect();
            if keys.is_empty() {
                return Err(format!("light {i} has no keys"));
            }
            if !sorted(&keys) {
                return Err(format!("light {i}: keys must be in increasing time"));
            }
            let parsed = keys
                .iter()
                .map(|(t, s)| {
                    prm_scene::parse_light(s)
                        .map(|l| (*t, l))
                        .map_err(|e| format!("light {i}: {e}"))
                })
                .collect::<Result<Vec<_>, _>>()?;
            if parsed
                .windows(2)
                .any(|w| std::mem::discriminant(&w[0].1) != std::mem::discriminant(&w[1].1))
            {
                return Err(format!("light {i}: all keys must be of the same kind"));
            }
            lights.push(parsed);
        }
        let mut emitters = Vec::new();
        for e in &f.emitter {
            let keys: Vec<(f32, String)> = e.keys.iter().map(|k| (k.t, k.spec.clone())).collect();
            if keys.is_empty() || !sorted(&keys) {
                return Err(format!(
                    "emitter {:?}: keys must be present and in increasing time",
                    e.name
                ));
            }
            let parsed = keys
                .iter()
                .map(|(t, s)| {
                    prm_scene::parse_emitter_scale(&format!("{}={s}", e.name))
                        .map(|(_, v)| (*t, v))
                        .map_err(|err| format!("emitter {:?}: {err}", e.name))
                })
                .collect::<Result<Vec<_>, _>>()?;
            emitters.push((e.name.clone(), parsed));
        }
        let sky: Vec<(f32, [f32; 2])> = f
            .sky
            .iter()
            .map(|k| (k.t, [k.intensity.unwrap_or(1.0), k.rotation.unwrap_or(0.0)]))
            .collect();
        if !sky.windows(2).all(|w| w[0].0 <= w[1].0) || sky.iter().any(|(t, v)| !t.is_finite() || !v[1].is_finite()) {
            return Err("sky keys must be in increasing time, with finite rotations".into());
        }
        if let Some((t, _)) = sky.iter().find(|(_, v)| !(v[0].is_finite() && v[0] >= 0.0)) {
            return Err(format!("sky key at t = {t}: the intensity must be finite and ≥ 0"));
        }
        Ok(Animation {
            fps,
            camera,
            lights,
            emitters,
            sky,
        })
    }

    /// Time of frame `i`.
    pub fn time(&self, frame: u32) -> f32 {
        frame as f32 / self.fps
    }

    /// The camera at time `t`, if the animation has camera keys.
    pub fn camera_at(&self, t: f32) -> Option<Camera> {
        if self.camera.is_empty() {
            return None;
        }
        let (i, j, s) = locate(&self.camera, t);
        let (a, b) = (self.camera[i].1, self.camera[j].1);
        let eye = a.eye.lerp(b.eye, s);
        let mut target = a.target.lerp(b.target, s);
        // Where the eye passes through the target, look along the keys' interpolated view
        // direction instead of at nothing (a black frame).
        let span = (a.target - a.eye).length().min((b.target - b.eye).length());
        if (target - eye).length() < 1e-3 * span {
            let forward = (a.target - a.eye)
                .normalize()
                .lerp((b.target - b.eye).normalize(), s)
                .normalize_or((b.target - b.eye).normalize());
            target = eye + forward * span;
        }
        Some(Camera {
            eye,
            target,
            fov_y_deg: a.fov_y_deg + (b.fov_y_deg - a.fov_y_deg) * s,
        })
    }

    /// The scales of the emitter groups named `names` at time `t`: `base` (one per group) with
    /// the animated groups' interpolated keys in place. An animated name that is no group's is
    /// an error naming the groups.
    pub fn emitter_scales_at(&self, names: &[&str], base: &[[f32; 3]], t: f32) -> Result<Vec<[f32; 3]>, String> {
        let mut out = base.to_vec();
        for (name, keys) in &self.emitters {
            let (i, j, s) = locate(keys, t);
            let scale = [0, 1, 2].map(|k| keys[i].1[k] + (keys[j].1[k] - keys[i].1[k]) * s);
            // `*` scales every group, as `--emitter *=S` does.
            if name == "*" {
                out.iter_mut().for_each(|o| *o = scale);
                continue;
            }
            let g = names.iter().position(|n| n == name).ok_or_else(|| {
                format!(
                    "the animation scales emitter {name:?}, which the archive does not have (its groups: {})",
                    if names.is_empty() {
                        "none".to_string()
                    } else {
                        names.join(", ")
                    }
                )
            })?;
            out[g] = scale;
        }
        Ok(out)
    }

    /// The sky's intensity and rotation (degrees) at time `t`, if the animation has sky keys.
    pub fn sky_at(&self, t: f32) -> Option<[f32; 2]> {
        if self.sky.is_empty() {
            return None;
        }
        let (i, j, s) = locate(&self.sky, t);
        let (a, b) = (self.sky[i].1, self.sky[j].1);
        Some([a[0] + (b[0] - a[0]) * s, a[1] + (b[1] - a[1]) * s])
    }

    /// `sky` with its intensity and rotation at time `t`, when the animation has sky keys.
    pub fn sky_state_at(&self, sky: &prm_scene::Sky, t: f32) -> Option<prm_scene::Sky> {
        self.sky_at(t).map(|[intensity, rotation]| {
            let mut s = sky.clone();
            s.intensity = intensity;
            s.rotation = rotation.to_radians();
            s
        })
    }

    /// The lights at time `t` (empty if the animation has none).
    pub fn lights_at(&self, t: f32) -> Vec<Light> {
        self.lights
            .iter()
            .map(|keys| {
                let (i, j, s) = locate(keys, t);
                lerp_light(&keys[i].1, &keys[j].1, s)
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A rectangular light whose vertical would pass through its direction between two valid
    /// keys (the two vectors swap) keeps a valid frame at every time: a unit vertical
    /// perpendicular to a unit direction, ending at the second key's.
    #[test]
    fn a_rect_light_keeps_a_valid_frame_between_keys() {
        let a = Animation::parse(
            "[[light]]\nkeys = [ { t = 0.0, spec = \"rect:0,1,0:1,0,0:0,1,0:30,20:1,1,1\" },\n\
             { t = 1.0, spec = \"rect:0,1,0:0,1,0:1,0,0:30,20:1,1,1\" } ]\n",
        )
        .unwrap();
        for i in 0..=20 {
            let t = i as f32 / 20.0;
            let Light::Rect { direction, up, .. } = a.lights_at(t)[0] else {
                panic!("a rect light")
            };
            assert!(
                (direction.length() - 1.0).abs() < 1e-4 && (up.length() - 1.0).abs() < 1e-4,
                "t {t}"
            );
            assert!(direction.dot(up).abs() < 1e-4, "t {t}: direction {direction}, up {up}");
        }
        let Light::Rect { direction, up, .. } = a.lights_at(1.0)[0] else {
            panic!("a rect light")
        };
        assert!(direction.distance(Vec3::Y) < 1e-4 && up.distance(Vec3::X) < 1e-4);
    }

    /// A camera whose eye passes through its target between two keys stays a camera that can
    /// render (what `--camera` accepts) at every time.
    #[test]
    fn a_camera_passing_through_its_target_stays_valid() {
        let a = Animation::parse(
            "[[camera]]\nt = 0.0\nspec = \"0,0,-1:0,0,0:40\"\n[[camera]]\nt = 1.0\nspec = \"0,0,1:0,0,0:40\"\n",
        )
        .unwrap();
        for i in 0..=20 {
            let t = i as f32 / 20.0;
            let c = a.camera_at(t).unwrap();
            assert!(c.is_valid(), "t {t}: {c:?}");
        }
    }

    /// `[[emitter]] name = "*"` scales every group, as `--emitter *=S` does; unknown keys in any
    /// table are refused, not only at the top level and in `[[sky]]`.
    #[test]
    fn a_star_scales_every_group_and_unknown_keys_are_refused() {
        let a = Animation::parse("[[emitter]]\nname = \"*\"\nkeys = [ { t = 0.0, spec = \"0.5\" } ]\n").unwrap();
        let scales = a.emitter_scales_at(&["lamp", "glow"], &[[1.0; 3]; 2], 0.0).unwrap();
        assert_eq!(scales, vec![[0.5; 3]; 2]);
        for text in [
            "[[camera]]\nt = 0.0\nspec = \"0,1,3:0,1,0:40\"\nfov = 3\n",
            "[[light]]\nkeys = [ { t = 0.0, spec = \"point:0,1,0:1,1,1\", x = 1 } ]\n",
            "[[light]]\nkeys = []\nspeed = 2\n",
            "[[emitter]]\nname = \"lamp\"\nkeys = []\nscale = 2\n",
        ] {
            let err = Animation::parse(text)
                .err()
                .unwrap_or_else(|| panic!("accepted: {text}"));
            assert!(err.contains("unknown field"), "{text}: {err}");
        }
    }
}
