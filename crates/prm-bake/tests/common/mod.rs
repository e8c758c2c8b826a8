//! Helpers shared by the test files of `prm-bake` (`bake.rs`, `library.rs`).

use std::path::{Path, PathBuf};

/// The Cornell box every test bakes.
pub fn scene_path() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes/cornell-box/cornell-box.obj")
}

/// A fresh, empty directory `suite/name` under the cargo-provided temporary directory.
pub fn scratch_dir(suite: &str, name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join(suite).join(name);
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// The steps every bake times (`Baked::timings`, the report's `timings`).
pub const STEPS: [&str; 7] = [
    "atlas",
    "bvh",
    "light_tracing",
    "clustering",
    "pane_rendering",
    "accuracy_check",
    "compression_write",
];
