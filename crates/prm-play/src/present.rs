//! The present pass (`shaders/play/present.wgsl`): the renderer's linear frame, × exposure,
//! clamped and sRGB-encoded (by the shader unless the target format is sRGB), onto a window's
//! swapchain image or a screenshot texture.

use prm_gpu_kit::{pipeline, GpuContext};

use crate::Renderer;

/// Draws the renderer's image onto a target of one format.
pub struct Presenter {
    pipeline: wgpu::RenderPipeline,
    uniform: wgpu::Buffer,
    group: Option<wgpu::BindGroup>,
}

impl Presenter {
    /// Builds the pass for targets of `format`.
    pub fn new(ctx: &GpuContext, format: wgpu::TextureFormat, exposure: f32) -> Presenter {
        let module = pipeline::shader(
            &ctx.device,
            "play present",
            &[include_str!("../../../shaders/play/present.wgsl")],
        );
        let pipeline = pipeline::render(
            &ctx.device,
            &pipeline::RenderSpec {
                label: "play present",
                module: &module,
                layout: None,
                vertex_buffers: &[],
                depth: None,
                color: Some(format),
                topology: wgpu::PrimitiveTopology::TriangleList,
            },
        );
        let uniform = pipeline::uniform(&ctx.device, "play present", 16);
        let encode = u32::from(!format.is_srgb());
        ctx.queue
            .write_buffer(&uniform, 0, bytemuck::cast_slice(&[exposure.to_bits(), encode, 0, 0]));
        Presenter {
            pipeline,
            uniform,
            group: None,
        }
    }

    /// Binds the renderer's colour target (again after [`Renderer::resize`]).
    pub fn bind(&mut self, renderer: &Renderer) {
        self.group = Some(pipeline::bind_group(
            &renderer.context().device,
            "play present",
            &self.pipeline.get_bind_group_layout(0),
            &[
                wgpu::BindingResource::TextureView(renderer.color_view()),
                self.uniform.as_entire_binding(),
            ],
        ));
    }

    /// Records the pass drawing onto `target` (same size as the renderer's image).
    pub fn draw(&self, encoder: &mut wgpu::CommandEncoder, target: &wgpu::TextureView) {
        let mut pass = pipeline::begin_render_pass(encoder, "play present", Some(target), None, None);
        if let Some(group) = &self.group {
            pass.set_pipeline(&self.pipeline);
            pass.set_bind_group(0, group, &[]);
            pass.draw(0..3, 0..1);
        }
    }
}
