//! The errors of the player library.

use std::path::PathBuf;

/// Why the player could not load or render.
#[derive(Debug, thiserror::Error)]
pub enum PlayError {
    /// The archive could not be read.
    #[error("cannot read archive {path}")]
    Archive {
        /// The archive.
        path: PathBuf,
        /// The reader's reason.
        source: prm_format::Error,
    },
    /// The archive records no source scene and none was given.
    #[error("archive {0} records no source scene: pass --scene")]
    NoSourceScene(PathBuf),
    /// The scene could not be loaded.
    #[error("cannot load scene {path}")]
    Scene {
        /// The scene file.
        path: PathBuf,
        /// The loader's reason.
        source: prm_scene::SceneError,
    },
    /// The scene the archive records is not where it says (the archive was moved or copied).
    #[error(
        "cannot find the scene {path} that {archive} was baked from (its `source_scene`, relative \
         to the archive); give it with --scene"
    )]
    SceneMoved {
        /// The archive.
        archive: PathBuf,
        /// The scene file.
        path: PathBuf,
        /// The loader's reason.
        source: prm_scene::SceneError,
    },
    /// The archive was baked for other geometry.
    #[error(
        "archive {archive} was baked for another scene: its fingerprint is {expected:016x}, \
         {scene} has {found:016x} (re-bake, or pass the right --scene)"
    )]
    FingerprintMismatch {
        /// The archive.
        archive: PathBuf,
        /// The scene file.
        scene: PathBuf,
        /// Fingerprint recorded in the archive.
        expected: u64,
        /// Fingerprint of the scene.
        found: u64,
    },
    /// An option is out of range, or beyond what this device can allocate.
    #[error("{option}: {message}")]
    Option {
        /// The option, named as `prm-play` spells it.
        option: &'static str,
        /// What is wrong and which limit it breaks.
        message: String,
    },
    /// A GPU error (no device, validation, device lost).
    #[error(transparent)]
    Gpu(#[from] prm_gpu_kit::GpuError),
    /// The run time could not load the archive or run a frame.
    #[error(transparent)]
    Runtime(prm_runtime::RuntimeError),
    /// The CPU player could not read what it needs of the archive or build its model.
    #[error("CPU player: {0}")]
    Cpu(String),
    /// Window mode failed (no display, no surface).
    #[error("window mode: {0}")]
    Window(String),
    /// An animation file could not be read or is invalid.
    #[error("animation {path}: {message}")]
    Animation {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// Writing the exported lightmaps or scene failed.
    #[error(transparent)]
    Export(prm_scene::ExportError),
    /// Writing an image failed.
    #[error("cannot write {path}: {message}")]
    Output {
        /// The file.
        path: PathBuf,
        /// Why.
        message: String,
    },
}

impl From<prm_runtime::RuntimeError> for PlayError {
    /// GPU errors stay [`PlayError::Gpu`] whichever layer raised them.
    fn from(e: prm_runtime::RuntimeError) -> PlayError {
        match e {
            prm_runtime::RuntimeError::Gpu(g) => PlayError::Gpu(g),
            e => PlayError::Runtime(e),
        }
    }
}
