//! Errors of scene loading and atlas building.

use std::path::PathBuf;

/// Why a scene could not be loaded or given an atlas.
#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    /// The scene file does not exist.
    #[error("{0}: no such file")]
    NotFound(PathBuf),
    /// The path names a directory.
    #[error("{0}: is a directory; give the scene file (.obj, .gltf or .glb) inside it")]
    IsDirectory(PathBuf),
    /// The path is `-`: scenes are files (an OBJ names its `.mtl`, a glTF its buffers).
    #[error("reading a scene from standard input is not supported; give the scene file's path")]
    Stdin,
    /// The extension is neither `.obj`, `.gltf` nor `.glb`.
    #[error("{0}: unsupported scene format (expected .obj, .gltf or .glb)")]
    UnsupportedFormat(PathBuf),
    /// Reading the file failed (the I/O error is the source: `{:#}` prints it once).
    #[error("{path}: cannot read it")]
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
    /// An external glTF buffer file (`.bin`) could not be read: names that file, not the scene.
    #[error("{path}: buffer {buffer} of {scene} could not be read")]
    BufferFile {
        /// The buffer file the glTF refers to.
        path: PathBuf,
        /// The glTF file that refers to it.
        scene: PathBuf,
        /// Index of the buffer in the glTF.
        buffer: usize,
        /// The I/O error.
        source: std::io::Error,
    },
    /// A glTF buffer holds fewer bytes than its declared `byteLength`.
    #[error("{path}: buffer {buffer} declares {declared} bytes but holds only {actual}")]
    BufferLength {
        /// The buffer file (the scene itself for GLB and data-URI buffers).
        path: PathBuf,
        /// Index of the buffer.
        buffer: usize,
        /// Its declared `byteLength`.
        declared: u64,
        /// How many bytes it really holds.
        actual: u64,
    },
    /// A glTF bufferView reaches past the end of its buffer.
    #[error("{path}: bufferView {view} needs {needed} bytes of buffer {buffer}, which is {actual} bytes long")]
    BufferView {
        /// The glTF file.
        path: PathBuf,
        /// Index of the bufferView.
        view: usize,
        /// Index of the buffer it reads.
        buffer: usize,
        /// `byteOffset + byteLength` of the view.
        needed: u64,
        /// The buffer's real length.
        actual: u64,
    },
    /// A glTF accessor cannot be read: its range overruns its bufferView, its count is
    /// absurd, or its type does not fit its use.
    #[error("{path}: accessor {accessor}: {message}")]
    Accessor {
        /// The glTF file.
        path: PathBuf,
        /// Index of the accessor.
        accessor: usize,
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
