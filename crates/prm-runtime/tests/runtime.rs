//! The run time as an engine embeds it: on a device it did not open, next to another run time,
//! with shadow maps handed in, and refusing bad input with errors that name it.

use glam::Vec3;
use prm_gpu_kit::{Backend, GpuContext};
use prm_runtime::synthetic::{cornell_box_path, write_archive, SyntheticParams};
use prm_runtime::{GiUpdate, Runtime, RuntimeError, RuntimeOptions, Shadows, MAX_LIGHTS};
use prm_scene::{Light, Scene};

type FileArchive = prm_format::Archive<std::io::BufReader<std::fs::File>>;

fn gpu() -> GpuContext {
    // Vulkan explicitly: a missing driver fails loudly instead of falling back to GL.
    GpuContext::new(Backend::Vulkan).expect("a Vulkan adapter (apt-get install mesa-vulkan-drivers)")
}

fn archive(name: &str) -> (Scene, FileArchive) {
    archive_with(name, SyntheticParams::default())
}

fn archive_with(name: &str, params: SyntheticParams) -> (Scene, FileArchive) {
    let scene_path = cornell_box_path();
    let scene = prm_scene::load(&scene_path).unwrap();
    let dir = std::env::temp_dir().join(format!("prm-runtime-{}-{name}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let out = dir.join("synthetic.prm");
    write_archive(&scene, &scene_path, &out, params).unwrap();
    let a = prm_format::Archive::open(&out).unwrap();
    (scene, a)
}

fn point(x: f32, y: f32, z: f32) -> Light {
    Light::Point {
        position: Vec3::new(x, y, z),
        intensity: Vec3::splat(0.3),
    }
}

fn frame(ctx: &GpuContext, rt: &mut Runtime, lights: &[Light], shadows: Shadows) -> Vec<[f32; 3]> {
    rt.update(lights).unwrap();
    let mut enc = ctx.device.create_command_encoder(&Default::default());
    rt.encode(&mut enc, shadows, None);
    ctx.queue.submit([enc.finish()]);
    ctx.wait().unwrap();
    rt.read_lightmap().unwrap()
}

#[test]
fn two_runtimes_share_a_device_and_shadow_maps_can_be_handed_in() {
    let ctx = gpu();
    let (scene, mut a) = archive("share");
    let opts = RuntimeOptions::for_archive(&a);
    let mut own = Runtime::new(&ctx.device, &ctx.queue, &mut a, &scene, opts.clone()).unwrap();
    let mut other = Runtime::new(&ctx.device, &ctx.queue, &mut a, &scene, opts).unwrap();
    let lights = [point(0.28, 0.45, 0.28), point(0.1, 0.3, 0.4)];

    let alone = frame(&ctx, &mut own, &lights, Shadows::Own);
    let total: f64 = alone.iter().flatten().map(|v| *v as f64).sum();
    assert!(total.is_finite() && total > 0.0, "the lightmap is empty: {total}");

    // Another light in the second run time leaves the first one's lightmap alone.
    let moved = frame(&ctx, &mut other, &[point(0.4, 0.2, 0.1)], Shadows::Own);
    assert_ne!(moved, alone);
    assert_eq!(own.read_lightmap().unwrap(), alone);

    // The second run time reading the first one's shadow maps (rendered for the same lights)
    // gives the same lightmap bit for bit.
    other.update(&lights).unwrap();
    let mut enc = ctx.device.create_command_encoder(&Default::default());
    own.encode_shadow_maps(&mut enc, None);
    other.encode(
        &mut enc,
        Shadows::External(own.direct_light_bindings().shadow_maps),
        None,
    );
    ctx.queue.submit([enc.finish()]);
    ctx.wait().unwrap();
    assert_eq!(other.read_lightmap().unwrap(), alone);
    let w = other.read_weights().unwrap();
    assert_eq!(w.len() as u32, other.cluster_count());
    assert!(w.iter().all(|c| c.score.is_finite()));
}

/// Overwrites the run time's lightmap with zeros, so that a frame that records no indirect-light
/// passes shows as a black lightmap.
fn clear_lightmap(ctx: &GpuContext, rt: &Runtime) {
    let r = rt.lightmap_resolution();
    let zeros = vec![0u8; (r * r * 16) as usize];
    ctx.queue.write_texture(
        rt.lightmap_texture().as_image_copy(),
        &zeros,
        wgpu::TexelCopyBufferLayout {
            offset: 0,
            bytes_per_row: Some(r * 16),
            rows_per_image: None,
        },
        rt.lightmap_texture().size(),
    );
    ctx.wait().unwrap();
}

#[test]
fn a_frame_whose_lights_stand_still_keeps_the_indirect_light() {
    let ctx = gpu();
    let (scene, mut a) = archive("still");
    let opts = RuntimeOptions::for_archive(&a);
    assert_eq!(opts.gi_update, GiUpdate::OnChange, "the default");
    let mut rt = Runtime::new(&ctx.device, &ctx.queue, &mut a, &scene, opts.clone()).unwrap();
    let lights = [point(0.28, 0.45, 0.28)];
    assert!(rt.gi_pending(), "nothing computed yet");
    let lit = frame(&ctx, &mut rt, &lights, Shadows::Own);
    assert!(lit.iter().flatten().any(|v| *v > 0.0));
    rt.update(&lights).unwrap();
    assert!(!rt.gi_pending());

    // The same lights: the passes are not recorded, the (cleared) lightmap stays as it is.
    clear_lightmap(&ctx, &rt);
    let still = frame(&ctx, &mut rt, &lights, Shadows::Own);
    assert!(
        still.iter().flatten().all(|v| *v == 0.0),
        "a still frame computed the lightmap again"
    );

    // Each input of the indirect light brings the passes back: the lights,
    let moved = [point(0.3, 0.45, 0.28)];
    let after_move = frame(&ctx, &mut rt, &moved, Shadows::Own);
    assert!(after_move != still && after_move != lit, "the lights moved");
    // shadow maps handed in, which may hold anything, even with the same lights,
    let mut other = Runtime::new(&ctx.device, &ctx.queue, &mut a, &scene, opts.clone()).unwrap();
    frame(&ctx, &mut other, &moved, Shadows::Own);
    for _ in 0..2 {
        clear_lightmap(&ctx, &rt);
        let maps = Shadows::External(other.direct_light_bindings().shadow_maps);
        assert!(frame(&ctx, &mut rt, &moved, maps) == after_move, "external shadow maps");
    }
    // K,
    clear_lightmap(&ctx, &rt);
    rt.set_top_k(rt.options().top_k + 1);
    let k = frame(&ctx, &mut rt, &moved, Shadows::Own);
    assert!(k.iter().flatten().any(|v| *v > 0.0), "K changed");
    // and the emitters' scales (the sky likewise); setting the ones in use changes nothing.
    rt.update(&moved).unwrap();
    assert!(!rt.gi_pending());
    let same = rt.emitter_scales().to_vec();
    rt.set_emitter_scales(&same).unwrap();
    assert!(!rt.gi_pending(), "the same emitter scales");

    // GiUpdate::EveryFrame computes still frames too, to the same light.
    let every = RuntimeOptions {
        gi_update: GiUpdate::EveryFrame,
        ..opts
    };
    let mut rt = Runtime::new(&ctx.device, &ctx.queue, &mut a, &scene, every).unwrap();
    assert!(frame(&ctx, &mut rt, &lights, Shadows::Own) == lit);
    clear_lightmap(&ctx, &rt);
    assert!(rt.gi_pending());
    assert!(frame(&ctx, &mut rt, &lights, Shadows::Own) == lit, "every frame");
}

#[test]
fn bad_input_is_refused_naming_it() {
    let ctx = gpu();
    let (scene, mut a) = archive("refuse");
    // Options out of range are refused before any allocation, naming the field.
    for (options, field) in [
        (
            RuntimeOptions {
                shadow_resolution: 4,
                ..RuntimeOptions::default()
            },
            "shadow_resolution",
        ),
        (
            RuntimeOptions {
                fade_band: f32::NAN,
                ..RuntimeOptions::default()
            },
            "fade_band",
        ),
        (
            RuntimeOptions {
                sun_tiles: 0,
                ..RuntimeOptions::default()
            },
            "sun_tiles",
        ),
        (
            RuntimeOptions {
                near_bounces: prm_runtime::MAX_NEAR_BOUNCES + 1,
                ..RuntimeOptions::default()
            },
            "near_bounces",
        ),
    ] {
        match Runtime::new(&ctx.device, &ctx.queue, &mut a, &scene, options) {
            Err(RuntimeError::Option { option, .. }) => assert_eq!(option, field),
            Err(e) => panic!("{field}: {e}"),
            Ok(_) => panic!("{field}: accepted"),
        }
    }

    // Another scene's geometry.
    let mut other = scene.clone();
    other.triangles.pop();
    let e = Runtime::new(&ctx.device, &ctx.queue, &mut a, &other, RuntimeOptions::default())
        .err()
        .unwrap();
    assert!(matches!(e, RuntimeError::Mismatch(_)), "{e}");

    let mut rt = Runtime::new(&ctx.device, &ctx.queue, &mut a, &scene, RuntimeOptions::default()).unwrap();
    let many = vec![point(0.2, 0.2, 0.2); MAX_LIGHTS + 1];
    let e = rt.update(&many).unwrap_err();
    assert!(e.to_string().contains(&format!("{} lights", MAX_LIGHTS + 1)), "{e}");
    // Directional lights take sun_tiles² views each: more views than fit are refused too, not
    // written past the views buffer.
    let sun = Light::Directional {
        direction: Vec3::new(0.2, -1.0, 0.1).normalize(),
        irradiance: Vec3::ONE,
    };
    let suns = vec![sun; MAX_LIGHTS];
    let e = rt.update(&suns).unwrap_err();
    assert!(matches!(e, RuntimeError::TooManyShadowViews { .. }), "{e}");
    assert!(e.to_string().contains("sun tiles"), "{e}");
    // The shadow array grows for more lights, and says so once.
    assert!(rt.update(&[point(0.2, 0.2, 0.2); 3]).unwrap());
    assert!(!rt.update(&[point(0.2, 0.2, 0.2); 2]).unwrap());
    ctx.wait().unwrap();
}

/// Bytes of tile `t`'s basis rows that are not zero (four `f16` per eight bytes, the rank
/// rounded up to four) and of its coefficients as the run time uploads them: a `u32` index
/// entry per pane (the clusters and the `groups` residual groups), then a block (a scale word and
/// a 4-byte word for each rank's three channels, likewise rounded) per cluster that is not zero
/// there and per group with such a member.
fn tile_bytes(archive: &FileArchive, groups: u32, t: usize) -> (u64, u64) {
    let basis = archive.pane_basis();
    let r = basis.ranks()[t] as usize;
    let quads = r.div_ceil(4) as u64;
    let rows = basis.nonzero_rows(t).count() as u64;
    if quads == 0 {
        return (0, 0);
    }
    let group_of = prm_format::residual_groups(archive.clusters(), groups);
    let clusters = basis.pane_count();
    let mut lit = vec![false; clusters + groups as usize];
    for c in (0..clusters).filter(|&c| !basis.block_is_zero(c, t)) {
        lit[c] = true;
        if groups > 0 {
            lit[clusters + group_of[c] as usize] = true;
        }
    }
    let blocks = lit.iter().filter(|&&l| l).count() as u64;
    (
        rows * quads * 8,
        8 * lit.len().div_ceil(2) as u64 + blocks * 8 * (1 + 2 * quads),
    )
}

/// Tiles of the panes grouped in many small chunks (a basis and a coefficient buffer each, and
/// a dispatch, `RuntimeOptions::pane_chunk_bytes`) blend the same lightmap bit for bit as one
/// chunk; a cap under one tile is refused, naming the pane count.
#[test]
fn panes_in_small_chunks_blend_the_same_lightmap() {
    let ctx = gpu();
    // A 256² atlas: 16 tiles of 64².
    let params = SyntheticParams {
        resolution: 256,
        ..SyntheticParams::default()
    };
    let (scene, mut a) = archive_with("chunks", params);
    let lights = [point(0.28, 0.45, 0.28), point(0.1, 0.3, 0.4)];
    let mut whole = Runtime::new(&ctx.device, &ctx.queue, &mut a, &scene, RuntimeOptions::default()).unwrap();
    let expected = frame(&ctx, &mut whole, &lights, Shadows::Own);
    assert!(expected.iter().flatten().any(|&v| v > 0.0));
    let panes = u64::from(whole.cluster_count() + whole.group_count());
    let largest = (0..a.pane_basis().tile_count())
        .map(|t| {
            let (b, c) = tile_bytes(&a, whole.group_count(), t);
            b.max(c)
        })
        .max()
        .unwrap();
    let basis = a.pane_basis();
    assert!(
        basis.ranks().iter().filter(|&&r| r > 0).count() > 4,
        "too few tiles: {:?}",
        basis.ranks()
    );
    // One tile's largest buffer a chunk: a chunk per tile, or nearly.
    let options = RuntimeOptions {
        pane_chunk_bytes: Some(largest),
        ..RuntimeOptions::default()
    };
    let mut chunked = Runtime::new(&ctx.device, &ctx.queue, &mut a, &scene, options).unwrap();
    assert_eq!(frame(&ctx, &mut chunked, &lights, Shadows::Own), expected);

    let options = RuntimeOptions {
        pane_chunk_bytes: Some(largest - 1),
        ..RuntimeOptions::default()
    };
    let e = Runtime::new(&ctx.device, &ctx.queue, &mut a, &scene, options)
        .err()
        .unwrap();
    assert!(matches!(e, RuntimeError::TooManyPanes { .. }), "{e}");
    assert!(e.to_string().contains(&panes.to_string()), "{e}");
}

/// One shard of a sharded bake (`params.shard`) holds the other shards' panes as zeros: the run
/// time refuses it, naming the shard and the merge.
#[test]
fn a_shard_of_a_bake_is_refused() {
    let ctx = gpu();
    let (scene, a) = archive("shard");
    let mut metadata = a.metadata().clone();
    metadata
        .params
        .insert("shard".into(), serde_json::json!({ "index": 1, "count": 4 }));
    let clusters: Vec<prm_format::Cluster> = a
        .clusters()
        .iter()
        .map(|c| prm_format::Cluster::new(c.first, c.count, c.centroid, c.mean_normal))
        .collect();
    let out = std::env::temp_dir().join(format!("prm-runtime-{}-shard/part.prm", std::process::id()));
    let mut w = prm_format::ArchiveWriter::create(&out, metadata, a.atlas(), a.entries(), &clusters).unwrap();
    for c in 0..clusters.len() {
        w.add_pane(&a.read_pane(c).unwrap()).unwrap();
    }
    w.finish().unwrap();
    let mut part = prm_format::Archive::open(&out).unwrap();
    let e = Runtime::new(&ctx.device, &ctx.queue, &mut part, &scene, RuntimeOptions::default())
        .err()
        .expect("a shard was accepted");
    assert!(matches!(e, RuntimeError::PartialArchive(_)), "{e}");
    assert!(
        e.to_string().contains("shard 1/4") && e.to_string().contains("prm-bake merge"),
        "{e}"
    );
}

/// The run time's GPU memory by part: the panes' part holds the basis rows and the
/// coefficients with the residual groups' (and little more), the lightmap its RGBA32F texels,
/// and the bytes an update reads cover the selected panes' coefficients and the lit texels'
/// basis rows.
#[test]
fn gpu_memory_is_reported_by_part() {
    let ctx = gpu();
    let (scene, mut a) = archive("memory");
    let texels = (a.atlas().resolution as u64).pow(2);
    let opts = RuntimeOptions::for_archive(&a);
    let mut rt = Runtime::new(&ctx.device, &ctx.queue, &mut a, &scene, opts).unwrap();
    frame(&ctx, &mut rt, &[point(0.28, 0.45, 0.28)], Shadows::Own);
    let parts = rt.gpu_memory().expect("Vulkan reports its allocations");
    assert_eq!(parts.len(), prm_runtime::MEMORY_PARTS.len());
    let part = |name: &str| parts.iter().find(|p| p.name == name).unwrap().bytes;
    let all = u64::from(rt.cluster_count() + rt.group_count());
    let (rows, coefficients) = (0..a.pane_basis().tile_count())
        .map(|t| tile_bytes(&a, rt.group_count(), t))
        .fold((0, 0), |(b, c), (tb, tc)| (b + tb, c + tc));
    let panes = rows + coefficients;
    assert!(
        part("panes") >= panes && part("panes") <= panes + panes / 10 + (1 << 20),
        "panes {} for {panes} bytes of basis and coefficients",
        part("panes")
    );
    assert!(part("lightmap") >= texels * 16, "lightmap {}", part("lightmap"));
    assert!(part("shadow maps") > 0 && part("weights") > 0);
    let read = rt.gi_bytes_read_by_part();
    assert_eq!(read.iter().map(|p| p.bytes).sum::<u64>(), rt.gi_bytes_read());
    let (clusters, top_k) = (rt.cluster_count(), rt.options().top_k);
    let groups = if clusters > top_k { rt.group_count() } else { 0 };
    let k = u64::from(top_k.min(clusters) + groups);
    // A kept pane's blocks on average, and its index word in every tile.
    let ranked = a.pane_basis().ranks().iter().filter(|&&r| r > 0).count() as u64;
    let index = ranked * 8 * all.div_ceil(2);
    let per_pane = (coefficients - index) / all + 8 * ranked;
    let panes = read.iter().find(|p| p.name == "panes").unwrap().bytes;
    assert!(panes > k * per_pane && panes <= k * per_pane + rows, "{read:?}");
}
