//! The shade pass (`shaders/play/shade.wgsl`): the radiance of every pixel, albedo/π × (direct
//! irradiance through the run time's shadow maps + the emitters' direct and the indirect
//! irradiance from its lightmaps) + the emission of emissive materials, in linear HDR, with the
//! material textures of the scene.

use glam::{Mat4, Vec3};
use prm_gpu_kit::{pipeline, GpuContext, PassTimer};
use prm_runtime::Runtime;
use prm_scene::Scene;

use crate::gpu::{GpuCamera, GpuMaterial, GpuVertex};

/// The colour target's format (linear radiance).
pub const COLOR_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba32Float;
/// The depth buffer's format.
pub const DEPTH_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;

/// The player's camera and modes (`shaders/play/camera.wgsl`), shared by its passes.
pub const CAMERA_WGSL: &str = include_str!("../../../shaders/play/camera.wgsl");

/// The shade pass source: the run time's shared structs and direct light, the camera, then the
/// pass.
pub fn source() -> [&'static str; 5] {
    [
        prm_runtime::SHARED_WGSL,
        prm_runtime::LIGHT_BINDINGS_WGSL,
        prm_runtime::LIGHTS_WGSL,
        CAMERA_WGSL,
        include_str!("../../../shaders/play/shade.wgsl"),
    ]
}

/// What the bind group holds besides the run time's buffers.
struct Resources {
    camera: wgpu::Buffer,
    /// The scene's materials without emission.
    base: Vec<GpuMaterial>,
    materials: wgpu::Buffer,
    textures: wgpu::TextureView,
    vertices: wgpu::Buffer,
    vertex_count: u32,
}

/// Shades the scene.
pub struct ShadePass {
    pipeline: wgpu::RenderPipeline,
    bind_group: wgpu::BindGroup,
    res: Resources,
}

impl ShadePass {
    /// The pass for `scene`, reading `runtime`'s lights, shadow maps and lightmap.
    pub fn new(ctx: &GpuContext, scene: &Scene, runtime: &Runtime) -> ShadePass {
        let device = &ctx.device;
        let uvs = runtime.lightmap_uvs();
        let vertices: Vec<GpuVertex> = scene
            .triangles
            .iter()
            .zip(uvs)
            .flat_map(|(tri, luv)| {
                (0..3).map(move |i| GpuVertex {
                    position: tri.positions[i].to_array(),
                    normal: tri.normals[i].to_array(),
                    uv: tri.uvs[i].to_array(),
                    lightmap_uv: luv[i],
                    material: tri.material,
                })
            })
            .collect();
        let (textures, sizes) = texture_array(ctx, scene);
        let base = base_materials(scene, &sizes);
        let materials = with_emission(&base, runtime);
        let res = Resources {
            camera: pipeline::uniform(device, "play camera", std::mem::size_of::<GpuCamera>() as u64),
            materials: pipeline::buffer_init(
                device,
                "play materials",
                bytemuck::cast_slice(&materials),
                wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
            ),
            base,
            textures,
            vertex_count: vertices.len() as u32,
            vertices: pipeline::vertex_buffer(device, "play vertices", &vertices),
        };
        let pipeline =
            pipeline::mesh::<GpuVertex>(device, "play shade", &source(), Some(DEPTH_FORMAT), Some(COLOR_FORMAT));
        let bind_group = Self::group(ctx, &pipeline, &res, runtime);
        ShadePass {
            pipeline,
            bind_group,
            res,
        }
    }

    fn group(ctx: &GpuContext, pipeline: &wgpu::RenderPipeline, res: &Resources, runtime: &Runtime) -> wgpu::BindGroup {
        let d = runtime.direct_light_bindings();
        pipeline::bind_group(
            &ctx.device,
            "play shade",
            &pipeline.get_bind_group_layout(0),
            &[
                &d.resources()[..],
                &[
                    res.materials.as_entire_binding(),
                    wgpu::BindingResource::TextureView(runtime.lightmap()),
                    wgpu::BindingResource::TextureView(&res.textures),
                    res.camera.as_entire_binding(),
                    wgpu::BindingResource::TextureView(runtime.emitter_lightmap()),
                ],
            ]
            .concat(),
        )
    }

    /// Binds the pass again after the run time's shadow maps grew.
    pub fn rebind(&mut self, ctx: &GpuContext, runtime: &Runtime) {
        self.bind_group = Self::group(ctx, &self.pipeline, &self.res, runtime);
    }

    /// Uploads the materials' emission again after [`Runtime::set_emitter_scales`].
    pub fn write_emission(&self, queue: &wgpu::Queue, runtime: &Runtime) {
        let materials = with_emission(&self.res.base, runtime);
        queue.write_buffer(&self.res.materials, 0, bytemuck::cast_slice(&materials));
    }

    /// Uploads the camera: view-projection, eye, [`Mode`](crate::Mode) code and image width.
    pub fn write_camera(&self, queue: &wgpu::Queue, view_proj: Mat4, eye: Vec3, mode: u32, width: u32) {
        let camera = GpuCamera {
            view_proj: view_proj.to_cols_array_2d(),
            eye: eye.to_array(),
            mode,
            width: width as f32,
            ..Default::default()
        };
        queue.write_buffer(&self.res.camera, 0, bytemuck::bytes_of(&camera));
    }

    /// The camera buffer (the probe sphere draws with it).
    pub fn camera(&self) -> &wgpu::Buffer {
        &self.res.camera
    }

    /// Draws the scene, and the probe sphere when given, into `color` with depth buffer `depth`.
    pub fn encode(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        color: &wgpu::TextureView,
        depth: &wgpu::TextureView,
        sphere: Option<&crate::sphere::SpherePass>,
        timer: Option<&PassTimer>,
    ) {
        let mut pass = pipeline::begin_render_pass(
            encoder,
            "play shade",
            Some(color),
            Some((depth, false)),
            timer.and_then(|t| t.render("shade", true, true)),
        );
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, &self.bind_group, &[]);
        pass.set_vertex_buffer(0, self.res.vertices.slice(..));
        pass.draw(0..self.res.vertex_count, 0..1);
        if let Some(s) = sphere {
            s.draw(&mut pass);
        }
    }
}

/// The scene's materials, none emitting; `sizes` are the texture layers' sizes.
fn base_materials(scene: &Scene, sizes: &[[u32; 2]]) -> Vec<GpuMaterial> {
    scene
        .materials
        .iter()
        .map(|m| {
            let layer = m.texture.filter(|&t| (t as usize) < sizes.len());
            let [texture_width, texture_height] = layer.map_or([1, 1], |t| sizes[t as usize]);
            GpuMaterial {
                albedo: m.albedo.to_array(),
                texture: layer.map_or(-1, |t| t as i32),
                emission: [0.0; 3],
                texture_width,
                texture_height,
                _pad0: 0,
                _pad1: 0,
                _pad2: 0,
            }
        })
        .collect()
}

/// `base` with the emission of the run time's emitter groups at their scales (the baked
/// radiance, on the material each group names).
fn with_emission(base: &[GpuMaterial], runtime: &Runtime) -> Vec<GpuMaterial> {
    let mut out = base.to_vec();
    for (g, s) in runtime.emitters().iter().zip(runtime.emitter_scales()) {
        if let Some(m) = out.get_mut(g.material as usize) {
            m.emission = [0, 1, 2].map(|k| g.radiance[k] * s[k]);
        }
    }
    out
}

/// Material textures as layers of one sRGB array, each at its own size in its layer's top-left
/// corner (only one larger than the device allows is shrunk, by nearest resampling), and their
/// sizes: the shader filters them by hand as `prm_scene::Texture::sample` does, wrap-around
/// bilinear at each texture's own size, so the player's albedo is the baker's and the
/// reference's. One white layer when the scene has none.
fn texture_array(ctx: &GpuContext, scene: &Scene) -> (wgpu::TextureView, Vec<[u32; 2]>) {
    let max = ctx.device.limits().max_texture_dimension_2d.min(2048);
    let sizes: Vec<[u32; 2]> = scene
        .textures
        .iter()
        .map(|t| [t.width.clamp(1, max), t.height.clamp(1, max)])
        .collect();
    let w = sizes.iter().map(|s| s[0]).max().unwrap_or(1);
    let h = sizes.iter().map(|s| s[1]).max().unwrap_or(1);
    let layers = scene.textures.len().max(1) as u32;
    let texture = pipeline::texture(
        &ctx.device,
        "play textures",
        [w, h, layers],
        wgpu::TextureFormat::Rgba8UnormSrgb,
        wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
    );
    for layer in 0..layers {
        let mut rgba = vec![255u8; (w * h * 4) as usize];
        if let (Some(t), Some(&[tw, th])) = (scene.textures.get(layer as usize), sizes.get(layer as usize)) {
            for y in 0..th {
                for x in 0..tw {
                    let sx = ((x as u64 * t.width as u64) / tw as u64) as usize;
                    let sy = ((y as u64 * t.height as u64) / th as u64) as usize;
                    let p = t.texels.get(sy * t.width as usize + sx).copied().unwrap_or([255; 3]);
                    let at = ((y * w + x) * 4) as usize;
                    rgba[at..at + 3].copy_from_slice(&p);
                }
            }
        }
        pipeline::write_layer(&ctx.queue, &texture, layer, &rgba, w * 4);
    }
    (pipeline::array_view(&texture), sizes)
}
