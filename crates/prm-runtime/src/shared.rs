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
/// `NearHit` in the shaders. Eight bytes: the two weights as half floats (WGSL's
/// `unpack2x16float`), which walking the hits twice a frame reads more than anything else.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct GpuNearHit {
    /// Gather point index.
    pub point: u32,
    /// Low 16 bits: Σ `R²/(r² + R²)` over the rays, the direct share's weight; high 16 bits:
    /// Σ `R₁²/(r² + R₁²)`, the deeper VPLs' share's (0 without it); both IEEE half floats.
    pub weights: u32,
}

impl GpuNearHit {
    /// The hit on gather point `point` with the two weights rounded to half floats.
    pub fn new(point: u32, weight: f32, indirect_weight: f32) -> GpuNearHit {
        let bits = |w: f32| u32::from(half::f16::from_f32(w).to_bits());
        GpuNearHit {
            point,
            weights: bits(weight) | bits(indirect_weight) << 16,
        }
    }

    /// The two weights (direct share, deeper VPLs' share) as the shader unpacks them.
    pub fn weights(&self) -> (f32, f32) {
        let half = |bits: u32| half::f16::from_bits(bits as u16).to_f32();
        (half(self.weights & 0xffff), half(self.weights >> 16))
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
    /// r² of the disk the entry stands for: the bound of its irradiance.
    pub disk: f32,
    /// Unit normal.
    pub normal: [f32; 3],
    /// Padding.
    pub _pad0: f32,
    /// Pane energy the cluster weight weighs this member by (1 for archives without an entry
    /// energy section, which makes the weight the plain mean).
    pub energy: [f32; 3],
    /// Padding.
    pub _pad1: f32,
    /// Irradiance from the emitters at their current scales (RGB, W/m²), added to the lights'.
    pub emitted: [f32; 3],
    /// Padding.
    pub _pad2: f32,
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
    /// Where the tile's basis starts in its chunk's basis buffer, in `vec2<u32>` (four `f16`).
    pub basis: u32,
    /// `vec2<u32>` per texel row of the basis: the rank rounded up to four, over four.
    pub stride: u32,
    /// The tile's rank `r` (0: every pane is zero there).
    pub rank: u32,
    /// Where the tile's coefficients start in its chunk's coefficient buffer, in `f32`: pane
    /// `p`'s channel `ch` at `coefficients + (3p + ch)·r + k`.
    pub coefficients: u32,
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
            [position, disk, normal, _pad0, energy, _pad1, emitted, _pad2]
        )
        .unwrap();
        wgsl_layout!(s, GpuWeight, "Weight", [weight, score]).unwrap();
        wgsl_layout!(s, GpuEffective, "Effective", [weight, rank]).unwrap();
        wgsl_layout!(s, GpuSelected, "Selected", [weight, cluster]).unwrap();
        wgsl_layout!(s, GpuPaneTile, "PaneTile", [basis, stride, rank, coefficients]).unwrap();
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
        wgsl_layout!(s, GpuNearHit, "NearHit", [point, weights]).unwrap();
        wgsl_layout!(s, GpuNearField, "NearField", [exits, points, scale, tail]).unwrap();
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
