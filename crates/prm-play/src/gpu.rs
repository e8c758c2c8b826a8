//! Device creation (Vulkan, with timestamp queries when the adapter has them) and the
//! `#[repr(C)]` structs shared with `shaders/play/shade.wgsl` (checked against it below).

use bytemuck::{Pod, Zeroable};
use prm_gpu_kit::{Backend, ContextOptions, GpuContext, GpuError};

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
    prm_gpu_kit::instance(wgpu::Backends::VULKAN)
}

/// Opens a Vulkan device on `instance` able to present to `surface`.
pub fn open_vulkan_for(instance: &wgpu::Instance, surface: &wgpu::Surface) -> Result<GpuContext, GpuError> {
    GpuContext::open(&ContextOptions {
        backend: Backend::Vulkan,
        optional_features: wgpu::Features::TIMESTAMP_QUERY,
        surface: Some((instance, surface)),
    })
}

/// The shade pass's camera; `Camera` in `shade.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct GpuCamera {
    /// View-projection.
    pub view_proj: [[f32; 4]; 4],
    /// Eye position.
    pub eye: [f32; 3],
    /// [`Mode`](crate::Mode) code.
    pub mode: u32,
    /// Image width in pixels.
    pub width: f32,
    /// Padding.
    pub _pad0: f32,
    /// Padding.
    pub _pad1: f32,
    /// Padding.
    pub _pad2: f32,
}

/// A material; `Material` in `shade.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct GpuMaterial {
    /// Diffuse albedo.
    pub albedo: [f32; 3],
    /// Texture layer or -1.
    pub texture: i32,
    /// Emitted radiance: the emitter group's baked radiance × its scale (0 if not emissive).
    pub emission: [f32; 3],
    /// Width of the texture in its layer (texels from the layer's left edge).
    pub texture_width: u32,
    /// Height of the texture in its layer (rows from the layer's top edge).
    pub texture_height: u32,
    /// Padding.
    pub _pad0: u32,
    /// Padding.
    pub _pad1: u32,
    /// Padding.
    pub _pad2: u32,
}

/// The probe sphere; `Sphere` in `sphere.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct GpuSphere {
    /// Centre.
    pub centre: [f32; 3],
    /// Radius.
    pub radius: f32,
    /// Diffuse albedo.
    pub albedo: [f32; 3],
    /// Padding.
    pub _pad0: f32,
}

/// A vertex of the probe sphere: a point of the unit sphere.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct SphereVertex {
    /// Position on the unit sphere, also the normal.
    pub unit: [f32; 3],
}

impl prm_gpu_kit::pipeline::Vertex for SphereVertex {
    const ATTRIBUTES: &'static [wgpu::VertexAttribute] = &wgpu::vertex_attr_array![0 => Float32x3];
}

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

impl prm_gpu_kit::pipeline::Vertex for GpuVertex {
    const ATTRIBUTES: &'static [wgpu::VertexAttribute] =
        &wgpu::vertex_attr_array![0 => Float32x3, 1 => Float32x3, 2 => Float32x2, 3 => Float32x2, 4 => Uint32];
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Mode;
    use prm_gpu_kit::layout::check_consts;
    use prm_gpu_kit::wgsl_layout;

    #[test]
    fn shade_structs_and_modes_match_the_shader() {
        let src = crate::shade::source().join("\n");
        wgsl_layout!(
            &src,
            GpuCamera,
            "Camera",
            [view_proj, eye, mode, width, _pad0, _pad1, _pad2]
        )
        .unwrap();
        wgsl_layout!(
            &src,
            GpuMaterial,
            "Material",
            [
                albedo,
                texture,
                emission,
                texture_width,
                texture_height,
                _pad0,
                _pad1,
                _pad2
            ]
        )
        .unwrap();
        let sphere = crate::sphere::source().join("\n");
        wgsl_layout!(&sphere, GpuSphere, "Sphere", [centre, radius, albedo, _pad0]).unwrap();
        check_consts(
            &src,
            &[
                ("MODE_GI", Mode::Gi as i64),
                ("MODE_DIRECT", Mode::Direct as i64),
                ("MODE_INDIRECT", Mode::Indirect as i64),
                ("MODE_SPLIT", Mode::Split as i64),
            ],
        )
        .unwrap();
    }
}
