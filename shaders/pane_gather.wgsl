// pane_gather: adds every VPL of a batch to its cluster's pane at every exit point, with hemicube
// depth-map visibility. One thread per exit point; VPLs arrive sorted by cluster. Prepended with
// hemicube.wgsl and vpl.wgsl (the estimator and its bound). The structs are twins of
// crates/prm-gpu/src/pane_gather.rs (GpuExit, GatherParams), checked there through naga.

// How a depth map is read (prm-gpu's DepthFilter).
const DEPTH_NEAREST: u32 = 0u;
const DEPTH_PCF2X2: u32 = 1u;

struct Exit {
    position: vec3<f32>,
    _pad0: f32,
    normal: vec3<f32>,
    _pad1: f32,
}

struct Gather {
    exit_count: u32,
    vpl_count: u32,
    first_cluster: u32,
    // VPL_BOUND_NONE, VPL_BOUND_CLAMP (value = d_min²) or VPL_BOUND_DISK (value = scale²/π)
    bound_kind: u32,
    bound_value: f32,
    near: f32,
    far: f32,
    lift: f32,
    receiver_offset: f32,
    // Distance bias in scene units: constant + slope × (one depth texel's footprint) × tan θ.
    bias_constant: f32,
    bias_slope: f32,
    texel_angle: f32,
    // DEPTH_NEAREST: the depth texel under the receiver; DEPTH_PCF2X2: 2×2 percentage-closer
    // filtering
    depth_filter: u32,
    // Face tiling of the depth layers (see vpl_depth.rs).
    face_resolution: u32,
    faces_per_row: u32,
    _pad: u32,
}

@group(0) @binding(0) var<storage, read> vpls: array<Vpl>;
@group(0) @binding(1) var<storage, read> exits: array<Exit>;
@group(0) @binding(2) var<storage, read_write> panes: array<vec4<f32>>;
@group(0) @binding(3) var<uniform> g: Gather;
@group(0) @binding(4) var depth: texture_depth_2d_array;
@group(0) @binding(5) var shadow: sampler_comparison;

fn visibility(j: u32, v: Vpl, x: Exit, cos_x: f32) -> f32 {
    let origin = v.position + v.normal * g.lift;
    let p = x.position + x.normal * g.receiver_offset;
    let l = vpl_local(v, p - origin);
    let lz = vec3<f32>(l.xy, max(l.z, 0.0));
    let f = hemicube_face(lz);
    let c = hemicube_clip(lz, f, g.near, g.far);
    if (c.w <= g.near) {
        // Closer to the VPL than the depth maps resolve: nothing can lie between.
        return 1.0;
    }
    let ndc = c.xy / c.w;
    let uv = vec2<f32>(ndc.x * 0.5 + 0.5, 0.5 - ndc.y * 0.5);
    // Bias in scene units along the face axis: constant + slope × texel footprint × tan θ.
    let tan_x = min(sqrt(max(1.0 - cos_x * cos_x, 0.0)) / max(cos_x, 1e-3), 8.0);
    let w = c.w - (g.bias_constant + g.bias_slope * c.w * g.texel_angle * tan_x);
    if (w <= g.near) {
        return 1.0;
    }
    // Stored depth is (w - near)·far / ((far - near)·w); compare in that space.
    let reference = (w - g.near) * g.far / ((g.far - g.near) * w);
    // Face i = 5j + f (HEMICUBE_FACES = 5) sits in layer i / per_layer, tile i % per_layer (row-major).
    let i = j * HEMICUBE_FACES + f;
    let per_layer = g.faces_per_row * g.faces_per_row;
    let slot = i % per_layer;
    let tile = vec2<f32>(f32(slot % g.faces_per_row), f32(slot / g.faces_per_row));
    let layer = i32(i / per_layer);
    let res = f32(g.face_resolution);
    if (g.depth_filter == DEPTH_PCF2X2) {
        // Keep the 2×2 footprint inside the face's tile.
        let inside = clamp(uv, vec2<f32>(0.5 / res), vec2<f32>(1.0 - 0.5 / res));
        let at = (tile + inside) / f32(g.faces_per_row);
        return textureSampleCompareLevel(depth, shadow, at, layer, reference);
    }
    let texel = vec2<i32>(tile) * i32(g.face_resolution)
        + clamp(vec2<i32>(uv * res), vec2<i32>(0), vec2<i32>(i32(g.face_resolution) - 1));
    return select(0.0, 1.0, reference <= textureLoad(depth, texel, layer, 0));
}

fn flush(cluster: u32, i: u32, acc: vec3<f32>) {
    let k = (cluster - g.first_cluster) * g.exit_count + i;
    panes[k] = panes[k] + vec4<f32>(acc, 0.0);
}

const TILE: u32 = 64u;
// The batch's VPLs pass through workgroup memory a tile at a time: every invocation reads every
// VPL, and on lavapipe a storage-buffer read at a varying index costs a per-lane loop, while a
// workgroup-memory read is a plain load.
var<workgroup> tile: array<Vpl, TILE>;

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) id: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let i = id.x;
    // No early return: every invocation must reach the barriers.
    let live = i < g.exit_count;
    let x = exits[min(i, max(g.exit_count, 1u) - 1u)];
    var current = g.first_cluster;
    var acc = vec3<f32>(0.0);
    for (var base = 0u; base < g.vpl_count; base = base + TILE) {
        if (base + lid < g.vpl_count) {
            tile[lid] = vpls[base + lid];
        }
        workgroupBarrier();
        let n = min(TILE, g.vpl_count - base);
        for (var t = 0u; t < n; t = t + 1u) {
            let v = tile[t];
            if (v.cluster != current) {
                if (live && any(acc != vec3<f32>(0.0))) {
                    flush(current, i, acc);
                }
                acc = vec3<f32>(0.0);
                current = v.cluster;
            }
            // rgb: the unoccluded irradiance, a: cos θ_x (0 when either side faces away).
            let e = vpl_irradiance(v, x.position, x.normal, g.bound_kind, g.bound_value);
            if (e.a <= 0.0) {
                continue;
            }
            acc = acc + e.rgb * visibility(base + t, v, x, e.a);
        }
        workgroupBarrier();
    }
    if (live && any(acc != vec3<f32>(0.0))) {
        flush(current, i, acc);
    }
}
