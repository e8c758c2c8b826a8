//! Helpers shared by the end-to-end tests of `prm-tests` (the test files sit beside this
//! folder, one `[[test]]` each in `tests/Cargo.toml`).

use std::path::{Path, PathBuf};

use prm_gpu_kit::{Backend, GpuContext};

/// A path inside the repository.
pub fn repo(path: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..").join(path)
}

/// A fresh, empty scratch folder under the target directory, named for the test.
pub fn temp_dir(name: &str) -> PathBuf {
    let dir = repo("target/prm-tests").join(name);
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("create a scratch folder under target/");
    dir
}

/// A Vulkan device, explicitly: a missing driver fails loudly instead of falling back to GL.
pub fn gpu() -> GpuContext {
    GpuContext::new(Backend::Vulkan).expect("a Vulkan adapter (apt-get install mesa-vulkan-drivers)")
}
