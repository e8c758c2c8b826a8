//! `cargo xtask demo`: the main job end to end (bake the Cornell box, render a frame headless),
//! and `cargo xtask eval`, which runs the `xtask-eval` package.

use anyhow::{bail, Context, Result};
use std::process::Command;

/// Runs one `cargo run --release` step, streaming its output.
fn cargo_run(package: &str, args: &[&str]) -> Result<()> {
    let status = Command::new(env!("CARGO"))
        .args(["run", "--release", "--quiet", "-p", package, "--"])
        .args(args)
        .status()
        .with_context(|| format!("starting cargo run -p {package}"))?;
    if !status.success() {
        bail!("{package} {} failed ({status})", args.join(" "));
    }
    Ok(())
}

/// `cargo xtask eval ARGS`: runs the `xtask-eval` package (dev profile for `--quick`, which CI's
/// test build has already compiled; release for the others).
pub fn run_eval(args: &[String]) -> Result<()> {
    let mut cmd = Command::new(env!("CARGO"));
    cmd.args(["run", "--quiet", "-p", "xtask-eval"]);
    let release = ["--full", "--budget", "--targets", "--emitters", "--sky", "--probes"];
    if args.first().is_some_and(|a| a == "experiment") || args.iter().any(|a| release.contains(&a.as_str())) {
        cmd.arg("--release");
    }
    let status = cmd
        .arg("--")
        .args(args)
        .status()
        .context("starting cargo run -p xtask-eval")?;
    if !status.success() {
        // The evaluation printed its own reason; pass its exit code on.
        std::process::exit(status.code().unwrap_or(1));
    }
    Ok(())
}

pub fn run(args: &[String]) -> Result<()> {
    let scene = args
        .first()
        .map(String::as_str)
        .unwrap_or("scenes/cornell-box/cornell-box.gltf");
    let name = std::path::Path::new(scene)
        .file_stem()
        .and_then(|s| s.to_str())
        .unwrap_or("scene")
        .to_string();
    let archive = format!("out/{name}.prm");
    let frames = format!("out/{name}");
    cargo_run("prm-bake", &["bake", scene, "-o", &archive])?;
    cargo_run(
        "prm-play",
        &[
            &archive,
            "--headless",
            "--mode",
            "split",
            "--size",
            "800x600",
            "--out",
            &frames,
        ],
    )?;
    println!("\narchive: {archive}\nframe:   {frames}/ (EXR linear radiance, PNG tone-mapped; left half direct light only, right half with PRM indirect light)");
    Ok(())
}
