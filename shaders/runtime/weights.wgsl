// prm-runtime weights pass: irradiance of every entry point from the lights (shadow-mapped, over
// the points of its cell: N/M × their sum, prm-format's entry cells) and the emitters
// (precomputed), and
// each cluster's weight = its members' irradiance weighed by their pane energy,
// Σ E_i e_i / Σ e_i per channel (the mean when every e_i is 1, archives without entry energies), so the
// cluster gives the indirect energy its members would give unclustered; score = Σ_rgb weight ×
// pane energy.

@group(0) @binding(0) var<uniform> frame: Frame;
@group(0) @binding(1) var<storage, read> lights: array<Light>;
@group(0) @binding(2) var<storage, read> views: array<ShadowView>;
@group(0) @binding(3) var shadow_maps: texture_depth_2d_array;
@group(0) @binding(4) var<storage, read> clusters: array<Cluster>;
@group(0) @binding(5) var<storage, read> entries: array<Entry>;
// Every entry's cell points: the offset from the entry point as three f16 (x, y = the first
// word's halves, z = the second's low half), the unit normal octahedral in the second word's two
// high bytes.
@group(0) @binding(6) var<storage, read> cell_points: array<vec2<u32>>;
@group(0) @binding(7) var<storage, read_write> weights: array<Weight>;

// Lanes that share one member's cell points.
const CELL_LANES: u32 = 4u;

// Octahedral u8 pair (0 ↦ −1, 255 ↦ 1) to a unit vector.
fn octahedral_u8(q: u32) -> vec3<f32> {
    let e = vec2<f32>(f32(q & 255u), f32(q >> 8u)) / 255.0 * 2.0 - 1.0;
    var n = vec3<f32>(e, 1.0 - abs(e.x) - abs(e.y));
    if n.z < 0.0 {
        let s = select(vec2<f32>(-1.0), vec2<f32>(1.0), n.xy >= vec2<f32>(0.0));
        n = vec3<f32>((1.0 - abs(n.yx)) * s, n.z);
    }
    return normalize(n);
}

// Part `part` (of CELL_LANES) of entry e's irradiance from the lights. With cells, a point or
// spot light within √e.disk sums over the cell points part, part + CELL_LANES, …, times N/M;
// part 0 takes every other light at the entry point times its cell's area, cell_count · N/M
// (prm_trace::cell_irradiance). Without cells, part 0 takes the entry's own irradiance,
// bounded by its disk (light_irradiance_disk).
fn entry_irradiance(e: Entry, part: u32) -> vec3<f32> {
    if e.cell_weight == 0.0 {
        return select(vec3<f32>(0.0), direct_irradiance_disk(e.position, e.normal, e.disk), part == 0u);
    }
    var sum = vec3<f32>(0.0);
    // Bounded by the lights buffer's length too, as direct_irradiance_ng (lights.wgsl) says.
    let count = min(frame.light_count, arrayLength(&lights));
    for (var i = 0u; i < count; i++) {
        let l = lights[i];
        let d = l.position - e.position;
        if l.kind != LIGHT_DIRECTIONAL && dot(d, d) < e.disk {
            for (var k = part; k < e.cell_count; k += CELL_LANES) {
                let q = cell_points[e.cell_first + k];
                let offset = vec3<f32>(unpack2x16float(q.x), unpack2x16float(q.y & 0xFFFFu).x);
                let n = octahedral_u8(q.y >> 16u);
                sum += light_irradiance_ng(i, e.position + offset, n, n, 0.0) * e.cell_weight;
            }
        } else if part == 0u {
            sum += light_irradiance_ng(i, e.position, e.normal, e.normal, 0.0) * (f32(e.cell_count) * e.cell_weight);
        }
    }
    return sum;
}

// One workgroup per cluster (x + 65535·y), its invocations sharing the members: with one
// invocation per cluster, 64 clusters made a single workgroup, which lavapipe runs on one thread.
const WEIGHT_LANES: u32 = 32u;
var<workgroup> partial: array<vec3<f32>, WEIGHT_LANES>;
var<workgroup> partial_energy: array<vec3<f32>, WEIGHT_LANES>;

@compute @workgroup_size(32)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_index) lane: u32) {
    let c = wid.x + wid.y * 65535u;
    // Uniform per workgroup, so the barrier below stays in uniform control flow.
    if c >= frame.cluster_count {
        return;
    }
    let cl = clusters[c];
    var sum = vec3<f32>(0.0);
    var sum_energy = vec3<f32>(0.0);
    // Lane k takes part k % CELL_LANES of member k / CELL_LANES.
    for (var k = lane; k < cl.count * CELL_LANES; k += WEIGHT_LANES) {
        let e = entries[cl.first + k / CELL_LANES];
        let part = k % CELL_LANES;
        // Plus the emitters' (baked at unit scale, summed at their scales on the CPU), once.
        let emitted = select(vec3<f32>(0.0), e.emitted, part == 0u);
        sum += (entry_irradiance(e, part) + emitted) * e.energy;
        sum_energy += select(vec3<f32>(0.0), e.energy, part == 0u);
    }
    partial[lane] = sum;
    partial_energy[lane] = sum_energy;
    workgroupBarrier();
    if lane == 0u {
        var total = vec3<f32>(0.0);
        var total_energy = vec3<f32>(0.0);
        for (var i = 0u; i < WEIGHT_LANES; i++) {
            total += partial[i];
            total_energy += partial_energy[i];
        }
        // A channel whose members carry no energy contributes nothing whatever its weight.
        let w = select(vec3<f32>(0.0), total / total_energy, total_energy > vec3<f32>(0.0));
        weights[c] = Weight(w, dot(w, cl.energy));
    }
}
