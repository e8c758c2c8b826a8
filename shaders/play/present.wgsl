// prm-play present pass (window mode): the linear HDR frame × exposure, clamped, sRGB-encoded
// when the swapchain format does not do it, drawn with one full-screen triangle.

struct Present {
    exposure: f32,
    encode_srgb: u32,
    _pad0: u32,
    _pad1: u32,
};

@group(0) @binding(0) var image: texture_2d<f32>;
@group(0) @binding(1) var<uniform> present: Present;

@vertex
fn vs_main(@builtin(vertex_index) i: u32) -> @builtin(position) vec4<f32> {
    let uv = vec2<f32>(f32((i << 1u) & 2u), f32(i & 2u));
    return vec4<f32>(uv * 2.0 - 1.0, 0.0, 1.0);
}

@fragment
fn fs_main(@builtin(position) p: vec4<f32>) -> @location(0) vec4<f32> {
    let size = vec2<i32>(textureDimensions(image)) - 1;
    let c = clamp(textureLoad(image, min(vec2<i32>(p.xy), size), 0).rgb * present.exposure, vec3<f32>(0.0), vec3<f32>(1.0));
    if present.encode_srgb == 1u {
        let lo = c * 12.92;
        let hi = 1.055 * pow(c, vec3<f32>(1.0 / 2.4)) - 0.055;
        return vec4<f32>(select(hi, lo, c <= vec3<f32>(0.0031308)), 1.0);
    }
    return vec4<f32>(c, 1.0);
}
