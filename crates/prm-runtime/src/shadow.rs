//! The shadow pass (`shaders/runtime/shadow.wgsl`): the scene's depth from every shadow view of
//! the frame's lights ([`shadow_views`](crate::shadow_views)), one layer of a depth array each,
//! one render pass per view with the view's matrix at a dynamic uniform offset.

use prm_gpu_kit::{pipeline, PassTimer};

/// Depth format of the shadow maps (`texture_depth_2d_array` in `lights.wgsl`).
pub const SHADOW_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;

/// The shadow-map array, its per-layer views and the matrices the pass reads.
pub(crate) struct ShadowMaps {
    pub capacity: u32,
    pub array: wgpu::TextureView,
    pub layers: Vec<wgpu::TextureView>,
    pub matrices: wgpu::Buffer,
    /// Bytes between two matrices (the device's uniform offset alignment, at least 64).
    pub stride: u32,
}

impl ShadowMaps {
    /// `capacity` layers of `resolution`² texels.
    pub fn new(device: &wgpu::Device, resolution: u32, capacity: u32) -> ShadowMaps {
        let (array, layers) = pipeline::layered_target(
            device,
            "prm shadow maps",
            [resolution, resolution, capacity],
            SHADOW_FORMAT,
        );
        let stride = device.limits().min_uniform_buffer_offset_alignment.max(64);
        ShadowMaps {
            capacity,
            array,
            layers,
            matrices: pipeline::uniform(device, "prm shadow matrices", (capacity * stride) as u64),
            stride,
        }
    }

    /// Uploads the views' matrices, one per stride.
    pub fn write_matrices(&self, queue: &wgpu::Queue, views: &[crate::GpuView]) {
        if views.is_empty() {
            return;
        }
        let stride = self.stride as usize;
        let mut bytes = vec![0u8; views.len() * stride];
        for (i, v) in views.iter().enumerate() {
            bytes[i * stride..i * stride + 64].copy_from_slice(bytemuck::cast_slice(&v.view_proj));
        }
        queue.write_buffer(&self.matrices, 0, &bytes);
    }
}

/// Renders the shadow maps.
pub(crate) struct ShadowPass {
    pipeline: wgpu::RenderPipeline,
    bind_group: wgpu::BindGroup,
}

impl ShadowPass {
    pub fn new(device: &wgpu::Device, maps: &ShadowMaps) -> ShadowPass {
        let layout = pipeline::dynamic_uniform_layout(device, "prm shadow", 64);
        let pipeline = pipeline::depth_only(
            device,
            "prm shadow",
            &[include_str!("../../../shaders/runtime/shadow.wgsl")],
            &[&layout],
            12,
            SHADOW_FORMAT,
        );
        let bind_group = Self::group(device, &pipeline, maps);
        ShadowPass { pipeline, bind_group }
    }

    fn group(device: &wgpu::Device, pipeline: &wgpu::RenderPipeline, maps: &ShadowMaps) -> wgpu::BindGroup {
        pipeline::bind_group(
            device,
            "prm shadow",
            &pipeline.get_bind_group_layout(0),
            &[wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                buffer: &maps.matrices,
                offset: 0,
                size: wgpu::BufferSize::new(64),
            })],
        )
    }

    /// Binds the pass to new (larger) shadow maps.
    pub fn rebind(&mut self, device: &wgpu::Device, maps: &ShadowMaps) {
        self.bind_group = Self::group(device, &self.pipeline, maps);
    }

    /// One depth pass per view: layers `0..views` of `maps`, drawing `vertex_count` positions.
    pub fn encode(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        maps: &ShadowMaps,
        views: u32,
        positions: &wgpu::Buffer,
        vertex_count: u32,
        timer: Option<&PassTimer>,
    ) {
        for (l, layer) in maps.layers.iter().take(views as usize).enumerate() {
            let mut pass = pipeline::begin_render_pass(
                encoder,
                "prm shadow",
                None,
                Some((layer, true)),
                timer.and_then(|t| t.render("shadow", l == 0, l + 1 == views as usize)),
            );
            pass.set_pipeline(&self.pipeline);
            pass.set_bind_group(0, &self.bind_group, &[l as u32 * maps.stride]);
            pass.set_vertex_buffer(0, positions.slice(..));
            pass.draw(0..vertex_count, 0..1);
        }
    }
}
