//! The blend pass (`shaders/runtime/blend.wgsl`) and the panes it reads: at every lit texel, the
//! tile's basis row times the mixed coefficients of the mix pass ([`crate::mix`]), plus the
//! emitters' and the near field's lightmaps, into the indirect-irradiance lightmap.
//!
//! The panes stay on the GPU as the archive holds them, a low-rank basis per atlas tile
//! (`prm_format::PaneBasis`), not expanded to one texture per pane: the basis rows that are not
//! zero as `f16` (rounded up to four per texel, zero-padded; a texel outside every chart has a
//! zero row, a third of the Cornell box's atlas) and the coefficients under a scale per pane and
//! tile, a shared-exponent word per rank ([`PaneBlock`]), with every residual group's
//! coefficients (its members' summed) after the clusters'. Since blending is linear, the
//! frame's `Σ_c w_c·pane_c` is `U·(Σ_c w_c·C_c)` per tile: the mix pass forms the bracket, a few
//! hundred values per tile, and this pass one dot product of rank length per texel. Tiles are
//! grouped in *chunks* whose basis and coefficients each fit the device's storage binding (128
//! MiB on lavapipe); each pass dispatches once per chunk.
//!
//! On the bundled Cornell box's automatic bake (512 clusters + 64 residual groups, a 128² atlas,
//! 4 tiles of mean rank 107) the panes take 3.6 MiB of GPU memory this way, against 32 MiB as
//! one RGB9E5 buffer per pane, and an update that blends every cluster reads 3.6 MB of them
//! (`prm-play --timings`, `gpu_memory` and `gi_bytes_read_by_part`). A tile keeps only the
//! blocks of the panes that light it ([`tile_blocks`]).
//! On lavapipe the frame bench (`cargo bench -p prm-play --bench frame`,
//! `PRM_BENCH_PRESET=default`) puts the 504 clusters beyond the first 8 at −3.0 to 4.1 ms of a
//! frame whose lights move (two runs, within their noise; RGB9E5 buffers: 13.7 ms for 120 panes
//! and 64 groups).

use prm_format::PaneBasis;
use prm_gpu_kit::{linear_workgroups, pipeline, ComputePass, PassTimer};

use crate::{GpuBlendChunk, GpuPaneTile, RuntimeError};

/// Basis values per `vec2<u32>`: four `f16`.
const LANES: usize = 4;

/// One chunk of tiles: their basis and coefficients, each a storage buffer.
pub(crate) struct PaneChunk {
    /// The chunk's constants (its tiles; lit texels are set by [`BlendPass::new`]).
    pub constants: GpuBlendChunk,
    pub basis: wgpu::Buffer,
    pub coefficients: wgpu::Buffer,
}

/// The panes as the mix and blend passes read them.
pub(crate) struct Panes {
    pub chunks: Vec<PaneChunk>,
    /// One [`GpuPaneTile`] per tile, offsets within its chunk's buffers.
    pub tiles: wgpu::Buffer,
    /// The mixed coefficients, `mixed_stride` `vec4<f32>` per tile.
    pub mixed: wgpu::Buffer,
    /// Each tile's chunk.
    tile_chunk: Vec<usize>,
    /// Bytes the mix reads a frame per kept pane, on average: its blocks that are not zero and
    /// its index word in every tile.
    coefficient_bytes_per_pane: u64,
    /// Each tile's rank.
    ranks: Vec<u32>,
    /// Every atlas texel's basis row in its chunk's basis buffer (in `vec2<u32>`), [`NO_ROW`]
    /// where the row is zero; taken by [`BlendPass::new`].
    rows: Vec<u32>,
    /// Mixed coefficients per tile: the largest rank rounded up to four.
    mixed_stride: u32,
    tile_size: u32,
    tiles_per_side: u32,
}

impl Panes {
    /// Uploads `basis` with each of the `group_count` residual groups' coefficients (the sum of
    /// those of the clusters `group_of` puts in it) after the clusters', in chunks the device
    /// can bind and of at most `cap` bytes when given.
    pub fn upload(
        device: &wgpu::Device,
        basis: &PaneBasis,
        group_of: &[u32],
        group_count: u32,
        cap: Option<u64>,
    ) -> Result<Panes, RuntimeError> {
        let limits = device.limits();
        let binding = limits
            .max_storage_buffer_binding_size
            .min(limits.max_buffer_size)
            .min(cap.unwrap_or(u64::MAX));
        let panes = basis.pane_count() + group_count as usize;
        let mut blocks: Vec<Vec<[u32; 2]>> = (0..basis.tile_count())
            .map(|t| tile_blocks(basis, t, group_of, group_count))
            .collect();
        let sizes: Vec<(u64, u64)> = (0..basis.tile_count())
            .map(|t| {
                let stride = u64::from(basis.ranks()[t]).div_ceil(LANES as u64);
                let rows = basis.nonzero_rows(t).count() as u64;
                (rows * stride * 8, blocks[t].len() as u64 * 8)
            })
            .collect();
        if let Some(&(b, c)) = sizes.iter().find(|&&(b, c)| b.max(c) > binding) {
            return Err(RuntimeError::TooManyPanes {
                panes,
                bytes: b.max(c),
                binding,
            });
        }
        // Tiles in order, a new chunk whenever the basis or the coefficients would not fit.
        let mut bounds = vec![0usize];
        let (mut b_sum, mut c_sum) = (0u64, 0u64);
        for (t, &(b, c)) in sizes.iter().enumerate() {
            if b_sum + b > binding || c_sum + c > binding {
                bounds.push(t);
                (b_sum, c_sum) = (0, 0);
            }
            b_sum += b;
            c_sum += c;
        }
        bounds.push(sizes.len());
        let mut gpu_tiles = Vec::with_capacity(sizes.len());
        let mut tile_chunk = Vec::with_capacity(sizes.len());
        let res = (basis.tile_size() * basis.tiles_per_side()) as usize;
        let mut rows = vec![NO_ROW; res * res];
        let chunks = bounds
            .windows(2)
            .enumerate()
            .map(|(c, w)| {
                let tiles = w[0]..w[1];
                let chunk = upload_chunk(device, basis, &mut blocks, tiles, &mut gpu_tiles, &mut rows);
                tile_chunk.extend(std::iter::repeat_n(c, w[1] - w[0]));
                chunk
            })
            .collect();
        let mixed_stride = basis.max_rank().div_ceil(LANES as u32) * LANES as u32;
        // Per kept pane, its index word in every tile of rank > 0 and its blocks on average.
        let ranked = (0..basis.tile_count()).filter(|&t| basis.ranks()[t] > 0).count() as u64;
        let index_bytes = ranked * 8 * (panes as u64).div_ceil(2);
        let block_bytes = sizes.iter().map(|s| s.1).sum::<u64>() - index_bytes;
        Ok(Panes {
            chunks,
            tiles: pipeline::buffer_init(
                device,
                "prm panes tiles",
                bytemuck::cast_slice(&gpu_tiles),
                wgpu::BufferUsages::STORAGE,
            ),
            mixed: pipeline::storage(
                device,
                "prm panes mixed",
                (basis.tile_count() as u64 * u64::from(mixed_stride.max(LANES as u32)) * 16).max(16),
                wgpu::BufferUsages::empty(),
            ),
            tile_chunk,
            coefficient_bytes_per_pane: block_bytes / panes.max(1) as u64 + 8 * ranked,
            ranks: basis.ranks().to_vec(),
            rows,
            mixed_stride,
            tile_size: basis.tile_size(),
            tiles_per_side: basis.tiles_per_side(),
        })
    }

    /// Marks in `lit` (one flag per atlas texel, row-major) every texel whose basis row is not
    /// zero: where some pane may light it.
    pub fn mark_lit(&self, lit: &mut [bool]) {
        for (l, &row) in lit.iter_mut().zip(&self.rows) {
            *l |= row != NO_ROW;
        }
    }

    /// The tile that holds atlas texel `texel`.
    fn tile_of(&self, texel: u32) -> usize {
        let res = self.tile_size * self.tiles_per_side;
        let (x, y) = (texel % res, texel / res);
        ((y / self.tile_size) * self.tiles_per_side + x / self.tile_size) as usize
    }

    /// Mixed coefficients per tile, as the passes index them: the largest rank rounded up to
    /// four.
    pub fn mixed_stride(&self) -> u32 {
        self.mixed_stride
    }

    /// Bytes the mix pass reads a frame for each kept pane, on average: its index word and,
    /// where it is not zero, its [`PaneBlock`] in every tile.
    pub fn coefficient_bytes_per_pane(&self) -> u64 {
        self.coefficient_bytes_per_pane
    }
}

/// A pane's coefficients in one tile of rank `r` as the mix reads them, in `vec2<u32>` words:
/// first its scale `s`, the largest magnitude of its coefficients there (f32 bits in `x`), then
/// per rank one [`PaneBlock::triple`] of its three channels over `s`, two ranks a word and
/// zero-padded to a multiple of four ranks. Under its own scale a pane keeps its precision
/// wherever it is bright, however dim beside the tile's brightest pane; a shared exponent per
/// rank keeps it for the small coefficients of the high ranks. Four bytes a rank instead of
/// three `f16` take a third off the coefficients: 23.1 MiB instead of 34.3 for Sponza baked in
/// 1024 clusters (`prm-bake dump`), whose GPU frame under its ceiling lamp then lies 0.20% from
/// the CPU player's (`f32` coefficients; 0.19% with `f16`; `prm-play --backend cpu`, compared
/// by `cargo xtask eval compare`).
pub(crate) struct PaneBlock;

impl PaneBlock {
    /// Appends the block of one pane's coefficients `v` (three channels of `r` each) to `out`.
    fn push(v: &[f32], r: usize, out: &mut Vec<[u32; 2]>) {
        let scale = v.iter().fold(0.0f32, |m, x| m.max(x.abs()));
        let inv = if scale > 0.0 { 1.0 / scale } else { 0.0 };
        out.push([scale.to_bits(), 0]);
        let word = |k: usize| {
            if k < r {
                Self::triple([v[k] * inv, v[r + k] * inv, v[2 * r + k] * inv])
            } else {
                0
            }
        };
        out.extend((0..r.div_ceil(LANES) * 2).map(|q| [word(2 * q), word(2 * q + 1)]));
    }

    /// Three values within ±1 as one word: each a 9-bit two's-complement mantissa `m` (bits
    /// 0–8, 9–17, 18–26) under a shared exponent `n` (bits 27–31), the value being
    /// `m·2^-(n+7)`. `n` is the largest (up to 31) that keeps the largest magnitude's mantissa
    /// within 255, so that one has 8 significant bits (within 0.4%) and the others the same
    /// step.
    pub(crate) fn triple(c: [f32; 3]) -> u32 {
        let a = c.iter().fold(0.0f32, |m, x| m.max(x.abs()));
        if a == 0.0 {
            return 0;
        }
        let mut n = ((255.5 / a).log2().floor() as i32 - 7).clamp(0, 31);
        while n > 0 && (a * 2f32.powi(n + 7)).round() > 255.0 {
            n -= 1;
        }
        let s = 2f32.powi(n + 7);
        let m = |x: f32| ((x * s).round().clamp(-255.0, 255.0) as i32 & 0x1ff) as u32;
        m(c[0]) | m(c[1]) << 9 | m(c[2]) << 18 | (n as u32) << 27
    }
}

/// A texel without a basis row (zero there), in [`Panes`]'s rows and the blend's texels.
const NO_ROW: u32 = u32::MAX;

/// A pane without a block in a tile (zero there), in the tile's block index.
const NO_BLOCK: u32 = u32::MAX;

/// Tile `tile`'s coefficients as the mix reads them, in `vec2<u32>` words: first an index with
/// one `u32` per pane (two a word; the clusters', then the `group_count` residual groups'),
/// each the word where the pane's [`PaneBlock`] starts, counted from the tile's first word, or
/// [`NO_BLOCK`]; then the blocks. A cluster has a block where its coefficients are not all
/// zero (in a large scene most clusters light few tiles: 27% of the blocks of Sponza's default
/// bake are zero), a residual group (its members' coefficients summed by `group_of`) where one
/// of its members has. Empty for a tile of rank 0.
fn tile_blocks(basis: &PaneBasis, tile: usize, group_of: &[u32], group_count: u32) -> Vec<[u32; 2]> {
    let r = basis.ranks()[tile] as usize;
    if r == 0 {
        return Vec::new();
    }
    let own = basis.coefficients(tile);
    let (clusters, groups) = (basis.pane_count(), group_count as usize);
    let mut sums = vec![0.0f32; 3 * r * groups];
    let mut kept = vec![false; clusters + groups];
    for (pane, v) in own.chunks_exact(3 * r).enumerate() {
        kept[pane] = !basis.block_is_zero(pane, tile);
        let g = group_of.get(pane).map_or(groups, |&g| g as usize);
        if g < groups && kept[pane] {
            kept[clusters + g] = true;
            let sum = &mut sums[3 * r * g..3 * r * (g + 1)];
            sum.iter_mut().zip(v).for_each(|(s, v)| *s += v);
        }
    }
    let mut index = vec![NO_BLOCK; clusters + groups];
    let mut out = vec![[0u32; 2]; (clusters + groups).div_ceil(2)];
    for (pane, v) in own.chunks_exact(3 * r).chain(sums.chunks_exact(3 * r)).enumerate() {
        if kept[pane] {
            index[pane] = out.len() as u32;
            PaneBlock::push(v, r, &mut out);
        }
    }
    for (word, pair) in out.iter_mut().zip(index.chunks(2)) {
        *word = [pair[0], pair.get(1).copied().unwrap_or(NO_BLOCK)];
    }
    out
}

/// Chunk `tiles` of `basis` in two buffers, each tile's coefficients as [`tile_blocks`]
/// encoded them in `blocks` (moved out of it); its tiles' entries appended to `gpu_tiles`, its
/// texels' rows written to `rows`.
fn upload_chunk(
    device: &wgpu::Device,
    basis: &PaneBasis,
    blocks: &mut [Vec<[u32; 2]>],
    tiles: std::ops::Range<usize>,
    gpu_tiles: &mut Vec<GpuPaneTile>,
    rows: &mut [u32],
) -> PaneChunk {
    let (t, s) = (basis.tile_size() as usize, basis.tiles_per_side() as usize);
    let mut words: Vec<u32> = Vec::new();
    let mut coefficients: Vec<[u32; 2]> = Vec::new();
    for tile in tiles.clone() {
        let r = basis.ranks()[tile] as usize;
        let stride = r.div_ceil(LANES);
        gpu_tiles.push(GpuPaneTile {
            stride: stride as u32,
            rank: r as u32,
            coefficients: coefficients.len() as u32,
            _pad0: 0,
        });
        if r == 0 {
            continue;
        }
        let (x0, y0) = ((tile % s) * t, (tile / s) * t);
        for i in basis.nonzero_rows(tile) {
            let row = &basis.basis(tile)[i * r..(i + 1) * r];
            rows[(y0 + i / t) * t * s + x0 + i % t] = (words.len() / 2) as u32;
            let half = |k: usize| row.get(k).map_or(0, |&u| u32::from(half::f16::from_f32(u).to_bits()));
            words.extend((0..2 * stride).map(|p| half(2 * p) | half(2 * p + 1) << 16));
        }
        coefficients.append(&mut blocks[tile]);
    }
    PaneChunk {
        constants: GpuBlendChunk {
            first_tile: tiles.start as u32,
            tiles: tiles.len() as u32,
            ..Default::default()
        },
        basis: pipeline::buffer_init(
            device,
            "prm panes basis",
            bytemuck::cast_slice(&crate::gather::at_least_one(words)),
            wgpu::BufferUsages::STORAGE,
        ),
        coefficients: pipeline::buffer_init(
            device,
            "prm panes coefficients",
            bytemuck::cast_slice(&coefficients),
            wgpu::BufferUsages::STORAGE,
        ),
    }
}

/// The blend: one pipeline, one bind group and dispatch per chunk of tiles, after the mix.
pub(crate) struct BlendPass {
    mix: crate::mix::MixPass,
    pass: ComputePass,
    /// Per chunk with a lit texel: its bind group and workgroups.
    chunks: Vec<(wgpu::BindGroup, [u32; 3])>,
    /// The chunks' constants and lit texels, which the bind groups name (kept alive here).
    _buffers: Vec<wgpu::Buffer>,
    /// Bytes of basis rows the blend reads a frame (those of the lit texels).
    pub basis_bytes_read: u64,
    /// Bytes the mix reads a frame per kept pane.
    pub coefficient_bytes_per_pane: u64,
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
    /// The mix and the blend on `b`'s frame and selection, blending `panes` into
    /// `targets.lightmap` at the texels of `lit` (one flag per atlas texel, row-major).
    pub fn new(
        device: &wgpu::Device,
        b: &crate::Buffers,
        panes: &mut Panes,
        targets: &BlendTargets,
        lit: &[bool],
    ) -> BlendPass {
        let rows = std::mem::take(&mut panes.rows);
        // Per chunk, its lit texels and their basis rows.
        let mut texels: Vec<Vec<[u32; 2]>> = vec![Vec::new(); panes.chunks.len()];
        let mut basis_bytes_read = 0;
        for t in (0..lit.len() as u32).filter(|&t| lit[t as usize]) {
            let tile = panes.tile_of(t);
            let row = rows[t as usize];
            texels[panes.tile_chunk[tile]].push([t, row]);
            if row != NO_ROW {
                basis_bytes_read += u64::from(panes.ranks[tile].div_ceil(LANES as u32)) * 8;
            }
        }
        let mut buffers = Vec::new();
        for (chunk, texels) in panes.chunks.iter().zip(&texels) {
            let constants = GpuBlendChunk {
                lit_texels: texels.len() as u32,
                mixed_stride: panes.mixed_stride(),
                tile_size: panes.tile_size,
                tiles_per_side: panes.tiles_per_side,
                ..chunk.constants
            };
            buffers.push(pipeline::buffer_init(
                device,
                "prm blend chunk",
                bytemuck::bytes_of(&constants),
                wgpu::BufferUsages::UNIFORM,
            ));
            buffers.push(pipeline::buffer_init(
                device,
                "prm lit texels",
                bytemuck::cast_slice(texels),
                wgpu::BufferUsages::STORAGE,
            ));
        }
        let resources = |c: usize| {
            [
                buffers[2 * c].as_entire_binding(),
                panes.tiles.as_entire_binding(),
                panes.chunks[c].basis.as_entire_binding(),
                buffers[2 * c + 1].as_entire_binding(),
                panes.mixed.as_entire_binding(),
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
            .filter(|&c| !texels[c].is_empty())
            .map(|c| {
                (
                    pass.group(device, &resources(c)),
                    linear_workgroups(texels[c].len() as u32),
                )
            })
            .collect();
        let uniforms: Vec<&wgpu::Buffer> = buffers.iter().step_by(2).collect();
        let mix = crate::mix::MixPass::new(device, b, panes, &uniforms);
        BlendPass {
            mix,
            pass,
            chunks,
            _buffers: buffers,
            basis_bytes_read,
            coefficient_bytes_per_pane: panes.coefficient_bytes_per_pane(),
        }
    }

    /// Records the mix, then the blend: a compute pass each, a dispatch per chunk.
    pub fn encode(&self, encoder: &mut wgpu::CommandEncoder, timer: Option<&PassTimer>) {
        self.mix.encode(encoder, timer);
        self.pass.encode_groups(encoder, &self.chunks, timer);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Decodes a [`PaneBlock::triple`] as the mix does.
    fn triple(w: u32) -> [f32; 3] {
        let m = |shift: u32| ((w << shift) as i32 >> 23) as f32;
        let s = f32::from_bits((120 - (w >> 27)) << 23);
        [m(23) * s, m(14) * s, m(5) * s]
    }

    /// Decodes pane `pane`'s block from a tile's words as the mix does: `None` where its index
    /// says there is none.
    fn block(words: &[[u32; 2]], pane: usize, r: usize) -> Option<Vec<f32>> {
        let at = words[pane / 2][pane % 2];
        if at == NO_BLOCK {
            return None;
        }
        let b = &words[at as usize..];
        let scale = f32::from_bits(b[0][0]);
        let ranks: Vec<[f32; 3]> = (0..r).map(|k| triple(b[1 + k / 2][k % 2])).collect();
        Some((0..3).flat_map(|ch| ranks.iter().map(move |t| scale * t[ch])).collect())
    }

    /// A triple keeps its largest magnitude to 8 significant bits and the others to the same
    /// step, signs included, from ±1 down to values far below the coefficients' range.
    #[test]
    fn triples_keep_eight_bits_of_the_largest_channel() {
        let cases = [
            [1.0, -1.0, 0.5],
            [-0.999, 0.3, -0.001],
            [0.37, 0.0, -0.2],
            [1e-6, -3e-7, 2e-8],
            [0.0, 0.0, 0.0],
            [-0.5, 0.49, 0.001],
        ];
        for c in cases {
            let d = triple(PaneBlock::triple(c));
            let a = c.iter().fold(0f32, |m, x| m.max(x.abs()));
            for (d, c) in d.iter().zip(c) {
                assert!((d - c).abs() <= a / 250.0, "{c} decoded as {d}");
            }
        }
    }

    /// Panes that are zero in a tile have no block there, the others and the residual groups
    /// (their members' sums) decode to their coefficients, and a group whose members are all
    /// zero in a tile has none either.
    #[test]
    fn tiles_keep_the_blocks_of_the_panes_that_light_them() {
        let (res, tile) = (16usize, 8usize);
        let panes: Vec<Vec<[f32; 3]>> = (0..5)
            .map(|p| {
                (0..res * res)
                    .map(|i| {
                        let (x, y) = (i % res, i / res);
                        let t = (y / tile) * (res / tile) + x / tile;
                        if (p + t) % 3 == 0 {
                            [0.0; 3]
                        } else {
                            let v = 1.0 + (p as f32) * 0.3 + (x as f32 * 0.1 + y as f32 * 0.07).sin();
                            [v, 0.5 * v, 0.25 * v + 0.1]
                        }
                    })
                    .collect()
            })
            .collect();
        let basis = PaneBasis::compress(&panes, res as u32, tile as u32, 0.0, 64).unwrap();
        let group_of = [0, 0, 1, 1, 2];
        let mut absent = 0;
        for t in 0..basis.tile_count() {
            let r = basis.ranks()[t] as usize;
            let words = tile_blocks(&basis, t, &group_of, 3);
            let own = basis.coefficients(t);
            for p in 0..5 {
                match block(&words, p, r) {
                    None => {
                        assert!(basis.block_is_zero(p, t), "pane {p} tile {t}");
                        absent += 1;
                    }
                    Some(decoded) => {
                        let want = &own[3 * p * r..3 * (p + 1) * r];
                        let scale = want.iter().fold(0f32, |m, c| m.max(c.abs()));
                        for (d, w) in decoded.iter().zip(want) {
                            assert!((d - w).abs() <= scale / 250.0, "pane {p} tile {t}: {d} for {w}");
                        }
                    }
                }
            }
            for g in 0..3 {
                let members: Vec<usize> = (0..5).filter(|&p| group_of[p] == g).collect();
                let decoded = block(&words, 5 + g as usize, r);
                assert_eq!(decoded.is_none(), members.iter().all(|&p| basis.block_is_zero(p, t)));
                if let Some(decoded) = decoded {
                    let sums: Vec<f32> = (0..3 * r)
                        .map(|k| members.iter().map(|&p| own[3 * p * r + k]).sum())
                        .collect();
                    let scale = sums.iter().fold(0f32, |m, c| m.max(c.abs()));
                    for (d, sum) in decoded.iter().zip(&sums) {
                        assert!((d - sum).abs() <= scale / 250.0, "group {g} tile {t}: {d} for {sum}");
                    }
                }
            }
        }
        assert!(absent >= 5, "{absent} panes absent from their tiles");
    }
}
