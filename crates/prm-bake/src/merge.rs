//! `prm-bake merge`: arguments → [`prm_bake::merge`] → one line of summary.

use anyhow::{Context, Result};
use std::path::PathBuf;

/// Arguments of `prm-bake merge`.
#[derive(clap::Args, Debug)]
pub struct MergeArgs {
    /// The partial archives, one per shard, in any order.
    #[arg(required = true, value_name = "PARTS")]
    pub parts: Vec<PathBuf>,
    /// The archive to write (replaced atomically; nothing is left behind on failure; missing
    /// directories are created). An existing file that is not an archive, or one of the parts,
    /// is not replaced.
    #[arg(short, long, value_name = "OUT.prm")]
    pub output: PathBuf,
    /// The scene the parts were baked from: then the merged archive's accuracy is estimated as
    /// a single bake's last step does, and recorded (the shards skip it).
    #[arg(long, value_name = "SCENE")]
    pub scene: Option<PathBuf>,
    /// Print nothing but errors.
    #[arg(long)]
    pub quiet: bool,
}

/// `prm-bake merge`.
pub fn run(args: &MergeArgs) -> Result<()> {
    // As for a bake: SIGINT, SIGTERM and SIGHUP remove the temporary file.
    crate::signals::install(prm_scene::check_destination(&args.output)?);
    let context = || {
        format!(
            "merging {} part{} into {}",
            args.parts.len(),
            prm_bake::params::plural(args.parts.len()),
            args.output.display()
        )
    };
    let merged = match &args.scene {
        None => prm_bake::merge(&args.parts, &args.output).with_context(context)?,
        Some(path) => {
            let scene = prm_scene::load(path).with_context(|| format!("cannot load scene {}", path.display()))?;
            let mut progress = crate::progress::Progress::new(args.quiet);
            let (merged, accuracy) =
                prm_bake::merge_checked(&args.parts, &args.output, &scene, &mut progress).with_context(context)?;
            progress.say(&format!("estimated accuracy: {}", prm_bake::accuracy_line(&accuracy)));
            merged
        }
    };
    if !args.quiet {
        outln!(
            "wrote {} ({} panes from {} shards, {:.2} MiB)",
            args.output.display(),
            merged.panes,
            merged.shards,
            merged.archive_bytes as f64 / (1024.0 * 1024.0)
        );
    }
    Ok(())
}
