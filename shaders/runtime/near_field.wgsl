// prm-runtime near field pass: every exit point's share of what the panes' VPL disk bound
// removes (formats/prm.md §5.6), π/M × Σ over its near hits of R²/(r² + R²) × the radiance the
// near radiance pass gave the gather point (near_sum.wgsl), written to its texel of the near
// lightmap the blend adds. Texels without near hits are never written and stay zero. One
// invocation per exit point with near hits.

@group(0) @binding(0) var<uniform> near: NearField;
@group(0) @binding(1) var<storage, read> exits: array<NearExit>;
@group(0) @binding(2) var<storage, read> hits: array<NearHit>;
@group(0) @binding(3) var<storage, read> radiance: array<vec4<f32>>;
@group(0) @binding(4) var near_map: texture_storage_2d<rgba32float, write>;

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = linear_index(gid, groups);
    if i >= near.exits {
        return;
    }
    let s = near_sum(i, false, textureDimensions(near_map).x);
    textureStore(near_map, s.xy, vec4<f32>(s.irradiance, 0.0));
}
