//! Device creation (Vulkan, with timestamp queries when the adapter has them) and the
//! `#[repr(C)]` structs shared with the `play_*.wgsl` shaders.

use bytemuck::{Pod, Zeroable};
use prm_gpu::{Backend, GpuContext, GpuError};

/// Opens a Vulkan device (lavapipe on a machine without a GPU), requesting
/// `TIMESTAMP_QUERY` when the adapter supports it. A copy of `prm_gpu::GpuContext::new` that
/// adds the feature; fails loudly when no Vulkan driver exists.
pub fn open_vulkan() -> Result<GpuContext, GpuError> {
    Ok(open_vulkan_for(&vulkan_instance(), None)?.0)
}

/// A Vulkan-only wgpu instance.
pub fn vulkan_instance() -> wgpu::Instance {
    let mut desc = wgpu::InstanceDescriptor::new_without_display_handle();
    desc.backends = wgpu::Backends::VULKAN;
    wgpu::Instance::new(desc)
}

/// Opens a device on `instance` (a real GPU before a software one), able to present to
/// `surface` if given; returns the adapter too (for surface configuration).
pub fn open_vulkan_for(
    instance: &wgpu::Instance,
    surface: Option<&wgpu::Surface>,
) -> Result<(GpuContext, wgpu::Adapter), GpuError> {
    let mut adapters = pollster::block_on(instance.enumerate_adapters(wgpu::Backends::VULKAN));
    adapters.retain(|a| surface.is_none_or(|s| a.is_surface_supported(s)));
    adapters.sort_by_key(|a| a.get_info().device_type == wgpu::DeviceType::Cpu);
    let adapter = adapters.into_iter().next().ok_or(GpuError::NoAdapter {
        backend: Backend::Vulkan,
    })?;
    let info = adapter.get_info();
    let features = adapter.features() & wgpu::Features::TIMESTAMP_QUERY;
    let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
        label: Some("prm-play"),
        required_features: features,
        required_limits: adapter.limits(),
        ..Default::default()
    }))
    .map_err(|source| GpuError::Device {
        adapter: info.name.clone(),
        source,
    })?;
    Ok((GpuContext { device, queue, info }, adapter))
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
}
const _: () = assert!(std::mem::size_of::<GpuEntry>() == 32);

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
