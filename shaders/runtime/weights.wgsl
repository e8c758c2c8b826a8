// prm-runtime weights pass: irradiance of every entry point from the lights (shadow-mapped) and
// the emitters (precomputed), and
// each cluster's weight = its members' irradiance weighed by their pane energy,
// Σ E_i e_i / Σ e_i per channel (the mean when every e_i is 1, archives without entry energies), so the
// cluster gives the indirect energy its members would give unclustered; score = Σ_rgb weight ×
// pane energy.

@group(0) @binding(0) var<uniform> frame: Frame;
@group(0) @binding(1) var<storage, read> lights: array<Light>;
@group(0) @binding(2) var<storage, read> views: array<ShadowView>;
@group(0) @binding(3) var shadow_maps: texture_depth_2d_array;
@group(0) @binding(4) var<storage, read> clusters: array<Cluster>;
@group(0) @binding(5) var<storage, read> entries: array<Entry>;
@group(0) @binding(6) var<storage, read_write> weights: array<Weight>;

// One workgroup per cluster (x + 65535·y), its invocations sharing the members: with one
// invocation per cluster, 64 clusters made a single workgroup, which lavapipe runs on one thread.
const WEIGHT_LANES: u32 = 32u;
var<workgroup> partial: array<vec3<f32>, WEIGHT_LANES>;
var<workgroup> partial_energy: array<vec3<f32>, WEIGHT_LANES>;

@compute @workgroup_size(32)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_index) lane: u32) {
    let c = wid.x + wid.y * 65535u;
    // Uniform per workgroup, so the barrier below stays in uniform control flow.
    if c >= frame.cluster_count {
        return;
    }
    let cl = clusters[c];
    var sum = vec3<f32>(0.0);
    var sum_energy = vec3<f32>(0.0);
    for (var k = lane; k < cl.count; k += WEIGHT_LANES) {
        let e = entries[cl.first + k];
        // Bounded: the entry stands for a disk of radius² e.disk, see light_irradiance_disk.
        // Plus the emitters' (baked at unit scale, summed at their scales on the CPU).
        sum += (direct_irradiance_disk(e.position, e.normal, e.disk) + e.emitted) * e.energy;
        sum_energy += e.energy;
    }
    partial[lane] = sum;
    partial_energy[lane] = sum_energy;
    workgroupBarrier();
    if lane == 0u {
        var total = vec3<f32>(0.0);
        var total_energy = vec3<f32>(0.0);
        for (var i = 0u; i < WEIGHT_LANES; i++) {
            total += partial[i];
            total_energy += partial_energy[i];
        }
        // A channel whose members carry no energy contributes nothing whatever its weight.
        let w = select(vec3<f32>(0.0), total / total_energy, total_energy > vec3<f32>(0.0));
        weights[c] = Weight(w, dot(w, cl.energy));
    }
}
