//! Wavefront OBJ + MTL loading through `tobj`.
//!
//! The file is read as bytes and pre-scanned line by line before `tobj` sees it, so that
//! malformed input is reported as `file:line` ([`SceneError::Malformed`]): numbers that do not
//! parse or are not finite, `f` lines with fewer than 3 vertices, and vertex, texture-coordinate
//! or normal indices that are out of range (a `vt` index in a file without `vt` lines included)
//! are all **errors**, never silently dropped. Comments (`#` at the start of a word) are removed
//! first, so non-UTF-8 bytes inside them are harmless; non-UTF-8 bytes elsewhere are replaced by
//! U+FFFD with a warning naming the line (or, where that makes the line unreadable, the error
//! names it). Polylines and points (`l`, `p`) are not lit and are removed before `tobj` parses.

use glam::{Vec2, Vec3};
use std::collections::HashMap;
use std::path::{Path, PathBuf};

use crate::scene::{area_epsilon, Aabb, LoadReport, Material, Scene, Triangle};
use crate::texture::Texture;
use crate::SceneError;

/// Albedo given to faces without a material, or whose MTL could not be read.
pub(crate) const DEFAULT_GREY: Vec3 = Vec3::splat(0.5);

/// Loads a Wavefront `.obj` scene and the MTL libraries and textures it names.
pub(crate) fn load(path: &Path) -> Result<Scene, SceneError> {
    let mut report = LoadReport::default();
    let prepared = read_and_check(path, &mut report.warnings)?;
    let dir = path.parent().unwrap_or(Path::new("."));
    let (models, obj_materials) = parse(path, dir, &prepared.text, &mut report.warnings)?;
    let (materials, textures) = read_materials(path, dir, &obj_materials, &mut report.warnings);
    let default_material = materials.len() as u32 - 1;
    let bounds = vertex_bounds(path, &prepared.text, &models)?;
    let eps = area_epsilon(bounds.diagonal());

    let mut scene = Scene {
        source: path.to_path_buf(),
        triangles: Vec::new(),
        lightmap_uvs: None,
        materials,
        textures,
        lights: Vec::new(),
        cameras: Vec::new(),
        report,
    };
    for model in &models {
        let material = model
            .mesh
            .material_id
            .filter(|&id| id < obj_materials.len())
            .map_or(default_material, |id| id as u32);
        push_mesh(&mut scene, &model.mesh, material, eps);
    }
    scene.finish_load()
}

/// Reads the file and prepares it for `tobj`, warning about each line with non-UTF-8 bytes;
/// the first malformed line is an error.
fn read_and_check(path: &Path, warnings: &mut Vec<String>) -> Result<Prepared, SceneError> {
    let bytes = read_regular_file(path).map_err(|source| SceneError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    let prepared = prepare(&bytes);
    for line in &prepared.lossy_lines {
        warnings.push(format!("{}:{line}: non-UTF-8 bytes replaced by U+FFFD", path.display()));
    }
    if let Some((line, why)) = first_bad_line(&prepared.text) {
        let why = if prepared.lossy_lines.contains(&line) {
            format!("{why} (the line has non-UTF-8 bytes)")
        } else {
            why
        };
        return Err(SceneError::Malformed {
            path: path.to_path_buf(),
            line: Some(line),
            message: why,
        });
    }
    Ok(prepared)
}

/// Parses the prepared text with `tobj`: its models, and the materials of its libraries (none,
/// with a warning, when a library cannot be read).
fn parse(
    path: &Path,
    dir: &Path,
    text: &str,
    warnings: &mut Vec<String>,
) -> Result<(Vec<tobj::Model>, Vec<tobj::Material>), SceneError> {
    let options = tobj::LoadOptions {
        triangulate: true,
        single_index: true,
        ignore_points: true,
        ignore_lines: true,
    };
    // MTL files too are read as bytes and decoded lossily, so one stray byte cannot lose them,
    // and their colour lines are checked first (`tobj` panics on `Kd` with 2 numbers).
    let mtl_warnings = std::cell::RefCell::new(Vec::new());
    let load_mtl = |mtl: &Path| {
        let file = dir.join(mtl);
        let bytes = read_regular_file(&file).map_err(|_| tobj::LoadError::OpenFileFailed)?;
        let text = prepare_mtl(&file, &bytes, &mut mtl_warnings.borrow_mut());
        tobj::load_mtl_buf(&mut std::io::Cursor::new(text.as_bytes()))
    };
    let mut reader = std::io::Cursor::new(text.as_bytes());
    let (models, materials) = match tobj::load_obj_buf(&mut reader, &options, load_mtl) {
        Ok(r) => r,
        Err(e) => return Err(locate_error(path, text, &e.to_string())),
    };
    warnings.append(&mut mtl_warnings.into_inner());
    let obj_materials = match materials {
        Ok(m) => m,
        Err(e) => {
            warnings.push(format!(
                "{}: material library could not be read ({e}); every face is grey {}",
                path.display(),
                DEFAULT_GREY.x
            ));
            Vec::new()
        }
    };
    Ok((models, obj_materials))
}

/// The material table (the file's materials, then one default grey for faces without one) and
/// the textures it uses, each image read once; an unreadable one is a warning.
fn read_materials(
    path: &Path,
    dir: &Path,
    obj_materials: &[tobj::Material],
    warnings: &mut Vec<String>,
) -> (Vec<Material>, Vec<Texture>) {
    let mut textures = Vec::new();
    let mut texture_ids: HashMap<PathBuf, Option<u32>> = HashMap::new();
    let mut scene_materials = Vec::with_capacity(obj_materials.len() + 1);
    for m in obj_materials {
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
                        warnings.push(format!(
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
        // Negative or non-finite Ke is refused, with a warning, in `Scene::finish_load`.
        let emission = m.emissive.map(Vec3::from_array).unwrap_or(Vec3::ZERO);
        scene_materials.push(Material {
            name: m.name.clone(),
            albedo,
            texture,
            emission,
        });
    }
    scene_materials.push(Material {
        name: "default-grey".into(),
        albedo: DEFAULT_GREY,
        texture: None,
        emission: Vec3::ZERO,
    });
    (scene_materials, textures)
}

/// The bounds of every model's vertices; a non-finite one is an error, named by its line where
/// it can be found.
fn vertex_bounds(path: &Path, text: &str, models: &[tobj::Model]) -> Result<Aabb, SceneError> {
    let mut bounds = Aabb::EMPTY;
    for model in models {
        for (i, p) in model.mesh.positions.chunks_exact(3).enumerate() {
            let p = Vec3::new(p[0], p[1], p[2]);
            if !p.is_finite() {
                let err = locate_error(path, text, "non-finite coordinate");
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
    Ok(bounds)
}

/// Adds a triangulated mesh's faces to `scene` with `material`; normals and UVs are kept only
/// when the mesh has one per vertex.
fn push_mesh(scene: &mut Scene, mesh: &tobj::Mesh, material: u32, eps: f32) {
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

/// Reads a regular file whole (a device or a directory is refused rather than read forever).
pub(crate) fn read_regular_file(file: &Path) -> std::io::Result<Vec<u8>> {
    if !std::fs::metadata(file)?.is_file() {
        return Err(std::io::Error::other("not a regular file"));
    }
    std::fs::read(file)
}

/// An OBJ file made ready for `tobj`: one line per input line (so line numbers are kept).
struct Prepared {
    /// The text: comments removed, `l`/`p` lines blanked, vertex colours dropped.
    text: String,
    /// 1-based lines whose non-comment part had non-UTF-8 bytes (replaced by U+FFFD).
    lossy_lines: Vec<usize>,
}

/// Turns raw OBJ bytes into text `tobj` can read without losing line numbers.
fn prepare(bytes: &[u8]) -> Prepared {
    let mut text = String::with_capacity(bytes.len());
    let mut lossy_lines = Vec::new();
    for (i, raw) in bytes.split(|&b| b == b'\n').enumerate() {
        let raw = raw.strip_suffix(b"\r").unwrap_or(raw);
        // A comment starts at a '#' that begins a word (so `usemtl a#1` keeps its name).
        let cut = (0..raw.len())
            .find(|&k| raw[k] == b'#' && (k == 0 || raw[k - 1].is_ascii_whitespace()))
            .unwrap_or(raw.len());
        let line = String::from_utf8_lossy(&raw[..cut]);
        if matches!(line, std::borrow::Cow::Owned(_)) {
            lossy_lines.push(i + 1);
        }
        let mut words = line.split_whitespace();
        match words.next() {
            // Not lit; and `tobj` would turn an `l` of 3 or more vertices into a triangle.
            Some("l" | "p") => {}
            // `v x y z r g b`: the colours are not used, and `tobj` trips on partial ones.
            Some("v") if line.split_whitespace().count() == 7 => {
                text.push_str("v ");
                text.push_str(&words.take(3).collect::<Vec<_>>().join(" "));
            }
            _ => text.push_str(line.trim_end()),
        }
        text.push('\n');
    }
    Prepared { text, lossy_lines }
}

/// Decodes an MTL file lossily and fixes its colour lines for `tobj`: `Ka`/`Kd`/`Ks`/`Ke` with one
/// number mean grey (`r r r`, as the MTL spec says); with 0 or 2 numbers the line is dropped with
/// a warning naming it.
fn prepare_mtl(file: &Path, bytes: &[u8], warnings: &mut Vec<String>) -> String {
    let text = String::from_utf8_lossy(bytes);
    let mut out = String::with_capacity(text.len());
    for (i, line) in text.lines().enumerate() {
        let words: Vec<&str> = line.split_whitespace().collect();
        match words.as_slice() {
            [key @ ("Ka" | "Kd" | "Ks" | "Ke"), grey] => {
                out.push_str(&format!("{key} {grey} {grey} {grey}"));
            }
            [key @ ("Ka" | "Kd" | "Ks" | "Ke")] | [key @ ("Ka" | "Kd" | "Ks" | "Ke"), _, _] => {
                warnings.push(format!(
                    "{}:{}: {key} needs 3 numbers (or 1), found {}; line ignored",
                    file.display(),
                    i + 1,
                    words.len() - 1
                ));
            }
            _ => out.push_str(line),
        }
        out.push('\n');
    }
    out
}

/// `tobj` reports what went wrong but not where: scan the text for the first line that is
/// malformed in the way `message` says (or in any way), so the error can name it.
fn locate_error(path: &Path, text: &str, message: &str) -> SceneError {
    let line = first_bad_line(text);
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
///
/// Relative (negative) indices count back from the elements defined so far, as `tobj` resolves
/// them; positive ones may refer to any element of the file.
fn first_bad_line(text: &str) -> Option<(usize, String)> {
    let mut total = [0i64; 3];
    for line in text.lines() {
        match line.split_whitespace().next() {
            Some("v") => total[0] += 1,
            Some("vt") => total[1] += 1,
            Some("vn") => total[2] += 1,
            _ => {}
        }
    }
    let mut so_far = [0i64; 3];
    for (i, raw) in text.lines().enumerate() {
        // Comments were removed by `prepare`; a '#' left is inside a word.
        let mut words = raw.split_whitespace();
        let Some(key) = words.next() else { continue };
        let rest: Vec<&str> = words.collect();
        let floats = |counts: &[usize]| -> Result<(), String> {
            if !counts.contains(&rest.len()) {
                let expected: Vec<String> = counts.iter().map(|c| c.to_string()).collect();
                return Err(format!(
                    "expected {} numbers, found {}",
                    expected.join(" or "),
                    rest.len()
                ));
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
            "v" => floats(&[3, 4, 6]).and_then(|_| match rest.get(3).map(|w| w.parse::<f32>()) {
                Some(Ok(w)) if rest.len() == 4 && w == 0.0 => Err("weight w is 0".to_string()),
                _ => {
                    so_far[0] += 1;
                    Ok(())
                }
            }),
            "vt" => floats(&[2, 3]).map(|_| so_far[1] += 1),
            "vn" => floats(&[3]).map(|_| so_far[2] += 1),
            "f" => check_face(&rest, so_far, total),
            "usemtl" if rest.is_empty() => Err("usemtl needs a material name".to_string()),
            _ => Ok(()),
        };
        if let Err(why) = result {
            return Some((i + 1, format!("{why} in '{}'", raw.trim())));
        }
    }
    None
}

/// Checks one `f` line: at least 3 vertices, each `v[/vt[/vn]]` with indices in range.
fn check_face(verts: &[&str], so_far: [i64; 3], total: [i64; 3]) -> Result<(), String> {
    if verts.len() < 3 {
        return Err(format!("a face needs 3 vertices, found {}", verts.len()));
    }
    const NAMES: [&str; 3] = ["vertex", "texture coordinate", "normal"];
    const KEYS: [&str; 3] = ["v", "vt", "vn"];
    for v in verts {
        let parts: Vec<&str> = v.split('/').collect();
        if parts.len() > 3 {
            return Err(format!("bad face vertex '{v}' (more than v/vt/vn)"));
        }
        for (k, part) in parts.iter().enumerate() {
            if part.is_empty() && k > 0 {
                continue;
            }
            let idx: i64 = part.parse().map_err(|_| format!("bad index '{part}'"))?;
            let (name, key) = (NAMES[k], KEYS[k]);
            if total[k] == 0 {
                return Err(format!("{name} index {idx} but the file has no '{key}' lines"));
            }
            if idx < 0 {
                let count = so_far[k];
                let resolved = count + idx + 1;
                if resolved < 1 {
                    return Err(format!(
                        "relative {name} index {idx} out of range ({count} defined so far)"
                    ));
                }
            } else if idx == 0 || idx > total[k] {
                return Err(format!(
                    "{name} index {idx} out of range (1..={} in the file)",
                    total[k]
                ));
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn prepare_keeps_lines_and_strips_comments() {
        let p = prepare(b"# \xff\r\nusemtl a#1 # c\nl 1 2 3\nv 1 2 3 0.1 0.2 0.3\no \xe9\n");
        assert_eq!(p.text, "\nusemtl a#1\n\nv 1 2 3\no \u{fffd}\n\n");
        assert_eq!(p.lossy_lines, vec![5], "the comment's byte is not reported");
        assert_eq!(first_bad_line("v 0 0 0\nvt 0 0\nf 1/1 1/1 1/2\n").map(|l| l.0), Some(3));
        assert_eq!(first_bad_line("v 0 0 0\nf 1/1 1 1\n").map(|l| l.0), Some(2));
        // Positive indices may refer forward (tobj resolves them at the end); relative may not.
        assert_eq!(first_bad_line("f 1 2 3\nv 0 0 0\nv 1 0 0\nv 0 1 0\n"), None);
    }

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
