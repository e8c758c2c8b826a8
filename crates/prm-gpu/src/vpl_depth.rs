//! The VPL depth pass (`shaders/vpl_depth.wgsl`): the scene's depth through each hemicube face of
//! each VPL of a batch, faces tiled side by side in the layers of a depth texture array.
//!
//! Tiling matters on lavapipe: a render pass costs about 0.15 ms however little it draws, so one
//! pass per face made the depth maps cost as much as the shading; with a viewport per face, one
//! pass renders a whole layer of faces.

use bytemuck::{Pod, Zeroable};

/// A VPL as the GPU sees it; layout shared with `hemicube.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct GpuVpl {
    /// Position.
    pub position: [f32; 3],
    /// Area it stands for (for the disk bound).
    pub area: f32,
    /// Unit normal.
    pub normal: [f32; 3],
    /// Cluster index.
    pub cluster: u32,
    /// Power per unit entry irradiance.
    pub power: [f32; 3],
    /// Padding.
    pub _pad0: f32,
    /// Unit tangent of the hemicube frame.
    pub tangent: [f32; 3],
    /// Padding.
    pub _pad1: f32,
    /// Unit bitangent (normal × tangent).
    pub bitangent: [f32; 3],
    /// Padding.
    pub _pad2: f32,
}
const _: () = assert!(std::mem::size_of::<GpuVpl>() == 80);

impl GpuVpl {
    /// A VPL with its hemicube frame; `(tangent, bitangent, normal)` is right-handed.
    pub fn new(position: glam::Vec3, normal: glam::Vec3, power: glam::Vec3, area: f32, cluster: u32) -> GpuVpl {
        let (t, b) = normal.any_orthonormal_pair();
        GpuVpl {
            position: position.to_array(),
            area,
            normal: normal.to_array(),
            cluster,
            power: power.to_array(),
            _pad0: 0.0,
            tangent: t.to_array(),
            _pad1: 0.0,
            bitangent: b.to_array(),
            _pad2: 0.0,
        }
    }
}

/// Near/far planes and the lift of the VPL off its surface; layout shared with WGSL.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct DepthFrame {
    /// Near plane (distance along a face axis).
    pub near: f32,
    /// Far plane.
    pub far: f32,
    /// VPL origin offset along its normal.
    pub lift: f32,
    /// Padding.
    pub _pad: f32,
}
const _: () = assert!(std::mem::size_of::<DepthFrame>() == 16);

/// Faces per VPL (hemicube).
pub const FACES: u32 = 5;
/// Depth format of the face layers.
pub const DEPTH_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;

/// Pipeline and per-layer state of the depth pass for batches of up to `capacity` VPLs.
pub struct VplDepthPass {
    pipeline: wgpu::RenderPipeline,
    frame_group: wgpu::BindGroup,
    face_group: wgpu::BindGroup,
    face_stride: u32,
    layer_views: Vec<wgpu::TextureView>,
    /// All layers, for sampling.
    pub array_view: wgpu::TextureView,
    /// Face size in texels.
    pub resolution: u32,
    /// Faces on a row of a layer (a layer holds `faces_per_row²` faces).
    pub faces_per_row: u32,
}

impl VplDepthPass {
    /// Creates the pass: the depth array for `capacity` VPLs of `resolution²` faces, bound to
    /// `vpls` (the batch buffer) and `frame`.
    pub fn new(
        device: &wgpu::Device,
        capacity: u32,
        resolution: u32,
        vpls: &wgpu::Buffer,
        frame: &wgpu::Buffer,
    ) -> VplDepthPass {
        let source = format!(
            "{}\n{}",
            include_str!("../../../shaders/hemicube.wgsl"),
            include_str!("../../../shaders/vpl_depth.wgsl")
        );
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("vpl_depth"),
            source: wgpu::ShaderSource::Wgsl(source.into()),
        });
        let frame_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("vpl_depth frame"),
            entries: &[
                wgpu::BindGroupLayoutEntry {
                    binding: 0,
                    visibility: wgpu::ShaderStages::VERTEX,
                    ty: wgpu::BindingType::Buffer {
                        ty: wgpu::BufferBindingType::Storage { read_only: true },
                        has_dynamic_offset: false,
                        min_binding_size: None,
                    },
                    count: None,
                },
                wgpu::BindGroupLayoutEntry {
                    binding: 1,
                    visibility: wgpu::ShaderStages::VERTEX,
                    ty: wgpu::BindingType::Buffer {
                        ty: wgpu::BufferBindingType::Uniform,
                        has_dynamic_offset: false,
                        min_binding_size: None,
                    },
                    count: None,
                },
            ],
        });
        let face_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("vpl_depth face"),
            entries: &[wgpu::BindGroupLayoutEntry {
                binding: 0,
                visibility: wgpu::ShaderStages::VERTEX,
                ty: wgpu::BindingType::Buffer {
                    ty: wgpu::BufferBindingType::Uniform,
                    has_dynamic_offset: true,
                    min_binding_size: wgpu::BufferSize::new(16),
                },
                count: None,
            }],
        });
        let layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("vpl_depth"),
            bind_group_layouts: &[Some(&frame_layout), Some(&face_layout)],
            immediate_size: 0,
        });
        let pipeline = device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
            label: Some("vpl_depth"),
            layout: Some(&layout),
            vertex: wgpu::VertexState {
                module: &module,
                entry_point: Some("vs_main"),
                compilation_options: Default::default(),
                buffers: &[Some(wgpu::VertexBufferLayout {
                    array_stride: 12,
                    step_mode: wgpu::VertexStepMode::Vertex,
                    attributes: &wgpu::vertex_attr_array![0 => Float32x3],
                })],
            },
            primitive: wgpu::PrimitiveState {
                cull_mode: None,
                ..Default::default()
            },
            depth_stencil: Some(wgpu::DepthStencilState {
                format: DEPTH_FORMAT,
                depth_write_enabled: Some(true),
                depth_compare: Some(wgpu::CompareFunction::Less),
                stencil: Default::default(),
                // No raster bias: the gather pass biases distances in scene units.
                bias: Default::default(),
            }),
            multisample: Default::default(),
            fragment: None,
            multiview_mask: None,
            cache: None,
        });
        let frame_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("vpl_depth frame"),
            layout: &frame_layout,
            entries: &[
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: vpls.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 1,
                    resource: frame.as_entire_binding(),
                },
            ],
        });
        // Face selectors: layer j·5+f reads VPL j, face f; one aligned uniform slot per layer.
        let layers = capacity * FACES;
        let face_stride = device.limits().min_uniform_buffer_offset_alignment.max(16);
        let mut faces = vec![0u8; (layers * face_stride) as usize];
        for layer in 0..layers {
            let sel = [layer / FACES, layer % FACES, 0, 0];
            let at = (layer * face_stride) as usize;
            faces[at..at + 16].copy_from_slice(bytemuck::cast_slice(&sel));
        }
        let face_buffer = wgpu::util::DeviceExt::create_buffer_init(
            device,
            &wgpu::util::BufferInitDescriptor {
                label: Some("vpl_depth faces"),
                contents: &faces,
                usage: wgpu::BufferUsages::UNIFORM,
            },
        );
        let face_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("vpl_depth face"),
            layout: &face_layout,
            entries: &[wgpu::BindGroupEntry {
                binding: 0,
                resource: wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                    buffer: &face_buffer,
                    offset: 0,
                    size: wgpu::BufferSize::new(16),
                }),
            }],
        });
        let faces_per_row = (4096.min(device.limits().max_texture_dimension_2d) / resolution).max(1);
        let per_layer = faces_per_row * faces_per_row;
        let side = faces_per_row * resolution;
        let texture = device.create_texture(&wgpu::TextureDescriptor {
            label: Some("vpl_depth layers"),
            size: wgpu::Extent3d {
                width: side,
                height: side,
                depth_or_array_layers: layers.div_ceil(per_layer),
            },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: DEPTH_FORMAT,
            usage: wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::TEXTURE_BINDING,
            view_formats: &[],
        });
        let layer_views = (0..layers.div_ceil(per_layer))
            .map(|layer| {
                texture.create_view(&wgpu::TextureViewDescriptor {
                    label: Some("vpl_depth layer"),
                    dimension: Some(wgpu::TextureViewDimension::D2),
                    base_array_layer: layer,
                    array_layer_count: Some(1),
                    ..Default::default()
                })
            })
            .collect();
        let array_view = texture.create_view(&wgpu::TextureViewDescriptor {
            label: Some("vpl_depth array"),
            dimension: Some(wgpu::TextureViewDimension::D2Array),
            ..Default::default()
        });
        VplDepthPass {
            pipeline,
            frame_group,
            face_group,
            face_stride,
            layer_views,
            array_view,
            resolution,
            faces_per_row,
        }
    }

    /// Records the depth of `vertex_count` scene vertices for the first `vpls` VPLs of the batch:
    /// face `i` (VPL `i / 5`, face `i % 5`) goes to layer `i / per_layer`, tile `i % per_layer`
    /// (row-major, `faces_per_row` to a row).
    pub fn encode(&self, encoder: &mut wgpu::CommandEncoder, scene: &wgpu::Buffer, vertex_count: u32, vpls: u32) {
        let faces = vpls * FACES;
        let per_layer = self.faces_per_row * self.faces_per_row;
        let res = self.resolution;
        for (layer, view) in self
            .layer_views
            .iter()
            .enumerate()
            .take(faces.div_ceil(per_layer) as usize)
        {
            let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("vpl_depth"),
                color_attachments: &[],
                depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                    view,
                    depth_ops: Some(wgpu::Operations {
                        load: wgpu::LoadOp::Clear(1.0),
                        store: wgpu::StoreOp::Store,
                    }),
                    stencil_ops: None,
                }),
                timestamp_writes: None,
                occlusion_query_set: None,
                multiview_mask: None,
            });
            pass.set_pipeline(&self.pipeline);
            pass.set_bind_group(0, &self.frame_group, &[]);
            pass.set_vertex_buffer(0, scene.slice(..));
            let first = layer as u32 * per_layer;
            for face in first..(first + per_layer).min(faces) {
                let slot = face - first;
                let (x, y) = ((slot % self.faces_per_row) * res, (slot / self.faces_per_row) * res);
                pass.set_viewport(x as f32, y as f32, res as f32, res as f32, 0.0, 1.0);
                pass.set_scissor_rect(x, y, res, res);
                pass.set_bind_group(1, &self.face_group, &[face * self.face_stride]);
                pass.draw(0..vertex_count, 0..1);
            }
        }
    }
}
