//! What the run time keeps on the GPU, by part, and what its indirect-light passes read a frame.
//!
//! The sizes come from the device's own allocator report (wgpu's Vulkan backend names every
//! allocation after its buffer's or texture's label), so they are what was allocated, padding
//! included, not what the code meant to allocate. Only the run time's labels count: a caller's
//! allocations on the same device are left out, those of another run time on it are not.

/// One part of the run time and its bytes: of GPU memory ([`crate::Runtime::gpu_memory`]) or
/// read on every update ([`crate::Runtime::gi_bytes_read_by_part`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MemoryPart {
    /// The part: `panes`, `near field`, `weights`, `probes`, `baked light` (emitters and sky),
    /// `lightmap`, `shadow maps`, `geometry` or `other`.
    pub name: &'static str,
    /// Bytes allocated for it.
    pub bytes: u64,
}

/// The parts in the order reports list them.
pub const MEMORY_PARTS: [&str; 9] = [
    "panes",
    "near field",
    "weights",
    "probes",
    "baked light",
    "lightmap",
    "shadow maps",
    "geometry",
    "other",
];

/// The part an allocation labelled `label` belongs to, or `None` when the label is not the run
/// time's.
pub(crate) fn part_of(label: &str) -> Option<&'static str> {
    let name = label.strip_prefix("prm ")?;
    let starts = |prefixes: &[&str]| prefixes.iter().any(|p| name.starts_with(p));
    Some(if starts(&["panes", "blend chunk", "lit texels", "group energy"]) {
        "panes"
    } else if starts(&["near"]) {
        "near field"
    } else if starts(&["probe", "gather"]) {
        "probes"
    } else if starts(&["baked"]) {
        "baked light"
    } else if starts(&["lightmap"]) {
        "lightmap"
    } else if starts(&["shadow"]) {
        "shadow maps"
    } else if starts(&[
        "weights",
        "ranks",
        "threshold",
        "selected",
        "effective",
        "entries",
        "cell points",
        "clusters",
        "frame",
        "lights",
        "views",
    ]) {
        "weights"
    } else if starts(&["positions", "atlas vertices", "irradiance"]) {
        "geometry"
    } else {
        "other"
    })
}

/// Sums `report`'s allocations of the run time by part, every part listed (zero when absent).
pub(crate) fn by_part(report: &wgpu::AllocatorReport) -> Vec<MemoryPart> {
    let mut parts: Vec<MemoryPart> = MEMORY_PARTS.iter().map(|&name| MemoryPart { name, bytes: 0 }).collect();
    for a in &report.allocations {
        if let Some(name) = part_of(&a.name) {
            if let Some(p) = parts.iter_mut().find(|p| p.name == name) {
                p.bytes += a.size;
            }
        }
    }
    parts
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every label the run time gives a buffer or texture falls in a named part, and a
    /// caller's labels are not counted.
    #[test]
    fn labels_fall_in_their_parts() {
        let parts: [(Option<&str>, &[&str]); 10] = [
            (Some("panes"), &["prm panes basis", "prm lit texels"]),
            (Some("near field"), &["prm near hits", "prm near field, last sum"]),
            (Some("probes"), &["prm probe coefficients", "prm gather points"]),
            (Some("baked light"), &["prm baked direct lightmap"]),
            (Some("lightmap"), &["prm lightmap"]),
            (Some("shadow maps"), &["prm shadow maps"]),
            (Some("weights"), &["prm weights", "prm cell points"]),
            (Some("geometry"), &["prm positions"]),
            (Some("other"), &["prm something new"]),
            (None, &["my engine's gbuffer"]),
        ];
        for (part, labels) in parts {
            for label in labels {
                assert_eq!(part_of(label), part, "{label}");
            }
        }
    }
}
