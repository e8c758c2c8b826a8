//! `cargo xtask eval --sky`: the sky (and a sun) against the reference tracer (its accuracy
//! targets), and what a change of the sky costs a frame.
//!
//! Cases, each baked with `prm-bake bake SCENE --sky` and played with `prm-play --headless
//! --sky ...`, against `prm-bake reference --sky ...` at the same camera, sky and sun:
//! - `scenes/courtyard` (a yard open to the sky) under a uniform blue sky with a low sun, and
//!   under a smooth environment map (written here: bright towards one side of the horizon and
//!   the zenith) turned by 40°, without a sun;
//! - the Dabrovic Sponza (`../shared/scenes`) under the uniform sky and a high sun, baked at the
//!   default settings as the target asks (about 300 s of the 600 s budget with the 1024 sky
//!   paths the budget gives),
//!   once more with `--seed 1` to show how far the seed moves it, and once more with
//!   `--sky-paths 256` to show the sky paths' noise.
//!
//! Errors are `../shared/notes/metrics.md`'s (`compare.rs`): the indirect image after a 4×4
//! downsample and the full image. The frame cost compares, on one renderer, frames whose sky
//! turns every frame with frames whose point light moves.

use anyhow::Result;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

use crate::compare;
use crate::emitters::run_cmd;
use crate::plan;

/// Image size and reference paths per pixel.
const SIZE: &str = "192x144";
const SPP: u32 = 1024;
/// Frames per timing.
const FRAMES: usize = 24;
/// The uniform sky (radiance, W/(m²·sr)).
const BLUE_SKY: &str = "0.4,0.6,1.0";

struct Case {
    name: &'static str,
    scene: PathBuf,
    camera: Option<&'static str>,
    bake_args: Vec<String>,
    /// Per row: label, then the lighting arguments both `prm-play` and `prm-bake reference`
    /// take (`--sky`, `--sky-rotation`, `--light`).
    rows: Vec<(&'static str, Vec<String>)>,
}

fn strings(v: &[&str]) -> Vec<String> {
    v.iter().map(|s| s.to_string()).collect()
}

/// Writes the courtyard's environment map (EXR, 128 × 64) under `cache`.
fn gradient_map(cache: &Path) -> Result<PathBuf> {
    let path = cache.join("sky-gradient.exr");
    let map = prm_scene::SkyMap::from_fn(128, 64, |d| {
        glam::Vec3::new(0.3, 0.5, 0.9) * d.y.max(0.0) * 1.5
            + glam::Vec3::new(1.2, 0.8, 0.4) * (0.5 + 0.5 * d.x).powi(2) * d.y.max(0.0).sqrt()
    });
    let rgb: Vec<[f32; 3]> = map.texels.iter().map(|t| t.to_array()).collect();
    std::fs::create_dir_all(cache)?;
    prm_scene::write_exr_rgb(&path, map.width, map.height, &rgb)?;
    Ok(path)
}

/// Where one case is played and traced: the binaries, the cache, the archive and its scene,
/// the camera, the image size and the reference's paths per pixel.
pub(crate) struct Playback<'a> {
    pub bake_bin: &'a Path,
    pub play_bin: PathBuf,
    pub cache: &'a Path,
    /// Names the reference cache (`cache/refs-NAME`).
    pub name: &'a str,
    pub archive: &'a Path,
    pub scene: &'a Path,
    pub camera: Option<&'a str>,
    pub size: &'a str,
    pub spp: u32,
}

/// What the playbacks of one evaluation share: the `prm-bake` binary (the `prm-play` beside it
/// plays), the cache, the name of the reference cache (`cache/refs-NAME`), and the image size and
/// the reference's paths per pixel.
#[derive(Clone, Copy)]
pub(crate) struct Bench<'a> {
    bake_bin: &'a Path,
    cache: &'a Path,
    name: &'a str,
    quality: (&'a str, u32),
}

impl<'a> Bench<'a> {
    /// The playbacks of the evaluation `name`, by the `prm-play` beside `bake_bin`, with the
    /// reference cache under `cache`, at `quality` (image size, reference paths per pixel).
    pub fn new(bake_bin: &'a Path, cache: &'a Path, name: &'a str, quality: (&'a str, u32)) -> Bench<'a> {
        Bench {
            bake_bin,
            cache,
            name,
            quality,
        }
    }
}

impl<'a> Playback<'a> {
    /// The playback on `bench` of `archive`, baked from `scene`, seen by `camera` (the scene's
    /// own without one).
    pub fn new(bench: Bench<'a>, archive: &'a Path, scene: &'a Path, camera: Option<&'a str>) -> Playback<'a> {
        let Bench {
            bake_bin,
            cache,
            name,
            quality: (size, spp),
        } = bench;
        Playback {
            bake_bin,
            play_bin: bake_bin.with_file_name(format!("prm-play{}", std::env::consts::EXE_SUFFIX)),
            cache,
            name,
            archive,
            scene,
            camera,
            size,
            spp,
        }
    }

    /// The archive played (indirect, then gi) with `play_args` into `out`, against the
    /// reference with `reference_args` (indirect-only, then full): the two comparisons.
    pub fn compare(
        &self,
        play_args: &[String],
        reference_args: &[String],
        out: &Path,
    ) -> Result<(compare::Metrics, compare::Metrics)> {
        let play = |mode: &str| self.play(play_args, mode, &out.join(mode));
        let reference = |indirect| reference_image(self, reference_args, indirect, None);
        let indirect = compare::compare_files(&play("indirect")?, &reference(true)?)?;
        let full = compare::compare_files(&play("gi")?, &reference(false)?)?;
        Ok((indirect, full))
    }

    /// The archive played headless in `mode` with `play_args` into `out`: the frame's EXR.
    pub fn play(&self, play_args: &[String], mode: &str, out: &Path) -> Result<PathBuf> {
        play_image(
            &self.play_bin,
            self.archive,
            self.camera,
            play_args,
            (self.size, mode),
            out,
        )
    }
}

/// A row of a table of cases played against their references: the case, its lighting `label`,
/// [`metric_cells`], the bake time and, on the case's first row (`row` 0) only, the frame costs.
pub(crate) fn case_row(
    case: &str,
    label: &str,
    (indirect, full): &(compare::Metrics, compare::Metrics),
    bake: &str,
    row: usize,
    frames: &str,
) -> String {
    let frames = if row == 0 { frames } else { "" };
    format!(
        "| {case} | {label} | {} | {bake} | {frames} |",
        metric_cells(indirect, full)
    )
}

/// The table cells of an indirect and a full comparison: indirect error (4×4), at full
/// resolution, energy, shape, full image error (4×4).
pub(crate) fn metric_cells(indirect: &compare::Metrics, full: &compare::Metrics) -> String {
    format!(
        "{:.2}% | {:.2}% | {:.3} | {:.2}% | {:.2}%",
        100.0 * indirect.error,
        100.0 * indirect.error_full,
        indirect.energy,
        100.0 * indirect.shape,
        100.0 * full.error
    )
}

/// The reference image of `p`'s scene (`p.spp` paths per pixel) with the extra `args`, indirect
/// light only or not, with `seed` (`None`: the tracer's default), cached under
/// `cache/refs-NAME`.
pub(crate) fn reference_image(p: &Playback, args: &[String], indirect: bool, seed: Option<u64>) -> Result<PathBuf> {
    let (bake_bin, cache, name, scene, camera, size, spp) =
        (p.bake_bin, p.cache, p.name, p.scene, p.camera, p.size, p.spp);
    let seed_key = seed.map(|s| format!("|{s}")).unwrap_or_default();
    let key = format!(
        "{}|{:?}|{camera:?}|{args:?}|{indirect}|{spp}|{size}{seed_key}|image{}",
        scene.display(),
        std::fs::metadata(scene).map(|m| m.len()).unwrap_or(0),
        crate::reference::IMAGE_EPOCH,
    );
    let dir = cache.join(format!("refs-{name}"));
    std::fs::create_dir_all(&dir)?;
    let path = dir.join(format!("{:016x}.exr", xxhash_rust::xxh3::xxh3_64(key.as_bytes())));
    if path.is_file() {
        return Ok(path);
    }
    let t = Instant::now();
    let mut cmd = Command::new(bake_bin);
    cmd.arg("reference").arg(scene).args(args);
    if let Some(c) = camera {
        cmd.args(["--camera", c]);
    }
    if let Some(s) = seed {
        cmd.args(["--seed", &s.to_string()]);
    }
    cmd.args(["--size", size, "--spp", &spp.to_string(), "-o"]).arg(&path);
    if indirect {
        cmd.arg("--indirect-only");
    }
    run_cmd(cmd, "prm-bake reference")?;
    println!(
        "{name}: {} reference ({}, {spp} paths per pixel{}) in {:.0} s",
        scene.display(),
        if indirect { "indirect" } else { "full" },
        seed.map(|s| format!(", seed {s}")).unwrap_or_default(),
        t.elapsed().as_secs_f64()
    );
    Ok(path)
}

/// Plays `archive` headless at `camera` with the extra `args` into `out` and returns the
/// frame's EXR.
fn play_image(
    play_bin: &Path,
    archive: &Path,
    camera: Option<&str>,
    args: &[String],
    (size, mode): (&str, &str),
    out: &Path,
) -> Result<PathBuf> {
    let mut cmd = Command::new(play_bin);
    cmd.arg(archive)
        .args(["--headless", "--size", size, "--mode", mode])
        .args(args);
    if let Some(c) = camera {
        cmd.args(["--camera", c]);
    }
    cmd.arg("--out").arg(out);
    run_cmd(cmd, "prm-play --headless")?;
    Ok(out.join("frame0000.exr"))
}

/// Mean frame times (ms) on one renderer of `archive`: the sky turning (and its intensity
/// changing) every frame, and a point light moving every frame instead; and the mean time of the
/// sky change alone (`Renderer::set_sky`: CPU dot products and uploads).
fn frame_costs(archive: &Path, scene_path: &Path) -> Result<(f64, f64, f64)> {
    let mut sky = prm_scene::Sky::parse(BLUE_SKY)?;
    crate::measure::change_costs(archive, scene_path, FRAMES, &mut |r, i| {
        sky.rotation = i as f32 * 0.3;
        sky.intensity = 0.5 + 0.5 * (i % 5) as f32 / 4.0;
        r.set_sky(&sky).expect("the archive has the sky's transfer");
    })
}

/// Runs the sky cases; returns the Markdown table.
pub fn run(bake_bin: &Path, cache: &Path, root: &Path, out: &Path) -> Result<String> {
    let map = gradient_map(cache)?;
    let mut cases = vec![Case {
        name: "courtyard",
        // The glTF: it has the camera.
        scene: root.join("scenes/courtyard/courtyard.gltf"),
        camera: None,
        bake_args: strings(&["--sky"]),
        rows: vec![
            (
                "blue sky + low sun",
                strings(&["--sky", BLUE_SKY, "--light", "dir:-0.3,-0.5,0.8:3,2.8,2.5"]),
            ),
            (
                "map turned 40°, no sun",
                vec![
                    "--sky".into(),
                    map.display().to_string(),
                    "--sky-rotation".into(),
                    "40".into(),
                ],
            ),
        ],
    }];
    let sponza = root.join("../shared/scenes/sponza-dabrovic/sponza.obj");
    if sponza.is_file() {
        cases.push(Case {
            name: "sponza",
            scene: sponza,
            camera: Some("14,3,0:-10,5,0:60"),
            bake_args: strings(&["--sky"]),
            rows: vec![
                (
                    "blue sky + high sun",
                    strings(&["--sky", BLUE_SKY, "--light", "dir:-0.25,-0.9,0.35:6,5.6,5"]),
                ),
                ("blue sky alone", strings(&["--sky", BLUE_SKY])),
                (
                    "high sun alone (no --sky)",
                    strings(&["--light", "dir:-0.25,-0.9,0.35:6,5.6,5"]),
                ),
            ],
        });
        // The same bake with another seed: how much of the error the seed moves.
        cases.push(Case {
            name: "sponza, --seed 1",
            scene: cases[1].scene.clone(),
            camera: cases[1].camera,
            bake_args: strings(&["--sky", "--seed", "1"]),
            rows: vec![cases[1].rows[0].clone()],
        });
        // The same bake with the fewest sky paths the plan gives (a budget the panes fill): how
        // much of the error is their noise.
        cases.push(Case {
            name: "sponza, --sky-paths 256",
            scene: cases[1].scene.clone(),
            camera: cases[1].camera,
            bake_args: strings(&["--sky", "--sky-paths", "256"]),
            rows: vec![("blue sky alone", strings(&["--sky", BLUE_SKY]))],
        });
    } else {
        println!("sky: {} is absent: sponza skipped", sponza.display());
    }
    let mut md = String::from(
        "| case | lighting | indirect error (4×4) | full res. | energy | shape | full image error (4×4) | bake s (sky step) | frame ms: sky turns / light moves |\n| --- | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: |\n",
    );
    let bench = Bench::new(bake_bin, cache, "sky", (SIZE, SPP));
    for case in &cases {
        let case_label = format!("sky-{}", case.name);
        let (baked, bake_s) = plan::bake_case(bake_bin, cache, &case_label, &case.scene, &case.bake_args)?;
        let sky_s = baked.report["timings"]["sky"].as_f64().unwrap_or(f64::NAN);
        println!("sky: {}: baked ({bake_s:.1} s, sky {sky_s:.1} s)", case.name);
        let (turned_ms, moved_ms, alone_ms) = frame_costs(&baked.archive, &case.scene)?;
        let playback = Playback::new(bench, &baked.archive, &case.scene, case.camera);
        let (bake, frames) = (
            format!("{bake_s:.1} ({sky_s:.1})"),
            format!("{turned_ms:.1} / {moved_ms:.1} ({alone_ms:.2} for the sky)"),
        );
        for (row, (label, lighting)) in case.rows.iter().enumerate() {
            let out = out.join(format!("{}-{row}", plan::case_name(&case_label)));
            let metrics = playback.compare(lighting, lighting, &out)?;
            let _ = writeln!(md, "{}", case_row(case.name, label, &metrics, &bake, row, &frames));
        }
    }
    Ok(md)
}
