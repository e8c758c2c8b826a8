//! `cargo xtask eval --emitters`: emissive surfaces against the reference tracer, at default
//! bake settings (issue #15's targets), and what a change of an emitter's scale costs a frame.
//!
//! Cases, each baked with `prm-bake bake SCENE` and played with `prm-play --headless` (no
//! punctual light), against `prm-bake reference --emitters` at the same camera and scales:
//! - McGuire's `CornellBox-Original` lit only by its own ceiling lamp (`../shared/scenes`);
//! - `scenes/cornell-box-lamps` (our Cornell box lit by two small ceiling lamps of different
//!   colours, two emitter groups), at scales 1 and 1, then the warm one dimmed and the blue one
//!   tinted.
//!
//! Errors are `../shared/notes/metrics.md`'s (`compare.rs`): the indirect image after a 4×4
//! downsample (target ≤ 5%) and the full image (≤ 3%). The frame cost compares, in one run on one
//! renderer, frames whose emitter scales change every frame with frames whose point light moves.

use anyhow::{bail, Context, Result};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

use crate::compare;
use crate::plan::{self, SceneSpec};

/// Reference paths per pixel: its noise after the downsample stays under a fifth of the
/// errors measured (0.2–0.4% against 5–11%).
const SPP: u32 = 1024;
/// Image size and the McGuire boxes' camera (metrics.md).
const SIZE: &str = "256x256";
const MCGUIRE_CAMERA: &str = "0,1,3.6:0,1,0:40";
/// Frames per timing.
const FRAMES: usize = 24;

struct Case {
    name: String,
    scene: PathBuf,
    camera: Option<&'static str>,
    /// `--emitter` specs, one set per row.
    scales: Vec<Vec<&'static str>>,
}

/// Runs `cmd`, failing with its output.
fn run_cmd(mut cmd: Command, what: &str) -> Result<()> {
    let out = cmd.output().with_context(|| format!("starting {what}"))?;
    if !out.status.success() {
        bail!(
            "{what} failed ({}):\n{}{}",
            out.status,
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        );
    }
    Ok(())
}

/// The reference image (cached under `cache/refs-emitters` by scene stamp, camera, scales and
/// mode).
fn reference(bake_bin: &Path, cache: &Path, case: &Case, scales: &[&str], indirect: bool) -> Result<PathBuf> {
    let key = format!(
        "{}|{:?}|{:?}|{scales:?}|{indirect}|{SPP}|{SIZE}",
        case.scene.display(),
        std::fs::metadata(&case.scene).map(|m| m.len()).unwrap_or(0),
        case.camera
    );
    let dir = cache.join("refs-emitters");
    std::fs::create_dir_all(&dir)?;
    let path = dir.join(format!("{:016x}.exr", xxhash_rust::xxh3::xxh3_64(key.as_bytes())));
    if path.is_file() {
        return Ok(path);
    }
    let t = Instant::now();
    let mut cmd = Command::new(bake_bin);
    cmd.arg("reference").arg(&case.scene).arg("--emitters");
    for s in scales {
        cmd.arg("--emitter").arg(s);
    }
    if let Some(c) = case.camera {
        cmd.args(["--camera", c]);
    }
    cmd.args(["--size", SIZE, "--spp", &SPP.to_string(), "-o"]).arg(&path);
    if indirect {
        cmd.arg("--indirect-only");
    }
    run_cmd(cmd, "prm-bake reference")?;
    println!(
        "emitters:   reference ({}) in {:.0} s",
        if indirect { "indirect" } else { "full" },
        t.elapsed().as_secs_f64()
    );
    Ok(path)
}

/// Plays `archive` headless into `out` and returns the frame's EXR.
fn play(play_bin: &Path, archive: &Path, case: &Case, scales: &[&str], mode: &str, out: &Path) -> Result<PathBuf> {
    let mut cmd = Command::new(play_bin);
    cmd.arg(archive).args(["--headless", "--size", SIZE, "--mode", mode]);
    if let Some(c) = case.camera {
        cmd.args(["--camera", c]);
    }
    for s in scales {
        cmd.arg("--emitter").arg(s);
    }
    cmd.arg("--out").arg(out);
    run_cmd(cmd, "prm-play --headless")?;
    Ok(out.join("frame0000.exr"))
}

/// Mean frame times (ms) on one renderer of `archive`: the emitter scales changing every frame,
/// and a point light moving every frame instead (with the emitters on); and the mean time of the
/// scale change alone (`Renderer::set_emitter_scales`: CPU sums and uploads).
fn frame_costs(archive: &Path, scene_path: &Path) -> Result<(f64, f64, f64)> {
    let (mut r, scene) = crate::measure::renderer(archive, scene_path, 32)?;
    let groups = r.runtime().emitters().len();
    let camera = prm_play::default_camera(&scene);
    let b = scene.bounds();
    let mode = prm_play::Mode::Gi;
    let time = |r: &mut prm_play::Renderer,
                f: &mut dyn FnMut(&mut prm_play::Renderer, usize) -> Vec<prm_scene::Light>|
     -> Result<f64> {
        let mut total = 0.0;
        for i in 0..FRAMES + 2 {
            let t = Instant::now();
            let lights = f(r, i);
            r.render(&prm_play::FrameInput {
                camera,
                lights: &lights,
                mode,
            })?;
            if i >= 2 {
                total += t.elapsed().as_secs_f64();
            }
        }
        Ok(total * 1e3 / FRAMES as f64)
    };
    let light_at = |i: usize| prm_scene::Light::Point {
        position: b.min + b.extent() * glam::Vec3::new(0.2 + 0.6 * (i % 7) as f32 / 6.0, 0.7, 0.5),
        intensity: glam::Vec3::splat(0.05 * b.diagonal() * b.diagonal()),
    };
    let mut alone = 0.0;
    let scaled = time(&mut r, &mut |r, i| {
        let s = 0.5 + 0.5 * (i % 5) as f32 / 4.0;
        let t = Instant::now();
        r.set_emitter_scales(&vec![[s, s, 1.0]; groups]).expect("valid scales");
        if i >= 2 {
            alone += t.elapsed().as_secs_f64();
        }
        vec![light_at(0)]
    })?;
    let moved = time(&mut r, &mut |_, i| vec![light_at(i)])?;
    Ok((scaled, moved, alone * 1e3 / FRAMES as f64))
}

/// Runs the emitter cases; returns the Markdown table.
pub fn run(bake_bin: &Path, cache: &Path, root: &Path, out: &Path) -> Result<String> {
    let play_bin = bake_bin.with_file_name(format!("prm-play{}", std::env::consts::EXE_SUFFIX));
    let mut cases = Vec::new();
    let original = root.join("../shared/scenes/cornell-box/CornellBox-Original.obj");
    if original.is_file() {
        cases.push(Case {
            name: "CornellBox-Original, its own lamp".into(),
            scene: original,
            camera: Some(MCGUIRE_CAMERA),
            scales: vec![vec![]],
        });
    } else {
        println!("emitters: {} is absent: the McGuire box is skipped", original.display());
    }
    cases.push(Case {
        name: "Cornell box, two lamps".into(),
        // The glTF: its emissive materials and camera.
        scene: root.join("scenes/cornell-box-lamps/cornell-box-lamps.gltf"),
        camera: None,
        scales: vec![vec![], vec!["lamp_warm=0.25", "lamp_blue=1,0.5,2"]],
    });
    let mut md = String::from(
        "| case | scales | indirect error (4×4) | full res. | energy | shape | full image error (4×4) | bake s | frame ms: scales change / light moves |\n| --- | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: |\n",
    );
    for case in &cases {
        let spec = SceneSpec::new(
            &case.name.replace([' ', ','], "-"),
            case.scene.clone(),
            vec![],
            Default::default(),
            SPP,
        );
        let t = Instant::now();
        let baked = plan::bake(bake_bin, cache, &spec, &[], None, false)?;
        let bake_s = baked.report["timings"]["total"]
            .as_f64()
            .unwrap_or(t.elapsed().as_secs_f64());
        println!("emitters: {}: baked ({:.1} s)", case.name, bake_s);
        let (scaled_ms, moved_ms, alone_ms) = frame_costs(&baked.archive, &case.scene)?;
        for (row, scales) in case.scales.iter().enumerate() {
            let dir = out.join(format!("{}-{row}", spec.name));
            let ind = play(
                &play_bin,
                &baked.archive,
                case,
                scales,
                "indirect",
                &dir.join("indirect"),
            )?;
            let gi = play(&play_bin, &baked.archive, case, scales, "gi", &dir.join("gi"))?;
            let ri = reference(bake_bin, cache, case, scales, true)?;
            let rf = reference(bake_bin, cache, case, scales, false)?;
            let mi = compare::compare_files(&ind, &ri)?;
            let mf = compare::compare_files(&gi, &rf)?;
            let label = if scales.is_empty() {
                "1".to_string()
            } else {
                scales.join(" ")
            };
            let _ = writeln!(
                md,
                "| {} | {label} | {:.2}% | {:.2}% | {:.3} | {:.2}% | {:.2}% | {bake_s:.1} | {} |",
                case.name,
                100.0 * mi.error,
                100.0 * mi.error_full,
                mi.energy,
                100.0 * mi.shape,
                100.0 * mf.error,
                if row == 0 {
                    format!("{scaled_ms:.1} / {moved_ms:.1} ({alone_ms:.2} for the scales)")
                } else {
                    String::new()
                }
            );
        }
    }
    Ok(md)
}
