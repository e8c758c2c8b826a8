// prm-runtime near field gather points' radiance, shared by near_radiance.wgsl and
// near_indirect_radiance.wgsl, which declare `near`, `points` and `radiance` and define
// `point_irradiance(g)`, the irradiance of gather point `g` the pass gathers: the entry point,
// one invocation per gather point, writing albedo/π × that irradiance (`w` unused).

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = linear_index(gid, groups);
    if i >= near.points {
        return;
    }
    let g = points[i];
    radiance[i] = vec4<f32>(near_albedo(g) * INV_PI * point_irradiance(g), 0.0);
}
