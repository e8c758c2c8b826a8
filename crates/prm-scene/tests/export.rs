//! Integration tests of the glTF export: round trips through `prm_scene::load`, file structure, failures.

mod common;
use common::temp_case;
use glam::{Vec2, Vec3};
use prm_scene::{write_gltf, Atlas, AtlasParams, ExportError, Scene, Sizing, Texture};
use serde_json::Value;
use std::path::{Path, PathBuf};

fn repo(rel: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..").join(rel)
}

fn load(path: &Path) -> Scene {
    prm_scene::load(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

fn atlas_uvs(scene: &Scene, res: u32) -> Vec<[Vec2; 3]> {
    Atlas::build(scene, &AtlasParams::with_sizing(Sizing::Resolution(res)))
        .unwrap()
        .uvs
}

fn bits(uvs: &[[Vec2; 3]]) -> Vec<[[u32; 2]; 3]> {
    uvs.iter()
        .map(|t| t.map(|uv| uv.to_array().map(f32::to_bits)))
        .collect()
}

/// Writes `scene` at `out`, reloads it and checks that nothing the baker depends on changed.
fn round_trip(scene: &Scene, uvs: &[[Vec2; 3]], out: &Path) -> Scene {
    write_gltf(scene, uvs, out).unwrap_or_else(|e| panic!("{e}"));
    let back = load(out);
    assert!(back.report.warnings.is_empty(), "{:?}", back.report.warnings);
    assert_eq!(back.triangles.len(), scene.triangles.len(), "{}", out.display());
    assert_eq!(back.fingerprint(), scene.fingerprint(), "{}: geometry", out.display());
    assert_eq!(
        back.materials_fingerprint(),
        scene.materials_fingerprint(),
        "{}: materials",
        out.display()
    );
    let luv = back.lightmap_uvs.as_ref().expect("TEXCOORD_1 read back");
    assert_eq!(bits(luv), bits(uvs), "{}: lightmap UVs bit-exact", out.display());
    for (a, b) in back.triangles.iter().zip(&scene.triangles) {
        assert_eq!(
            back.materials[a.material as usize].albedo,
            scene.materials[b.material as usize].albedo
        );
    }
    back
}

#[test]
fn our_scenes_round_trip_as_glb_and_gltf() {
    let dir = temp_case("export-round-trip");
    for (rel, res) in [
        ("scenes/cornell-box/cornell-box.obj", 128),
        ("scenes/cornell-box/cornell-box.gltf", 128),
        ("scenes/two-rooms/two-rooms.gltf", 128),
        ("scenes/chairs/chairs.obj", 512),
    ] {
        let scene = load(&repo(rel));
        let uvs = atlas_uvs(&scene, res);
        let stem = Path::new(rel).file_stem().unwrap().to_string_lossy().into_owned();
        let ext = Path::new(rel).extension().unwrap().to_string_lossy().into_owned();
        round_trip(&scene, &uvs, &dir.join(format!("{stem}-{ext}.glb")));
        round_trip(&scene, &uvs, &dir.join(format!("{stem}-{ext}.gltf")));
        assert!(dir.join(format!("{stem}-{ext}.bin")).is_file());
        // The reloaded scene's UVs are used as its atlas as they are.
        let again = load(&dir.join(format!("{stem}-{ext}.glb")));
        let atlas = Atlas::build(&again, &AtlasParams::with_sizing(Sizing::Resolution(res))).unwrap();
        assert_eq!(bits(&atlas.uvs), bits(&uvs));
    }
    // Overwriting an existing export is fine and leaves no temporary files.
    let scene = load(&repo("scenes/cornell-box/cornell-box.obj"));
    let uvs = atlas_uvs(&scene, 64);
    round_trip(&scene, &uvs, &dir.join("cornell-box-obj.glb"));
    let stray: Vec<_> = std::fs::read_dir(&*dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.ends_with(".tmp"))
        .collect();
    assert!(stray.is_empty(), "{stray:?}");
}

/// The furnace box with one textured and one plain material, interleaved triangle by triangle.
fn textured_furnace() -> Scene {
    let mut scene = prm_scene::analytic::furnace_box(2, 0.5);
    scene.textures.push(Texture {
        width: 3,
        height: 2,
        texels: vec![
            [255, 0, 0],
            [0, 255, 0],
            [0, 0, 255],
            [10, 20, 30],
            [200, 100, 50],
            [1, 2, 3],
        ],
    });
    scene.materials[0].albedo = Vec3::new(0.8, 0.6, 0.1);
    scene.materials.push(prm_scene::Material {
        name: "textured \"one\"".into(),
        albedo: Vec3::new(0.9, 0.7, 0.333),
        texture: Some(0),
        emission: Vec3::ZERO,
    });
    for (i, t) in scene.triangles.iter_mut().enumerate() {
        t.material = (i % 3 == 0) as u32;
        // Material UVs on values the v flip keeps exact, some outside [0, 1] (repeat).
        t.uvs = [
            Vec2::new(0.1 * i as f32, 0.75),
            Vec2::new(0.3, -1.25 + i as f32 / 64.0),
            Vec2::new(1.5, 0.5 + i as f32 / 1000.0),
        ];
    }
    scene
}

#[test]
fn interleaved_materials_and_textures_round_trip() {
    let dir = temp_case("export-textured");
    let scene = textured_furnace();
    let uvs = atlas_uvs(&scene, 64);
    for name in ["furnace.glb", "furnace.gltf"] {
        let back = round_trip(&scene, &uvs, &dir.join(name));
        assert_eq!(back.textures, scene.textures, "texels survive the PNG");
        for (a, b) in back.triangles.iter().zip(&scene.triangles) {
            assert_eq!(a.uvs, b.uvs, "material UVs after the v flip and back");
            assert_eq!(back.materials[a.material as usize].texture.is_some(), b.material == 1);
        }
    }
    // One primitive per run of equal materials: runs of 1 (textured) and 2 (plain).
    let doc = read_glb(&dir.join("furnace.glb")).0;
    let runs = 1 + scene
        .triangles
        .windows(2)
        .filter(|w| w[0].material != w[1].material)
        .count();
    assert_eq!(doc["meshes"][0]["primitives"].as_array().unwrap().len(), runs);
    assert_eq!(doc["images"].as_array().unwrap().len(), 1, "texture embedded once");
}

/// The JSON and BIN chunks of a GLB, after checking its container.
fn read_glb(path: &Path) -> (Value, Vec<u8>) {
    let bytes = std::fs::read(path).unwrap();
    let u32_at = |o: usize| u32::from_le_bytes(bytes[o..o + 4].try_into().unwrap()) as usize;
    assert_eq!(&bytes[0..4], b"glTF");
    assert_eq!(u32_at(4), 2);
    assert_eq!(u32_at(8), bytes.len(), "header length is the file length");
    let json_len = u32_at(12);
    assert_eq!(&bytes[16..20], b"JSON");
    assert_eq!(json_len % 4, 0, "JSON chunk padded to 4");
    let json: Value = serde_json::from_slice(&bytes[20..20 + json_len]).unwrap();
    let bin_at = 20 + json_len;
    let bin_len = u32_at(bin_at);
    assert_eq!(&bytes[bin_at + 4..bin_at + 8], b"BIN\0");
    assert_eq!(bin_len % 4, 0, "BIN chunk padded to 4");
    assert_eq!(bin_at + 8 + bin_len, bytes.len(), "nothing after the BIN chunk");
    (json, bytes[bin_at + 8..].to_vec())
}

#[test]
fn glb_structure_is_what_validators_check() {
    let dir = temp_case("export-structure");
    let scene = textured_furnace();
    let uvs = atlas_uvs(&scene, 64);
    let out = dir.join("furnace.glb");
    write_gltf(&scene, &uvs, &out).unwrap();
    // `gltf`'s own validation accepts it.
    gltf::Gltf::open(&out).unwrap();
    let (doc, bin) = read_glb(&out);
    assert_eq!(doc["asset"]["version"], "2.0");
    let buffers = doc["buffers"].as_array().unwrap();
    assert_eq!(buffers.len(), 1);
    assert_eq!(buffers[0]["byteLength"].as_u64().unwrap() as usize, bin.len());
    assert!(buffers[0].get("uri").is_none(), "GLB buffer is the BIN chunk");
    let views = doc["bufferViews"].as_array().unwrap();
    for v in views {
        let (off, len) = (v["byteOffset"].as_u64().unwrap(), v["byteLength"].as_u64().unwrap());
        assert_eq!(off % 4, 0, "bufferView aligned to 4: {v}");
        assert!(len > 0 && off + len <= bin.len() as u64, "{v}");
    }
    let accessors = doc["accessors"].as_array().unwrap();
    let f32_at = |o: usize| f32::from_le_bytes(bin[o..o + 4].try_into().unwrap());
    let mut vertices = 0;
    for prim in doc["meshes"][0]["primitives"].as_array().unwrap() {
        assert_eq!(prim["mode"], 4);
        let attrs = prim["attributes"].as_object().unwrap();
        let mut keys: Vec<_> = attrs.keys().cloned().collect();
        keys.sort();
        assert_eq!(keys, ["NORMAL", "POSITION", "TEXCOORD_0", "TEXCOORD_1"]);
        let count = accessors[attrs["POSITION"].as_u64().unwrap() as usize]["count"]
            .as_u64()
            .unwrap();
        assert_eq!(count % 3, 0);
        vertices += count;
        for (semantic, index) in attrs {
            let a = &accessors[index.as_u64().unwrap() as usize];
            assert_eq!(a["count"].as_u64().unwrap(), count, "{semantic}: counts agree");
            assert_eq!(a["componentType"], 5126);
            let comps = if a["type"] == "VEC3" { 3 } else { 2 };
            let view = &views[a["bufferView"].as_u64().unwrap() as usize];
            assert_eq!(view["target"], 34962);
            let off = a["byteOffset"].as_u64().unwrap() as usize;
            assert_eq!(off % 4, 0);
            assert!(off + count as usize * comps * 4 <= view["byteLength"].as_u64().unwrap() as usize);
            let base = view["byteOffset"].as_u64().unwrap() as usize + off;
            let values: Vec<f32> = (0..count as usize * comps).map(|i| f32_at(base + 4 * i)).collect();
            if semantic == "POSITION" {
                for c in 0..3 {
                    let col = values.iter().skip(c).step_by(3);
                    let lo = col.clone().copied().fold(f32::INFINITY, f32::min);
                    let hi = col.copied().fold(f32::NEG_INFINITY, f32::max);
                    // min/max equal the data exactly, read as doubles (as validators do).
                    assert_eq!(a["min"][c].as_f64().unwrap(), lo as f64);
                    assert_eq!(a["max"][c].as_f64().unwrap(), hi as f64);
                }
            } else {
                assert!(a.get("min").is_none());
            }
            if semantic == "NORMAL" {
                for n in values.chunks_exact(3) {
                    let len = Vec3::from_slice(n).length();
                    assert!((len - 1.0).abs() < 1e-4, "unit normals");
                }
            }
        }
    }
    assert_eq!(vertices as usize, 3 * scene.triangles.len());
    for m in doc["materials"].as_array().unwrap() {
        let pbr = &m["pbrMetallicRoughness"];
        assert_eq!(pbr["metallicFactor"], 0.0);
        assert_eq!(pbr["roughnessFactor"], 1.0);
        assert_eq!(pbr["baseColorFactor"].as_array().unwrap().len(), 4);
    }
    let image_view = &views[doc["images"][0]["bufferView"].as_u64().unwrap() as usize];
    assert!(image_view.get("target").is_none(), "image views have no target");
    assert_eq!(doc["images"][0]["mimeType"], "image/png");

    // The .gltf form names its buffer file and that file has the declared length.
    let text = dir.join("furnace.gltf");
    write_gltf(&scene, &uvs, &text).unwrap();
    let json: Value = serde_json::from_slice(&std::fs::read(&text).unwrap()).unwrap();
    assert_eq!(json["buffers"][0]["uri"], "furnace.bin");
    assert_eq!(
        json["buffers"][0]["byteLength"].as_u64().unwrap(),
        std::fs::metadata(dir.join("furnace.bin")).unwrap().len()
    );
    assert_eq!(json["bufferViews"], doc["bufferViews"]);
    gltf::Gltf::open(&text).unwrap();
}

fn entries(dir: &Path) -> Vec<String> {
    let mut v: Vec<_> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

#[test]
fn failures_name_the_path_and_leave_no_partial_file() {
    let dir = temp_case("export-failures");
    let scene = prm_scene::analytic::furnace_box(1, 0.5);
    let uvs = atlas_uvs(&scene, 32);

    // A directory that does not exist.
    let missing = dir.join("no-such-dir").join("out.glb");
    let err = write_gltf(&scene, &uvs, &missing).unwrap_err();
    assert!(matches!(err, ExportError::Io { .. }), "{err:?}");
    assert!(err.to_string().contains("no-such-dir/out.glb"), "{err}");
    assert!(entries(&dir).is_empty());

    // A target that is a directory, or a symlink, is left alone.
    std::fs::create_dir(dir.join("taken.glb")).unwrap();
    let err = write_gltf(&scene, &uvs, &dir.join("taken.glb")).unwrap_err();
    assert!(matches!(err, ExportError::NotRegularFile(_)), "{err:?}");
    assert!(err.to_string().contains("taken.glb"), "{err}");
    #[cfg(unix)]
    {
        std::fs::write(dir.join("real.glb"), b"keep").unwrap();
        std::os::unix::fs::symlink(dir.join("real.glb"), dir.join("link.glb")).unwrap();
        let err = write_gltf(&scene, &uvs, &dir.join("link.glb")).unwrap_err();
        assert!(matches!(err, ExportError::NotRegularFile(_)), "{err:?}");
        assert_eq!(std::fs::read(dir.join("real.glb")).unwrap(), b"keep");
    }

    // `.gltf` whose `.bin` is taken: neither file is written.
    std::fs::create_dir(dir.join("split.bin")).unwrap();
    let err = write_gltf(&scene, &uvs, &dir.join("split.gltf")).unwrap_err();
    assert!(err.to_string().contains("split.bin"), "{err}");

    // Invalid input is refused before anything is written.
    let err = write_gltf(&scene, &uvs[1..], &dir.join("short.glb")).unwrap_err();
    assert!(
        matches!(
            err,
            ExportError::UvCount {
                triangles: 12,
                uvs: 11,
                ..
            }
        ),
        "{err:?}"
    );
    let mut bad = scene.clone();
    bad.triangles[5].positions[1].y = f32::NAN;
    let err = write_gltf(&bad, &uvs, &dir.join("nan.glb")).unwrap_err();
    assert!(
        err.to_string().contains("triangle 5 has a non-finite position"),
        "{err}"
    );
    let mut bad = scene.clone();
    bad.triangles[2].material = 7;
    let err = write_gltf(&bad, &uvs, &dir.join("material.glb")).unwrap_err();
    assert!(
        matches!(
            err,
            ExportError::Material {
                triangle: 2,
                material: 7,
                ..
            }
        ),
        "{err:?}"
    );
    let mut bad = scene.clone();
    bad.materials[0].texture = Some(0);
    let err = write_gltf(&bad, &uvs, &dir.join("texture.glb")).unwrap_err();
    assert!(err.to_string().contains("texture 0 out of range"), "{err}");
    bad.textures.push(Texture {
        width: 2,
        height: 2,
        texels: vec![[0; 3]; 3],
    });
    let err = write_gltf(&bad, &uvs, &dir.join("texture.glb")).unwrap_err();
    assert!(err.to_string().contains("3 texels for 2×2"), "{err}");
    let mut bad = scene.clone();
    bad.triangles.clear();
    assert!(matches!(
        write_gltf(&bad, &[], &dir.join("empty.glb")),
        Err(ExportError::NoTriangles(_))
    ));
    let err = write_gltf(&scene, &uvs, &dir.join("scene.obj")).unwrap_err();
    assert!(matches!(err, ExportError::UnsupportedFormat(_)), "{err:?}");

    assert_eq!(entries(&dir), ["link.glb", "real.glb", "split.bin", "taken.glb"]);
}

#[test]
fn exr_lightmaps_round_trip_bit_exactly() {
    let dir = temp_case("export-exr");
    let (w, h) = (37, 5);
    let rgb: Vec<[f32; 3]> = (0..w * h)
        .map(|i| [i as f32 * 0.1, 1e-30 * i as f32, -(i as f32) / 7.0 + 1e6])
        .collect();
    let out = dir.join("indirect.exr");
    prm_scene::write_exr_rgb(&out, w, h, &rgb).unwrap();
    let (rw, rh, back) = prm_scene::read_exr_rgb(&out).unwrap();
    assert_eq!((rw, rh), (w, h));
    let b = |v: &[[f32; 3]]| v.iter().map(|p| p.map(f32::to_bits)).collect::<Vec<_>>();
    assert_eq!(b(&back), b(&rgb), "row 0 on top, values exact");
    // Overwrite in place.
    let dark = vec![[0.0f32; 3]; w * h];
    prm_scene::write_exr_rgb(&out, w, h, &dark).unwrap();
    assert_eq!(prm_scene::read_exr_rgb(&out).unwrap().2, dark);

    let err = prm_scene::write_exr_rgb(&dir.join("short.exr"), w, h, &rgb[1..]).unwrap_err();
    assert!(err.to_string().contains("184 pixels given for a 37×5 image"), "{err}");
    let err = prm_scene::write_exr_rgb(&dir.join("empty.exr"), 0, 3, &[]).unwrap_err();
    assert!(matches!(err, ExportError::BadImage { .. }), "{err:?}");
    let err = prm_scene::write_exr_rgb(&dir.join("overflow.exr"), usize::MAX, 2, &rgb).unwrap_err();
    assert!(matches!(err, ExportError::BadImage { .. }), "{err:?}");
    std::fs::create_dir(dir.join("taken.exr")).unwrap();
    let err = prm_scene::write_exr_rgb(&dir.join("taken.exr"), w, h, &rgb).unwrap_err();
    assert!(matches!(err, ExportError::NotRegularFile(_)), "{err:?}");
    let err = prm_scene::write_exr_rgb(&dir.join("none").join("x.exr"), w, h, &rgb).unwrap_err();
    assert!(err.to_string().contains("none/x.exr"), "{err}");
    assert_eq!(entries(&dir), ["indirect.exr", "taken.exr"]);
}
