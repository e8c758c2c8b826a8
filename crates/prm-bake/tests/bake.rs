//! Integration tests of the `prm-bake` binary: real bakes of the Cornell box at small settings
//! (archive contents, report, determinism, CPU vs Vulkan), failures that leave nothing behind,
//! and `prm-bake dump`. Measured numbers are printed (run with `--nocapture` to see them). The
//! stability suite, which crosses into the player, is in the top-level `tests/stability.rs`.
//!
//! Long on purpose: each test runs the real binary end to end and spells out its case.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::sync::OnceLock;
use std::time::Instant;

use prm_format::Archive;

mod common;
use common::{scene_path, STEPS};

const BIN: &str = env!("CARGO_BIN_EXE_prm-bake");

/// A fresh, empty directory for one test under the cargo-provided temporary directory.
fn temp_dir(name: &str) -> PathBuf {
    common::scratch_dir("prm-bake-tests", name)
}

/// The sizes of the tiniest bakes (64 entries in 8 clusters, 32² texels, one walk each).
const TINY: [&str; 8] = [
    "--entries",
    "64",
    "--clusters",
    "8",
    "--resolution",
    "32",
    "--paths-per-entry",
    "1",
];

fn run(args: &[&str]) -> Output {
    Command::new(BIN).args(args).output().expect("running prm-bake")
}

/// Lines of `bytes`.
fn lines(bytes: &[u8]) -> Vec<String> {
    String::from_utf8_lossy(bytes).lines().map(str::to_string).collect()
}

fn describe(out: &Output) -> String {
    format!(
        "status {:?}\nstdout:\n{}\nstderr:\n{}",
        out.status,
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    )
}

/// Asserts that the command `what` was refused before any work, with status 2 (by clap or by
/// the bake's own checks; never 0 or 1, never a panic's 101) and an error containing `expected`.
fn assert_refused(r: &Output, what: &str, expected: &str) {
    assert_eq!(r.status.code(), Some(2), "{what}: {}", describe(r));
    assert!(
        String::from_utf8_lossy(&r.stderr).contains(expected),
        "{what}: expected `{expected}` in the error:\n{}",
        describe(r)
    );
}

/// Writes the config file with the settings the command line has no flag for, one per bake
/// `name` in `dir`, so that bakes run at once never read a file another is writing.
/// VPL disks of three entry-point radii: at 256 entry points the plan's eight (its rule for a
/// 64² atlas) would be 40 cm discs in a 55 cm box, and the panes would hold little of the light
/// (the accuracy check then measured 28% with every cluster and with one alike).
fn config_file(dir: &Path, name: &str) -> PathBuf {
    let path = dir.join(format!("{name}-small.toml"));
    std::fs::write(&path, "face_resolution = 64\nvpl_disk_scale = 3.0\n").unwrap();
    path
}

/// Bakes the Cornell box at small settings into `dir/name.prm`; `extra` is appended.
fn bake(dir: &Path, name: &str, seed: u64, backend: &str, extra: &[&str]) -> (PathBuf, Output, f64) {
    bake_with(dir, name, seed, backend, extra, |_| {})
}

/// [`bake`], with `env` setting up the command's environment.
fn bake_with(
    dir: &Path,
    name: &str,
    seed: u64,
    backend: &str,
    extra: &[&str],
    env: impl FnOnce(&mut Command),
) -> (PathBuf, Output, f64) {
    let out = dir.join(format!("{name}.prm"));
    let config = config_file(dir, name);
    let seed = seed.to_string();
    let scene = scene_path();
    let mut cmd = Command::new(BIN);
    cmd.args(["bake", scene.to_str().unwrap(), "-o", out.to_str().unwrap()])
        .args([
            "--entries",
            "256",
            "--clusters",
            "16",
            "--resolution",
            "64",
            "--paths-per-entry",
            "1",
        ])
        .args([
            "--seed",
            &seed,
            "--backend",
            backend,
            "--config",
            config.to_str().unwrap(),
        ])
        .args(extra);
    env(&mut cmd);
    let t = Instant::now();
    let output = cmd.output().expect("running prm-bake");
    let seconds = t.elapsed().as_secs_f64();
    assert!(output.status.success(), "bake {name} failed: {}", describe(&output));
    (out, output, seconds)
}

/// The reference bake (Vulkan, seed 1, with a report), shared by the tests that only read it.
struct Baked {
    dir: PathBuf,
    archive: PathBuf,
    report: PathBuf,
}

fn baked() -> &'static Baked {
    static BAKED: OnceLock<Baked> = OnceLock::new();
    BAKED.get_or_init(|| {
        let dir = temp_dir("reference");
        let report = dir.join("report.json");
        let (archive, output, seconds) = bake(&dir, "a", 1, "vulkan", &["--report", report.to_str().unwrap()]);
        eprintln!("reference bake (vulkan): {seconds:.2} s\n{}", describe(&output));
        Baked { dir, archive, report }
    })
}

/// What an archive holds, for comparing bakes with different seeds.
#[derive(Debug, PartialEq)]
struct Contents {
    entries: Vec<prm_format::Entry>,
    clusters: Vec<prm_format::Cluster>,
    atlas: prm_format::AtlasSection,
    panes: Vec<Vec<u32>>,
    seed: u64,
    fingerprint: u64,
    params: serde_json::Map<String, serde_json::Value>,
}

fn contents(path: &Path) -> Contents {
    let a = Archive::open(path).unwrap();
    let panes = (0..a.pane_count()).map(|p| a.read_pane_rgb9e5(p).unwrap()).collect();
    Contents {
        entries: a.entries().to_vec(),
        clusters: a.clusters().to_vec(),
        atlas: a.atlas().clone(),
        panes,
        seed: a.metadata().seed,
        fingerprint: a.metadata().scene_fingerprint,
        params: a.metadata().params.clone(),
    }
}

/// Σ over panes at every texel (decoded), the unclustered irradiance field for unit weights.
fn summed_panes(path: &Path) -> Vec<[f64; 3]> {
    let a = Archive::open(path).unwrap();
    let n = a.atlas().texels_per_pane();
    let mut sum = vec![[0f64; 3]; n];
    for p in 0..a.pane_count() {
        for (s, t) in sum.iter_mut().zip(a.read_pane(p).unwrap()) {
            for c in 0..3 {
                s[c] += t[c] as f64;
            }
        }
    }
    sum
}

#[test]
fn bake_writes_a_valid_archive_and_report() {
    let b = baked();
    let mut archive = Archive::open(&b.archive).expect("archive opens");
    let report = archive.verify().expect("archive verifies");
    assert_eq!(report.panes, 16);
    assert_eq!(archive.entries().len(), 256);
    assert_eq!(archive.clusters().len(), 16);
    assert_eq!(archive.atlas().resolution, 64);
    let meta = archive.metadata();
    // Timings go to the report, not the archive, whose bytes must not change between runs.
    assert!(meta.timings.is_empty(), "timings in the archive: {:?}", meta.timings);
    assert_eq!(meta.seed, 1);
    assert_eq!(meta.params["face_resolution"], 64, "the config file was read");
    let scene = prm_scene::load(&scene_path()).unwrap();
    assert_eq!(meta.scene_fingerprint, scene.fingerprint());
    let source = b.archive.parent().unwrap().join(&meta.source_scene);
    assert_eq!(
        source.canonicalize().unwrap(),
        scene_path().canonicalize().unwrap(),
        "source_scene {:?} is relative to the archive's directory",
        meta.source_scene
    );
    assert!(Path::new(&meta.source_scene).is_relative(), "{}", meta.source_scene);
    // Every entry belongs to the cluster whose range holds it.
    for (c, cluster) in archive.clusters().iter().enumerate() {
        for e in &archive.entries()[cluster.members()] {
            assert_eq!(e.cluster as usize, c);
        }
    }

    let text = std::fs::read_to_string(&b.report).expect("--report written");
    let json: serde_json::Value = serde_json::from_str(&text).expect("report is JSON");
    let timings = json["timings"].as_object().expect("report has timings");
    for key in [&["load"][..], &STEPS, &["total"]].concat() {
        let t = timings.get(key).and_then(|t| t.as_f64());
        assert!(
            t.is_some_and(|t| t.is_finite() && t >= 0.0),
            "timing {key}: {timings:?}"
        );
    }
    assert_eq!(
        json["archive_bytes"].as_u64(),
        Some(std::fs::metadata(&b.archive).unwrap().len()),
        "archive_bytes is the file size"
    );
    assert_eq!(json["entries"], 256);
    assert_eq!(json["clusters"], 16);
    eprintln!("report timings: {timings:?}");
    // The accuracy check: three test lights free in the box and one close under its ceiling, a
    // plausible estimate, the same in the report and the archive.
    let accuracy = meta.accuracy.as_ref().expect("the bake estimates its accuracy");
    assert_eq!((archive.info().major, archive.info().minor), (2, 1));
    assert!(archive.near_field().is_some());
    let cells = archive.entry_cells().expect("the bake writes the entry cells");
    assert_eq!(cells.points.len(), 256 * prm_trace::CELL_POINTS_PER_ENTRY);
    assert_eq!(
        accuracy.lights.len(),
        prm_trace::check::CHECK_LIGHTS + 1,
        "{accuracy:?}"
    );
    let (clear, hard) = (accuracy.lights[0].position, accuracy.lights[3].position);
    assert_eq!(
        (hard[0], hard[2]),
        (clear[0], clear[2]),
        "the hard light is above the first"
    );
    assert!(hard[1] > clear[1], "{accuracy:?}");
    assert_eq!(accuracy.exit_points, prm_bake::ACCURACY_POINTS);
    assert_eq!(accuracy.top_k, meta.params["top_k"].as_u64().unwrap() as u32);
    for l in &accuracy.lights {
        assert!(l.error < 0.6 && l.error_all_clusters < 0.6, "{l:?}");
        assert!((0.7..1.3).contains(&l.energy), "{l:?}");
        assert!(l.standard_error > 0.0 && l.standard_error < l.error.max(0.05), "{l:?}");
        assert!(l.measured >= l.error && l.reference_noise > 0.0, "{l:?}");
    }
    let reported: prm_format::Accuracy = serde_json::from_value(json["accuracy"].clone()).unwrap();
    assert_eq!(&reported, accuracy);
    // Nothing but the archive, the report and the config is left in the output directory.
    let mut names: Vec<String> = std::fs::read_dir(&b.dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    assert_eq!(names, ["a-small.toml", "a.prm", "report.json"]);
}

#[test]
fn bake_is_byte_identical_across_runs_and_threads_and_quiet_is_silent() {
    let reference = std::fs::read(&baked().archive).unwrap();
    let dir = temp_dir("determinism");
    // The repeats are also the `--quiet` check: nothing on stdout or stderr, not even the
    // `XDG_RUNTIME_DIR` line libwayland prints when a window-system probe runs without it.
    for threads in ["1", "2"] {
        let (out, output, _) = bake_with(&dir, &format!("threads-{threads}"), 1, "vulkan", &["--quiet"], |c| {
            c.env("RAYON_NUM_THREADS", threads).env_remove("XDG_RUNTIME_DIR");
        });
        assert!(output.stdout.is_empty(), "--quiet: {}", describe(&output));
        assert!(output.stderr.is_empty(), "--quiet: {}", describe(&output));
        let again = std::fs::read(&out).unwrap();
        // Whole files: the archive holds no timings or dates, so caches can key on its bytes.
        assert!(
            again == reference,
            "RAYON_NUM_THREADS={threads}: the archive differs from the reference bake's bytes \
             (same scene, seed and parameters)"
        );
    }

    let reference = contents(&baked().archive);
    let (other, _, _) = bake(&dir, "other", 2, "vulkan", &["--quiet"]);
    let other = contents(&other);
    assert_eq!(other.seed, 2);
    assert_ne!(
        reference.entries, other.entries,
        "a different seed gives different entries"
    );
}

/// Without a Vulkan driver (`VK_ICD_FILENAMES` naming nothing): `auto` passes over Vulkan and
/// OpenGL (whose GLSL cannot load from depth textures, or which is not installed) and bakes on
/// the CPU, saying so; an explicit `--backend vulkan` or `gl` stops with exit 1 and the driver
/// to install. Never a panic (exit 101), on GL as on any other backend.
#[test]
fn without_a_vulkan_driver_auto_bakes_on_the_cpu_and_explicit_backends_fail_cleanly() {
    let dir = temp_dir("no-vulkan");
    let scene = scene_path();
    let no_vulkan = |args: &[&str]| {
        Command::new(BIN)
            .args(args)
            .env("VK_ICD_FILENAMES", "/nonexistent/icd.json")
            .env("VK_DRIVER_FILES", "/nonexistent/icd.json")
            .output()
            .unwrap()
    };
    let out = dir.join("auto.prm");
    let r = no_vulkan(
        &[
            &["bake", scene.to_str().unwrap(), "-o", out.to_str().unwrap()][..],
            &TINY[..],
        ]
        .concat(),
    );
    let stderr = String::from_utf8_lossy(&r.stderr);
    assert!(r.status.success(), "{}", describe(&r));
    assert!(stderr.contains("passing over vulkan"), "{stderr}");
    assert!(stderr.contains("baking on the CPU"), "{stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
    let a = Archive::open(&out).unwrap();
    assert_eq!(a.metadata().params["backend"], "cpu");

    for backend in ["vulkan", "gl"] {
        let r = no_vulkan(&[
            "bake",
            scene.to_str().unwrap(),
            "-o",
            dir.join("x.prm").to_str().unwrap(),
            "--backend",
            backend,
        ]);
        let stderr = String::from_utf8_lossy(&r.stderr);
        assert_eq!(r.status.code(), Some(1), "--backend {backend}: {}", describe(&r));
        assert!(!stderr.contains("panicked"), "{stderr}");
        assert!(
            stderr.contains("apt-get install") || stderr.contains("cannot render panes"),
            "{stderr}"
        );
        assert!(!dir.join("x.prm").exists());
    }
}

/// Limits are checked before any work, naming the option: none of these is accepted, and the
/// reference's size never aborts on allocation.
#[test]
fn limits_are_refused_up_front() {
    let dir = temp_dir("limits");
    let scene = scene_path();
    let scene = scene.to_str().unwrap();
    let out = dir.join("x.prm");
    let out = out.to_str().unwrap();
    let exr = dir.join("x.exr");
    let exr = exr.to_str().unwrap();
    let png = dir.join("x.png");
    let png = png.to_str().unwrap();
    let plan = |options: &[&'static str]| [&["bake", scene, "-o", out][..], options, &["--plan"]].concat();
    let reference = |options: &[&'static str]| {
        let view = [
            "reference",
            scene,
            "--light",
            "point:0,1,0:1,1,1",
            "--camera",
            "0,1,3:0,1,0:40",
        ];
        [&view[..], options, &["-o", exr]].concat()
    };
    let cases = [
        (plan(&["--entries", "16777217", "--clusters", "64"]), "--entries"),
        (plan(&["--top-k", "0"]), "--top-k"),
        (plan(&["--accuracy-paths", "1"]), "--accuracy-paths"),
        (plan(&["--clusters", "2000000", "--entries", "4000000"]), "--clusters"),
        (reference(&["--spp", "0"]), "--spp"),
        (reference(&["--size", "16384x16384"]), "--size"),
        // An EXR under another name: `-o x.png` must not write one silently.
        (
            [
                "reference",
                scene,
                "--light",
                "point:0,1,0:1,1,1",
                "--size",
                "8x8",
                "-o",
                png,
            ]
            .to_vec(),
            "name it FILE.exr",
        ),
    ];
    for (args, option) in cases {
        let r = run(&args);
        assert_refused(&r, &format!("{args:?}"), option);
        assert!(!Path::new(out).exists() && !Path::new(exr).exists() && !Path::new(png).exists());
    }
}

/// `--backend auto` never renders panes on a software rasterizer: on this project's machines
/// (lavapipe only) it bakes on the CPU and says why; with a hardware GPU it takes the GPU.
#[test]
fn auto_passes_over_software_rasterizers() {
    let dir = temp_dir("auto");
    let (out, output, _) = bake(&dir, "auto", 1, "auto", &[]);
    let said = format!(
        "{}{}",
        String::from_utf8_lossy(&output.stdout),
        String::from_utf8_lossy(&output.stderr)
    );
    let backend = Archive::open(&out).unwrap().metadata().params["backend"].clone();
    if backend == "cpu" {
        assert!(
            said.contains("software rasterizer") || said.contains("no GPU backend"),
            "auto chose the CPU without saying why:\n{said}"
        );
    } else {
        let backend = backend.as_str().unwrap_or_default().to_string();
        assert!(
            !backend.contains("Cpu"),
            "auto rendered on a software rasterizer: {backend}"
        );
        assert!(said.contains("device:"), "{said}");
    }
}

#[test]
fn cpu_and_vulkan_backends_agree() {
    let gpu = summed_panes(&baked().archive);
    let dir = temp_dir("cpu");
    let (cpu, _, seconds) = bake(&dir, "cpu", 1, "cpu-exact", &["--quiet"]);
    eprintln!("exact CPU bake: {seconds:.2} s");
    let cpu = summed_panes(&cpu);
    let (mut err, mut norm, mut sum_g, mut sum_c) = (0.0, 0.0, 0.0, 0.0);
    for (g, c) in gpu.iter().zip(&cpu) {
        for k in 0..3 {
            err += (g[k] - c[k]).powi(2);
            norm += c[k] * c[k];
            sum_g += g[k];
            sum_c += c[k];
        }
    }
    let rmse = (err / norm).sqrt();
    eprintln!(
        "summed panes, Vulkan vs CPU: relative RMSE {rmse:.4}, energy ratio {:.4}",
        sum_g / sum_c
    );
    // Same entries, walks and clusters (same seed, and sampling, walks and clustering run on the
    // CPU either way); only the visibility differs: 64² hemicube depth faces with PCF and biases
    // against exact shadow rays, which disagree near the shadow edges of the two blocks, plus
    // RGB9E5 rounding of both (< 0.4 % per texel). Measured 0.020 (energy ratio 1.001); prm-gpu's
    // own comparison gets under 0.02 with 256² faces. 0.05 leaves room for driver and bias
    // changes while still catching a lost cluster or batch (one of 16 panes is ~6 % of the sum,
    // far more in its own region).
    assert!(rmse < 0.05, "relative RMSE {rmse}");
    assert!((sum_g / sum_c - 1.0).abs() < 0.02, "energy ratio {}", sum_g / sum_c);
}

#[test]
fn failures_are_clean_and_leave_existing_archives_alone() {
    let dir = temp_dir("failures");
    let out = dir.join("out.prm");
    let scene = scene_path();
    let scene = scene.to_str().unwrap();
    let out_s = out.to_str().unwrap();

    // A missing scene: non-zero exit naming the file, no archive.
    let missing = dir.join("no-such-scene.obj");
    let r = run(&["bake", missing.to_str().unwrap(), "-o", out_s, "--backend", "cpu"]);
    assert!(!r.status.success(), "{}", describe(&r));
    assert!(
        String::from_utf8_lossy(&r.stderr).contains("no-such-scene.obj"),
        "{}",
        describe(&r)
    );
    assert!(!out.exists(), "no archive after a failed bake");

    // More clusters than entries: refused before any work (exit status 2).
    let r = run(&[
        "bake",
        scene,
        "-o",
        out_s,
        "--clusters",
        "100",
        "--entries",
        "10",
        "--backend",
        "vulkan",
    ]);
    assert_refused(&r, "--clusters 100 --entries 10", "clusters");
    assert!(
        !String::from_utf8_lossy(&r.stdout).contains("device:"),
        "refused before opening the GPU: {}",
        describe(&r)
    );
    assert!(!out.exists());

    // An archive already at the output path survives failing bakes untouched.
    std::fs::copy(&baked().archive, &out).unwrap();
    let old = std::fs::read(&out).unwrap();
    let bad_config = dir.join("missing.toml");
    let invalid_config = dir.join("invalid.toml");
    std::fs::write(&invalid_config, "entires = 3\n").unwrap();
    for args in [
        vec!["bake", scene, "-o", out_s, "--config", bad_config.to_str().unwrap()],
        vec!["bake", scene, "-o", out_s, "--config", invalid_config.to_str().unwrap()],
        vec!["bake", scene, "-o", out_s, "--clusters", "100", "--entries", "10"],
        vec!["bake", scene, "-o", out_s, "--entries", "64", "--resolution", "4"],
    ] {
        let r = run(&args);
        assert!(!r.status.success(), "{args:?}: {}", describe(&r));
        assert!(!lines(&r.stderr).is_empty(), "{args:?} says why");
        assert_eq!(std::fs::read(&out).unwrap(), old, "{args:?} touched the existing file");
    }
    let r = run(&["bake", scene, "-o", out_s, "--config", bad_config.to_str().unwrap()]);
    assert!(
        String::from_utf8_lossy(&r.stderr).contains("missing.toml"),
        "{}",
        describe(&r)
    );

    // Refused before any work, the files kept: an -o that names the scene (or any file that is
    // not an archive), a --report that names the archive, a --report below a file.
    let obj = dir.join("room.obj");
    std::fs::copy(scene_path(), &obj).unwrap();
    let obj_bytes = std::fs::read(&obj).unwrap();
    let not_a_dir = dir.join("invalid.toml");
    let under_file = not_a_dir.join("r.json");
    let elsewhere = dir.join("elsewhere.prm");
    for (args, expected) in [
        (
            vec!["bake", obj.to_str().unwrap(), "-o", obj.to_str().unwrap()],
            "not a .prm archive",
        ),
        (
            vec!["bake", scene, "-o", out_s, "--report", out_s],
            "it is the archive the bake writes",
        ),
        (
            vec![
                "bake",
                obj.to_str().unwrap(),
                "-o",
                elsewhere.to_str().unwrap(),
                "--report",
                obj.to_str().unwrap(),
            ],
            "it is the scene",
        ),
        (
            vec!["bake", scene, "-o", elsewhere.to_str().unwrap(), "--report", out_s],
            "it is a .prm archive",
        ),
        (
            vec!["bake", scene, "-o", out_s, "--report", under_file.to_str().unwrap()],
            "not a directory",
        ),
    ] {
        let r = run(&[&args[..], &["--backend", "cpu"]].concat());
        // Exit status 2: refused before any work (no scene loaded, no phase started).
        assert_eq!(r.status.code(), Some(2), "{args:?}: {}", describe(&r));
        assert!(
            !String::from_utf8_lossy(&r.stderr).contains("atlas"),
            "{args:?}: {}",
            describe(&r)
        );
        assert!(
            String::from_utf8_lossy(&r.stderr).contains(expected),
            "{args:?}: {}",
            describe(&r)
        );
        assert_eq!(std::fs::read(&out).unwrap(), old, "{args:?} touched the archive");
        assert_eq!(std::fs::read(&obj).unwrap(), obj_bytes, "{args:?} touched the scene");
    }
    std::fs::remove_file(&obj).unwrap();
    // Nothing else (no temporary files) is left behind.
    let mut names: Vec<String> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    assert_eq!(names, ["invalid.toml", "out.prm"]);
}

#[test]
fn dump_summarises_verifies_and_rejects_damage() {
    let archive = &baked().archive;
    let path = archive.to_str().unwrap();
    let r = run(&["dump", path]);
    assert!(r.status.success(), "{}", describe(&r));
    // What the archive needs resident on the GPU, panes and near field apart.
    let stdout = String::from_utf8_lossy(&r.stdout);
    let resident = stdout.lines().find(|l| l.starts_with("resident")).unwrap_or_default();
    assert!(
        resident.contains("MiB on the GPU: panes") && resident.contains("basis") && resident.contains("near field"),
        "{resident}"
    );
    assert!(
        String::from_utf8_lossy(&r.stdout).contains("near field"),
        "{}",
        describe(&r)
    );

    let r = run(&["dump", path, "--json"]);
    assert!(r.status.success(), "{}", describe(&r));
    let json: serde_json::Value = serde_json::from_slice(&r.stdout).expect("dump --json is JSON");
    for key in [
        "version",
        "entries",
        "clusters",
        "resolution",
        "sections",
        "params",
        "timings",
    ] {
        assert!(json.get(key).is_some(), "dump --json lacks {key}: {json}");
    }
    assert_eq!(json["entries"], 256);
    assert_eq!(json["clusters"], 16);
    assert_eq!(json["resolution"], 64);
    assert_eq!(json["near_field"]["rays_per_exit"], prm_trace::NEAR_RAYS);
    assert!(
        json["near_field"]["hits"].as_u64().unwrap() > 0,
        "{}",
        json["near_field"]
    );

    let r = run(&["dump", path, "--verify"]);
    assert!(r.status.success(), "{}", describe(&r));

    // A truncated copy: exit status 1 and a message.
    let dir = temp_dir("dump");
    let bytes = std::fs::read(archive).unwrap();
    let truncated = dir.join("truncated.prm");
    std::fs::write(&truncated, &bytes[..bytes.len() / 2]).unwrap();
    for extra in [&[][..], &["--verify"][..], &["--json"][..]] {
        let mut args = vec!["dump", truncated.to_str().unwrap()];
        args.extend_from_slice(extra);
        let r = run(&args);
        assert_eq!(r.status.code(), Some(1), "{args:?}: {}", describe(&r));
        let stderr = lines(&r.stderr).join("\n");
        assert!(stderr.contains("truncated.prm"), "{args:?}: {}", describe(&r));
    }
}

/// SIGINT, SIGTERM and SIGHUP during a bake remove its temporary file (formats/prm.md §9) and
/// exit with 128 + the signal; the archive already there stays untouched. (SIGKILL cannot be
/// caught: prm-format's `sigkill_leftover_is_removed_by_the_next_writer` covers the sweep of its
/// leftover by the next bake.)
#[cfg(unix)]
#[test]
fn catchable_signals_during_a_bake_leave_no_temporary_file() {
    let dir = temp_dir("signals");
    let out = dir.join("x.prm");
    // An earlier archive (a damaged one: the magic bytes, then anything) that each interrupted bake leaves as it was.
    std::fs::write(&out, b"\x89PRM\r\n\x1a\nold archive").unwrap();
    let scene = scene_path();
    let temp_files = || -> Vec<PathBuf> {
        std::fs::read_dir(&dir)
            .unwrap()
            .map(|e| e.unwrap().path())
            .filter(|p| p.file_name().unwrap().to_string_lossy().contains(".tmp-"))
            .collect()
    };
    for (signal, code) in [("INT", 130), ("TERM", 143), ("HUP", 129)] {
        // Long enough to be caught while the panes are rendered: exact CPU visibility.
        let mut child = Command::new(BIN)
            .args(["bake", scene.to_str().unwrap(), "-o", out.to_str().unwrap()])
            .args([
                "--entries",
                "1024",
                "--clusters",
                "64",
                "--resolution",
                "128",
                "--backend",
                "cpu-exact",
                "--quiet",
            ])
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap();
        // The writer's temporary file, seen on two polls in a row: the destination check's probe
        // (named alike, so that a sweep can remove it too) lives for microseconds, before the
        // handler is installed.
        let started = Instant::now();
        let mut seen = 0;
        while seen < 2 {
            assert!(
                child.try_wait().unwrap().is_none(),
                "the bake ended before its temporary file appeared"
            );
            assert!(started.elapsed().as_secs() < 120, "no temporary file after 120 s");
            seen = if temp_files().is_empty() { 0 } else { seen + 1 };
            std::thread::sleep(std::time::Duration::from_millis(20));
        }
        let kill = Command::new("kill")
            .args([format!("-{signal}"), child.id().to_string()])
            .status()
            .unwrap();
        assert!(kill.success());
        let output = child.wait_with_output().unwrap();
        let stderr = String::from_utf8_lossy(&output.stderr);
        assert_eq!(output.status.code(), Some(code), "SIG{signal}: {stderr}");
        assert!(stderr.contains("removed 1 temporary file"), "SIG{signal}: {stderr}");
        assert_eq!(temp_files(), Vec::<PathBuf>::new(), "SIG{signal} left a temporary file");
        assert_eq!(
            std::fs::read(&out).unwrap(),
            b"\x89PRM\r\n\x1a\nold archive",
            "SIG{signal} touched the old archive"
        );
    }
}

/// Destinations are checked before any work: a directory, a device or a FIFO is refused (as
/// root, writing `-o /dev/full` by rename would replace the device node with a regular file),
/// and a symlink is written through, so the link stays a link.
#[cfg(unix)]
#[test]
fn destinations_are_checked_before_work_and_symlinks_written_through() {
    let dir = temp_dir("destinations");
    let scene = scene_path();
    let scene = scene.to_str().unwrap();
    let small = [&TINY[..], &["--backend", "cpu"]].concat();
    let fifo = dir.join("fifo.prm");
    assert!(Command::new("mkfifo").arg(&fifo).status().unwrap().success());
    let subdir = dir.join("a-directory.prm");
    std::fs::create_dir(&subdir).unwrap();
    for (dest, what) in [
        (PathBuf::from("/dev/null"), "character device"),
        (fifo.clone(), "FIFO"),
        (subdir.clone(), "directory"),
    ] {
        let r = run(&[&["bake", scene, "-o", dest.to_str().unwrap()][..], &small[..]].concat());
        assert_refused(&r, &format!("-o {}", dest.display()), what);
        // Refused before any work: not even the plan was printed.
        assert!(r.stdout.is_empty(), "-o {}: {}", dest.display(), describe(&r));
    }
    use std::os::unix::fs::FileTypeExt;
    assert!(
        std::fs::metadata("/dev/null").unwrap().file_type().is_char_device(),
        "/dev/null was replaced"
    );

    let target_dir = dir.join("real");
    std::fs::create_dir(&target_dir).unwrap();
    let target = target_dir.join("target.prm");
    let link = dir.join("link.prm");
    std::os::unix::fs::symlink(&target, &link).unwrap();
    let r = run(&[&["bake", scene, "-o", link.to_str().unwrap()][..], &small[..]].concat());
    assert!(r.status.success(), "{}", describe(&r));
    assert!(
        std::fs::symlink_metadata(&link).unwrap().file_type().is_symlink(),
        "the link was replaced"
    );
    let a = Archive::open(&target).expect("the archive is where the link points");
    // source_scene is relative to the archive's real directory.
    let source = target_dir.join(&a.metadata().source_scene);
    assert_eq!(source.canonicalize().unwrap(), scene_path().canonicalize().unwrap());
}

/// The accuracy check sees what a bake gets wrong: the same panes blended with K = 1 of 16
/// clusters are estimated worse than with all of them, and their K = all estimate is the same
/// number. `--accuracy-points 0` skips it, `--near-rays 0` the near field: the archive is still
/// 2.1, for its entry cells.
#[test]
fn the_accuracy_check_sees_a_worse_bake() {
    let dir = temp_dir("accuracy");
    let estimate = |name: &str, extra: &[&str]| {
        let (path, _, _) = bake(&dir, name, 3, "cpu", &[&["--quiet"][..], extra].concat());
        Archive::open(&path).unwrap().metadata().accuracy.clone()
    };
    let all = estimate("all", &[]).expect("checked");
    let one = estimate("one", &["--top-k", "1"]).expect("checked");
    assert_eq!(all.top_k, 16);
    assert_eq!(one.top_k, 1);
    assert_eq!(all.mean_error(), all.mean_error_all_clusters(), "K = 16 of 16 is all");
    assert_eq!(
        one.mean_error_all_clusters(),
        all.mean_error_all_clusters(),
        "the same panes"
    );
    assert!(
        one.mean_error() > all.mean_error() + 2.0 * one.mean_standard_error(),
        "K = 1: {one:?}\nK = all: {all:?}"
    );
    let (path, _, _) = bake(
        &dir,
        "none",
        3,
        "cpu",
        &["--quiet", "--accuracy-points", "0", "--near-rays", "0"],
    );
    let a = Archive::open(&path).unwrap();
    assert!(a.metadata().accuracy.is_none() && a.near_field().is_none());
    assert_eq!((a.info().major, a.info().minor), (2, 1));
}

/// `prm-bake check` estimates an archive as the bake's last step did: the same estimate to the
/// bit (near field and all) from the archive, the scene and the seed it records; it refuses a
/// shard's part, another scene, and nonsense sizes, with a message.
#[test]
fn check_repeats_the_bake_s_own_estimate() {
    let dir = temp_dir("check");
    let size = ["--accuracy-points", "96", "--accuracy-paths", "32"];
    let (path, _, _) = bake(&dir, "box", 5, "cpu", &[&["--quiet"][..], &size].concat());
    let archive = Archive::open(&path).unwrap();
    assert!(archive.near_field().is_some(), "the check plays the near field too");
    let recorded = archive.metadata().accuracy.clone().expect("checked");
    let (scene, p) = (scene_path(), path.to_str().unwrap().to_string());
    let scene = scene.to_str().unwrap();
    let out = run(&[&["check", scene, &p, "--json", "--quiet"][..], &size].concat());
    assert!(out.status.success(), "{}", describe(&out));
    let got: prm_format::Accuracy = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(got, recorded);
    // The text form, as `dump` shows it.
    let out = run(&[&["check", scene, &p, "--quiet"][..], &size].concat());
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        text.starts_with("estimated accuracy: indirect light")
            && text.matches("light at (").count() == prm_trace::check::CHECK_LIGHTS + 1,
        "{}",
        describe(&out)
    );

    // Under a light of the user's: that light alone, where it was given.
    let light = "point:0.2,0.4,0.3:1,1,1";
    let out = run(&[&["check", scene, &p, "--json", "--quiet", "--light", light][..], &size].concat());
    assert!(out.status.success(), "{}", describe(&out));
    let theirs: prm_format::Accuracy = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(theirs.lights.len(), 1);
    assert_eq!(theirs.lights[0].position, [0.2, 0.4, 0.3]);
    assert!(theirs.lights[0].error.is_finite() && theirs.lights[0].energy > 0.0);

    let (part, _, _) = bake(&dir, "part", 5, "cpu", &["--quiet", "--shard", "0/2"]);
    let chairs = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes/chairs/chairs.obj");
    for (args, expected) in [
        (vec![scene, part.to_str().unwrap()], "merge the shards first"),
        (vec![chairs.to_str().unwrap(), &p], "other geometry"),
        (vec![scene, &p, "--accuracy-paths", "0"], "at least 1"),
        (vec![scene, &p, "--light", "dir:0,-1,0:1,1,1"], "point lights only"),
    ] {
        let r = run(&[&["check"][..], &args, &["--quiet"]].concat());
        assert_refused(&r, &format!("{args:?}"), expected);
    }
}

/// `--shard I/N` on two processes at once, then `merge`: exactly the bytes of the single bake
/// (probes included: each part has its own clusters' transfer), whatever order the parts come
/// in; and the merge refuses what does not make one bake. A shard never checks its accuracy
/// (whatever `--accuracy-points` says) and a merge writes no estimate, so the merge is the single
/// bake made with `--accuracy-points 0`; `merge --scene` checks the merged archive, and is the
/// single bake with its default check.
#[test]
fn shards_merge_into_the_single_bake_byte_for_byte() {
    let dir = temp_dir("shards");
    let parts_dir = dir.join("parts");
    std::fs::create_dir_all(&parts_dir).unwrap();
    let (single, _, _) = bake(
        &dir,
        "single",
        1,
        "cpu",
        &["--quiet", "--probes", "32", "--accuracy-points", "0"],
    );
    assert!(Archive::open(&single).unwrap().probes().is_some());
    let shard = |i| ["--quiet", "--probes", "32", "--shard", i];
    let (args0, args1) = (shard("0/2"), shard("1/2"));
    let (part0, part1) = std::thread::scope(|s| {
        let a = s.spawn(|| bake(&parts_dir, "part0", 1, "cpu", &args0).0);
        let b = s.spawn(|| bake(&parts_dir, "part1", 1, "cpu", &args1).0);
        (a.join().unwrap(), b.join().unwrap())
    });
    let part = Archive::open(&part0).unwrap();
    assert_eq!(
        part.metadata().params["shard"],
        serde_json::json!({ "index": 0, "count": 2 })
    );
    let merged = dir.join("merged.prm");
    let (p0, p1, m) = (
        part0.to_str().unwrap(),
        part1.to_str().unwrap(),
        merged.to_str().unwrap(),
    );
    let dump = run(&["dump", p0]);
    assert!(
        String::from_utf8_lossy(&dump.stdout).contains("shard        0/2: a partial archive"),
        "{}",
        describe(&dump)
    );
    let r = run(&["merge", p1, p0, "-o", m]);
    assert!(r.status.success(), "{}", describe(&r));
    assert!(
        std::fs::read(&merged).unwrap() == std::fs::read(&single).unwrap(),
        "the merged archive differs from the single bake"
    );
    // The arguments of a merge of both parts into `out`, checked against the scene `against`.
    let checked_merge = |out, against| vec!["merge", p0, p1, "-o", out, "--scene", against];
    // With the scene, the merge checks the merged archive as the single bake checks itself.
    let (single_checked, _, _) = bake(&dir, "single-checked", 1, "cpu", &["--quiet", "--probes", "32"]);
    let checked = dir.join("merged-checked.prm");
    let scene = scene_path();
    let mut args = checked_merge(checked.to_str().unwrap(), scene.to_str().unwrap());
    args.push("--quiet");
    let r = run(&args);
    assert!(r.status.success(), "{}", describe(&r));
    assert!(Archive::open(&checked).unwrap().metadata().accuracy.is_some());
    assert!(
        std::fs::read(&checked).unwrap() == std::fs::read(&single_checked).unwrap(),
        "the merged and checked archive differs from the single bake with its check"
    );

    // A part of a bake with another seed, a missing shard, a repeated one, a whole archive.
    let (other_seed, _, _) = bake(&parts_dir, "seed2", 2, "cpu", &["--quiet", "--shard", "1/2"]);
    let s = single.to_str().unwrap();
    for (args, expected) in [
        (vec![p0, other_seed.to_str().unwrap()], "seed"),
        (vec![p0], "shard 1/2 is missing"),
        (vec![p0, p0], "given twice"),
        (vec![p0, s], "whole archive"),
    ] {
        let out = dir.join("refused.prm");
        let r = run(&[&["merge"][..], &args, &["-o", out.to_str().unwrap()]].concat());
        assert_refused(&r, &format!("{args:?}"), expected);
        assert!(!out.exists(), "{args:?} left {}", out.display());
    }
    // A merge checked against another scene, or written over one of its parts, fails before
    // it writes: the output keeps its archive and nothing is left beside it.
    let keep = dir.join("keep.prm");
    std::fs::copy(&single, &keep).unwrap();
    let other_scene = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes/courtyard/courtyard.obj");
    let before = std::fs::read_dir(&dir).unwrap().count();
    for (args, expected) in [
        (
            checked_merge(keep.to_str().unwrap(), other_scene.to_str().unwrap()),
            "other geometry",
        ),
        (vec!["merge", p0, p1, "-o", p0], "is the part"),
    ] {
        let r = run(&args);
        assert_refused(&r, &format!("{args:?}"), expected);
    }
    assert!(
        std::fs::read(&keep).unwrap() == std::fs::read(&single).unwrap(),
        "a failed merge replaced the output"
    );
    assert!(
        Archive::open(&part0).unwrap().metadata().params.contains_key("shard"),
        "the part was replaced"
    );
    assert_eq!(
        std::fs::read_dir(&dir).unwrap().count(),
        before,
        "a failed merge left a file"
    );

    let r = run(&["bake", scene_path().to_str().unwrap(), "-o", m, "--shard", "2/2"]);
    assert_eq!(r.status.code(), Some(2), "--shard 2/2 accepted: {}", describe(&r));
    let r = run(&["bake", scene_path().to_str().unwrap(), "-o", m, "--shard", "0/1"]);
    assert_refused(&r, "--shard 0/1", "whole bake");
}

/// Small command-line conventions: a closed standard output ends a listing quietly, paths
/// that name no scene file say what they name, a shard that holds no cluster says so, `dump`
/// refuses an EXR directory that is a file before printing anything, and messages count right.
#[test]
fn command_line_conventions() {
    let dir = temp_dir("conventions");
    let scene = scene_path();
    let scene = scene.to_str().unwrap();

    // `prm-bake atlas scene | head -1`: the reader is gone before the first line is written.
    let mut child = Command::new(BIN)
        .args(["atlas", scene])
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    drop(child.stdout.take());
    let out = child.wait_with_output().unwrap();
    assert!(out.status.success(), "{}", describe(&out));
    assert!(
        !String::from_utf8_lossy(&out.stderr).contains("panicked"),
        "{}",
        describe(&out)
    );

    // A directory and `-` are named as such, refused before any work.
    for (path, expected) in [(dir.to_str().unwrap(), "is a directory"), ("-", "standard input")] {
        for command in ["atlas", "bake"] {
            let r =
                run(&[command, path, "-o", dir.join("x.prm").to_str().unwrap()]
                    [..if command == "atlas" { 2 } else { 4 }]);
            assert_refused(&r, &format!("{command} {path}"), expected);
        }
    }

    // Shard 99 of 100 of a 64-cluster plan renders nothing: a warning says so.
    let r = run(&[
        "bake",
        scene,
        "-o",
        dir.join("x.prm").to_str().unwrap(),
        "--preset",
        "preview",
        "--shard",
        "99/100",
        "--plan",
    ]);
    assert!(r.status.success(), "{}", describe(&r));
    let stderr = String::from_utf8_lossy(&r.stderr);
    assert!(stderr.contains("shard 99/100 holds no clusters"), "{}", describe(&r));
    // The plan bounds the panes' footprint: 64 clusters + 16 residual groups, 128² texels in
    // four 64² tiles of rank 128 at most: 4 × (4096 × 32 × 8 B of basis + 80 × 97 × 8 B of
    // coefficients, a scale word and three channels of 32 words of four f16 per pane).
    assert!(
        stderr.contains("footprint: panes at most 4.2 MiB resident on the GPU (64 clusters + 16 residual groups"),
        "{}",
        describe(&r)
    );

    // `dump --export-exr FILE`: refused before the summary is printed.
    let file = dir.join("not-a-dir");
    std::fs::write(&file, b"x").unwrap();
    let r = run(&[
        "dump",
        baked().archive.to_str().unwrap(),
        "--export-exr",
        file.to_str().unwrap(),
    ]);
    assert_refused(&r, "--export-exr onto a file", "not a directory");
    assert!(
        r.stdout.is_empty(),
        "nothing printed before the refusal: {}",
        describe(&r)
    );

    // A merge of one part counts it as one.
    let r = run(&[
        "merge",
        baked().archive.to_str().unwrap(),
        "-o",
        dir.join("merged.prm").to_str().unwrap(),
    ]);
    assert_refused(&r, "merge of one part", "merging 1 part into");

    // One sample per pixel has no standard error to report.
    let exr = dir.join("ref.exr");
    let r = run(&[
        "reference",
        scene,
        "--light",
        "point:0.278,0.5,0.28:1,1,1",
        "--camera",
        "0.28,0.27,-0.8:0.28,0.27,0.28:40",
        "--size",
        "8x8",
        "--spp",
        "1",
        "-o",
        exr.to_str().unwrap(),
    ]);
    assert!(r.status.success(), "{}", describe(&r));
    let stderr = String::from_utf8_lossy(&r.stderr);
    assert!(
        !stderr.contains("standard error 0.00%") && stderr.contains("no standard error"),
        "{}",
        describe(&r)
    );
}
