// prm-runtime mix pass: per atlas tile, the mixed coefficients a_k = Σ_j weight_j ⊙
// C[3·pane_j .. 3·pane_j + 3][k] over the kept clusters and the residual groups (select.wgsl;
// a group's coefficients are its members' summed, built at load), so that the blend's texel i
// of the tile is Σ_k U[i][k]·a_k (blend.wgsl). A tile's coefficients start with an index, one
// u32 per pane, two a word: where pane p's block starts after `coefficients`, or NO_BLOCK where
// the pane is zero in the tile (blend.rs's tile_blocks). A block is its scale (f32 bits in x),
// then per rank its three channels over the scale as one shared-exponent word, two ranks a
// vec2 (zero-padded to a multiple of four ranks; blend.rs's PaneBlock). One invocation per tile
// of the chunk and group of four ranks, up to mixed_stride/4; beyond the tile's rank it writes
// zeros, which the blend's padded basis rows multiply.

@group(0) @binding(0) var<uniform> frame: Frame;
@group(0) @binding(1) var<storage, read> selected: array<Selected>;
@group(0) @binding(2) var<uniform> chunk: BlendChunk;
@group(0) @binding(3) var<storage, read> tiles: array<PaneTile>;
@group(0) @binding(4) var<storage, read> coefficients: array<vec2<u32>>;
@group(0) @binding(5) var<storage, read_write> mixed: array<vec4<f32>>;

// A pane without a block in a tile (blend.rs's NO_BLOCK).
const NO_BLOCK: u32 = 0xffffffffu;

// One rank's three channels (blend.rs's PaneBlock::triple): 9-bit two's-complement mantissas
// in bits 0-8, 9-17 and 18-26 over 2^(n+7), n in bits 27-31 (the power built exactly).
fn triple(w: u32) -> vec3<f32> {
    let m = vec3<i32>(bitcast<i32>(w << 23u), bitcast<i32>(w << 14u), bitcast<i32>(w << 5u)) >> vec3<u32>(23u);
    return vec3<f32>(m) * bitcast<f32>((120u - (w >> 27u)) << 23u);
}

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = linear_index(gid, groups);
    let quads = chunk.mixed_stride / 4u;
    if i >= chunk.tiles * quads {
        return;
    }
    let t = chunk.first_tile + i / quads;
    let k4 = i % quads;
    let tile = tiles[t];
    var a0 = vec3<f32>(0.0);
    var a1 = vec3<f32>(0.0);
    var a2 = vec3<f32>(0.0);
    var a3 = vec3<f32>(0.0);
    if k4 < tile.stride {
        let kept = min(frame.cluster_count, frame.top_k) +
            select(0u, frame.group_count, frame.cluster_count > frame.top_k);
        for (var j = 0u; j < kept; j++) {
            let s = selected[j];
            let pair = coefficients[tile.coefficients + s.cluster / 2u];
            let at = select(pair.x, pair.y, (s.cluster & 1u) == 1u);
            if at == NO_BLOCK {
                continue;
            }
            let block = tile.coefficients + at;
            let w = s.weight * bitcast<f32>(coefficients[block].x);
            let lo = coefficients[block + 1u + 2u * k4];
            let hi = coefficients[block + 2u + 2u * k4];
            a0 += w * triple(lo.x);
            a1 += w * triple(lo.y);
            a2 += w * triple(hi.x);
            a3 += w * triple(hi.y);
        }
    }
    let m = t * chunk.mixed_stride + 4u * k4;
    mixed[m] = vec4<f32>(a0, 0.0);
    mixed[m + 1u] = vec4<f32>(a1, 0.0);
    mixed[m + 2u] = vec4<f32>(a2, 0.0);
    mixed[m + 3u] = vec4<f32>(a3, 0.0);
}
