//! The panes section (kind 5, formats/prm.md §7): every pane as a low-rank basis per atlas tile.
//!
//! Cut the atlas into tiles of `T²` texels. In one tile, the panes of the `P` clusters form a
//! matrix `M` of `T²` rows (the tile's texels, row-major) and `3P` columns (column `3c + ch` holds
//! channel `ch` of pane `c`). Clusters light the same surfaces with alike, smooth falloffs, so
//! `M` is close to a matrix of low rank `r`: `M ≈ U·Cᵀ`, `U` of `T² × r` with orthonormal
//! columns (the tile's *basis*, stored as `f16`: its entries lie in `[−1, 1]`) and `C` of
//! `3P × r` (the *coefficients*, stored as `f16` times a scale per pane, the largest magnitude
//! of its `3r`: they keep 11 significant bits of it). The rank of each tile is the smallest that keeps the
//! discarded singular values' energy within `ε²‖M‖²_F` ([`PANE_TOLERANCE`]).
//!
//! **Decoding** (normative, formats/prm.md §7.2): channel `ch` of pane `c` at texel `i` of a tile
//! of rank `r` is `v_r`, with `v_0 = +0` and `v_{k+1} = v_k + U[i][k]·C[3c + ch][k]`, the product
//! and the sum each rounded to binary32 (a plain multiply then an add, never a fused
//! multiply-add; Rust does not contract them), then clamped: `v > 0 ? v : +0`. Every reader gets
//! the same bits, so the clusters' `energy` and `peak` are reproducible bit for bit.
//!
//! **Compression** is a randomized SVD per tile (Halko, Martinsson and Tropp, 2011): a Gaussian
//! sketch `Y = M·Ω` of width `l = min(max_rank + 16, T², 3P)` from a fixed-seed generator, one
//! power iteration (`Mᵀ`, then `M`, each followed by a QR re-orthonormalisation), `Q` the thin Q
//! of the sketch, `B = Qᵀ·M`, the thin SVD `B = Ũ·Σ·Vᵀ` (small), and `U = Q·Ũ`. Whatever the
//! sketch captures, the stored approximation's error is exactly `‖M‖² − Σ_{k<r} σ_k²`, the very
//! quantity the rank criterion bounds. Every tile runs sequentially (faer's `Par::Seq`) with its
//! own fixed seed, and tiles are spread over threads, so an input gives the same bytes on every
//! run on a machine.

use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;

use faer::diag::Diag;
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::householder::{
    apply_block_householder_sequence_on_the_left_in_place_scratch,
    apply_block_householder_sequence_on_the_left_in_place_with_conj,
};
use faer::linalg::matmul::matmul;
use faer::linalg::qr::no_pivoting::factor::{qr_in_place, qr_in_place_scratch, recommended_block_size};
use faer::linalg::svd::{svd, svd_scratch, ComputeSvdVectors};
use faer::prelude::default;
use faer::{Accum, Conj, Mat, MatRef, Par};

use crate::error::{Error, Result};
use crate::layout::{check_reserved, from_planes, limits, to_planes, Cursor, PutLe};

/// Default relative tolerance ε of the panes' low-rank approximation ([`crate::WriterOptions`]):
/// each tile keeps the fewest basis vectors whose discarded singular values hold at most ε of the
/// tile's Frobenius norm (`‖M − U·Cᵀ‖_F ≤ ε·‖M‖_F`, before the `f16` rounding of the basis).
///
/// Chosen by measurement on the bundled Cornell box (512 clusters, a 256² atlas in 64² tiles),
/// with `cargo xtask eval experiment pane_rank SCENE ARCHIVE`: at ε = 2% the tiles keep a mean
/// rank of about 43, the panes take 5.1 MiB in the archive (128 MiB as RGB9E5 textures), and lit
/// combinations `Σ_c w_c·pane_c` deviate by 0.34% (relative RMSE) from the dense panes, well
/// below the bake's own noise.
pub const PANE_TOLERANCE: f32 = 0.02;

/// Default largest rank of a tile ([`crate::WriterOptions::max_pane_rank`]).
pub const MAX_PANE_RANK: u32 = 128;

/// Columns the sketch holds beyond the largest rank it may keep.
const OVERSAMPLING: usize = 16;

/// Power iterations of the randomized SVD.
const POWER_ITERATIONS: usize = 1;

/// Seed of the Gaussian test matrices; tile `t` uses `SKETCH_SEED + t`.
const SKETCH_SEED: u64 = 0x5052_4d20_6261_7365;

/// Size of the panes section's fixed header: pane count, tiles per side, largest rank, reserved.
pub(crate) const PANES_HEADER_SIZE: usize = 16;

/// Every pane of an archive as a low-rank basis per atlas tile (module docs, formats/prm.md §7).
///
/// Tile `t = ty·S + tx` (`S` = [`tiles_per_side`](Self::tiles_per_side)) covers atlas texels
/// `(tx·T + i, ty·T + j)`, `0 ≤ i, j < T`; its texel `j·T + i` is row `j·T + i` of its basis.
#[derive(Clone, Debug, PartialEq)]
pub struct PaneBasis {
    pane_count: u32,
    tile_size: u32,
    tiles_per_side: u32,
    ranks: Vec<u32>,
    /// Per tile, `3P·r` values, index `(3c + ch)·r + k`.
    coefficients: Vec<Vec<f32>>,
    /// Per tile, `T²·r` values (each exactly an `f16`), index `texel·r + k`.
    basis: Vec<Vec<f32>>,
}

impl PaneBasis {
    /// Compresses `panes` (one per cluster, each `resolution²` RGB texels, row-major) for an atlas
    /// of `resolution` texels per side cut into tiles of `tile_size`: each tile keeps the fewest
    /// basis vectors whose discarded singular values hold at most `tolerance` of its Frobenius
    /// norm, and at most `max_rank`.
    ///
    /// Channels are taken as the writer takes them: NaN and negative values as 0, values above
    /// [`RGB9E5_MAX`](crate::RGB9E5_MAX) (the largest a run time's RGB9E5 texture holds) as that.
    /// Refused: a layout outside the format's limits, a pane of another size, a tolerance outside
    /// `[0, 1)` and a largest rank of 0.
    pub fn compress<T: AsRef<[[f32; 3]]>>(
        panes: &[T],
        resolution: u32,
        tile_size: u32,
        tolerance: f32,
        max_rank: u32,
    ) -> Result<PaneBasis> {
        check_layout(resolution, tile_size, panes.len())?;
        let mut dense = DenseTiles::new(resolution, tile_size, panes.len());
        for (c, pane) in panes.iter().enumerate() {
            dense.set_pane(c, pane.as_ref())?;
        }
        PaneBasis::from_dense(&dense, tolerance, max_rank)
    }

    /// Compresses the panes collected in `dense` (see [`PaneBasis::compress`]).
    pub(crate) fn from_dense(dense: &DenseTiles, tolerance: f32, max_rank: u32) -> Result<PaneBasis> {
        check_options(tolerance, max_rank)?;
        let s = dense.resolution / dense.tile_size;
        let tiles = (s * s) as usize;
        let results: Vec<Mutex<Option<Result<TileBasis>>>> = (0..tiles).map(|_| Mutex::new(None)).collect();
        let next = AtomicUsize::new(0);
        let threads = std::thread::available_parallelism().map_or(1, |n| n.get()).min(tiles);
        std::thread::scope(|scope| {
            for _ in 0..threads {
                scope.spawn(|| loop {
                    let t = next.fetch_add(1, Ordering::Relaxed);
                    if t >= tiles {
                        break;
                    }
                    let m = dense.tile(t);
                    let seed = SKETCH_SEED.wrapping_add(t as u64);
                    let out = compress_tile(m, f64::from(tolerance), max_rank as usize, seed).map_err(|e| {
                        Error::InvalidInput(format!("panes tile ({}, {}): {e}", t as u32 % s, t as u32 / s))
                    });
                    *results[t].lock().unwrap_or_else(|e| e.into_inner()) = Some(out);
                });
            }
        });
        let mut basis = PaneBasis {
            pane_count: dense.panes as u32,
            tile_size: dense.tile_size,
            tiles_per_side: s,
            ranks: Vec::with_capacity(tiles),
            coefficients: Vec::with_capacity(tiles),
            basis: Vec::with_capacity(tiles),
        };
        for slot in results {
            let tile = slot
                .into_inner()
                .unwrap_or_else(|e| e.into_inner())
                .ok_or_else(|| Error::InvalidInput("a panes tile was not compressed".into()))??;
            basis.ranks.push(tile.rank as u32);
            basis.coefficients.push(tile.coefficients);
            basis.basis.push(tile.basis);
        }
        Ok(basis)
    }

    /// Number of panes (`P`, the clusters).
    pub fn pane_count(&self) -> usize {
        self.pane_count as usize
    }

    /// Texels per side of a tile (`T`, the atlas's tile size).
    pub fn tile_size(&self) -> u32 {
        self.tile_size
    }

    /// Tiles per side of the atlas (`S = R/T`).
    pub fn tiles_per_side(&self) -> u32 {
        self.tiles_per_side
    }

    /// Texels per side of the atlas and of every pane (`R = S·T`).
    pub fn resolution(&self) -> u32 {
        self.tiles_per_side * self.tile_size
    }

    /// Number of tiles (`S²`).
    pub fn tile_count(&self) -> usize {
        self.ranks.len()
    }

    /// Every tile's rank `r_t`, in tile order (`t = ty·S + tx`); 0 for a tile where every pane is
    /// zero.
    pub fn ranks(&self) -> &[u32] {
        &self.ranks
    }

    /// The largest rank of a tile (0 when every pane is zero).
    pub fn max_rank(&self) -> u32 {
        self.ranks.iter().copied().max().unwrap_or(0)
    }

    /// Tile `tile`'s coefficients: `3P·r_t` values, `C[3c + ch][k]` at index `(3c + ch)·r_t + k`
    /// (empty for a tile of rank 0). Panics if `tile` is not below [`tile_count`](Self::tile_count).
    pub fn coefficients(&self, tile: usize) -> &[f32] {
        &self.coefficients[tile]
    }

    /// Tile `tile`'s basis: `T²·r_t` values, each exactly an `f16` (binary16) as stored, `U[i][k]`
    /// at index `i·r_t + k` for the tile's texel `i = j·T + i_x` (row-major; empty for a tile of
    /// rank 0). Panics if `tile` is not below [`tile_count`](Self::tile_count).
    pub fn basis(&self, tile: usize) -> &[f32] {
        &self.basis[tile]
    }

    /// The texels of tile `tile` (row-major within the tile, ascending) whose basis row is not
    /// all zero: the only ones a pane can light there. None for a tile of rank 0. Panics if
    /// `tile` is not below [`tile_count`](Self::tile_count).
    pub fn nonzero_rows(&self, tile: usize) -> impl Iterator<Item = usize> + '_ {
        let r = (self.ranks[tile] as usize).max(1);
        self.basis[tile]
            .chunks_exact(r)
            .enumerate()
            .filter(|(_, row)| row.iter().any(|&u| u != 0.0))
            .map(|(i, _)| i)
    }

    /// Decodes texel `texel` (row-major within the tile) of tile `tile` of pane `pane`, by the
    /// normative rule (module docs). Panics if an index is out of range.
    pub fn decode_texel(&self, pane: usize, tile: usize, texel: usize) -> [f32; 3] {
        let r = self.ranks[tile] as usize;
        let u = &self.basis[tile][texel * r..(texel + 1) * r];
        let c = &self.coefficients[tile];
        std::array::from_fn(|ch| clamp(dot(u, &c[(3 * pane + ch) * r..(3 * pane + ch + 1) * r])))
    }

    /// Decodes pane `pane`: `R²` RGB texels, row-major over the atlas (texel `(x, y)` at
    /// `y·R + x`). [`Error::InvalidInput`] if there is no such pane.
    pub fn decode_pane(&self, pane: usize) -> Result<Vec<[f32; 3]>> {
        if pane >= self.pane_count() {
            return Err(Error::InvalidInput(format!(
                "pane {pane} out of range ({} panes)",
                self.pane_count
            )));
        }
        let (t, res) = (self.tile_size as usize, self.resolution() as usize);
        let s = self.tiles_per_side as usize;
        let mut out = vec![[0f32; 3]; res * res];
        for tile in 0..self.tile_count() {
            let r = self.ranks[tile] as usize;
            if r == 0 {
                continue;
            }
            let c = &self.coefficients[tile][3 * pane * r..3 * (pane + 1) * r];
            let (cr, rest) = c.split_at(r);
            let (cg, cb) = rest.split_at(r);
            let (x0, y0) = ((tile % s) * t, (tile / s) * t);
            for (i, u) in self.basis[tile].chunks_exact(r).enumerate() {
                let (mut a0, mut a1, mut a2) = (0f32, 0f32, 0f32);
                for k in 0..r {
                    a0 += u[k] * cr[k];
                    a1 += u[k] * cg[k];
                    a2 += u[k] * cb[k];
                }
                out[(y0 + i / t) * res + x0 + i % t] = [clamp(a0), clamp(a1), clamp(a2)];
            }
        }
        Ok(out)
    }

    /// The lit combination `Σ_c w_c ⊙ pane_c` of every pane under `weights` (RGB, one per pane),
    /// as a player blends it from the basis: per tile, the mixed coefficients `a_k = Σ_c w_c ⊙
    /// C[3c..3c + 3][k]` first, then `Σ_k U[i][k]·a_k` at every texel, clamped at +0 once. Row-major
    /// over the atlas like [`decode_pane`](Self::decode_pane). It differs from the sum of the
    /// decoded panes only where a pane's approximation dips below zero, which the decoder clamps
    /// per pane. Panics unless there is one weight per pane.
    pub fn blend(&self, weights: &[[f32; 3]]) -> Vec<[f32; 3]> {
        assert_eq!(weights.len(), self.pane_count(), "one weight per pane");
        let (t, res) = (self.tile_size as usize, self.resolution() as usize);
        let s = self.tiles_per_side as usize;
        let mut out = vec![[0f32; 3]; res * res];
        let mut mixed = Vec::new();
        for tile in 0..self.tile_count() {
            let r = self.ranks[tile] as usize;
            if r == 0 {
                continue;
            }
            mixed.clear();
            mixed.resize(r, [0f32; 3]);
            for (w, c) in weights.iter().zip(self.coefficients[tile].chunks_exact(3 * r)) {
                if *w == [0.0; 3] {
                    continue;
                }
                for (k, a) in mixed.iter_mut().enumerate() {
                    (0..3).for_each(|ch| a[ch] += w[ch] * c[ch * r + k]);
                }
            }
            let (x0, y0) = ((tile % s) * t, (tile / s) * t);
            for (i, u) in self.basis[tile].chunks_exact(r).enumerate() {
                let mut v = [0f32; 3];
                for (uk, a) in u.iter().zip(&mixed) {
                    (0..3).for_each(|ch| v[ch] += uk * a[ch]);
                }
                out[(y0 + i / t) * res + x0 + i % t] = v.map(clamp);
            }
        }
        out
    }

    /// Every pane's `energy` and `peak` as the cluster table records them (formats/prm.md §6):
    /// per channel, the decoded values summed in binary64 over the tiles in tile order and the
    /// texels of a tile row-major, rounded to binary32; and their maximum.
    pub fn energy_peak(&self) -> Vec<([f32; 3], [f32; 3])> {
        let panes = self.pane_count();
        let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
        let per = panes.div_ceil(threads.max(1)).max(1);
        std::thread::scope(|scope| {
            let jobs: Vec<_> = (0..panes)
                .step_by(per)
                .map(|first| scope.spawn(move || self.energy_peak_of(first..(first + per).min(panes))))
                .collect();
            jobs.into_iter()
                .flat_map(|j| j.join().unwrap_or_else(|e| std::panic::resume_unwind(e)))
                .collect()
        })
    }

    /// [`energy_peak`](Self::energy_peak) of the panes in `panes`: every texel decoded for all of
    /// them at once, four texels at a time, which vectorises across the panes while each value
    /// keeps the normative order.
    fn energy_peak_of(&self, panes: std::ops::Range<usize>) -> Vec<([f32; 3], [f32; 3])> {
        const BLOCK: usize = 4;
        let cols = 3 * panes.len();
        let mut energy = vec![0f64; cols];
        let mut peak = vec![0f32; cols];
        let mut acc = vec![0f32; BLOCK * cols];
        let mut ct = Vec::new();
        for tile in 0..self.tile_count() {
            let r = self.ranks[tile] as usize;
            if r == 0 || cols == 0 {
                continue; // zeros: adding +0 changes no sum, and no peak
            }
            // The coefficients of these panes, transposed: `ct[k·cols + j]`.
            let c = &self.coefficients[tile][3 * panes.start * r..3 * panes.end * r];
            ct.clear();
            ct.extend((0..r).flat_map(|k| (0..cols).map(move |j| c[j * r + k])));
            for block in self.basis[tile].chunks(BLOCK * r) {
                let texels = block.len() / r;
                let acc = &mut acc[..texels * cols];
                acc.fill(0.0);
                if texels == BLOCK {
                    let (a0, rest) = acc.split_at_mut(cols);
                    let (a1, rest) = rest.split_at_mut(cols);
                    let (a2, a3) = rest.split_at_mut(cols);
                    for (k, row) in ct.chunks_exact(cols).enumerate() {
                        let u = [block[k], block[r + k], block[2 * r + k], block[3 * r + k]];
                        for ((((x0, x1), x2), x3), &ck) in
                            a0.iter_mut().zip(&mut *a1).zip(&mut *a2).zip(&mut *a3).zip(row)
                        {
                            *x0 += u[0] * ck;
                            *x1 += u[1] * ck;
                            *x2 += u[2] * ck;
                            *x3 += u[3] * ck;
                        }
                    }
                } else {
                    for (a, u) in acc.chunks_exact_mut(cols).zip(block.chunks_exact(r)) {
                        for (row, &uk) in ct.chunks_exact(cols).zip(u) {
                            for (x, &ck) in a.iter_mut().zip(row) {
                                *x += uk * ck;
                            }
                        }
                    }
                }
                // Texel by texel, in row-major order, into the binary64 sums.
                for a in acc.chunks_exact(cols) {
                    for ((e, p), &x) in energy.iter_mut().zip(&mut peak).zip(a) {
                        let v = clamp(x);
                        *e += f64::from(v);
                        *p = p.max(v);
                    }
                }
            }
        }
        (0..panes.len())
            .map(|i| {
                let e = std::array::from_fn(|ch| energy[3 * i + ch] as f32);
                (e, std::array::from_fn(|ch| peak[3 * i + ch]))
            })
            .collect()
    }

    /// Whether pane `pane`'s coefficients in tile `tile` are all zero: it lights nothing there
    /// (true for a tile of rank 0). Panics if `tile` is out of range, or `pane` where the rank
    /// is not 0.
    pub fn block_is_zero(&self, pane: usize, tile: usize) -> bool {
        let r = self.ranks[tile] as usize;
        self.coefficients[tile][3 * pane * r..3 * (pane + 1) * r]
            .iter()
            .all(|&c| c == 0.0)
    }

    /// Bytes of the basis values of every tile (`2·T²·Σ r_t`).
    pub fn basis_bytes(&self) -> u64 {
        2 * u64::from(self.tile_size).pow(2) * self.rank_sum()
    }

    /// Bytes of the coefficients of every tile with their scales (`6·P·Σ r_t + 4·P·S²`).
    pub fn coefficient_bytes(&self) -> u64 {
        let p = u64::from(self.pane_count);
        6 * p * self.rank_sum() + 4 * p * self.tile_count() as u64
    }

    /// Bytes of the panes section before any zstd compression:
    /// `16 + 4·S² + 4·P·S² + Σ_t r_t·(6·P + 2·T²)`.
    pub fn byte_size(&self) -> u64 {
        (PANES_HEADER_SIZE + 4 * self.tile_count()) as u64 + self.coefficient_bytes() + self.basis_bytes()
    }

    fn rank_sum(&self) -> u64 {
        self.ranks.iter().map(|&r| u64::from(r)).sum()
    }

    /// The section's raw bytes (formats/prm.md §7.1).
    pub(crate) fn encode(&self) -> Vec<u8> {
        let mut b = Vec::with_capacity(self.byte_size() as usize);
        b.put_u32(self.pane_count);
        b.put_u32(self.tiles_per_side);
        b.put_u32(self.max_rank());
        b.put_u32(0);
        for &r in &self.ranks {
            b.put_u32(r);
        }
        let p = self.pane_count as usize;
        let mut halves = Vec::new();
        for (c, &r) in self.coefficients.iter().zip(&self.ranks) {
            let r = r as usize;
            if r == 0 {
                (0..p).for_each(|_| b.put_f32(0.0));
                continue;
            }
            for pane in c.chunks_exact(3 * r) {
                let scale = pane_scale(pane);
                b.put_f32(scale);
                halves.extend(pane.iter().map(|&v| to_half(v, scale)));
            }
        }
        b.extend(to_planes(halves.iter().map(|h| h.to_le_bytes())));
        let mut basis = Vec::with_capacity(self.basis.iter().map(Vec::len).sum());
        for (u, &r) in self.basis.iter().zip(&self.ranks) {
            let r = r as usize;
            for k in 0..r {
                basis.extend(
                    u.iter()
                        .skip(k)
                        .step_by(r)
                        .map(|&v| half::f16::from_f32(v).to_le_bytes()),
                );
            }
        }
        b.extend(to_planes(basis.into_iter()));
        b
    }

    /// A basis read from a file, its parts checked by the reader.
    pub(crate) fn from_parts(
        header: &Header,
        tile_size: u32,
        ranks: Vec<u32>,
        coefficients: Vec<Vec<f32>>,
        basis: Vec<Vec<f32>>,
    ) -> PaneBasis {
        PaneBasis {
            pane_count: header.pane_count,
            tile_size,
            tiles_per_side: header.tiles_per_side,
            ranks,
            coefficients,
            basis,
        }
    }
}

/// A pane's scale in a tile (formats/prm.md §7.1): the largest magnitude of its `3r`
/// coefficients, so that each stored `f16` lies in `[−1, 1]`.
fn pane_scale(pane: &[f32]) -> f32 {
    pane.iter().fold(0.0f32, |m, v| m.max(v.abs()))
}

/// The `f16` that stores coefficient `v` of a pane of scale `scale` (0 for a zero pane).
fn to_half(v: f32, scale: f32) -> half::f16 {
    if scale > 0.0 {
        half::f16::from_f32(v / scale)
    } else {
        half::f16::ZERO
    }
}

/// The coefficient a reader decodes from `h` under `scale`: `f32(h) ⊗ scale`.
fn from_half(h: half::f16, scale: f32) -> f32 {
    h.to_f32() * scale
}

/// Rounds a pane's coefficients in a tile to what the archive stores, so that what a writer
/// holds decodes the same as what it writes: the largest becomes its scale exactly, so the
/// scale is the same when taken again.
fn quantize_pane(pane: &mut [f32]) {
    let scale = pane_scale(pane);
    for v in pane.iter_mut() {
        *v = from_half(to_half(*v, scale), scale);
    }
}

/// `a·b` summed in increasing index from +0, each product and sum rounded to binary32.
#[inline]
fn dot(a: &[f32], b: &[f32]) -> f32 {
    let mut v = 0f32;
    for (x, y) in a.iter().zip(b) {
        v += x * y;
    }
    v
}

/// The decoded value's clamp: `v` when positive, else +0 (also for −0).
#[inline]
fn clamp(v: f32) -> f32 {
    if v > 0.0 {
        v
    } else {
        0.0
    }
}

/// Refuses an atlas layout or a pane count outside the format's limits.
fn check_layout(resolution: u32, tile_size: u32, panes: usize) -> Result<()> {
    if resolution == 0 || resolution > limits::MAX_RESOLUTION {
        return Err(Error::InvalidInput(format!(
            "atlas resolution {resolution} outside 1..={}",
            limits::MAX_RESOLUTION
        )));
    }
    if tile_size == 0 || tile_size > limits::MAX_TILE_SIZE || !resolution.is_multiple_of(tile_size) {
        return Err(Error::InvalidInput(format!(
            "tile size {tile_size} must be in 1..={} and divide the resolution {resolution}",
            limits::MAX_TILE_SIZE
        )));
    }
    if panes as u64 > limits::MAX_CLUSTERS {
        return Err(Error::InvalidInput(format!(
            "{panes} panes exceed the limit {}",
            limits::MAX_CLUSTERS
        )));
    }
    Ok(())
}

/// Refuses a tolerance outside `[0, 1)` and a largest rank of 0.
pub(crate) fn check_options(tolerance: f32, max_rank: u32) -> Result<()> {
    if !(0.0..1.0).contains(&tolerance) {
        return Err(Error::InvalidInput(format!(
            "pane tolerance {tolerance} is not in [0, 1)"
        )));
    }
    if max_rank == 0 {
        return Err(Error::InvalidInput("the largest pane rank must be at least 1".into()));
    }
    Ok(())
}

/// Dense panes cut into tiles, as the writer collects them: per tile, `M` (`T²` rows, `3P`
/// columns), column `3c + ch` holding channel `ch` of pane `c` at the tile's texels (row-major).
/// Each is a faer matrix, whose columns faer aligns itself: the products' rounding does not
/// depend on where the allocator puts the panes.
pub(crate) struct DenseTiles {
    resolution: u32,
    tile_size: u32,
    panes: usize,
    /// Allocated on the first pane.
    tiles: Vec<Mat<f32>>,
}

impl DenseTiles {
    /// Room for `panes` panes of an atlas of `resolution` texels per side in tiles of `tile_size`
    /// (a layout the caller checked).
    pub(crate) fn new(resolution: u32, tile_size: u32, panes: usize) -> DenseTiles {
        DenseTiles {
            resolution,
            tile_size,
            panes,
            tiles: Vec::new(),
        }
    }

    /// Stores pane `pane` (below the pane count), `resolution²` texels row-major; channels are
    /// clamped to `[0, RGB9E5_MAX]`, NaN to 0.
    pub(crate) fn set_pane(&mut self, pane: usize, texels: &[[f32; 3]]) -> Result<()> {
        let (res, t) = (self.resolution as usize, self.tile_size as usize);
        if texels.len() != res * res {
            return Err(Error::InvalidInput(format!(
                "pane has {} texels, resolution {res} needs {}",
                texels.len(),
                res * res
            )));
        }
        let s = res / t;
        if self.tiles.is_empty() {
            self.tiles = (0..s * s).map(|_| Mat::zeros(t * t, 3 * self.panes)).collect();
        }
        for (tile, m) in self.tiles.iter_mut().enumerate() {
            let (x0, y0) = ((tile % s) * t, (tile / s) * t);
            for ch in 0..3 {
                let col = m.col_as_slice_mut(3 * pane + ch);
                for j in 0..t {
                    let row = &texels[(y0 + j) * res + x0..][..t];
                    for (out, v) in col[j * t..(j + 1) * t].iter_mut().zip(row) {
                        *out = crate::rgb9e5::clamp_channel(v[ch]);
                    }
                }
            }
        }
        Ok(())
    }

    /// Tile `t`'s matrix `M` (all zero before the first pane).
    fn tile(&self, t: usize) -> MatRef<'_, f32> {
        let rows = (self.tile_size * self.tile_size) as usize;
        match self.tiles.get(t) {
            Some(m) => m.as_ref(),
            None => MatRef::from_column_major_slice(&[], rows, 0),
        }
    }
}

/// One tile's part of a [`PaneBasis`].
struct TileBasis {
    rank: usize,
    coefficients: Vec<f32>,
    basis: Vec<f32>,
}

/// The smallest `r ≤ s.len()` with `‖M‖² − Σ_{k<r} σ_k² ≤ ε²·‖M‖²` (in binary64), or `s.len()`
/// when there is none.
fn truncation_rank(norm2: f64, s: &[f32], tolerance: f64) -> usize {
    let bound = tolerance * tolerance * norm2;
    let mut kept = 0f64;
    for (r, &sigma) in s.iter().enumerate() {
        if norm2 - kept <= bound {
            return r;
        }
        kept += f64::from(sigma) * f64::from(sigma);
    }
    s.len()
}

/// Compresses one tile's `M` (module docs); `seed` fixes its Gaussian test matrix.
fn compress_tile(m: MatRef<'_, f32>, tolerance: f64, max_rank: usize, seed: u64) -> Result<TileBasis, String> {
    let (rows, cols) = m.shape();
    let norm2: f64 = m
        .col_iter()
        .flat_map(|c| c.iter())
        .map(|&v| f64::from(v) * f64::from(v))
        .sum();
    // Texels and pane channels that are zero throughout decode to exact zeros (uncovered texels,
    // the panes a partial archive leaves empty): their basis rows and coefficients are set to 0.
    let zero_col: Vec<bool> = m.col_iter().map(|c| c.iter().all(|&v| v == 0.0)).collect();
    let mut zero_row = vec![true; rows];
    for c in m.col_iter() {
        for (z, &v) in zero_row.iter_mut().zip(c.iter()) {
            *z &= v == 0.0;
        }
    }
    let l = max_rank.saturating_add(OVERSAMPLING).min(rows).min(cols);
    if norm2 == 0.0 || l == 0 {
        return Ok(TileBasis {
            rank: 0,
            coefficients: Vec::new(),
            basis: Vec::new(),
        });
    }
    let product = |a: MatRef<'_, f32>, b: MatRef<'_, f32>| {
        let mut out = Mat::<f32>::zeros(a.nrows(), b.ncols());
        matmul(out.as_mut(), Accum::Replace, a, b, 1.0, Par::Seq);
        out
    };
    let omega = gaussian(cols, l, seed);
    let mut q = orthonormalize(product(m, omega.as_ref()));
    for _ in 0..POWER_ITERATIONS {
        let z = orthonormalize(product(m.transpose(), q.as_ref()));
        q = orthonormalize(product(m, z.as_ref()));
    }
    let b = product(q.transpose(), m);
    let ThinSvd { sigma, u: ub, v: vb } = thin_svd(b.as_ref())?;
    let rank = truncation_rank(norm2, &sigma, tolerance).min(max_rank);
    let u = product(q.as_ref(), ub.as_ref().get(.., ..rank));
    let mut basis = Vec::with_capacity(rows * rank);
    for (i, &zero) in zero_row.iter().enumerate() {
        basis.extend((0..rank).map(|k| {
            if zero {
                0.0
            } else {
                half::f16::from_f32(u[(i, k)]).to_f32()
            }
        }));
    }
    let mut coefficients = Vec::with_capacity(cols * rank);
    for (j, &zero) in zero_col.iter().enumerate() {
        coefficients.extend((0..rank).map(|k| if zero { 0.0 } else { sigma[k] * vb[(j, k)] }));
    }
    if rank > 0 {
        for pane in coefficients.chunks_exact_mut(3 * rank) {
            quantize_pane(pane);
        }
    }
    if !basis.iter().chain(&coefficients).all(|v| v.is_finite()) {
        return Err("the basis or its coefficients are not finite".into());
    }
    Ok(TileBasis {
        rank,
        coefficients,
        basis,
    })
}

/// The thin Q of `y` (rows ≥ columns): orthonormal columns spanning `y`'s.
fn orthonormalize(mut y: Mat<f32>) -> Mat<f32> {
    let (m, n) = y.shape();
    let bs = recommended_block_size::<f32>(m, n);
    let mut coeff = Mat::<f32>::zeros(bs, n);
    let mut mem = MemBuffer::new(qr_in_place_scratch::<f32>(m, n, bs, Par::Seq, default()).or(
        apply_block_householder_sequence_on_the_left_in_place_scratch::<f32>(m, bs, n),
    ));
    qr_in_place(y.as_mut(), coeff.as_mut(), Par::Seq, MemStack::new(&mut mem), default());
    let mut q = Mat::<f32>::identity(m, n);
    apply_block_householder_sequence_on_the_left_in_place_with_conj(
        y.as_ref(),
        coeff.as_ref(),
        Conj::No,
        q.as_mut(),
        Par::Seq,
        MemStack::new(&mut mem),
    );
    q
}

/// A thin SVD `B = Ũ·Σ·Vᵀ`.
struct ThinSvd {
    /// The singular values, non-increasing.
    sigma: Vec<f32>,
    /// `Ũ`, rows × min(rows, columns).
    u: Mat<f32>,
    /// `V`, columns × min(rows, columns).
    v: Mat<f32>,
}

/// The thin SVD of `b`.
fn thin_svd(b: MatRef<'_, f32>) -> Result<ThinSvd, String> {
    let (m, n) = b.shape();
    let size = m.min(n);
    let mut s = Diag::<f32>::zeros(size);
    let mut u = Mat::<f32>::zeros(m, size);
    let mut v = Mat::<f32>::zeros(n, size);
    let thin = ComputeSvdVectors::Thin;
    let mut mem = MemBuffer::new(svd_scratch::<f32>(m, n, thin, thin, Par::Seq, default()));
    svd(
        b,
        s.as_mut(),
        Some(u.as_mut()),
        Some(v.as_mut()),
        Par::Seq,
        MemStack::new(&mut mem),
        default(),
    )
    .map_err(|e| format!("the SVD failed ({e:?})"))?;
    let sigma = s.column_vector().iter().copied().collect();
    Ok(ThinSvd { sigma, u, v })
}

/// A `rows × cols` matrix of independent standard normal values from SplitMix64 seeded with
/// `seed` (Box–Muller), filled column by column.
fn gaussian(rows: usize, cols: usize, seed: u64) -> Mat<f32> {
    let mut state = seed;
    let mut next = move || {
        state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = state;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        // In (0, 1): never 0, so the logarithm is finite.
        (((z ^ (z >> 31)) >> 11) as f64 + 0.5) / (1u64 << 53) as f64
    };
    let mut values = Vec::with_capacity(rows * cols + 1);
    while values.len() < rows * cols {
        let (a, b) = (next(), next());
        let radius = (-2.0 * a.ln()).sqrt();
        let angle = std::f64::consts::TAU * b;
        values.push((radius * angle.cos()) as f32);
        values.push((radius * angle.sin()) as f32);
    }
    Mat::from_fn(rows, cols, |i, j| values[j * rows + i])
}

/// The panes section's fixed header.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Header {
    pub pane_count: u32,
    pub tiles_per_side: u32,
    pub max_rank: u32,
}

/// Parses the fixed 16-byte header; checks the pane count's limit and, when `strict`, the
/// reserved word.
pub(crate) fn decode_header(head: &[u8], strict: bool) -> Result<Header, String> {
    let [pane_count, tiles_per_side, max_rank, reserved] =
        Cursor::new(head, "panes").u32s().map_err(|e| e.to_string())?;
    check_reserved("panes header", strict, reserved)?;
    if u64::from(pane_count) > limits::MAX_CLUSTERS {
        return Err(format!("{pane_count} panes exceed the limit {}", limits::MAX_CLUSTERS));
    }
    Ok(Header {
        pane_count,
        tiles_per_side,
        max_rank,
    })
}

/// Checks the ranks against the header (its largest rank, each at most `min(T², 3P)`).
pub(crate) fn check_ranks(header: &Header, tile_size: u32, ranks: &[u32]) -> Result<(), String> {
    let bound = (u64::from(tile_size) * u64::from(tile_size)).min(3 * u64::from(header.pane_count));
    if let Some((t, &r)) = ranks.iter().enumerate().find(|(_, &r)| u64::from(r) > bound) {
        return Err(format!("panes tile {t} has rank {r}, more than min(T², 3P) = {bound}"));
    }
    let largest = ranks.iter().copied().max().unwrap_or(0);
    if largest != header.max_rank {
        return Err(format!(
            "panes header gives the largest rank {}, the tiles' largest is {largest}",
            header.max_rank
        ));
    }
    Ok(())
}

/// Raw size of the section for these counts, `None` on overflow:
/// `16 + 4·S² + 4·P·S² + Σ_t r_t·(6·P + 2·T²)`.
pub(crate) fn raw_size_for(pane_count: u32, tile_size: u32, ranks: &[u32]) -> Option<u64> {
    let per_rank = 6 * u64::from(pane_count) + 2 * u64::from(tile_size) * u64::from(tile_size);
    let ranks_total: u64 = ranks.iter().map(|&r| u64::from(r)).sum();
    let tiles = ranks.len() as u64;
    (PANES_HEADER_SIZE as u64 + 4 * tiles + 4 * tiles * u64::from(pane_count))
        .checked_add(ranks_total.checked_mul(per_rank)?)
}

/// Decodes whole `f32` scales; a negative, NaN or infinite one is refused.
pub(crate) fn decode_scales(raw: &[u8]) -> Result<Vec<f32>, String> {
    let values: Vec<f32> = raw
        .chunks_exact(4)
        .map(|w| f32::from_le_bytes([w[0], w[1], w[2], w[3]]))
        .collect();
    if values.iter().any(|v| !(v.is_finite() && *v >= 0.0)) {
        return Err("panes scales are not all finite and at least 0".into());
    }
    Ok(values)
}

/// Every tile's coefficients from their scales (`P` per tile, tile by tile) and their `f16`
/// values in byte planes; a NaN or infinity is refused.
pub(crate) fn decode_coefficients(
    pane_count: usize,
    ranks: &[u32],
    scales: &[f32],
    planes: &[u8],
) -> Result<Vec<Vec<f32>>, String> {
    let mut halves = from_planes::<2>(planes).map(half::f16::from_le_bytes);
    let mut out = Vec::with_capacity(ranks.len());
    for (t, &r) in ranks.iter().enumerate() {
        let r = r as usize;
        let mut c = Vec::with_capacity(3 * pane_count * r);
        for p in 0..pane_count {
            let scale = scales[t * pane_count + p];
            c.extend(halves.by_ref().take(3 * r).map(|h| from_half(h, scale)));
        }
        if c.iter().any(|v| !v.is_finite()) {
            return Err(format!("panes tile {t}'s coefficients are not all finite"));
        }
        out.push(c);
    }
    Ok(out)
}

/// Every tile's basis (row-major, `T²·r_t` values) from its `f16` values, column after column,
/// in byte planes; a NaN or infinity is refused.
pub(crate) fn decode_basis(texels: usize, ranks: &[u32], planes: &[u8]) -> Result<Vec<Vec<f32>>, String> {
    let mut halves = from_planes::<2>(planes).map(|h| half::f16::from_le_bytes(h).to_f32());
    let mut out = Vec::with_capacity(ranks.len());
    for (t, &r) in ranks.iter().enumerate() {
        let r = r as usize;
        let mut u = vec![0.0f32; texels * r];
        for k in 0..r {
            for (i, v) in halves.by_ref().take(texels).enumerate() {
                u[i * r + k] = v;
            }
        }
        if u.iter().any(|v| !v.is_finite()) {
            return Err(format!("panes tile {t}'s basis values are not all finite"));
        }
        out.push(u);
    }
    Ok(out)
}

/// Decodes whole `u32` ranks.
pub(crate) fn decode_ranks(raw: &[u8]) -> Result<Vec<u32>, String> {
    Ok(raw
        .chunks_exact(4)
        .map(|w| u32::from_le_bytes([w[0], w[1], w[2], w[3]]))
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::splitmix::Rng;

    fn unit(rng: &mut Rng) -> f32 {
        (rng.next() >> 40) as f32 / (1u64 << 24) as f32
    }

    /// Panes that are sums of `k` fixed images with per-pane weights: rank `k` in every tile.
    fn panes_of_rank(k: usize, panes: usize, res: usize, seed: u64) -> Vec<Vec<[f32; 3]>> {
        let mut rng = Rng(seed);
        let images: Vec<Vec<f32>> = (0..k)
            .map(|_| {
                let (cx, cy, w) = (
                    unit(&mut rng) * res as f32,
                    unit(&mut rng) * res as f32,
                    1.0 + unit(&mut rng),
                );
                (0..res * res)
                    .map(|i| {
                        let (x, y) = ((i % res) as f32, (i / res) as f32);
                        w / (1.0 + ((x - cx).powi(2) + (y - cy).powi(2)) / 8.0)
                    })
                    .collect()
            })
            .collect();
        (0..panes)
            .map(|_| {
                let w: Vec<[f32; 3]> = (0..k)
                    .map(|_| [unit(&mut rng), unit(&mut rng), unit(&mut rng)])
                    .collect();
                (0..res * res)
                    .map(|i| std::array::from_fn(|ch| (0..k).map(|j| w[j][ch] * images[j][i]).sum()))
                    .collect()
            })
            .collect()
    }

    #[test]
    fn rank_criterion() {
        // ‖M‖² = 1 + 0.25 + 0.0001: 1.2501.
        let s = [1.0, 0.5, 0.01];
        assert_eq!(truncation_rank(1.2501, &s, 0.5), 1);
        assert_eq!(truncation_rank(1.2501, &s, 0.02), 2);
        assert_eq!(truncation_rank(1.2501, &s, 0.0), 3);
        assert_eq!(truncation_rank(1.3, &s, 0.0), 3, "none within: all");
    }

    #[test]
    fn low_rank_panes_keep_their_rank_and_decode_exactly_enough() {
        let panes = panes_of_rank(2, 5, 16, 3);
        let basis = PaneBasis::compress(&panes, 16, 8, PANE_TOLERANCE, MAX_PANE_RANK).unwrap();
        assert_eq!(basis.ranks(), &[2, 2, 2, 2]);
        for (c, pane) in panes.iter().enumerate() {
            let got = basis.decode_pane(c).unwrap();
            for (g, w) in got.iter().zip(pane) {
                for ch in 0..3 {
                    assert!((g[ch] - w[ch]).abs() <= 2e-3 * w[ch].max(0.05), "{g:?} vs {w:?}");
                }
            }
        }
        // The texel rule and the pane decoder agree bit for bit.
        let pane = basis.decode_pane(4).unwrap();
        assert_eq!(pane[9 * 16 + 3], basis.decode_texel(4, 2, 8 + 3));
    }

    /// The basis blend is the weighted sum of the decoded panes where no pane dips below zero,
    /// and zero weights give zeros.
    #[test]
    fn blend_is_the_weighted_sum_of_the_panes() {
        let panes = panes_of_rank(3, 6, 16, 11);
        let basis = PaneBasis::compress(&panes, 16, 8, 0.0, MAX_PANE_RANK).unwrap();
        let weights: Vec<[f32; 3]> = (0..6)
            .map(|c| [c as f32 * 0.5, 1.0, if c == 2 { 0.0 } else { 2.0 }])
            .collect();
        let decoded: Vec<_> = (0..6).map(|c| basis.decode_pane(c).unwrap()).collect();
        let blended = basis.blend(&weights);
        for (i, b) in blended.iter().enumerate() {
            for ch in 0..3 {
                let sum: f32 = decoded.iter().zip(&weights).map(|(p, w)| w[ch] * p[i][ch]).sum();
                assert!((b[ch] - sum).abs() <= 1e-5 * sum.max(1.0), "texel {i}: {b:?} vs {sum}");
            }
        }
        assert!(basis.blend(&[[0.0; 3]; 6]).iter().all(|v| *v == [0.0; 3]));
    }

    #[test]
    fn energy_peak_is_the_decoded_panes() {
        let panes = panes_of_rank(3, 7, 16, 5);
        let basis = PaneBasis::compress(&panes, 16, 4, 0.01, 2).unwrap();
        assert!(basis.ranks().iter().all(|&r| r == 2), "capped: {:?}", basis.ranks());
        for (c, (energy, peak)) in basis.energy_peak().into_iter().enumerate() {
            let pane = basis.decode_pane(c).unwrap();
            let mut e = [0f64; 3];
            let mut p = [0f32; 3];
            for tile in 0..16 {
                let (x0, y0) = (tile % 4 * 4, tile / 4 * 4);
                for i in 0..16 {
                    let v = pane[(y0 + i / 4) * 16 + x0 + i % 4];
                    for ch in 0..3 {
                        e[ch] += f64::from(v[ch]);
                        p[ch] = p[ch].max(v[ch]);
                    }
                }
            }
            assert_eq!(energy, e.map(|x| x as f32));
            assert_eq!(peak, p);
        }
    }

    #[test]
    fn zero_tiles_have_rank_zero_and_bad_options_are_refused() {
        let mut panes = panes_of_rank(1, 2, 8, 9);
        for p in &mut panes {
            p[..32].fill([0.0; 3]); // the top half: tiles 0 and 1 of 4²
        }
        let basis = PaneBasis::compress(&panes, 8, 4, 0.02, 8).unwrap();
        assert_eq!(&basis.ranks()[..2], &[0, 0]);
        assert_eq!(basis.ranks()[2..], [1, 1]);
        let raw = basis.encode();
        assert_eq!(raw.len() as u64, basis.byte_size());
        assert_eq!(raw_size_for(2, 4, basis.ranks()), Some(basis.byte_size()));
        assert!(PaneBasis::compress(&panes, 8, 4, 1.0, 8).is_err());
        assert!(PaneBasis::compress(&panes, 8, 4, f32::NAN, 8).is_err());
        assert!(PaneBasis::compress(&panes, 8, 4, 0.02, 0).is_err());
        assert!(PaneBasis::compress(&panes, 8, 3, 0.02, 8).is_err());
        assert!(PaneBasis::compress(&panes, 16, 4, 0.02, 8).is_err());
        assert!(basis.decode_pane(2).is_err());
    }

    #[test]
    fn texels_and_panes_of_zeros_decode_to_exact_zeros() {
        // The first texels of every tile are zero in every pane, and pane 1 is zero throughout.
        let mut panes = panes_of_rank(5, 4, 16, 13);
        for p in &mut panes {
            for (i, t) in p.iter_mut().enumerate() {
                if i % 16 % 8 < 2 && i / 16 % 8 < 3 {
                    *t = [0.0; 3];
                }
            }
        }
        panes[1].fill([0.0; 3]);
        let basis = PaneBasis::compress(&panes, 16, 8, 0.05, 3).unwrap();
        assert!(basis.ranks().iter().all(|&r| r > 0));
        assert!(basis.decode_pane(1).unwrap().iter().flatten().all(|v| v.to_bits() == 0));
        for c in [0, 2, 3] {
            let pane = basis.decode_pane(c).unwrap();
            for (i, t) in pane.iter().enumerate() {
                let zero = i % 16 % 8 < 2 && i / 16 % 8 < 3;
                assert_eq!(zero, t.iter().all(|v| v.to_bits() == 0), "pane {c} texel {i}: {t:?}");
            }
        }
    }

    #[test]
    fn compression_is_deterministic() {
        let panes = panes_of_rank(4, 6, 16, 11);
        let a = PaneBasis::compress(&panes, 16, 8, 0.001, 16).unwrap();
        let b = PaneBasis::compress(&panes, 16, 8, 0.001, 16).unwrap();
        assert_eq!(a.encode(), b.encode());
    }
}
