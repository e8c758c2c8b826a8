//! Tests of the parameter planning: presets, config precedence, automatic sizes and budgets.

use super::*;

fn cornell() -> Scene {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes/cornell-box/cornell-box.obj");
    prm_scene::load(&p).unwrap()
}

/// [`BakeParams::resolve`] with the CPU renderer's cost model.
fn resolve(
    config: &BakeConfig,
    scene: &Scene,
    probe: impl Fn() -> Result<Atlas, BakeError>,
) -> Result<BakeParams, BakeError> {
    BakeParams::resolve(config, scene, &CostModel::CPU, bounces_per_walk(scene), probe)
}

fn probe(scene: &Scene) -> impl Fn() -> Result<Atlas, BakeError> + '_ {
    move || {
        Atlas::build(scene, &prm_scene::AtlasParams::DEFAULT).map_err(|source| BakeError::Atlas {
            what: "building the automatic atlas",
            source,
        })
    }
}

#[test]
fn paper_preset_is_the_papers_settings() {
    let scene = cornell();
    let cfg = BakeConfig {
        preset: Some(Preset::Paper),
        ..Default::default()
    };
    let p = resolve(&cfg, &scene, probe(&scene)).unwrap();
    assert_eq!(
        (p.entries, p.clusters, p.atlas, p.top_k),
        (4096, 256, AtlasSize::Resolution(256), 32)
    );
    // The preset fixes every size; only the VPL disks, which the paper does not have, are
    // chosen (from the atlas: 256² texels × 32 near rays fit the hit budget, so the larger disks).
    assert_eq!(p.vpl_disk_scale, NEAR_FIELD_DISK_SCALE);
    assert_eq!(p.reasons.len(), 1, "{:?}", p.reasons);
    assert!(p.reasons[0].starts_with("VPL disks"), "{:?}", p.reasons);
}

#[test]
fn command_line_overrides_config_overrides_preset() {
    let scene = cornell();
    let file: BakeConfig = toml::from_str("preset = \"paper\"\nentries = 2048\nclusters = 128\n").unwrap();
    let cli = BakeConfig {
        clusters: Some(64),
        ..Default::default()
    };
    let p = resolve(&file.overridden_by(&cli), &scene, probe(&scene)).unwrap();
    assert_eq!((p.entries, p.clusters), (2048, 64));
    assert!(
        toml::from_str::<BakeConfig>("entires = 3").is_err(),
        "unknown keys are errors"
    );
}

#[test]
fn automatic_sizes_follow_the_scene_and_budgets() {
    let scene = cornell();
    let p = resolve(&BakeConfig::default(), &scene, probe(&scene)).unwrap();
    // A 16-chart box needs the minimum, 1024, doubled twice where nothing cut it: 8 per
    // cluster, 16 walks each (65536 in all), and every one of its 512 clusters blended.
    assert_eq!(
        (p.entries, p.clusters, p.paths_per_entry, p.top_k),
        (4096, 512, 16, 512)
    );
    assert_eq!(
        p.reasons.iter().filter(|r| r.contains("twice as many")).count(),
        2,
        "{:?}",
        p.reasons
    );
    assert!(!p.reasons.is_empty());
    // A tight memory budget shrinks the atlas or the cluster count until the panes fit it at
    // the largest rank.
    let bytes = |p: &BakeParams| match p.atlas {
        AtlasSize::Resolution(r) => pane_memory_bound(p.clusters as f64, f64::from(r).powi(2)),
        AtlasSize::TexelSize(_) => unreachable!(),
    };
    let tight = BakeConfig {
        memory_budget_mib: Some(2.0),
        ..Default::default()
    };
    let q = resolve(&tight, &scene, probe(&scene)).unwrap();
    assert!(
        bytes(&q) <= 2.0 * 1024.0 * 1024.0 && bytes(&q) < bytes(&p),
        "{q:?} vs {p:?}"
    );
}

#[test]
fn time_budget_shrinks_automatic_sizes_only() {
    let scene = cornell();
    let roomy = resolve(&BakeConfig::default(), &scene, probe(&scene)).unwrap();
    // Below the undoubled plan's time (a quarter of the doubled twice).
    let budget = roomy.estimated_seconds / 8.0;
    let tight = BakeConfig {
        time_budget_s: Some(budget),
        ..Default::default()
    };
    let p = resolve(&tight, &scene, probe(&scene)).unwrap();
    assert!(p.estimated_seconds <= budget, "{p:?}");
    assert!(p.estimated_seconds < roomy.estimated_seconds);
    assert!(p.reasons.iter().any(|r| r.contains("time budget")), "{:?}", p.reasons);
    // Explicit sizes are never changed, only estimated.
    let fixed = BakeConfig {
        preset: Some(Preset::Paper),
        time_budget_s: Some(1.0),
        ..Default::default()
    };
    let q = resolve(&fixed, &scene, probe(&scene)).unwrap();
    assert_eq!((q.entries, q.clusters, q.paths_per_entry), (4096, 256, 1));
    assert!(q.estimated_seconds > 1.0);
}

#[test]
fn impossible_parameters_are_refused() {
    let scene = cornell();
    for (cfg, needle) in [
        (
            BakeConfig {
                entries: Some(0),
                ..Default::default()
            },
            "entries",
        ),
        (
            BakeConfig {
                entries: Some(100),
                clusters: Some(200),
                ..Default::default()
            },
            "more clusters",
        ),
        (
            BakeConfig {
                resolution: Some(100_000),
                ..Default::default()
            },
            "resolution",
        ),
        (
            BakeConfig {
                preset: Some(Preset::High),
                memory_budget_mib: Some(16.0),
                ..Default::default()
            },
            "memory budget",
        ),
    ] {
        let e = resolve(&cfg, &scene, probe(&scene)).unwrap_err().to_string();
        assert!(e.contains(needle), "{e}");
    }
}

/// Automatic entry points stop at 16 per cluster the bake can have: chairs' 913 charts want
/// 3840 (15360, in 1920 clusters, where nothing cuts them; doubled once in nine tenths of that
/// plan's time), 100 clusters take 1536 (16 × 100, a multiple of 256, not doubled), and a
/// memory budget that allows fewer clusters lowers them too, never below 1024.
#[test]
fn automatic_entries_follow_the_clusters() {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes/chairs/chairs.obj");
    let scene = prm_scene::load(&p).unwrap();
    let free = resolve(&BakeConfig::default(), &scene, probe(&scene)).unwrap();
    // Doubled twice where nothing cuts them: 15360 in 1920 clusters (8 entry points each), 5
    // walks each (about 65536 in all).
    assert_eq!((free.entries, free.clusters, free.paths_per_entry), (15360, 1920, 5));
    let hurried = BakeConfig {
        time_budget_s: Some(free.estimated_seconds * 0.9),
        ..Default::default()
    };
    let h = resolve(&hurried, &scene, probe(&scene)).unwrap();
    // Nine tenths of its time: doubled once.
    assert_eq!(
        (h.entries, h.clusters, h.paths_per_entry),
        (7680, 960, 9),
        "{:?}",
        h.reasons
    );
    let given = BakeConfig {
        clusters: Some(100),
        ..Default::default()
    };
    let p = resolve(&given, &scene, probe(&scene)).unwrap();
    // The cut entry points' walks go to those kept: twice 65536 in all, at most 32 each.
    assert_eq!((p.entries, p.clusters, p.paths_per_entry), (1536, 100, 32));
    assert!(p
        .reasons
        .iter()
        .any(|r| r.contains("at most 16 for each of the 100 clusters given")));
    // A memory budget that caps the clusters (the atlas stops shrinking at 96², what the 913
    // charts need, whose basis may take 2.25 MiB) caps the entries: 16 per cluster, never below
    // 1024.
    let tight = BakeConfig {
        memory_budget_mib: Some(2.5),
        ..Default::default()
    };
    let q = resolve(&tight, &scene, probe(&scene)).unwrap();
    assert_eq!(q.atlas, AtlasSize::Resolution(96), "{q:?}");
    assert!(q.entries < 3840, "{q:?}");
    assert_eq!(q.entries, (q.clusters * 16 / 256 * 256).max(1024), "{q:?}");
}

#[test]
fn probes_lit_through_the_panes_keep_the_smaller_disks() {
    let scene = cornell();
    let scale = |probes: Option<u32>, probe_rays: Option<u32>, near_rays: Option<u32>| {
        let cfg = BakeConfig {
            resolution: Some(64),
            probes,
            probe_rays,
            near_rays,
            ..Default::default()
        };
        resolve(&cfg, &scene, probe(&scene)).unwrap().vpl_disk_scale
    };
    // 64² texels × 32 near rays fit the hit budget: the larger disks, with probes or without.
    assert_eq!(scale(None, None, None), NEAR_FIELD_DISK_SCALE);
    assert_eq!(scale(Some(64), None, None), NEAR_FIELD_DISK_SCALE);
    // Probes without rays read the panes, which have no near field.
    assert_eq!(scale(Some(64), Some(0), None), NEAR_FIELD_DISK_SCALE_LARGE);
    // Without the near field the disks stay one radius whatever the probes.
    assert_eq!(scale(Some(64), Some(0), Some(0)), 1.0);
}

/// Every named preset plans on the bundled Cornell box with the default budgets: `high`'s
/// 1024 panes of 512² texels fit the default memory budget at the largest rank.
#[test]
fn every_preset_works_as_shipped() {
    let scene = cornell();
    for preset in [Preset::Preview, Preset::Default, Preset::Paper, Preset::High] {
        let cfg = BakeConfig {
            preset: Some(preset),
            ..Default::default()
        };
        let p = resolve(&cfg, &scene, probe(&scene)).unwrap_or_else(|e| panic!("{preset:?}: {e}"));
        if preset == Preset::High {
            assert_eq!(p.memory_budget_mib, DEFAULT_MEMORY_BUDGET_MIB);
        }
    }
}

/// A texel size far too small is refused naming `--texel-size`, not the options it was not
/// given.
#[test]
fn a_tiny_texel_size_names_texel_size() {
    let scene = cornell();
    let cfg = BakeConfig {
        texel_size: Some(1e-9),
        ..Default::default()
    };
    let e = resolve(&cfg, &scene, probe(&scene)).unwrap_err().to_string();
    assert!(e.contains("--texel-size") && !e.contains("--resolution"), "{e}");
}

/// The automatic top K's reason states arithmetic that holds, also when the residual groups
/// outnumber the panes a frame blends.
#[test]
fn the_top_k_reason_adds_up() {
    let r = top_k_reason(32, 48, 51, 1024);
    assert!(!r.contains("less 51"), "{r}");
    assert!(r.contains("at least 32"), "{r}");
    let r = top_k_reason(277, 341, 64, 1024);
    assert!(r.contains("341 panes") && r.contains("less 64"), "{r}");
    let r = top_k_reason(512, 1365, 64, 512);
    assert!(r.contains("every cluster"), "{r}");
    let r = top_k_reason(20, 1365, 5, 20);
    assert!(r.contains("every cluster"), "{r}");
}

/// `count` separate triangles (one chart each), 200 to a row 5 cm apart.
fn separate_triangles(count: usize) -> Scene {
    let dir = std::env::temp_dir().join(format!("prm-bake-charts-{}-{count}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let mut obj = String::new();
    for i in 0..count {
        let (x, z) = ((i % 200) as f32 * 0.05, (i / 200) as f32 * 0.05);
        obj.push_str(&format!("v {x} 0 {z}\nv {} 0 {z}\nv {x} 0 {}\n", x + 0.03, z + 0.03));
        obj.push_str(&format!("f {} {} {}\n", 3 * i + 1, 3 * i + 3, 3 * i + 2));
    }
    let path = dir.join("charts.obj");
    std::fs::write(&path, obj).unwrap();
    let scene = prm_scene::load(&path).unwrap();
    std::fs::remove_dir_all(&dir).unwrap();
    scene
}

#[test]
fn many_charts_fill_the_most_clusters() {
    // 3000 charts ask 12000 entry points; the chart rule takes 4 for each of the 2048 clusters,
    // and the doublings add none, though this scene of separate triangles bakes fast.
    let scene = separate_triangles(3000);
    let p = resolve(&BakeConfig::default(), &scene, probe(&scene)).unwrap();
    assert_eq!(
        (p.entries, p.clusters),
        (MAX_CHART_ENTRIES, MAX_AUTO_CLUSTERS),
        "{:?}",
        p.reasons
    );
    assert_eq!(p.entries, MANY_CHARTS_ENTRIES_PER_CLUSTER * p.clusters);
}

/// A scene of many small charts under a tight memory budget: the automatic atlas stops
/// shrinking at the size that holds every chart, so the bake can build the atlas the plan
/// promises.
#[test]
fn the_planned_atlas_holds_every_chart() {
    // 40,000 separate triangles over a 10 m square.
    let scene = separate_triangles(40_000);
    let cfg = BakeConfig {
        memory_budget_mib: Some(128.0),
        ..Default::default()
    };
    let p = resolve(&cfg, &scene, probe(&scene)).unwrap();
    let AtlasSize::Resolution(r) = p.atlas else {
        panic!("an automatic resolution")
    };
    let sizing = prm_scene::AtlasParams::with_sizing(prm_scene::Sizing::Resolution(r));
    Atlas::build(&scene, &sizing).unwrap_or_else(|e| panic!("the plan's {r}² atlas: {e}"));
}
