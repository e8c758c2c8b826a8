// prm-runtime mix pass: per atlas tile, the mixed coefficients a_k = Σ_j weight_j ⊙
// C[3·pane_j .. 3·pane_j + 3][k] over the kept clusters and the residual groups (select.wgsl;
// a group's coefficients are its members' summed, built at load), so that the blend's texel i
// of the tile is Σ_k U[i][k]·a_k (blend.wgsl). A tile's coefficients start with an index, one
// u32 per pane, two a word: where pane p's block starts after `coefficients`, or NO_BLOCK where
// the pane is zero in the tile (blend.rs's tile_blocks). A block is its scale (f32 bits in x),
// then each channel's coefficients over the scale as f16, four ranks a word (zero-padded beyond
// the rank; blend.rs's PaneBlock). One invocation per tile of the chunk and group of four
// ranks, up to mixed_stride/4; beyond the tile's rank it writes zeros, which the blend's padded
// basis rows multiply.

@group(0) @binding(0) var<uniform> frame: Frame;
@group(0) @binding(1) var<storage, read> selected: array<Selected>;
@group(0) @binding(2) var<uniform> chunk: BlendChunk;
@group(0) @binding(3) var<storage, read> tiles: array<PaneTile>;
@group(0) @binding(4) var<storage, read> coefficients: array<vec2<u32>>;
@group(0) @binding(5) var<storage, read_write> mixed: array<vec4<f32>>;

// A pane without a block in a tile (blend.rs's NO_BLOCK).
const NO_BLOCK: u32 = 0xffffffffu;

// Four f16 coefficients of word `c`.
fn quad(c: u32) -> vec4<f32> {
    let q = coefficients[c];
    return vec4<f32>(unpack2x16float(q.x), unpack2x16float(q.y));
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
    var r = vec4<f32>(0.0);
    var g = vec4<f32>(0.0);
    var b = vec4<f32>(0.0);
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
            let c = block + 1u + k4;
            r += w.r * quad(c);
            g += w.g * quad(c + tile.stride);
            b += w.b * quad(c + 2u * tile.stride);
        }
    }
    let m = t * chunk.mixed_stride + 4u * k4;
    for (var k = 0u; k < 4u; k++) {
        mixed[m + k] = vec4<f32>(r[k], g[k], b[k], 0.0);
    }
}
