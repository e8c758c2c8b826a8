//! Errors of the transport crate.

use thiserror::Error;

/// Everything that can go wrong while tracing, sampling, clustering or parsing a spec.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum TraceError {
    /// The scene has no triangles (or only zero-area ones).
    #[error("the scene has no surface to trace (no triangles of positive area)")]
    EmptyScene,
    /// A parameter is outside its valid range.
    #[error("invalid parameter: {0}")]
    InvalidParameter(String),
    /// A light, camera or size spec could not be parsed.
    #[error(transparent)]
    Spec(#[from] prm_scene::SpecError),
}
