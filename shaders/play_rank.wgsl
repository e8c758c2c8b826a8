// prm-play rank pass: rank of every cluster by score (number of clusters with a larger score,
// ties broken by index), O(C²); the cluster ranked K (the first one dropped) publishes its score
// as the fade threshold.

struct Frame {
    view_proj: mat4x4<f32>,
    eye: vec4<f32>,
    counts: vec4<u32>,
    clusters: vec4<u32>,
    params: vec4<f32>,
};

@group(0) @binding(0) var<uniform> frame: Frame;
@group(0) @binding(1) var<storage, read> weights: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read_write> ranks: array<u32>;
@group(0) @binding(3) var<storage, read_write> threshold: array<f32>;

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let i = gid.x;
    let n = frame.clusters.x;
    if i >= n {
        return;
    }
    let s = weights[i].w;
    var rank = 0u;
    for (var j = 0u; j < n; j++) {
        let t = weights[j].w;
        if t > s || (t == s && j < i) {
            rank += 1u;
        }
    }
    ranks[i] = rank;
    if rank == frame.clusters.y {
        threshold[0] = s;
    }
}
