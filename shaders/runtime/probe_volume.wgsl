// prm-runtime probe volume: the indirect irradiance at a point of the scene's empty space from
// the probes around it, for shaders that light moving objects (`prm_runtime::PROBES_WGSL`).
// Needs SHARED_WGSL before it; the including shader binds `probe_grid` (uniform ProbeGrid),
// `probe_cells` (storage array<i32>, each cell's probe or -1) and `probe_sh` (storage
// array<vec4<f32>>, 9 coefficients per probe, the probes pass's output).

// The nine real spherical harmonics of order 2 at unit direction d (prm_format::sh_basis).
fn sh_basis(d: vec3<f32>) -> array<f32, 9> {
    let c0 = 0.2820948;
    let c1 = 0.4886025;
    let c2 = 1.0925484;
    let c20 = 0.31539157;
    return array<f32, 9>(
        c0,
        c1 * d.x,
        c1 * d.y,
        c1 * d.z,
        c2 * d.x * d.z,
        c2 * d.x * d.y,
        c20 * (3.0 * d.y * d.y - 1.0),
        c2 * d.y * d.z,
        0.5 * c2 * (d.z * d.z - d.x * d.x),
    );
}

// Probe `p`'s irradiance on a surface of unit normal n (never negative).
fn probe_irradiance_at(p: u32, n: vec3<f32>) -> vec3<f32> {
    let y = sh_basis(n);
    var e = vec3<f32>(0.0);
    for (var i = 0u; i < 9u; i++) {
        e += probe_sh[p * 9u + i].rgb * y[i];
    }
    return max(e, vec3<f32>(0.0));
}

// Indirect irradiance (W/m²) at world position x on a surface of unit normal n: the trilinear
// blend of the eight probes around x, cells without a probe (inside geometry) left out and the
// rest renormalised; positions beyond the grid take its border probes; 0 with none around.
fn probe_irradiance(x: vec3<f32>, n: vec3<f32>) -> vec3<f32> {
    let dims = probe_grid.dims;
    let top = vec3<f32>(dims) - vec3<f32>(1.0);
    let q = clamp((x - probe_grid.origin) / probe_grid.spacing - vec3<f32>(0.5), vec3<f32>(0.0), top);
    let base = min(vec3<u32>(floor(q)), dims - vec3<u32>(1u));
    let f = q - vec3<f32>(base);
    var sum = vec3<f32>(0.0);
    var total = 0.0;
    for (var c = 0u; c < 8u; c++) {
        let o = vec3<u32>(c & 1u, (c >> 1u) & 1u, (c >> 2u) & 1u);
        let cell = min(base + o, dims - vec3<u32>(1u));
        let w3 = select(vec3<f32>(1.0) - f, f, o == vec3<u32>(1u));
        let w = w3.x * w3.y * w3.z;
        let probe = probe_cells[cell.x + dims.x * (cell.y + dims.y * cell.z)];
        if probe >= 0 && w > 0.0 {
            sum += w * probe_irradiance_at(u32(probe), n);
            total += w;
        }
    }
    return select(vec3<f32>(0.0), sum / total, total > 0.0);
}
