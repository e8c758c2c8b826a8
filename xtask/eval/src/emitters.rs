//! `cargo xtask eval --emitters`: emissive surfaces against the reference tracer, at default
//! bake settings (its accuracy targets), and what a change of an emitter's scale costs a frame.
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

use crate::plan;
use crate::sky::{case_row, Bench, Playback};

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
pub(crate) fn run_cmd(mut cmd: Command, what: &str) -> Result<()> {
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

/// Mean frame times (ms) on one renderer of `archive`: the emitter scales changing every frame,
/// and a point light moving every frame instead (with the emitters on); and the mean time of the
/// scale change alone (`Renderer::set_emitter_scales`: CPU sums and uploads).
fn frame_costs(archive: &Path, scene_path: &Path) -> Result<(f64, f64, f64)> {
    let mut groups = None;
    crate::measure::change_costs(archive, scene_path, FRAMES, &mut |r, i| {
        let n = *groups.get_or_insert_with(|| r.runtime().emitters().len());
        let s = 0.5 + 0.5 * (i % 5) as f32 / 4.0;
        r.set_emitter_scales(&vec![[s, s, 1.0]; n]).expect("valid scales");
    })
}

/// Runs the emitter cases; returns the Markdown table.
pub fn run(bake_bin: &Path, cache: &Path, root: &Path, out: &Path) -> Result<String> {
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
    let bench = Bench::new(bake_bin, cache, "emitters", (SIZE, SPP));
    for case in &cases {
        let (baked, bake_s) = plan::bake_case(bake_bin, cache, &case.name, &case.scene, &[])?;
        println!("emitters: {}: baked ({:.1} s)", case.name, bake_s);
        let (scaled_ms, moved_ms, alone_ms) = frame_costs(&baked.archive, &case.scene)?;
        let playback = Playback::new(bench, &baked.archive, &case.scene, case.camera);
        let (bake, frames) = (
            format!("{bake_s:.1}"),
            format!("{scaled_ms:.1} / {moved_ms:.1} ({alone_ms:.2} for the scales)"),
        );
        for (row, scales) in case.scales.iter().enumerate() {
            let play_args: Vec<String> = scales
                .iter()
                .flat_map(|s| ["--emitter".to_string(), s.to_string()])
                .collect();
            let reference_args: Vec<String> = std::iter::once("--emitters".to_string())
                .chain(play_args.iter().cloned())
                .collect();
            let out = out.join(format!("{}-{row}", plan::case_name(&case.name)));
            let metrics = playback.compare(&play_args, &reference_args, &out)?;
            let label = if scales.is_empty() {
                "1".to_string()
            } else {
                scales.join(" ")
            };
            let _ = writeln!(md, "{}", case_row(&case.name, &label, &metrics, &bake, row, &frames));
        }
    }
    Ok(md)
}
