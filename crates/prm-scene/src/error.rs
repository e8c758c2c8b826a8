//! Errors of scene loading and atlas building.

use std::path::PathBuf;

/// Why a scene could not be loaded or given an atlas.
#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    /// The scene file does not exist.
    #[error("{0}: no such file")]
    NotFound(PathBuf),
    /// The extension is neither `.obj`, `.gltf` nor `.glb`.
    #[error("{0}: unsupported scene format (expected .obj, .gltf or .glb)")]
    UnsupportedFormat(PathBuf),
    /// Reading the file failed.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// The file is not a well-formed scene of its format.
    #[error("{path}{}: {message}", line.map(|l| format!(":{l}")).unwrap_or_default())]
    Malformed {
        /// The file.
        path: PathBuf,
        /// The 1-based line, where the format has lines and the fault could be located.
        line: Option<usize>,
        /// What is wrong.
        message: String,
    },
    /// A coordinate is NaN or infinite.
    #[error("{path}: non-finite coordinate ({what})")]
    NonFinite {
        /// The file.
        path: PathBuf,
        /// Which value (object or node and vertex).
        what: String,
    },
    /// Nothing left to light: the file has no (non-degenerate) triangles.
    #[error("{path}: no triangles ({dropped} degenerate triangles dropped)")]
    NoTriangles {
        /// The file.
        path: PathBuf,
        /// How many degenerate triangles were dropped.
        dropped: usize,
    },
    /// The atlas parameters cannot be satisfied for this scene.
    #[error("atlas: {0}")]
    Atlas(String),
}
