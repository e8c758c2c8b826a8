// prm-runtime probes pass: every probe's irradiance coefficients, Σ over all clusters of
// weight ⊙ the cluster's transfer to the probe (formats/prm.md §5.4), with the weights of the
// weights pass. One invocation per probe and coefficient.
//
// All clusters, not the blend's top K: the top K are chosen by their light on the whole atlas,
// and a probe near a cluster the cut drops loses its light (on the Cornell box with 8192 entries
// in 256 clusters, the probes were 40% from the reference with the blend's kept weights and
// 8.2% with all). The sum costs probes × 9 × clusters multiply-adds, small beside the blend.
//
// transfer: cluster-major, 27 floats (9 RGB coefficients) per cluster and probe.

@group(0) @binding(0) var<uniform> frame: Frame;
@group(0) @binding(1) var<storage, read> weights: array<Weight>;
@group(0) @binding(2) var<uniform> grid: ProbeGrid;
@group(0) @binding(3) var<storage, read> transfer: array<f32>;
@group(0) @binding(4) var<storage, read_write> probe_sh: array<vec4<f32>>;
// The sky's part (direct and bounced), summed on the CPU when the sky changes; zero without one.
@group(0) @binding(5) var<storage, read> sky_sh: array<vec4<f32>>;

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let n = grid.count;
    let slot = gid.x;
    if slot >= n * 9u {
        return;
    }
    var sum = vec3<f32>(0.0);
    for (var c = 0u; c < frame.cluster_count; c++) {
        let base = (c * n * 9u + slot) * 3u;
        sum += weights[c].weight * vec3<f32>(transfer[base], transfer[base + 1u], transfer[base + 2u]);
    }
    probe_sh[slot] = vec4<f32>(sum + sky_sh[slot].rgb, 0.0);
}
