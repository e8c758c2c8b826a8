//! `prm-bake`: bakes Precomputed Radiance Maps and inspects scenes and archives.

mod atlas;
mod dump;

use clap::{Parser, Subcommand};
use std::process::ExitCode;

/// Precomputed Radiance Maps: bake a static scene's indirect light for moving lights.
///
/// A bake gives every surface a lightmap atlas whose texel centres are the exit points, traces
/// random walks from sampled entry points, and stores, per cluster of entry points, the indirect
/// irradiance that unit irradiance on the cluster causes at every exit point.
#[derive(Parser)]
#[command(name = "prm-bake", version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Load a scene (OBJ or glTF), build its lightmap atlas and print statistics.
    ///
    /// Example: prm-bake atlas scenes/cornell-box/cornell-box.obj --resolution 256 --png charts.png
    Atlas(atlas::AtlasArgs),
    /// Inspect a .prm archive: summary, JSON, full verification or EXR export of its panes.
    ///
    /// Exit status 0 when the archive is good, 1 when it is damaged or the arguments are wrong.
    Dump(dump::DumpArgs),
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match &cli.command {
        Command::Atlas(args) => atlas::run(args),
        Command::Dump(args) => dump::run(args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}
