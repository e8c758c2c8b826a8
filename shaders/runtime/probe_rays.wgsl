// prm-runtime probe rays pass: every probe's nine irradiance coefficients gathered along its
// rays (formats/prm.md §5.5) from the radiance the probe radiance pass gave the points they end at,
// plus the sky's direct part (summed on the CPU when the sky changes). One invocation per probe.
//
// basis: per direction d, the nine Y_i(ω_d) already times Â_i · 4π/M.

@group(0) @binding(0) var<uniform> info: ProbeRays;
@group(0) @binding(1) var<storage, read> basis: array<f32>;
@group(0) @binding(2) var<storage, read> hits: array<u32>;
@group(0) @binding(3) var<storage, read> radiance: array<vec4<f32>>;
@group(0) @binding(4) var<storage, read_write> probe_sh: array<vec4<f32>>;
@group(0) @binding(5) var<storage, read> sky_sh: array<vec4<f32>>;

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let p = gid.x;
    if p >= info.probes {
        return;
    }
    var c: array<vec3<f32>, 9>;
    let m = info.rays_per_probe;
    for (var d = 0u; d < m; d++) {
        let h = hits[p * m + d];
        // RAY_SKY and RAY_BLOCKED lie beyond every gather point.
        if h >= info.points {
            continue;
        }
        let l = radiance[h].rgb;
        for (var i = 0u; i < 9u; i++) {
            c[i] += basis[d * 9u + i] * l;
        }
    }
    for (var i = 0u; i < 9u; i++) {
        probe_sh[p * 9u + i] = vec4<f32>(c[i] + sky_sh[p * 9u + i].rgb, 0.0);
    }
}
