// prm-runtime near radiance pass: the radiance every gather point of the near field
// (formats/prm.md §5.6) sends this frame from the lights' direct light, albedo/π × their
// irradiance through the shadow maps. (The emitters' and the sky's light reach the lightmap
// traced, not through the panes' VPLs, and lose nothing to their bound.) One invocation per
// gather point; comes after shared.wgsl and lights.wgsl.

@group(0) @binding(0) var<uniform> frame: Frame;
@group(0) @binding(1) var<storage, read> lights: array<Light>;
@group(0) @binding(2) var<storage, read> views: array<ShadowView>;
@group(0) @binding(3) var shadow_maps: texture_depth_2d_array;
@group(0) @binding(4) var<storage, read> points: array<GatherPoint>;
@group(0) @binding(5) var<storage, read_write> radiance: array<vec4<f32>>;
@group(0) @binding(6) var<uniform> near: NearField;

const INV_PI: f32 = 0.31830988;

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = linear_index(gid, groups);
    if i >= near.points {
        return;
    }
    let g = points[i];
    radiance[i] = vec4<f32>(g.albedo * INV_PI * direct_irradiance(g.position, g.normal), 0.0);
}
