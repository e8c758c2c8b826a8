// prm-runtime: the structs and codes every run-time pass shares, defined once here and once in
// crates/prm-runtime/src/shared.rs (field for field; the crate's tests compare the two layouts
// through naga, and the codes below with the Rust enums).

const LIGHT_POINT: u32 = 0u;
const LIGHT_SPOT: u32 = 1u;
const LIGHT_DIRECTIONAL: u32 = 2u;
const LIGHT_RECT: u32 = 3u;

// A frame's constants.
struct Frame {
    light_count: u32,
    cluster_count: u32,
    top_k: u32,
    entry_count: u32,
    // Fade band: kept clusters within band × threshold above the threshold fade (select.wgsl).
    fade_band: f32,
    // Shadow-map side in texels.
    shadow_resolution: f32,
    // Shadow lookups move the point this many shadow texels along its normal.
    normal_offset: f32,
    // Depth tolerance of a shadow lookup, in shadow texels.
    depth_bias: f32,
    // Residual groups: group g's summed pane is pane cluster_count + g (select.wgsl).
    group_count: u32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
};

struct Light {
    // LIGHT_POINT, LIGHT_SPOT, LIGHT_DIRECTIONAL or LIGHT_RECT
    kind: u32,
    // first shadow view (texture layer) and how many (1, or 6 for a cube)
    first_view: u32,
    view_count: u32,
    // cosine of a spot light's half angle
    cos_cutoff: f32,
    position: vec3<f32>,
    // tangent of a rectangular spot's horizontal half angle (about direction × up)
    tan_x: f32,
    // spot or rect axis, or directional travel direction (unit)
    direction: vec3<f32>,
    // tangent of a rectangular spot's vertical half angle (about up)
    tan_y: f32,
    // W/sr (point, spot, rect) or W/m² (directional)
    color: vec3<f32>,
    _pad0: f32,
    // a rectangular spot's vertical (unit, perpendicular to direction)
    up: vec3<f32>,
    _pad1: f32,
};

struct ShadowView {
    view_proj: mat4x4<f32>,
    // world units per texel: at unit distance for perspective views, absolute for orthographic
    texel: f32,
    near: f32,
    far: f32,
    // 1 for an orthographic view (directional light), 0 for a perspective one
    orthographic: u32,
};

struct Cluster {
    first: u32,
    count: u32,
    // residual group (0 without groups)
    group: u32,
    _pad1: u32,
    // pane energy (RGB)
    energy: vec3<f32>,
    _pad2: f32,
};

struct Entry {
    position: vec3<f32>,
    // without entry cells, r² of the disk the entry stands for (area A/N over π, times
    // ENTRY_DISK): the bound of its irradiance, see light_irradiance_disk; with them, the squared
    // distance within which a point or spot light is summed over the cell's points (weights.wgsl)
    disk: f32,
    normal: vec3<f32>,
    // its cell's points in the cell points buffer (weights.wgsl)
    cell_first: u32,
    // pane energy e_i the cluster weight weighs this member by (1 without an entry-energy section)
    energy: vec3<f32>,
    cell_count: u32,
    // irradiance from the emitters at their current scales, added to the lights' (baked.rs)
    emitted: vec3<f32>,
    // what each cell point's irradiance counts for, N/M; 0: no cells, the disk bound instead
    cell_weight: f32,
};

// A cluster's weight (RGB) and score = Σ_rgb weight × pane energy.
struct Weight {
    weight: vec3<f32>,
    score: f32,
};

// The weight a cluster is blended with (0 if dropped, faded near the threshold) and its rank.
struct Effective {
    weight: vec3<f32>,
    rank: u32,
};

// A kept cluster, at slot = rank.
struct Selected {
    weight: vec3<f32>,
    cluster: u32,
};

// One atlas tile of the panes' basis (blend.rs): its basis rows' length (four f16 per
// vec2<u32>, zero beyond the rank; each lit texel names its row, blend.wgsl), its rank, and
// where its coefficients start in its chunk's coefficients: an index of its panes' blocks, then
// the blocks (blend.rs's tile_blocks, mix.wgsl).
struct PaneTile {
    stride: u32,
    rank: u32,
    coefficients: u32,
    _pad0: u32,
};

// One chunk of the panes' tiles (blend.rs): tiles first_tile .. first_tile + tiles, lit_texels
// of whose texels anything lights; mixed_stride mixed coefficients per tile.
struct BlendChunk {
    first_tile: u32,
    tiles: u32,
    lit_texels: u32,
    mixed_stride: u32,
    tile_size: u32,
    tiles_per_side: u32,
    _pad0: u32,
    _pad1: u32,
};

// The probe grid (`prm_format::ProbeGrid`): cell (i, j, k) is index i + nx·(j + ny·k), its centre
// origin + spacing·(i + ½, j + ½, k + ½); `count` probes.
struct ProbeGrid {
    origin: vec3<f32>,
    spacing: f32,
    dims: vec3<u32>,
    count: u32,
};

// Where probe rays end (`prm_format::GatherPoint`): a covered lightmap texel (index y·R + x) and
// its exit point's position, normal and albedo; on an emissive surface its emitter group (else
// NO_EMITTER) and emitted radiance at scale 1.
struct GatherPoint {
    position: vec3<f32>,
    texel: u32,
    normal: vec3<f32>,
    _pad0: u32,
    albedo: vec3<f32>,
    emitter: u32,
    emission: vec3<f32>,
    _pad1: u32,
};

const NO_EMITTER: u32 = 0xFFFFFFFFu;

// A gather point of the near field: GatherPoint without the emission, its texel flagged with
// NEAR_EXIT where the texel has an exit record, its normal octahedral in two snorm16 and its
// albedo in RGB9E5.
struct NearPoint {
    position: array<f32, 3>,
    texel: u32,
    normal: u32,
    albedo: u32,
};

const NEAR_EXIT: u32 = 0x80000000u;

fn near_position(g: NearPoint) -> vec3<f32> {
    return vec3<f32>(g.position[0], g.position[1], g.position[2]);
}

// The unit normal of an octahedral snorm16 pair.
fn near_normal(g: NearPoint) -> vec3<f32> {
    let e = unpack2x16snorm(g.normal);
    var n = vec3<f32>(e, 1.0 - abs(e.x) - abs(e.y));
    let t = max(-n.z, 0.0);
    n.x += select(t, -t, n.x >= 0.0);
    n.y += select(t, -t, n.y >= 0.0);
    return normalize(n);
}

// An RGB9E5 value (WebGPU's rgb9e5ufloat layout): mantissas × 2^(exponent − 24).
fn near_albedo(g: NearPoint) -> vec3<f32> {
    let v = g.albedo;
    let scale = exp2(f32(i32(v >> 27u) - 24));
    return vec3<f32>(f32(v & 511u), f32((v >> 9u) & 511u), f32((v >> 18u) & 511u)) * scale;
}

// The item of a one-dimensional dispatch of 64-wide workgroups laid out in rows
// (prm_gpu_kit::linear_workgroups): any count fits, past one dimension's 65 535 groups.
fn linear_index(gid: vec3<u32>, groups: vec3<u32>) -> u32 {
    return gid.x + gid.y * groups.x * 64u;
}

// The texel `y·side + x` of a `side`-wide map (a lightmap's texel index) as (x, y).
fn texel_xy(texel: u32, side: u32) -> vec2<i32> {
    return vec2<i32>(i32(texel % side), i32(texel / side));
}

// 1/π: a diffuse surface sends albedo/π × its irradiance.
const INV_PI: f32 = 0.31830988;

// The counts of the probe rays (formats/prm.md §5.5).
struct ProbeRays {
    probes: u32,
    rays_per_probe: u32,
    points: u32,
    _pad0: u32,
};

// An exit point with near hits (formats/prm.md §5.6): its texel and one past its last hit.
struct NearExit {
    texel: u32,
    end: u32,
};

// An exit point's near rays on one gather point: the point's index above the low
// `NearField.weight_bits` bits, which hold the top bits of their summed weight's half float.
struct NearHit {
    packed: u32,
};

// The near field's constants: counts, π/M, whether to add the series' tail and how a hit packs.
struct NearField {
    exits: u32,
    points: u32,
    scale: f32,
    tail: u32,
    weight_bits: u32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
};
