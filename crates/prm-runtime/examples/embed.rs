//! Embedding prm-runtime in a wgpu program of one's own (with a few helpers of prm-gpu-kit for
//! wgpu's longer descriptors): open a device, load an archive and its scene, run one frame of the run time headless, shade it with a few lines of WGSL (albedo/π ×
//! (direct + indirect irradiance)) and write a PNG.
//!
//! `cargo run -p prm-runtime --example embed -- ARCHIVE.prm [OUT.png]`
//!
//! The scene is the archive's `source_scene`; the light is the scene's first, else a point light
//! under the top of its bounds. Fails when the frame has no finite, non-black indirect light.
//! `cargo test` runs it too (`test = true` in Cargo.toml), on a synthetic archive of the
//! bundled Cornell box.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use glam::{Mat4, Vec3};
use prm_gpu_kit::pipeline as kit;
use prm_runtime::{
    look_to, perspective, Runtime, RuntimeOptions, Shadows, LIGHTS_WGSL, LIGHT_BINDINGS_WGSL, SHARED_WGSL,
};
use wgpu::util::DeviceExt;

const SIZE: u32 = 256;

/// The shading: after the run time's structs, its direct light's bindings (0 to 3) and direct
/// light, a camera and the lightmap.
const SHADE: &str = r#"
@group(0) @binding(4) var lightmap: texture_2d<f32>;
@group(0) @binding(5) var<uniform> view_proj: mat4x4<f32>;

struct Out {
    @builtin(position) clip: vec4<f32>,
    @location(0) position: vec3<f32>,
    @location(1) normal: vec3<f32>,
    @location(2) lightmap_uv: vec2<f32>,
    @location(3) albedo: vec3<f32>,
};

@vertex
fn vs_main(@location(0) p: vec3<f32>, @location(1) n: vec3<f32>, @location(2) uv: vec2<f32>, @location(3) a: vec3<f32>) -> Out {
    return Out(view_proj * vec4<f32>(p, 1.0), p, n, uv, a);
}

@fragment
fn fs_main(v: Out) -> @location(0) vec4<f32> {
    let size = vec2<f32>(textureDimensions(lightmap));
    let indirect = textureLoad(lightmap, vec2<i32>(v.lightmap_uv * size), 0).rgb;
    let direct = direct_irradiance(v.position, normalize(v.normal));
    let radiance = v.albedo / 3.14159265 * (direct + indirect);
    // Reinhard and a display gamma: enough for a look.
    return vec4<f32>(pow(radiance / (1.0 + radiance), vec3<f32>(1.0 / 2.2)), 1.0);
}
"#;

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct Vertex {
    position: [f32; 3],
    normal: [f32; 3],
    lightmap_uv: [f32; 2],
    albedo: [f32; 3],
}

impl kit::Vertex for Vertex {
    const ATTRIBUTES: &'static [wgpu::VertexAttribute] =
        &wgpu::vertex_attr_array![0 => Float32x3, 1 => Float32x3, 2 => Float32x2, 3 => Float32x3];
}

fn main() -> std::process::ExitCode {
    // Headless: no stray "XDG_RUNTIME_DIR is invalid" lines from wgpu's window-system probe.
    prm_gpu_kit::silence_wayland_probe();
    let args: Vec<PathBuf> = std::env::args_os().skip(1).map(PathBuf::from).collect();
    let Some(archive_path) = args.first() else {
        eprintln!("usage: embed ARCHIVE.prm [OUT.png]");
        return std::process::ExitCode::from(2);
    };
    let out = args.get(1).cloned().unwrap_or_else(|| PathBuf::from("embed.png"));
    match run(archive_path, &out) {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            std::process::ExitCode::FAILURE
        }
    }
}

/// Plays `archive_path` for one frame and writes the shaded image to `out`.
fn run(archive_path: &Path, out: &Path) -> Result<()> {
    // The caller's device: any adapter wgpu finds.
    let instance = wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle());
    let adapter = pollster::block_on(instance.request_adapter(&Default::default())).context("no GPU adapter")?;
    let (device, queue) = pollster::block_on(adapter.request_device(&Default::default()))?;

    // The archive and the scene it was baked for.
    let mut archive = prm_format::Archive::open(archive_path).with_context(|| format!("{}", archive_path.display()))?;
    let dir = archive_path.parent().unwrap_or(Path::new("."));
    let scene_path = dir.join(&archive.metadata().source_scene);
    let scene = prm_scene::load(&scene_path).with_context(|| format!("{}", scene_path.display()))?;
    let options = RuntimeOptions::for_archive(&archive);
    let mut runtime = Runtime::new(&device, &queue, &mut archive, &scene, options)?;

    // One frame of the run time.
    let b = scene.bounds();
    let light = scene.lights.first().copied().unwrap_or(prm_scene::Light::Point {
        position: Vec3::new(
            (b.min.x + b.max.x) * 0.5,
            b.max.y - 0.25 * b.extent().y,
            (b.min.z + b.max.z) * 0.5,
        ),
        intensity: Vec3::splat((b.diagonal() * 0.5).powi(2)),
    });
    runtime.update(&[light])?;
    let mut encoder = device.create_command_encoder(&Default::default());
    runtime.encode(&mut encoder, Shadows::Own, None);

    // Our own shading of it.
    let vertices: Vec<Vertex> = scene
        .triangles
        .iter()
        .zip(runtime.lightmap_uvs())
        .flat_map(|(t, uv)| {
            let albedo = scene.materials[t.material as usize].albedo.to_array();
            (0..3).map(move |i| Vertex {
                position: t.positions[i].to_array(),
                normal: t.normals[i].to_array(),
                lightmap_uv: uv[i],
                albedo,
            })
        })
        .collect();
    let vertex_buffer = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: None,
        contents: bytemuck::cast_slice(&vertices),
        usage: wgpu::BufferUsages::VERTEX,
    });
    // The scene's first camera, else a view of the bounds from +Z.
    let centre = (b.min + b.max) * 0.5;
    let (eye, target, fov) = scene
        .cameras
        .first()
        .map_or((centre + Vec3::new(0.0, 0.0, b.diagonal() * 1.2), centre, 45.0), |c| {
            (c.eye, c.target, c.fov_y_deg)
        });
    // The run time's helpers give wgpu's conventions: right-handed, z in [0, 1], y up.
    let camera: Mat4 =
        perspective(fov.to_radians(), 1.0, 0.01, b.diagonal() * 4.0) * look_to(eye, target - eye, Vec3::Y);
    let camera_buffer = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: None,
        contents: bytemuck::cast_slice(&camera.to_cols_array()),
        usage: wgpu::BufferUsages::UNIFORM,
    });
    let format = wgpu::TextureFormat::Rgba8Unorm;
    let depth_format = wgpu::TextureFormat::Depth32Float;
    let parts = [SHARED_WGSL, LIGHT_BINDINGS_WGSL, LIGHTS_WGSL, SHADE];
    let pipeline = kit::mesh::<Vertex>(&device, "embed", &parts, Some(depth_format), Some(format));
    let d = runtime.direct_light_bindings();
    let own = [
        wgpu::BindingResource::TextureView(runtime.lightmap()),
        camera_buffer.as_entire_binding(),
    ];
    let resources = [&d.resources()[..], &own].concat();
    let bind_group = kit::bind_group(&device, "embed", &pipeline.get_bind_group_layout(0), &resources);
    let target = |format, usage| kit::texture(&device, "embed", [SIZE, SIZE, 1], format, usage);
    let color = target(
        format,
        wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
    );
    let depth = target(depth_format, wgpu::TextureUsages::RENDER_ATTACHMENT);
    {
        let color_view = color.create_view(&Default::default());
        let depth_view = depth.create_view(&Default::default());
        let mut pass = kit::begin_render_pass(
            &mut encoder,
            "embed",
            Some(&color_view),
            Some((&depth_view, false)),
            None,
        );
        pass.set_pipeline(&pipeline);
        pass.set_bind_group(0, &bind_group, &[]);
        pass.set_vertex_buffer(0, vertex_buffer.slice(..));
        pass.draw(0..vertices.len() as u32, 0..1);
    }
    queue.submit([encoder.finish()]);
    let pixels = prm_gpu_kit::readback::read_texture(&device, &queue, &color, 0)?;
    image::save_buffer(out, &pixels, SIZE, SIZE, image::ExtendedColorType::Rgba8)
        .with_context(|| format!("write {}", out.display()))?;

    // The check: the run time's indirect light is finite and not black.
    let lightmap = runtime.read_lightmap()?;
    let total: f64 = lightmap.iter().flatten().map(|&v| v as f64).sum();
    if !total.is_finite() || total <= 0.0 {
        bail!("the indirect lightmap sums to {total}: nothing was blended");
    }
    println!(
        "embed: {} ({} clusters, {}² lightmap, indirect sum {total:.3}) → {}",
        archive_path.display(),
        runtime.cluster_count(),
        runtime.lightmap_resolution(),
        out.display()
    );
    Ok(())
}

#[test]
fn embeds_a_synthetic_archive_of_the_cornell_box() {
    use prm_runtime::synthetic::{cornell_box_path, write_archive, SyntheticParams};
    let dir = std::env::temp_dir().join(format!("prm-embed-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let scene_path = cornell_box_path();
    let scene = prm_scene::load(&scene_path).unwrap();
    let archive = dir.join("cornell.prm");
    write_archive(&scene, &scene_path, &archive, SyntheticParams::default()).unwrap();
    let out = dir.join("embed.png");
    run(&archive, &out).unwrap();
    let image = image::open(&out).unwrap().to_rgb8();
    assert!(image.pixels().any(|p| p.0 != [0, 0, 0]), "the image is black");
}
