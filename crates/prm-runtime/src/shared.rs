//! The `#[repr(C)]` structs and codes shared with the run-time shaders, defined once here and
//! once in `shaders/runtime/shared.wgsl`, field for field; the tests below compare the two
//! layouts through naga and the enums with the shader's constants.

use bytemuck::{Pod, Zeroable};

/// The shared WGSL structs and codes (`shaders/runtime/shared.wgsl`).
pub const SHARED_WGSL: &str = include_str!("../../../shaders/runtime/shared.wgsl");
/// The direct irradiance of a point from every light, shadow-mapped
/// (`shaders/runtime/lights.wgsl`); needs [`SHARED_WGSL`] before it and declares nothing: the
/// including shader binds `frame`, `lights`, `views` and `shadow_maps`
/// (see [`Runtime::direct_light_bindings`](crate::Runtime::direct_light_bindings)).
pub const LIGHTS_WGSL: &str = include_str!("../../../shaders/runtime/lights.wgsl");
/// What [`LIGHTS_WGSL`] reads declared as group 0, bindings 0 to 3, in the order of
/// [`DirectLight::resources`](crate::DirectLight::resources)
/// (`shaders/runtime/light_bindings.wgsl`); needs [`SHARED_WGSL`] before it. The including shader
/// binds its own resources from binding 4.
pub const LIGHT_BINDINGS_WGSL: &str = include_str!("../../../shaders/runtime/light_bindings.wgsl");

/// The indirect irradiance at a point from the probes around it, `probe_irradiance(x, n)`
/// (`shaders/runtime/probe_volume.wgsl`); needs [`SHARED_WGSL`] before it, and the including
/// shader binds `probe_grid`, `probe_cells` and `probe_sh` ([`crate::ProbeVolume`]).
pub const PROBES_WGSL: &str = include_str!("../../../shaders/runtime/probe_volume.wgsl");

/// A light's kind, as `Light.kind` holds it.
#[repr(u32)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LightKind {
    /// `LIGHT_POINT`: W/sr in every direction, a cube of six shadow views.
    Point = 0,
    /// `LIGHT_SPOT`: W/sr inside a cone, one shadow view (a cube beyond 60°).
    Spot = 1,
    /// `LIGHT_DIRECTIONAL`: W/m² along one direction, one orthographic shadow view.
    Directional = 2,
    /// `LIGHT_RECT`: W/sr inside a rectangular frustum, one perspective shadow view of its
    /// aspect.
    Rect = 3,
}

/// A frame's constants; `Frame` in the shaders.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct GpuFrame {
    /// Lights this frame.
    pub light_count: u32,
    /// Clusters (= panes) in the archive.
    pub cluster_count: u32,
    /// Clusters kept.
    pub top_k: u32,
    /// Entry points in the archive.
    pub entry_count: u32,
    /// Fade band (see `select.wgsl`).
    pub fade_band: f32,
    /// Shadow-map side in texels.
    pub shadow_resolution: f32,
    /// Normal offset of shadow lookups, in shadow texels.
    pub normal_offset: f32,
    /// Depth bias of shadow lookups, in shadow texels.
    pub depth_bias: f32,
    /// Residual groups; their panes (the members' summed) are panes `cluster_count + g` (see
    /// `select.wgsl`).
    pub group_count: u32,
    /// Padding.
    pub _pad0: u32,
    /// Padding.
    pub _pad1: u32,
    /// Padding.
    pub _pad2: u32,
}

/// The probe grid; `ProbeGrid` in the shaders.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct GpuProbeGrid {
    /// The grid's lower corner.
    pub origin: [f32; 3],
    /// Cell edge.
    pub spacing: f32,
    /// Cells along x, y, z.
    pub dims: [u32; 3],
    /// Probes.
    pub count: u32,
}

/// Where probe rays end: a covered lightmap texel's exit point; `GatherPoint` in the shaders
/// ([`prm_format::GatherPoint`]).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct GpuGatherPoint {
    /// World position.
    pub position: [f32; 3],
    /// Texel index `y·R + x`.
    pub texel: u32,
    /// Unit normal.
    pub normal: [f32; 3],
    /// Padding.
    pub _pad0: u32,
    /// Albedo.
    pub albedo: [f32; 3],
    /// Emitter group whose scale multiplies `emission` ([`prm_format::NO_EMITTER`]: none).
    pub emitter: u32,
    /// Emitted radiance at scale 1.
    pub emission: [f32; 3],
    /// Padding.
    pub _pad1: u32,
}

/// The counts of the probe rays; `ProbeRays` in the shaders.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct GpuProbeRays {
    /// Probes.
    pub probes: u32,
    /// Rays per probe.
    pub rays_per_probe: u32,
    /// Gather points.
    pub points: u32,
    /// Padding.
    pub _pad0: u32,
}

/// A gather point of the near field ([`prm_format::GatherPoint`] without what only the probes
/// read); `NearPoint` in the shaders. 24 bytes instead of [`GpuGatherPoint`]'s 64: the normal
/// octahedral in two `snorm16` (WGSL's `unpack2x16snorm`), the albedo in RGB9E5 (9 bits under
/// the largest channel's exponent).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct GpuNearPoint {
    /// World position.
    pub position: [f32; 3],
    /// Texel index `y·R + x`, with [`GpuNearPoint::EXIT`] where the texel has an exit record.
    pub texel: u32,
    /// Unit normal, octahedral, two `snorm16` ([`GpuNearPoint::normal`]).
    pub normal: u32,
    /// Albedo, RGB9E5 (`prm_format::encode_rgb9e5`).
    pub albedo: u32,
}

impl GpuNearPoint {
    /// The texel's flag for a texel with an exit record, whose near sums change it (above every
    /// texel index of an atlas of at most 8192²); `NEAR_EXIT` in the shaders.
    pub const EXIT: u32 = 1 << 31;

    /// Gather point `g`, packed; `exit`: its texel has an exit record.
    pub fn new(g: &prm_format::GatherPoint, exit: bool) -> GpuNearPoint {
        GpuNearPoint {
            position: g.position,
            texel: g.texel | if exit { Self::EXIT } else { 0 },
            normal: octahedral(g.normal),
            albedo: prm_format::encode_rgb9e5(g.albedo),
        }
    }

    /// The unit normal as the shader unpacks it (`oct_normal` in shared.wgsl).
    pub fn normal(&self) -> [f32; 3] {
        let s = |b: u32| f32::from(b as u16 as i16).max(-32767.0) / 32767.0;
        let (x, y) = (s(self.normal), s(self.normal >> 16));
        let z = 1.0 - x.abs() - y.abs();
        let t = (-z).max(0.0);
        let (x, y) = (x + if x >= 0.0 { -t } else { t }, y + if y >= 0.0 { -t } else { t });
        let l = (x * x + y * y + z * z).sqrt();
        [x / l, y / l, z / l]
    }
}

/// `n` (unit length) on the octahedron unfolded to [−1, 1]², as two `snorm16` (x low).
fn octahedral(n: [f32; 3]) -> u32 {
    let l1 = n[0].abs() + n[1].abs() + n[2].abs();
    let (mut x, mut y) = if l1 > 0.0 { (n[0] / l1, n[1] / l1) } else { (0.0, 0.0) };
    if n[2] < 0.0 {
        let sign = |v: f32| if v >= 0.0 { 1.0 } else { -1.0 };
        (x, y) = ((1.0 - y.abs()) * sign(x), (1.0 - x.abs()) * sign(y));
    }
    let snorm = |v: f32| u32::from((v.clamp(-1.0, 1.0) * 32767.0).round() as i16 as u16);
    snorm(x) | snorm(y) << 16
}

/// An exit point with near hits (`prm_format::NearExit`); `NearExit` in the shaders.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct GpuNearExit {
    /// Texel index `y·R + x`.
    pub texel: u32,
    /// One past its last hit.
    pub end: u32,
}

/// An exit point's near rays that end on one gather point (`prm_format::NearHit`s merged);
/// `NearHit` in the shaders. Four bytes, as walking the hits three times a frame reads more
/// than anything else: the gather point's index in the high bits and the weight summed over the
/// rays in the low [`GpuNearField::weight_bits`] (at most 15), the top bits of its IEEE half
/// float (which has no sign bit to keep, weights being positive). Up to 2¹⁷ gather points the
/// weight is the whole half float; each doubling beyond drops one bit of its 10-bit mantissa.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Pod, Zeroable)]
pub struct GpuNearHit {
    /// The gather point index `<< weight_bits`, or the weight's bits.
    pub packed: u32,
}

impl GpuNearHit {
    /// The low bits that hold the weight when the gather points number `points`: the bits the
    /// largest index leaves, at most the 15 of a positive half float.
    pub fn weight_bits(points: u32) -> u32 {
        let index_bits = (32 - points.saturating_sub(1).leading_zeros()).max(1);
        (32 - index_bits).min(15)
    }

    /// The hit on gather point `point` of weight `weight` (≥ 0), rounded to `weight_bits` bits.
    pub fn new(point: u32, weight: f32, weight_bits: u32) -> GpuNearHit {
        let dropped = 15 - weight_bits;
        let half = u32::from(half::f16::from_f32(weight.max(0.0)).to_bits()) & 0x7fff;
        let round = if dropped > 0 { 1 << (dropped - 1) } else { 0 };
        // Rounding may carry into the exponent, which is what the next larger value is; the
        // largest finite value, below the infinities' exponent, caps it.
        let bits = ((half + round) >> dropped).min(0x7bff >> dropped);
        GpuNearHit {
            packed: point << weight_bits | bits,
        }
    }

    /// The gather point index and the weight, as the shader unpacks them.
    pub fn unpack(&self, weight_bits: u32) -> (u32, f32) {
        let bits = (self.packed & ((1 << weight_bits) - 1)) << (15 - weight_bits);
        (self.packed >> weight_bits, half::f16::from_bits(bits as u16).to_f32())
    }
}

/// The near field's constants; `NearField` in the shaders.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct GpuNearField {
    /// Exit points with near hits.
    pub exits: u32,
    /// Gather points.
    pub points: u32,
    /// `π / M`, `M` the rays per exit point.
    pub scale: f32,
    /// 1 when the deeper share's sum adds the rest of its series (the last gather with
    /// [`crate::NearTail::Extrapolated`]), else 0.
    pub tail: u32,
    /// The bits of a [`GpuNearHit`] that hold its weight ([`GpuNearHit::weight_bits`]).
    pub weight_bits: u32,
    /// Padding.
    pub _pad0: u32,
    /// Padding.
    pub _pad1: u32,
    /// Padding.
    pub _pad2: u32,
}

/// A light; `Light` in the shaders.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct GpuLight {
    /// [`LightKind`] as `u32`.
    pub kind: u32,
    /// First shadow view (texture layer).
    pub first_view: u32,
    /// Shadow views: 1, 6 for a cube, or a directional light's tiles (a square number).
    pub view_count: u32,
    /// Cosine of a spot light's half angle (−2 for the others).
    pub cos_cutoff: f32,
    /// Position (point, spot, rect), or the centre of a directional light's shadow map.
    pub position: [f32; 3],
    /// Tangent of a rectangular spot's horizontal half angle (about `direction × up`), or half
    /// the side of a directional light's shadow map (world units).
    pub tan_x: f32,
    /// Spot or rect axis, or directional travel direction (unit).
    pub direction: [f32; 3],
    /// Tangent of a rectangular spot's vertical half angle (about `up`).
    pub tan_y: f32,
    /// Intensity (W/sr) or irradiance (W/m²), RGB.
    pub color: [f32; 3],
    /// Padding.
    pub _pad0: f32,
    /// A rectangular spot's vertical, or a directional light's shadow-map vertical (unit,
    /// perpendicular to `direction`).
    pub up: [f32; 3],
    /// Padding.
    pub _pad1: f32,
}

/// A shadow view; `ShadowView` in the shaders.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct GpuView {
    /// View-projection (column major), depth in [0, 1].
    pub view_proj: [[f32; 4]; 4],
    /// World units per texel: at unit distance (perspective) or absolute (orthographic).
    pub texel: f32,
    /// Near plane.
    pub near: f32,
    /// Far plane.
    pub far: f32,
    /// 1 for an orthographic view, 0 for a perspective one.
    pub orthographic: u32,
}

/// A cluster; `Cluster` in the shaders.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct GpuCluster {
    /// First entry.
    pub first: u32,
    /// Entry count.
    pub count: u32,
    /// Residual group ([`prm_format::residual_groups`]; 0 without groups).
    pub group: u32,
    /// Padding.
    pub _pad1: u32,
    /// Pane energy (RGB).
    pub energy: [f32; 3],
    /// Padding.
    pub _pad2: f32,
}

/// An entry point; `Entry` in the shaders.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct GpuEntry {
    /// Position.
    pub position: [f32; 3],
    /// Without entry cells, r² of the disk the entry stands for: the bound of its irradiance.
    /// With them, the squared distance within which a point or spot light is summed over the
    /// cell's points (`prm_scene::cell_reach2`).
    pub disk: f32,
    /// Unit normal.
    pub normal: [f32; 3],
    /// Its cell's first point in the cell points buffer.
    pub cell_first: u32,
    /// Pane energy the cluster weight weighs this member by (1 for archives without an entry
    /// energy section, which makes the weight the plain mean).
    pub energy: [f32; 3],
    /// Its cell's points.
    pub cell_count: u32,
    /// Irradiance from the emitters at their current scales (RGB, W/m²), added to the lights'.
    pub emitted: [f32; 3],
    /// What each cell point's irradiance counts for, `N/M` (prm-format's
    /// `EntryCells::point_weight`); 0: the archive has no cells, and the entry's own irradiance
    /// bounded by `disk` stands for it.
    pub cell_weight: f32,
}

/// A cluster's weight and score; `Weight` in the shaders.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct GpuWeight {
    /// The members' entry irradiance weighed by their pane energy (RGB).
    pub weight: [f32; 3],
    /// Σ_rgb weight × pane energy.
    pub score: f32,
}

/// The weight a cluster is blended with and its rank; `Effective` in the shaders.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct GpuEffective {
    /// Blend weight (0 if dropped, faded near the threshold).
    pub weight: [f32; 3],
    /// Rank by score (0 = largest).
    pub rank: u32,
}

/// A kept cluster; `Selected` in the shaders.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct GpuSelected {
    /// Effective (faded) weight.
    pub weight: [f32; 3],
    /// Cluster (= pane; the residual group g is pane `cluster_count + g`).
    pub cluster: u32,
}

/// One atlas tile of the panes' basis (`blend.rs`); `PaneTile` in the shaders.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct GpuPaneTile {
    /// `vec2<u32>` per texel row of the basis: the rank rounded up to four, over four. (Each
    /// lit texel names its own row, `blend.wgsl`.)
    pub stride: u32,
    /// The tile's rank `r` (0: every pane is zero there).
    pub rank: u32,
    /// Where the tile's coefficients start in its chunk's coefficient buffer, in `vec2<u32>`:
    /// its block index, then its panes' blocks (`blend.rs`, `tile_blocks`).
    pub coefficients: u32,
    /// Padding.
    pub _pad0: u32,
}

/// One chunk of the panes' tiles, each chunk's basis and coefficients in buffers of their own
/// (`blend.rs`); `BlendChunk` in the shaders.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct GpuBlendChunk {
    /// The chunk's first tile.
    pub first_tile: u32,
    /// Tiles in the chunk.
    pub tiles: u32,
    /// The chunk's texels that anything lights: the blend's invocations.
    pub lit_texels: u32,
    /// Mixed coefficients per tile (the largest rank rounded up to four).
    pub mixed_stride: u32,
    /// Texels per side of a tile.
    pub tile_size: u32,
    /// Tiles per side of the atlas.
    pub tiles_per_side: u32,
    /// Padding.
    pub _pad0: u32,
    /// Padding.
    pub _pad1: u32,
}

#[cfg(test)]
mod tests {
    use super::*;
    use prm_gpu_kit::layout::check_consts;
    use prm_gpu_kit::wgsl_layout;

    #[test]
    fn rust_structs_match_the_shaders() {
        let s = SHARED_WGSL;
        wgsl_layout!(
            s,
            GpuFrame,
            "Frame",
            [
                light_count,
                cluster_count,
                top_k,
                entry_count,
                fade_band,
                shadow_resolution,
                normal_offset,
                depth_bias,
                group_count,
                _pad0,
                _pad1,
                _pad2
            ]
        )
        .unwrap();
        wgsl_layout!(
            s,
            GpuLight,
            "Light",
            [kind, first_view, view_count, cos_cutoff, position, tan_x, direction, tan_y, color, _pad0, up, _pad1]
        )
        .unwrap();
        wgsl_layout!(s, GpuView, "ShadowView", [view_proj, texel, near, far, orthographic]).unwrap();
        wgsl_layout!(s, GpuCluster, "Cluster", [first, count, group, _pad1, energy, _pad2]).unwrap();
        wgsl_layout!(
            s,
            GpuEntry,
            "Entry",
            [
                position,
                disk,
                normal,
                cell_first,
                energy,
                cell_count,
                emitted,
                cell_weight
            ]
        )
        .unwrap();
        wgsl_layout!(s, GpuWeight, "Weight", [weight, score]).unwrap();
        wgsl_layout!(s, GpuEffective, "Effective", [weight, rank]).unwrap();
        wgsl_layout!(s, GpuSelected, "Selected", [weight, cluster]).unwrap();
        wgsl_layout!(s, GpuPaneTile, "PaneTile", [stride, rank, coefficients, _pad0]).unwrap();
        wgsl_layout!(
            s,
            GpuBlendChunk,
            "BlendChunk",
            [
                first_tile,
                tiles,
                lit_texels,
                mixed_stride,
                tile_size,
                tiles_per_side,
                _pad0,
                _pad1
            ]
        )
        .unwrap();
        wgsl_layout!(s, GpuProbeGrid, "ProbeGrid", [origin, spacing, dims, count]).unwrap();
        wgsl_layout!(
            s,
            GpuGatherPoint,
            "GatherPoint",
            [position, texel, normal, _pad0, albedo, emitter, emission, _pad1]
        )
        .unwrap();
        wgsl_layout!(s, GpuProbeRays, "ProbeRays", [probes, rays_per_probe, points, _pad0]).unwrap();
        wgsl_layout!(s, GpuNearExit, "NearExit", [texel, end]).unwrap();
        wgsl_layout!(s, GpuNearPoint, "NearPoint", [position, texel, normal, albedo]).unwrap();
        wgsl_layout!(s, GpuNearHit, "NearHit", [packed]).unwrap();
        wgsl_layout!(
            s,
            GpuNearField,
            "NearField",
            [exits, points, scale, tail, weight_bits, _pad0, _pad1, _pad2]
        )
        .unwrap();
    }

    #[test]
    fn near_points_keep_their_normal_and_albedo() {
        let mut rng = 0x2545_f491_4f6c_dd1du64;
        let mut next = || {
            rng ^= rng << 13;
            rng ^= rng >> 7;
            rng ^= rng << 17;
            (rng >> 40) as f32 / (1u64 << 24) as f32 * 2.0 - 1.0
        };
        let axes = [[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, 1.0], [0.0, 0.0, -1.0]];
        let random = (0..1000).map(|_| {
            let v = [next(), next(), next()];
            let l = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt().max(1e-3);
            [v[0] / l, v[1] / l, v[2] / l]
        });
        for n in axes.into_iter().chain(random) {
            let g = prm_format::GatherPoint {
                texel: 7,
                position: [1.0, -2.0, 3.5],
                normal: n,
                albedo: [0.8, 0.05, 0.4],
                emission: [0.0; 3],
                emitter: prm_format::NO_EMITTER,
            };
            let p = GpuNearPoint::new(&g, true);
            assert_eq!(p.texel, 7 | GpuNearPoint::EXIT);
            let m = p.normal();
            let dot = n[0] * m[0] + n[1] * m[1] + n[2] * m[2];
            assert!(dot > 0.999_99, "{n:?} became {m:?}");
            let a = prm_format::decode_rgb9e5(p.albedo);
            for (x, y) in a.iter().zip(g.albedo) {
                assert!((x - y).abs() <= 0.8 / 511.0, "{a:?}");
            }
        }
    }

    #[test]
    fn light_kinds_match_the_shader_codes() {
        check_consts(
            SHARED_WGSL,
            &[
                ("LIGHT_POINT", LightKind::Point as i64),
                ("LIGHT_SPOT", LightKind::Spot as i64),
                ("LIGHT_DIRECTIONAL", LightKind::Directional as i64),
                ("LIGHT_RECT", LightKind::Rect as i64),
            ],
        )
        .unwrap();
    }
}
