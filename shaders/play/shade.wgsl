// prm-play shade pass: radiance of every pixel, albedo/π × (direct irradiance with shadows +
// the baked direct irradiance of the emitters and the sky, and the indirect irradiance, bilinearly sampled from their
// lightmaps) + the surface's own emission, linear HDR. Comes after the run
// time's shared.wgsl, light_bindings.wgsl (bindings 0 to 3: `frame`, `lights`, `views`,
// `shadow_maps`) and lights.wgsl, and play/camera.wgsl.

struct Material {
    albedo: vec3<f32>,
    // texture layer, or -1
    texture: i32,
    // emitted radiance (the emitter group's baked radiance × its scale), 0 if not emissive
    emission: vec3<f32>,
    // the texture's size in its layer (from the top-left corner)
    texture_width: u32,
    texture_height: u32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
};

@group(0) @binding(4) var<storage, read> materials: array<Material>;
@group(0) @binding(5) var lightmap: texture_2d<f32>;
@group(0) @binding(6) var textures: texture_2d_array<f32>;
@group(0) @binding(7) var<uniform> camera: Camera;
// The emitters' and the sky's direct irradiance (prm_runtime::Runtime::emitter_lightmap), any size.
@group(0) @binding(8) var emitter_lightmap: texture_2d<f32>;

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
    o.clip = camera.view_proj * vec4<f32>(v.position, 1.0);
    o.position = v.position;
    o.normal = v.normal;
    o.uv = v.uv;
    o.lightmap_uv = v.lightmap_uv;
    o.material = v.material;
    return o;
}

// Bilinear lightmap lookup (rgba32float is not filterable everywhere: filtered by hand).
fn bilinear(map: texture_2d<f32>, uv: vec2<f32>) -> vec3<f32> {
    let size = vec2<i32>(textureDimensions(map));
    let t = uv * vec2<f32>(size) - 0.5;
    let base = floor(t);
    let f = t - base;
    let b = vec2<i32>(base);
    let hi = size - 1;
    let a00 = textureLoad(map, clamp(b, vec2<i32>(0), hi), 0).rgb;
    let a10 = textureLoad(map, clamp(b + vec2<i32>(1, 0), vec2<i32>(0), hi), 0).rgb;
    let a01 = textureLoad(map, clamp(b + vec2<i32>(0, 1), vec2<i32>(0), hi), 0).rgb;
    let a11 = textureLoad(map, clamp(b + vec2<i32>(1, 1), vec2<i32>(0), hi), 0).rgb;
    return mix(mix(a00, a10, f.x), mix(a01, a11, f.x), f.y);
}

// The material's texture at `uv` as prm_scene::Texture::sample reads it: v = 0 at the bottom
// row, wrap-around bilinear at the texture's own size (the layer may be larger), sRGB decoded
// per texel by the format.
fn albedo_texture(m: Material, uv: vec2<f32>) -> vec3<f32> {
    let size = vec2<i32>(i32(m.texture_width), i32(m.texture_height));
    let t = fract(vec2<f32>(uv.x, 1.0 - uv.y)) * vec2<f32>(size) - 0.5;
    let base = floor(t);
    let f = t - base;
    let b = vec2<i32>(base);
    let x0 = (b.x % size.x + size.x) % size.x;
    let y0 = (b.y % size.y + size.y) % size.y;
    let x1 = (x0 + 1) % size.x;
    let y1 = (y0 + 1) % size.y;
    let a00 = textureLoad(textures, vec2<i32>(x0, y0), m.texture, 0).rgb;
    let a10 = textureLoad(textures, vec2<i32>(x1, y0), m.texture, 0).rgb;
    let a01 = textureLoad(textures, vec2<i32>(x0, y1), m.texture, 0).rgb;
    let a11 = textureLoad(textures, vec2<i32>(x1, y1), m.texture, 0).rgb;
    return mix(mix(a00, a10, f.x), mix(a01, a11, f.x), f.y);
}

@fragment
fn fs_main(v: VsOut) -> @location(0) vec4<f32> {
    let m = materials[v.material];
    var albedo = m.albedo;
    if m.texture >= 0 {
        albedo *= albedo_texture(m, v.uv);
    }
    // The geometric normal from screen-space derivatives (before any branch: derivatives need
    // uniform control flow), turned to the eye; the shading normal to the same side. Direct
    // light tests both (light_irradiance_ng), so a smooth-shaded surface gets no light from
    // below its own plane.
    let cross_dp = cross(dpdx(v.position), dpdy(v.position));
    var n = normalize(v.normal);
    var ng = n;
    if dot(cross_dp, cross_dp) > 1e-30 {
        ng = normalize(cross_dp);
    }
    if dot(ng, camera.eye - v.position) < 0.0 {
        ng = -ng;
    }
    if dot(n, ng) < 0.0 {
        n = -n;
    }
    var mode = camera.mode;
    if mode == MODE_SPLIT {
        mode = select(MODE_GI, MODE_DIRECT, v.clip.x < camera.width * 0.5);
    }
    var e = vec3<f32>(0.0);
    var emitted = vec3<f32>(0.0);
    if mode != MODE_INDIRECT {
        e += direct_irradiance_ng(v.position, ng, n, 0.0) + bilinear(emitter_lightmap, v.lightmap_uv);
        // Emitters are one-sided: they show their radiance from the side their normals face.
        let front = dot(v.normal, camera.eye - v.position) > 0.0;
        emitted = select(vec3<f32>(0.0), m.emission, front);
    }
    if mode != MODE_DIRECT {
        e += bilinear(lightmap, v.lightmap_uv);
    }
    return vec4<f32>(albedo / 3.14159265358979 * e + emitted, 1.0);
}
