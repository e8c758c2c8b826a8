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
    Spec(#[from] SpecError),
}

/// A light, camera or image-size spec that could not be parsed.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum SpecError {
    /// The light kind before the first `:` is not `point`, `spot` or `dir`.
    #[error("unknown light kind {kind:?} in {spec:?} (expected point, spot or dir)")]
    UnknownLightKind {
        /// The whole spec.
        spec: String,
        /// The kind found.
        kind: String,
    },
    /// Wrong number of `:`-separated fields.
    #[error("{what} spec {spec:?} has {found} ':'-separated fields, expected {expected} ({format})")]
    FieldCount {
        /// What was being parsed.
        what: &'static str,
        /// The whole spec.
        spec: String,
        /// Fields found.
        found: usize,
        /// Fields expected.
        expected: usize,
        /// The expected format.
        format: &'static str,
    },
    /// A field is not a number or not a vector of the right length.
    #[error("bad {field} {value:?} in {spec:?}: {reason}")]
    BadField {
        /// The whole spec.
        spec: String,
        /// Which field.
        field: &'static str,
        /// Its text.
        value: String,
        /// What is wrong with it.
        reason: String,
    },
}
