// The run time's indirect lightmap (irradiance E, rgba32float) as Bevy's `Lightmap` expects it:
// the outgoing radiance of a white Lambertian surface, E/π, in a filterable rgba16float texture.
// Bevy multiplies what it samples by the material's diffuse colour.

@group(0) @binding(0) var irradiance: texture_2d<f32>;
@group(0) @binding(1) var radiance: texture_storage_2d<rgba16float, write>;

const PI: f32 = 3.14159265358979;

@compute @workgroup_size(8, 8)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    let size = textureDimensions(irradiance);
    if id.x >= size.x || id.y >= size.y {
        return;
    }
    let e = textureLoad(irradiance, vec2<i32>(id.xy), 0).rgb;
    textureStore(radiance, vec2<i32>(id.xy), vec4<f32>(e / PI, 1.0));
}
