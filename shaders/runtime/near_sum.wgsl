// prm-runtime near field sums, shared by near_field.wgsl and near_indirect.wgsl, which declare
// `near`, `exits`, `hits` and `radiance`: exit record `i`'s π/M × Σ over its merged hits of their
// weight (the direct share's R²/(r² + R²) summed, or with `deeper` the deeper VPLs'
// R₁²/(r² + R₁²)) × the radiance of the gather point, and the record's texel.

struct NearSum {
    irradiance: vec3<f32>,
    xy: vec2<i32>,
};

fn near_sum(i: u32, deeper: bool, side: u32) -> NearSum {
    let x = exits[i];
    var start = 0u;
    if i > 0u {
        start = exits[i - 1u].end;
    }
    var e = vec3<f32>(0.0);
    for (var h = start; h < x.end; h++) {
        let hit = hits[h];
        let w = unpack2x16float(hit.weights);
        e += select(w.x, w.y, deeper) * radiance[hit.point].rgb;
    }
    return NearSum(e * near.scale, vec2<i32>(i32(x.texel % side), i32(x.texel / side)));
}
