//! Helpers shared by the integration tests of `prm-scene` (`scene.rs`, `fuzz.rs`).

use std::path::{Path, PathBuf};

/// A fresh directory under the system temp dir, unique to this test and process; removed
/// when dropped.
pub struct TempDir(pub PathBuf);

impl std::ops::Deref for TempDir {
    type Target = Path;
    fn deref(&self) -> &Path {
        &self.0
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// A fresh `TempDir` named after `name`.
pub fn temp_case(name: &str) -> TempDir {
    let dir = std::env::temp_dir().join(format!("prm-scene-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    TempDir(dir)
}
