//! What the evaluation runs: scenes, lights, cameras and the settings swept around the automatic choice.

use anyhow::{bail, Context, Result};
use std::path::{Path, PathBuf};
use std::process::Command;

/// Quick (CI) or full (the committed charts) evaluation.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Mode {
    Quick,
    Full,
}

/// Factors and values swept around the automatic choice, one parameter at a time.
#[derive(Clone, Debug, Default)]
pub struct Sweep {
    pub entries: Vec<f64>,
    pub clusters: Vec<f64>,
    pub resolution: Vec<f64>,
    pub paths_per_entry: Vec<f64>,
    pub vpl_disk_scale: Vec<f32>,
    pub top_k: Vec<u32>,
    pub presets: Vec<&'static str>,
}

/// One scene of the evaluation.
#[derive(Clone, Debug)]
pub struct SceneSpec {
    pub name: String,
    pub path: PathBuf,
    /// Extra arguments of every bake of this scene (e.g. a smaller `--time-budget`).
    pub base_args: Vec<String>,
    /// Light positions as fractions of the scene bounds.
    pub light_fractions: Vec<[f32; 3]>,
    /// Camera spec, or the scene's own / a view of its bounds.
    pub camera: Option<String>,
    pub sweep: Sweep,
    /// Reference paths per texel (lightmap) and per pixel (image).
    pub lightmap_spp: u32,
    /// Lightmap errors are measured over at most this many exit points (an even stride through
    /// them), so that the reference can afford more paths per texel.
    pub lightmap_texels: usize,
    pub image_spp: u32,
    /// Image size of the error images (the frame time is always measured at 1024×768).
    pub image_size: (u32, u32),
}

impl SceneSpec {
    /// A scene baked with no extra arguments, seen from its own camera (or a view of its bounds),
    /// its references taking `spp` paths per texel and per pixel over as many texels, at 96×72.
    pub fn new(name: &str, path: PathBuf, light_fractions: Vec<[f32; 3]>, sweep: Sweep, spp: u32) -> SceneSpec {
        SceneSpec {
            name: name.into(),
            path,
            base_args: vec![],
            light_fractions,
            camera: None,
            sweep,
            lightmap_spp: spp,
            lightmap_texels: spp as usize,
            image_spp: spp,
            image_size: (96, 72),
        }
    }
}

/// Light positions for box-like rooms lit from inside, above the furniture: centre near the
/// ceiling, left front, right back.
const ROOM_LIGHTS: [[f32; 3]; 3] = [[0.5, 0.85, 0.5], [0.2, 0.7, 0.3], [0.8, 0.7, 0.75]];

/// The scenes of `mode`; shared scenes are skipped (with a message) when `../shared/scenes` is absent.
pub fn scenes(mode: Mode, root: &Path) -> Vec<SceneSpec> {
    let full_sweep = Sweep {
        entries: vec![0.5, 2.0],
        clusters: vec![0.25, 4.0],
        resolution: vec![0.5, 1.25],
        paths_per_entry: vec![0.25, 2.0],
        vpl_disk_scale: vec![0.0],
        top_k: vec![4, 8, 16, u32::MAX],
        presets: vec!["preview", "paper"],
    };
    // The few settings that the quick run and the largest scene afford.
    let small_sweep = Sweep {
        resolution: vec![0.5],
        top_k: vec![8, u32::MAX],
        presets: vec!["preview"],
        ..Default::default()
    };
    let cornell = root.join("scenes/cornell-box/cornell-box.gltf");
    if mode == Mode::Quick {
        let sweep = Sweep {
            paths_per_entry: vec![0.25],
            ..small_sweep
        };
        return vec![SceneSpec {
            image_size: (64, 48),
            ..SceneSpec::new("cornell-box", cornell, ROOM_LIGHTS.to_vec(), sweep, 1024)
        }];
    }
    let budget = || vec!["--time-budget".into(), "20".into()];
    let mut out = vec![
        SceneSpec::new("cornell-box", cornell, ROOM_LIGHTS.to_vec(), full_sweep.clone(), 2048),
        SceneSpec {
            base_args: budget(),
            ..SceneSpec::new(
                "chairs",
                root.join("scenes/chairs/chairs.gltf"),
                ROOM_LIGHTS.to_vec(),
                full_sweep.clone(),
                2048,
            )
        },
    ];
    let shared = root.join("../shared/scenes");
    if !shared.is_dir() {
        println!(
            "eval: {} is absent: skipping the shared scenes (CornellBox-Sphere, sponza)",
            shared.display()
        );
        return out;
    }
    let sphere_lights = vec![[0.5, 0.8, 0.5], [0.25, 0.7, 0.3], [0.75, 0.7, 0.7]];
    let sphere_sweep = Sweep {
        presets: vec!["preview"],
        ..full_sweep.clone()
    };
    let sphere = shared.join("cornell-box/CornellBox-Sphere.obj");
    out.push(SceneSpec {
        base_args: budget(),
        ..SceneSpec::new("CornellBox-Sphere", sphere, sphere_lights, sphere_sweep, 2048)
    });
    let sponza_lights = vec![[0.5, 0.45, 0.5], [0.3, 0.2, 0.5], [0.7, 0.12, 0.45]];
    let sponza_sweep = Sweep {
        clusters: vec![0.25],
        ..small_sweep
    };
    let sponza = shared.join("sponza-dabrovic/sponza.obj");
    out.push(SceneSpec {
        base_args: budget(),
        camera: Some("14,3,0:-10,5,0:60".into()),
        lightmap_texels: 2048,
        ..SceneSpec::new("sponza", sponza, sponza_lights, sponza_sweep, 1024)
    });
    out
}

/// The bake parameters the automatic choice made (from `prm-bake bake --plan --report`).
/// A point light at `fraction` of `scene`'s bounds, as a light spec and parsed, with the
/// eval's warm white intensity scaled by the bounds' diagonal squared (so that scenes of every
/// size get comparable irradiance).
pub fn point_light(scene: &prm_scene::Scene, fraction: [f32; 3]) -> Result<(String, prm_scene::Light)> {
    let b = scene.bounds();
    let p = b.min + (b.max - b.min) * glam::Vec3::from_array(fraction);
    let i = light_intensity(scene);
    let s = format!("point:{},{},{}:{},{},{}", p.x, p.y, p.z, i.x, i.y, i.z);
    let l = prm_trace::parse_light(&s).map_err(|e| anyhow::anyhow!("light {s}: {e}"))?;
    Ok((s, l))
}

/// The eval's warm white point-light intensity for `scene`, scaled by its bounds' diagonal
/// squared.
pub fn light_intensity(scene: &prm_scene::Scene) -> glam::Vec3 {
    let d = scene.bounds().diagonal();
    glam::Vec3::new(1.0, 0.9, 0.75) * 0.3 * d * d
}

#[derive(Clone, Copy, Debug)]
pub struct Params {
    pub entries: u32,
    pub clusters: u32,
    pub resolution: u32,
    pub paths_per_entry: u32,
    pub top_k: u32,
    pub vpl_disk_scale: f32,
}

impl Params {
    /// Reads the `params` of a bake report (a `--plan` report is the params alone).
    pub fn from_report(report: &serde_json::Value) -> Result<Params> {
        let p = if report["params"].is_object() {
            &report["params"]
        } else {
            report
        };
        let u = |v: &serde_json::Value, what: &str| -> Result<u32> {
            v.as_u64()
                .map(|x| x as u32)
                .with_context(|| format!("bake report lacks {what}"))
        };
        let resolution = match report["atlas"]["resolution"].as_u64() {
            Some(r) => r as u32,
            None => u(&p["atlas"]["Resolution"], "params.atlas.Resolution")?,
        };
        Ok(Params {
            entries: u(&p["entries"], "params.entries")?,
            clusters: u(&p["clusters"], "params.clusters")?,
            resolution,
            paths_per_entry: u(&p["paths_per_entry"], "params.paths_per_entry")?,
            top_k: u(&p["top_k"], "params.top_k")?,
            vpl_disk_scale: p["vpl_disk_scale"].as_f64().unwrap_or(1.0) as f32,
        })
    }

    pub fn args(&self) -> Vec<String> {
        vec![
            "--entries".into(),
            self.entries.to_string(),
            "--clusters".into(),
            self.clusters.to_string(),
            "--resolution".into(),
            self.resolution.to_string(),
            "--paths-per-entry".into(),
            self.paths_per_entry.to_string(),
            "--top-k".into(),
            self.top_k.to_string(),
        ]
    }
}

/// One bake of a scene: its arguments and, for the K sweep, the run-time K values played from it.
#[derive(Clone, Debug)]
pub struct BakeSpec {
    /// Setting label (`auto`, `entries=512`, `preset=paper`, ...).
    pub label: String,
    /// Which parameter this point varies (`auto`, `entries`, `clusters`, ..., `preset`).
    pub group: &'static str,
    pub args: Vec<String>,
    /// A `--config` TOML file's contents, if any.
    pub config: Option<String>,
}

/// The bakes of a scene around the automatic choice `auto` (the first bake is the automatic one).
pub fn bakes(scene: &SceneSpec, auto: &Params) -> Vec<BakeSpec> {
    let mut out = vec![BakeSpec {
        label: "auto".into(),
        group: "auto",
        args: scene.base_args.clone(),
        config: None,
    }];
    let mut push = |group: &'static str, label: String, p: Params, config: Option<String>| {
        if out.iter().any(|b| b.label == label) {
            return;
        }
        out.push(BakeSpec {
            label,
            group,
            args: p.args(),
            config,
        });
    };
    let scale = |v: u32, f: f64| ((v as f64 * f).round() as u32).max(1);
    let s = &scene.sweep;
    for &f in &s.entries {
        let e = scale(auto.entries, f);
        if e != auto.entries && e >= auto.clusters {
            push("entries", format!("entries={e}"), Params { entries: e, ..*auto }, None);
        }
    }
    for &f in &s.clusters {
        let c = scale(auto.clusters, f).min(auto.entries).min(2048);
        if c != auto.clusters {
            let top_k = auto.top_k.min(c);
            push(
                "clusters",
                format!("clusters={c}"),
                Params {
                    clusters: c,
                    top_k,
                    ..*auto
                },
                None,
            );
        }
    }
    for &f in &s.resolution {
        let r = (scale(auto.resolution, f) / 8 * 8).max(32);
        if r != auto.resolution {
            push(
                "resolution",
                format!("resolution={r}"),
                Params { resolution: r, ..*auto },
                None,
            );
        }
    }
    for &f in &s.paths_per_entry {
        let m = scale(auto.paths_per_entry, f);
        if m != auto.paths_per_entry {
            push(
                "paths_per_entry",
                format!("paths_per_entry={m}"),
                Params {
                    paths_per_entry: m,
                    ..*auto
                },
                None,
            );
        }
    }
    for &v in &s.vpl_disk_scale {
        if v != auto.vpl_disk_scale {
            push(
                "vpl_disk_scale",
                format!("vpl_disk_scale={v}"),
                *auto,
                Some(format!("vpl_disk_scale = {v:?}\n")),
            );
        }
    }
    for &name in &s.presets {
        out.push(BakeSpec {
            label: format!("preset={name}"),
            group: "preset",
            args: vec!["--preset".into(), name.into()],
            config: None,
        });
    }
    out
}

/// A finished (or cached) bake.
#[derive(Clone, Debug)]
pub struct Baked {
    pub archive: PathBuf,
    pub report: serde_json::Value,
}

fn file_stamp(path: &Path) -> String {
    match std::fs::metadata(path) {
        Ok(m) => format!(
            "{}:{:?}",
            m.len(),
            m.modified()
                .ok()
                .and_then(|t| t.duration_since(std::time::UNIX_EPOCH).ok())
        ),
        Err(_) => "missing".into(),
    }
}

/// Part of every cached bake's key: bump it when what a bake writes for the same arguments
/// changes, so cached bakes are redone and the eval never measures a stale archive.
const CACHE_VERSION: u32 = 29;

/// A case's label as a file name: spaces and punctuation as dashes.
pub fn case_name(label: &str) -> String {
    label.replace([' ', ',', '(', ')', '='], "-")
}

/// The default bake of `scene` with `args` for one case of an eval mode (cached under
/// [`case_name`] of `label`), through [`bake`]: the result and the bake's seconds (its
/// report's, else the wall time of this call).
pub fn bake_case(bin: &Path, cache: &Path, label: &str, scene: &Path, args: &[String]) -> Result<(Baked, f64)> {
    let spec = SceneSpec::new(&case_name(label), scene.to_path_buf(), vec![], Default::default(), 0);
    let t = std::time::Instant::now();
    let baked = bake(bin, cache, &spec, args, None, false)?;
    let seconds = baked.report["timings"]["total"]
        .as_f64()
        .unwrap_or(t.elapsed().as_secs_f64());
    Ok((baked, seconds))
}

/// Runs `prm-bake bake` for `spec` (extra arguments `extra`), or reuses the cached result under
/// `cache` keyed by [`CACHE_VERSION`], the scene file, the arguments and the config.
pub fn bake(
    bin: &Path,
    cache: &Path,
    scene: &SceneSpec,
    args: &[String],
    config: Option<&str>,
    plan_only: bool,
) -> Result<Baked> {
    let key_text = format!(
        "{CACHE_VERSION}|{}|{}|{}|{}|{}",
        scene.path.display(),
        file_stamp(&scene.path),
        args.join(" "),
        config.unwrap_or(""),
        plan_only
    );
    let key = xxhash_rust::xxh3::xxh3_64(key_text.as_bytes());
    let dir = cache.join("bakes");
    std::fs::create_dir_all(&dir)?;
    let stem = format!("{}-{key:016x}{}", scene.name, if plan_only { "-plan" } else { "" });
    let archive = dir.join(format!("{stem}.prm"));
    let report_path = dir.join(format!("{stem}.json"));
    let log = dir.join(format!("{stem}.log"));
    let done = report_path.is_file() && (plan_only || archive.is_file());
    if !done {
        let mut cmd = Command::new(bin);
        cmd.arg("bake").arg(&scene.path).arg("-o").arg(&archive);
        cmd.arg("--report").arg(&report_path).args(args);
        if plan_only {
            cmd.arg("--plan");
        } else {
            cmd.arg("--quiet");
        }
        if let Some(text) = config {
            let toml = dir.join(format!("{stem}.toml"));
            std::fs::write(&toml, text)?;
            cmd.arg("--config").arg(&toml);
        }
        let output = cmd.output().with_context(|| format!("starting {}", bin.display()))?;
        let mut text = output.stdout.clone();
        text.extend_from_slice(&output.stderr);
        std::fs::write(&log, &text)?;
        if !output.status.success() {
            let _ = std::fs::remove_file(&report_path);
            bail!(
                "prm-bake bake {} {} failed ({}):\n{}",
                scene.path.display(),
                args.join(" "),
                output.status,
                String::from_utf8_lossy(&text)
            );
        }
        let _ = std::fs::write(dir.join(format!("{stem}.args")), &key_text);
    }
    let report: serde_json::Value = serde_json::from_slice(
        &std::fs::read(&report_path).with_context(|| format!("reading {}", report_path.display()))?,
    )
    .with_context(|| format!("parsing {}", report_path.display()))?;
    Ok(Baked { archive, report })
}
