// prm-runtime near radiance pass: the radiance every gather point of the near field
// (formats/prm.md §5.6) sends this frame from the lights' direct light, albedo/π × their
// irradiance through the shadow maps. (The emitters' and the sky's light reach the lightmap
// traced, not through the panes' VPLs, and lose nothing to their bound.) One invocation per
// gather point (near_points.wgsl's entry point); comes after shared.wgsl, light_bindings.wgsl
// (bindings 0 to 3), lights.wgsl and near_points.wgsl.

@group(0) @binding(4) var<storage, read> points: array<NearPoint>;
@group(0) @binding(5) var<storage, read_write> radiance: array<vec4<f32>>;
@group(0) @binding(6) var<uniform> near: NearField;

// The lights' direct irradiance of gather point `g`.
fn point_irradiance(g: NearPoint) -> vec3<f32> {
    return direct_irradiance(near_position(g), near_normal(g));
}
