//! Static lightmap export, scene side: the flat scene written as glTF 2.0 with lightmap UVs as `TEXCOORD_1`.
//!
//! Over 600 lines on purpose: the glTF layout, its atomic write and the unit tests that check
//! both in one place; a tenth of the file is unit tests.
//!
//! [`write_gltf`] writes a [`Scene`] for engines that take only baked lightmaps (Bevy's
//! `Lightmap`, Godot, three.js): one node, one mesh, non-indexed triangles with `POSITION`,
//! `NORMAL`, `TEXCOORD_0` (material UVs) and `TEXCOORD_1` (the lightmap UVs given). The format
//! follows the extension: `.glb` is one binary file; `.gltf` is JSON plus a `<stem>.bin` beside it.
//!
//! **Reloading gives the same scene.** Triangles keep their order: the mesh has one primitive
//! per run of consecutive triangles with the same material (so one per material when the scene
//! is grouped by material), and [`crate::load`] reads primitives in order. Positions, lightmap
//! UVs and albedos are written bit-exactly (floats as the exact decimal of their `f32` value),
//! so [`Scene::fingerprint`] and [`Scene::materials_fingerprint`] of the reloaded scene equal
//! the original's and its [`Scene::lightmap_uvs`] equal the UVs written, with three exceptions
//! that come from the format or the loader, not from this writer:
//!
//! * a `-0.0` position coordinate comes back as `+0.0` (the loader applies the node transform);
//! * `TEXCOORD_0` is stored with `v` flipped (`1 − v`, glTF's convention, undone by the loader):
//!   the stored value is chosen so that the loader's `1 − v'` gives back `v` exactly where one
//!   exists, which is so for every `v` in `[0.5, 2]` and for multiples of `2⁻²⁴` (0, 0.25, …), but
//!   not for every `v` below 0.5 (`1 − v'` is then a multiple of `2⁻²⁴`), so a textured material's
//!   UVs (the only ones the materials fingerprint reads) may come back one ulp off;
//! * albedos outside `[0, 1]` are clamped (glTF's `baseColorFactor` range).
//!
//! A triangle the loader would drop as degenerate (a hand-built scene's, never a loaded one's)
//! is written too, and is then missing on reload.
//!
//! Materials are `pbrMetallicRoughness` with `baseColorFactor` = albedo (linear), metallic 0,
//! roughness 1. A [`Texture`](crate::Texture) keeps no file path, so textures used by a material
//! are embedded as PNG (8-bit sRGB RGB, the texels as they are) in the binary buffer. Lights and
//! cameras are not written: an engine playing baked lightmaps must not light the scene again.
//!
//! [`write_exr_rgb`] writes a lightmap (linear RGB, 32-bit float) as OpenEXR, row 0 on top, so
//! that texel `(x, y)` of the atlas (`uv = (x + ½, y + ½) / resolution`) is pixel `(x, y)` and
//! glTF's top-left UV origin samples it as the baker laid it out.
//!
//! Files are written atomically (a temporary file in the same directory, then a rename); an
//! existing target that is not a regular file (a directory, a symlink, a device) is refused.

use glam::{Vec2, Vec3};
use serde_json::{json, Map, Value};
use std::io::Write;
use std::path::{Path, PathBuf};

use crate::{Scene, Triangle};

mod ktx2;
pub use ktx2::{write_ktx2_rgb9e5, VK_FORMAT_E5B9G9R9_UFLOAT_PACK32};

/// Why a scene could not be exported.
#[derive(Debug, thiserror::Error)]
pub enum ExportError {
    /// Creating, writing or renaming a file failed (the I/O error is the source).
    #[error("{path}: cannot write it")]
    Io {
        /// The file being written.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// The target exists and is not a regular file; it is left alone.
    #[error("{0}: exists and is not a regular file; refusing to overwrite it")]
    NotRegularFile(PathBuf),
    /// The extension is neither `.glb` nor `.gltf`.
    #[error("{0}: unsupported export format (expected .glb or .gltf)")]
    UnsupportedFormat(PathBuf),
    /// The scene has no triangles (a glTF mesh needs at least one primitive).
    #[error("{0}: the scene has no triangles to export")]
    NoTriangles(PathBuf),
    /// The lightmap UVs are not one per triangle.
    #[error("{path}: {uvs} lightmap UV triples given for {triangles} triangles")]
    UvCount {
        /// The file being written.
        path: PathBuf,
        /// Triangles in the scene.
        triangles: usize,
        /// Lightmap UV triples given.
        uvs: usize,
    },
    /// A triangle holds a NaN or infinite value.
    #[error("{path}: triangle {triangle} has a non-finite {what}")]
    NonFinite {
        /// The file being written.
        path: PathBuf,
        /// Index of the triangle.
        triangle: usize,
        /// Which attribute (position, normal, material UV, lightmap UV).
        what: &'static str,
    },
    /// A triangle's material index is out of range.
    #[error("{path}: triangle {triangle} uses material {material}, but the scene has {materials}")]
    Material {
        /// The file being written.
        path: PathBuf,
        /// Index of the triangle.
        triangle: usize,
        /// Its material index.
        material: u32,
        /// Materials in the scene.
        materials: usize,
    },
    /// A material's albedo is not finite, or its texture cannot be written.
    #[error("{path}: material {material} ('{name}'): {message}")]
    BadMaterial {
        /// The file being written.
        path: PathBuf,
        /// Index of the material.
        material: usize,
        /// Its name.
        name: String,
        /// What is wrong.
        message: String,
    },
    /// An image's size and pixel count disagree, or it is empty.
    #[error("{path}: {message}")]
    BadImage {
        /// The file being written.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// The EXR encoder failed.
    #[error("{path}: EXR encoding failed: {message}")]
    Exr {
        /// The file being written.
        path: PathBuf,
        /// The encoder's message.
        message: String,
    },
    /// An EXR could not be read ([`read_exr_rgb`]).
    #[error("{path}: cannot read EXR: {message}")]
    ExrRead {
        /// The file being read.
        path: PathBuf,
        /// The decoder's message.
        message: String,
    },
    /// The binary data exceeds what the format can address (4 GiB for `.glb`).
    #[error("{path}: {bytes} bytes exceed the format's limit of {limit}")]
    TooLarge {
        /// The file being written.
        path: PathBuf,
        /// Bytes needed.
        bytes: u64,
        /// The limit.
        limit: u64,
    },
}

/// glTF `bufferView.target` of vertex attributes.
const ARRAY_BUFFER: u32 = 34962;
/// glTF `componentType` of 32-bit floats.
const FLOAT: u32 = 5126;

/// Writes `scene` as glTF 2.0 at `path` with `lightmap_uvs` (one triple per triangle, in the
/// scene's order, e.g. [`Atlas::uvs`](crate::Atlas::uvs)) as `TEXCOORD_1`.
///
/// `.glb` writes one binary glTF; `.gltf` writes JSON and a `<stem>.bin` buffer beside it
/// (both replaced atomically, the `.bin` first). Nothing is written when the scene is invalid
/// (no triangles, non-finite values, a material index out of range, a wrong UV count).
pub fn write_gltf(scene: &Scene, lightmap_uvs: &[[Vec2; 3]], path: &Path) -> Result<(), ExportError> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase)
        .unwrap_or_default();
    let binary = match ext.as_str() {
        "glb" => true,
        "gltf" => false,
        _ => return Err(ExportError::UnsupportedFormat(path.to_path_buf())),
    };
    if path.file_name().is_none() {
        return Err(ExportError::UnsupportedFormat(path.to_path_buf()));
    }
    check_target(path)?;
    if binary {
        let (json, bin) = build(scene, lightmap_uvs, path, None)?;
        let glb = glb_bytes(path, &json, &bin)?;
        write_atomic(path, |f| f.write_all(&glb))
    } else {
        let bin_path = path.with_extension("bin");
        check_target(&bin_path)?;
        let bin_name = bin_path
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        let (json, bin) = build(scene, lightmap_uvs, path, Some(&percent_encode(&bin_name)))?;
        let text = serde_json::to_vec_pretty(&json).map_err(|e| ExportError::Io {
            path: path.to_path_buf(),
            source: e.into(),
        })?;
        // Both files are complete on disk before either replaces its target.
        let bin_tmp = TempFile::write(&bin_path, |f| f.write_all(&bin))?;
        let json_tmp = TempFile::write(path, |f| f.write_all(&text))?;
        bin_tmp.commit(&bin_path)?;
        json_tmp.commit(path)
    }
}

/// [`ExportError::BadImage`] for the image to be written at `path`.
fn bad_image(path: &Path, message: String) -> ExportError {
    ExportError::BadImage {
        path: path.to_path_buf(),
        message,
    }
}

/// The image writers' refusals of their arguments: an empty image, or `pixels` that are not
/// `width × height`.
fn check_image(path: &Path, width: usize, height: usize, pixels: usize) -> Result<(), ExportError> {
    if width == 0 || height == 0 {
        return Err(bad_image(path, format!("empty image ({width}×{height})")));
    }
    if width.checked_mul(height) != Some(pixels) {
        return Err(bad_image(
            path,
            format!("{pixels} pixels given for a {width}×{height} image"),
        ));
    }
    Ok(())
}

/// Writes a linear RGB image as a 32-bit float OpenEXR file at `path` (atomically).
///
/// `rgb` is row-major, row 0 on top (pixel `(x, y)` is `rgb[y * width + x]`), as the atlas
/// numbers its texels. An empty image or one whose pixel count is not `width × height` is
/// refused; an existing target that is not a regular file is left alone. Values are stored
/// as they are (NaN included).
pub fn write_exr_rgb(path: &Path, width: usize, height: usize, rgb: &[[f32; 3]]) -> Result<(), ExportError> {
    check_image(path, width, height, rgb.len())?;
    if path.file_name().is_none() {
        return Err(bad_image(path, "not a file name".into()));
    }
    check_target(path)?;
    let channels = exr::prelude::SpecificChannels::rgb(|p: exr::prelude::Vec2<usize>| {
        let [r, g, b] = rgb[p.y() * width + p.x()];
        (r, g, b)
    });
    let mut bytes = std::io::Cursor::new(Vec::new());
    {
        use exr::prelude::WritableImage;
        exr::prelude::Image::from_channels((width, height), channels)
            .write()
            .to_buffered(&mut bytes)
            .map_err(|e| ExportError::Exr {
                path: path.to_path_buf(),
                message: e.to_string(),
            })?;
    }
    let bytes = bytes.into_inner();
    write_atomic(path, |f| f.write_all(&bytes))
}

/// Reads the first RGB(A) layer of an EXR as linear RGB: width, height and the pixels row by
/// row, top row first (alpha dropped); what [`write_exr_rgb`] wrote comes back as it was.
pub fn read_exr_rgb(path: &Path) -> Result<(usize, usize, Vec<[f32; 3]>), ExportError> {
    let img = exr::prelude::read_first_rgba_layer_from_file(
        path,
        |size, _| (size.0, size.1, vec![[0f32; 3]; size.0 * size.1]),
        |px: &mut (usize, usize, Vec<[f32; 3]>), pos, (r, g, b, _a): (f32, f32, f32, f32)| {
            let w = px.0;
            px.2[pos.1 * w + pos.0] = [r, g, b];
        },
    )
    .map_err(|e| ExportError::ExrRead {
        path: path.to_path_buf(),
        message: e.to_string(),
    })?;
    Ok(img.layer_data.channel_data.pixels)
}

/// Refuses an existing target that is not a regular file (a symlink counts as not regular).
fn check_target(path: &Path) -> Result<(), ExportError> {
    match std::fs::symlink_metadata(path) {
        Ok(m) if m.file_type().is_file() => Ok(()),
        Ok(_) => Err(ExportError::NotRegularFile(path.to_path_buf())),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(()),
        Err(source) => Err(ExportError::Io {
            path: path.to_path_buf(),
            source,
        }),
    }
}

/// A temporary file beside its target, removed when dropped unless committed.
struct TempFile {
    path: Option<PathBuf>,
}

impl TempFile {
    /// Creates a fresh temporary file in `target`'s directory, fills it with `fill` and syncs it.
    fn write(
        target: &Path,
        fill: impl FnOnce(&mut std::fs::File) -> std::io::Result<()>,
    ) -> Result<TempFile, ExportError> {
        use std::sync::atomic::{AtomicU32, Ordering};
        static COUNTER: AtomicU32 = AtomicU32::new(0);
        let dir = target
            .parent()
            .filter(|p| !p.as_os_str().is_empty())
            .unwrap_or(Path::new("."));
        let name = target.file_name().map(|n| n.to_string_lossy()).unwrap_or_default();
        let io = |source| ExportError::Io {
            path: target.to_path_buf(),
            source,
        };
        loop {
            let n = COUNTER.fetch_add(1, Ordering::Relaxed);
            let tmp = dir.join(format!(".{name}.{}.{n}.tmp", std::process::id()));
            let mut file = match std::fs::OpenOptions::new().write(true).create_new(true).open(&tmp) {
                Ok(f) => f,
                Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => continue,
                Err(e) => return Err(io(e)),
            };
            // From here on the guard removes the file on every failure.
            let guard = TempFile { path: Some(tmp) };
            fill(&mut file).and_then(|()| file.sync_all()).map_err(io)?;
            return Ok(guard);
        }
    }

    /// Renames the temporary file onto `target`.
    fn commit(mut self, target: &Path) -> Result<(), ExportError> {
        let Some(tmp) = self.path.take() else {
            return Ok(());
        };
        std::fs::rename(&tmp, target).map_err(|source| {
            let _ = std::fs::remove_file(&tmp);
            ExportError::Io {
                path: target.to_path_buf(),
                source,
            }
        })
    }
}

impl Drop for TempFile {
    fn drop(&mut self) {
        if let Some(tmp) = self.path.take() {
            let _ = std::fs::remove_file(tmp);
        }
    }
}

/// Writes `path` atomically: a temporary file filled by `fill`, then a rename.
fn write_atomic(path: &Path, fill: impl FnOnce(&mut std::fs::File) -> std::io::Result<()>) -> Result<(), ExportError> {
    TempFile::write(path, fill)?.commit(path)
}

/// A float as JSON: the exact decimal of its `f32` value (so it reads back bit-exactly both as
/// `f32` and as `f64`, as validators compare `min`/`max`).
fn num(x: f32) -> Value {
    json!(x as f64)
}

/// The stored `TEXCOORD_0` `v'` for a material `v`: one whose loader flip `1 − v'` (in `f32`)
/// gives back `v` bit-exactly when such a value lies within a few ulps of `1 − v`.
fn flip_v(v: f32) -> f32 {
    let w = 1.0 - v;
    let back = |c: f32| (1.0 - c).to_bits() == v.to_bits();
    if back(w) {
        return w;
    }
    let (mut up, mut down) = (w, w);
    for _ in 0..4 {
        up = up.next_up();
        down = down.next_down();
        for c in [up, down] {
            if back(c) {
                return c;
            }
        }
    }
    w
}

/// Percent-encodes a file name for a relative glTF URI.
fn percent_encode(name: &str) -> String {
    let mut out = String::with_capacity(name.len());
    for b in name.bytes() {
        if b.is_ascii_alphanumeric() || matches!(b, b'-' | b'_' | b'.' | b'~') {
            out.push(b as char);
        } else {
            out.push_str(&format!("%{b:02X}"));
        }
    }
    out
}

/// The glTF JSON and the binary buffer of `scene`; `uri` names the external buffer (`.gltf`),
/// `None` for the GLB binary chunk.
fn build(
    scene: &Scene,
    lightmap_uvs: &[[Vec2; 3]],
    path: &Path,
    uri: Option<&str>,
) -> Result<(Value, Vec<u8>), ExportError> {
    check_triangles(scene, lightmap_uvs, path)?;
    let mut buffer = Buffer::with_vertex_data(&scene.triangles, lightmap_uvs);
    let (materials, images) = buffer.write_materials(scene, path)?;
    buffer.pad();
    let (accessors, primitives) = primitives(&scene.triangles);

    let name = path
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "scene".into());
    let Buffer { bin, views } = buffer;
    let mut buffer = json!({ "byteLength": bin.len() });
    if let Some(uri) = uri {
        buffer["uri"] = json!(uri);
    }
    let mut root = json!({
        "asset": { "version": "2.0", "generator": concat!("prm-scene ", env!("CARGO_PKG_VERSION")) },
        "scene": 0,
        "scenes": [{ "nodes": [0] }],
        "nodes": [{ "mesh": 0, "name": name }],
        "meshes": [{ "name": name, "primitives": primitives }],
        "materials": materials,
        "accessors": accessors,
        "bufferViews": views,
        "buffers": [buffer],
    });
    if !images.is_empty() {
        let textures: Vec<Value> = (0..images.len())
            .map(|i| json!({ "sampler": 0, "source": i }))
            .collect();
        root["images"] = json!(images);
        root["textures"] = json!(textures);
        // Repeat wrapping and bilinear filtering, as the baker samples.
        root["samplers"] = json!([{ "magFilter": 9729, "minFilter": 9987, "wrapS": 10497, "wrapT": 10497 }]);
    }
    Ok((root, bin))
}

/// Refuses a scene that cannot be exported: no triangles, a lightmap UV count that differs
/// from the triangle count, a non-finite vertex attribute or a material out of range.
fn check_triangles(scene: &Scene, lightmap_uvs: &[[Vec2; 3]], path: &Path) -> Result<(), ExportError> {
    let tris = &scene.triangles;
    let n = tris.len();
    if n == 0 {
        return Err(ExportError::NoTriangles(path.to_path_buf()));
    }
    if lightmap_uvs.len() != n {
        return Err(ExportError::UvCount {
            path: path.to_path_buf(),
            triangles: n,
            uvs: lightmap_uvs.len(),
        });
    }
    let non_finite = |triangle, what| ExportError::NonFinite {
        path: path.to_path_buf(),
        triangle,
        what,
    };
    for (i, (t, luv)) in tris.iter().zip(lightmap_uvs).enumerate() {
        if !t.positions.iter().all(|p| p.is_finite()) {
            return Err(non_finite(i, "position"));
        }
        if !t.normals.iter().all(|p| p.is_finite()) {
            return Err(non_finite(i, "normal"));
        }
        if !t.uvs.iter().all(|p| p.is_finite()) {
            return Err(non_finite(i, "material UV"));
        }
        if !luv.iter().all(|p| p.is_finite()) {
            return Err(non_finite(i, "lightmap UV"));
        }
        if t.material as usize >= scene.materials.len() {
            return Err(ExportError::Material {
                path: path.to_path_buf(),
                triangle: i,
                material: t.material,
                materials: scene.materials.len(),
            });
        }
    }
    Ok(())
}

/// The vertex attributes: semantic and bytes per element, in the order of their bufferViews.
const ATTRIBUTES: [(usize, &str); 4] = [(12, "POSITION"), (12, "NORMAL"), (8, "TEXCOORD_0"), (8, "TEXCOORD_1")];

/// The binary buffer being written and the bufferViews into it.
struct Buffer {
    bin: Vec<u8>,
    views: Vec<Value>,
}

impl Buffer {
    /// The vertex data: four tightly packed sections (one bufferView each), three vertices per
    /// triangle in the scene's order. Every element is a multiple of 4 bytes, so every section
    /// and every accessor offset is 4-aligned.
    fn with_vertex_data(tris: &[Triangle], lightmap_uvs: &[[Vec2; 3]]) -> Buffer {
        let verts = 3 * tris.len();
        let mut bin: Vec<u8> = Vec::with_capacity(verts * (12 + 12 + 8 + 8));
        let put = |bin: &mut Vec<u8>, xs: &[f32]| xs.iter().for_each(|x| bin.extend_from_slice(&x.to_le_bytes()));
        for t in tris {
            for p in t.positions {
                put(&mut bin, &p.to_array());
            }
        }
        for t in tris {
            for nrm in t.normals {
                put(&mut bin, &unit_normal(nrm, t.normal()).to_array());
            }
        }
        for t in tris {
            for uv in t.uvs {
                put(&mut bin, &[uv.x, flip_v(uv.y)]);
            }
        }
        for luv in lightmap_uvs {
            for uv in luv {
                put(&mut bin, &uv.to_array());
            }
        }
        let sections = ["positions", "normals", "TEXCOORD_0", "TEXCOORD_1"];
        let mut views = Vec::new();
        let mut offset = 0usize;
        for ((size, _), name) in ATTRIBUTES.into_iter().zip(sections) {
            views.push(json!({
                "buffer": 0, "byteOffset": offset, "byteLength": size * verts,
                "target": ARRAY_BUFFER, "name": name,
            }));
            offset += size * verts;
        }
        Buffer { bin, views }
    }

    /// Zero bytes up to the next multiple of 4.
    fn pad(&mut self) {
        while !self.bin.len().is_multiple_of(4) {
            self.bin.push(0);
        }
    }

    /// The glTF materials, and the images of the textures they use, embedded as PNG after the
    /// data written so far (each once).
    fn write_materials(&mut self, scene: &Scene, path: &Path) -> Result<(Vec<Value>, Vec<Value>), ExportError> {
        let mut images = Vec::new();
        let mut image_of_texture: Vec<Option<usize>> = vec![None; scene.textures.len()];
        let mut materials = Vec::with_capacity(scene.materials.len());
        for (mi, m) in scene.materials.iter().enumerate() {
            let bad = |message: String| ExportError::BadMaterial {
                path: path.to_path_buf(),
                material: mi,
                name: m.name.clone(),
                message,
            };
            if !m.albedo.is_finite() {
                return Err(bad(format!("non-finite albedo {}", m.albedo)));
            }
            let a = m.albedo.clamp(Vec3::ZERO, Vec3::ONE);
            let mut pbr = Map::new();
            pbr.insert("baseColorFactor".into(), json!([num(a.x), num(a.y), num(a.z), 1.0]));
            pbr.insert("metallicFactor".into(), json!(0.0));
            pbr.insert("roughnessFactor".into(), json!(1.0));
            if let Some(ti) = m.texture {
                let slot = image_of_texture.get_mut(ti as usize).ok_or_else(|| {
                    bad(format!(
                        "texture {ti} out of range (the scene has {})",
                        scene.textures.len()
                    ))
                })?;
                let image = match *slot {
                    Some(i) => i,
                    None => {
                        let png =
                            png_bytes(&scene.textures[ti as usize]).map_err(|e| bad(format!("texture {ti}: {e}")))?;
                        self.pad();
                        self.views
                            .push(json!({ "buffer": 0, "byteOffset": self.bin.len(), "byteLength": png.len() }));
                        self.bin.extend_from_slice(&png);
                        images.push(json!({ "bufferView": self.views.len() - 1, "mimeType": "image/png" }));
                        *slot = Some(images.len() - 1);
                        images.len() - 1
                    }
                };
                pbr.insert("baseColorTexture".into(), json!({ "index": image, "texCoord": 0 }));
            }
            materials.push(json!({ "name": m.name, "pbrMetallicRoughness": pbr }));
        }
        Ok((materials, images))
    }
}

/// The accessors and primitives of the mesh: one primitive per run of consecutive triangles
/// with the same material, its accessors ranges of the four vertex bufferViews.
fn primitives(tris: &[Triangle]) -> (Vec<Value>, Vec<Value>) {
    let n = tris.len();
    let mut accessors = Vec::new();
    let mut primitives = Vec::new();
    let mut start = 0;
    while start < n {
        let material = tris[start].material;
        let end = start + tris[start..].iter().take_while(|t| t.material == material).count();
        let (first, count) = (3 * start, 3 * (end - start));
        let (mut lo, mut hi) = (Vec3::INFINITY, Vec3::NEG_INFINITY);
        for t in &tris[start..end] {
            for p in t.positions {
                lo = lo.min(p);
                hi = hi.max(p);
            }
        }
        let mut attributes = Map::new();
        for (view, (size, semantic)) in ATTRIBUTES.into_iter().enumerate() {
            let mut acc = json!({
                "bufferView": view, "byteOffset": first * size, "componentType": FLOAT,
                "count": count, "type": if size == 12 { "VEC3" } else { "VEC2" },
            });
            if semantic == "POSITION" {
                acc["min"] = json!([num(lo.x), num(lo.y), num(lo.z)]);
                acc["max"] = json!([num(hi.x), num(hi.y), num(hi.z)]);
            }
            accessors.push(acc);
            attributes.insert(semantic.into(), json!(accessors.len() - 1));
        }
        primitives.push(json!({ "attributes": attributes, "material": material, "mode": 4 }));
        start = end;
    }
    (accessors, primitives)
}

/// A unit shading normal: `n` when already unit length (kept bit-exact), else normalised, else
/// the face normal `face`, else +Y (a degenerate face).
fn unit_normal(n: Vec3, face: Vec3) -> Vec3 {
    if (n.length_squared() - 1.0).abs() <= 1e-4 {
        return n;
    }
    let u = n.normalize_or_zero();
    if u != Vec3::ZERO {
        u
    } else if face != Vec3::ZERO {
        face
    } else {
        Vec3::Y
    }
}

/// A texture encoded as an 8-bit RGB PNG.
fn png_bytes(t: &crate::Texture) -> Result<Vec<u8>, String> {
    if t.width == 0 || t.height == 0 {
        return Err(format!("empty ({}×{})", t.width, t.height));
    }
    let expected = t.width as u64 * t.height as u64;
    if t.texels.len() as u64 != expected {
        return Err(format!(
            "{} texels for {}×{} = {expected}",
            t.texels.len(),
            t.width,
            t.height
        ));
    }
    let flat: Vec<u8> = t.texels.iter().flatten().copied().collect();
    let img = image::RgbImage::from_raw(t.width, t.height, flat).ok_or("texel buffer of the wrong size")?;
    let mut out = std::io::Cursor::new(Vec::new());
    img.write_to(&mut out, image::ImageFormat::Png)
        .map_err(|e| e.to_string())?;
    Ok(out.into_inner())
}

/// The GLB container of a glTF: serialises `json` and hands it to [`glb_container`].
fn glb_bytes(path: &Path, json: &Value, bin: &[u8]) -> Result<Vec<u8>, ExportError> {
    let text = serde_json::to_vec(json).map_err(|e| ExportError::Io {
        path: path.to_path_buf(),
        source: e.into(),
    })?;
    glb_container(&text, bin).map_err(|bytes| ExportError::TooLarge {
        path: path.to_path_buf(),
        bytes,
        limit: u32::MAX as u64,
    })
}

/// A GLB file of a glTF's `json` text and its binary buffer `bin`: the 12-byte header, the JSON
/// chunk padded with spaces and the BIN chunk padded with zeros to a multiple of 4 bytes; the
/// size instead when it exceeds the format's limit of `u32::MAX` bytes.
pub fn glb_container(json: &[u8], bin: &[u8]) -> Result<Vec<u8>, u64> {
    let chunks = [(json, *b"JSON", b' '), (bin, *b"BIN\0", 0)];
    let total: u64 = 12
        + chunks
            .iter()
            .map(|c| 8 + c.0.len().next_multiple_of(4) as u64)
            .sum::<u64>();
    if total > u32::MAX as u64 {
        return Err(total);
    }
    let mut out = Vec::with_capacity(total as usize);
    out.extend_from_slice(b"glTF");
    out.extend_from_slice(&2u32.to_le_bytes());
    out.extend_from_slice(&(total as u32).to_le_bytes());
    for (data, kind, pad) in chunks {
        let len = data.len().next_multiple_of(4);
        out.extend_from_slice(&(len as u32).to_le_bytes());
        out.extend_from_slice(&kind);
        out.extend_from_slice(data);
        out.resize(out.len() + len - data.len(), pad);
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn flip_v_round_trips_through_the_loaders_flip() {
        let exact = [0.0f32, 0.25, 0.5, 0.75, 1.0, 0.9, 1.7, 2.0, 3.25, 0.625, 3.0 / 1024.0];
        let grid = (0..1000).map(|i| (i as f32 * 12_345.0).rem_euclid(16_777_216.0) / 16_777_216.0);
        let upper = (0..1000).map(|i| 0.5 + i as f32 * 1.5 / 1000.0);
        for v in exact.into_iter().chain(grid).chain(upper) {
            let w = flip_v(v);
            assert_eq!((1.0 - w).to_bits(), v.to_bits(), "v = {v}");
        }
        // Below 2⁻²⁴ no f32 near 1 flips back to v; the plain flip is kept.
        assert_eq!(flip_v(1e-10), 1.0);
        // Elsewhere the stored value is always within an ulp of the true flip.
        for v in [0.1f32, 0.333, -0.3, 1e6, -7.5e-3] {
            assert!(
                (1.0 - flip_v(v) - v).abs() <= v.abs().max(1.0) * f32::EPSILON,
                "v = {v}"
            );
        }
    }

    /// The error and its sources as a binary prints them (`anyhow`'s `{:#}`).
    fn anyhow_like(err: &dyn std::error::Error) -> String {
        let mut s = err.to_string();
        let mut source = err.source();
        while let Some(e) = source {
            s.push_str(&format!(": {e}"));
            source = e.source();
        }
        s
    }

    #[test]
    fn a_failing_write_leaves_no_file() {
        let dir = std::env::temp_dir().join(format!("prm-scene-export-atomic-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let target = dir.join("scene.glb");
        let err = write_atomic(&target, |f| {
            f.write_all(b"half a file")?;
            Err(std::io::Error::other("disk full"))
        })
        .unwrap_err();
        // The I/O error is the source, printed once by `{:#}`.
        let chain = anyhow_like(&err);
        assert!(chain.contains("scene.glb") && chain.contains("disk full"), "{chain}");
        assert_eq!(chain.matches("disk full").count(), 1, "{chain}");
        assert_eq!(
            std::fs::read_dir(&dir).unwrap().count(),
            0,
            "no target and no temporary file"
        );
        // An existing target survives a failed replacement untouched.
        std::fs::write(&target, b"old").unwrap();
        write_atomic(&target, |_| Err(std::io::Error::other("boom"))).unwrap_err();
        assert_eq!(std::fs::read(&target).unwrap(), b"old");
        assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 1);
        write_atomic(&target, |f| f.write_all(b"new")).unwrap();
        assert_eq!(std::fs::read(&target).unwrap(), b"new");
        assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 1);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn percent_encoding_of_buffer_names() {
        assert_eq!(percent_encode("a b%.bin"), "a%20b%25.bin");
        assert_eq!(percent_encode("é.bin"), "%C3%A9.bin");
    }
}
