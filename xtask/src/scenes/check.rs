//! `scenes --check`: verifies the scene files on disk without writing anything.
//!
//! The files are current, glTF and OBJ agree, lights and cameras make sense, and closed scenes
//! are closed (by casting rays from the light).

use std::path::Path;

use anyhow::{bail, ensure, Context};

use super::mesh::{cross, dot, length, normalize, sub, tri_area, SceneDesc, V3};
use super::{bundles, files, two_rooms, Enclosure, Stats};

type Tri = [[f32; 3]; 3];

/// Accepted triangle count for the chairs scene (the paper's scene has about 3,000).
const CHAIRS_TRIANGLES: std::ops::RangeInclusive<usize> = 2800..=3300;
/// Rays cast from each light.
const RAYS: usize = 4096;

pub fn run(dir: &Path) -> anyhow::Result<()> {
    let mut problems = Vec::new();
    for (rel, want) in files() {
        let path = dir.join(&rel);
        match std::fs::read_to_string(&path) {
            Ok(have) if have == want => {}
            Ok(_) => problems.push(format!("{} differs from the generator's output", path.display())),
            Err(e) => problems.push(format!("{}: {e}", path.display())),
        }
    }
    for b in bundles() {
        for (scene, enclosure) in &b.scenes {
            let base = dir.join(b.dir);
            match check_scene(&base, scene, *enclosure) {
                Ok(line) => println!("ok   {line}"),
                Err(e) => problems.push(format!("{}: {e:#}", scene.name)),
            }
        }
    }
    if !problems.is_empty() {
        for p in &problems {
            eprintln!("FAIL {p}");
        }
        bail!(
            "{} problem(s); run `cargo run -p xtask -- scenes` to regenerate",
            problems.len()
        );
    }
    println!("all scenes ok");
    Ok(())
}

/// Rotation so that the smallest vertex comes first (keeps the winding), for comparing sets.
fn canonical(t: Tri) -> [[u32; 3]; 3] {
    let b = t.map(|v| v.map(f32::to_bits));
    let k = (0..3).min_by_key(|&i| b[i]).unwrap_or(0);
    [b[k], b[(k + 1) % 3], b[(k + 2) % 3]]
}

fn area_sum(tris: &[Tri]) -> f64 {
    tris.iter().map(tri_area).sum()
}

fn f64v(v: [f32; 3]) -> V3 {
    v.map(f64::from)
}

fn check_scene(base: &Path, scene: &SceneDesc, enclosure: Enclosure) -> anyhow::Result<String> {
    let expected = Stats::of(scene);
    let gltf_path = base.join(format!("{}.gltf", scene.name));
    let obj_path = base.join(format!("{}.obj", scene.name));
    let g = load_gltf(&gltf_path, scene).with_context(|| format!("{}", gltf_path.display()))?;
    let o = load_obj(&obj_path).with_context(|| format!("{}", obj_path.display()))?;

    ensure!(
        g.tris.len() == o.tris.len(),
        "glTF has {} triangles, OBJ {}",
        g.tris.len(),
        o.tris.len()
    );
    ensure!(
        g.tris.len() == expected.triangles,
        "{} triangles, generator says {}",
        g.tris.len(),
        expected.triangles
    );
    let (ga, oa) = (area_sum(&g.tris), area_sum(&o.tris));
    ensure!((ga - oa).abs() <= 1e-5 * oa, "total area glTF {ga} vs OBJ {oa}");
    let mut gs: Vec<_> = g.tris.iter().copied().map(canonical).collect();
    let mut os: Vec<_> = o.tris.iter().copied().map(canonical).collect();
    gs.sort_unstable();
    os.sort_unstable();
    ensure!(gs == os, "glTF and OBJ triangles differ (positions or winding)");
    ensure!(
        g.parts == o.parts,
        "part names differ: glTF {:?}, OBJ {:?}",
        g.parts,
        o.parts
    );
    let want: Vec<String> = scene.parts.iter().map(|p| p.name.clone()).collect();
    ensure!(o.parts == want, "OBJ objects {:?}, expected {want:?}", o.parts);
    ensure!(
        g.albedo_by_part == o.albedo_by_part,
        "albedos differ: glTF {:?}, OBJ {:?}",
        g.albedo_by_part,
        o.albedo_by_part
    );
    if scene.name == "chairs" {
        ensure!(
            CHAIRS_TRIANGLES.contains(&g.tris.len()),
            "chairs has {} triangles, want {CHAIRS_TRIANGLES:?}",
            g.tris.len()
        );
    }

    // Camera: looks at the target, and its central ray hits a front face.
    let cam = &scene.camera;
    let want_dir = normalize(sub(cam.target, cam.eye));
    ensure!(
        dot(g.camera_forward, want_dir) > 0.9999,
        "camera looks along {:?}, want {want_dir:?}",
        g.camera_forward
    );
    ensure!(
        (g.camera_yfov_deg - cam.fov_y_deg).abs() < 1e-4,
        "yfov {} deg, want {}",
        g.camera_yfov_deg,
        cam.fov_y_deg
    );
    let eye = f64v(g.camera_eye);
    match cast(&g.tris, eye, g.camera_forward) {
        Some(hit) => ensure!(hit.front, "the camera's central ray hits the back of a surface"),
        None => bail!("the camera's central ray hits nothing"),
    }

    // Light: as specified, and the rays from it behave as the scene's enclosure demands.
    let light_check = || -> anyhow::Result<(usize, f64, String)> {
        let (light, (light_pos, light_intensity)) = match (&scene.light, g.light) {
            (Some(l), Some(found)) => (l, found),
            (None, None) => {
                return Ok((
                    g.tris.len(),
                    ga,
                    ", no point light (lit by its emissive materials)".to_string(),
                ))
            }
            (want, found) => bail!(
                "point light {found:?} in the glTF, the scene has {}",
                if want.is_some() { "one" } else { "none" }
            ),
        };
        ensure!(
            light_pos == super::mesh::to_f32(light.position),
            "light at {light_pos:?}"
        );
        ensure!(
            (0..3).all(|k| (light_intensity[k] - light.intensity[k]).abs() < 1e-5),
            "light intensity {light_intensity:?} W/sr, want {:?}",
            light.intensity
        );
        let lp = f64v(light_pos);
        let (mut escaped, mut back, mut in_b) = (0, 0, 0);
        for i in 0..RAYS {
            // Fibonacci sphere directions.
            let z = 1.0 - 2.0 * (i as f64 + 0.5) / RAYS as f64;
            let phi = i as f64 * std::f64::consts::PI * (3.0 - 5f64.sqrt());
            let r = (1.0 - z * z).sqrt();
            let d = [r * phi.cos(), z, r * phi.sin()];
            match cast(&g.tris, lp, d) {
                None => escaped += 1,
                Some(hit) => {
                    back += usize::from(!hit.front);
                    in_b += usize::from(lp[0] + hit.t * d[0] > two_rooms::WALL_X1 - 1e-9);
                }
            }
        }
        ensure!(
            back == 0,
            "{back} of {RAYS} rays from the light hit the back of a surface"
        );
        match enclosure {
            Enclosure::Open => ensure!(escaped < RAYS / 2, "{escaped} of {RAYS} rays from the light escape"),
            _ => ensure!(
                escaped == 0,
                "{escaped} of {RAYS} rays from the light escape a closed scene"
            ),
        }
        match enclosure {
            Enclosure::ClosedNoLeak => ensure!(in_b == 0, "{in_b} rays from the light reach room B"),
            Enclosure::ClosedWithDoor => ensure!(in_b > 0, "no ray from the light reaches room B"),
            _ => {}
        }
        let extra = match enclosure {
            Enclosure::Open => format!(", {escaped}/{RAYS} light rays leave by the open side"),
            Enclosure::ClosedWithDoor => format!(", {in_b}/{RAYS} light rays reach room B"),
            Enclosure::ClosedNoLeak => ", no light ray reaches room B".to_string(),
            Enclosure::Closed => ", closed".to_string(),
        };
        Ok((g.tris.len(), ga, extra))
    };
    let (tris, ga, extra) = light_check()?;
    Ok(format!(
        "{}: {tris} triangles, area {ga:.6} m² (glTF and OBJ agree){extra}",
        scene.name
    ))
}

struct Loaded {
    tris: Vec<Tri>,
    parts: Vec<String>,
    /// (part, albedo) per part in file order.
    albedo_by_part: Vec<(String, [u32; 3])>,
    camera_eye: [f32; 3],
    camera_forward: V3,
    camera_yfov_deg: f64,
    /// Position and intensity of the point light (glTF only).
    light: Option<([f32; 3], [f64; 3])>,
}

/// Albedo rounded to 1e-6 as integers, so tiny float noise cannot break equality.
fn albedo_key(c: [f32; 3]) -> [u32; 3] {
    c.map(|v| (f64::from(v) * 1e6).round() as u32)
}

fn rotate(q: [f32; 4], v: V3) -> V3 {
    let u = [f64::from(q[0]), f64::from(q[1]), f64::from(q[2])];
    let w = f64::from(q[3]);
    let t = cross(u, v).map(|c| 2.0 * c);
    let a = [v[0] + w * t[0], v[1] + w * t[1], v[2] + w * t[2]];
    let c = cross(u, t);
    [a[0] + c[0], a[1] + c[1], a[2] + c[2]]
}

fn load_gltf(path: &Path, scene: &SceneDesc) -> anyhow::Result<Loaded> {
    let (doc, buffers, _) = gltf::import(path)?;
    ensure!(
        scene.light.is_none() || doc.extensions_used().any(|e| e == "KHR_lights_punctual"),
        "KHR_lights_punctual not declared"
    );
    let emissive = scene.materials.iter().any(|m| m.emission.is_some());
    ensure!(
        !emissive || doc.extensions_used().any(|e| e == "KHR_materials_emissive_strength"),
        "KHR_materials_emissive_strength not declared"
    );
    let mut tris = Vec::new();
    let mut parts = Vec::new();
    let mut albedo_by_part = Vec::new();
    let mut camera = None;
    let mut light = None;
    let scene0 = doc.default_scene().context("no default scene")?;
    for node in scene0.nodes() {
        ensure!(
            node.children().len() == 0,
            "node {:?} has children (not expected)",
            node.name()
        );
        let (t, r, s) = node.transform().decomposed();
        if let Some(mesh) = node.mesh() {
            ensure!(
                t == [0.0; 3] && r == [0.0, 0.0, 0.0, 1.0] && s == [1.0; 3],
                "mesh node with a transform"
            );
            let name = node.name().context("unnamed mesh node")?.to_string();
            for prim in mesh.primitives() {
                ensure!(
                    prim.mode() == gltf::mesh::Mode::Triangles,
                    "primitive mode {:?}",
                    prim.mode()
                );
                let reader = prim.reader(|b| Some(&buffers[b.index()]));
                let pos: Vec<[f32; 3]> = reader.read_positions().context("no POSITION")?.collect();
                let nrm: Vec<[f32; 3]> = reader.read_normals().context("no NORMAL")?.collect();
                ensure!(
                    nrm.len() == pos.len(),
                    "NORMAL count {} vs POSITION {}",
                    nrm.len(),
                    pos.len()
                );
                let idx: Vec<u32> = reader.read_indices().context("no indices")?.into_u32().collect();
                ensure!(
                    idx.len().is_multiple_of(3),
                    "index count {} not a multiple of 3",
                    idx.len()
                );
                // POSITION min/max must be the exact bounds.
                let acc = prim.get(&gltf::Semantic::Positions).context("no POSITION")?;
                let bound = |v: Option<gltf::json::Value>| -> anyhow::Result<Vec<f32>> {
                    let v = v.context("POSITION without min/max")?;
                    let a = v.as_array().context("min/max not an array")?;
                    Ok(a.iter().map(|x| x.as_f64().unwrap_or(f64::NAN) as f32).collect())
                };
                let (mn, mx) = (bound(acc.min())?, bound(acc.max())?);
                for k in 0..3 {
                    let lo = pos.iter().map(|p| p[k]).fold(f32::INFINITY, f32::min);
                    let hi = pos.iter().map(|p| p[k]).fold(f32::NEG_INFINITY, f32::max);
                    ensure!(mn[k] == lo && mx[k] == hi, "POSITION min/max wrong on axis {k}");
                }
                for c in idx.chunks_exact(3) {
                    let t = [pos[c[0] as usize], pos[c[1] as usize], pos[c[2] as usize]];
                    let p = t.map(f64v);
                    let gn = normalize(cross(sub(p[1], p[0]), sub(p[2], p[0])));
                    for &i in c {
                        let n = f64v(nrm[i as usize]);
                        ensure!((length(n) - 1.0).abs() < 1e-5, "normal not unit length");
                        ensure!(dot(n, gn) > 0.9999, "vertex normal disagrees with the winding");
                    }
                    tris.push(t);
                }
                let bc = prim.material().pbr_metallic_roughness().base_color_factor();
                albedo_by_part.push((name.clone(), albedo_key([bc[0], bc[1], bc[2]])));
            }
            parts.push(name);
        }
        if let Some(cam) = node.camera() {
            let yfov = match cam.projection() {
                gltf::camera::Projection::Perspective(p) => f64::from(p.yfov()).to_degrees(),
                gltf::camera::Projection::Orthographic(_) => bail!("orthographic camera"),
            };
            camera = Some((t, rotate(r, [0.0, 0.0, -1.0]), yfov));
        }
        if let Some(l) = node.light() {
            ensure!(
                matches!(l.kind(), gltf::khr_lights_punctual::Kind::Point),
                "light is not a point light"
            );
            let c = l.color();
            let i = l.intensity();
            light = Some((t, [0, 1, 2].map(|k| f64::from(c[k]) * f64::from(i))));
        }
    }
    let (camera_eye, camera_forward, camera_yfov_deg) = camera.context("no camera node")?;
    ensure!(
        camera_eye == super::mesh::to_f32(scene.camera.eye),
        "camera at {camera_eye:?}, want {:?}",
        scene.camera.eye
    );
    Ok(Loaded {
        tris,
        parts,
        albedo_by_part,
        camera_eye,
        camera_forward,
        camera_yfov_deg,
        light,
    })
}

fn load_obj(path: &Path) -> anyhow::Result<Loaded> {
    let opts = tobj::LoadOptions {
        triangulate: true,
        ..Default::default()
    };
    let (models, materials) = tobj::load_obj(path, &opts)?;
    let materials = materials?;
    let mut tris = Vec::new();
    let mut parts = Vec::new();
    let mut albedo_by_part = Vec::new();
    for m in &models {
        let p = &m.mesh.positions;
        let v = |i: u32| [p[3 * i as usize], p[3 * i as usize + 1], p[3 * i as usize + 2]];
        for c in m.mesh.indices.chunks_exact(3) {
            tris.push([v(c[0]), v(c[1]), v(c[2])]);
        }
        let mat = &materials[m.mesh.material_id.context("object without a material")?];
        albedo_by_part.push((m.name.clone(), albedo_key(mat.diffuse.context("material without Kd")?)));
        parts.push(m.name.clone());
    }
    Ok(Loaded {
        tris,
        parts,
        albedo_by_part,
        camera_eye: [0.0; 3],
        camera_forward: [0.0; 3],
        camera_yfov_deg: 0.0,
        light: None,
    })
}

struct Hit {
    t: f64,
    /// The ray meets the side the triangle faces (counter-clockwise side).
    front: bool,
}

/// Nearest hit of the ray `o + t·d` (t > 1e-9) against all triangles (Möller–Trumbore, f64,
/// edges inclusive so rays cannot slip between triangles that share an edge).
fn cast(tris: &[Tri], o: V3, d: V3) -> Option<Hit> {
    let mut best: Option<Hit> = None;
    for t in tris {
        let p = t.map(f64v);
        let e1 = sub(p[1], p[0]);
        let e2 = sub(p[2], p[0]);
        let pv = cross(d, e2);
        let det = dot(e1, pv);
        if det.abs() < 1e-18 {
            continue;
        }
        let inv = 1.0 / det;
        let tv = sub(o, p[0]);
        let u = dot(tv, pv) * inv;
        const EPS: f64 = 1e-9;
        if !(-EPS..=1.0 + EPS).contains(&u) {
            continue;
        }
        let qv = cross(tv, e1);
        let v = dot(d, qv) * inv;
        if v < -EPS || u + v > 1.0 + EPS {
            continue;
        }
        let dist = dot(e2, qv) * inv;
        if dist > 1e-9 && best.as_ref().is_none_or(|b| dist < b.t) {
            best = Some(Hit {
                t: dist,
                front: dot(cross(e1, e2), d) < 0.0,
            });
        }
    }
    best
}
