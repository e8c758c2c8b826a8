//! [`BakeError`]: why planning or baking failed.

use std::path::PathBuf;

/// Why a bake could not be planned or finished. Displayed with its sources (`{:#}` through
/// `anyhow`, or by walking [`std::error::Error::source`]), it reads like the command line's
/// messages: "building the BVH: the scene has no surface to trace …".
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum BakeError {
    /// The TOML config file could not be read.
    #[error("reading {}", path.display())]
    ConfigRead {
        /// The config file.
        path: PathBuf,
        /// The I/O error.
        #[source]
        source: std::io::Error,
    },
    /// The TOML config file is not a valid bake config (syntax, unknown key, wrong type).
    #[error("{}: not a valid bake config", path.display())]
    ConfigParse {
        /// The config file.
        path: PathBuf,
        /// What the TOML parser says.
        #[source]
        source: Box<toml::de::Error>,
    },
    /// Parameters that cannot work together (zero counts, more clusters than entries, values
    /// outside their ranges, non-positive budgets).
    #[error("{0}")]
    InvalidParams(String),
    /// Parameters over a limit: the archive format's, the run-time memory budget, the atlas's.
    #[error("{0}")]
    OverLimit(String),
    /// Building an atlas failed (`what` says which).
    #[error("{what}")]
    Atlas {
        /// "building the lightmap atlas" or "building the automatic atlas".
        what: &'static str,
        /// The atlas builder's reason.
        #[source]
        source: prm_scene::SceneError,
    },
    /// A transport step failed: BVH, entry sampling, walks, clustering, CPU panes.
    #[error("{what}")]
    Trace {
        /// The step, e.g. "tracing walks".
        what: &'static str,
        /// The transport crate's reason.
        #[source]
        source: prm_trace::TraceError,
    },
    /// Rendering the panes on the GPU failed.
    #[error("rendering panes on the GPU")]
    Gpu(#[source] prm_gpu::GpuError),
    /// The archive cannot be written at the destination (checked before any work).
    #[error(transparent)]
    Destination(prm_format::Error),
    /// Writing the archive failed (`what` says at which step); the temporary file is gone and an
    /// older archive at the destination is untouched.
    #[error("{what}")]
    Archive {
        /// The step, e.g. "writing a pane".
        what: String,
        /// The archive writer's reason.
        #[source]
        source: prm_format::Error,
    },
    /// Creating the output directory failed.
    #[error("creating {}", path.display())]
    OutputDir {
        /// The directory.
        path: PathBuf,
        /// The I/O error.
        #[source]
        source: std::io::Error,
    },
    /// The parameters could not be recorded in the archive's metadata.
    #[error("recording the parameters in the archive's metadata")]
    Metadata(#[source] serde_json::Error),
}

impl From<prm_gpu::GpuError> for BakeError {
    fn from(e: prm_gpu::GpuError) -> Self {
        BakeError::Gpu(e)
    }
}
