//! `prm-play` on a machine without a Vulkan driver: the Vulkan loader is pointed at no driver,
//! so no adapter exists; `--backend auto` renders on the CPU with a note, and what only the GPU
//! player does is refused up front (exit status 2). The CPU frame's agreement with the GPU
//! frame is `tests/cpu_player.rs` in the workspace's `tests/`.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use prm_play::synthetic::{cornell_box_path, write_archive, SyntheticParams};

fn archive(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join(name);
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let scene_path = cornell_box_path();
    let scene = prm_scene::load(&scene_path).unwrap();
    let path = dir.join("cornell.prm");
    write_archive(&scene, &scene_path, &path, SyntheticParams::default()).unwrap();
    path
}

/// `prm-play` with the Vulkan loader shown no driver, and a backtrace asked for.
fn play_without_driver(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_prm-play"))
        .args(args)
        .env("VK_ICD_FILENAMES", "/nonexistent/icd.json")
        .env("VK_DRIVER_FILES", "/nonexistent/icd.json")
        .env("RUST_BACKTRACE", "1")
        .output()
        .unwrap()
}

#[test]
fn without_a_driver_frames_are_rendered_on_the_cpu() {
    let path = archive("prm-play-cpu");
    let out = path.with_file_name("frames");
    let result = play_without_driver(&[
        path.to_str().unwrap(),
        "--headless",
        "--size",
        "48x32",
        "--mode",
        "split",
        "--out",
        out.to_str().unwrap(),
    ]);
    let stderr = String::from_utf8_lossy(&result.stderr);
    assert!(result.status.success(), "{}:\n{stderr}", result.status);
    assert!(stderr.contains("rendering on the CPU"), "{stderr}");
    let image = prm_play::output::read_exr(&out.join("frame0000.exr")).unwrap();
    assert_eq!((image.width, image.height), (48, 32));
    let lit = image.rgb.iter().filter(|p| p.iter().sum::<f32>() > 0.0).count();
    assert!(lit > image.rgb.len() / 2, "{lit} of {} pixels lit", image.rgb.len());
    assert!(out.join("frame0000.png").is_file());
}

#[test]
fn what_only_the_gpu_player_does_is_refused_up_front() {
    let path = archive("prm-play-cpu-refused");
    let export = path.with_file_name("export");
    for args in [
        vec!["--headless", "--backend", "cpu", "--export", export.to_str().unwrap()],
        vec!["--headless", "--backend", "cpu", "--sky", "1,1,1"],
        vec!["--backend", "cpu"],
    ] {
        let mut all = vec![path.to_str().unwrap()];
        all.extend(&args);
        let result = play_without_driver(&all);
        let stderr = String::from_utf8_lossy(&result.stderr);
        assert_eq!(result.status.code(), Some(2), "{args:?}: {stderr}");
        assert_eq!(stderr.matches("error:").count(), 1, "{args:?}: {stderr}");
        assert!(!stderr.contains("backtrace"), "{args:?}: {stderr}");
    }
    // Vulkan asked for by name with no driver: one clear error, exit status 1.
    let result = play_without_driver(&[path.to_str().unwrap(), "--headless", "--backend", "vulkan"]);
    let stderr = String::from_utf8_lossy(&result.stderr);
    assert_eq!(result.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("mesa-vulkan-drivers"), "{stderr}");
}
