// prm-runtime near indirect radiance pass (archives of format 1.8), after the blend: the radiance
// every gather point of the near field sends from the lights' indirect light, albedo/π × the
// blended lightmap at its texel (read from `source`, a copy of it) less the emitters' and the
// sky's traced part, for the deeper VPLs' share (near_indirect.wgsl). One invocation per gather
// point.

@group(0) @binding(0) var<uniform> near: NearField;
@group(0) @binding(1) var<storage, read> points: array<GatherPoint>;
@group(0) @binding(2) var source: texture_2d<f32>;
// The emitters' and sky's traced indirect lightmap (baked.rs); 1×1, ignored, without one.
@group(0) @binding(3) var emitted: texture_2d<f32>;
@group(0) @binding(4) var<storage, read_write> radiance: array<vec4<f32>>;

const INV_PI: f32 = 0.31830988;

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = linear_index(gid, groups);
    if i >= near.points {
        return;
    }
    let g = points[i];
    let side = textureDimensions(source).x;
    let xy = vec2<i32>(i32(g.texel % side), i32(g.texel / side));
    var e = textureLoad(source, xy, 0).rgb;
    if all(textureDimensions(emitted) == textureDimensions(source)) {
        e -= textureLoad(emitted, xy, 0).rgb;
    }
    radiance[i] = vec4<f32>(g.albedo * INV_PI * max(e, vec3<f32>(0.0)), 0.0);
}
