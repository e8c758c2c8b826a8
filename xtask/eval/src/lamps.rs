//! `cargo xtask eval --lamps`: the large scenes' lamps of `--targets` (0.4 m from a ceiling and
//! from a wall, [`targets::near_surface_lamps`]), each moved to the [`MOVES`] nearby positions
//! along its surface, played by the default bake that `--targets` caches, against
//! [`SPP`]-path references. The table gives the mean 4×4 image error over the positions, the
//! worst, and the energy's mean and range. One position's error moves by a few points when the
//! lamp moves a fifth of a metre, as its irradiance peak falls on other entry points, so plans
//! are compared on the mean. `--only CASE` runs the scenes whose name contains CASE.

use anyhow::Result;
use glam::Vec3;
use std::fmt::Write as _;
use std::path::Path;

use crate::sky::{reference_image, Bench, Playback};
use crate::{compare, plan, targets};

/// Reference paths per pixel: the mean over the positions averages the references' noise too
/// (one 256-path reference of Sponza under its ceiling lamp is 3–4% off after the downsample).
const SPP: u32 = 256;

/// The lamp's moves along its surface, metres along the surface's two [`axes`].
const MOVES: [(f32, f32); 6] = [(0.0, 0.0), (0.2, 0.0), (-0.2, 0.0), (0.0, 0.2), (0.0, -0.2), (0.3, 0.3)];

/// Two axes along the surface a lamp faces (`towards` it): x and z under a ceiling; by a
/// wall, the horizontal axis along it and y.
fn axes(towards: Vec3) -> [Vec3; 2] {
    if towards.y.abs() > 0.5 {
        [Vec3::X, Vec3::Z]
    } else if towards.z.abs() > 0.5 {
        [Vec3::X, Vec3::Y]
    } else {
        [Vec3::Z, Vec3::Y]
    }
}

/// Runs the scenes (those whose name contains `only`, when given); returns the Markdown table.
pub fn run(bake_bin: &Path, cache: &Path, root: &Path, out: &Path, only: Option<&str>) -> Result<String> {
    let mut md = String::from(
        "| case | lamp | positions | mean error (4×4) | worst | energy: mean (range) |\n| --- | --- | ---: | ---: | ---: | ---: |\n",
    );
    let shared = root.join("../shared/scenes");
    let chosen = targets::LARGE_SCENES
        .into_iter()
        .filter(|l| only.is_none_or(|o| l.0.contains(o)));
    for (name, file, camera, bases) in chosen {
        let scene = shared.join(file);
        if !scene.is_file() {
            println!("lamps: {} is absent: {name} skipped", scene.display());
            let _ = writeln!(md, "| {name} | absent ({}): skipped | | | | |", scene.display());
            continue;
        }
        let (baked, _) = plan::bake_case(bake_bin, cache, &targets::bake_name(name), &scene, &[])?;
        let bench = Bench::new(bake_bin, cache, "lamps", ("256x192", SPP));
        let playback = Playback::new(bench, &baked.archive, &scene, Some(camera));
        for (row, lamp) in targets::near_surface_lamps(&scene, bases)?.iter().enumerate() {
            let [a, b] = axes(lamp.towards);
            let mut measured = Vec::with_capacity(MOVES.len());
            for (i, (da, db)) in MOVES.into_iter().enumerate() {
                let args = ["--light".to_string(), lamp.spec(a * da + b * db)];
                let dir = out.join(format!("{}-{row}-{i}", plan::case_name(name)));
                let played = playback.play(&args, "indirect", &dir)?;
                let reference = reference_image(&playback, &args, true, Some(1))?;
                measured.push(compare::compare_files(&played, &reference)?);
            }
            let n = measured.len() as f64;
            let error = measured.iter().map(|m| m.error).sum::<f64>() / n;
            let worst = measured.iter().map(|m| m.error).fold(0.0, f64::max);
            let energy = measured.iter().map(|m| m.energy).sum::<f64>() / n;
            let low = measured.iter().map(|m| m.energy).fold(f64::INFINITY, f64::min);
            let high = measured.iter().map(|m| m.energy).fold(0.0, f64::max);
            let target = targets::LARGE;
            let most = target.energy.unwrap_or(f64::INFINITY);
            let _ = writeln!(
                md,
                "| {name} | {} | {} | {} | {:.1}% | {} ({low:.3}..{high:.3}) |",
                lamp.label,
                measured.len(),
                targets::against(
                    format!("{:.1}%", 100.0 * error),
                    Some(error <= target.error),
                    format!("≤ {:.0}%", 100.0 * target.error)
                ),
                100.0 * worst,
                targets::against(
                    format!("{energy:.3}"),
                    Some((energy - 1.0).abs() <= most),
                    format!("±{:.0}%", 100.0 * most)
                ),
            );
            println!(
                "lamps: {name} {}: mean {:.2}% (4x4), energy {energy:.3}",
                lamp.label,
                100.0 * error
            );
        }
    }
    Ok(md)
}
