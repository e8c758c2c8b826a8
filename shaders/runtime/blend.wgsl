// prm-runtime blend pass: the indirect-irradiance lightmap, Σ over the kept clusters of
// weight_eff × pane and over the residual groups (when clusters were dropped) of their weight ×
// summed pane, per atlas texel (select.wgsl), plus the traced indirect light of the emitters at
// their scales and of the sky (baked.rs; a 1×1 texture, ignored, when neither has one), plus the
// near field (near_field.wgsl, likewise). Panes are RGB9E5 words in storage buffers, one per
// chunk of quads (four row-major texels, one vec4<u32>; blend.rs): pane p's quad q of this chunk
// at p × chunk.quads + q. One invocation per quad of the chunk that anything lights (`quads`,
// built at load: a pane, the traced indirect lightmap or the near field is not zero at one of
// its texels); the others keep the lightmap's zero.

@group(0) @binding(0) var<uniform> frame: Frame;
@group(0) @binding(1) var<storage, read> selected: array<Selected>;
@group(0) @binding(2) var<uniform> chunk: BlendChunk;
@group(0) @binding(3) var<storage, read> panes: array<vec4<u32>>;
// The chunk's lit quads, relative to its first, ascending.
@group(0) @binding(4) var<storage, read> quads: array<u32>;
@group(0) @binding(5) var lightmap: texture_storage_2d<rgba32float, write>;
@group(0) @binding(6) var emitted: texture_2d<f32>;
// The near field's lightmap (near_field.wgsl); 1×1, ignored, without one.
@group(0) @binding(7) var near_map: texture_2d<f32>;

// An RGB9E5 word (prm_format::decode_rgb9e5): three 9-bit mantissas × 2^(exponent − 24).
fn rgb9e5(w: u32) -> vec3<f32> {
    let scale = bitcast<f32>(((w >> 27u) + 103u) << 23u);
    return scale * vec3<f32>(f32(w & 0x1ffu), f32((w >> 9u) & 0x1ffu), f32((w >> 18u) & 0x1ffu));
}

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = linear_index(gid, groups);
    if i >= chunk.lit_quads {
        return;
    }
    let q = quads[i];
    let kept = min(frame.cluster_count, frame.top_k) +
        select(0u, frame.group_count, frame.cluster_count > frame.top_k);
    var s0 = vec3<f32>(0.0);
    var s1 = vec3<f32>(0.0);
    var s2 = vec3<f32>(0.0);
    var s3 = vec3<f32>(0.0);
    for (var k = 0u; k < kept; k++) {
        let s = selected[k];
        let w = panes[s.cluster * chunk.quads + q];
        s0 += s.weight * rgb9e5(w.x);
        s1 += s.weight * rgb9e5(w.y);
        s2 += s.weight * rgb9e5(w.z);
        s3 += s.weight * rgb9e5(w.w);
    }
    let sums = array<vec3<f32>, 4>(s0, s1, s2, s3);
    let size = textureDimensions(lightmap);
    let first = 4u * (chunk.first_quad + q);
    for (var j = 0u; j < 4u; j++) {
        let t = first + j;
        if t >= size.x * size.y {
            break;
        }
        let xy = texel_xy(t, size.x);
        var sum = sums[j];
        if all(textureDimensions(emitted) == size) {
            sum += textureLoad(emitted, xy, 0).rgb;
        }
        if all(textureDimensions(near_map) == size) {
            sum += textureLoad(near_map, xy, 0).rgb;
        }
        textureStore(lightmap, xy, vec4<f32>(sum, 1.0));
    }
}
