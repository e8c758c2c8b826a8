// prm-runtime probe radiance pass: the radiance every gather point (a lightmap texel probe rays end at,
// formats/prm.md §5.5) sends this frame, albedo/π × its irradiance: the lights' direct light
// through the shadow maps, the indirect lightmap the blend just wrote and the emitters' and
// sky's baked direct lightmap; plus, on an emissive surface, its emission times its group's
// scale. One invocation per gather point; comes after shared.wgsl, light_bindings.wgsl (bindings
// 0 to 3) and lights.wgsl.

@group(0) @binding(4) var<storage, read> points: array<GatherPoint>;
@group(0) @binding(5) var lightmap: texture_2d<f32>;
// 1×1 and black without emitters or sky.
@group(0) @binding(6) var baked_direct: texture_2d<f32>;
@group(0) @binding(7) var<storage, read_write> radiance: array<vec4<f32>>;
// Every emitter group's scale (rgb), at least one entry.
@group(0) @binding(8) var<storage, read> scales: array<vec4<f32>>;

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = linear_index(gid, groups);
    if i >= arrayLength(&points) {
        return;
    }
    let g = points[i];
    let side = textureDimensions(lightmap).x;
    let texel = texel_xy(g.texel, side);
    var e = direct_irradiance(g.position, g.normal) + textureLoad(lightmap, texel, 0).rgb;
    if textureDimensions(baked_direct).x == side {
        e += textureLoad(baked_direct, texel, 0).rgb;
    }
    var l = g.albedo * INV_PI * e;
    if g.emitter != NO_EMITTER && g.emitter < arrayLength(&scales) {
        l += g.emission * scales[g.emitter].rgb;
    }
    radiance[i] = vec4<f32>(l, 0.0);
}
