//! `prm-bake check`: the bake's accuracy estimate of an archive already written
//! ([`prm_bake::estimate_accuracy`]), printed as `dump` shows it or as JSON.

use anyhow::{Context, Result};
use prm_bake::EstimateSize;
use std::path::PathBuf;

use crate::progress::Progress;

/// Arguments of `prm-bake check`.
#[derive(clap::Args, Debug)]
pub struct CheckArgs {
    /// The scene the archive was baked from (.obj with its .mtl, .gltf or .glb).
    pub scene: PathBuf,
    /// The archive to check.
    pub archive: PathBuf,
    /// Points compared with the reference, drawn at random by surface area with the bake's
    /// seed: each the mean of the 3×3 texels around it.
    #[arg(long, value_name = "N", default_value_t = EstimateSize::DEFAULT.exit_points)]
    pub accuracy_points: u32,
    /// Reference paths per point and light, shared by its texels: the reference's noise is
    /// removed from the estimate, more paths only narrow its spread.
    #[arg(long, value_name = "PATHS", default_value_t = EstimateSize::DEFAULT.paths)]
    pub accuracy_paths: u32,
    /// A test light instead of the check's own, repeatable: `point:X,Y,Z:R,G,B` (as `prm-play
    /// --light`; the check measures each light alone, so its colour does not matter). Only
    /// point lights: the check's lights shine every way.
    #[arg(long = "light", value_name = "SPEC", value_parser = prm_scene::parse_light, allow_hyphen_values = true)]
    pub lights: Vec<prm_scene::Light>,
    /// Print the estimate as one JSON object (the archive metadata's `accuracy`).
    #[arg(long)]
    pub json: bool,
    /// No progress on stderr.
    #[arg(long)]
    pub quiet: bool,
}

/// `prm-bake check`.
pub fn run(args: &CheckArgs) -> Result<()> {
    if args.accuracy_points == 0 || args.accuracy_paths == 0 {
        crate::refuse!("--accuracy-points and --accuracy-paths must be at least 1");
    }
    let mut positions = Vec::with_capacity(args.lights.len());
    for light in &args.lights {
        match light {
            prm_scene::Light::Point { position, .. } => positions.push(*position),
            _ => crate::refuse!("--light: the check places point lights only (point:X,Y,Z:R,G,B)"),
        }
    }
    let scene = prm_scene::load(&args.scene).with_context(|| format!("cannot load scene {}", args.scene.display()))?;
    let mut progress = Progress::new(args.quiet);
    for w in &scene.report.warnings {
        progress.warn(w);
    }
    let size = EstimateSize {
        exit_points: args.accuracy_points,
        paths: args.accuracy_paths,
    };
    let lights = (!positions.is_empty()).then_some(positions.as_slice());
    let accuracy = prm_bake::estimate_accuracy(&scene, &args.archive, size, lights, &mut progress)
        .with_context(|| format!("checking {} against {}", args.archive.display(), args.scene.display()))?;
    accuracy.validate().map_err(|e| anyhow::anyhow!("no estimate: {e}"))?;
    if args.json {
        outln!("{}", serde_json::to_string_pretty(&accuracy)?);
    } else {
        crate::dump::write_accuracy(&mut std::io::stdout().lock(), "estimated accuracy: ", &accuracy)?;
    }
    Ok(())
}
