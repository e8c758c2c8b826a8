//! The README's quick start and build-server commands, run as written: every command of the
//! shell blocks in its "Quick start" and "Bake on a build server" sections, in the repository
//! root, in order, each expected to exit 0.
//!
//! `prm-bake` and `prm-play` stand for the binaries of this build (dev profile; the README runs
//! them in release, which changes only the time). Window commands (`prm-play` without
//! `--headless` or `--export`) are left out: they run until the window is closed; the window
//! test in `prm-play` covers them.

use std::path::{Path, PathBuf};
use std::process::Command;

use prm_tests::repo;

/// The shell commands of the ```sh blocks in the README's `## Quick start` section, comments
/// removed.
fn quick_start_commands(readme: &str) -> Vec<String> {
    let start = readme
        .find("\n## Quick start")
        .expect("the README has a Quick start section");
    // The Bevy section's command is run by bevy_prm's own tests.
    let end = ["\n## Use it in Bevy", "\n## Commands"]
        .iter()
        .filter_map(|h| readme[start..].find(h))
        .min()
        .map_or(readme.len(), |e| start + e);
    let mut commands = Vec::new();
    let mut in_block = false;
    for line in readme[start..end].lines() {
        match line.trim() {
            "```sh" => in_block = true,
            "```" => in_block = false,
            text if in_block && !text.is_empty() => {
                let command = text.split(" #").next().unwrap_or(text).trim();
                commands.push(command.to_string());
            }
            _ => {}
        }
    }
    commands
}

/// A window command: the player without `--headless` or `--export`.
fn opens_a_window(words: &[&str]) -> bool {
    words[0] == "prm-play" && !words.iter().any(|w| *w == "--headless" || *w == "--export")
}

fn binary(dir: &Path, name: &str) -> PathBuf {
    dir.join(format!("{name}{}", std::env::consts::EXE_SUFFIX))
}

/// The directory the dev-profile binaries of this workspace are built into.
fn binary_dir() -> PathBuf {
    let target = std::env::var_os("CARGO_TARGET_DIR")
        .map(PathBuf::from)
        .map(|p| if p.is_absolute() { p } else { repo(".").join(p) })
        .unwrap_or_else(|| repo("target"));
    target.join("debug")
}

#[test]
fn the_readme_quick_start_and_build_server_commands_run_as_written() {
    let root = repo(".");
    let readme = std::fs::read_to_string(root.join("README.md")).expect("README.md");
    let commands = quick_start_commands(&readme);
    assert!(
        commands.iter().any(|c| c.starts_with("prm-bake bake")),
        "no bake command found in the README's quick start: {commands:?}"
    );
    let built = Command::new(env!("CARGO"))
        .args(["build", "--quiet", "-p", "prm-bake", "-p", "prm-play"])
        .current_dir(&root)
        .status()
        .expect("starting cargo build");
    assert!(built.success(), "cargo build -p prm-bake -p prm-play failed");
    let bin = binary_dir();
    let mut ran = 0;
    for command in &commands {
        let words: Vec<&str> = command.split_whitespace().collect();
        if opens_a_window(&words) {
            println!("left out (opens a window): {command}");
            continue;
        }
        let program = match words[0] {
            "prm-bake" | "prm-play" => binary(&bin, words[0]),
            "cargo" => PathBuf::from(env!("CARGO")),
            other => panic!("the README's quick start runs {other:?}, which this test does not know"),
        };
        println!("running: {command}");
        let output = Command::new(&program)
            .args(&words[1..])
            .current_dir(&root)
            .env_remove("RUST_BACKTRACE")
            .output()
            .unwrap_or_else(|e| panic!("starting {}: {e}", program.display()));
        assert!(
            output.status.success(),
            "`{command}` failed ({}):\n{}",
            output.status,
            String::from_utf8_lossy(&output.stderr)
        );
        ran += 1;
    }
    assert!(ran >= 9, "only {ran} of the quick start's commands ran");
}
