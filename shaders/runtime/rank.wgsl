// prm-runtime rank pass: rank of every cluster by score (number of clusters with a larger score,
// ties broken by index), O(C²); the cluster ranked K (the first one dropped) publishes its score
// as the fade threshold.

@group(0) @binding(0) var<uniform> frame: Frame;
@group(0) @binding(1) var<storage, read> weights: array<Weight>;
@group(0) @binding(2) var<storage, read_write> ranks: array<u32>;
@group(0) @binding(3) var<storage, read_write> threshold: array<f32>;

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let i = gid.x;
    let n = frame.cluster_count;
    if i >= n {
        return;
    }
    let s = weights[i].score;
    var rank = 0u;
    for (var j = 0u; j < n; j++) {
        let t = weights[j].score;
        if t > s || (t == s && j < i) {
            rank += 1u;
        }
    }
    ranks[i] = rank;
    if rank == frame.top_k {
        threshold[0] = s;
    }
}
