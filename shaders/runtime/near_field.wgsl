// prm-runtime near field pass: every exit point's share of what the panes' VPL disk bound
// removes (formats/prm.md §5.6), π/M × Σ over its near hits of R²/(r² + R²) × the radiance the
// near radiance pass gave the gather point (near_sum.wgsl), written to its texel of the near
// lightmap the blend adds. Texels without near hits are never written and stay zero. One
// invocation per exit point with near hits (near_sum.wgsl's entry point, which calls
// `sum_exit`); comes after shared.wgsl and near_sum.wgsl, which declares bindings 0 to 3.

@group(0) @binding(4) var near_map: texture_storage_2d<rgba32float, write>;

// Exit record `i`'s sum, into its texel of the near lightmap.
fn sum_exit(i: u32) {
    let s = near_sum(i, textureDimensions(near_map).x);
    textureStore(near_map, s.xy, vec4<f32>(s.irradiance, 0.0));
}
