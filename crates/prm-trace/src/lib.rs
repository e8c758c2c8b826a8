//! CPU light transport (placeholder until the transport issue lands).
