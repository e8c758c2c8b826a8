//! The probe sphere (`shaders/play/sphere.wgsl`): a moving object lit from the run time's probe
//! volume (its indirect light) and its shadow maps (its direct light), drawn inside the shade
//! pass. It shows what an engine does with [`prm_runtime::Runtime::probes`] for its dynamic
//! objects.

use glam::Vec3;
use prm_gpu_kit::{pipeline, GpuContext};
use prm_runtime::Runtime;
use prm_scene::Aabb;

use crate::gpu::{GpuSphere, SphereVertex};
use crate::shade::{CAMERA_WGSL, COLOR_FORMAT, DEPTH_FORMAT};

/// Rings of latitude and segments of longitude of the sphere's mesh.
const RINGS: u32 = 24;
const SEGMENTS: u32 = 48;

/// A sphere in the scene.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ProbeSphere {
    /// Centre.
    pub centre: Vec3,
    /// Radius.
    pub radius: f32,
    /// Diffuse albedo.
    pub albedo: Vec3,
}

impl ProbeSphere {
    /// Seconds per turn of [`ProbeSphere::orbit`].
    pub const ORBIT_PERIOD_S: f32 = 8.0;

    /// The `--probe-sphere` path: a light grey sphere of 6% of the bounds' smallest side,
    /// circling the bounds' vertical axis at a third of their height, on a circle of 30% of
    /// their smaller horizontal side, one turn per [`ProbeSphere::ORBIT_PERIOD_S`]; at time `t`.
    pub fn orbit(bounds: &Aabb, t: f32) -> ProbeSphere {
        let e = bounds.extent();
        let centre = (bounds.min + bounds.max) * 0.5;
        let r = 0.3 * e.x.min(e.z);
        let a = std::f32::consts::TAU * t / Self::ORBIT_PERIOD_S;
        ProbeSphere {
            centre: Vec3::new(centre.x + r * a.cos(), bounds.min.y + e.y / 3.0, centre.z + r * a.sin()),
            radius: 0.06 * e.min_element().max(e.max_element() * 0.05),
            albedo: Vec3::splat(0.8),
        }
    }
}

/// The sphere pass source: the run time's shared structs, direct light and probe volume, the
/// camera, then the pass.
pub fn source() -> [&'static str; 6] {
    [
        prm_runtime::SHARED_WGSL,
        prm_runtime::LIGHT_BINDINGS_WGSL,
        prm_runtime::LIGHTS_WGSL,
        prm_runtime::PROBES_WGSL,
        CAMERA_WGSL,
        include_str!("../../../shaders/play/sphere.wgsl"),
    ]
}

/// Draws the probe sphere.
pub struct SpherePass {
    pipeline: wgpu::RenderPipeline,
    bind_group: wgpu::BindGroup,
    uniform: wgpu::Buffer,
    vertices: wgpu::Buffer,
    vertex_count: u32,
}

/// The unit sphere as a list of triangles.
fn mesh() -> Vec<SphereVertex> {
    let point = |ring: u32, seg: u32| {
        let theta = std::f32::consts::PI * ring as f32 / RINGS as f32;
        let phi = std::f32::consts::TAU * seg as f32 / SEGMENTS as f32;
        SphereVertex {
            unit: [theta.sin() * phi.sin(), theta.cos(), theta.sin() * phi.cos()],
        }
    };
    let mut out = Vec::with_capacity((RINGS * SEGMENTS * 6) as usize);
    for ring in 0..RINGS {
        for seg in 0..SEGMENTS {
            let (a, b) = (point(ring, seg), point(ring + 1, seg));
            let (c, d) = (point(ring + 1, seg + 1), point(ring, seg + 1));
            out.extend([a, b, c, a, c, d]);
        }
    }
    out
}

impl SpherePass {
    /// The pass on `runtime`'s lights, shadow maps and probe volume, with the shade pass's
    /// `camera`; `None` when the archive has no probes.
    pub fn new(ctx: &GpuContext, runtime: &Runtime, camera: &wgpu::Buffer) -> Option<SpherePass> {
        runtime.probes()?;
        let device = &ctx.device;
        let vertices = mesh();
        let uniform = pipeline::uniform(device, "play sphere", std::mem::size_of::<GpuSphere>() as u64);
        let pipeline =
            pipeline::mesh::<SphereVertex>(device, "play sphere", &source(), Some(DEPTH_FORMAT), Some(COLOR_FORMAT));
        let bind_group = Self::group(ctx, &pipeline, runtime, camera, &uniform)?;
        Some(SpherePass {
            pipeline,
            bind_group,
            uniform,
            vertex_count: vertices.len() as u32,
            vertices: pipeline::vertex_buffer(device, "play sphere vertices", &vertices),
        })
    }

    fn group(
        ctx: &GpuContext,
        pipeline: &wgpu::RenderPipeline,
        runtime: &Runtime,
        camera: &wgpu::Buffer,
        uniform: &wgpu::Buffer,
    ) -> Option<wgpu::BindGroup> {
        let d = runtime.direct_light_bindings();
        let probes = runtime.probes()?;
        Some(pipeline::bind_group(
            &ctx.device,
            "play sphere",
            &pipeline.get_bind_group_layout(0),
            &[
                &d.resources()[..],
                &[camera.as_entire_binding(), uniform.as_entire_binding()],
                &probes.resources()[..],
            ]
            .concat(),
        ))
    }

    /// Binds the pass again after the run time's shadow maps grew.
    pub fn rebind(&mut self, ctx: &GpuContext, runtime: &Runtime, camera: &wgpu::Buffer) {
        if let Some(g) = Self::group(ctx, &self.pipeline, runtime, camera, &self.uniform) {
            self.bind_group = g;
        }
    }

    /// Uploads the sphere's place and colour.
    pub fn write(&self, queue: &wgpu::Queue, s: &ProbeSphere) {
        let gpu = GpuSphere {
            centre: s.centre.to_array(),
            radius: s.radius,
            albedo: s.albedo.to_array(),
            _pad0: 0.0,
        };
        queue.write_buffer(&self.uniform, 0, bytemuck::bytes_of(&gpu));
    }

    /// Draws the sphere in `pass` (the shade pass, whose depth buffer it shares).
    pub fn draw(&self, pass: &mut wgpu::RenderPass<'_>) {
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, &self.bind_group, &[]);
        pass.set_vertex_buffer(0, self.vertices.slice(..));
        pass.draw(0..self.vertex_count, 0..1);
    }
}
