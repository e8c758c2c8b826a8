//! glTF 2.0 (`.gltf`, `.glb`) loading: node transforms, base colour, lightmap UVs, lights, cameras.
//!
//! Light intensities are taken as radiometric: `KHR_lights_punctual` point and spot intensities
//! (candela in the spec) are read as W/sr per channel after multiplying by the colour, and
//! directional intensities (lux) as W/m². Texture coordinates are flipped (`v → 1 − v`) to the
//! OBJ convention the texture sampler uses.

use glam::{Mat3, Mat4, Vec2, Vec3};
use std::collections::HashMap;
use std::path::Path;

use crate::scene::{area_epsilon, Aabb, Camera, Light, LoadReport, Material, Scene, Triangle};
use crate::texture::Texture;
use crate::SceneError;

pub(crate) fn load(path: &Path) -> Result<Scene, SceneError> {
    let malformed = |message: String| SceneError::Malformed {
        path: path.to_path_buf(),
        line: None,
        message,
    };
    let gltf::Gltf { document, blob } = gltf::Gltf::open(path).map_err(|e| match e {
        gltf::Error::Io(source) => SceneError::Io {
            path: path.to_path_buf(),
            source,
        },
        e => malformed(e.to_string()),
    })?;
    let base = path.parent().unwrap_or(Path::new("."));
    let buffers = gltf::import_buffers(&document, Some(base), blob).map_err(|e| malformed(e.to_string()))?;

    let mut report = LoadReport::default();
    // Images are decoded lazily, once each, only when a material uses them.
    let mut textures = Vec::new();
    let mut image_ids: HashMap<usize, Option<u32>> = HashMap::new();
    let mut materials = Vec::new();
    for m in document.materials() {
        let f = m.pbr_metallic_roughness().base_color_factor();
        let mut texture = None;
        if let Some(info) = m.pbr_metallic_roughness().base_color_texture() {
            if info.tex_coord() != 0 {
                report.warnings.push(format!(
                    "{}: material '{}' samples its base colour with TEXCOORD_{}; only TEXCOORD_0 is supported, using it",
                    path.display(),
                    m.name().unwrap_or("?"),
                    info.tex_coord()
                ));
            }
            let img = info.texture().source();
            texture = *image_ids.entry(img.index()).or_insert_with(|| {
                match gltf::image::Data::from_source(img.source(), Some(base), &buffers) {
                    Ok(data) => match texture_from_gltf(data) {
                        Some(t) => {
                            textures.push(t);
                            Some(textures.len() as u32 - 1)
                        }
                        None => {
                            report.warnings.push(format!(
                                "{}: image {} has an unsupported pixel format; ignored",
                                path.display(),
                                img.index()
                            ));
                            None
                        }
                    },
                    Err(e) => {
                        report.warnings.push(format!(
                            "{}: image {} could not be read ({e}); using the base colour factor",
                            path.display(),
                            img.index()
                        ));
                        None
                    }
                }
            });
        }
        materials.push(Material {
            name: m
                .name()
                .map_or_else(|| format!("material-{}", materials.len()), str::to_string),
            albedo: Vec3::new(f[0], f[1], f[2]),
            texture,
        });
    }
    let default_material = materials.len() as u32;
    materials.push(Material {
        name: "default".into(),
        albedo: Vec3::ONE,
        texture: None,
    });

    // Flatten the node hierarchy of the default scene (or of every scene when none is marked).
    let mut nodes = Vec::new();
    let roots: Vec<gltf::Node> = match document.default_scene().or_else(|| document.scenes().next()) {
        Some(s) => s.nodes().collect(),
        None => Vec::new(),
    };
    let mut stack: Vec<(gltf::Node, Mat4)> = roots.into_iter().map(|n| (n, Mat4::IDENTITY)).collect();
    while let Some((node, parent)) = stack.pop() {
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

    let mut raw: Vec<(Triangle, Option<[Vec2; 3]>)> = Vec::new();
    let mut lights = Vec::new();
    let mut cameras = Vec::new();
    let mut bounds = Aabb::EMPTY;
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
                gltf::camera::Projection::Orthographic(_) => report
                    .warnings
                    .push(format!("{}: orthographic camera ignored", path.display())),
            }
        }
        if let Some(light) = node.light() {
            let power = Vec3::from_array(light.color()) * light.intensity();
            lights.push(match light.kind() {
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
            });
        }
        let Some(mesh) = node.mesh() else { continue };
        let normal_matrix = Mat3::from_mat4(*world).inverse().transpose();
        let mirrored = Mat3::from_mat4(*world).determinant() < 0.0;
        for prim in mesh.primitives() {
            let reader = prim.reader(|b| buffers.get(b.index()).map(|d| &d.0[..]));
            let Some(positions) = reader.read_positions() else {
                report.warnings.push(format!(
                    "{}: mesh {} has a primitive without positions; skipped",
                    path.display(),
                    mesh.index()
                ));
                continue;
            };
            let positions: Vec<Vec3> = positions.map(|p| world.transform_point3(Vec3::from_array(p))).collect();
            if let Some(i) = positions.iter().position(|p| !p.is_finite()) {
                return Err(SceneError::NonFinite {
                    path: path.to_path_buf(),
                    what: format!("mesh {}, vertex {i}", mesh.index()),
                });
            }
            positions.iter().for_each(|&p| bounds.grow(p));
            let normals: Option<Vec<Vec3>> = reader.read_normals().map(|n| {
                n.map(|n| (normal_matrix * Vec3::from_array(n)).normalize_or_zero())
                    .collect()
            });
            let uv0: Option<Vec<Vec2>> = reader
                .read_tex_coords(0)
                .map(|t| t.into_f32().map(|[u, v]| Vec2::new(u, 1.0 - v)).collect());
            let uv1: Option<Vec<Vec2>> = reader
                .read_tex_coords(1)
                .map(|t| t.into_f32().map(|[u, v]| Vec2::new(u, v)).collect());
            let indices: Vec<u32> = match reader.read_indices() {
                Some(i) => i.into_u32().collect(),
                None => (0..positions.len() as u32).collect(),
            };
            if let Some(&bad) = indices.iter().find(|&&i| i as usize >= positions.len()) {
                return Err(malformed(format!(
                    "mesh {}: index {bad} out of range ({} vertices)",
                    mesh.index(),
                    positions.len()
                )));
            }
            let corners: Vec<[u32; 3]> = match prim.mode() {
                gltf::mesh::Mode::Triangles => indices.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect(),
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
                other => {
                    report.warnings.push(format!(
                        "{}: mesh {} has a {other:?} primitive; only triangles are lit, skipped",
                        path.display(),
                        mesh.index()
                    ));
                    continue;
                }
            };
            let material = prim.material().index().map_or(default_material, |i| i as u32);
            for mut c in corners {
                if mirrored {
                    c.swap(1, 2);
                }
                let at = |i: u32| i as usize;
                let tri = Triangle {
                    positions: c.map(|i| positions[at(i)]),
                    normals: normals.as_ref().map_or([Vec3::ZERO; 3], |n| c.map(|i| n[at(i)])),
                    uvs: uv0.as_ref().map_or([Vec2::ZERO; 3], |t| c.map(|i| t[at(i)])),
                    material,
                };
                raw.push((tri, uv1.as_ref().map(|t| c.map(|i| t[at(i)]))));
            }
        }
    }

    let mut scene = Scene {
        source: path.to_path_buf(),
        triangles: Vec::with_capacity(raw.len()),
        lightmap_uvs: None,
        materials,
        textures,
        lights,
        cameras,
        report,
    };
    let all_have_lightmap_uvs = !raw.is_empty() && raw.iter().all(|(_, l)| l.is_some());
    if !all_have_lightmap_uvs && raw.iter().any(|(_, l)| l.is_some()) {
        scene.report.warnings.push(format!(
            "{}: only some primitives have TEXCOORD_1; an atlas will be generated instead",
            path.display()
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
    scene.finish_load()
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
