//! `prm-bake`: bakes Precomputed Radiance Maps (through the `prm_bake` library) and inspects
//! scenes and archives.

mod atlas;
mod bake;
mod check;
mod dump;
mod merge;
mod progress;
mod reference;
mod signals;

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
    /// Bake a scene into a .prm archive (atlas, entry points, walks, clusters, panes).
    ///
    /// Without sizes, the bake derives them from the scene and the budgets and says why.
    /// Emissive materials (OBJ Ke, glTF emissiveFactor) are baked as emitter groups whose
    /// direct and indirect light the player scales at run time (prm-play --emitter); --sky also
    /// bakes the sky's transfer, so that any sky lights the archive (prm-play --sky).
    /// Example: prm-bake bake scenes/cornell-box/cornell-box.gltf -o out/cornell-box.prm
    Bake(Box<bake::BakeArgs>),
    /// Join the partial archives of a sharded bake (`bake --shard I/N`) into one archive.
    ///
    /// Refuses parts of different scenes, seeds, parameters or backends, and a missing or
    /// repeated shard. CPU-baked shards merge into exactly the bytes a single bake writes; with
    /// --scene the merged archive's accuracy is checked and recorded as a single bake's is.
    /// Example: prm-bake merge part-0.prm part-1.prm -o out/scene.prm --scene scene.obj
    Merge(merge::MergeArgs),
    /// Load a scene (OBJ or glTF), build its lightmap atlas and print statistics.
    ///
    /// Example: prm-bake atlas scenes/cornell-box/cornell-box.obj --resolution 256 --png charts.png
    Atlas(atlas::AtlasArgs),
    /// Estimate an archive's accuracy as a bake's last step does: its indirect light, played
    /// as prm-play plays it, against the reference path tracer under three test lights.
    ///
    /// For a merged sharded bake (whose shards skip the check) or at another size than the
    /// bake's. Needs the scene the archive was baked from; refuses another.
    /// Example: prm-bake check scenes/cornell-box/cornell-box.gltf out/cornell-box.prm
    Check(check::CheckArgs),
    /// Inspect a .prm archive: summary, JSON, full verification or EXR export of its panes.
    ///
    /// Without --verify it reads the header, the section table and the metadata; --verify also
    /// reads every pane and section and checks their checksums. Exit status 0 when what was
    /// read is good, 1 when it is damaged or cannot be read, 2 when the arguments are wrong.
    Dump(dump::DumpArgs),
    /// Reference path tracer: ground-truth image or lightmap (EXR) under given lights.
    ///
    /// Example: prm-bake reference scenes/cornell-box/cornell-box.obj
    /// --light point:0.278,0.5,0.2795:0.2347,0.1566,0.0418 --spp 256 -o ref.exr
    Reference(reference::ReferenceArgs),
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    // Every subcommand is headless.
    prm_gpu::silence_wayland_probe();
    let result = match &cli.command {
        Command::Bake(args) => bake::run(args),
        Command::Atlas(args) => atlas::run(args),
        Command::Check(args) => check::run(args),
        Command::Dump(args) => dump::run(args),
        Command::Merge(args) => merge::run(args),
        Command::Reference(args) => reference::run(args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `--sky` alone leaves the paths per texel to the plan; `--sky-paths N` takes N.
    #[test]
    fn sky_flag_leaves_the_paths_to_the_plan() {
        let sky = |args: &[&str]| match Cli::parse_from([&["prm-bake", "bake", "s.obj", "-o", "o.prm"], args].concat())
            .command
        {
            Command::Bake(b) => (b.config().sky, b.config().sky_paths),
            _ => unreachable!("a bake"),
        };
        assert_eq!(sky(&["--sky"]), (Some(true), None));
        assert_eq!(sky(&["--sky", "--sky-paths", "64"]), (Some(true), Some(64)));
        assert_eq!(sky(&[]), (None, None));
        assert!(Cli::try_parse_from(["prm-bake", "bake", "s.obj", "-o", "o.prm", "--sky-paths", "64"]).is_err());
    }

    /// `--probes` alone takes the library's cell budget; `--probes N` takes N.
    #[test]
    fn probes_flag_defaults_to_the_library_budget() {
        let cells =
            |args: &[&str]| match Cli::parse_from([&["prm-bake", "bake", "s.obj", "-o", "o.prm"], args].concat())
                .command
            {
                Command::Bake(b) => b.config().probes,
                _ => unreachable!("a bake"),
            };
        assert_eq!(cells(&["--probes"]), Some(prm_bake::PROBE_CELLS));
        assert_eq!(cells(&["--probes", "64"]), Some(64));
        assert_eq!(cells(&[]), None);
    }
}
