//! The per-frame GPU pipeline: shadow maps → cluster weights → rank → top-K selection with fade
//! → lightmap blend → shading. Everything inside a frame stays on the GPU; the CPU only uploads
//! the frame's constants (camera, lights, shadow-view matrices) and reads results on request.

use std::time::Instant;

use glam::{Mat4, Vec3};
use prm_format::Archive;
use prm_gpu::{ErrorScopes, GpuContext};
use prm_scene::{Aabb, Camera, Light, Scene};
use wgpu::util::DeviceExt;

use crate::gpu::{GpuCluster, GpuEntry, GpuFrame, GpuLight, GpuMaterial, GpuVertex, GpuView};
use crate::shadow::{look_to, perspective};
use crate::{shadow, PlayError};

/// Most lights a frame may have.
pub const MAX_LIGHTS: usize = 256;
/// Names of the timed passes, in frame order.
pub const PASS_NAMES: [&str; 6] = ["shadow", "weights", "rank", "select", "blend", "shade"];

const COLOR_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba32Float;
const DEPTH_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;
const LIGHTMAP_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba32Float;

/// What a frame shows.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Mode {
    /// Direct + indirect (global illumination).
    #[default]
    Gi,
    /// Direct light only (local illumination).
    Direct,
    /// Indirect light only.
    Indirect,
    /// Left half direct, right half global.
    Split,
}

impl Mode {
    fn code(self) -> u32 {
        match self {
            Mode::Gi => 0,
            Mode::Direct => 1,
            Mode::Indirect => 2,
            Mode::Split => 3,
        }
    }
    /// The mode's name as `--mode` takes it.
    pub fn name(self) -> &'static str {
        match self {
            Mode::Gi => "gi",
            Mode::Direct => "direct",
            Mode::Indirect => "indirect",
            Mode::Split => "split",
        }
    }
    fn needs_indirect(self) -> bool {
        self != Mode::Direct
    }
}

impl std::str::FromStr for Mode {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s.to_ascii_lowercase().as_str() {
            "gi" => Ok(Mode::Gi),
            "direct" => Ok(Mode::Direct),
            "indirect" => Ok(Mode::Indirect),
            "split" => Ok(Mode::Split),
            _ => Err(format!("unknown mode '{s}' (expected gi, direct, indirect or split)")),
        }
    }
}

/// Renderer settings.
#[derive(Clone, Debug)]
pub struct PlayOptions {
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// Clusters kept per frame.
    pub top_k: u32,
    /// Shadow-map side in texels (every view).
    pub shadow_resolution: u32,
    /// Fade band: kept clusters whose score is within `band × threshold` above the threshold
    /// (the first dropped cluster's score) are faded by a smoothstep.
    pub fade_band: f32,
    /// Shadow lookups move the point this many shadow texels along its normal.
    pub normal_offset: f32,
    /// Depth tolerance of a shadow lookup, in shadow texels (world size at the point).
    pub depth_bias: f32,
    /// Time every pass with GPU timestamp queries (when the device has them).
    pub timestamps: bool,
}

/// Largest shadow-map side [`PlayOptions::validate`] accepts: a point light's six faces take
/// 6 × 8192² × 4 bytes = 1.5 GiB of depth at this size; beyond it lavapipe runs out of memory
/// with a single light.
pub const MAX_SHADOW_RESOLUTION: u32 = 8192;

impl PlayOptions {
    /// Checks the options against each other and `limits` before any GPU allocation, naming
    /// the `prm-play` option and the limit it breaks.
    pub fn validate(&self, limits: &wgpu::Limits) -> Result<(), PlayError> {
        let bad = |option: &'static str, message: String| Err(PlayError::Option { option, message });
        let max_dim = limits.max_texture_dimension_2d;
        if self.width == 0 || self.height == 0 || self.width > max_dim || self.height > max_dim {
            return bad(
                "--size",
                format!(
                    "{}x{} is outside this device's 1..={max_dim} texels per side (max_texture_dimension_2d)",
                    self.width, self.height
                ),
            );
        }
        let readback = readback_bytes(self.width, self.height);
        if readback > limits.max_buffer_size {
            return bad(
                "--size",
                format!(
                    "{}x{} needs a {readback}-byte image buffer (16 bytes a pixel), over this device's \
                     max_buffer_size of {} bytes",
                    self.width, self.height, limits.max_buffer_size
                ),
            );
        }
        let max_shadow = max_dim.min(MAX_SHADOW_RESOLUTION);
        if !(16..=max_shadow).contains(&self.shadow_resolution) {
            return bad(
                "--shadow-resolution",
                format!(
                    "{} is outside 16..={max_shadow} (the least of this device's max_texture_dimension_2d \
                     {max_dim} and {MAX_SHADOW_RESOLUTION}, where one point light's six faces take 1.5 GiB)",
                    self.shadow_resolution
                ),
            );
        }
        if self.top_k == 0 {
            return bad("--top-k", "must be at least 1".into());
        }
        if !(self.fade_band.is_finite() && self.fade_band >= 0.0) {
            return bad(
                "--fade-band",
                format!("{} must be a finite number >= 0", self.fade_band),
            );
        }
        for (option, v) in [("normal_offset", self.normal_offset), ("depth_bias", self.depth_bias)] {
            if !(v.is_finite() && v >= 0.0) {
                return bad(option, format!("{v} must be a finite number >= 0"));
            }
        }
        Ok(())
    }
}

/// Bytes of the buffer a `width × height` frame is read back through (rgba32float rows padded
/// to wgpu's copy alignment).
fn readback_bytes(width: u32, height: u32) -> u64 {
    let row = width as u64 * 16;
    let align = wgpu::COPY_BYTES_PER_ROW_ALIGNMENT as u64;
    row.div_ceil(align) * align * height as u64
}

impl Default for PlayOptions {
    fn default() -> Self {
        PlayOptions {
            width: 1024,
            height: 768,
            top_k: crate::DEFAULT_TOP_K,
            shadow_resolution: 512,
            fade_band: 0.25,
            normal_offset: 1.5,
            depth_bias: 1.5,
            timestamps: false,
        }
    }
}

/// One frame's camera, lights and mode.
#[derive(Clone, Copy, Debug)]
pub struct FrameInput<'a> {
    /// Camera.
    pub camera: Camera,
    /// Lights (at most [`MAX_LIGHTS`]).
    pub lights: &'a [Light],
    /// What to show.
    pub mode: Mode,
}

/// Times of one frame.
#[derive(Clone, Debug, Default)]
pub struct FrameTimings {
    /// Wall time from recording to the GPU finishing, milliseconds.
    pub cpu_ms: f64,
    /// GPU time per pass (from [`PASS_NAMES`], only the passes that ran), milliseconds; empty
    /// without timestamp queries.
    pub gpu_ms: Vec<(&'static str, f64)>,
}

/// A linear-radiance image read back from the GPU.
#[derive(Clone, Debug)]
pub struct Image {
    /// Width.
    pub width: u32,
    /// Height.
    pub height: u32,
    /// Row-major, top row first.
    pub rgb: Vec<[f32; 3]>,
}

/// A cluster's weights as the GPU computed them.
#[derive(Clone, Copy, Debug)]
pub struct ClusterWeight {
    /// The members' entry irradiance weighed by their pane energy (their mean in archives
    /// before 1.1).
    pub weight: [f32; 3],
    /// Σ_rgb weight × pane energy.
    pub score: f32,
    /// Weight used in the blend (0 if dropped, faded near the threshold).
    pub effective: [f32; 3],
    /// Rank by score (0 = largest).
    pub rank: u32,
}

struct ShadowMaps {
    capacity: u32,
    layers: Vec<wgpu::TextureView>,
    matrices: wgpu::Buffer,
    group: wgpu::BindGroup,
}

struct Timestamps {
    set: wgpu::QuerySet,
    resolve: wgpu::Buffer,
    read: wgpu::Buffer,
}

/// The player's GPU state for one archive and scene.
pub struct Renderer {
    ctx: GpuContext,
    opts: PlayOptions,
    bounds: Aabb,
    cluster_count: u32,
    entry_count: u32,
    lightmap_resolution: u32,
    vertex_count: u32,
    positions: wgpu::Buffer,
    vertices: wgpu::Buffer,
    frame: wgpu::Buffer,
    lights: wgpu::Buffer,
    views: wgpu::Buffer,
    clusters: wgpu::Buffer,
    entries: wgpu::Buffer,
    weights: wgpu::Buffer,
    effective: wgpu::Buffer,
    lightmap: wgpu::Texture,
    color: wgpu::Texture,
    color_view: wgpu::TextureView,
    depth_view: wgpu::TextureView,
    matrix_stride: u32,
    shadow_layout: wgpu::BindGroupLayout,
    shadow_pipeline: wgpu::RenderPipeline,
    weights_pipeline: wgpu::ComputePipeline,
    rank_pipeline: wgpu::ComputePipeline,
    select_pipeline: wgpu::ComputePipeline,
    blend_pipeline: wgpu::ComputePipeline,
    shade_pipeline: wgpu::RenderPipeline,
    rank_group: wgpu::BindGroup,
    select_group: wgpu::BindGroup,
    blend_group: wgpu::BindGroup,
    weights_group: wgpu::BindGroup,
    shade_group: wgpu::BindGroup,
    shade_resources: ShadeResources,
    shadow: ShadowMaps,
    timestamps: Option<Timestamps>,
    /// Whether this frame writes the timestamps (see [`Renderer::set_timing`]).
    timing: bool,
}

struct ShadeResources {
    materials: wgpu::Buffer,
    textures: wgpu::TextureView,
    sampler: wgpu::Sampler,
    lightmap: wgpu::TextureView,
}

fn lights_source(pass: &str) -> String {
    format!("{}\n{}", include_str!("../../../shaders/play_lights.wgsl"), pass)
}

fn storage(device: &wgpu::Device, label: &str, size: u64, extra: wgpu::BufferUsages) -> wgpu::Buffer {
    device.create_buffer(&wgpu::BufferDescriptor {
        label: Some(label),
        size: size.max(16),
        usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST | extra,
        mapped_at_creation: false,
    })
}

fn compute(device: &wgpu::Device, label: &str, source: String) -> wgpu::ComputePipeline {
    let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some(label),
        source: wgpu::ShaderSource::Wgsl(source.into()),
    });
    device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
        label: Some(label),
        layout: None,
        module: &module,
        entry_point: Some("main"),
        compilation_options: Default::default(),
        cache: None,
    })
}

fn group(
    device: &wgpu::Device,
    label: &str,
    layout: &wgpu::BindGroupLayout,
    res: &[wgpu::BindingResource],
) -> wgpu::BindGroup {
    let entries: Vec<wgpu::BindGroupEntry> = res
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

fn check(ctx: &GpuContext, scope: ErrorScopes, pass: &'static str) -> Result<(), PlayError> {
    scope.pop(pass)?;
    ctx.take_uncaptured()?;
    Ok(())
}

/// The colour target (linear radiance; sampled by the window's present pass) and depth buffer.
fn targets(device: &wgpu::Device, width: u32, height: u32) -> (wgpu::Texture, wgpu::TextureView, wgpu::TextureView) {
    let target = |label: &str, format, usage| {
        device.create_texture(&wgpu::TextureDescriptor {
            label: Some(label),
            size: wgpu::Extent3d {
                width,
                height,
                depth_or_array_layers: 1,
            },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format,
            usage,
            view_formats: &[],
        })
    };
    let color = target(
        "play color",
        COLOR_FORMAT,
        wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC | wgpu::TextureUsages::TEXTURE_BINDING,
    );
    let color_view = color.create_view(&Default::default());
    let depth_view =
        target("play depth", DEPTH_FORMAT, wgpu::TextureUsages::RENDER_ATTACHMENT).create_view(&Default::default());
    (color, color_view, depth_view)
}

/// Reads a whole 2D texture of 16-byte texels (rgba32float) as RGB.
fn read_texture_rgb(ctx: &GpuContext, texture: &wgpu::Texture) -> Result<Vec<[f32; 3]>, PlayError> {
    let (w, h) = (texture.width(), texture.height());
    let row = w * 16;
    let padded = row.div_ceil(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT) * wgpu::COPY_BYTES_PER_ROW_ALIGNMENT;
    let buffer = ctx.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("readback"),
        size: readback_bytes(w, h),
        usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
        mapped_at_creation: false,
    });
    let mut enc = ctx.device.create_command_encoder(&Default::default());
    enc.copy_texture_to_buffer(
        wgpu::TexelCopyTextureInfo {
            texture,
            mip_level: 0,
            origin: wgpu::Origin3d::ZERO,
            aspect: wgpu::TextureAspect::All,
        },
        wgpu::TexelCopyBufferInfo {
            buffer: &buffer,
            layout: wgpu::TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some(padded),
                rows_per_image: Some(h),
            },
        },
        wgpu::Extent3d {
            width: w,
            height: h,
            depth_or_array_layers: 1,
        },
    );
    ctx.queue.submit([enc.finish()]);
    let bytes = ctx.read_buffer(&buffer)?;
    let mut out = Vec::with_capacity((w * h) as usize);
    for y in 0..h as usize {
        let r: &[f32] = bytemuck::cast_slice(&bytes[y * padded as usize..y * padded as usize + row as usize]);
        out.extend(r.chunks_exact(4).map(|p| [p[0], p[1], p[2]]));
    }
    Ok(out)
}

fn read_storage(ctx: &GpuContext, src: &wgpu::Buffer, size: u64) -> Result<Vec<u8>, PlayError> {
    let buffer = ctx.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("readback"),
        size,
        usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
        mapped_at_creation: false,
    });
    let mut enc = ctx.device.create_command_encoder(&Default::default());
    enc.copy_buffer_to_buffer(src, 0, &buffer, 0, size);
    ctx.queue.submit([enc.finish()]);
    Ok(ctx.read_buffer(&buffer)?)
}

/// Material textures as layers of one sRGB array, all at the largest size (nearest resampling
/// of the smaller ones); one white layer when the scene has none.
fn texture_array(ctx: &GpuContext, scene: &Scene) -> wgpu::TextureView {
    let max = ctx.device.limits().max_texture_dimension_2d.min(2048);
    let w = scene.textures.iter().map(|t| t.width).max().unwrap_or(1).clamp(1, max);
    let h = scene.textures.iter().map(|t| t.height).max().unwrap_or(1).clamp(1, max);
    let layers = scene.textures.len().max(1) as u32;
    let texture = ctx.device.create_texture(&wgpu::TextureDescriptor {
        label: Some("play textures"),
        size: wgpu::Extent3d {
            width: w,
            height: h,
            depth_or_array_layers: layers,
        },
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format: wgpu::TextureFormat::Rgba8UnormSrgb,
        usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
        view_formats: &[],
    });
    for layer in 0..layers {
        let mut rgba = vec![255u8; (w * h * 4) as usize];
        if let Some(t) = scene.textures.get(layer as usize) {
            for y in 0..h {
                for x in 0..w {
                    let sx = ((x as u64 * t.width as u64) / w as u64) as usize;
                    let sy = ((y as u64 * t.height as u64) / h as u64) as usize;
                    let p = t.texels.get(sy * t.width as usize + sx).copied().unwrap_or([255; 3]);
                    let at = ((y * w + x) * 4) as usize;
                    rgba[at..at + 3].copy_from_slice(&p);
                }
            }
        }
        ctx.queue.write_texture(
            wgpu::TexelCopyTextureInfo {
                texture: &texture,
                mip_level: 0,
                origin: wgpu::Origin3d { x: 0, y: 0, z: layer },
                aspect: wgpu::TextureAspect::All,
            },
            &rgba,
            wgpu::TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some(w * 4),
                rows_per_image: Some(h),
            },
            wgpu::Extent3d {
                width: w,
                height: h,
                depth_or_array_layers: 1,
            },
        );
    }
    texture.create_view(&wgpu::TextureViewDescriptor {
        dimension: Some(wgpu::TextureViewDimension::D2Array),
        ..Default::default()
    })
}

impl Renderer {
    /// Uploads the scene, the archive's entries, clusters and panes, and builds the pipelines.
    /// The archive must belong to the scene (see [`crate::open`]).
    pub fn new<R: std::io::Read + std::io::Seek>(
        ctx: GpuContext,
        scene: &Scene,
        archive: &mut Archive<R>,
        opts: PlayOptions,
    ) -> Result<Renderer, PlayError> {
        opts.validate(&ctx.device.limits())?;
        let device = &ctx.device;
        let atlas = archive.atlas().clone();
        if atlas.triangle_uvs.len() != scene.triangles.len() {
            return Err(PlayError::Mismatch(format!(
                "the archive's atlas has {} triangles, the scene {}",
                atlas.triangle_uvs.len(),
                scene.triangles.len()
            )));
        }
        let cluster_count = archive.clusters().len() as u32;
        let max_layers = device.limits().max_texture_array_layers;
        if cluster_count > max_layers {
            return Err(PlayError::TooManyPanes {
                panes: cluster_count as usize,
                max: max_layers,
            });
        }
        let scope = ErrorScopes::push(device);

        // Geometry: positions for the shadow pass, full vertices for shading.
        let mut positions = Vec::with_capacity(scene.triangles.len() * 3);
        let mut vertices = Vec::with_capacity(scene.triangles.len() * 3);
        for (t, tri) in scene.triangles.iter().enumerate() {
            for i in 0..3 {
                positions.push(tri.positions[i].to_array());
                vertices.push(GpuVertex {
                    position: tri.positions[i].to_array(),
                    normal: tri.normals[i].to_array(),
                    uv: tri.uvs[i].to_array(),
                    lightmap_uv: atlas.triangle_uvs[t][i],
                    material: tri.material,
                });
            }
        }
        let init = |label: &str, contents: &[u8], usage: wgpu::BufferUsages| {
            let mut padded = contents.to_vec();
            padded.resize(contents.len().max(16), 0);
            device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some(label),
                contents: &padded,
                usage,
            })
        };
        let positions = init(
            "play positions",
            bytemuck::cast_slice(&positions),
            wgpu::BufferUsages::VERTEX,
        );
        let vertex_count = vertices.len() as u32;
        let vertices = init(
            "play vertices",
            bytemuck::cast_slice(&vertices),
            wgpu::BufferUsages::VERTEX,
        );

        // Entries (each stands for a disk of area A/N: its bound, see play_weights.wgsl) and
        // clusters.
        let disk = prm_trace::ENTRY_DISK
            * (scene.area() / archive.entries().len().max(1) as f64 / std::f64::consts::PI) as f32;
        let energy = archive.entry_energy();
        let entries: Vec<GpuEntry> = archive
            .entries()
            .iter()
            .enumerate()
            .map(|(i, e)| {
                let [r, g, b] = energy.map_or([1.0; 3], |en| en[i]);
                GpuEntry {
                    position: [e.position[0], e.position[1], e.position[2], disk],
                    normal: [e.normal[0], e.normal[1], e.normal[2], 0.0],
                    energy: [r, g, b, 0.0],
                }
            })
            .collect();
        let clusters: Vec<GpuCluster> = archive
            .clusters()
            .iter()
            .map(|c| GpuCluster {
                first: c.first,
                count: c.count,
                pad: [0; 2],
                energy: [c.energy[0], c.energy[1], c.energy[2], 0.0],
            })
            .collect();
        let entry_count = entries.len() as u32;
        let st = wgpu::BufferUsages::STORAGE;
        let entries = init("play entries", bytemuck::cast_slice(&entries), st);
        let clusters = init("play clusters", bytemuck::cast_slice(&clusters), st);
        let per_cluster = cluster_count.max(1) as u64 * 16;
        let src = wgpu::BufferUsages::COPY_SRC;
        let weights = storage(device, "play weights", per_cluster, src);
        let ranks = storage(device, "play ranks", cluster_count.max(1) as u64 * 4, src);
        let threshold = storage(device, "play threshold", 16, src);
        let selected = storage(device, "play selected", per_cluster, src);
        let effective = storage(device, "play effective", per_cluster, src);
        let frame = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("play frame"),
            size: std::mem::size_of::<GpuFrame>() as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let lights = storage(
            device,
            "play lights",
            (MAX_LIGHTS * 64) as u64,
            wgpu::BufferUsages::empty(),
        );
        let views = storage(
            device,
            "play views",
            (MAX_LIGHTS * 6 * 80) as u64,
            wgpu::BufferUsages::empty(),
        );

        // Panes: one rgb9e5ufloat layer each.
        let res = atlas.resolution;
        let pane_texture = device.create_texture(&wgpu::TextureDescriptor {
            label: Some("play panes"),
            size: wgpu::Extent3d {
                width: res,
                height: res,
                depth_or_array_layers: cluster_count.max(1),
            },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: wgpu::TextureFormat::Rgb9e5Ufloat,
            usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
            view_formats: &[],
        });
        for p in 0..cluster_count {
            let words = archive.read_pane_rgb9e5(p as usize).map_err(|source| PlayError::Pane {
                pane: p as usize,
                source,
            })?;
            ctx.queue.write_texture(
                wgpu::TexelCopyTextureInfo {
                    texture: &pane_texture,
                    mip_level: 0,
                    origin: wgpu::Origin3d { x: 0, y: 0, z: p },
                    aspect: wgpu::TextureAspect::All,
                },
                bytemuck::cast_slice(&words),
                wgpu::TexelCopyBufferLayout {
                    offset: 0,
                    bytes_per_row: Some(res * 4),
                    rows_per_image: Some(res),
                },
                wgpu::Extent3d {
                    width: res,
                    height: res,
                    depth_or_array_layers: 1,
                },
            );
        }
        let panes = pane_texture.create_view(&wgpu::TextureViewDescriptor {
            dimension: Some(wgpu::TextureViewDimension::D2Array),
            ..Default::default()
        });
        let lightmap = device.create_texture(&wgpu::TextureDescriptor {
            label: Some("play lightmap"),
            size: wgpu::Extent3d {
                width: res,
                height: res,
                depth_or_array_layers: 1,
            },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: LIGHTMAP_FORMAT,
            usage: wgpu::TextureUsages::STORAGE_BINDING
                | wgpu::TextureUsages::TEXTURE_BINDING
                | wgpu::TextureUsages::COPY_SRC,
            view_formats: &[],
        });
        let lightmap_view = lightmap.create_view(&Default::default());

        // Materials and textures.
        let materials: Vec<GpuMaterial> = scene
            .materials
            .iter()
            .map(|m| GpuMaterial {
                albedo: m.albedo.to_array(),
                texture: m.texture.map_or(-1, |t| t as i32),
            })
            .collect();
        let materials = init("play materials", bytemuck::cast_slice(&materials), st);
        let textures = texture_array(&ctx, scene);
        let sampler = device.create_sampler(&wgpu::SamplerDescriptor {
            label: Some("play textures"),
            address_mode_u: wgpu::AddressMode::Repeat,
            address_mode_v: wgpu::AddressMode::Repeat,
            mag_filter: wgpu::FilterMode::Linear,
            min_filter: wgpu::FilterMode::Linear,
            ..Default::default()
        });

        // Render targets.
        let (color, color_view, depth_view) = targets(device, opts.width, opts.height);

        // Pipelines.
        let shadow_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("play shadow"),
            entries: &[wgpu::BindGroupLayoutEntry {
                binding: 0,
                visibility: wgpu::ShaderStages::VERTEX,
                ty: wgpu::BindingType::Buffer {
                    ty: wgpu::BufferBindingType::Uniform,
                    has_dynamic_offset: true,
                    min_binding_size: wgpu::BufferSize::new(64),
                },
                count: None,
            }],
        });
        let shadow_module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("play_shadow"),
            source: wgpu::ShaderSource::Wgsl(include_str!("../../../shaders/play_shadow.wgsl").into()),
        });
        let shadow_pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("play_shadow"),
            bind_group_layouts: &[Some(&shadow_layout)],
            immediate_size: 0,
        });
        let shadow_pipeline = device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
            label: Some("play_shadow"),
            layout: Some(&shadow_pipeline_layout),
            vertex: wgpu::VertexState {
                module: &shadow_module,
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
                bias: Default::default(),
            }),
            multisample: Default::default(),
            fragment: None,
            multiview_mask: None,
            cache: None,
        });
        let weights_pipeline = compute(
            device,
            "play_weights",
            lights_source(include_str!("../../../shaders/play_weights.wgsl")),
        );
        let rank_pipeline = compute(
            device,
            "play_rank",
            include_str!("../../../shaders/play_rank.wgsl").into(),
        );
        let select_pipeline = compute(
            device,
            "play_select",
            include_str!("../../../shaders/play_select.wgsl").into(),
        );
        let blend_pipeline = compute(
            device,
            "play_blend",
            include_str!("../../../shaders/play_blend.wgsl").into(),
        );
        let shade_module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("play_shade"),
            source: wgpu::ShaderSource::Wgsl(lights_source(include_str!("../../../shaders/play_shade.wgsl")).into()),
        });
        let shade_pipeline = device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
            label: Some("play_shade"),
            layout: None,
            vertex: wgpu::VertexState {
                module: &shade_module,
                entry_point: Some("vs_main"),
                compilation_options: Default::default(),
                buffers: &[Some(wgpu::VertexBufferLayout {
                    array_stride: std::mem::size_of::<GpuVertex>() as u64,
                    step_mode: wgpu::VertexStepMode::Vertex,
                    attributes: &wgpu::vertex_attr_array![
                        0 => Float32x3, 1 => Float32x3, 2 => Float32x2, 3 => Float32x2, 4 => Uint32
                    ],
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
                bias: Default::default(),
            }),
            multisample: Default::default(),
            fragment: Some(wgpu::FragmentState {
                module: &shade_module,
                entry_point: Some("fs_main"),
                compilation_options: Default::default(),
                targets: &[Some(wgpu::ColorTargetState {
                    format: COLOR_FORMAT,
                    blend: None,
                    write_mask: wgpu::ColorWrites::ALL,
                })],
            }),
            multiview_mask: None,
            cache: None,
        });

        let rank_group = group(
            device,
            "play_rank",
            &rank_pipeline.get_bind_group_layout(0),
            &[
                frame.as_entire_binding(),
                weights.as_entire_binding(),
                ranks.as_entire_binding(),
                threshold.as_entire_binding(),
            ],
        );
        let select_group = group(
            device,
            "play_select",
            &select_pipeline.get_bind_group_layout(0),
            &[
                frame.as_entire_binding(),
                weights.as_entire_binding(),
                ranks.as_entire_binding(),
                threshold.as_entire_binding(),
                selected.as_entire_binding(),
                effective.as_entire_binding(),
            ],
        );
        let blend_group = group(
            device,
            "play_blend",
            &blend_pipeline.get_bind_group_layout(0),
            &[
                frame.as_entire_binding(),
                selected.as_entire_binding(),
                wgpu::BindingResource::TextureView(&panes),
                wgpu::BindingResource::TextureView(&lightmap_view),
            ],
        );
        let matrix_stride = device.limits().min_uniform_buffer_offset_alignment.max(64);
        let shade_resources = ShadeResources {
            materials,
            textures,
            sampler,
            lightmap: lightmap_view,
        };
        let (shadow, weights_group, shade_group) = Self::shadow_maps(
            &ctx,
            &opts,
            1,
            matrix_stride,
            &shadow_layout,
            &weights_pipeline,
            &shade_pipeline,
            [&frame, &lights, &views, &clusters, &entries, &weights],
            &shade_resources,
        );
        let timestamps = (opts.timestamps && device.features().contains(wgpu::Features::TIMESTAMP_QUERY)).then(|| {
            let n = PASS_NAMES.len() as u64;
            Timestamps {
                set: device.create_query_set(&wgpu::QuerySetDescriptor {
                    label: Some("play timestamps"),
                    ty: wgpu::QueryType::Timestamp,
                    count: 2 * n as u32,
                }),
                resolve: device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some("play timestamps resolve"),
                    size: n * 256,
                    usage: wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
                    mapped_at_creation: false,
                }),
                read: device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some("play timestamps read"),
                    size: n * 256,
                    usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
                    mapped_at_creation: false,
                }),
            }
        });
        let _ = ranks;
        check(&ctx, scope, "renderer setup")?;
        Ok(Renderer {
            bounds: scene.bounds(),
            cluster_count,
            entry_count,
            lightmap_resolution: res,
            vertex_count,
            positions,
            vertices,
            frame,
            lights,
            views,
            clusters,
            entries,
            weights,
            effective,
            lightmap,
            color,
            color_view,
            depth_view,
            matrix_stride,
            shadow_layout,
            shadow_pipeline,
            weights_pipeline,
            rank_pipeline,
            select_pipeline,
            blend_pipeline,
            shade_pipeline,
            rank_group,
            select_group,
            blend_group,
            weights_group,
            shade_group,
            shade_resources,
            shadow,
            timing: timestamps.is_some(),
            timestamps,
            ctx,
            opts,
        })
    }

    /// Shadow-map array of `capacity` layers and the bind groups that read it.
    #[allow(clippy::too_many_arguments)]
    fn shadow_maps(
        ctx: &GpuContext,
        opts: &PlayOptions,
        capacity: u32,
        matrix_stride: u32,
        shadow_layout: &wgpu::BindGroupLayout,
        weights_pipeline: &wgpu::ComputePipeline,
        shade_pipeline: &wgpu::RenderPipeline,
        [frame, lights, views, clusters, entries, weights]: [&wgpu::Buffer; 6],
        shade: &ShadeResources,
    ) -> (ShadowMaps, wgpu::BindGroup, wgpu::BindGroup) {
        let device = &ctx.device;
        let res = opts.shadow_resolution;
        let texture = device.create_texture(&wgpu::TextureDescriptor {
            label: Some("play shadow maps"),
            size: wgpu::Extent3d {
                width: res,
                height: res,
                depth_or_array_layers: capacity,
            },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: DEPTH_FORMAT,
            usage: wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::TEXTURE_BINDING,
            view_formats: &[],
        });
        let view = texture.create_view(&wgpu::TextureViewDescriptor {
            dimension: Some(wgpu::TextureViewDimension::D2Array),
            ..Default::default()
        });
        let layers = (0..capacity)
            .map(|l| {
                texture.create_view(&wgpu::TextureViewDescriptor {
                    dimension: Some(wgpu::TextureViewDimension::D2),
                    base_array_layer: l,
                    array_layer_count: Some(1),
                    ..Default::default()
                })
            })
            .collect();
        let matrices = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("play shadow matrices"),
            size: (capacity * matrix_stride) as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let matrix_group = group(
            device,
            "play_shadow",
            shadow_layout,
            &[wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                buffer: &matrices,
                offset: 0,
                size: wgpu::BufferSize::new(64),
            })],
        );
        let weights_group = group(
            device,
            "play_weights",
            &weights_pipeline.get_bind_group_layout(0),
            &[
                frame.as_entire_binding(),
                lights.as_entire_binding(),
                views.as_entire_binding(),
                wgpu::BindingResource::TextureView(&view),
                clusters.as_entire_binding(),
                entries.as_entire_binding(),
                weights.as_entire_binding(),
            ],
        );
        let shade_group = group(
            device,
            "play_shade",
            &shade_pipeline.get_bind_group_layout(0),
            &[
                frame.as_entire_binding(),
                lights.as_entire_binding(),
                views.as_entire_binding(),
                wgpu::BindingResource::TextureView(&view),
                shade.materials.as_entire_binding(),
                wgpu::BindingResource::TextureView(&shade.lightmap),
                wgpu::BindingResource::TextureView(&shade.textures),
                wgpu::BindingResource::Sampler(&shade.sampler),
            ],
        );
        (
            ShadowMaps {
                capacity,
                layers,
                matrices,
                group: matrix_group,
            },
            weights_group,
            shade_group,
        )
    }

    fn ensure_shadow_capacity(&mut self, layers: u32) {
        if layers <= self.shadow.capacity {
            return;
        }
        let capacity = layers.next_power_of_two();
        let (shadow, weights_group, shade_group) = Self::shadow_maps(
            &self.ctx,
            &self.opts,
            capacity,
            self.matrix_stride,
            &self.shadow_layout,
            &self.weights_pipeline,
            &self.shade_pipeline,
            [
                &self.frame,
                &self.lights,
                &self.views,
                &self.clusters,
                &self.entries,
                &self.weights,
            ],
            &self.shade_resources,
        );
        self.shadow = shadow;
        self.weights_group = weights_group;
        self.shade_group = shade_group;
    }

    /// The GPU context.
    pub fn context(&self) -> &GpuContext {
        &self.ctx
    }

    /// The options in use.
    pub fn options(&self) -> &PlayOptions {
        &self.opts
    }

    /// Number of clusters (= panes).
    pub fn cluster_count(&self) -> u32 {
        self.cluster_count
    }

    /// Whether per-pass GPU timestamps are recorded.
    pub fn has_timestamps(&self) -> bool {
        self.timestamps.is_some()
    }

    /// Pauses (`false`) or resumes per-pass timestamp queries; nothing changes without them.
    /// On lavapipe a timestamp is a synchronisation point, so frame times are cleanest without.
    pub fn set_timing(&mut self, on: bool) {
        self.timing = on;
    }

    /// The last frame (linear radiance, `rgba32float`), for presenting.
    pub fn color_view(&self) -> &wgpu::TextureView {
        &self.color_view
    }

    /// Changes the image size (re-creates the render targets only).
    pub fn resize(&mut self, width: u32, height: u32) {
        let (w, h) = (width.max(1), height.max(1));
        if (w, h) == (self.opts.width, self.opts.height) {
            return;
        }
        (self.color, self.color_view, self.depth_view) = targets(&self.ctx.device, w, h);
        self.opts.width = w;
        self.opts.height = h;
    }

    /// Changes the number of clusters kept per frame.
    pub fn set_top_k(&mut self, k: u32) {
        self.opts.top_k = k.max(1);
    }

    fn camera_matrix(&self, camera: &Camera) -> Mat4 {
        let aspect = self.opts.width as f32 / self.opts.height as f32;
        let diag = self.bounds.diagonal().max(1e-3);
        let centre = (self.bounds.min + self.bounds.max) * 0.5;
        let far = (camera.eye.distance(centre) + diag) * 1.1;
        let near = (diag * 1e-3).min(far * 1e-3);
        let fwd = (camera.target - camera.eye).normalize_or(Vec3::NEG_Z);
        let up = if fwd.y.abs() > 0.999 { Vec3::Z } else { Vec3::Y };
        perspective(camera.fov_y_deg.to_radians(), aspect, near, far) * look_to(camera.eye, fwd, up)
    }

    /// Renders one frame and waits for the GPU.
    pub fn render(&mut self, input: &FrameInput) -> Result<FrameTimings, PlayError> {
        if input.lights.len() > MAX_LIGHTS {
            return Err(PlayError::Mismatch(format!(
                "{} lights, at most {MAX_LIGHTS} are supported",
                input.lights.len()
            )));
        }
        let start = Instant::now();
        let (lights, views) = shadow::build(input.lights, &self.bounds, self.opts.shadow_resolution);
        let scope = ErrorScopes::push(&self.ctx.device);
        self.ensure_shadow_capacity(views.len() as u32);
        let queue = &self.ctx.queue;
        let frame = GpuFrame {
            view_proj: self.camera_matrix(&input.camera).to_cols_array_2d(),
            eye: input.camera.eye.extend(1.0).to_array(),
            counts: [
                lights.len() as u32,
                input.mode.code(),
                self.opts.width,
                self.opts.height,
            ],
            clusters: [self.cluster_count, self.opts.top_k.max(1), self.entry_count, 0],
            params: [
                self.opts.fade_band,
                self.opts.shadow_resolution as f32,
                self.opts.normal_offset,
                self.opts.depth_bias,
            ],
        };
        queue.write_buffer(&self.frame, 0, bytemuck::bytes_of(&frame));
        if !lights.is_empty() {
            queue.write_buffer(&self.lights, 0, bytemuck::cast_slice::<GpuLight, u8>(&lights));
            queue.write_buffer(&self.views, 0, bytemuck::cast_slice::<GpuView, u8>(&views));
            let stride = self.matrix_stride as usize;
            let mut mats = vec![0u8; views.len() * stride];
            for (i, v) in views.iter().enumerate() {
                mats[i * stride..i * stride + 64].copy_from_slice(bytemuck::cast_slice(&v.view_proj));
            }
            queue.write_buffer(&self.shadow.matrices, 0, &mats);
        }

        let timestamps = self.timestamps.as_ref().filter(|_| self.timing);
        let ts = |pass: usize, first: bool, last: bool| timestamps.map(|t| (t, pass, first, last));
        let mut enc = self.ctx.device.create_command_encoder(&Default::default());
        let mut ran = [false; PASS_NAMES.len()];
        // Shadow maps: one depth pass per view.
        for (l, layer) in self.shadow.layers.iter().take(views.len()).enumerate() {
            let t = ts(0, l == 0, l + 1 == views.len());
            let mut pass = enc.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("play_shadow"),
                color_attachments: &[],
                depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                    view: layer,
                    depth_ops: Some(wgpu::Operations {
                        load: wgpu::LoadOp::Clear(1.0),
                        store: wgpu::StoreOp::Store,
                    }),
                    stencil_ops: None,
                }),
                timestamp_writes: t
                    .filter(|(_, _, first, last)| *first || *last)
                    .map(|(t, p, first, last)| wgpu::RenderPassTimestampWrites {
                        query_set: &t.set,
                        beginning_of_pass_write_index: first.then_some(2 * p as u32),
                        end_of_pass_write_index: last.then_some(2 * p as u32 + 1),
                    }),
                occlusion_query_set: None,
                multiview_mask: None,
            });
            pass.set_pipeline(&self.shadow_pipeline);
            pass.set_bind_group(0, &self.shadow.group, &[l as u32 * self.matrix_stride]);
            pass.set_vertex_buffer(0, self.positions.slice(..));
            pass.draw(0..self.vertex_count, 0..1);
            ran[0] = true;
        }
        if input.mode.needs_indirect() && self.cluster_count > 0 {
            let groups = self.cluster_count.div_ceil(64);
            let lm = self.lightmap_resolution.div_ceil(8);
            let passes: [(&wgpu::ComputePipeline, &wgpu::BindGroup, [u32; 2]); 4] = [
                // One workgroup per cluster (play_weights.wgsl), in rows of 65535.
                (
                    &self.weights_pipeline,
                    &self.weights_group,
                    [self.cluster_count.min(65535), self.cluster_count.div_ceil(65535)],
                ),
                (&self.rank_pipeline, &self.rank_group, [groups, 1]),
                (&self.select_pipeline, &self.select_group, [groups, 1]),
                (&self.blend_pipeline, &self.blend_group, [lm, lm]),
            ];
            for (i, (pipeline, bind, [x, y])) in passes.into_iter().enumerate() {
                let p = i + 1;
                let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
                    label: Some(PASS_NAMES[p]),
                    timestamp_writes: ts(p, true, true).map(|(t, p, _, _)| wgpu::ComputePassTimestampWrites {
                        query_set: &t.set,
                        beginning_of_pass_write_index: Some(2 * p as u32),
                        end_of_pass_write_index: Some(2 * p as u32 + 1),
                    }),
                });
                pass.set_pipeline(pipeline);
                pass.set_bind_group(0, bind, &[]);
                pass.dispatch_workgroups(x, y, 1);
                ran[p] = true;
            }
        }
        {
            let mut pass = enc.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("play_shade"),
                color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                    view: &self.color_view,
                    depth_slice: None,
                    resolve_target: None,
                    ops: wgpu::Operations {
                        load: wgpu::LoadOp::Clear(wgpu::Color::BLACK),
                        store: wgpu::StoreOp::Store,
                    },
                })],
                depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                    view: &self.depth_view,
                    depth_ops: Some(wgpu::Operations {
                        load: wgpu::LoadOp::Clear(1.0),
                        store: wgpu::StoreOp::Discard,
                    }),
                    stencil_ops: None,
                }),
                timestamp_writes: ts(5, true, true).map(|(t, p, _, _)| wgpu::RenderPassTimestampWrites {
                    query_set: &t.set,
                    beginning_of_pass_write_index: Some(2 * p as u32),
                    end_of_pass_write_index: Some(2 * p as u32 + 1),
                }),
                occlusion_query_set: None,
                multiview_mask: None,
            });
            pass.set_pipeline(&self.shade_pipeline);
            pass.set_bind_group(0, &self.shade_group, &[]);
            pass.set_vertex_buffer(0, self.vertices.slice(..));
            pass.draw(0..self.vertex_count, 0..1);
            ran[5] = true;
        }
        if let Some(t) = timestamps {
            for (p, _) in ran.iter().enumerate().filter(|(_, r)| **r) {
                let p = p as u32;
                enc.resolve_query_set(&t.set, 2 * p..2 * p + 2, &t.resolve, p as u64 * 256);
            }
            enc.copy_buffer_to_buffer(&t.resolve, 0, &t.read, 0, t.resolve.size());
        }
        queue.submit([enc.finish()]);
        self.ctx.wait()?;
        check(&self.ctx, scope, "frame")?;
        let cpu_ms = start.elapsed().as_secs_f64() * 1e3;
        let mut gpu_ms = Vec::new();
        if let Some(t) = timestamps {
            let bytes = self.ctx.read_buffer(&t.read)?;
            let period = queue.get_timestamp_period() as f64;
            for (p, _) in ran.iter().enumerate().filter(|(_, r)| **r) {
                let at = p * 256;
                let b: u64 = bytemuck::pod_read_unaligned(&bytes[at..at + 8]);
                let e: u64 = bytemuck::pod_read_unaligned(&bytes[at + 8..at + 16]);
                gpu_ms.push((PASS_NAMES[p], e.saturating_sub(b) as f64 * period * 1e-6));
            }
        }
        Ok(FrameTimings { cpu_ms, gpu_ms })
    }

    /// The last frame's image (linear radiance).
    pub fn read_image(&self) -> Result<Image, PlayError> {
        Ok(Image {
            width: self.opts.width,
            height: self.opts.height,
            rgb: read_texture_rgb(&self.ctx, &self.color)?,
        })
    }

    /// The last indirect-irradiance lightmap (texel (x, y) at `y·R + x`).
    pub fn read_lightmap(&self) -> Result<Vec<[f32; 3]>, PlayError> {
        read_texture_rgb(&self.ctx, &self.lightmap)
    }

    /// The last frame's cluster weights, scores, ranks and effective weights.
    pub fn read_weights(&self) -> Result<Vec<ClusterWeight>, PlayError> {
        let n = self.cluster_count as u64;
        if n == 0 {
            return Ok(Vec::new());
        }
        let w = read_storage(&self.ctx, &self.weights, n * 16)?;
        let e = read_storage(&self.ctx, &self.effective, n * 16)?;
        let w: &[[f32; 4]] = bytemuck::cast_slice(&w);
        let e: &[[f32; 4]] = bytemuck::cast_slice(&e);
        Ok(w.iter()
            .zip(e)
            .map(|(w, e)| ClusterWeight {
                weight: [w[0], w[1], w[2]],
                score: w[3],
                effective: [e[0], e[1], e[2]],
                rank: e[3] as u32,
            })
            .collect())
    }
}
