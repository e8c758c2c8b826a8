// prm-runtime near field sums, shared by near_field.wgsl and near_indirect.wgsl, which come
// after it, bind their own resources from binding 4 and define `sum_exit(i)`, what the sum does
// for exit record `i`: the entry point, one invocation per exit record with near hits, and
// `near_sum`, exit record `i`'s π/M × Σ over its merged hits of their weight (the direct share's
// R²/(r² + R²) summed, or the deeper VPLs' R₁²/(r² + R₁²) in the deeper share's hits) × the
// radiance of the gather point, and the record's texel.

@group(0) @binding(0) var<uniform> near: NearField;
@group(0) @binding(1) var<storage, read> exits: array<NearExit>;
@group(0) @binding(2) var<storage, read> hits: array<NearHit>;
// The gather points' radiance (near_radiance.wgsl or near_indirect_radiance.wgsl).
@group(0) @binding(3) var<storage, read> radiance: array<vec4<f32>>;

struct NearSum {
    irradiance: vec3<f32>,
    xy: vec2<i32>,
};

fn near_sum(i: u32, side: u32) -> NearSum {
    let x = exits[i];
    var start = 0u;
    if i > 0u {
        start = exits[i - 1u].end;
    }
    let mask = (1u << near.weight_bits) - 1u;
    let dropped = 15u - near.weight_bits;
    var e = vec3<f32>(0.0);
    for (var h = start; h < x.end; h++) {
        let hit = hits[h].packed;
        let w = unpack2x16float((hit & mask) << dropped).x;
        e += w * radiance[hit >> near.weight_bits].rgb;
    }
    return NearSum(e * near.scale, texel_xy(x.texel, side));
}

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = linear_index(gid, groups);
    if i >= near.exits {
        return;
    }
    sum_exit(i);
}
