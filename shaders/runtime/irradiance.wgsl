// prm-runtime irradiance pass: the full irradiance (direct through the shadow maps + indirect
// from the lightmap) at every lightmap texel a triangle or its edge covers, for static-lightmap
// export. Triangles (and, first, their edges as lines) are drawn in atlas space (lightmap UV →
// clip space); alpha 1 marks a drawn texel.
// Comes after shared.wgsl, light_bindings.wgsl (bindings 0 to 3) and lights.wgsl.

@group(0) @binding(4) var lightmap: texture_2d<f32>;

struct VsOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) position: vec3<f32>,
    @location(1) normal: vec3<f32>,
};

@vertex
fn vs_main(@location(0) position: vec3<f32>, @location(1) normal: vec3<f32>, @location(2) uv: vec2<f32>) -> VsOut {
    // Atlas UVs are [0, 1]² with v down; clip space has y up.
    return VsOut(vec4<f32>(uv.x * 2.0 - 1.0, 1.0 - uv.y * 2.0, 0.5, 1.0), position, normal);
}

@fragment
fn fs_main(v: VsOut) -> @location(0) vec4<f32> {
    let indirect = textureLoad(lightmap, vec2<i32>(v.clip.xy), 0).rgb;
    return vec4<f32>(direct_irradiance(v.position, normalize(v.normal)) + indirect, 1.0);
}
