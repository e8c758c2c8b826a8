// prm-play shade pass: radiance of every pixel, albedo/π × (direct irradiance with shadows +
// indirect irradiance bilinearly sampled from the lightmap), linear HDR. Modes: 0 gi, 1 direct,
// 2 indirect, 3 split (left half direct, right half gi).

struct Material {
    albedo: vec3<f32>,
    // texture layer, or -1
    texture: i32,
};

@group(0) @binding(0) var<uniform> frame: Frame;
@group(0) @binding(1) var<storage, read> lights: array<Light>;
@group(0) @binding(2) var<storage, read> views: array<ShadowView>;
@group(0) @binding(3) var shadow_maps: texture_depth_2d_array;
@group(0) @binding(4) var<storage, read> materials: array<Material>;
@group(0) @binding(5) var lightmap: texture_2d<f32>;
@group(0) @binding(6) var textures: texture_2d_array<f32>;
@group(0) @binding(7) var texture_sampler: sampler;

struct VsIn {
    @location(0) position: vec3<f32>,
    @location(1) normal: vec3<f32>,
    @location(2) uv: vec2<f32>,
    @location(3) lightmap_uv: vec2<f32>,
    @location(4) material: u32,
};

struct VsOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) position: vec3<f32>,
    @location(1) normal: vec3<f32>,
    @location(2) uv: vec2<f32>,
    @location(3) lightmap_uv: vec2<f32>,
    @location(4) @interpolate(flat) material: u32,
};

@vertex
fn vs_main(v: VsIn) -> VsOut {
    var o: VsOut;
    o.clip = frame.view_proj * vec4<f32>(v.position, 1.0);
    o.position = v.position;
    o.normal = v.normal;
    o.uv = v.uv;
    o.lightmap_uv = v.lightmap_uv;
    o.material = v.material;
    return o;
}

// Bilinear lightmap lookup (rgba32float is not filterable everywhere: filtered by hand).
fn indirect(uv: vec2<f32>) -> vec3<f32> {
    let size = vec2<i32>(textureDimensions(lightmap));
    let t = uv * vec2<f32>(size) - 0.5;
    let base = floor(t);
    let f = t - base;
    let b = vec2<i32>(base);
    let hi = size - 1;
    let a00 = textureLoad(lightmap, clamp(b, vec2<i32>(0), hi), 0).rgb;
    let a10 = textureLoad(lightmap, clamp(b + vec2<i32>(1, 0), vec2<i32>(0), hi), 0).rgb;
    let a01 = textureLoad(lightmap, clamp(b + vec2<i32>(0, 1), vec2<i32>(0), hi), 0).rgb;
    let a11 = textureLoad(lightmap, clamp(b + vec2<i32>(1, 1), vec2<i32>(0), hi), 0).rgb;
    return mix(mix(a00, a10, f.x), mix(a01, a11, f.x), f.y);
}

@fragment
fn fs_main(v: VsOut) -> @location(0) vec4<f32> {
    let m = materials[v.material];
    var albedo = m.albedo;
    if m.texture >= 0 {
        albedo *= textureSampleLevel(textures, texture_sampler, v.uv, m.texture, 0.0).rgb;
    }
    var n = normalize(v.normal);
    if dot(n, frame.eye.xyz - v.position) < 0.0 {
        n = -n;
    }
    var mode = frame.counts.y;
    if mode == 3u {
        mode = select(0u, 1u, v.clip.x < f32(frame.counts.z) * 0.5);
    }
    var e = vec3<f32>(0.0);
    if mode != 2u {
        e += direct_irradiance(v.position, n);
    }
    if mode != 1u {
        e += indirect(v.lightmap_uv);
    }
    return vec4<f32>(albedo / 3.14159265358979 * e, 1.0);
}
