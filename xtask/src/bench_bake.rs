//! `cargo xtask bench-bake`: wall time of the bakes that have bake-time targets, beside the
//! paper's 8.5 s and the figures of the Vulkan renderer on lavapipe (main at 2b215ab).
//!
//! Each case is baked once by the release `prm-bake` with `--report`; the table gives the bake's
//! own total time (scene load to archive written), its pane rendering time, the shadow rays and
//! the peak resident memory. Sibenik is baked twice: at the sizes the default chose before the
//! cost model knew the CPU renderer (the like-for-like comparison with the earlier 245 s), and
//! at today's default (2048 entries, 16 for each of the 128 clusters its memory budget allows). `--compare` bakes each case again with `--backend vulkan` (lavapipe
//! on machines without a GPU, the default renderer before) and prints the ratio within the same
//! run, which is what to quote on a shared, noisy machine. Not a test: nothing is asserted.

use anyhow::{bail, Context, Result};
use std::path::{Path, PathBuf};
use std::process::Command;

/// One bake to time.
struct Case {
    name: &'static str,
    /// Relative to the workspace root.
    scene: &'static str,
    args: &'static [&'static str],
    /// The bake-time target, seconds.
    target_s: f64,
    /// Measured on main at 2b215ab with the Vulkan renderer on lavapipe.
    before: &'static str,
}

const CASES: &[Case] = &[
    Case {
        name: "cornell-box, default (the demo's bake)",
        scene: "scenes/cornell-box/cornell-box.gltf",
        args: &[],
        target_s: 10.0,
        before: "55 s",
    },
    Case {
        name: "chairs, --preset paper",
        scene: "scenes/chairs/chairs.obj",
        args: &["--preset", "paper"],
        target_s: 8.5,
        before: "70 s (40.7 s quiet)",
    },
    Case {
        name: "sibenik, the earlier default's sizes",
        scene: "../shared/scenes/sibenik/sibenik.obj",
        args: &[
            "--entries",
            "5120",
            "--clusters",
            "135",
            "--resolution",
            "704",
            "--paths-per-entry",
            "1",
        ],
        target_s: 60.0,
        before: "245 s",
    },
    Case {
        name: "sibenik, default",
        scene: "../shared/scenes/sibenik/sibenik.obj",
        args: &[],
        target_s: 60.0,
        before: "245 s (at the sizes above)",
    },
];

/// What one bake reported.
struct Timed {
    backend: String,
    total_s: f64,
    panes_s: f64,
    rays: u64,
    peak_mib: Option<f64>,
}

fn bake(bin: &Path, scene: &Path, out: &Path, args: &[&str]) -> Result<Timed> {
    let report = out.with_extension("json");
    let status = Command::new(bin)
        .arg("bake")
        .arg(scene)
        .arg("-o")
        .arg(out)
        .arg("--report")
        .arg(&report)
        .arg("--quiet")
        .args(args)
        .status()
        .with_context(|| format!("starting {}", bin.display()))?;
    if !status.success() {
        bail!("prm-bake bake {} {} failed ({status})", scene.display(), args.join(" "));
    }
    let r: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&report)?)
        .with_context(|| format!("reading {}", report.display()))?;
    let timing = |k: &str| r["timings"][k].as_f64().unwrap_or(f64::NAN);
    Ok(Timed {
        backend: r["backend"].as_str().unwrap_or("?").to_string(),
        total_s: timing("total"),
        panes_s: timing("pane_rendering"),
        rays: r["rays"].as_u64().unwrap_or(0),
        peak_mib: r["peak_rss_bytes"].as_u64().map(|b| b as f64 / (1024.0 * 1024.0)),
    })
}

/// The backend as a short name: `cpu`, or the adapter's name.
fn short(backend: &str) -> &str {
    backend.split(" (").next().unwrap_or(backend)
}

pub fn run(args: &[String]) -> Result<()> {
    let compare = args.iter().any(|a| a == "--compare");
    let only = args.iter().position(|a| a == "--only").and_then(|i| args.get(i + 1));
    if let Some(a) = args
        .iter()
        .find(|a| a.starts_with("--") && *a != "--compare" && *a != "--only")
    {
        bail!("unknown option {a}\nusage: cargo xtask bench-bake [--compare] [--only NAME]");
    }
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..");
    let root = root.canonicalize().unwrap_or(root);
    let status = Command::new(env!("CARGO"))
        .args(["build", "--release", "--quiet", "-p", "prm-bake"])
        .current_dir(&root)
        .status()
        .context("starting cargo build")?;
    if !status.success() {
        bail!("building prm-bake failed ({status})");
    }
    let target = std::env::var_os("CARGO_TARGET_DIR").map_or(root.join("target"), PathBuf::from);
    let bin = target.join("release/prm-bake");
    let out_dir = target.join("bench-bake");
    std::fs::create_dir_all(&out_dir)?;

    let mut md = String::from(
        "| case | backend | wall s | pane rendering s | shadow rays | peak memory | target | before (lavapipe, main 2b215ab) | paper |\n\
         | --- | --- | ---: | ---: | ---: | ---: | ---: | --- | --- |\n",
    );
    for (i, case) in CASES.iter().enumerate() {
        if only.is_some_and(|o| !case.name.contains(o.as_str())) {
            continue;
        }
        let scene = root.join(case.scene);
        if !scene.is_file() {
            println!("bench-bake: {} is absent: {} skipped", scene.display(), case.name);
            continue;
        }
        let mut runs = vec![(
            "auto",
            bake(&bin, &scene, &out_dir.join(format!("case{i}.prm")), case.args)?,
        )];
        if compare {
            let args = [case.args, &["--backend", "vulkan"]].concat();
            runs.push((
                "vulkan",
                bake(&bin, &scene, &out_dir.join(format!("case{i}-vulkan.prm")), &args)?,
            ));
        }
        for (label, t) in &runs {
            let paper = if case.args.contains(&"paper") {
                "8.5 s (2007 GPU)"
            } else {
                ""
            };
            let line = format!(
                "| {} | {} ({label}) | {:.1} | {:.1} | {:.3e} | {} | ≤ {} s | {} | {paper} |",
                case.name,
                short(&t.backend),
                t.total_s,
                t.panes_s,
                t.rays as f64,
                t.peak_mib.map_or("?".to_string(), |m| format!("{m:.0} MiB")),
                case.target_s,
                case.before,
            );
            println!("{line}");
            md.push_str(&line);
            md.push('\n');
        }
        if let [(_, a), (_, v)] = &runs[..] {
            println!(
                "bench-bake: {}: vulkan / auto wall time = {:.2}",
                case.name,
                v.total_s / a.total_s
            );
        }
    }
    let path = out_dir.join("bench.md");
    std::fs::write(&path, md)?;
    println!("bench-bake: table written to {}", path.display());
    Ok(())
}
