//! Pane encoding apart from the writer: RGB9E5, the tile filter and zstd, tile by tile.
//!
//! Encoding is most of the cost of writing a pane (on chairs, 256 panes of 256², 0.8 of the
//! bake's 7.5 s), and it needs nothing from the file. A [`PaneEncoder`] does it on any thread;
//! [`crate::ArchiveWriter::add_encoded_pane`] then only appends the bytes. A producer holding
//! many panes (the CPU bake renders them all at once) encodes them in parallel and adds them in
//! order; [`crate::ArchiveWriter::add_pane`] is the same two steps on one thread, so both write
//! the same bytes.

use crate::error::{Error, Result};
use crate::filter::TileFilter;
use crate::rgb9e5::{decode_rgb9e5, encode_rgb9e5};

/// A pane ready to be appended by [`crate::ArchiveWriter::add_encoded_pane`].
#[derive(Clone, Debug)]
pub struct EncodedPane {
    pub(crate) resolution: u32,
    pub(crate) tile_size: u32,
    pub(crate) filter: TileFilter,
    pub(crate) zstd_level: i32,
    /// Compressed tiles in row-major tile order; empty for a tile whose texels all encode to 0
    /// (stored as a zero record, formats/prm.md §6).
    pub(crate) tiles: Vec<Vec<u8>>,
    pub(crate) energy: [f64; 3],
    pub(crate) peak: [f32; 3],
}

impl EncodedPane {
    /// The sum of the decoded texels per channel, as the cluster table records it.
    pub fn energy(&self) -> [f32; 3] {
        self.energy.map(|e| e as f32)
    }
}

/// Encodes panes for archives of one atlas layout (from [`crate::ArchiveWriter::pane_encoder`]).
pub struct PaneEncoder {
    resolution: u32,
    tile_size: u32,
    filter: TileFilter,
    zstd_level: i32,
    compressor: zstd::bulk::Compressor<'static>,
    texels: Vec<[f32; 3]>,
    words: Vec<u32>,
    bytes: Vec<u8>,
}

impl PaneEncoder {
    pub(crate) fn new(resolution: u32, tile_size: u32, filter: TileFilter, zstd_level: i32) -> Result<PaneEncoder> {
        let n = tile_size as usize * tile_size as usize;
        Ok(PaneEncoder {
            resolution,
            tile_size,
            filter,
            zstd_level,
            compressor: zstd::bulk::Compressor::new(zstd_level)?,
            texels: vec![[0.0; 3]; n],
            words: Vec::with_capacity(n),
            bytes: Vec::with_capacity(n * 4),
        })
    }

    /// Encodes a pane produced tile by tile: `fill(tile_x, tile_y, texels)` as
    /// [`crate::ArchiveWriter::add_pane_with`] calls it.
    pub fn encode_with<F>(&mut self, mut fill: F) -> Result<EncodedPane>
    where
        F: FnMut(u32, u32, &mut [[f32; 3]]),
    {
        let per_side = self.resolution / self.tile_size;
        let mut pane = EncodedPane {
            resolution: self.resolution,
            tile_size: self.tile_size,
            filter: self.filter,
            zstd_level: self.zstd_level,
            tiles: Vec::with_capacity((per_side * per_side) as usize),
            energy: [0.0; 3],
            peak: [0.0; 3],
        };
        for ty in 0..per_side {
            for tx in 0..per_side {
                self.texels.fill([0.0; 3]);
                fill(tx, ty, &mut self.texels);
                let tile = self.encode_tile(&mut pane.energy, &mut pane.peak)?;
                pane.tiles.push(tile);
            }
        }
        Ok(pane)
    }

    /// Encodes a pane from a full `resolution²` row-major RGB image.
    pub fn encode(&mut self, texels: &[[f32; 3]]) -> Result<EncodedPane> {
        let res = self.resolution as usize;
        if texels.len() != res * res {
            return Err(Error::InvalidInput(format!(
                "pane has {} texels, resolution {res} needs {}",
                texels.len(),
                res * res
            )));
        }
        let t = self.tile_size as usize;
        self.encode_with(|tx, ty, tile| {
            for j in 0..t {
                let row = (ty as usize * t + j) * res + tx as usize * t;
                tile[j * t..(j + 1) * t].copy_from_slice(&texels[row..row + t]);
            }
        })
    }

    /// Encodes and compresses the tile in `self.texels`; accumulates the energy and peak of the
    /// decoded texels in the order the spec prescribes. Empty for an all-zero tile.
    fn encode_tile(&mut self, energy: &mut [f64; 3], peak: &mut [f32; 3]) -> Result<Vec<u8>> {
        self.words.clear();
        self.words.extend(self.texels.iter().map(|&t| encode_rgb9e5(t)));
        if self.words.iter().all(|&w| w == 0) {
            return Ok(Vec::new());
        }
        for &w in &self.words {
            let d = decode_rgb9e5(w);
            for c in 0..3 {
                energy[c] += f64::from(d[c]);
                peak[c] = peak[c].max(d[c]);
            }
        }
        self.filter.apply(&self.words, &mut self.bytes);
        Ok(self.compressor.compress(&self.bytes)?)
    }
}
