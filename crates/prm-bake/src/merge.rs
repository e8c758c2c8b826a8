//! `prm-bake merge`: arguments → [`prm_bake::merge`] → one line of summary.

use anyhow::{Context, Result};
use std::path::PathBuf;

/// Arguments of `prm-bake merge`.
#[derive(clap::Args, Debug)]
pub struct MergeArgs {
    /// The partial archives, one per shard, in any order.
    #[arg(required = true, value_name = "PARTS")]
    pub parts: Vec<PathBuf>,
    /// The archive to write (replaced atomically; nothing is left behind on failure).
    #[arg(short, long, value_name = "OUT.prm")]
    pub output: PathBuf,
    /// Print nothing but errors.
    #[arg(long)]
    pub quiet: bool,
}

/// `prm-bake merge`.
pub fn run(args: &MergeArgs) -> Result<()> {
    // As for a bake: SIGINT, SIGTERM and SIGHUP remove the temporary file.
    crate::signals::install(prm_format::check_destination(&args.output)?);
    let merged = prm_bake::merge(&args.parts, &args.output)
        .with_context(|| format!("merging {} parts into {}", args.parts.len(), args.output.display()))?;
    if !args.quiet {
        println!(
            "wrote {} ({} panes from {} shards, {:.2} MiB)",
            args.output.display(),
            merged.panes,
            merged.shards,
            merged.archive_bytes as f64 / (1024.0 * 1024.0)
        );
    }
    Ok(())
}
