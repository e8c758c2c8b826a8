//! The VPL depth pass (`shaders/vpl_depth.wgsl`): the scene's depth through each hemicube face of
//! each VPL of a batch, faces tiled side by side in the layers of a depth texture array.
//!
//! Tiling matters on lavapipe: a render pass costs about 0.15 ms however little it draws, so one
//! pass per face made the depth maps cost as much as the shading; with a viewport per face, one
//! pass renders a whole layer of faces.
//!
//! Culling matters on big scenes: lavapipe's cost grows with the triangles a face is given, visible
//! or not. The scene's triangles are sorted along a Morton curve and cut into chunks of
//! [`CHUNK`]; each face draws only the chunks whose bounding spheres meet its frustum (tested on
//! the CPU), as short runs of consecutive chunks in one multi-draw-indirect call. (Pulling vertices
//! from a storage buffer through a chunk list instead cost more than the culling saved: lavapipe
//! reads storage buffers lane by lane, while vertex buffers take its fast fetch path.)

use std::mem::size_of;

use bytemuck::{Pod, Zeroable};
use prm_gpu_kit::pipeline;

/// The hemicube faces and the VPL struct (`shaders/hemicube.wgsl`), shared by the depth and the
/// gather pass.
pub const HEMICUBE_WGSL: &str = include_str!("../../../shaders/hemicube.wgsl");
/// The depth pass (`shaders/vpl_depth.wgsl`); needs [`HEMICUBE_WGSL`] before it.
pub const VPL_DEPTH_WGSL: &str = include_str!("../../../shaders/vpl_depth.wgsl");

/// A VPL as the GPU sees it; `Vpl` in `hemicube.wgsl`.
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

/// Near/far planes and the lift of the VPL off its surface; `DepthFrame` in `vpl_depth.wgsl`.
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

/// Which face of which VPL a depth layer's draws render; `FaceSelect` in `vpl_depth.wgsl`, one
/// per uniform slot (bound with a dynamic offset).
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct FaceSelect {
    /// VPL of the batch.
    pub vpl: u32,
    /// Hemicube face (0: along the normal; 1–4: +t, −t, +b, −b).
    pub face: u32,
    /// Padding.
    pub _pad0: u32,
    /// Padding.
    pub _pad1: u32,
}

/// Faces per VPL (hemicube); `HEMICUBE_FACES` in `hemicube.wgsl`.
pub const FACES: u32 = 5;
/// Triangles per culling chunk.
pub const CHUNK: u32 = 32;
/// Side of a depth layer in texels (faces are tiled into layers of this size).
const LAYER_SIDE: u32 = 4096;
/// Chunks a draw may hold at most. lavapipe's clipper resets every vertex of a draw each time
/// its buffer of clipped triangles fills, a cost quadratic in the draw's size: on Sibenik a face
/// took 9.5 ms in runs of any length, 5.2 ms in draws of at most 2 chunks, 6.2 ms with 1.
const MAX_DRAW_CHUNKS: u32 = 2;

/// The scene's triangles in culling order: Morton-sorted, padded with empty triangles to whole
/// chunks, with a bounding sphere per chunk.
pub struct ChunkedScene {
    /// Vertex positions, three per triangle, `w` unused.
    pub vertices: Vec<[f32; 4]>,
    /// Bounding sphere of each chunk: centre and radius.
    pub spheres: Vec<[f32; 4]>,
}

impl ChunkedScene {
    /// Chunks `triangles` (three positions each).
    pub fn new(triangles: &[[glam::Vec3; 3]]) -> ChunkedScene {
        let (lo, hi) = triangles.iter().flatten().fold(
            (glam::Vec3::splat(f32::INFINITY), glam::Vec3::splat(f32::NEG_INFINITY)),
            |(lo, hi), p| (lo.min(*p), hi.max(*p)),
        );
        let scale = 1023.0 / (hi - lo).max_element().max(1e-30);
        let spread = |v: u32| {
            // Interleave the 10 bits of v with two zero bits each.
            let mut x = v & 0x3ff;
            x = (x | (x << 16)) & 0x030000ff;
            x = (x | (x << 8)) & 0x0300f00f;
            x = (x | (x << 4)) & 0x030c30c3;
            (x | (x << 2)) & 0x09249249
        };
        let mut order: Vec<(u32, u32)> = triangles
            .iter()
            .enumerate()
            .map(|(i, t)| {
                let c = ((t[0] + t[1] + t[2]) / 3.0 - lo) * scale;
                let q = c.clamp(glam::Vec3::ZERO, glam::Vec3::splat(1023.0)).as_uvec3();
                (spread(q.x) | (spread(q.y) << 1) | (spread(q.z) << 2), i as u32)
            })
            .collect();
        order.sort_unstable();
        let chunks = triangles.len().div_ceil(CHUNK as usize);
        let mut vertices = Vec::with_capacity(chunks * CHUNK as usize * 3);
        let mut spheres = Vec::with_capacity(chunks);
        for chunk in order.chunks(CHUNK as usize) {
            let (mut a, mut b) = (glam::Vec3::splat(f32::INFINITY), glam::Vec3::splat(f32::NEG_INFINITY));
            for &(_, i) in chunk {
                for p in triangles[i as usize] {
                    (a, b) = (a.min(p), b.max(p));
                    vertices.push(p.extend(1.0).to_array());
                }
            }
            let centre = (a + b) * 0.5;
            let radius = chunk
                .iter()
                .flat_map(|&(_, i)| triangles[i as usize])
                .map(|p| p.distance(centre))
                .fold(0.0f32, f32::max);
            // Pad the last chunk with empty triangles at its centre: they cover no sample.
            for _ in chunk.len()..CHUNK as usize {
                vertices.extend([centre.extend(1.0).to_array(); 3]);
            }
            spheres.push(centre.extend(radius * 1.0001 + 1e-30).to_array());
        }
        ChunkedScene { vertices, spheres }
    }

    /// Chunks.
    pub fn chunks(&self) -> usize {
        self.spheres.len()
    }

    /// Appends to `out` the chunks that can show in face `face` of `vpl`, whose hemicube origin
    /// is lifted `lift` off its surface.
    pub fn cull(&self, vpl: &GpuVpl, lift: f32, face: u32, out: &mut Vec<u32>) {
        let n = glam::Vec3::from(vpl.normal);
        let (t, b) = (glam::Vec3::from(vpl.tangent), glam::Vec3::from(vpl.bitangent));
        let origin = glam::Vec3::from(vpl.position) + n * lift;
        // Half-spaces p · l >= 0 bounding the face in the local frame (x, y, z) = (t, b, n); side
        // faces keep their upper half only (see hemicube.wgsl).
        const H: f32 = std::f32::consts::FRAC_1_SQRT_2;
        let planes: [[f32; 3]; 4] = match face {
            0 => [[-H, 0.0, H], [H, 0.0, H], [0.0, -H, H], [0.0, H, H]],
            1 => [[H, -H, 0.0], [H, H, 0.0], [0.0, 0.0, 1.0], [H, 0.0, -H]],
            2 => [[-H, -H, 0.0], [-H, H, 0.0], [0.0, 0.0, 1.0], [-H, 0.0, -H]],
            3 => [[-H, H, 0.0], [H, H, 0.0], [0.0, 0.0, 1.0], [0.0, H, -H]],
            _ => [[-H, -H, 0.0], [H, -H, 0.0], [0.0, 0.0, 1.0], [0.0, -H, -H]],
        };
        for (k, s) in self.spheres.iter().enumerate() {
            let d = glam::Vec3::new(s[0], s[1], s[2]) - origin;
            let l = glam::Vec3::new(d.dot(t), d.dot(b), d.dot(n));
            if planes.iter().all(|p| glam::Vec3::from(*p).dot(l) >= -s[3]) {
                out.push(k as u32);
            }
        }
    }
}
/// Depth format of the face layers.
pub const DEPTH_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;

/// Pipeline and per-layer state of the depth pass for batches of up to `capacity` VPLs.
pub struct VplDepthPass {
    pipeline: wgpu::RenderPipeline,
    indirect: wgpu::Buffer,
    visible: Vec<u32>,
    draws: Vec<[u32; 4]>,
    spans: Vec<(u32, u32)>,
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
        scene: &ChunkedScene,
    ) -> VplDepthPass {
        let indirect = draw_buffer(device, capacity, scene);
        let vertex = wgpu::ShaderStages::VERTEX;
        let frame_layout = pipeline::bind_group_layout(
            device,
            "vpl_depth frame",
            &[
                pipeline::storage_entry(0, vertex, true),
                pipeline::uniform_entry(1, vertex),
            ],
        );
        let face_layout = pipeline::dynamic_uniform_layout(device, "vpl_depth face", size_of::<FaceSelect>() as u64);
        let pipeline = depth_pipeline(device, &frame_layout, &face_layout);
        let frame_group = pipeline::bind_group(
            device,
            "vpl_depth frame",
            &frame_layout,
            &[vpls.as_entire_binding(), frame.as_entire_binding()],
        );
        let layers = capacity * FACES;
        let (face_group, face_stride) = face_selectors(device, &face_layout, layers);
        let tiles = DepthTiles::new(device, layers, resolution);
        VplDepthPass {
            pipeline,
            indirect,
            visible: Vec::new(),
            draws: Vec::new(),
            spans: Vec::new(),
            frame_group,
            face_group,
            face_stride,
            layer_views: tiles.layer_views,
            array_view: tiles.array_view,
            resolution,
            faces_per_row: tiles.faces_per_row,
        }
    }

    /// Records the depth of the scene (`vertices`, the [`ChunkedScene`]'s, in a vertex buffer) for
    /// the VPLs of the batch (`batch`, as uploaded to the batch buffer): face `i` (VPL `i / 5`,
    /// face `i % 5`) goes to layer `i / per_layer`, tile `i % per_layer` (row-major,
    /// `faces_per_row` to a row). Culls on the CPU and writes the draws through `queue`, so submit
    /// `encoder` before recording another batch. Returns the triangles and the draws issued.
    pub fn encode(
        &mut self,
        encoder: &mut wgpu::CommandEncoder,
        queue: &wgpu::Queue,
        scene: &ChunkedScene,
        vertices: &wgpu::Buffer,
        lift: f32,
        batch: &[GpuVpl],
    ) -> (u64, u64) {
        const CHUNK_VERTICES: u32 = CHUNK * 3;
        self.draws.clear();
        self.spans.clear();
        let mut triangles = 0u64;
        for v in batch {
            for f in 0..FACES {
                self.visible.clear();
                scene.cull(v, lift, f, &mut self.visible);
                let start = self.draws.len() as u32;
                // Runs of consecutive chunks, one indirect draw each: [vertices, 1, first, 0].
                for &c in &self.visible {
                    let open = self.draws.len() as u32 > start;
                    let first = c * CHUNK_VERTICES;
                    match self.draws.last_mut() {
                        Some(d) if open && d[2] + d[0] == first && d[0] < MAX_DRAW_CHUNKS * CHUNK_VERTICES => {
                            d[0] += CHUNK_VERTICES
                        }
                        _ => self.draws.push([CHUNK_VERTICES, 1, first, 0]),
                    }
                }
                triangles += self.draws[start as usize..]
                    .iter()
                    .map(|d| d[0] as u64 / 3)
                    .sum::<u64>();
                self.spans.push((start, self.draws.len() as u32 - start));
            }
        }
        if !self.draws.is_empty() {
            queue.write_buffer(&self.indirect, 0, bytemuck::cast_slice(&self.draws));
        }
        let vpls = batch.len() as u32;
        let faces = vpls * FACES;
        let per_layer = self.faces_per_row * self.faces_per_row;
        let res = self.resolution;
        for (layer, view) in self
            .layer_views
            .iter()
            .enumerate()
            .take(faces.div_ceil(per_layer) as usize)
        {
            let mut pass = pipeline::begin_render_pass(encoder, "vpl_depth", None, Some((view, true)), None);
            pass.set_pipeline(&self.pipeline);
            pass.set_bind_group(0, &self.frame_group, &[]);
            pass.set_vertex_buffer(0, vertices.slice(..));
            let first = layer as u32 * per_layer;
            for face in first..(first + per_layer).min(faces) {
                let slot = face - first;
                let (x, y) = ((slot % self.faces_per_row) * res, (slot / self.faces_per_row) * res);
                pass.set_viewport(x as f32, y as f32, res as f32, res as f32, 0.0, 1.0);
                pass.set_scissor_rect(x, y, res, res);
                let (start, count) = self.spans[face as usize];
                if count > 0 {
                    pass.set_bind_group(1, &self.face_group, &[face * self.face_stride]);
                    pass.multi_draw_indirect(&self.indirect, 16 * start as u64, count);
                }
            }
        }
        (triangles, self.draws.len() as u64)
    }
}

/// The indirect draws of a batch of `capacity` VPLs: runs of visible chunks per face, at worst
/// every other chunk starting a run.
fn draw_buffer(device: &wgpu::Device, capacity: u32, scene: &ChunkedScene) -> wgpu::Buffer {
    let runs_capacity = (capacity as u64 * FACES as u64 * scene.chunks().div_ceil(2) as u64).max(1);
    let usage = wgpu::BufferUsages::INDIRECT | wgpu::BufferUsages::COPY_DST;
    pipeline::buffer(device, "vpl_depth draws", 16 * runs_capacity, usage)
}

/// The depth-only pipeline over the scene's vertex buffer, with the frame (group 0) and the
/// face selector (group 1, dynamic offset) bound. No raster bias: the gather pass biases
/// distances in scene units.
fn depth_pipeline(
    device: &wgpu::Device,
    frame_layout: &wgpu::BindGroupLayout,
    face_layout: &wgpu::BindGroupLayout,
) -> wgpu::RenderPipeline {
    pipeline::depth_only(
        device,
        "vpl_depth",
        &[HEMICUBE_WGSL, VPL_DEPTH_WGSL],
        &[frame_layout, face_layout],
        16,
        DEPTH_FORMAT,
    )
}

/// The face selectors of `layers` depth faces, one aligned uniform slot each (face `j·5 + f`
/// reads VPL `j`, face `f`), bound at a dynamic offset; and the slots' stride.
fn face_selectors(device: &wgpu::Device, layout: &wgpu::BindGroupLayout, layers: u32) -> (wgpu::BindGroup, u32) {
    let face_stride = device.limits().min_uniform_buffer_offset_alignment.max(16);
    let mut faces = vec![0u8; (layers * face_stride) as usize];
    for layer in 0..layers {
        let sel = FaceSelect {
            vpl: layer / FACES,
            face: layer % FACES,
            _pad0: 0,
            _pad1: 0,
        };
        let at = (layer * face_stride) as usize;
        faces[at..at + size_of::<FaceSelect>()].copy_from_slice(bytemuck::bytes_of(&sel));
    }
    let face_buffer = pipeline::buffer_init(device, "vpl_depth faces", &faces, wgpu::BufferUsages::UNIFORM);
    let resource = wgpu::BindingResource::Buffer(wgpu::BufferBinding {
        buffer: &face_buffer,
        offset: 0,
        size: wgpu::BufferSize::new(size_of::<FaceSelect>() as u64),
    });
    let group = pipeline::bind_group(device, "vpl_depth face", layout, &[resource]);
    (group, face_stride)
}

/// The depth texture array the faces are tiled into.
struct DepthTiles {
    /// One view per layer, to render into.
    layer_views: Vec<wgpu::TextureView>,
    /// All layers, for sampling.
    array_view: wgpu::TextureView,
    /// Faces on a row of a layer.
    faces_per_row: u32,
}

impl DepthTiles {
    /// Layers of [`LAYER_SIDE`]² texels (or the device's largest side) for `faces` faces of
    /// `resolution`² texels.
    fn new(device: &wgpu::Device, faces: u32, resolution: u32) -> DepthTiles {
        let faces_per_row = (LAYER_SIDE.min(device.limits().max_texture_dimension_2d) / resolution).max(1);
        let per_layer = faces_per_row * faces_per_row;
        let side = faces_per_row * resolution;
        let layers = faces.div_ceil(per_layer);
        let (array_view, layer_views) =
            pipeline::layered_target(device, "vpl_depth layers", [side, side, layers], DEPTH_FORMAT);
        DepthTiles {
            layer_views,
            array_view,
            faces_per_row,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;
    use prm_gpu_kit::layout::check_consts;
    use prm_gpu_kit::wgsl_layout;

    #[test]
    fn rust_structs_match_the_shaders() {
        let s = [HEMICUBE_WGSL, VPL_DEPTH_WGSL].join("\n");
        wgsl_layout!(
            &s,
            GpuVpl,
            "Vpl",
            [position, area, normal, cluster, power, _pad0, tangent, _pad1, bitangent, _pad2]
        )
        .unwrap();
        wgsl_layout!(&s, DepthFrame, "DepthFrame", [near, far, lift, _pad]).unwrap();
        wgsl_layout!(&s, FaceSelect, "FaceSelect", [vpl, face, _pad0, _pad1]).unwrap();
        check_consts(&s, &[("HEMICUBE_FACES", FACES as i64)]).unwrap();
    }

    /// Local coordinates of `p` in the hemicube frame of `v` and the face that sees them, as
    /// `hemicube.wgsl` decides (None below the VPL's horizon).
    fn face_of(v: &GpuVpl, lift: f32, p: Vec3) -> Option<u32> {
        let n = Vec3::from(v.normal);
        let d = p - (Vec3::from(v.position) + n * lift);
        let l = Vec3::new(d.dot(Vec3::from(v.tangent)), d.dot(Vec3::from(v.bitangent)), d.dot(n));
        let a = l.abs();
        if l.z < 0.0 {
            None
        } else if l.z >= a.x && l.z >= a.y {
            Some(0)
        } else if a.x >= a.y {
            Some(if l.x > 0.0 { 1 } else { 2 })
        } else {
            Some(if l.y > 0.0 { 3 } else { 4 })
        }
    }

    #[test]
    fn culling_keeps_every_chunk_a_face_can_see() {
        // A cloud of small random triangles; every vertex a face sees must be in a kept chunk.
        let mut seed = 0x2545_f491_4f6c_dd1du64;
        let mut rand = || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 40) as f32 / (1u64 << 24) as f32
        };
        let mut tris = Vec::new();
        for _ in 0..2000 {
            let c = Vec3::new(rand(), rand(), rand()) * 10.0 - 5.0;
            let mut r = || Vec3::new(rand(), rand(), rand()) * 0.6 - 0.3;
            tris.push([c + r(), c + r(), c + r()]);
        }
        let chunked = ChunkedScene::new(&tris);
        assert_eq!(chunked.vertices.len(), chunked.chunks() * CHUNK as usize * 3);
        let mut kept_total = 0;
        for _ in 0..50 {
            let n = (Vec3::new(rand(), rand(), rand()) - 0.5).normalize();
            let p = Vec3::new(rand(), rand(), rand()) * 10.0 - 5.0;
            let v = GpuVpl::new(p, n, Vec3::ONE, 0.01, 0);
            for f in 0..FACES {
                let mut kept = Vec::new();
                chunked.cull(&v, 1e-3, f, &mut kept);
                kept_total += kept.len();
                for (k, vertex) in chunked.vertices.iter().enumerate() {
                    let q = Vec3::new(vertex[0], vertex[1], vertex[2]);
                    if face_of(&v, 1e-3, q) == Some(f) {
                        let chunk = (k / (CHUNK as usize * 3)) as u32;
                        assert!(kept.contains(&chunk), "face {f} sees chunk {chunk} but culled it");
                    }
                }
            }
        }
        // And it culls: a face sees well under half of a cloud around it.
        let fraction = kept_total as f64 / (50.0 * FACES as f64 * chunked.chunks() as f64);
        assert!(fraction < 0.6, "kept {fraction:.2} of the chunks per face");
    }
}
