//! Integration tests of scene loading and atlas building on our scenes, third-party scenes and bad input.
//!
//! Long on purpose: one test per scene and per malformed input, each spelled out.

mod common;
use common::{temp_case, TempDir};
use glam::Vec3;
use prm_scene::{Atlas, AtlasParams, Scene, SceneError, Sizing, EMPTY_TEXEL};
use std::path::{Path, PathBuf};

fn repo(rel: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..").join(rel)
}

fn load(rel: &str) -> Scene {
    prm_scene::load(&repo(rel)).unwrap_or_else(|e| panic!("{rel}: {e}"))
}

/// A scratch directory under the target dir, emptied first.
fn scratch(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join(name);
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

#[test]
fn cornell_box_obj_and_gltf_agree() {
    let obj = load("scenes/cornell-box/cornell-box.obj");
    let gltf = load("scenes/cornell-box/cornell-box.gltf");
    assert_eq!(obj.triangles.len(), gltf.triangles.len());
    let (a, b) = (obj.area(), gltf.area());
    assert!((a - b).abs() <= 1e-5 * a, "areas {a} vs {b}");
    assert!((obj.bounds().min - gltf.bounds().min).abs().max_element() < 1e-5);
    assert!((obj.bounds().max - gltf.bounds().max).abs().max_element() < 1e-5);
    assert_eq!(obj.fingerprint(), gltf.fingerprint(), "same geometry in the same order");
    // The glTF brings a point light under the ceiling and a camera; the OBJ has neither.
    assert_eq!(gltf.lights.len(), 1);
    assert_eq!(gltf.cameras.len(), 1);
    match gltf.lights[0] {
        prm_scene::Light::Point { position, intensity } => {
            let b = gltf.bounds();
            assert!(position.y < b.max.y && position.y > 0.5 * (b.min.y + b.max.y));
            assert!(intensity.min_element() > 0.0);
        }
        other => panic!("expected a point light, got {other:?}"),
    }
    // Albedos: the white walls are about 0.74, the red wall reddest in R.
    assert!(obj
        .materials
        .iter()
        .any(|m| (m.albedo.x - 0.74).abs() < 0.02 && (m.albedo.y - 0.74).abs() < 0.02));
    assert!(obj.materials.iter().any(|m| m.albedo.x > 5.0 * m.albedo.y));
}

/// The invariants every generated atlas keeps.
fn check_atlas(scene: &Scene, atlas: &Atlas, gutter: u32) {
    let r = atlas.resolution as usize;
    let s = &atlas.stats;
    assert_eq!(s.shared_texels, 0, "no texel is touched by two charts");
    assert_eq!(s.uncovered_triangles, 0, "every triangle touches a covered texel");
    // Charts stay apart: between covered texels of different charts lie at least 2·gutter texels.
    let chart_at = |i: usize| atlas.chart_of_triangle[atlas.exits[atlas.texel_exit[i] as usize].triangle as usize];
    let reach = 2 * gutter as i64;
    for y in 0..r as i64 {
        for x in 0..r as i64 {
            let i = (y as usize) * r + x as usize;
            if atlas.texel_exit[i] == EMPTY_TEXEL {
                continue;
            }
            for dy in -reach..=reach {
                for dx in -reach..=reach {
                    let (nx, ny) = (x + dx, y + dy);
                    if nx < 0 || ny < 0 || nx >= r as i64 || ny >= r as i64 {
                        continue;
                    }
                    let j = ny as usize * r + nx as usize;
                    if atlas.texel_exit[j] != EMPTY_TEXEL {
                        assert_eq!(chart_at(i), chart_at(j), "charts closer than the gutter at ({x},{y})");
                    }
                }
            }
        }
    }
    // Every empty texel next to a covered one is dilated (no black in bilinear taps).
    let dilated: std::collections::HashSet<u32> = atlas.dilation.iter().map(|d| d.0).collect();
    for y in 0..r {
        for x in 0..r {
            let i = y * r + x;
            if atlas.texel_exit[i] != EMPTY_TEXEL {
                continue;
            }
            let next_to_cover = (x.saturating_sub(1)..=(x + 1).min(r - 1)).any(|nx| {
                (y.saturating_sub(1)..=(y + 1).min(r - 1)).any(|ny| atlas.texel_exit[ny * r + nx] != EMPTY_TEXEL)
            });
            if next_to_cover {
                assert!(dilated.contains(&(i as u32)), "gutter texel ({x},{y}) not dilated");
            }
        }
    }
    for &(dst, src) in &atlas.dilation {
        assert_eq!(atlas.texel_exit[dst as usize], EMPTY_TEXEL);
        assert_ne!(atlas.texel_exit[src as usize], EMPTY_TEXEL);
    }
    // Exit points lie on their triangles and face like them.
    for e in &atlas.exits {
        let t = &scene.triangles[e.triangle as usize];
        let n = t.normal();
        let d = (e.position - t.positions[0]).dot(n).abs();
        assert!(
            d < 1e-4 * scene.bounds().diagonal().max(1.0),
            "exit point off its plane by {d}"
        );
        assert!(e.normal.dot(n) > 0.0);
        assert!(e.coverage > 0.0 && e.coverage <= 1.0);
    }
    // Lightmap UVs are inside the atlas.
    for uv in atlas.uvs.iter().flatten() {
        assert!(
            (0.0..=1.0).contains(&uv.x) && (0.0..=1.0).contains(&uv.y),
            "uv {uv} outside [0,1]"
        );
    }
}

#[test]
fn atlas_invariants_on_our_scenes() {
    for (rel, res) in [
        ("scenes/cornell-box/cornell-box.obj", 128),
        ("scenes/chairs/chairs.obj", 512),
        ("scenes/two-rooms/two-rooms.obj", 128),
    ] {
        let scene = load(rel);
        for gutter in [1, 2] {
            let params = AtlasParams {
                sizing: Sizing::Resolution(res),
                gutter,
                ..AtlasParams::DEFAULT
            };
            let atlas = Atlas::build(&scene, &params).unwrap();
            assert_eq!(atlas.resolution, res);
            check_atlas(&scene, &atlas, gutter);
            assert_eq!(
                atlas.stats.triangles_without_exit, 0,
                "{rel} gutter {gutter}: every triangle owns a texel"
            );
        }
    }
}

#[test]
fn texel_size_sets_resolution() {
    let scene = load("scenes/cornell-box/cornell-box.obj");
    let coarse = Atlas::build(&scene, &AtlasParams::with_sizing(Sizing::TexelSize(0.02))).unwrap();
    let fine = Atlas::build(&scene, &AtlasParams::with_sizing(Sizing::TexelSize(0.01))).unwrap();
    assert!((coarse.texel_size() - 0.02).abs() < 1e-6);
    // Half the texel size, twice the resolution (within packing slack).
    let ratio = fine.resolution as f32 / coarse.resolution as f32;
    assert!((1.7..2.3).contains(&ratio), "ratio {ratio}");
    // Covered area ≈ scene area: texels × texel area (coverage-weighted) matches within 15%.
    let covered: f64 = fine.exits.iter().map(|e| e.coverage as f64).sum::<f64>() * 0.01f64.powi(2);
    assert!(
        (covered / scene.area() - 1.0).abs() < 0.15,
        "covered {covered} vs area {}",
        scene.area()
    );
    check_atlas(&scene, &fine, 1);
}

#[test]
fn third_party_scenes_load_and_pack() {
    let shared = repo("../shared/scenes");
    if !shared.exists() {
        // CI lays the evaluation scenes beside the clone: a skip there is a failure.
        assert!(std::env::var_os("CI").is_none(), "{} is absent in CI", shared.display());
        eprintln!("skipped: {} is absent", shared.display());
        return;
    }
    // McGuire's Cornell box uses negative (relative) indices; its extent is 2.02 x 1.99 x 2.03.
    let cb = prm_scene::load(&shared.join("cornell-box/CornellBox-Original.obj")).unwrap();
    let e = cb.bounds().extent();
    assert!(
        (e - Vec3::new(2.02, 1.99, 2.03)).abs().max_element() < 1e-3,
        "extent {e}"
    );
    let atlas = Atlas::build(&cb, &AtlasParams::with_sizing(Sizing::Resolution(128))).unwrap();
    check_atlas(&cb, &atlas, 1);
    let holodeck = prm_scene::load(&shared.join("holodeck/holodeck.obj")).unwrap();
    assert!(!holodeck.textures.is_empty(), "map_Kd wall.png is loaded");
    let atlas = Atlas::build(&holodeck, &AtlasParams::DEFAULT).unwrap();
    check_atlas(&holodeck, &atlas, 1);
}

/// Asserts that some load warning of `scene` contains every one of `parts`.
fn assert_warned(scene: &Scene, parts: &[&str]) {
    let warnings = &scene.report.warnings;
    assert!(
        warnings.iter().any(|w| parts.iter().all(|p| w.contains(p))),
        "no warning with {parts:?} in {warnings:?}"
    );
}

/// Loads `text`, written as file `name` in a fresh directory for `case` (returned, so that it
/// outlives the load).
fn load_text(case: &str, name: &str, text: &str) -> (TempDir, Result<Scene, SceneError>) {
    let dir = temp_case(case);
    let loaded = prm_scene::load(&write(&dir, name, text));
    (dir, loaded)
}

fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p
}

#[test]
fn obj_features_negative_indices_groups_and_missing_files() {
    let (dir, loaded) = load_text(
        "obj-features",
        "quads.obj",
        "mtllib missing.mtl\no first\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf -4 -3 -2 -1\n\
         g second\nv 0 0 1\nv 1 0 1\nv 1 1 1\nf 5 6 7\n",
    );
    let scene = loaded.unwrap();
    assert_eq!(scene.triangles.len(), 3, "a quad triangulated plus a triangle");
    assert!((scene.area() - 1.5).abs() < 1e-6);
    assert_warned(&scene, &["material library"]);
    assert!(scene
        .triangles
        .iter()
        .all(|t| scene.materials[t.material as usize].albedo == Vec3::splat(0.5)));

    write(
        &dir,
        "tex.mtl",
        "newmtl red\nKd 0.8 0.1 0.1\nnewmtl textured\nKd 1 1 1\nmap_Kd nowhere.png\n",
    );
    let obj = write(
        &dir,
        "tex.obj",
        "mtllib tex.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\nusemtl red\nf 1/1 2/2 3/3\nusemtl textured\nf 1/1 3/3 2/2\n",
    );
    let scene = prm_scene::load(&obj).unwrap();
    assert_eq!(
        scene.materials[scene.triangles[0].material as usize].albedo,
        Vec3::new(0.8, 0.1, 0.1)
    );
    assert_warned(&scene, &["nowhere.png"]);

    // A texture that exists: a 2x2 PNG written here; the albedo is sampled from it.
    let img = image::RgbImage::from_fn(2, 2, |_, _| image::Rgb([255, 255, 255]));
    img.save(dir.join("white.png")).unwrap();
    write(&dir, "ok.mtl", "newmtl w\nKd 0.2 0.2 0.2\nmap_Kd white.png\n");
    let obj = write(
        &dir,
        "ok.obj",
        "mtllib ok.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\nusemtl w\nf 1/1 2/2 3/3\n",
    );
    let scene = prm_scene::load(&obj).unwrap();
    assert_eq!(scene.textures.len(), 1);
    assert!((scene.albedo(0, 0.3, 0.3) - Vec3::ONE).abs().max_element() < 1e-5);
}

/// Degenerate triangles, and a triangle listed again, are dropped, counted and warned of.
/// McGuire's boxes list a face twice ("f -12 -11 -10 -9" after four new vertices); the same
/// corners in the other winding are a two-sided wall, not a copy, and stay.
#[test]
fn degenerate_and_duplicate_triangles_are_dropped_and_counted() {
    let cases = [
        (
            "degenerate",
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 2 0 0\nf 1 2 3\nf 1 2 4\nf 1 1 3\n",
            1,
            (2, 0),
            "2 degenerate",
        ),
        (
            "duplicates",
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nf 1 2 3\nf 2 3 1\nf 1 3 2\nf 2 4 3\nf 1 2 3\n",
            3,
            (0, 2),
            "2 duplicate triangles dropped",
        ),
    ];
    for (case, text, kept, dropped, warning) in cases {
        let (_dir, loaded) = load_text(case, "d.obj", text);
        let scene = loaded.unwrap();
        assert_eq!(scene.triangles.len(), kept, "{case}");
        let report = &scene.report;
        assert_eq!(
            (report.degenerate_dropped, report.duplicates_dropped),
            dropped,
            "{case}"
        );
        assert_warned(&scene, &[warning]);
        if case == "duplicates" {
            assert!(scene.triangles[1].normal().z < 0.0 && scene.triangles[2].normal().z > 0.0);
        }
    }
}

#[test]
fn bad_input_gives_clear_errors() {
    let dir = scratch("bad-input");
    let err = |p: &Path| prm_scene::load(p).expect_err("must fail");

    let missing = dir.join("nope.obj");
    let e = err(&missing);
    assert!(
        matches!(e, SceneError::NotFound(_)) && e.to_string().contains("nope.obj"),
        "{e}"
    );

    let e = err(&write(&dir, "scene.fbx", "whatever"));
    assert!(matches!(e, SceneError::UnsupportedFormat(_)), "{e}");

    // A directory, and `-` (standard input), are named as what they are.
    let folder = dir.join("level.obj");
    std::fs::create_dir_all(&folder).unwrap();
    let e = err(&folder);
    assert!(
        matches!(e, SceneError::IsDirectory(_)) && e.to_string().contains("is a directory"),
        "{e}"
    );
    let e = err(Path::new("-"));
    assert!(
        matches!(e, SceneError::Stdin) && e.to_string().contains("standard input"),
        "{e}"
    );

    let e = err(&write(&dir, "bad.obj", "v 0 0 0\nv 1 0 0\nv 0 1 oops\nf 1 2 3\n"));
    assert!(e.to_string().contains("bad.obj:3"), "names file and line: {e}");

    let e = err(&write(&dir, "range.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n"));
    assert!(e.to_string().contains("range.obj:4"), "{e}");

    let e = err(&write(&dir, "nan.obj", "v 0 0 0\nv 1 0 0\nv 0 nan 0\nf 1 2 3\n"));
    assert!(
        e.to_string().contains("nan.obj") && e.to_string().contains("non-finite"),
        "{e}"
    );

    let e = err(&write(&dir, "empty.obj", "# nothing\nv 0 0 0\n"));
    assert!(matches!(e, SceneError::NoTriangles { .. }), "{e}");

    let e = err(&write(&dir, "flat.obj", "v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n"));
    assert!(matches!(e, SceneError::NoTriangles { dropped: 1, .. }), "{e}");

    let e = err(&write(
        &dir,
        "bad.gltf",
        "{ \"asset\": { \"version\": \"2.0\" }, \"meshes\": [ oops",
    ));
    assert!(
        matches!(e, SceneError::Malformed { .. }) && e.to_string().contains("bad.gltf"),
        "{e}"
    );

    let e = err(&write(&dir, "bad.glb", "glTF but not really"));
    assert!(e.to_string().contains("bad.glb"), "{e}");

    let e = err(&write(&dir, "nomesh.gltf", "{ \"asset\": { \"version\": \"2.0\" } }"));
    assert!(matches!(e, SceneError::NoTriangles { .. }), "{e}");
}

/// A minimal glTF: one triangle in a buffer, instanced by two nodes (translated, and mirrored),
/// with TEXCOORD_1, a spot light and a camera.
fn tiny_gltf(dir: &Path) -> PathBuf {
    let mut bin = Vec::new();
    for v in [0.0f32, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0] {
        bin.extend_from_slice(&v.to_le_bytes());
    }
    for v in [0.1f32, 0.1, 0.4, 0.1, 0.1, 0.4] {
        bin.extend_from_slice(&v.to_le_bytes());
    }
    std::fs::write(dir.join("tiny.bin"), &bin).unwrap();
    let json = r#"{
      "asset": {"version": "2.0"},
      "extensionsUsed": ["KHR_lights_punctual"],
      "extensions": {"KHR_lights_punctual": {"lights": [
        {"type": "spot", "color": [1, 0.5, 0.25], "intensity": 4, "spot": {"outerConeAngle": 0.5}}]}},
      "buffers": [{"uri": "tiny.bin", "byteLength": 60}],
      "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": 36}, {"buffer": 0, "byteOffset": 36, "byteLength": 24}],
      "accessors": [
        {"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3", "min": [0,0,0], "max": [1,1,0]},
        {"bufferView": 1, "componentType": 5126, "count": 3, "type": "VEC2"}],
      "materials": [{"pbrMetallicRoughness": {"baseColorFactor": [0.2, 0.4, 0.6, 1]}}],
      "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "TEXCOORD_1": 1}, "material": 0}]}],
      "cameras": [{"type": "perspective", "perspective": {"yfov": 0.8, "znear": 0.01}}],
      "nodes": [
        {"mesh": 0, "translation": [0, 0, 5]},
        {"mesh": 0, "scale": [-2, 2, 2]},
        {"camera": 0, "translation": [0, 0, 10]},
        {"extensions": {"KHR_lights_punctual": {"light": 0}}, "translation": [0, 3, 0]}],
      "scenes": [{"nodes": [0, 1, 2, 3]}],
      "scene": 0
    }"#;
    write(dir, "tiny.gltf", json)
}

/// An extension the file uses and the loader does not read is named in a warning: the scene
/// loads, but not as the file means it.
#[test]
fn gltf_extensions_the_loader_ignores_are_warned_of() {
    let dir = scratch("ignored-extensions");
    let plain = tiny_gltf(&dir);
    let scene = prm_scene::load(&plain).unwrap();
    assert!(
        !scene.report.warnings.iter().any(|w| w.contains("extension")),
        "{:?}",
        scene.report.warnings
    );
    let text = std::fs::read_to_string(&plain).unwrap().replace(
        r#"["KHR_lights_punctual"]"#,
        r#"["KHR_lights_punctual", "KHR_texture_transform"]"#,
    );
    let transformed = write(&dir, "transformed.gltf", &text);
    let scene = prm_scene::load(&transformed).unwrap();
    let warned: Vec<&String> = scene
        .report
        .warnings
        .iter()
        .filter(|w| w.contains("extension"))
        .collect();
    assert_eq!(warned.len(), 1, "{:?}", scene.report.warnings);
    assert!(
        warned[0].contains("KHR_texture_transform") && warned[0].contains("untransformed"),
        "{}",
        warned[0]
    );
}

/// Values no surface, light or camera can have are refused at load, with a warning naming them,
/// instead of failing the bake after its panes or playing a black frame.
#[test]
fn impossible_materials_lights_and_cameras_are_refused_at_load() {
    let dir = scratch("sanitize");
    write(
        &dir,
        "m.mtl",
        "newmtl neg\nKd -1 0.5 0.5\nnewmtl nan\nKd nan 0.5 2\nnewmtl hot\nKd 0.5 0.5 0.5\nKe -1 0 0\n",
    );
    let tri = |m: &str, z: f32| format!("usemtl {m}\nv 0 0 {z}\nv 1 0 {z}\nv 0 1 {z}\nf -3 -2 -1\n");
    let obj = write(
        &dir,
        "m.obj",
        &format!(
            "mtllib m.mtl\n{}{}{}",
            tri("neg", 0.0),
            tri("nan", 1.0),
            tri("hot", 2.0)
        ),
    );
    let scene = prm_scene::load(&obj).unwrap();
    let albedo = |name: &str| scene.materials.iter().find(|m| m.name == name).unwrap().albedo;
    assert_eq!(albedo("neg"), Vec3::new(0.0, 0.5, 0.5));
    assert_eq!(albedo("nan"), Vec3::new(0.0, 0.5, 1.0));
    assert!(scene.materials.iter().all(|m| m.emission == Vec3::ZERO));
    let warned = |what: &str| scene.report.warnings.iter().any(|w| w.contains(what));
    assert!(
        warned("'neg' has albedo") && warned("'nan' has albedo") && warned("'hot' has emission"),
        "{:?}",
        scene.report.warnings
    );

    // Beyond ±MAX_COORDINATE: an error, not triangles dropped as degenerate.
    let far = write(
        &dir,
        "far.obj",
        "v 0 0 0\nv 1e18 0 0\nv 0 1e18 0\nf 1 2 3\nv 0 0 1\nv 1 0 1\nv 0 1 1\nf 4 5 6\n",
    );
    let err = prm_scene::load(&far).unwrap_err().to_string();
    assert!(err.contains("1 triangles have a corner beyond ±1e9"), "{err}");

    // A spot light of negative intensity and a camera of no field of view are left out.
    let good = tiny_gltf(&dir);
    let text = std::fs::read_to_string(&good).unwrap();
    let bad = text
        .replace("\"intensity\": 4", "\"intensity\": -4")
        .replace("\"yfov\": 0.8", "\"yfov\": 0");
    assert_ne!(bad, text);
    let scene = prm_scene::load(&write(&dir, "bad.gltf", &bad)).unwrap();
    assert!(scene.lights.is_empty() && scene.cameras.is_empty());
    let warned = |what: &str| scene.report.warnings.iter().any(|w| w.contains(what));
    assert!(
        warned("the spot light at [0, 3, 0] is left out") && warned("field of view 0°"),
        "{:?}",
        scene.report.warnings
    );
}

#[test]
fn gltf_transforms_lights_cameras_and_lightmap_uvs() {
    let dir = scratch("gltf-tiny");
    let scene = prm_scene::load(&tiny_gltf(&dir)).unwrap();
    assert_eq!(scene.triangles.len(), 2);
    let t0 = &scene.triangles[0];
    assert_eq!(t0.positions[1], Vec3::new(1.0, 0.0, 5.0), "translation applied");
    let t1 = &scene.triangles[1];
    assert!((t1.area() - 2.0).abs() < 1e-6, "scale 2 quadruples the area");
    assert!(
        t1.normal().z > 0.0,
        "mirroring keeps the face pointing +Z (winding swapped)"
    );
    assert_eq!(scene.materials[t0.material as usize].albedo, Vec3::new(0.2, 0.4, 0.6));
    let luv = scene.lightmap_uvs.as_ref().expect("TEXCOORD_1 becomes lightmap UVs");
    assert_eq!(luv.len(), 2);
    match scene.lights[0] {
        prm_scene::Light::Spot {
            position,
            direction,
            angle,
            intensity,
        } => {
            assert_eq!(position, Vec3::new(0.0, 3.0, 0.0));
            assert_eq!(direction, Vec3::NEG_Z);
            assert!((angle - 0.5).abs() < 1e-6);
            assert_eq!(intensity, Vec3::new(4.0, 2.0, 1.0));
        }
        other => panic!("expected a spot light, got {other:?}"),
    }
    assert_eq!(scene.cameras[0].eye, Vec3::new(0.0, 0.0, 10.0));
    assert!((scene.cameras[0].fov_y_deg - 0.8f32.to_degrees()).abs() < 1e-4);
    // The file's lightmap UVs are used as they are.
    let atlas = Atlas::build(&scene, &AtlasParams::with_sizing(Sizing::Resolution(32))).unwrap();
    assert!((atlas.uvs[0][1] - glam::Vec2::new(0.4, 0.1)).length() < 1e-6);
    assert!(atlas.exits.len() > 10);

    // The same file as a binary .glb (JSON chunk only; the buffer stays external).
    let text = std::fs::read_to_string(dir.join("tiny.gltf")).unwrap();
    let mut json = text.into_bytes();
    while !json.len().is_multiple_of(4) {
        json.push(b' ');
    }
    let mut glb = Vec::new();
    glb.extend_from_slice(b"glTF");
    glb.extend_from_slice(&2u32.to_le_bytes());
    glb.extend_from_slice(&(12 + 8 + json.len() as u32).to_le_bytes());
    glb.extend_from_slice(&(json.len() as u32).to_le_bytes());
    glb.extend_from_slice(b"JSON");
    glb.extend_from_slice(&json);
    std::fs::write(dir.join("tiny.glb"), glb).unwrap();
    let from_glb = prm_scene::load(&dir.join("tiny.glb")).unwrap();
    assert_eq!(from_glb.fingerprint(), scene.fingerprint());
}

#[test]
fn fingerprint_tracks_geometry_only() {
    let a = load("scenes/cornell-box/cornell-box.obj");
    let mut b = a.clone();
    b.materials[0].albedo = Vec3::ONE;
    assert_eq!(a.fingerprint(), b.fingerprint());
    b.triangles[3].positions[0].x += 1e-4;
    assert_ne!(a.fingerprint(), b.fingerprint());
}

// ---- Hostile input: bad scene files. ----

/// Little-endian bytes of floats and u32s.
fn le_f32(v: &[f32]) -> Vec<u8> {
    v.iter().flat_map(|x| x.to_le_bytes()).collect()
}

/// A glTF of one mesh: POSITION accessor 0 (3 vertices in bufferView 0), index accessor 1
/// (`index_count` u32 indices in bufferView 1). The buffer `buffer.bin` holds `bin`.
fn indexed_gltf(dir: &Path, bin: &[u8], buffer_len: usize, views: [(usize, usize); 2], counts: [u64; 2]) -> PathBuf {
    std::fs::write(dir.join("buffer.bin"), bin).unwrap();
    let json = format!(
        r#"{{
      "asset": {{"version": "2.0"}},
      "buffers": [{{"uri": "buffer.bin", "byteLength": {buffer_len}}}],
      "bufferViews": [{{"buffer": 0, "byteOffset": {}, "byteLength": {}}}, {{"buffer": 0, "byteOffset": {}, "byteLength": {}}}],
      "accessors": [
        {{"bufferView": 0, "componentType": 5126, "count": {}, "type": "VEC3", "min": [0,0,0], "max": [1,1,0]}},
        {{"bufferView": 1, "componentType": 5125, "count": {}, "type": "SCALAR"}}],
      "meshes": [{{"primitives": [{{"attributes": {{"POSITION": 0}}, "indices": 1}}]}}],
      "nodes": [{{"mesh": 0}}],
      "scenes": [{{"nodes": [0]}}],
      "scene": 0
    }}"#,
        views[0].0, views[0].1, views[1].0, views[1].1, counts[0], counts[1]
    );
    write(dir, "scene.gltf", &json)
}

/// 3 vertices and 30 triangles' worth of indices (all the same triangle, shifted corners).
fn thirty_triangles() -> Vec<u8> {
    let mut bin = le_f32(&[0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0]);
    for _ in 0..30 {
        for i in [0u32, 1, 2] {
            bin.extend_from_slice(&i.to_le_bytes());
        }
    }
    bin
}

/// [`thirty_triangles`] as an indexed glTF in a fresh directory for `case`: its buffer file
/// holds the first `stored` bytes and declares `declared`, its accessors have `counts`.
fn thirty_triangles_gltf(case: &str, stored: usize, declared: usize, counts: [u64; 2]) -> (TempDir, PathBuf) {
    let dir = temp_case(case);
    let bin = thirty_triangles();
    let p = indexed_gltf(&dir, &bin[..stored], declared, [(0, 36), (36, 360)], counts);
    (dir, p)
}

#[test]
fn gltf_valid_indexed_mesh_loads() {
    let (_dir, p) = thirty_triangles_gltf("gltf-indexed-ok", 396, 396, [3, 90]);
    let scene = prm_scene::load(&p).unwrap();
    // All 30 read; they are one triangle thirty times, so 29 are dropped as its copies.
    assert_eq!((scene.triangles.len(), scene.report.duplicates_dropped), (1, 29));
}

#[test]
fn gltf_buffer_shorter_than_its_views_is_an_error() {
    // The buffer really holds (and declares) half of what the index view needs.
    let (_dir, p) = thirty_triangles_gltf("gltf-short-buffer", 36 + 180, 36 + 180, [3, 90]);
    let e = prm_scene::load(&p).expect_err("a truncated buffer must not bake half the mesh");
    assert!(
        matches!(
            e,
            SceneError::BufferView {
                view: 1,
                buffer: 0,
                needed: 396,
                actual: 216,
                ..
            }
        ),
        "{e}"
    );
    let s = e.to_string();
    assert!(
        s.contains("bufferView 1") && s.contains("396") && s.contains("216"),
        "{s}"
    );
}

#[test]
fn gltf_accessor_count_overrunning_its_view_is_an_error() {
    let (_dir, p) = thirty_triangles_gltf("gltf-huge-count", 396, 396, [1_000_000, 90]);
    let e = prm_scene::load(&p).expect_err("count 1e6 over a 36-byte view");
    assert!(matches!(e, SceneError::Accessor { accessor: 0, .. }), "{e}");
    assert!(e.to_string().contains("accessor 0"), "{e}");
    assert!(!e.to_string().contains("without positions"), "{e}");
}

#[test]
fn gltf_index_accessor_with_count_4e9_is_an_error() {
    let (_dir, p) = thirty_triangles_gltf("gltf-4e9-indices", 396, 396, [3, 4_000_000_000]);
    let e = prm_scene::load(&p).expect_err("4e9 indices in a 360-byte view");
    assert!(matches!(e, SceneError::Accessor { accessor: 1, .. }), "{e}");
    assert!(e.to_string().contains("accessor 1"), "{e}");
}

#[test]
fn gltf_missing_bin_is_named() {
    let (dir, p) = thirty_triangles_gltf("gltf-missing-bin", 396, 396, [3, 90]);
    std::fs::remove_file(dir.join("buffer.bin")).unwrap();
    let e = prm_scene::load(&p).expect_err("missing buffer file");
    match &e {
        SceneError::BufferFile {
            path, scene, buffer, ..
        } => {
            assert_eq!(path, &dir.join("buffer.bin"));
            assert_eq!(scene, &p);
            assert_eq!(*buffer, 0);
        }
        other => panic!("expected BufferFile, got {other}"),
    }
    assert!(
        e.to_string().starts_with(&dir.join("buffer.bin").display().to_string()),
        "{e}"
    );
}

#[test]
fn gltf_buffer_shorter_than_declared_is_an_error() {
    let (_dir, p) = thirty_triangles_gltf("gltf-declared-length", 100, 396, [3, 90]);
    let e = prm_scene::load(&p).expect_err("buffer shorter than its byteLength");
    assert!(
        matches!(
            e,
            SceneError::BufferLength {
                buffer: 0,
                declared: 396,
                actual: 100,
                ..
            }
        ),
        "{e}"
    );
    assert!(e.to_string().contains("buffer.bin"), "{e}");
}

/// The error of loading `text` as an OBJ; it must be `Malformed` at `line`.
fn obj_error_at(name: &str, text: &[u8], line: usize) -> String {
    let dir = temp_case(name);
    let p = dir.join(format!("{name}.obj"));
    std::fs::write(&p, text).unwrap();
    let e = prm_scene::load(&p).expect_err("must fail");
    assert!(
        matches!(e, SceneError::Malformed { line: Some(l), .. } if l == line),
        "expected {name}.obj:{line}, got {e}"
    );
    let s = e.to_string();
    assert!(s.contains(&format!("{name}.obj:{line}")), "{s}");
    s
}

const TRIANGLE: &str = "v 0 0 0\nv 1 0 0\nv 0 1 0\n";

/// Malformed OBJ lines are errors naming the file and the line, and what is wrong where the
/// case gives it.
#[test]
fn obj_malformed_lines_are_errors_with_their_line() {
    let cases: [(&str, Vec<u8>, usize, Option<&str>); 6] = [
        (
            "two-vertex-face",
            format!("{TRIANGLE}f 1 2 3\nf 1 2\n").into(),
            5,
            Some("3 vertices"),
        ),
        ("one-vertex-face", format!("{TRIANGLE}f 1\nf 1 2 3\n").into(), 4, None),
        ("no-vt", format!("{TRIANGLE}f 1/2 2 3\n").into(), 4, Some("no 'vt'")),
        (
            "vt-range",
            format!("{TRIANGLE}vt 0 0\nvt 1 0\nf 1/1 2/2 3/3\n").into(),
            6,
            None,
        ),
        (
            "vn-range",
            format!("{TRIANGLE}vn 0 0 1\nf 1//1 2//2 3//1\n").into(),
            5,
            None,
        ),
        (
            "non-utf8-vertex",
            b"v 0 0 0\nv 1 \xff 0\nv 0 1 0\nf 1 2 3\n".to_vec(),
            2,
            Some("non-UTF-8"),
        ),
    ];
    for (name, text, line, what) in cases {
        let s = obj_error_at(name, &text, line);
        if let Some(what) = what {
            assert!(s.contains(what), "{name}: {s}");
        }
    }
}

#[test]
fn obj_non_utf8_in_comment_is_tolerated() {
    let dir = temp_case("non-utf8-comment");
    let p = dir.join("c.obj");
    let mut text = b"# caf\xe9 \xff\n".to_vec();
    text.extend_from_slice(TRIANGLE.as_bytes());
    text.extend_from_slice(b"f 1 2 3 # end \xfe\n");
    std::fs::write(&p, text).unwrap();
    let scene = prm_scene::load(&p).unwrap();
    assert_eq!(scene.triangles.len(), 1);
    assert!(scene.report.warnings.is_empty(), "{:?}", scene.report.warnings);
}

#[test]
fn obj_non_utf8_in_a_name_is_a_warning_with_its_line() {
    let dir = temp_case("non-utf8-name");
    let p = dir.join("n.obj");
    let mut text = b"o chaise-\xe9\n".to_vec();
    text.extend_from_slice(format!("{TRIANGLE}f 1 2 3\n").as_bytes());
    std::fs::write(&p, text).unwrap();
    let scene = prm_scene::load(&p).unwrap();
    assert_eq!(scene.triangles.len(), 1);
    assert_warned(&scene, &["n.obj:1", "non-UTF-8"]);
}

#[test]
fn obj_trailing_comments_and_vertex_colours_load() {
    let (_dir, loaded) = load_text(
        "obj-comments-colours",
        "c.obj",
        "v 0 0 0 1 0 0 # red\nv 1 0 0\nv 0 1 0 0 0 1\nl 1 2 3\nf 1 2 3 # one\n",
    );
    let scene = loaded.unwrap();
    assert_eq!(scene.triangles.len(), 1, "the polyline is not a triangle");
}

#[test]
fn materials_fingerprint_tracks_albedo_not_geometry() {
    let dir = temp_case("materials-fingerprint");
    let obj = "mtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl a\nf 1 2 3\n";
    write(&dir, "m.mtl", "newmtl a\nKd 0.5 0.5 0.5\n");
    let p = write(&dir, "s.obj", obj);
    let grey = prm_scene::load(&p).unwrap();
    write(&dir, "m.mtl", "newmtl a\nKd 0.8 0.1 0.1\n");
    let red = prm_scene::load(&p).unwrap();
    assert_eq!(grey.fingerprint(), red.fingerprint(), "geometry unchanged");
    assert_ne!(
        grey.materials_fingerprint(),
        red.materials_fingerprint(),
        "albedo changed"
    );
    // Deterministic, and blind to names.
    let again = prm_scene::load(&p).unwrap();
    assert_eq!(red.materials_fingerprint(), again.materials_fingerprint());
    let mut renamed = red.clone();
    renamed.materials[0].name = "other".into();
    assert_eq!(red.materials_fingerprint(), renamed.materials_fingerprint());
    // A texture's content enters it.
    let mut textured = red.clone();
    textured.textures.push(prm_scene::Texture {
        width: 1,
        height: 1,
        texels: vec![[255, 0, 0]],
    });
    textured.materials[0].texture = Some(0);
    let fp = textured.materials_fingerprint();
    assert_ne!(fp, red.materials_fingerprint());
    textured.textures[0].texels[0] = [0, 255, 0];
    assert_ne!(fp, textured.materials_fingerprint());
    assert_eq!(textured.fingerprint(), red.fingerprint());
}

#[test]
fn mtl_colour_with_two_numbers_is_a_warning_not_a_panic() {
    // Found by the fuzzer: tobj panics on `Kd` with two numbers.
    let dir = temp_case("mtl-two-numbers");
    write(&dir, "m.mtl", "newmtl a\nKd 0.8 0.1\nnewmtl b\nKd 0.3\n");
    let p = write(
        &dir,
        "s.obj",
        "mtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl a\nf 1 2 3\nusemtl b\nf 1 3 2\n",
    );
    let scene = prm_scene::load(&p).unwrap();
    assert_warned(&scene, &["m.mtl:2", "Kd"]);
    let b = &scene.materials[scene.triangles[1].material as usize];
    assert_eq!(b.albedo, Vec3::splat(0.3), "one number means grey");
}

#[test]
fn gltf_position_accessor_out_of_range_is_an_error_not_a_panic() {
    // Found by the fuzzer: gltf's validation indexes the POSITION accessor unchecked.
    let (_dir, loaded) = load_text(
        "gltf-position-index",
        "s.gltf",
        r#"{"asset": {"version": "2.0"}, "meshes": [{"primitives": [{"attributes": {"POSITION": 7}}]}],
            "nodes": [{"mesh": 0}], "scenes": [{"nodes": [0]}]}"#,
    );
    let e = loaded.expect_err("no accessor 7");
    assert!(e.to_string().contains("accessor 7"), "{e}");
}

#[test]
fn gltf_node_cycle_is_an_error() {
    let (_dir, loaded) = load_text(
        "gltf-node-cycle",
        "s.gltf",
        r#"{"asset": {"version": "2.0"}, "nodes": [{"children": [1]}, {"children": [0]}],
            "scenes": [{"nodes": [0]}]}"#,
    );
    let e = loaded.expect_err("a cycle");
    assert!(e.to_string().contains("appears twice"), "{e}");
}

#[test]
fn emission_loads_from_obj_ke_and_gltf_emissive_factor_and_strength() {
    let dir = temp_case("emission");
    let obj =
        "mtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl lamp\nf 1 2 3\nusemtl wall\nf 1 3 2\nusemtl bad\nf 2 3 1\n";
    write(
        &dir,
        "m.mtl",
        "newmtl lamp\nKd 0.7 0.7 0.7\nKe 17 12 4\nnewmtl wall\nKd 0.5 0.5 0.5\nKe 0 0 0\nnewmtl bad\nKe -1 2 3\n",
    );
    let s = prm_scene::load(&write(&dir, "s.obj", obj)).unwrap();
    let by_name = |n: &str| s.materials.iter().find(|m| m.name == n).unwrap().emission;
    assert_eq!(by_name("lamp"), Vec3::new(17.0, 12.0, 4.0));
    assert_eq!(by_name("wall"), Vec3::ZERO);
    assert_eq!(by_name("bad"), Vec3::ZERO);
    assert_warned(&s, &["'bad'", "does not emit"]);

    let bin: Vec<u8> = [0.0f32, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0]
        .iter()
        .flat_map(|v| v.to_le_bytes())
        .collect();
    std::fs::write(dir.join("e.bin"), &bin).unwrap();
    let json = r#"{
      "asset": {"version": "2.0"},
      "extensionsUsed": ["KHR_materials_emissive_strength"],
      "buffers": [{"uri": "e.bin", "byteLength": 36}],
      "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": 36}],
      "accessors": [{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3", "min": [0,0,0], "max": [1,1,0]}],
      "materials": [
        {"name": "strong", "emissiveFactor": [1, 0.5, 0.25], "extensions": {"KHR_materials_emissive_strength": {"emissiveStrength": 8}}},
        {"name": "plain", "emissiveFactor": [0.5, 0.5, 0.5]}],
      "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "material": 0}, {"attributes": {"POSITION": 0}, "material": 1}]}],
      "nodes": [{"mesh": 0}],
      "scenes": [{"nodes": [0]}],
      "scene": 0
    }"#;
    let g = prm_scene::load(&write(&dir, "e.gltf", json)).unwrap();
    let by_name = |n: &str| g.materials.iter().find(|m| m.name == n).unwrap().emission;
    assert_eq!(by_name("strong"), Vec3::new(8.0, 4.0, 2.0));
    assert_eq!(by_name("plain"), Vec3::splat(0.5));
}
