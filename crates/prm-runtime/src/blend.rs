//! The blend pass (`shaders/runtime/blend.wgsl`) and the panes it reads: Σ over the kept
//! clusters and the residual groups of effective weight × pane, plus the emitters' and the near
//! field's lightmaps, into the indirect-irradiance lightmap, one invocation per four lit texels.
//!
//! The panes live in storage buffers of RGB9E5 words, decoded in the shader, in the atlas's
//! row-major texel order grouped by four (a *quad*: texels `4q..4q + 3`, one `vec4<u32>`): a
//! *chunk* holds, for a range of quads, every pane's words of those quads (pane `p`'s quad `q`
//! at `p × quads + (q − first)`), as many quads as keep the chunk within the device's storage
//! binding (128 MiB on lavapipe), and the pass dispatches once per chunk over the quads it
//! lights. So the pane count is bounded by memory only, not by `max_texture_array_layers`
//! (2048 on lavapipe, which would refuse an unclustered bake of 4096 entry points).
//!
//! Measured on lavapipe (McGuire's CornellBox-Original, its default archive, 512 clusters, K =
//! 128 + 64 groups; `prm-play --headless --size 1024x768 --frames 12 --timings --gi-update every-frame`, medians,
//! the three builds interleaved): the `gi` frame took 86–102 ms (direct light alone 29 ms) with
//! the panes in an `rgb9e5ufloat` texture array read one texel per invocation, 65–74 ms with the
//! array read four texels per invocation, and **54–64 ms** as here: the blend itself about 17 ms
//! against about 50 ms. Four texels share each kept cluster's weight load and come in one
//! 16-byte load; eight per invocation were no faster (62–67 ms).

use prm_gpu_kit::{linear_workgroups, pipeline, ComputePass, PassTimer};

use crate::{Buffers, GpuBlendChunk, RuntimeError};

/// Texels per quad: one `vec4<u32>` of RGB9E5 words, one invocation of the blend.
const QUAD: usize = 4;

/// The panes as the blend reads them: chunks of quads, each a storage buffer.
pub(crate) struct Panes {
    /// One buffer per chunk.
    chunks: Vec<wgpu::Buffer>,
    /// Quads per chunk (the last may hold fewer).
    quads_per_chunk: usize,
    /// Quads in the atlas.
    quads: usize,
    /// Panes (clusters, then the residual groups' summed panes).
    layers: usize,
}

impl Panes {
    /// Buffers for `layers` panes of `texels` texels each, in chunks the device can bind and
    /// of at most `cap` bytes when given.
    pub fn new(device: &wgpu::Device, layers: usize, texels: usize, cap: Option<u64>) -> Result<Panes, RuntimeError> {
        let limits = device.limits();
        let binding = limits
            .max_storage_buffer_binding_size
            .min(limits.max_buffer_size)
            .min(cap.unwrap_or(u64::MAX));
        let quad_bytes = (layers * QUAD * 4) as u64;
        let quads = texels.div_ceil(QUAD);
        if quad_bytes > binding {
            return Err(RuntimeError::TooManyPanes {
                panes: layers,
                max: (binding / (QUAD as u64 * 4)) as u32,
            });
        }
        let quads_per_chunk = ((binding / quad_bytes) as usize).min(quads).max(1);
        let chunks = (0..quads.div_ceil(quads_per_chunk))
            .map(|c| {
                let n = quads_per_chunk.min(quads - c * quads_per_chunk);
                pipeline::storage(
                    device,
                    "prm panes",
                    (layers * n * QUAD * 4) as u64,
                    wgpu::BufferUsages::COPY_DST,
                )
            })
            .collect();
        Ok(Panes {
            chunks,
            quads_per_chunk,
            quads,
            layers,
        })
    }

    /// Quads in chunk `c`.
    fn chunk_quads(&self, c: usize) -> usize {
        self.quads_per_chunk.min(self.quads - c * self.quads_per_chunk)
    }

    /// Uploads pane `layer` (RGB9E5 words, row-major texels).
    pub fn write(&self, queue: &wgpu::Queue, layer: u32, words: &[u32]) {
        assert!((layer as usize) < self.layers && words.len() <= self.quads * QUAD);
        let mut padded = Vec::new();
        for (c, buffer) in self.chunks.iter().enumerate() {
            let n = self.chunk_quads(c);
            let start = c * self.quads_per_chunk * QUAD;
            let end = (start + n * QUAD).min(words.len());
            let slice = if end - start == n * QUAD {
                &words[start..end]
            } else {
                padded.clear();
                padded.extend_from_slice(&words[start..end]);
                padded.resize(n * QUAD, 0);
                &padded
            };
            let offset = (layer as usize * n * QUAD * 4) as u64;
            queue.write_buffer(buffer, offset, bytemuck::cast_slice(slice));
        }
    }
}

/// The blend: one pipeline, one bind group and dispatch per chunk of panes.
pub(crate) struct BlendPass {
    pass: ComputePass,
    /// Per chunk: its bind group and workgroups (chunks no texel of which is lit are left out).
    chunks: Vec<(wgpu::BindGroup, [u32; 3])>,
    /// The chunks' constants and lit quads, which the bind groups name (kept alive here).
    _buffers: Vec<wgpu::Buffer>,
    /// Quads the blend reads of every selected pane: the lit ones.
    pub lit_quads: u64,
}

/// What the blend writes and adds besides the panes.
pub(crate) struct BlendTargets<'a> {
    /// The indirect-irradiance lightmap it writes.
    pub lightmap: &'a wgpu::TextureView,
    /// The emitters' and sky's traced indirect lightmap (used when it has the lightmap's size).
    pub emitted: &'a wgpu::TextureView,
    /// The near field's lightmap (likewise).
    pub near: &'a wgpu::TextureView,
}

impl BlendPass {
    /// The pass on `b`'s frame and selection, blending `panes` into `targets.lightmap` at the
    /// quads holding a texel of `lit` (one flag per atlas texel, row-major).
    pub fn new(device: &wgpu::Device, b: &Buffers, panes: &Panes, targets: &BlendTargets, lit: &[bool]) -> BlendPass {
        // Per chunk: its constants and its lit quads (chunk-relative).
        let mut counts = Vec::new();
        let mut buffers = Vec::new();
        for c in 0..panes.chunks.len() {
            let first = c * panes.quads_per_chunk;
            let n = panes.chunk_quads(c);
            let lit_quads: Vec<u32> = (0..n as u32)
                .filter(|&q| {
                    let t = ((first + q as usize) * QUAD).min(lit.len());
                    lit[t..(t + QUAD).min(lit.len())].iter().any(|&l| l)
                })
                .collect();
            let constants = GpuBlendChunk {
                first_quad: first as u32,
                quads: n as u32,
                lit_quads: lit_quads.len() as u32,
                _pad0: 0,
            };
            counts.push(lit_quads.len() as u32);
            buffers.push(pipeline::buffer_init(
                device,
                "prm blend chunk",
                bytemuck::bytes_of(&constants),
                wgpu::BufferUsages::UNIFORM,
            ));
            buffers.push(pipeline::buffer_init(
                device,
                "prm lit quads",
                bytemuck::cast_slice(&lit_quads),
                wgpu::BufferUsages::STORAGE,
            ));
        }
        let resources = |c: usize| {
            [
                b.frame.as_entire_binding(),
                b.selected.as_entire_binding(),
                buffers[2 * c].as_entire_binding(),
                panes.chunks[c].as_entire_binding(),
                buffers[2 * c + 1].as_entire_binding(),
                wgpu::BindingResource::TextureView(targets.lightmap),
                wgpu::BindingResource::TextureView(targets.emitted),
                wgpu::BindingResource::TextureView(targets.near),
            ]
        };
        let pass = ComputePass::new(
            device,
            "blend",
            &[crate::SHARED_WGSL, include_str!("../../../shaders/runtime/blend.wgsl")],
            &resources(0),
        );
        // Chunks with no lit texel are not dispatched.
        let chunks = (0..panes.chunks.len())
            .filter(|&c| counts[c] > 0)
            .map(|c| (pass.group(device, &resources(c)), linear_workgroups(counts[c])))
            .collect();
        BlendPass {
            pass,
            chunks,
            _buffers: buffers,
            lit_quads: counts.iter().map(|&n| n as u64).sum(),
        }
    }

    /// Records the blend: one compute pass, a dispatch per chunk.
    pub fn encode(&self, encoder: &mut wgpu::CommandEncoder, timer: Option<&PassTimer>) {
        self.pass.encode_groups(encoder, &self.chunks, timer);
    }
}
