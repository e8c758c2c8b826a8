//! Wavefront OBJ + MTL writer: one `o` per part, shared deduplicated positions, positive indices.

use std::collections::HashMap;
use std::fmt::Write as _;

use super::mesh::{is_planar, to_f32, SceneDesc, V3};

/// Writes the OBJ text (non-planar polygons as explicit triangles, so no loader can pick a
/// different diagonal) for `scene`, referencing `mtl_name`.
pub fn write_obj(scene: &SceneDesc, mtl_name: &str, header: &[String]) -> String {
    let mut index: HashMap<[u32; 3], usize> = HashMap::new();
    let mut verts = String::new();
    let mut faces = String::new();
    let mut vid = |p: V3, verts: &mut String| -> usize {
        let f = to_f32(p);
        let key = f.map(f32::to_bits);
        let next = index.len() + 1;
        *index.entry(key).or_insert_with(|| {
            writeln!(verts, "v {} {} {}", f[0], f[1], f[2]).unwrap();
            next
        })
    };
    for part in &scene.parts {
        writeln!(faces, "o {}", part.name).unwrap();
        writeln!(faces, "usemtl {}", part.material).unwrap();
        for poly in &part.polys {
            let ids: Vec<usize> = poly.iter().map(|p| vid(*p, &mut verts)).collect();
            if is_planar(poly) {
                let list: Vec<String> = ids.iter().map(usize::to_string).collect();
                writeln!(faces, "f {}", list.join(" ")).unwrap();
            } else {
                for i in 1..ids.len() - 1 {
                    writeln!(faces, "f {} {} {}", ids[0], ids[i], ids[i + 1]).unwrap();
                }
            }
        }
    }
    let mut out = String::new();
    for line in header {
        writeln!(out, "# {line}").unwrap();
    }
    writeln!(out, "mtllib {mtl_name}").unwrap();
    writeln!(out).unwrap();
    out.push_str(&verts);
    writeln!(out).unwrap();
    out.push_str(&faces);
    out
}

/// Writes the MTL text: Lambertian materials only (`Kd`; `Ke` where given; no specular).
pub fn write_mtl(scene: &SceneDesc, header: &[String]) -> String {
    let mut out = String::new();
    for line in header {
        writeln!(out, "# {line}").unwrap();
    }
    for m in &scene.materials {
        let [r, g, b] = m.albedo;
        writeln!(out).unwrap();
        writeln!(out, "newmtl {}", m.name).unwrap();
        writeln!(out, "Ka 0 0 0").unwrap();
        writeln!(out, "Kd {r:.4} {g:.4} {b:.4}").unwrap();
        writeln!(out, "Ks 0 0 0").unwrap();
        if let Some([r, g, b]) = m.emission {
            writeln!(out, "Ke {r:.4} {g:.4} {b:.4}").unwrap();
        }
        writeln!(out, "d 1").unwrap();
        writeln!(out, "illum 1").unwrap();
    }
    out
}
