// prm-runtime near indirect radiance pass, after the blend: the radiance
// every gather point of the near field sends from the lights' indirect light, albedo/π × the
// blended lightmap at its texel (read from `source`, a copy of it, or at texels with an exit
// record from `completed`, where the previous gather's sum completed it) less the emitters' and
// the sky's traced part, for the deeper VPLs' share (near_indirect.wgsl). One invocation per gather
// point (near_points.wgsl's entry point); comes after shared.wgsl and near_points.wgsl.

@group(0) @binding(0) var<uniform> near: NearField;
@group(0) @binding(1) var<storage, read> points: array<NearPoint>;
@group(0) @binding(2) var source: texture_2d<f32>;
// The emitters' and sky's traced indirect lightmap (baked.rs); 1×1, ignored, without one.
@group(0) @binding(3) var emitted: texture_2d<f32>;
@group(0) @binding(4) var<storage, read_write> radiance: array<vec4<f32>>;
// `source` for the first gather; the near lightmap for the others (near_field.rs).
@group(0) @binding(5) var completed: texture_2d<f32>;

// The blended lightmap at gather point `g`'s texel less the emitters' and the sky's part.
fn point_irradiance(g: NearPoint) -> vec3<f32> {
    let side = textureDimensions(source).x;
    let xy = texel_xy(g.texel & ~NEAR_EXIT, side);
    var e = textureLoad(source, xy, 0).rgb;
    if (g.texel & NEAR_EXIT) != 0u {
        e = textureLoad(completed, xy, 0).rgb;
    }
    if all(textureDimensions(emitted) == textureDimensions(source)) {
        e -= textureLoad(emitted, xy, 0).rgb;
    }
    return max(e, vec3<f32>(0.0));
}
