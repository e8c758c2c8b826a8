// prm-runtime blend pass: the indirect-irradiance lightmap, Σ over the kept clusters of
// weight_eff × pane and over the residual groups (when clusters were dropped) of their weight ×
// summed pane, per atlas texel (select.wgsl), plus the traced indirect light of the emitters at their
// scales and of the sky (baked.rs; a 1×1 texture, ignored, when neither has one), plus the near field
// (near_field.wgsl, likewise); panes are layers of an
// rgb9e5ufloat texture array. One invocation per texel that anything lights (`lit`, built at
// load: a pane, the traced indirect lightmap or the near field is not zero there); the others
// keep the lightmap's zero.

@group(0) @binding(0) var<uniform> frame: Frame;
@group(0) @binding(1) var<storage, read> selected: array<Selected>;
@group(0) @binding(2) var panes: texture_2d_array<f32>;
@group(0) @binding(3) var lightmap: texture_storage_2d<rgba32float, write>;
@group(0) @binding(4) var emitted: texture_2d<f32>;
// The near field's lightmap (near_field.wgsl); 1×1, ignored, without one.
@group(0) @binding(5) var near_map: texture_2d<f32>;
// The lit texels, row-major indices, ascending.
@group(0) @binding(6) var<storage, read> lit: array<u32>;

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = linear_index(gid, groups);
    if i >= frame.lit_texels {
        return;
    }
    let size = textureDimensions(lightmap);
    let t = lit[i];
    let xy = vec2<i32>(i32(t % size.x), i32(t / size.x));
    let kept = min(frame.cluster_count, frame.top_k) +
        select(0u, frame.group_count, frame.cluster_count > frame.top_k);
    var sum = vec3<f32>(0.0);
    for (var k = 0u; k < kept; k++) {
        let s = selected[k];
        sum += s.weight * textureLoad(panes, xy, i32(s.cluster), 0).rgb;
    }
    if all(textureDimensions(emitted) == size) {
        sum += textureLoad(emitted, xy, 0).rgb;
    }
    if all(textureDimensions(near_map) == size) {
        sum += textureLoad(near_map, xy, 0).rgb;
    }
    textureStore(lightmap, xy, vec4<f32>(sum, 1.0));
}
