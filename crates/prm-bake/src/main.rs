//! `prm-bake`: bakes Precomputed Radiance Maps (through the `prm_bake` library) and inspects
//! scenes and archives.

/// `println!` that stops printing quietly when standard output is closed (`prm-bake atlas x.obj
/// | head -1`): the command still finishes and exits as it would have.
macro_rules! outln {
    ($($arg:tt)*) => {{
        use std::io::Write as _;
        let _ = writeln!(std::io::stdout().lock(), $($arg)*);
    }};
}

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
#[command(name = "prm-bake", version, about, long_about = None, after_help = EXIT_STATUS)]
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
    #[command(after_help = EXIT_STATUS)]
    Bake(Box<bake::BakeArgs>),
    /// Join the partial archives of a sharded bake (`bake --shard I/N`) into one archive.
    ///
    /// Refuses parts of different scenes, seeds, parameters or backends, and a missing or
    /// repeated shard. CPU-baked shards merge into exactly the bytes a single bake writes; with
    /// --scene the merged archive's accuracy is checked and recorded as a single bake's is.
    /// Example: prm-bake merge part-0.prm part-1.prm -o out/scene.prm --scene scene.obj
    #[command(after_help = EXIT_STATUS)]
    Merge(merge::MergeArgs),
    /// Load a scene (OBJ or glTF), build its lightmap atlas and print statistics.
    ///
    /// Example: prm-bake atlas scenes/cornell-box/cornell-box.obj --resolution 256 --png charts.png
    #[command(after_help = EXIT_STATUS)]
    Atlas(atlas::AtlasArgs),
    /// Estimate an archive's accuracy as a bake's last step does: its indirect light, played
    /// as prm-play plays it, against the reference path tracer under four test lights, one of them close under the ceiling.
    ///
    /// For a merged sharded bake (whose shards skip the check) or at another size than the
    /// bake's. Needs the scene the archive was baked from; refuses another.
    /// Example: prm-bake check scenes/cornell-box/cornell-box.gltf out/cornell-box.prm
    #[command(after_help = EXIT_STATUS)]
    Check(check::CheckArgs),
    /// Inspect a .prm archive: summary, JSON, full verification or EXR export of its panes.
    ///
    /// Without --verify it reads the header, the section table and the metadata; --verify also
    /// reads every pane and section and checks their checksums: exit status 1 when the archive
    /// is damaged or cannot be read.
    #[command(after_help = EXIT_STATUS)]
    Dump(dump::DumpArgs),
    /// Reference path tracer: ground-truth image or lightmap (EXR) under given lights.
    ///
    /// Example: prm-bake reference scenes/cornell-box/cornell-box.obj
    /// --light point:0.278,0.5,0.2795:0.2347,0.1566,0.0418 --spp 256 -o ref.exr
    #[command(after_help = EXIT_STATUS)]
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
            ExitCode::from(exit_status(&e))
        }
    }
}

/// The exit statuses, as `--help` states them.
const EXIT_STATUS: &str = "Exit status: 0 success; 2 the command was refused before any work (a wrong argument \
or parameter, an output that may not be written, a path that is no scene file: nothing was written); 1 a failure \
during the work (an unreadable or damaged input, the GPU).";

/// An argument refused before any work: exit status 2.
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct Refused(pub String);

/// Returns early with a [`Refused`] error (exit status 2) from a `format!` message.
macro_rules! refuse {
    ($($arg:tt)*) => {
        return Err(anyhow::Error::new(crate::Refused(format!($($arg)*))))
    };
}
pub(crate) use refuse;

/// The exit status of a failed command: 2 when it was refused before any work (a wrong argument,
/// parameters the bake cannot do, an output that may not be written, a scene path that names no
/// scene file: nothing was written), 1 when work failed (an input that cannot be read, a
/// damaged archive, the GPU). Clap's own refusals exit 2 as well.
fn exit_status(e: &anyhow::Error) -> u8 {
    use prm_bake::BakeError;
    use prm_scene::SceneError;
    let refused = e.chain().any(|c| {
        c.is::<Refused>()
            || matches!(
                c.downcast_ref::<BakeError>(),
                Some(
                    BakeError::InvalidParams(_)
                        | BakeError::OverLimit(_)
                        | BakeError::ConfigParse { .. }
                        | BakeError::Destination(_)
                )
            )
            || matches!(
                c.downcast_ref::<prm_format::Error>(),
                Some(prm_format::Error::Destination { .. })
            )
            || matches!(
                c.downcast_ref::<SceneError>(),
                Some(
                    SceneError::NotFound(_)
                        | SceneError::IsDirectory(_)
                        | SceneError::Stdin
                        | SceneError::UnsupportedFormat(_)
                )
            )
    });
    if refused {
        2
    } else {
        1
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

    /// Values refused before any work exit 2 with clap's message naming the option, and
    /// negative coordinates are values (`reference --camera -1,...`).
    #[test]
    fn bad_values_are_refused_up_front_with_status_2() {
        let bake = |extra: &[&str]| {
            Cli::try_parse_from([&["prm-bake", "bake", "s.obj", "-o", "o.prm"][..], extra].concat()).map(|_| ())
        };
        for args in [
            &["--top-k", "0"][..],
            &["--entries", "0"],
            &["--clusters", "0"],
            &["--resolution", "1"],
            &["--paths-per-entry", "0"],
        ] {
            let e = bake(args).unwrap_err();
            assert_eq!(e.exit_code(), 2, "{args:?}: {e}");
            assert!(e.to_string().contains(args[0]), "{args:?}: {e}");
        }
        let reference = |extra: &[&str]| Cli::try_parse_from([&["prm-bake", "reference", "s.obj"][..], extra].concat());
        if let Err(e) = reference(&[
            "--camera",
            "-1,0.5,-2:0,0.5,0:40",
            "--light",
            "point:-1,1,-1:1,1,1",
            "-o",
            "r.exr",
        ]) {
            panic!("negative coordinates: {e}");
        }
        let e = reference(&["--size", "-5x5"]).map(|_| ()).unwrap_err();
        assert!(
            e.to_string().contains("--size") && !e.to_string().contains("unexpected argument"),
            "{e}"
        );
    }

    /// Refusals of arguments and parameters exit 2; failures of the work exit 1.
    #[test]
    fn exit_status_tells_refusals_from_failures() {
        let params = prm_bake::BakeError::InvalidParams("--entries must be at least 1".into());
        assert_eq!(exit_status(&anyhow::Error::new(params).context("planning")), 2);
        assert_eq!(exit_status(&anyhow::Error::new(Refused("--report".into()))), 2);
        let missing = prm_scene::SceneError::NotFound("x.obj".into());
        assert_eq!(exit_status(&anyhow::Error::new(missing)), 2);
        assert_eq!(exit_status(&anyhow::anyhow!("the GPU was lost")), 1);
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
