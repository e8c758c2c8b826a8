//! Wavefront OBJ + MTL loading through `tobj`.

use glam::{Vec2, Vec3};
use std::collections::HashMap;
use std::path::{Path, PathBuf};

use crate::scene::{area_epsilon, Aabb, LoadReport, Material, Scene, Triangle};
use crate::texture::Texture;
use crate::SceneError;

/// Albedo given to faces without a material, or whose MTL could not be read.
pub(crate) const DEFAULT_GREY: Vec3 = Vec3::splat(0.5);

pub(crate) fn load(path: &Path) -> Result<Scene, SceneError> {
    let options = tobj::LoadOptions {
        triangulate: true,
        single_index: true,
        ignore_points: true,
        ignore_lines: true,
    };
    let (models, materials) = match tobj::load_obj(path, &options) {
        Ok(r) => r,
        Err(e) => return Err(locate_error(path, &e.to_string())),
    };
    let mut report = LoadReport::default();
    let dir = path.parent().unwrap_or(Path::new("."));
    let obj_materials = match materials {
        Ok(m) => m,
        Err(e) => {
            report.warnings.push(format!(
                "{}: material library could not be read ({e}); every face is grey {}",
                path.display(),
                DEFAULT_GREY.x
            ));
            Vec::new()
        }
    };

    // Material table: the file's materials, then one default grey for faces without one.
    let mut textures = Vec::new();
    let mut texture_ids: HashMap<PathBuf, Option<u32>> = HashMap::new();
    let mut scene_materials = Vec::with_capacity(obj_materials.len() + 1);
    for m in &obj_materials {
        let kd = m.diffuse.map(Vec3::from_array);
        let mut texture = None;
        if let Some(name) = &m.diffuse_texture {
            let file = dir.join(name.replace('\\', "/"));
            texture = *texture_ids
                .entry(file.clone())
                .or_insert_with(|| match image::open(&file) {
                    Ok(img) => {
                        textures.push(Texture::from_image(img));
                        Some(textures.len() as u32 - 1)
                    }
                    Err(e) => {
                        report.warnings.push(format!(
                            "{}: texture {} of material '{}' could not be read ({e}); using its Kd or grey",
                            path.display(),
                            file.display(),
                            m.name
                        ));
                        None
                    }
                });
        }
        // A texture, when present, is the albedo (Kd is often its mean, or a placeholder).
        let albedo = match (texture, kd) {
            (Some(_), _) => Vec3::ONE,
            (None, Some(kd)) => kd,
            (None, None) => DEFAULT_GREY,
        };
        scene_materials.push(Material {
            name: m.name.clone(),
            albedo,
            texture,
        });
    }
    let default_material = scene_materials.len() as u32;
    scene_materials.push(Material {
        name: "default-grey".into(),
        albedo: DEFAULT_GREY,
        texture: None,
    });

    let mut bounds = Aabb::EMPTY;
    for model in &models {
        for (i, p) in model.mesh.positions.chunks_exact(3).enumerate() {
            let p = Vec3::new(p[0], p[1], p[2]);
            if !p.is_finite() {
                let err = locate_error(path, "non-finite coordinate");
                if matches!(err, SceneError::Malformed { line: Some(_), .. }) {
                    return Err(err);
                }
                return Err(SceneError::NonFinite {
                    path: path.to_path_buf(),
                    what: format!("object '{}', vertex {i}", model.name),
                });
            }
            bounds.grow(p);
        }
    }
    let eps = area_epsilon(bounds.diagonal());

    let mut scene = Scene {
        source: path.to_path_buf(),
        triangles: Vec::new(),
        lightmap_uvs: None,
        materials: scene_materials,
        textures,
        lights: Vec::new(),
        cameras: Vec::new(),
        report,
    };
    for model in &models {
        let mesh = &model.mesh;
        let material = mesh
            .material_id
            .filter(|&id| id < obj_materials.len())
            .map_or(default_material, |id| id as u32);
        let pos = |i: u32| {
            let i = i as usize * 3;
            Vec3::new(mesh.positions[i], mesh.positions[i + 1], mesh.positions[i + 2])
        };
        let has_normals = mesh.normals.len() == mesh.positions.len();
        let has_uvs = mesh.texcoords.len() / 2 == mesh.positions.len() / 3;
        for f in mesh.indices.chunks_exact(3) {
            let f = [f[0], f[1], f[2]];
            let positions = [pos(f[0]), pos(f[1]), pos(f[2])];
            let normals = if has_normals {
                f.map(|i| {
                    let i = i as usize * 3;
                    Vec3::new(mesh.normals[i], mesh.normals[i + 1], mesh.normals[i + 2])
                })
            } else {
                [Vec3::ZERO; 3]
            };
            let uvs = if has_uvs {
                f.map(|i| {
                    let i = i as usize * 2;
                    Vec2::new(mesh.texcoords[i], mesh.texcoords[i + 1])
                })
            } else {
                [Vec2::ZERO; 3]
            };
            scene.push_triangle(
                Triangle {
                    positions,
                    normals,
                    uvs,
                    material,
                },
                eps,
            );
        }
    }
    scene.finish_load()
}

/// `tobj` reports what went wrong but not where: scan the file for the first line that is
/// malformed in the way `message` says (or in any way), so the error can name it.
fn locate_error(path: &Path, message: &str) -> SceneError {
    let text = match std::fs::read(path) {
        Ok(b) => String::from_utf8_lossy(&b).into_owned(),
        Err(source) => {
            return SceneError::Io {
                path: path.to_path_buf(),
                source,
            }
        }
    };
    let line = first_bad_line(&text);
    let message = match &line {
        Some((_, why)) => format!("{message}: {why}"),
        None => message.to_string(),
    };
    SceneError::Malformed {
        path: path.to_path_buf(),
        line: line.map(|(l, _)| l),
        message,
    }
}

/// The first line (1-based) of an OBJ text that cannot be read, with the reason.
fn first_bad_line(text: &str) -> Option<(usize, String)> {
    let (mut nv, mut nvt, mut nvn) = (0i64, 0i64, 0i64);
    for (i, raw) in text.lines().enumerate() {
        let line = raw.split('#').next().unwrap_or("").trim();
        let mut words = line.split_whitespace();
        let Some(key) = words.next() else { continue };
        let rest: Vec<&str> = words.collect();
        let floats = |min: usize| -> Result<(), String> {
            if rest.len() < min {
                return Err(format!("expected {min} numbers, found {}", rest.len()));
            }
            for w in &rest {
                match w.parse::<f32>() {
                    Ok(v) if v.is_finite() => {}
                    Ok(_) => return Err(format!("non-finite number '{w}'")),
                    Err(_) => return Err(format!("'{w}' is not a number")),
                }
            }
            Ok(())
        };
        let result = match key {
            "v" => floats(3).map(|_| nv += 1),
            "vt" => floats(1).map(|_| nvt += 1),
            "vn" => floats(3).map(|_| nvn += 1),
            "f" => check_face(&rest, nv, nvt, nvn),
            _ => Ok(()),
        };
        if let Err(why) = result {
            return Some((i + 1, format!("{why} in '{}'", raw.trim())));
        }
    }
    None
}

fn check_face(verts: &[&str], nv: i64, nvt: i64, nvn: i64) -> Result<(), String> {
    if verts.len() < 3 {
        return Err(format!("a face needs 3 vertices, found {}", verts.len()));
    }
    for v in verts {
        for (k, (part, count)) in v.split('/').zip([nv, nvt, nvn]).enumerate() {
            if part.is_empty() && k > 0 {
                continue;
            }
            let idx: i64 = part.parse().map_err(|_| format!("bad index '{part}'"))?;
            let resolved = if idx < 0 { count + idx + 1 } else { idx };
            if idx == 0 || resolved < 1 || resolved > count {
                return Err(format!("index {idx} out of range (1..={count} defined so far)"));
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bad_line_finder() {
        assert_eq!(first_bad_line("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"), None);
        assert_eq!(first_bad_line("v 0 0 0\nv 1 0 0\nv 0 1 0\nf -3 -2 -1\n"), None);
        assert_eq!(first_bad_line("v 0 0 0\nv 1 x 0\n").map(|l| l.0), Some(2));
        assert_eq!(first_bad_line("v 0 0 0\nv 1 nan 0\n").map(|l| l.0), Some(2));
        assert_eq!(
            first_bad_line("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n").map(|l| l.0),
            Some(4)
        );
        assert_eq!(first_bad_line("v 0 0 0\nf 1 -2 1\n").map(|l| l.0), Some(2));
        assert_eq!(first_bad_line("v 0 0 0\nv 1 0 0\nf 1 2\n").map(|l| l.0), Some(3));
    }
}
