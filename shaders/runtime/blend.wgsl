// prm-runtime blend pass: the indirect-irradiance lightmap. At texel i of atlas tile t, the
// panes' lit combination Σ_k U_t[i][k]·a_{t,k} (the tile's basis row times the mixed
// coefficients of mix.wgsl), clamped at zero, plus the traced indirect light of the emitters at
// their scales and of the sky (baked.rs; a 1×1 texture, ignored, when neither has one), plus the
// near field (near_field.wgsl, likewise). The basis rows are f16, four to a vec2<u32>, zero
// beyond the rank; only rows that are not zero are stored. One invocation per texel of the
// chunk that anything lights (`texels`, built at load: the basis, the traced indirect lightmap
// or the near field is not zero there); the others keep the lightmap's zero.

@group(0) @binding(0) var<uniform> chunk: BlendChunk;
@group(0) @binding(1) var<storage, read> tiles: array<PaneTile>;
@group(0) @binding(2) var<storage, read> basis: array<vec2<u32>>;
// The chunk's lit texels: atlas texel index (ascending) and its basis row in `basis`, NO_ROW
// where the row is zero.
@group(0) @binding(3) var<storage, read> texels: array<vec2<u32>>;
@group(0) @binding(4) var<storage, read> mixed: array<vec4<f32>>;
@group(0) @binding(5) var lightmap: texture_storage_2d<rgba32float, write>;
@group(0) @binding(6) var emitted: texture_2d<f32>;
// The near field's lightmap (near_field.wgsl); 1×1, ignored, without one.
@group(0) @binding(7) var near_map: texture_2d<f32>;

const NO_ROW: u32 = 0xFFFFFFFFu;

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = linear_index(gid, groups);
    if i >= chunk.lit_texels {
        return;
    }
    let size = textureDimensions(lightmap);
    let texel = texels[i];
    let xy = texel_xy(texel.x, size.x);
    let ts = chunk.tile_size;
    let t = (u32(xy.y) / ts) * chunk.tiles_per_side + u32(xy.x) / ts;
    let tile = tiles[t];
    let row = texel.y;
    let m = t * chunk.mixed_stride;
    let stride = select(tile.stride, 0u, row == NO_ROW);
    var sum = vec3<f32>(0.0);
    for (var k = 0u; k < stride; k++) {
        let w = basis[row + k];
        let u01 = unpack2x16float(w.x);
        let u23 = unpack2x16float(w.y);
        sum += u01.x * mixed[m + 4u * k].rgb + u01.y * mixed[m + 4u * k + 1u].rgb +
            u23.x * mixed[m + 4u * k + 2u].rgb + u23.y * mixed[m + 4u * k + 3u].rgb;
    }
    sum = max(sum, vec3<f32>(0.0));
    if all(textureDimensions(emitted) == size) {
        sum += textureLoad(emitted, xy, 0).rgb;
    }
    if all(textureDimensions(near_map) == size) {
        sum += textureLoad(near_map, xy, 0).rgb;
    }
    textureStore(lightmap, xy, vec4<f32>(sum, 1.0));
}
