//! Pipelines, bind groups and buffers in one call each, the way every pass of PRM builds them:
//! WGSL modules assembled from a shared prelude and the pass's file, compute pipelines with
//! layouts derived from the shader, bind groups whose bindings are numbered in order; where a
//! pass needs an explicit layout (dynamic offsets), its entries ([`storage_entry`],
//! [`uniform_entry`]) and depth-only pipelines on it ([`depth_only`]).

use wgpu::util::DeviceExt;

/// A WGSL module from `parts` joined in order (shared struct and function files first, the
/// pass's own file last), labelled `label`.
pub fn shader(device: &wgpu::Device, label: &str, parts: &[&str]) -> wgpu::ShaderModule {
    device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some(label),
        source: wgpu::ShaderSource::Wgsl(parts.join("\n").into()),
    })
}

/// A compute pipeline from `parts` (see [`shader`]) with entry point `main` and the layout the
/// shader implies (read it back with `get_bind_group_layout`).
pub fn compute(device: &wgpu::Device, label: &str, parts: &[&str]) -> wgpu::ComputePipeline {
    let module = shader(device, label, parts);
    device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
        label: Some(label),
        layout: None,
        module: &module,
        entry_point: Some("main"),
        compilation_options: Default::default(),
        cache: None,
    })
}

/// A bind group on `layout` whose binding `i` is `resources[i]`.
pub fn bind_group(
    device: &wgpu::Device,
    label: &str,
    layout: &wgpu::BindGroupLayout,
    resources: &[wgpu::BindingResource],
) -> wgpu::BindGroup {
    let entries: Vec<wgpu::BindGroupEntry> = resources
        .iter()
        .enumerate()
        .map(|(i, r)| wgpu::BindGroupEntry {
            binding: i as u32,
            resource: r.clone(),
        })
        .collect();
    device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some(label),
        layout,
        entries: &entries,
    })
}

/// A bind group for group 0 of a compute pipeline (layout from the shader).
pub fn compute_group(
    device: &wgpu::Device,
    label: &str,
    pipeline: &wgpu::ComputePipeline,
    resources: &[wgpu::BindingResource],
) -> wgpu::BindGroup {
    bind_group(device, label, &pipeline.get_bind_group_layout(0), resources)
}

/// An uninitialised buffer of `size` bytes with `usage`.
pub fn buffer(device: &wgpu::Device, label: &str, size: u64, usage: wgpu::BufferUsages) -> wgpu::Buffer {
    device.create_buffer(&wgpu::BufferDescriptor {
        label: Some(label),
        size,
        usage,
        mapped_at_creation: false,
    })
}

/// An uninitialised storage buffer of `size` bytes (at least 16: wgpu refuses empty bindings)
/// that can also be written from the CPU, plus `extra` usages.
pub fn storage(device: &wgpu::Device, label: &str, size: u64, extra: wgpu::BufferUsages) -> wgpu::Buffer {
    let usage = wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST | extra;
    buffer(device, label, size.max(16), usage)
}

/// A uniform buffer of `size` bytes written from the CPU.
pub fn uniform(device: &wgpu::Device, label: &str, size: u64) -> wgpu::Buffer {
    buffer(
        device,
        label,
        size,
        wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
    )
}

/// A buffer holding `contents`, zero-padded to at least 16 bytes (so an empty array still binds).
pub fn buffer_init(device: &wgpu::Device, label: &str, contents: &[u8], usage: wgpu::BufferUsages) -> wgpu::Buffer {
    let mut padded = contents.to_vec();
    padded.resize(contents.len().max(16), 0);
    device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some(label),
        contents: &padded,
        usage,
    })
}

/// A vertex buffer holding `vertices` (see [`buffer_init`]).
pub fn vertex_buffer<T: bytemuck::Pod>(device: &wgpu::Device, label: &str, vertices: &[T]) -> wgpu::Buffer {
    buffer_init(
        device,
        label,
        bytemuck::cast_slice(vertices),
        wgpu::BufferUsages::VERTEX,
    )
}

/// A 2D texture (array when `layers > 1`) of one mip level and one sample.
pub fn texture(
    device: &wgpu::Device,
    label: &str,
    [width, height, layers]: [u32; 3],
    format: wgpu::TextureFormat,
    usage: wgpu::TextureUsages,
) -> wgpu::Texture {
    device.create_texture(&wgpu::TextureDescriptor {
        label: Some(label),
        size: wgpu::Extent3d {
            width,
            height,
            depth_or_array_layers: layers,
        },
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format,
        usage,
        view_formats: &[],
    })
}

/// A view of every layer of `texture` as a 2D array.
pub fn array_view(texture: &wgpu::Texture) -> wgpu::TextureView {
    texture.create_view(&wgpu::TextureViewDescriptor {
        dimension: Some(wgpu::TextureViewDimension::D2Array),
        ..Default::default()
    })
}

/// A 2D view of layer `layer` of `texture`.
pub fn layer_view(texture: &wgpu::Texture, layer: u32) -> wgpu::TextureView {
    texture.create_view(&wgpu::TextureViewDescriptor {
        dimension: Some(wgpu::TextureViewDimension::D2),
        base_array_layer: layer,
        array_layer_count: Some(1),
        ..Default::default()
    })
}

/// A 2D array texture of `size` (`[width, height, layers]`) in `format` that render passes draw
/// into layer by layer and shaders read whole (depth maps): its view of every layer as an array
/// ([`array_view`]) and one view per layer ([`layer_view`]).
pub fn layered_target(
    device: &wgpu::Device,
    label: &str,
    size: [u32; 3],
    format: wgpu::TextureFormat,
) -> (wgpu::TextureView, Vec<wgpu::TextureView>) {
    let usage = wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::TEXTURE_BINDING;
    let texture = texture(device, label, size, format, usage);
    let layers = (0..size[2]).map(|layer| layer_view(&texture, layer)).collect();
    (array_view(&texture), layers)
}

/// Writes `data` (rows of `bytes_per_row` bytes) into layer `layer` of `texture`, whole.
pub fn write_layer(queue: &wgpu::Queue, texture: &wgpu::Texture, layer: u32, data: &[u8], bytes_per_row: u32) {
    queue.write_texture(
        wgpu::TexelCopyTextureInfo {
            texture,
            mip_level: 0,
            origin: wgpu::Origin3d { x: 0, y: 0, z: layer },
            aspect: wgpu::TextureAspect::All,
        },
        data,
        wgpu::TexelCopyBufferLayout {
            offset: 0,
            bytes_per_row: Some(bytes_per_row),
            rows_per_image: Some(texture.height()),
        },
        wgpu::Extent3d {
            width: texture.width(),
            height: texture.height(),
            depth_or_array_layers: 1,
        },
    );
}

/// A colour attachment of `view`, cleared to transparent black (alpha 0, so that a pass may mark
/// what it drew in alpha, as the run time's irradiance pass does) and stored.
pub fn color_attachment(view: &wgpu::TextureView) -> Option<wgpu::RenderPassColorAttachment<'_>> {
    Some(wgpu::RenderPassColorAttachment {
        view,
        depth_slice: None,
        resolve_target: None,
        ops: wgpu::Operations {
            load: wgpu::LoadOp::Clear(wgpu::Color::TRANSPARENT),
            store: wgpu::StoreOp::Store,
        },
    })
}

/// A depth attachment of `view`, cleared to 1 (far) and kept only if `store` (shadow maps are
/// read later; a camera's depth is not).
pub fn depth_attachment(view: &wgpu::TextureView, store: bool) -> Option<wgpu::RenderPassDepthStencilAttachment<'_>> {
    Some(wgpu::RenderPassDepthStencilAttachment {
        view,
        depth_ops: Some(wgpu::Operations {
            load: wgpu::LoadOp::Clear(1.0),
            store: if store {
                wgpu::StoreOp::Store
            } else {
                wgpu::StoreOp::Discard
            },
        }),
        stencil_ops: None,
    })
}

/// Depth state of an opaque pass: `format`, write, nearer wins.
pub fn depth_state(format: wgpu::TextureFormat) -> Option<wgpu::DepthStencilState> {
    Some(wgpu::DepthStencilState {
        format,
        depth_write_enabled: Some(true),
        depth_compare: Some(wgpu::CompareFunction::Less),
        stencil: Default::default(),
        bias: Default::default(),
    })
}

/// What [`render`] builds: entry points `vs_main` and (with a colour target) `fs_main` of
/// `module`, no culling, one sample, depth writes with nearer-wins when `depth` is given.
pub struct RenderSpec<'a> {
    /// Label.
    pub label: &'a str,
    /// The shader.
    pub module: &'a wgpu::ShaderModule,
    /// An explicit layout (dynamic offsets), or `None` for the one the shader implies.
    pub layout: Option<&'a wgpu::PipelineLayout>,
    /// Vertex buffers.
    pub vertex_buffers: &'a [Option<wgpu::VertexBufferLayout<'a>>],
    /// Depth format, if the pass has a depth attachment.
    pub depth: Option<wgpu::TextureFormat>,
    /// Colour target format (no blending), or `None` for a depth-only pass.
    pub color: Option<wgpu::TextureFormat>,
    /// What the vertices draw (triangle lists, or line lists for edges).
    pub topology: wgpu::PrimitiveTopology,
}

/// A render pipeline as `spec` says.
pub fn render(device: &wgpu::Device, spec: &RenderSpec) -> wgpu::RenderPipeline {
    let targets = [spec.color.map(wgpu::ColorTargetState::from)];
    device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
        label: Some(spec.label),
        layout: spec.layout,
        vertex: wgpu::VertexState {
            module: spec.module,
            entry_point: Some("vs_main"),
            compilation_options: Default::default(),
            buffers: spec.vertex_buffers,
        },
        primitive: wgpu::PrimitiveState {
            topology: spec.topology,
            ..Default::default()
        },
        depth_stencil: spec.depth.and_then(depth_state),
        multisample: Default::default(),
        fragment: spec.color.map(|_| wgpu::FragmentState {
            module: spec.module,
            entry_point: Some("fs_main"),
            compilation_options: Default::default(),
            targets: &targets,
        }),
        multiview_mask: None,
        cache: None,
    })
}

/// A depth-only pipeline (entry point `vs_main` of WGSL `parts`, see [`shader`]) that draws
/// triangle lists of one vertex buffer of `stride`-byte vertices, each starting with its
/// position (`vec3<f32>` at location 0), into a `format` depth attachment, with the bind group
/// `layouts` in order (dynamic offsets the shader alone cannot imply).
pub fn depth_only(
    device: &wgpu::Device,
    label: &str,
    parts: &[&str],
    layouts: &[&wgpu::BindGroupLayout],
    stride: usize,
    format: wgpu::TextureFormat,
) -> wgpu::RenderPipeline {
    let module = shader(device, label, parts);
    let layouts: Vec<Option<&wgpu::BindGroupLayout>> = layouts.iter().copied().map(Some).collect();
    let layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
        label: Some(label),
        bind_group_layouts: &layouts,
        immediate_size: 0,
    });
    render(
        device,
        &RenderSpec {
            label,
            module: &module,
            layout: Some(&layout),
            vertex_buffers: &[vertices(stride, &wgpu::vertex_attr_array![0 => Float32x3])],
            depth: Some(format),
            color: None,
            topology: wgpu::PrimitiveTopology::TriangleList,
        },
    )
}

/// A vertex type and its attributes, locations in field order, for [`mesh`].
pub trait Vertex: Sized {
    /// The attributes (`wgpu::vertex_attr_array!`).
    const ATTRIBUTES: &'static [wgpu::VertexAttribute];
}

/// The pipeline of a pass that draws one vertex buffer of `V`: shader from WGSL `parts` (see
/// [`shader`]) with the layout it implies, built as [`render`] says for `depth` and `color`.
pub fn mesh<V: Vertex>(
    device: &wgpu::Device,
    label: &str,
    parts: &[&str],
    depth: Option<wgpu::TextureFormat>,
    color: Option<wgpu::TextureFormat>,
) -> wgpu::RenderPipeline {
    let module = shader(device, label, parts);
    render(
        device,
        &RenderSpec {
            label,
            module: &module,
            layout: None,
            vertex_buffers: &[vertices(std::mem::size_of::<V>(), V::ATTRIBUTES)],
            depth,
            color,
            topology: wgpu::PrimitiveTopology::TriangleList,
        },
    )
}

/// A vertex buffer layout of `stride` bytes per vertex with `attributes`.
pub fn vertices(stride: usize, attributes: &[wgpu::VertexAttribute]) -> Option<wgpu::VertexBufferLayout<'_>> {
    Some(wgpu::VertexBufferLayout {
        array_stride: stride as u64,
        step_mode: wgpu::VertexStepMode::Vertex,
        attributes,
    })
}

/// A bind group layout entry of a storage buffer at `binding`, seen by `visibility`, read-only
/// or not, of any size.
pub fn storage_entry(binding: u32, visibility: wgpu::ShaderStages, read_only: bool) -> wgpu::BindGroupLayoutEntry {
    buffer_entry(binding, visibility, wgpu::BufferBindingType::Storage { read_only })
}

/// A bind group layout entry of a uniform buffer at `binding`, seen by `visibility`, of any size.
pub fn uniform_entry(binding: u32, visibility: wgpu::ShaderStages) -> wgpu::BindGroupLayoutEntry {
    buffer_entry(binding, visibility, wgpu::BufferBindingType::Uniform)
}

fn buffer_entry(
    binding: u32,
    visibility: wgpu::ShaderStages,
    ty: wgpu::BufferBindingType,
) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility,
        ty: wgpu::BindingType::Buffer {
            ty,
            has_dynamic_offset: false,
            min_binding_size: None,
        },
        count: None,
    }
}

/// A bind group layout of `entries`.
pub fn bind_group_layout(
    device: &wgpu::Device,
    label: &str,
    entries: &[wgpu::BindGroupLayoutEntry],
) -> wgpu::BindGroupLayout {
    device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
        label: Some(label),
        entries,
    })
}

/// A bind group layout of one uniform buffer of `size` bytes read by the vertex stage at a
/// dynamic offset (one matrix per view, selected per draw).
pub fn dynamic_uniform_layout(device: &wgpu::Device, label: &str, size: u64) -> wgpu::BindGroupLayout {
    let entry = wgpu::BindGroupLayoutEntry {
        ty: wgpu::BindingType::Buffer {
            ty: wgpu::BufferBindingType::Uniform,
            has_dynamic_offset: true,
            min_binding_size: wgpu::BufferSize::new(size),
        },
        ..uniform_entry(0, wgpu::ShaderStages::VERTEX)
    };
    bind_group_layout(device, label, &[entry])
}

/// Begins a render pass onto `color` (cleared to transparent black) and/or `depth` (cleared to
/// far, kept if its flag says so), with `timestamps` if given.
pub fn begin_render_pass<'e>(
    encoder: &'e mut wgpu::CommandEncoder,
    label: &str,
    color: Option<&wgpu::TextureView>,
    depth: Option<(&wgpu::TextureView, bool)>,
    timestamps: Option<wgpu::RenderPassTimestampWrites<'_>>,
) -> wgpu::RenderPass<'e> {
    let colors = [color.and_then(color_attachment)];
    encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
        label: Some(label),
        color_attachments: if color.is_some() { &colors } else { &[] },
        depth_stencil_attachment: depth.and_then(|(view, store)| depth_attachment(view, store)),
        timestamp_writes: timestamps,
        occlusion_query_set: None,
        multiview_mask: None,
    })
}
