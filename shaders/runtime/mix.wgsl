// prm-runtime mix pass: per atlas tile, the mixed coefficients a_k = Σ_j weight_j ⊙
// C[3·pane_j .. 3·pane_j + 3][k] over the kept clusters and the residual groups (select.wgsl;
// a group's coefficients are its members' summed, built at load), so that the blend's texel i
// of the tile is Σ_k U[i][k]·a_k (blend.wgsl). One invocation per (tile, k) of the chunk,
// k below mixed_stride; beyond the tile's rank it writes zeros, which the blend's padded basis
// rows multiply.

@group(0) @binding(0) var<uniform> frame: Frame;
@group(0) @binding(1) var<storage, read> selected: array<Selected>;
@group(0) @binding(2) var<uniform> chunk: BlendChunk;
@group(0) @binding(3) var<storage, read> tiles: array<PaneTile>;
@group(0) @binding(4) var<storage, read> coefficients: array<f32>;
@group(0) @binding(5) var<storage, read_write> mixed: array<vec4<f32>>;

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = linear_index(gid, groups);
    if i >= chunk.tiles * chunk.mixed_stride {
        return;
    }
    let t = chunk.first_tile + i / chunk.mixed_stride;
    let k = i % chunk.mixed_stride;
    let tile = tiles[t];
    var a = vec3<f32>(0.0);
    if k < tile.rank {
        let kept = min(frame.cluster_count, frame.top_k) +
            select(0u, frame.group_count, frame.cluster_count > frame.top_k);
        let r = tile.rank;
        for (var j = 0u; j < kept; j++) {
            let s = selected[j];
            let c = tile.coefficients + 3u * s.cluster * r + k;
            a += s.weight * vec3<f32>(coefficients[c], coefficients[c + r], coefficients[c + 2u * r]);
        }
    }
    mixed[t * chunk.mixed_stride + k] = vec4<f32>(a, 0.0);
}
