//! A long run of the player: 2,000 animated headless frames with 1, 2, 3 and 8 moving lights,
//! the indirect light recomputed every frame. The resident memory after frame 2,000 stays
//! within 10% of that after frame 100, whatever the light count.
//!
//! Small frames (32×24) and the smallest shadow maps (16²) keep it to about a minute per light
//! count on two cores with lavapipe; what grows per frame grows at any size.

use std::path::{Path, PathBuf};

use prm_play::synthetic::{cornell_box_path, write_archive, SyntheticParams};

const FRAMES: usize = 2000;
/// The frame whose resident memory is the baseline: past start-up and the first allocations of
/// every pass.
const BASELINE_FRAME: usize = 100;
/// Most growth allowed from the baseline to the last frame.
const MAX_GROWTH: f64 = 0.10;

fn out_dir(name: &str) -> PathBuf {
    let d = Path::new(env!("CARGO_TARGET_TMPDIR")).join("prm-play-soak").join(name);
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// An animation of `n` point lights circling the box at different heights and speeds.
fn animation(n: usize) -> String {
    let mut text = String::from("fps = 30.0\n");
    for l in 0..n {
        let keys: Vec<String> = (0..=8)
            .map(|k| {
                let a = (k as f32 / 8.0 + l as f32 / n as f32) * std::f32::consts::TAU;
                let (x, z) = (0.278 + 0.15 * a.cos(), 0.28 + 0.15 * a.sin());
                let y = 0.1 + 0.35 * (l as f32 + 0.5) / n as f32;
                format!(
                    "{{ t = {}, spec = \"point:{x},{y},{z}:0.05,0.05,0.05\" }}",
                    k as f32 * (2.0 + l as f32)
                )
            })
            .collect();
        text.push_str(&format!("[[light]]\nkeys = [ {} ]\n", keys.join(", ")));
    }
    text
}

/// The resident memory after each frame, from `--timings`.
fn resident_per_frame(timings: &Path) -> Vec<u64> {
    let json: serde_json::Value = serde_json::from_slice(&std::fs::read(timings).unwrap()).unwrap();
    json["frames"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| f["rss_bytes"].as_u64().expect("rss_bytes per frame (Linux)"))
        .collect()
}

#[test]
fn memory_stays_flat_over_2000_frames_for_any_light_count() {
    let dir = out_dir("archive");
    let scene_path = cornell_box_path();
    let scene = prm_scene::load(&scene_path).unwrap();
    let archive = dir.join("cornell-synthetic.prm");
    write_archive(&scene, &scene_path, &archive, SyntheticParams::default()).unwrap();
    let mut report = Vec::new();
    for lights in [1, 2, 3, 8] {
        let run = out_dir(&format!("lights-{lights}"));
        let anim = run.join("anim.toml");
        std::fs::write(&anim, animation(lights)).unwrap();
        let timings = run.join("timings.json");
        let started = std::time::Instant::now();
        let out = std::process::Command::new(env!("CARGO_BIN_EXE_prm-play"))
            .arg(&archive)
            .args(["--headless", "--size", "32x24", "--shadow-resolution", "16"])
            .args(["--gi-update", "every-frame", "--frames", &FRAMES.to_string()])
            .arg("--animation")
            .arg(&anim)
            .arg("--timings")
            .arg(&timings)
            .arg("--out")
            .arg(run.join("frames"))
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "{lights} lights: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        let rss = resident_per_frame(&timings);
        assert_eq!(rss.len(), FRAMES);
        let (base, last) = (rss[BASELINE_FRAME - 1], rss[FRAMES - 1]);
        let peak = *rss.iter().max().unwrap();
        let growth = last as f64 / base as f64 - 1.0;
        let mib = |b: u64| b as f64 / (1024.0 * 1024.0);
        report.push(format!(
            "{lights} lights: frame {BASELINE_FRAME} {:.1} MiB, frame {FRAMES} {:.1} MiB ({:+.1}%), peak {:.1} MiB, {:.0} s",
            mib(base),
            mib(last),
            100.0 * growth,
            mib(peak),
            started.elapsed().as_secs_f64()
        ));
        eprintln!("{}", report.last().unwrap());
        assert!(
            growth <= MAX_GROWTH,
            "memory grows with {lights} lights: {}",
            report.last().unwrap()
        );
        std::fs::remove_dir_all(run.join("frames")).unwrap();
    }
}
