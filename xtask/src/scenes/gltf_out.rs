//! glTF 2.0 writer for the generated scenes.
//!
//! One embedded base64 buffer, a node and mesh per part, flat per-face normals, a
//! `KHR_lights_punctual` point light and a perspective camera.

use serde_json::{json, Value};

#[cfg(test)]
use super::mesh::dot;
use super::mesh::{cross, is_planar, newell, normalize, sub, to_f32, SceneDesc, V3};

const ARRAY_BUFFER: u32 = 34962;
const ELEMENT_ARRAY_BUFFER: u32 = 34963;
const FLOAT: u32 = 5126;
const UNSIGNED_INT: u32 = 5125;
const TRIANGLES: u32 = 4;

/// A float as JSON with the shortest decimal text that reads back to the same f32.
pub fn jf(x: f32) -> Value {
    json!(format!("{x}").parse::<f64>().expect("float text"))
}

/// A value rounded to 4 decimals, as written to the MTL file.
fn j4(x: f64) -> Value {
    json!(format!("{x:.4}").parse::<f64>().expect("float text"))
}

/// Standard base64 (RFC 4648) with padding.
pub fn base64(bytes: &[u8]) -> String {
    const ALPHABET: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut out = String::with_capacity(bytes.len().div_ceil(3) * 4);
    for chunk in bytes.chunks(3) {
        let b = [chunk[0], *chunk.get(1).unwrap_or(&0), *chunk.get(2).unwrap_or(&0)];
        let n = (u32::from(b[0]) << 16) | (u32::from(b[1]) << 8) | u32::from(b[2]);
        for k in 0..4 {
            if k <= chunk.len() {
                out.push(ALPHABET[(n >> (18 - 6 * k)) as usize & 63] as char);
            } else {
                out.push('=');
            }
        }
    }
    out
}

/// Unit quaternion (x, y, z, w) of a camera at `eye` looking at `target` with +Y up
/// (glTF cameras look down their local −Z with +Y up).
pub fn look_at_quaternion(eye: V3, target: V3) -> [f64; 4] {
    let f = normalize(sub(target, eye));
    let r = normalize(cross(f, [0.0, 1.0, 0.0]));
    let u = cross(r, f);
    let b = [-f[0], -f[1], -f[2]];
    // Rotation matrix with columns r, u, b: m[row][col].
    let m = [[r[0], u[0], b[0]], [r[1], u[1], b[1]], [r[2], u[2], b[2]]];
    let trace = m[0][0] + m[1][1] + m[2][2];
    let q = if trace > 0.0 {
        let s = (trace + 1.0).sqrt() * 2.0;
        [
            (m[2][1] - m[1][2]) / s,
            (m[0][2] - m[2][0]) / s,
            (m[1][0] - m[0][1]) / s,
            0.25 * s,
        ]
    } else if m[0][0] > m[1][1] && m[0][0] > m[2][2] {
        let s = (1.0 + m[0][0] - m[1][1] - m[2][2]).sqrt() * 2.0;
        [
            0.25 * s,
            (m[0][1] + m[1][0]) / s,
            (m[0][2] + m[2][0]) / s,
            (m[2][1] - m[1][2]) / s,
        ]
    } else if m[1][1] > m[2][2] {
        let s = (1.0 + m[1][1] - m[0][0] - m[2][2]).sqrt() * 2.0;
        [
            (m[0][1] + m[1][0]) / s,
            0.25 * s,
            (m[1][2] + m[2][1]) / s,
            (m[0][2] - m[2][0]) / s,
        ]
    } else {
        let s = (1.0 + m[2][2] - m[0][0] - m[1][1]).sqrt() * 2.0;
        [
            (m[0][2] + m[2][0]) / s,
            (m[1][2] + m[2][1]) / s,
            0.25 * s,
            (m[1][0] - m[0][1]) / s,
        ]
    };
    // Clean tiny rounding noise so exact cases (e.g. a 180° turn about Y) read exactly.
    q.map(|c| if c.abs() < 1e-12 { 0.0 } else { (c * 1e9).round() / 1e9 })
}

/// Writes the .gltf JSON text for `scene`.
pub fn write_gltf(scene: &SceneDesc, generator: &str) -> String {
    let mut positions: Vec<[f32; 3]> = Vec::new();
    let mut normals: Vec<[f32; 3]> = Vec::new();
    let mut indices: Vec<u32> = Vec::new();
    let mut accessors = Vec::new();
    let mut meshes = Vec::new();
    let mut nodes = Vec::new();
    let material_index = |name: &str| {
        scene
            .materials
            .iter()
            .position(|m| m.name == name)
            .expect("part material is defined")
    };

    for part in &scene.parts {
        let (v0, i0) = (positions.len(), indices.len());
        for poly in &part.polys {
            // Non-planar polygons are emitted triangle by triangle, each with its own normal;
            // the triangles are exactly the fan the OBJ loader makes.
            let pieces: Vec<Vec<V3>> = if is_planar(poly) {
                vec![poly.clone()]
            } else {
                (1..poly.len() - 1)
                    .map(|i| vec![poly[0], poly[i], poly[i + 1]])
                    .collect()
            };
            for piece in pieces {
                let n = normalize(newell(&piece)).map(|c| c as f32);
                let base = (positions.len() - v0) as u32;
                for p in &piece {
                    positions.push(to_f32(*p));
                    normals.push(n);
                }
                for i in 1..piece.len() as u32 - 1 {
                    indices.extend([base, base + i, base + i + 1]);
                }
            }
        }
        let count = positions.len() - v0;
        let mut lo = [f32::INFINITY; 3];
        let mut hi = [f32::NEG_INFINITY; 3];
        for p in &positions[v0..] {
            for k in 0..3 {
                lo[k] = lo[k].min(p[k]);
                hi[k] = hi[k].max(p[k]);
            }
        }
        let acc = accessors.len();
        accessors.push(json!({
            "bufferView": 0, "byteOffset": v0 * 12, "componentType": FLOAT, "count": count,
            "type": "VEC3", "min": lo.map(jf), "max": hi.map(jf),
        }));
        accessors.push(json!({
            "bufferView": 1, "byteOffset": v0 * 12, "componentType": FLOAT, "count": count,
            "type": "VEC3",
        }));
        accessors.push(json!({
            "bufferView": 2, "byteOffset": i0 * 4, "componentType": UNSIGNED_INT,
            "count": indices.len() - i0, "type": "SCALAR",
        }));
        meshes.push(json!({
            "name": part.name,
            "primitives": [{
                "attributes": { "POSITION": acc, "NORMAL": acc + 1 },
                "indices": acc + 2,
                "material": material_index(&part.material),
                "mode": TRIANGLES,
            }],
        }));
        nodes.push(json!({ "name": part.name, "mesh": meshes.len() - 1 }));
    }

    let mut bin: Vec<u8> = Vec::new();
    for p in &positions {
        p.iter().for_each(|c| bin.extend(c.to_le_bytes()));
    }
    let normals_offset = bin.len();
    for n in &normals {
        n.iter().for_each(|c| bin.extend(c.to_le_bytes()));
    }
    let indices_offset = bin.len();
    for i in &indices {
        bin.extend(i.to_le_bytes());
    }

    let cam = &scene.camera;
    let eye = to_f32(cam.eye);
    let q = look_at_quaternion(cam.eye, cam.target);
    let mut perspective = json!({
        "yfov": jf(cam.fov_y_deg.to_radians() as f32),
        "znear": 0.01,
        "zfar": 100.0,
    });
    if let Some(aspect) = cam.aspect {
        perspective["aspectRatio"] = json!(aspect);
    }
    nodes.push(json!({
        "name": "camera",
        "camera": 0,
        "translation": eye.map(jf),
        "rotation": q,
    }));
    if let Some(light) = &scene.light {
        nodes.push(json!({
            "name": "point_light",
            "translation": to_f32(light.position).map(jf),
            "extensions": { "KHR_lights_punctual": { "light": 0 } },
        }));
    }

    let materials: Vec<Value> = scene
        .materials
        .iter()
        .map(|m| {
            let mut v = json!({
                "name": m.name,
                "pbrMetallicRoughness": {
                    "baseColorFactor": [j4(m.albedo[0]), j4(m.albedo[1]), j4(m.albedo[2]), 1.0],
                    "metallicFactor": 0.0,
                    "roughnessFactor": 1.0,
                },
            });
            // glTF caps emissiveFactor at 1: the peak goes into the strength extension.
            if let Some(e) = m.emission {
                let peak = e.iter().cloned().fold(0.0, f64::max);
                v["emissiveFactor"] = json!(e.map(|c| round6(c / peak)));
                v["extensions"] = json!({ "KHR_materials_emissive_strength": { "emissiveStrength": round6(peak) } });
            }
            v
        })
        .collect();

    let mut extensions_used = Vec::new();
    let mut doc = json!({
        "asset": { "version": "2.0", "generator": generator },
        "scene": 0,
        "scenes": [{ "name": scene.name, "nodes": (0..nodes.len()).collect::<Vec<_>>() }],
        "nodes": nodes,
        "meshes": meshes,
        "materials": materials,
        "cameras": [{ "name": "camera", "type": "perspective", "perspective": perspective }],
        "accessors": accessors,
        "bufferViews": [
            { "name": "positions", "buffer": 0, "byteOffset": 0, "byteLength": normals_offset,
              "byteStride": 12, "target": ARRAY_BUFFER },
            { "name": "normals", "buffer": 0, "byteOffset": normals_offset,
              "byteLength": indices_offset - normals_offset, "byteStride": 12, "target": ARRAY_BUFFER },
            { "name": "indices", "buffer": 0, "byteOffset": indices_offset,
              "byteLength": bin.len() - indices_offset, "target": ELEMENT_ARRAY_BUFFER },
        ],
        "buffers": [{
            "byteLength": bin.len(),
            "uri": format!("data:application/octet-stream;base64,{}", base64(&bin)),
        }],
    });
    if let Some(light) = &scene.light {
        let peak = light.intensity.iter().cloned().fold(0.0, f64::max);
        extensions_used.push("KHR_lights_punctual");
        doc["extensions"] = json!({ "KHR_lights_punctual": { "lights": [{
            "name": "point_light",
            "type": "point",
            "color": light.intensity.map(|c| round6(c / peak)),
            "intensity": round6(peak),
        }]}});
    }
    if scene.materials.iter().any(|m| m.emission.is_some()) {
        extensions_used.push("KHR_materials_emissive_strength");
    }
    if !extensions_used.is_empty() {
        doc["extensionsUsed"] = json!(extensions_used);
    }
    let mut text = serde_json::to_string_pretty(&doc).expect("JSON serialises");
    text.push('\n');
    text
}

fn round6(x: f64) -> f64 {
    (x * 1e6).round() / 1e6
}

/// Checks the camera basis used by [`look_at_quaternion`] (for tests).
#[cfg(test)]
fn rotate(q: [f64; 4], v: V3) -> V3 {
    let u = [q[0], q[1], q[2]];
    let t = super::mesh::scale(cross(u, v), 2.0);
    let a = super::mesh::add(v, super::mesh::scale(t, q[3]));
    super::mesh::add(a, cross(u, t))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn base64_matches_rfc4648_vectors() {
        let cases = [
            ("", ""),
            ("f", "Zg=="),
            ("fo", "Zm8="),
            ("foo", "Zm9v"),
            ("foob", "Zm9vYg=="),
            ("fooba", "Zm9vYmE="),
            ("foobar", "Zm9vYmFy"),
        ];
        for (plain, encoded) in cases {
            assert_eq!(base64(plain.as_bytes()), encoded);
        }
    }

    #[test]
    fn look_at_points_local_minus_z_at_target() {
        for (eye, target) in [
            ([0.278, 0.273, -0.8], [0.278, 0.273, 0.0]),
            ([0.5, 1.6, 0.5], [3.0, 0.7, 2.5]),
            ([7.6, 1.6, 4.6], [4.0, 1.0, 1.45]),
        ] {
            let q = look_at_quaternion(eye, target);
            let f = rotate(q, [0.0, 0.0, -1.0]);
            let want = normalize(sub(target, eye));
            assert!(dot(f, want) > 1.0 - 1e-9, "{f:?} vs {want:?}");
            let up = rotate(q, [0.0, 1.0, 0.0]);
            assert!(up[1] > 0.0);
            let right = rotate(q, [1.0, 0.0, 0.0]);
            assert!(right[1].abs() < 1e-9, "no roll");
        }
        assert_eq!(look_at_quaternion([0.0; 3], [0.0, 0.0, 1.0]), [0.0, 1.0, 0.0, 0.0]);
    }
}
