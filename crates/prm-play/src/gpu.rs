//! Device creation (Vulkan, with timestamp queries when the adapter has them) and the
//! `#[repr(C)]` structs shared with the `play_*.wgsl` shaders.

use bytemuck::{Pod, Zeroable};
use prm_gpu::{Backend, ContextOptions, GpuContext, GpuError};

/// Opens a headless Vulkan device (lavapipe on a machine without a GPU) with timestamp queries
/// when the adapter has them; fails with the driver to install when no Vulkan driver exists.
pub fn open_vulkan() -> Result<GpuContext, GpuError> {
    GpuContext::open(&ContextOptions {
        optional_features: wgpu::Features::TIMESTAMP_QUERY,
        ..ContextOptions::headless(Backend::Vulkan)
    })
}

/// A Vulkan-only wgpu instance (window mode creates its surface on it).
pub fn vulkan_instance() -> wgpu::Instance {
    prm_gpu::instance(wgpu::Backends::VULKAN)
}

/// Opens a Vulkan device on `instance` able to present to `surface`.
pub fn open_vulkan_for(instance: &wgpu::Instance, surface: &wgpu::Surface) -> Result<GpuContext, GpuError> {
    GpuContext::open(&ContextOptions {
        backend: Backend::Vulkan,
        optional_features: wgpu::Features::TIMESTAMP_QUERY,
        surface: Some((instance, surface)),
    })
}

/// Per-frame constants; `Frame` in the shaders.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct GpuFrame {
    /// Camera view-projection.
    pub view_proj: [[f32; 4]; 4],
    /// Camera position.
    pub eye: [f32; 4],
    /// Light count, mode, width, height.
    pub counts: [u32; 4],
    /// Cluster count, top K, entry count, unused.
    pub clusters: [u32; 4],
    /// Fade band, shadow-map resolution, normal offset and depth bias (in shadow texels).
    pub params: [f32; 4],
}
const _: () = assert!(std::mem::size_of::<GpuFrame>() == 128);

/// A light; `Light` in `play_lights.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct GpuLight {
    /// 0 point, 1 spot, 2 directional.
    pub kind: u32,
    /// First shadow view (texture layer).
    pub first_view: u32,
    /// 1 or 6 (cube).
    pub view_count: u32,
    /// Cosine of a spot light's half angle.
    pub cos_cutoff: f32,
    /// Position (point, spot).
    pub position: [f32; 4],
    /// Spot axis or directional travel direction.
    pub direction: [f32; 4],
    /// Intensity (W/sr) or irradiance (W/m²).
    pub color: [f32; 4],
}
const _: () = assert!(std::mem::size_of::<GpuLight>() == 64);

/// A shadow view; `ShadowView` in `play_lights.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct GpuView {
    /// View-projection.
    pub view_proj: [[f32; 4]; 4],
    /// Texel footprint, near, far, orthographic flag.
    pub params: [f32; 4],
}
const _: () = assert!(std::mem::size_of::<GpuView>() == 80);

/// A cluster; `Cluster` in `play_weights.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct GpuCluster {
    /// First entry.
    pub first: u32,
    /// Entry count.
    pub count: u32,
    /// Padding.
    pub pad: [u32; 2],
    /// Pane energy (RGB, w unused).
    pub energy: [f32; 4],
}
const _: () = assert!(std::mem::size_of::<GpuCluster>() == 32);

/// An entry point; `Entry` in `play_weights.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct GpuEntry {
    /// Position; w: area it stands for over π (r² of its disk), the bound of its irradiance.
    pub position: [f32; 4],
    /// Unit normal (w unused).
    pub normal: [f32; 4],
    /// Pane energy (RGB; w unused) the cluster weight weighs this member by: 1 for archives
    /// without an entry energy section, which makes the weight the plain mean.
    pub energy: [f32; 4],
}
const _: () = assert!(std::mem::size_of::<GpuEntry>() == 48);

/// A material; `Material` in `play_shade.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct GpuMaterial {
    /// Diffuse albedo.
    pub albedo: [f32; 3],
    /// Texture layer or -1.
    pub texture: i32,
}
const _: () = assert!(std::mem::size_of::<GpuMaterial>() == 16);

/// A kept cluster; `Selected` in `play_select.wgsl` and `play_blend.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct GpuSelected {
    /// Effective (faded) weight.
    pub weight: [f32; 3],
    /// Cluster (= pane layer).
    pub cluster: u32,
}
const _: () = assert!(std::mem::size_of::<GpuSelected>() == 16);

/// A vertex of the shade pass (flat triangles, no index buffer).
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct GpuVertex {
    /// Position.
    pub position: [f32; 3],
    /// Shading normal.
    pub normal: [f32; 3],
    /// Material texture coordinates.
    pub uv: [f32; 2],
    /// Lightmap coordinates (atlas).
    pub lightmap_uv: [f32; 2],
    /// Material index.
    pub material: u32,
}
const _: () = assert!(std::mem::size_of::<GpuVertex>() == 44);
