//! `cargo xtask eval --budget`: the error budget of the default bake, one idealised stage at a time.
//!
//! The cases: the Cornell box with the light under the ceiling and low near a wall, chairs,
//! McGuire's CornellBox-Sphere and, as the large shared scene, the Dabrovic Sponza (its bakes
//! plan under `--time-budget` [`LARGE_TIME_BUDGET`]: the whole budget takes about 35 minutes).
//! For every case (a scene and one light) the default bake (`prm-bake bake SCENE`, release; on a
//! machine without a GPU `--backend auto` renders panes with the native CPU evaluator) is played
//! as shipped, then each stage of the chain is replaced by its ideal while the others stay as
//! shipped:
//!
//! | row | what changes | how |
//! | --- | --- | --- |
//! | as played | nothing | the player's lightmap (`prm_play::Renderer::read_lightmap`) |
//! | K = all | no top-K truncation | the same archive played with K = every cluster |
//! | no near field | not an ideal: the panes alone, without the near field the player gathers back | `prm_play::NearLight::Off` |
//! | ray-cast entry irradiance | exact visibility at the entry points instead of shadow maps | the archive's panes blended on the CPU, weights from `prm_trace::bounded_irradiance` (K = all), plus the near field with ray-cast direct light |
//! | no entry-point bound | the entry disk bound `ENTRY_DISK` off | as above with disk 0 |
//! | exact-visibility panes | a shadow ray per exit point and VPL instead of shared ones | `--backend cpu-exact` |
//! | depth-map panes | not an ideal: the GPU path's hemicube depth maps (lavapipe here; not on the large scene) | `--backend vulkan` |
//! | unclustered | one pane per entry point | `--clusters = --entries`, K = all |
//! | no VPL bound | plain `1/r²` | `vpl_disk_scale = 0` |
//! | 4× walks | four times the walks per entry point | `--paths-per-entry ×4` |
//! | 2× atlas | twice the atlas resolution | `--resolution ×2` (its own reference) |
//! | all but the bounds | unclustered, exact visibility and 4× walks together | `--backend cpu-exact`, K = all |
//!
//! Every row is measured in lightmap space against `prm_trace::ReferenceTracer` at an even
//! stride of the atlas's exit points, and split into the energy bias (Σ PRM / Σ ref − 1), the
//! shape error (what is left after the best global scale) and the reference's own noise, and
//! located: the share of the squared error at exit points within 1.5 texels of an edge of the
//! geometry (a neighbour surface facing more than 60° away), and the error farther than 4 texels
//! from any edge. The table goes to `budget.md` in the output directory; the README quotes it.

use anyhow::{bail, Context, Result};
use glam::Vec3;
use prm_play::{FrameInput, Mode as PlayMode};
use prm_scene::Light;
use std::fmt::Write as _;
use std::path::Path;
use std::time::Instant;

use crate::plan::{self, Params, SceneSpec};
use crate::reference::{Reference, Tracer};

/// Reference paths per exit point and exit points measured per case.
const SPP: u32 = 4096;
const TEXELS: usize = 2048;

/// One case: a scene and the light (fractions of its bounds) that lights it.
struct Case {
    scene: SceneSpec,
    light_name: &'static str,
    light_fraction: [f32; 3],
    /// The large scene: no lavapipe row (hours on 2 cores).
    large: bool,
}

/// The large shared scene's bakes plan under this time budget (`--time-budget`, seconds)
/// instead of the default 600 s, so that its ten bakes take about 10 minutes.
const LARGE_TIME_BUDGET: &str = "60";

/// Exit points closer than this to an edge (in texels) are "at an edge"; farther than
/// [`INTERIOR`] they are "away from edges".
const EDGE: f32 = 1.5;
const INTERIOR: f32 = 4.0;

/// The measured exit points of one atlas resolution and their reference.
struct Measured {
    texels: Vec<u32>,
    reference: Reference,
    /// Distance of every measured exit point to the nearest exit point on a surface facing
    /// another way (more than 60° apart: an edge of the geometry), in texels.
    edge: Vec<f32>,
}

/// Error of one row against its reference, over the measured exit points.
#[derive(Clone, Copy, Debug)]
struct Split {
    error: f64,
    energy: f64,
    shape: f64,
    noise: f64,
    /// Share of the squared error at exit points within [`EDGE`] texels of an edge.
    edge_share: f64,
    /// The error over the exit points farther than [`INTERIOR`] texels from an edge (NaN if
    /// there are none: every texel of a coarse atlas of a detailed scene is near an edge).
    interior: f64,
}

fn split(test: &[Vec3], m: &Measured) -> Split {
    let reference = &m.reference;
    let (mut d2, mut r2, mut t2, mut tr, mut st, mut sr, mut var) = (0.0f64, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0);
    let (mut edge_d2, mut in_d2, mut in_r2) = (0.0f64, 0.0f64, 0.0f64);
    for (((t, r), v), e) in test.iter().zip(&reference.mean).zip(&reference.variance).zip(&m.edge) {
        let (t, r) = (t.as_dvec3(), r.as_dvec3());
        let d = (t - r).length_squared();
        if *e < EDGE {
            edge_d2 += d;
        } else if *e >= INTERIOR {
            in_d2 += d;
            in_r2 += r.length_squared();
        }
        d2 += d;
        r2 += r.length_squared();
        t2 += t.length_squared();
        tr += t.dot(r);
        st += t.element_sum();
        sr += r.element_sum();
        var += v.element_sum() as f64;
    }
    // The best global scale s = t·r / t·t leaves ‖s t − r‖² = r² − (t·r)² / t².
    let shape = ((r2 - tr * tr / t2.max(1e-300)).max(0.0) / r2).sqrt();
    Split {
        error: (d2 / r2).sqrt(),
        energy: st / sr,
        shape,
        noise: (var / r2).sqrt(),
        edge_share: edge_d2 / d2.max(1e-300),
        interior: if in_r2 > 0.0 { (in_d2 / in_r2).sqrt() } else { f64::NAN },
    }
}

fn cases(root: &Path) -> Vec<Case> {
    let mut out = Vec::new();
    let cornell = || {
        SceneSpec::new(
            "cornell-box",
            root.join("scenes/cornell-box/cornell-box.gltf"),
            vec![],
            Default::default(),
            SPP,
        )
    };
    out.push(Case {
        scene: cornell(),
        light_name: "under the ceiling",
        light_fraction: [0.5, 0.85, 0.5],
        large: false,
    });
    out.push(Case {
        scene: cornell(),
        light_name: "low near the red wall",
        light_fraction: [0.12, 0.35, 0.5],
        large: false,
    });
    out.push(Case {
        scene: SceneSpec::new(
            "chairs",
            root.join("scenes/chairs/chairs.obj"),
            vec![],
            Default::default(),
            SPP,
        ),
        light_name: "above the chairs",
        light_fraction: [0.5, 0.75, 0.5],
        large: false,
    });
    let sphere = root.join("../shared/scenes/cornell-box/CornellBox-Sphere.obj");
    if sphere.is_file() {
        out.push(Case {
            scene: SceneSpec::new("CornellBox-Sphere", sphere, vec![], Default::default(), SPP),
            light_name: "under the ceiling",
            light_fraction: [0.5, 0.8, 0.5],
            large: false,
        });
    } else {
        println!("budget: {} is absent: CornellBox-Sphere skipped", sphere.display());
    }
    let sponza = root.join("../shared/scenes/sponza-dabrovic/sponza.obj");
    if sponza.is_file() {
        out.push(Case {
            scene: SceneSpec {
                base_args: vec!["--time-budget".into(), LARGE_TIME_BUDGET.into()],
                ..SceneSpec::new("sponza", sponza, vec![], Default::default(), SPP)
            },
            light_name: "in the atrium, time budget 60 s",
            light_fraction: [0.5, 0.45, 0.5],
            large: true,
        });
    } else {
        println!("budget: {} is absent: sponza skipped", sponza.display());
    }
    out
}

/// The lightmaps the player computes for `light` at `texels`, one per run-time K in `ks`, from
/// one renderer.
fn played_each(archive: &Path, scene_path: &Path, ks: &[u32], light: Light, texels: &[u32]) -> Result<Vec<Vec<Vec3>>> {
    let (mut r, scene) = crate::measure::renderer(archive, scene_path, ks[0])?;
    r.resize(64, 48);
    let lights = [light];
    ks.iter()
        .map(|&k| {
            r.set_top_k(k);
            r.render(&FrameInput {
                camera: prm_play::default_camera(&scene),
                lights: &lights,
                mode: PlayMode::Gi,
            })?;
            let lm = r.read_lightmap()?;
            Ok(texels.iter().map(|&t| Vec3::from_array(lm[t as usize])).collect())
        })
        .collect()
}

/// [`played_each`] for one K.
fn played(archive: &Path, scene_path: &Path, top_k: u32, light: Light, texels: &[u32]) -> Result<Vec<Vec3>> {
    Ok(played_each(archive, scene_path, &[top_k], light, texels)?.remove(0))
}

/// The archive's panes blended on the CPU at `texels`, every cluster weighed by its members'
/// ray-cast direct irradiance (bounded by a disk of `entry_disk · A/(Nπ)`) and pane energy, as
/// the run time's weights pass does with shadow maps.
fn cpu_blend(archive: &Path, tracer: &Tracer, light: Light, texels: &[u32], entry_disk: f32) -> Result<Vec<Vec3>> {
    let a = prm_format::Archive::open(archive).with_context(|| format!("opening {}", archive.display()))?;
    let entries = a.entries().to_vec();
    let clusters = a.clusters().to_vec();
    let energy: Vec<Vec3> = a
        .entry_energy()
        .context("the archive has no entry energies: re-bake it")?
        .iter()
        .map(|e| Vec3::from_array(*e))
        .collect();
    let area: f32 = tracer.scene.triangles.iter().map(|t| t.area()).sum();
    let disk = entry_disk * area / (entries.len() as f32 * std::f32::consts::PI);
    let lights = [light];
    let weights = prm_trace::archive_weights(
        &tracer.bvh,
        &lights,
        &entries,
        &energy,
        &clusters,
        disk,
        a.entry_cells(),
    );
    // The near field as the player sums it (`prm_trace::NearPlay`, over the atlas's texels),
    // with ray-cast direct light: each pane with its deeper share's series.
    let near = a.near_field().cloned();
    let side = a.atlas().resolution;
    let identity: Vec<u32> = (0..side * side).collect();
    let model = near
        .as_ref()
        .map(|n| prm_trace::NearPlay::new(n, &identity, texels, prm_trace::NEAR_GATHERS));
    let mut out = vec![Vec3::ZERO; texels.len()];
    for (c, &w) in weights.iter().enumerate() {
        if w == Vec3::ZERO {
            continue;
        }
        let pane = a.read_pane(c)?;
        let played = match &model {
            Some(m) => m.series(&pane.iter().map(|v| Vec3::from_array(*v)).collect::<Vec<_>>()),
            None => texels.iter().map(|&t| Vec3::from_array(pane[t as usize])).collect(),
        };
        for (o, v) in out.iter_mut().zip(played) {
            *o += w * v;
        }
    }
    if let Some(m) = &model {
        for (o, add) in out.iter_mut().zip(m.direct(&tracer.bvh, &lights)) {
            *o += add;
        }
    }
    Ok(out)
}

/// Runs every case and returns the markdown table.
pub fn run(bin: &Path, cache: &Path, root: &Path) -> Result<String> {
    let mut md = String::new();
    let _ = writeln!(
        md,
        "| case | stage made ideal | error | energy | shape error | ref. noise | error² at edges | error away from edges | bake s |\n| --- | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: |"
    );
    for case in cases(root) {
        let spec = &case.scene;
        let started = Instant::now();
        let scene = prm_scene::load(&spec.path).with_context(|| format!("loading {}", spec.path.display()))?;
        let tracer = Tracer::new(
            &scene,
            crate::reference::scene_key(&spec.path, &scene),
            cache.join("refs"),
        )?;
        let (light_spec, light) = plan::point_light(&scene, case.light_fraction)?;
        let auto_bake = plan::bake(bin, cache, spec, &spec.base_args, None, false)?;
        let auto = Params::from_report(&auto_bake.report)?;
        let name = format!("{}, light {}", spec.name, case.light_name);
        println!(
            "budget: {name}: {} entries, {} clusters, {}², {} walks/entry, K {}",
            auto.entries, auto.clusters, auto.resolution, auto.paths_per_entry, auto.top_k
        );
        // The measured exit points of one resolution, and their reference.
        let measured = |resolution: u32| -> Result<Measured> {
            let atlas = tracer.atlas(resolution)?;
            let stride = atlas.exits.len().div_ceil(TEXELS).max(1);
            let exits: Vec<_> = atlas.exits.iter().step_by(stride).copied().collect();
            let reference = tracer.lightmap(resolution, &exits, &light_spec, &light, SPP)?;
            if reference.seconds > 0.0 {
                println!("budget:   reference {resolution}²: {:.1} s", reference.seconds);
            }
            let edge = exits
                .iter()
                .map(|x| {
                    let d2 = atlas
                        .exits
                        .iter()
                        .filter(|y| y.normal.dot(x.normal) < 0.5)
                        .map(|y| (y.position - x.position).length_squared())
                        .fold(f32::INFINITY, f32::min);
                    d2.sqrt() / atlas.stats.texel_size
                })
                .collect();
            Ok(Measured {
                texels: exits.iter().map(|x| x.texel).collect(),
                reference,
                edge,
            })
        };
        let base = measured(auto.resolution)?;
        let texels = &base.texels;
        let bake_s = |b: &plan::Baked| b.report["timings"]["total"].as_f64().unwrap_or(f64::NAN);
        let mut row = |stage: &str, test: &[Vec3], m: &Measured, seconds: f64| {
            let s = split(test, m);
            let interior = if s.interior.is_nan() {
                "none".to_string()
            } else {
                format!("{:.1}%", 100.0 * s.interior)
            };
            let line = format!(
                "| {name} | {stage} | {:.1}% | {:.3} | {:.1}% | {:.1}% | {:.0}% | {interior} | {seconds:.1} |",
                100.0 * s.error,
                s.energy,
                100.0 * s.shape,
                100.0 * s.noise,
                100.0 * s.edge_share,
            );
            println!("budget: {line}");
            md.push_str(&line);
            md.push('\n');
        };
        let t_auto = bake_s(&auto_bake);
        let a = &auto_bake.archive;
        let auto_played = played_each(a, &spec.path, &[auto.top_k, auto.clusters], light, texels)?;
        row("(none: as played)", &auto_played[0], &base, t_auto);
        row("K = all", &auto_played[1], &base, t_auto);
        if prm_format::Archive::open(a)?.near_field().is_some() {
            let (mut r, scene) = crate::measure::renderer_with(
                a,
                &spec.path,
                prm_play::RuntimeOptions {
                    top_k: auto.top_k,
                    near_light: prm_play::NearLight::Off,
                    ..Default::default()
                },
            )?;
            r.resize(64, 48);
            r.render(&FrameInput {
                camera: prm_play::default_camera(&scene),
                lights: &[light],
                mode: PlayMode::Gi,
            })?;
            let lm = r.read_lightmap()?;
            let off: Vec<Vec3> = texels.iter().map(|&t| Vec3::from_array(lm[t as usize])).collect();
            row("(not ideal) no near field, as played", &off, &base, t_auto);
        }
        let exact = cpu_blend(a, &tracer, light, texels, prm_scene::ENTRY_DISK)?;
        row("ray-cast entry irradiance, K = all", &exact, &base, t_auto);
        let unbounded = cpu_blend(a, &tracer, light, texels, 0.0)?;
        row("  and no entry-point bound", &unbounded, &base, t_auto);

        let variant = |args: Vec<String>, config: Option<&str>| plan::bake(bin, cache, spec, &args, config, false);
        let backend = |b: &str| {
            let mut args = auto.args();
            args.extend(["--backend".into(), b.into()]);
            args
        };
        let unclustered = Params {
            clusters: auto.entries,
            top_k: auto.entries,
            ..auto
        };
        let walks = Params {
            paths_per_entry: auto.paths_per_entry * 4,
            ..auto
        };
        // (stage, bake arguments, config, K played) at the default resolution.
        let mut stages = vec![("exact-visibility panes", backend("cpu-exact"), None, auto.top_k)];
        if !case.large {
            stages.push((
                "(not ideal) depth-map panes on lavapipe",
                backend("vulkan"),
                None,
                auto.top_k,
            ));
        }
        // One pane per entry point must fit prm-bake's default run-time memory budget (256 MiB
        // of RGB9E5 panes; the player has no cap of its own on the pane count).
        let pane_mib = f64::from(auto.resolution).powi(2) * 4.0 / (1024.0 * 1024.0);
        let unclustered_fits = f64::from(auto.entries) * pane_mib <= 256.0;
        if unclustered_fits {
            stages.push(("unclustered, K = all", unclustered.args(), None, auto.entries));
        } else {
            println!(
                "budget:   unclustered skipped: {} panes of {}² (over the 256 MiB memory budget)",
                auto.entries, auto.resolution
            );
        }
        stages.push(("no VPL bound", auto.args(), Some("vpl_disk_scale = 0.0\n"), auto.top_k));
        stages.push(("4× walks", walks.args(), None, auto.top_k));
        if unclustered_fits {
            let mut ideal = Params {
                clusters: auto.entries,
                top_k: auto.entries,
                ..walks
            }
            .args();
            ideal.extend(["--backend".into(), "cpu-exact".into()]);
            stages.push((
                "unclustered, exact visibility and 4× walks, K = all",
                ideal,
                None,
                auto.entries,
            ));
        }
        for (stage, args, config, k) in stages {
            let b = variant(args, config)?;
            let test = played(&b.archive, &spec.path, k, light, texels)?;
            row(stage, &test, &base, bake_s(&b));
        }
        let fine = Params {
            resolution: auto.resolution * 2,
            ..auto
        };
        // Twice the resolution is four times the panes' memory, past the default budgets on
        // every case (the Cornell box's 512 panes of 512² need 512 MiB; Sponza's 240 of 1024²
        // 960 MiB), resident and in the archive: this stage is an ideal, so they are raised.
        let budgets = Some("memory_budget_mib = 4096\narchive_budget_mib = 4096\n");
        let b = variant(fine.args(), budgets)?;
        let fine_measured = measured(fine.resolution)?;
        row(
            "2× atlas resolution",
            &played(&b.archive, &spec.path, auto.top_k, light, &fine_measured.texels)?,
            &fine_measured,
            bake_s(&b),
        );
        println!("budget: {name} done in {:.0} s", started.elapsed().as_secs_f64());
    }
    if md.lines().count() <= 2 {
        bail!("the budget measured nothing");
    }
    Ok(md)
}
