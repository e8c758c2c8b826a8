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

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let c = gid.x;
    if c >= frame.clusters.x {
        return;
    }
    let cl = clusters[c];
    var sum = vec3<f32>(0.0);
    for (var k = 0u; k < cl.count; k++) {
        let e = entries[cl.first + k];
        // Bounded: the entry stands for a disk (position.w = its radius²), see entry_irradiance.
        sum += direct_irradiance_disk(e.position.xyz, e.normal.xyz, e.position.w);
    }
    let w = sum / f32(max(cl.count, 1u));
    weights[c] = vec4<f32>(w, dot(w, cl.energy.rgb));
}
