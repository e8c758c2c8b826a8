//! [`ProgressSink`]: where the bake reports its phases, information and warnings (the library
//! never prints).

use std::fmt;

/// A phase of [`bake`](crate::bake), in the order they run.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub enum Phase {
    /// Building the lightmap atlas (its texel centres are the exit points).
    Atlas,
    /// Building the BVH the walks and the CPU panes trace against.
    Bvh,
    /// Sampling entry points and tracing random walks from them (the VPLs).
    LightTracing,
    /// Grouping entry points into clusters (one pane each).
    Clustering,
    /// The emitters' direct irradiance at the entry points and the texels (scenes with
    /// emissive materials only).
    Emitters,
    /// The sky's transfer at the texels (bakes with `--sky` only).
    Sky,
    /// The near rays from the exit points that gather back what the VPL bound removes
    /// (`near_rays` > 0 only).
    NearField,
    /// Rendering the panes (GPU or CPU) and writing them to the archive.
    PaneRendering,
    /// The clusters' transfer to the irradiance probes (bakes with `--probes` only).
    Probes,
    /// The bake's estimate of its own accuracy against the reference tracer
    /// ([`prm_trace::check_accuracy`]; whole bakes with `accuracy_points` > 0).
    AccuracyCheck,
}

impl Phase {
    /// The phase's name as the command line prints it, e.g. "light tracing".
    pub fn name(self) -> &'static str {
        match self {
            Phase::Atlas => "atlas",
            Phase::Bvh => "bvh",
            Phase::LightTracing => "light tracing",
            Phase::Clustering => "clustering",
            Phase::Emitters => "emitters",
            Phase::Sky => "sky",
            Phase::PaneRendering => "pane rendering",
            Phase::NearField => "near field",
            Phase::Probes => "probes",
            Phase::AccuracyCheck => "accuracy check",
        }
    }
}

impl fmt::Display for Phase {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// Receives a bake's progress. Every method has a do-nothing default, so a sink implements only
/// what it shows; [`NoProgress`] shows nothing.
///
/// A phase is reported as [`phase_start`](Self::phase_start), any number of
/// [`phase_advance`](Self::phase_advance), then [`phase_finish`](Self::phase_finish); phases do
/// not overlap. [`info`](Self::info) and [`warn`](Self::warn) may come at any time.
pub trait ProgressSink {
    /// `phase` starts; it has `total` steps (1 for phases without finer progress).
    fn phase_start(&mut self, phase: Phase, total: u64) {
        let _ = (phase, total);
    }

    /// The current phase has done `done` of its steps in all (not since the last call).
    fn phase_advance(&mut self, done: u64) {
        let _ = done;
    }

    /// `phase` ended after `seconds`; `summary` says what it produced, e.g. "16 clusters".
    fn phase_finish(&mut self, phase: Phase, summary: &str, seconds: f64) {
        let _ = (phase, summary, seconds);
    }

    /// A line of information (device statistics, why something was chosen).
    fn info(&mut self, line: &str) {
        let _ = line;
    }

    /// Something the user should know about even when they asked for quiet.
    fn warn(&mut self, line: &str) {
        let _ = line;
    }
}

/// A [`ProgressSink`] that ignores everything.
#[derive(Clone, Copy, Debug, Default)]
pub struct NoProgress;

impl ProgressSink for NoProgress {}
