// prm-play weights pass: irradiance of every entry point from the lights (shadow-mapped), and
// each cluster's weight = mean over its entry points; score = Σ_rgb weight × pane energy.

struct Cluster {
    first: u32,
    count: u32,
    _pad0: u32,
    _pad1: u32,
    energy: vec4<f32>,
};

struct Entry {
    position: vec4<f32>,
    normal: vec4<f32>,
};

@group(0) @binding(0) var<uniform> frame: Frame;
@group(0) @binding(1) var<storage, read> lights: array<Light>;
@group(0) @binding(2) var<storage, read> views: array<ShadowView>;
@group(0) @binding(3) var shadow_maps: texture_depth_2d_array;
@group(0) @binding(4) var<storage, read> clusters: array<Cluster>;
@group(0) @binding(5) var<storage, read> entries: array<Entry>;
// xyz: weight, w: score
@group(0) @binding(6) var<storage, read_write> weights: array<vec4<f32>>;

// One workgroup per cluster (x + 65535·y), its invocations sharing the members: with one
// invocation per cluster, 64 clusters made a single workgroup, which lavapipe runs on one thread.
const WEIGHT_LANES: u32 = 32u;
var<workgroup> partial: array<vec3<f32>, WEIGHT_LANES>;

@compute @workgroup_size(32)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_index) lane: u32) {
    let c = wid.x + wid.y * 65535u;
    // Uniform per workgroup, so the barrier below stays in uniform control flow.
    if c >= frame.clusters.x {
        return;
    }
    let cl = clusters[c];
    var sum = vec3<f32>(0.0);
    for (var k = lane; k < cl.count; k += WEIGHT_LANES) {
        let e = entries[cl.first + k];
        // Bounded: the entry stands for a disk (position.w = its radius²), see entry_irradiance.
        sum += direct_irradiance_disk(e.position.xyz, e.normal.xyz, e.position.w);
    }
    partial[lane] = sum;
    workgroupBarrier();
    if lane == 0u {
        var total = vec3<f32>(0.0);
        for (var i = 0u; i < WEIGHT_LANES; i++) {
            total += partial[i];
        }
        let w = total / f32(max(cl.count, 1u));
        weights[c] = vec4<f32>(w, dot(w, cl.energy.rgb));
    }
}
