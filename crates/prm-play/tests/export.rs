//! Static lightmap export (`prm_play::export`, `prm-play --export DIR`): the glTF reloads
//! through our own loader as the same geometry with the same lightmap UVs, the EXR maps are the
//! run time's lightmaps, and the KTX2 maps parse with the `ktx2` crate and decode to them.

use std::path::Path;

use glam::Vec3;
use prm_play::synthetic::{cornell_box_path, write_archive, SyntheticParams};
use prm_play::{PlayOptions, Renderer};
use prm_scene::Light;

/// Reads a KTX2 lightmap with the `ktx2` crate, checks its header and descriptor, inflates its
/// one level and decodes RGB9E5 as Vulkan defines it (9-bit mantissas R, G, B from bit 0, a
/// shared exponent with bias 15 in the top five bits).
fn read_ktx2(path: &Path) -> (usize, usize, Vec<[f32; 3]>) {
    let bytes = std::fs::read(path).unwrap();
    let reader = ktx2::Reader::new(&bytes[..]).expect("the ktx2 crate parses the file");
    let header = reader.header();
    assert_eq!(header.format, Some(ktx2::Format::E5B9G9R9_UFLOAT_PACK32));
    assert_eq!(
        header.supercompression_scheme,
        Some(ktx2::SupercompressionScheme::Zstandard)
    );
    assert_eq!((header.level_count, header.face_count, header.layer_count), (1, 1, 0));
    let (expected_dfd, type_size) = ktx2::dfd::Basic::from_format(ktx2::Format::E5B9G9R9_UFLOAT_PACK32).unwrap();
    assert_eq!(header.type_size, type_size);
    assert_eq!(
        reader.basic_dfd(),
        Some(&expected_dfd),
        "the descriptor the ktx2 crate derives"
    );
    assert!(reader.writer().is_some_and(|w| w.starts_with("prm-scene")));
    let level = reader.levels().next().unwrap();
    let raw = zstd::bulk::decompress(level.data, level.uncompressed_byte_length as usize).unwrap();
    let rgb = raw
        .chunks_exact(4)
        .map(|c| {
            let w = u32::from_le_bytes(c.try_into().unwrap());
            let scale = 2f32.powi((w >> 27) as i32 - 15 - 9);
            [0, 9, 18].map(|shift| ((w >> shift) & 511) as f32 * scale)
        })
        .collect();
    (header.pixel_width as usize, header.pixel_height as usize, rgb)
}

fn read_exr(path: &Path) -> (usize, usize, Vec<[f32; 3]>) {
    let image = prm_play::output::read_exr(path).unwrap();
    (image.width as usize, image.height as usize, image.rgb)
}

#[test]
fn exported_lightmaps_and_gltf_match_the_run_time_and_reload_as_the_same_scene() {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("prm-play-export");
    std::fs::create_dir_all(&dir).unwrap();
    let scene_path = cornell_box_path();
    let scene = prm_scene::load(&scene_path).unwrap();
    let archive_path = dir.join("cornell.prm");
    write_archive(&scene, &scene_path, &archive_path, SyntheticParams::default()).unwrap();
    let (mut archive, scene) = prm_play::open(&archive_path, None).unwrap();
    let ctx = prm_play::open_vulkan().expect("a Vulkan device (apt-get install mesa-vulkan-drivers)");
    let opts = PlayOptions {
        width: 32,
        height: 32,
        ..Default::default()
    };
    let mut r = Renderer::new(ctx, &scene, &mut archive, opts).unwrap();
    let lights = [Light::Point {
        position: Vec3::new(0.28, 0.45, 0.28),
        intensity: Vec3::splat(0.3),
    }];
    let out = prm_play::export::export(&mut r, &scene, &lights, &dir.join("out")).unwrap();

    // The glTF is the same geometry with the run time's lightmap UVs, bit for bit.
    let reloaded = prm_scene::load(&out.gltf).unwrap();
    assert_eq!(reloaded.fingerprint(), scene.fingerprint());
    assert_eq!(reloaded.materials_fingerprint(), scene.materials_fingerprint());
    let uvs = reloaded.lightmap_uvs.as_ref().expect("TEXCOORD_1 read back");
    let expected: Vec<[glam::Vec2; 3]> = r
        .runtime()
        .lightmap_uvs()
        .iter()
        .map(|t| t.map(glam::Vec2::from_array))
        .collect();
    assert_eq!(uvs, &expected);

    // The maps: indirect is the run time's lightmap; the full map adds non-negative direct
    // light, a lot of it (a point light inside the box lights most texels directly).
    let res = r.runtime().lightmap_resolution() as usize;
    let (w, h, indirect) = read_exr(&out.indirect);
    assert_eq!((w, h), (res, res));
    assert_eq!(indirect, r.read_lightmap().unwrap());
    let (w, h, full) = read_exr(&out.irradiance);
    assert_eq!((w, h), (res, res));
    // The KTX2 maps are the same to RGB9E5's precision: half a unit of the 9-bit mantissa of
    // the texel's largest channel.
    for (ktx2, exact) in [(&out.indirect_ktx2, &indirect), (&out.irradiance_ktx2, &full)] {
        let (w, h, decoded) = read_ktx2(ktx2);
        assert_eq!((w, h), (res, res));
        for (d, e) in decoded.iter().zip(exact.iter()) {
            let max = e[0].max(e[1]).max(e[2]);
            for c in 0..3 {
                assert!((d[c] - e[c]).abs() <= max / 512.0 * 1.001 + 1e-9, "{d:?} against {e:?}");
            }
        }
    }
    let sum = |m: &[[f32; 3]]| m.iter().flatten().map(|v| *v as f64).sum::<f64>();
    assert!(full.iter().flatten().all(|v| v.is_finite() && *v >= 0.0));
    assert!(
        sum(&full) > 2.0 * sum(&indirect),
        "direct {} vs indirect {}",
        sum(&full),
        sum(&indirect)
    );
    let lit = full.iter().zip(&indirect).filter(|(f, i)| f[0] > i[0] * 1.01).count();
    assert!(lit > res * res / 4, "{lit} of {} texels get direct light", res * res);
    // Every texel the indirect light reaches, chart borders and gutters included, is lit in the
    // full map too: those whose centre no triangle covers take their covered neighbours' light
    // (they were black while the pass's clear colour marked every texel covered).
    let reached = indirect.iter().filter(|i| i[0] > 0.0).count();
    let dark = full
        .iter()
        .zip(&indirect)
        .filter(|(f, i)| i[0] > 0.0 && f[0] < 0.5 * i[0])
        .count();
    assert_eq!(
        dark, 0,
        "{dark} of the {reached} texels the indirect light reaches are dark in the full map"
    );
}
