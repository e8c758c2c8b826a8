//! glTF 2.0 (`.gltf`, `.glb`) loading: node transforms, base colour, lightmap UVs, lights, cameras.
//!
//! Over 600 lines on purpose: each accessor and buffer view is validated where it is read
//! (hostile files), next to the attribute it yields.
//!
//! Light intensities are taken as radiometric: `KHR_lights_punctual` point and spot intensities
//! (candela in the spec) are read as W/sr per channel after multiplying by the colour, and
//! directional intensities (lux) as W/m². Texture coordinates are flipped (`v → 1 − v`) to the
//! OBJ convention the texture sampler uses.
//!
//! Hostile input: buffers, bufferViews and accessors are validated here with checked arithmetic
//! before anything is read (a bufferView must fit its buffer, an accessor's
//! `byteOffset + stride × (count − 1) + element size` must fit its bufferView, attribute counts
//! must agree), so a forged count is an error naming the accessor, never a huge allocation, a
//! panic or a silently shortened mesh. Accessors are decoded here rather than by `gltf`'s reader.

use glam::{Mat3, Mat4, Vec2, Vec3};
use std::collections::HashMap;
use std::path::Path;

use crate::scene::{area_epsilon, Aabb, Camera, Light, LoadReport, Material, Scene, Triangle};
use crate::texture::Texture;
use crate::SceneError;

/// The glTF extensions the loader reads; any other one the file uses is named in a warning.
const READ_EXTENSIONS: [&str; 2] = ["KHR_lights_punctual", "KHR_materials_emissive_strength"];

/// One warning per extension in `extensionsUsed` that the loader does not read.
fn ignored_extensions(path: &Path, document: &gltf::Document) -> Vec<String> {
    document
        .extensions_used()
        .filter(|e| !READ_EXTENSIONS.contains(e))
        .map(|e| {
            let effect = match e {
                "KHR_texture_transform" => "textures are sampled with their coordinates untransformed",
                _ => "what it adds is ignored",
            };
            format!(
                "{}: uses the glTF extension {e}, which the loader does not read: {effect}",
                path.display()
            )
        })
        .collect()
}

/// A `Malformed` error about the file at `path`, with no line number.
fn malformed(path: &Path, message: String) -> SceneError {
    SceneError::Malformed {
        path: path.to_path_buf(),
        line: None,
        message,
    }
}

/// Loads a `.gltf` or `.glb` scene: materials, node hierarchy, lights, cameras and triangles.
pub(crate) fn load(path: &Path) -> Result<Scene, SceneError> {
    let (document, buffers) = parse_document(path)?;
    let base = path.parent().unwrap_or(Path::new("."));
    let mut report = LoadReport::default();
    report.warnings.extend(ignored_extensions(path, &document));
    let (materials, textures) = read_materials(path, base, &document, &buffers, &mut report.warnings);
    let nodes = flatten_nodes(path, &document)?;

    let mut geometry = Geometry {
        path,
        buffers: &buffers,
        default_material: materials.len() as u32 - 1,
        warnings: &mut report.warnings,
        raw: Vec::new(),
        bounds: Aabb::EMPTY,
    };
    let mut lights = Vec::new();
    let mut cameras = Vec::new();
    for (node, world) in &nodes {
        let origin = world.transform_point3(Vec3::ZERO);
        let forward = world.transform_vector3(-Vec3::Z).normalize_or_zero();
        if let Some(cam) = node.camera() {
            match cam.projection() {
                gltf::camera::Projection::Perspective(p) => cameras.push(Camera {
                    eye: origin,
                    target: origin + forward,
                    fov_y_deg: p.yfov().to_degrees(),
                }),
                gltf::camera::Projection::Orthographic(_) => geometry
                    .warnings
                    .push(format!("{}: orthographic camera ignored", path.display())),
            }
        }
        if let Some(light) = node.light() {
            lights.push(read_light(&light, origin, forward));
        }
        if let Some(mesh) = node.mesh() {
            geometry.read_mesh(&mesh, world)?;
        }
    }
    let Geometry { raw, bounds, .. } = geometry;

    let scene = Scene {
        source: path.to_path_buf(),
        triangles: Vec::with_capacity(raw.len()),
        lightmap_uvs: None,
        materials,
        textures,
        lights,
        cameras,
        report,
    };
    add_triangles(scene, raw, bounds).finish_load()
}

/// Reads the file and parses its document (checked before `gltf`'s own validation can index
/// out of bounds), then loads and checks its buffers and buffer views.
fn parse_document(path: &Path) -> Result<(gltf::Document, Vec<gltf::buffer::Data>), SceneError> {
    let bytes = crate::obj::read_regular_file(path).map_err(|source| SceneError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    // `gltf`'s validation indexes the accessor of every POSITION without a bounds check: parse
    // without validation first and check those indices, then parse again with validation.
    let unvalidated = gltf::Gltf::from_slice_without_validation(&bytes).map_err(|e| malformed(path, e.to_string()))?;
    check_position_indices(&unvalidated.document).map_err(|m| malformed(path, m))?;
    drop(unvalidated);
    let gltf::Gltf { document, blob } = gltf::Gltf::from_slice(&bytes).map_err(|e| malformed(path, e.to_string()))?;
    drop(bytes);
    let base = path.parent().unwrap_or(Path::new("."));
    let buffers = load_buffers(path, base, &document, blob)?;
    check_views(path, &document, &buffers)?;
    Ok((document, buffers))
}

/// The document's materials followed by a white `default` one, and the textures they use.
/// Images are decoded lazily, once each, only when a material uses them.
fn read_materials(
    path: &Path,
    base: &Path,
    document: &gltf::Document,
    buffers: &[gltf::buffer::Data],
    warnings: &mut Vec<String>,
) -> (Vec<Material>, Vec<Texture>) {
    let mut images = Images {
        path,
        base,
        buffers,
        textures: Vec::new(),
        ids: HashMap::new(),
    };
    let mut materials = Vec::new();
    for m in document.materials() {
        let f = m.pbr_metallic_roughness().base_color_factor();
        let mut texture = None;
        if let Some(info) = m.pbr_metallic_roughness().base_color_texture() {
            if info.tex_coord() != 0 {
                warnings.push(format!(
                    "{}: material '{}' samples its base colour with TEXCOORD_{}; only TEXCOORD_0 is supported, using it",
                    path.display(),
                    m.name().unwrap_or("?"),
                    info.tex_coord()
                ));
            }
            texture = images.texture(&info.texture().source(), warnings);
        }
        if m.emissive_texture().is_some() && m.emissive_factor() != [0.0; 3] {
            warnings.push(format!(
                "{}: material {} has an emissive texture; its emission is the factor alone",
                path.display(),
                m.name().unwrap_or("(unnamed)")
            ));
        }
        materials.push(Material {
            name: m
                .name()
                .map_or_else(|| format!("material-{}", materials.len()), str::to_string),
            albedo: Vec3::new(f[0], f[1], f[2]),
            texture,
            // Negative or non-finite emission is refused, with a warning, in `finish_load`.
            emission: Vec3::from_array(m.emissive_factor()) * m.emissive_strength().unwrap_or(1.0),
        });
    }
    materials.push(Material {
        name: "default".into(),
        albedo: Vec3::ONE,
        texture: None,
        emission: Vec3::ZERO,
    });
    (materials, images.textures)
}

/// The images that materials use, decoded into textures lazily, once each.
struct Images<'a> {
    path: &'a Path,
    /// The directory relative URIs start from.
    base: &'a Path,
    buffers: &'a [gltf::buffer::Data],
    textures: Vec<Texture>,
    /// Per image decoded so far, its texture (`None` when it could not be used).
    ids: HashMap<usize, Option<u32>>,
}

impl Images<'_> {
    /// The texture of `img`, decoding it the first time.
    fn texture(&mut self, img: &gltf::Image, warnings: &mut Vec<String>) -> Option<u32> {
        if let Some(&id) = self.ids.get(&img.index()) {
            return id;
        }
        let id = self.decode(img, warnings);
        self.ids.insert(img.index(), id);
        id
    }

    /// Decodes `img` into a new texture and returns its index, or warns and returns `None`
    /// when it cannot be read or has an unsupported pixel format.
    fn decode(&mut self, img: &gltf::Image, warnings: &mut Vec<String>) -> Option<u32> {
        let (path, textures) = (self.path, &mut self.textures);
        let data = match img.source() {
            // `gltf` panics on a relative URI that percent-decodes to invalid UTF-8.
            gltf::image::Source::Uri { uri, .. } if !uri.contains(':') && percent_decode(uri).is_none() => {
                Err(gltf::Error::UnsupportedScheme)
            }
            source => gltf::image::Data::from_source(source, Some(self.base), self.buffers),
        };
        match data {
            Ok(data) => match texture_from_gltf(data) {
                Some(t) => {
                    textures.push(t);
                    Some(textures.len() as u32 - 1)
                }
                None => {
                    warnings.push(format!(
                        "{}: image {} has an unsupported pixel format; ignored",
                        path.display(),
                        img.index()
                    ));
                    None
                }
            },
            Err(e) => {
                warnings.push(format!(
                    "{}: image {} could not be read ({e}); using the base colour factor",
                    path.display(),
                    img.index()
                ));
                None
            }
        }
    }
}

/// Flattens the node hierarchy of the default scene (or of the first scene when none is
/// marked) into `(node, world transform)` pairs in node order, refusing cycles, shared
/// children, dangling light references and non-finite transforms.
fn flatten_nodes<'d>(path: &Path, document: &'d gltf::Document) -> Result<Vec<(gltf::Node<'d>, Mat4)>, SceneError> {
    let mut nodes = Vec::new();
    let roots: Vec<gltf::Node> = match document.default_scene().or_else(|| document.scenes().next()) {
        Some(s) => s.nodes().collect(),
        None => Vec::new(),
    };
    let mut stack: Vec<(gltf::Node, Mat4)> = roots.into_iter().map(|n| (n, Mat4::IDENTITY)).collect();
    let mut visited = vec![false; document.nodes().len()];
    let light_count = document.lights().map_or(0, |l| l.len());
    while let Some((node, parent)) = stack.pop() {
        // A node reached twice is a cycle (which would never end) or a shared child: both invalid.
        if std::mem::replace(&mut visited[node.index()], true) {
            return Err(malformed(
                path,
                format!(
                    "node {} appears twice in the node hierarchy (a cycle or a shared child)",
                    node.index()
                ),
            ));
        }
        if let Some(l) = node_light_index(document, node.index()) {
            if l >= light_count {
                return Err(malformed(
                    path,
                    format!(
                        "node {} refers to light {l}, but the file has {light_count} lights",
                        node.index()
                    ),
                ));
            }
        }
        let world = parent * Mat4::from_cols_array_2d(&node.transform().matrix());
        if !world.is_finite() {
            return Err(SceneError::NonFinite {
                path: path.to_path_buf(),
                what: format!("transform of node {}", node.index()),
            });
        }
        for child in node.children() {
            stack.push((child, world));
        }
        nodes.push((node, world));
    }
    nodes.sort_by_key(|(n, _)| n.index());
    Ok(nodes)
}

/// A `KHR_lights_punctual` light placed at `origin`, facing `forward`, its colour scaled by its
/// intensity.
fn read_light(light: &gltf::khr_lights_punctual::Light, origin: Vec3, forward: Vec3) -> Light {
    let power = Vec3::from_array(light.color()) * light.intensity();
    match light.kind() {
        gltf::khr_lights_punctual::Kind::Point => Light::Point {
            position: origin,
            intensity: power,
        },
        gltf::khr_lights_punctual::Kind::Spot { outer_cone_angle, .. } => Light::Spot {
            position: origin,
            direction: forward,
            angle: outer_cone_angle,
            intensity: power,
        },
        gltf::khr_lights_punctual::Kind::Directional => Light::Directional {
            direction: forward,
            irradiance: power,
        },
    }
}

/// A world-space triangle and, where its primitive has `TEXCOORD_1`, its lightmap UVs.
type RawTriangle = (Triangle, Option<[Vec2; 3]>);

/// The triangles read from the scene's meshes so far, with their bounds.
struct Geometry<'a> {
    path: &'a Path,
    buffers: &'a [gltf::buffer::Data],
    /// The material of primitives that name none.
    default_material: u32,
    warnings: &'a mut Vec<String>,
    raw: Vec<RawTriangle>,
    bounds: Aabb,
}

/// A primitive's per-vertex attributes, in world space.
struct Vertices {
    positions: Vec<Vec3>,
    normals: Option<Vec<Vec3>>,
    uv0: Option<Vec<Vec2>>,
    uv1: Option<Vec<Vec2>>,
}

impl Geometry<'_> {
    /// Reads every triangle primitive of `mesh`, placed by `world`; warns about and skips the
    /// others.
    fn read_mesh(&mut self, mesh: &gltf::Mesh, world: &Mat4) -> Result<(), SceneError> {
        let path = self.path;
        for prim in mesh.primitives() {
            let mode = prim.mode();
            if !matches!(
                mode,
                gltf::mesh::Mode::Triangles | gltf::mesh::Mode::TriangleStrip | gltf::mesh::Mode::TriangleFan
            ) {
                self.warnings.push(format!(
                    "{}: mesh {} has a {mode:?} primitive; only triangles are lit, skipped",
                    path.display(),
                    mesh.index()
                ));
                continue;
            }
            let Some(pos_acc) = prim.get(&gltf::Semantic::Positions) else {
                self.warnings.push(format!(
                    "{}: mesh {} has a primitive without positions; skipped",
                    path.display(),
                    mesh.index()
                ));
                continue;
            };
            let vertices = self.read_vertices(mesh, &prim, &pos_acc, world)?;
            let corners = self.read_corners(mesh, &prim, vertices.positions.len())?;
            let material = prim.material().index().map_or(self.default_material, |i| i as u32);
            let mirrored = Mat3::from_mat4(*world).determinant() < 0.0;
            self.push_triangles(&vertices, corners, material, mirrored);
        }
        Ok(())
    }

    /// Reads a primitive's positions (growing the bounds), normals and both UV sets, checking
    /// that every attribute has one element per position.
    fn read_vertices(
        &mut self,
        mesh: &gltf::Mesh,
        prim: &gltf::Primitive,
        pos_acc: &gltf::Accessor,
        world: &Mat4,
    ) -> Result<Vertices, SceneError> {
        let (path, buffers) = (self.path, self.buffers);
        let local: Vec<[f32; 3]> = read_floats(path, pos_acc, buffers, "POSITION")?;
        let positions: Vec<Vec3> = local
            .iter()
            .map(|&p| world.transform_point3(Vec3::from_array(p)))
            .collect();
        if let Some(i) = positions.iter().position(|p| !p.is_finite()) {
            return Err(SceneError::NonFinite {
                path: path.to_path_buf(),
                what: format!("mesh {}, vertex {i}", mesh.index()),
            });
        }
        positions.iter().for_each(|&p| self.bounds.grow(p));
        // Every other attribute has one element per position.
        let attribute = |semantic: gltf::Semantic,
                         what: &'static str|
         -> Result<Option<(gltf::Accessor, &'static str)>, SceneError> {
            let Some(acc) = prim.get(&semantic) else {
                return Ok(None);
            };
            if acc.count() != positions.len() {
                return Err(SceneError::Accessor {
                    path: path.to_path_buf(),
                    accessor: acc.index(),
                    message: format!(
                        "{what} has {} elements but POSITION (accessor {}) has {}",
                        acc.count(),
                        pos_acc.index(),
                        positions.len()
                    ),
                });
            }
            Ok(Some((acc, what)))
        };
        let normal_matrix = Mat3::from_mat4(*world).inverse().transpose();
        let normals = map_floats(
            path,
            buffers,
            attribute(gltf::Semantic::Normals, "NORMAL")?,
            |n: [f32; 3]| (normal_matrix * Vec3::from_array(n)).normalize_or_zero(),
        )?;
        let uv0 = map_floats(
            path,
            buffers,
            attribute(gltf::Semantic::TexCoords(0), "TEXCOORD_0")?,
            |[u, v]| Vec2::new(u, 1.0 - v),
        )?;
        let uv1 = map_floats(
            path,
            buffers,
            attribute(gltf::Semantic::TexCoords(1), "TEXCOORD_1")?,
            Vec2::from_array,
        )?;
        Ok(Vertices {
            positions,
            normals,
            uv0,
            uv1,
        })
    }

    /// A primitive's triangles as corner indices (its index accessor, or its vertices in
    /// order), with strips and fans unrolled; an index beyond `vertex_count` is an error.
    fn read_corners(
        &self,
        mesh: &gltf::Mesh,
        prim: &gltf::Primitive,
        vertex_count: usize,
    ) -> Result<Vec<[u32; 3]>, SceneError> {
        let indices: Vec<u32> = match prim.indices() {
            Some(acc) => read_indices(self.path, &acc, self.buffers)?,
            None => (0..vertex_count as u32).collect(),
        };
        if let Some(&bad) = indices.iter().find(|&&i| i as usize >= vertex_count) {
            return Err(malformed(
                self.path,
                format!(
                    "mesh {}: index {bad} out of range ({vertex_count} vertices)",
                    mesh.index()
                ),
            ));
        }
        Ok(match prim.mode() {
            gltf::mesh::Mode::TriangleStrip => (2..indices.len())
                .map(|i| {
                    if i % 2 == 0 {
                        [indices[i - 2], indices[i - 1], indices[i]]
                    } else {
                        [indices[i - 1], indices[i - 2], indices[i]]
                    }
                })
                .collect(),
            gltf::mesh::Mode::TriangleFan => (2..indices.len())
                .map(|i| [indices[0], indices[i - 1], indices[i]])
                .collect(),
            _ => indices.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect(),
        })
    }

    /// Appends one triangle per corner triple, wound the other way under a mirroring transform.
    fn push_triangles(&mut self, v: &Vertices, corners: Vec<[u32; 3]>, material: u32, mirrored: bool) {
        for mut c in corners {
            if mirrored {
                c.swap(1, 2);
            }
            let at = |i: u32| i as usize;
            let tri = Triangle {
                positions: c.map(|i| v.positions[at(i)]),
                normals: v.normals.as_ref().map_or([Vec3::ZERO; 3], |n| c.map(|i| n[at(i)])),
                uvs: v.uv0.as_ref().map_or([Vec2::ZERO; 3], |t| c.map(|i| t[at(i)])),
                material,
            };
            self.raw.push((tri, v.uv1.as_ref().map(|t| c.map(|i| t[at(i)]))));
        }
    }
}

/// Adds the triangles to `scene`, keeping their lightmap UVs only when every primitive has
/// `TEXCOORD_1` (and warning when only some do).
fn add_triangles(mut scene: Scene, raw: Vec<RawTriangle>, bounds: Aabb) -> Scene {
    let all_have_lightmap_uvs = !raw.is_empty() && raw.iter().all(|(_, l)| l.is_some());
    if !all_have_lightmap_uvs && raw.iter().any(|(_, l)| l.is_some()) {
        scene.report.warnings.push(format!(
            "{}: only some primitives have TEXCOORD_1; an atlas will be generated instead",
            scene.source.display()
        ));
    }
    let eps = area_epsilon(bounds.diagonal());
    let mut lightmap_uvs = Vec::new();
    for (tri, luv) in raw {
        if scene.push_triangle(tri, eps) && all_have_lightmap_uvs {
            lightmap_uvs.push(luv.unwrap_or_default());
        }
    }
    if all_have_lightmap_uvs {
        scene.lightmap_uvs = Some(lightmap_uvs);
    }
    scene
}

/// Most elements an accessor without a bufferView (all zeros, plus any sparse values) may have:
/// nothing in the file bounds its count, so this does.
const MAX_VIEWLESS_COUNT: usize = 1 << 20;

/// Reads every buffer: the GLB binary chunk, a data URI, or an external file (reported by its
/// own path when missing). Each must hold at least its declared `byteLength`.
fn load_buffers(
    path: &Path,
    base: &Path,
    document: &gltf::Document,
    mut blob: Option<Vec<u8>>,
) -> Result<Vec<gltf::buffer::Data>, SceneError> {
    let mut buffers = Vec::with_capacity(document.buffers().len());
    for buffer in document.buffers() {
        let index = buffer.index();
        let (data, origin) = match buffer.source() {
            gltf::buffer::Source::Bin => match blob.take() {
                Some(b) => (b, path.to_path_buf()),
                None => {
                    return Err(malformed(
                        path,
                        format!("buffer {index} refers to the GLB binary chunk, which is missing"),
                    ))
                }
            },
            gltf::buffer::Source::Uri(uri) => match external_file(base, uri) {
                Some(Ok(file)) => {
                    let data = read_regular_file(&file).map_err(|source| SceneError::BufferFile {
                        path: file.clone(),
                        scene: path.to_path_buf(),
                        buffer: index,
                        source,
                    })?;
                    (data, file)
                }
                Some(Err(message)) => return Err(malformed(path, format!("buffer {index}: {message}"))),
                None => {
                    let data = gltf::buffer::Data::from_source(buffer.source(), Some(base))
                        .map_err(|e| malformed(path, format!("buffer {index}: {e}")))?;
                    (data.0, path.to_path_buf())
                }
            },
        };
        if (data.len() as u64) < buffer.length() as u64 {
            return Err(SceneError::BufferLength {
                path: origin,
                buffer: index,
                declared: buffer.length() as u64,
                actual: data.len() as u64,
            });
        }
        buffers.push(gltf::buffer::Data(data));
    }
    Ok(buffers)
}

/// Every primitive's POSITION must name an existing accessor (checked before `gltf` validates).
fn check_position_indices(document: &gltf::Document) -> Result<(), String> {
    use gltf::json::validation::Checked;
    let root = document.as_json();
    for (m, mesh) in root.meshes.iter().enumerate() {
        for (p, prim) in mesh.primitives.iter().enumerate() {
            if let Some(i) = prim
                .attributes
                .get(&Checked::Valid(gltf::json::mesh::Semantic::Positions))
            {
                if i.value() >= root.accessors.len() {
                    return Err(format!(
                        "mesh {m}, primitive {p}: POSITION refers to accessor {}, but the file has {}",
                        i.value(),
                        root.accessors.len()
                    ));
                }
            }
        }
    }
    Ok(())
}

/// The file a buffer URI names: `None` for a data URI (or another scheme `gltf` reads itself),
/// `Some(Err)` for a relative URI that does not percent-decode to UTF-8.
fn external_file(base: &Path, uri: &str) -> Option<Result<std::path::PathBuf, String>> {
    if let Some(rest) = uri.strip_prefix("file://").or_else(|| uri.strip_prefix("file:")) {
        return Some(Ok(Path::new(rest).to_path_buf()));
    }
    if uri.contains(':') {
        return None;
    }
    Some(match percent_decode(uri) {
        Some(rel) => Ok(base.join(rel)),
        None => Err(format!("URI '{uri}' is not valid percent-encoded UTF-8")),
    })
}

/// Decodes `%XX` escapes; `None` when the result is not UTF-8.
fn percent_decode(uri: &str) -> Option<String> {
    let b = uri.as_bytes();
    let mut out = Vec::with_capacity(b.len());
    let mut i = 0;
    while i < b.len() {
        let hex = |c: u8| (c as char).to_digit(16);
        if b[i] == b'%' && i + 2 < b.len() {
            if let (Some(h), Some(l)) = (hex(b[i + 1]), hex(b[i + 2])) {
                out.push((h * 16 + l) as u8);
                i += 3;
                continue;
            }
        }
        out.push(b[i]);
        i += 1;
    }
    String::from_utf8(out).ok()
}

/// Reads a regular file whole (a device or a directory is refused rather than read forever).
fn read_regular_file(file: &Path) -> std::io::Result<Vec<u8>> {
    if !std::fs::metadata(file)?.is_file() {
        return Err(std::io::Error::other("not a regular file"));
    }
    std::fs::read(file)
}

/// Every bufferView must lie inside its buffer (`byteOffset + byteLength ≤ buffer length`).
fn check_views(path: &Path, document: &gltf::Document, buffers: &[gltf::buffer::Data]) -> Result<(), SceneError> {
    for view in document.views() {
        let buffer = view.buffer().index();
        let actual = buffers[buffer].0.len().min(view.buffer().length()) as u64;
        let needed = (view.offset() as u64).checked_add(view.length() as u64);
        if needed.is_none_or(|n| n > actual) {
            return Err(SceneError::BufferView {
                path: path.to_path_buf(),
                view: view.index(),
                buffer,
                needed: needed.unwrap_or(u64::MAX),
                actual,
            });
        }
    }
    Ok(())
}

/// The bytes of a (validated) bufferView.
fn view_bytes<'b>(view: &gltf::buffer::View, buffers: &'b [gltf::buffer::Data]) -> &'b [u8] {
    &buffers[view.buffer().index()].0[view.offset()..view.offset() + view.length()]
}

/// The `KHR_lights_punctual` light index of a node, if it has one.
fn node_light_index(document: &gltf::Document, node: usize) -> Option<usize> {
    let n = document.as_json().nodes.get(node)?;
    Some(n.extensions.as_ref()?.khr_lights_punctual.as_ref()?.light.value())
}

fn component_size(t: gltf::accessor::DataType) -> usize {
    use gltf::accessor::DataType::*;
    match t {
        I8 | U8 => 1,
        I16 | U16 => 2,
        U32 | F32 => 4,
    }
}

/// One component as a float, normalised as the glTF spec says when `normalized`.
fn component_f32(t: gltf::accessor::DataType, b: &[u8], normalized: bool) -> f32 {
    use gltf::accessor::DataType::*;
    match (t, normalized) {
        (F32, _) => f32::from_le_bytes([b[0], b[1], b[2], b[3]]),
        (I8, false) => b[0] as i8 as f32,
        (U8, false) => b[0] as f32,
        (I16, false) => i16::from_le_bytes([b[0], b[1]]) as f32,
        (U16, false) => u16::from_le_bytes([b[0], b[1]]) as f32,
        (U32, false) => u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f32,
        (I8, true) => (b[0] as i8 as f32 / 127.0).max(-1.0),
        (U8, true) => b[0] as f32 / 255.0,
        (I16, true) => (i16::from_le_bytes([b[0], b[1]]) as f32 / 32767.0).max(-1.0),
        (U16, true) => u16::from_le_bytes([b[0], b[1]]) as f32 / 65535.0,
        (U32, true) => u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f32 / u32::MAX as f32,
    }
}

/// Checks that `count` elements of `elem` bytes, `stride` apart from `offset`, fit in `len`
/// bytes: `offset + stride × (count − 1) + elem ≤ len`, in checked arithmetic.
fn range_fits(offset: usize, stride: usize, count: usize, elem: usize, len: usize) -> Result<(), String> {
    let end = (count as u64)
        .checked_sub(1)
        .and_then(|n| n.checked_mul(stride as u64))
        .and_then(|n| n.checked_add(offset as u64))
        .and_then(|n| n.checked_add(elem as u64));
    match end {
        Some(end) if end <= len as u64 => Ok(()),
        Some(end) => Err(format!(
            "count {count} × stride {stride} from byteOffset {offset} needs {end} bytes, its bufferView has {len}"
        )),
        None => Err(format!(
            "count {count} × stride {stride} from byteOffset {offset} overflows"
        )),
    }
}

/// Decodes an accessor element by element (dense data, then sparse substitutions), after
/// checking every range it reads. `decode` receives one element's bytes.
fn read_accessor<T: Copy>(
    path: &Path,
    acc: &gltf::Accessor,
    buffers: &[gltf::buffer::Data],
    zero: T,
    decode: impl Fn(&[u8]) -> T,
) -> Result<Vec<T>, SceneError> {
    let err = |message: String| SceneError::Accessor {
        path: path.to_path_buf(),
        accessor: acc.index(),
        message,
    };
    let count = acc.count();
    if count == 0 {
        return Err(err("count is 0".into()));
    }
    let elem = component_size(acc.data_type()) * acc.dimensions().multiplicity();
    let mut out = match acc.view() {
        Some(view) => {
            let stride = view.stride().unwrap_or(elem);
            if stride < elem {
                return Err(err(format!(
                    "bufferView {} has byteStride {stride}, less than the element size {elem}",
                    view.index()
                )));
            }
            let bytes = view_bytes(&view, buffers);
            range_fits(acc.offset(), stride, count, elem, bytes.len())
                .map_err(|m| err(format!("{m} (bufferView {})", view.index())))?;
            (0..count)
                .map(|i| decode(&bytes[acc.offset() + i * stride..][..elem]))
                .collect::<Vec<T>>()
        }
        None if count > MAX_VIEWLESS_COUNT => {
            return Err(err(format!(
                "count {count} without a bufferView exceeds the limit of {MAX_VIEWLESS_COUNT}"
            )))
        }
        None => vec![zero; count],
    };
    if let Some(sparse) = acc.sparse() {
        let n = sparse.count();
        if n == 0 || n > count {
            return Err(err(format!("sparse count {n} is not in 1..={count}")));
        }
        let indices = sparse.indices();
        let index_size = indices.index_type().size();
        let index_view = indices.view();
        let index_bytes = view_bytes(&index_view, buffers);
        range_fits(indices.offset(), index_size, n, index_size, index_bytes.len())
            .map_err(|m| err(format!("sparse indices: {m} (bufferView {})", index_view.index())))?;
        let values = sparse.values();
        let value_view = values.view();
        let value_bytes = view_bytes(&value_view, buffers);
        range_fits(values.offset(), elem, n, elem, value_bytes.len())
            .map_err(|m| err(format!("sparse values: {m} (bufferView {})", value_view.index())))?;
        for k in 0..n {
            let b = &index_bytes[indices.offset() + k * index_size..][..index_size];
            let i = match index_size {
                1 => b[0] as usize,
                2 => u16::from_le_bytes([b[0], b[1]]) as usize,
                _ => u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as usize,
            };
            let slot = out
                .get_mut(i)
                .ok_or_else(|| err(format!("sparse index {i} out of range (count {count})")))?;
            *slot = decode(&value_bytes[values.offset() + k * elem..][..elem]);
        }
    }
    Ok(out)
}

/// The floats of an optional attribute (`what` names it in errors), each mapped by `f`.
fn map_floats<const N: usize, T>(
    path: &Path,
    buffers: &[gltf::buffer::Data],
    attribute: Option<(gltf::Accessor, &str)>,
    f: impl FnMut([f32; N]) -> T,
) -> Result<Option<Vec<T>>, SceneError> {
    attribute
        .map(|(acc, what)| {
            Ok(read_floats::<N>(path, &acc, buffers, what)?
                .into_iter()
                .map(f)
                .collect())
        })
        .transpose()
}

/// Reads a float attribute of `N` components (`VEC2` or `VEC3`), any component type.
fn read_floats<const N: usize>(
    path: &Path,
    acc: &gltf::Accessor,
    buffers: &[gltf::buffer::Data],
    what: &str,
) -> Result<Vec<[f32; N]>, SceneError> {
    let dims = acc.dimensions();
    if dims.multiplicity() != N
        || !matches!(
            dims,
            gltf::accessor::Dimensions::Vec2 | gltf::accessor::Dimensions::Vec3
        )
    {
        return Err(SceneError::Accessor {
            path: path.to_path_buf(),
            accessor: acc.index(),
            message: format!("{what} must be VEC{N}, found {dims:?}"),
        });
    }
    let (t, normalized) = (acc.data_type(), acc.normalized());
    let size = component_size(t);
    read_accessor(path, acc, buffers, [0.0; N], |b| {
        std::array::from_fn(|c| component_f32(t, &b[c * size..], normalized))
    })
}

/// Reads an index accessor: `SCALAR` of unsigned bytes, shorts or ints.
fn read_indices(path: &Path, acc: &gltf::Accessor, buffers: &[gltf::buffer::Data]) -> Result<Vec<u32>, SceneError> {
    use gltf::accessor::DataType::*;
    let t = acc.data_type();
    if acc.dimensions() != gltf::accessor::Dimensions::Scalar || !matches!(t, U8 | U16 | U32) {
        return Err(SceneError::Accessor {
            path: path.to_path_buf(),
            accessor: acc.index(),
            message: format!(
                "indices must be SCALAR of unsigned byte, short or int, found {:?} of {t:?}",
                acc.dimensions()
            ),
        });
    }
    read_accessor(path, acc, buffers, 0, |b| match t {
        U8 => b[0] as u32,
        U16 => u16::from_le_bytes([b[0], b[1]]) as u32,
        _ => u32::from_le_bytes([b[0], b[1], b[2], b[3]]),
    })
}

/// Converts a decoded glTF image to an 8-bit RGB texture; `None` for float formats.
fn texture_from_gltf(data: gltf::image::Data) -> Option<Texture> {
    use gltf::image::Format;
    let (channels, bytes_per) = match data.format {
        Format::R8 => (1, 1),
        Format::R8G8 => (2, 1),
        Format::R8G8B8 => (3, 1),
        Format::R8G8B8A8 => (4, 1),
        Format::R16 => (1, 2),
        Format::R16G16 => (2, 2),
        Format::R16G16B16 => (3, 2),
        Format::R16G16B16A16 => (4, 2),
        _ => return None,
    };
    let stride = channels * bytes_per;
    // 16-bit channels are little-endian in gltf's decoded data: keep the high byte.
    let byte = |px: &[u8], c: usize| px[c * bytes_per + bytes_per - 1];
    let texels = data
        .pixels
        .chunks_exact(stride)
        .map(|px| match channels {
            1 | 2 => [byte(px, 0); 3],
            _ => [byte(px, 0), byte(px, 1), byte(px, 2)],
        })
        .collect::<Vec<_>>();
    if texels.len() != (data.width * data.height) as usize {
        return None;
    }
    Some(Texture {
        width: data.width,
        height: data.height,
        texels,
    })
}
