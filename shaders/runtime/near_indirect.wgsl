// prm-runtime near indirect pass, after the blend: the deeper VPLs' share
// of what the panes' bound removes (formats/prm.md §5.6), π/M × Σ over an exit point's near hits
// of R₁²/(r² + R₁²) × the radiance near_indirect_radiance.wgsl gave the gather point
// (near_sum.wgsl), added to the blend's value at the exit point's texel (read from `source`, a
// copy of the lightmap) and written to the lightmap; the other texels keep the blend's value.
// With `near.tail` (the last gather) it adds the rest of the share's series too: this sum less
// the previous gather's (`previous` less `source`; `previous` is `source` itself after the first
// gather), the series' last term, times the exit point's factor from near_field.rs's
// `series_tail`. One invocation per exit point with near hits (near_sum.wgsl's entry point,
// which calls `sum_exit`); comes after shared.wgsl and near_sum.wgsl, which declares bindings
// 0 to 3.

@group(0) @binding(4) var source: texture_2d<f32>;
@group(0) @binding(5) var lightmap: texture_storage_2d<rgba32float, write>;
@group(0) @binding(6) var previous: texture_2d<f32>;
// Every exit record's tail factor, RGB as half floats.
@group(0) @binding(7) var<storage, read> tail: array<vec2<u32>>;

// Exit record `i`'s sum, added to the blend's value into the lightmap.
fn sum_exit(i: u32) {
    let s = near_sum(i, textureDimensions(source).x);
    let base = textureLoad(source, s.xy, 0).rgb;
    var e = base + s.irradiance;
    if near.tail != 0u {
        let term = s.irradiance - (textureLoad(previous, s.xy, 0).rgb - base);
        let f = tail[i];
        e += vec3<f32>(unpack2x16float(f.x), unpack2x16float(f.y).x) * max(term, vec3<f32>(0.0));
    }
    textureStore(lightmap, s.xy, vec4<f32>(e, 1.0));
}
