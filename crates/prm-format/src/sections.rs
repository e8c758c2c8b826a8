//! Atlas, entry and cluster sections: types, binary encoding and validation.

use std::ops::Range;

use crate::error::Result;
use crate::layout::{
    check_reserved, limits, record_codec, Cursor, PutLe, ATLAS_HEADER_SIZE, CLUSTER_RECORD_SIZE,
    ENTRY_ENERGY_RECORD_SIZE, ENTRY_RECORD_SIZE,
};

/// The lightmap atlas shared by every pane.
#[derive(Clone, Debug, PartialEq)]
pub struct AtlasSection {
    /// Texels per side of the (square) atlas and of every pane.
    pub resolution: u32,
    /// Texels per side of a tile; divides `resolution`.
    pub tile_size: u32,
    /// Lightmap UVs of every scene triangle, in scene triangle order: three
    /// `[u, v]` pairs in `[0, 1]`, texel `(x, y)` having its centre at
    /// `((x + 0.5) / resolution, (y + 0.5) / resolution)`.
    pub triangle_uvs: Vec<[[f32; 2]; 3]>,
    /// One bit per texel, set where some triangle covers the texel; texel
    /// `(x, y)` is bit `i % 8` (LSB first) of byte `i / 8`, `i = y·resolution + x`.
    pub coverage: Vec<u8>,
}

impl AtlasSection {
    /// An atlas with no triangles and nothing covered.
    pub fn new(resolution: u32, tile_size: u32) -> Self {
        AtlasSection {
            resolution,
            tile_size,
            triangle_uvs: Vec::new(),
            coverage: vec![0; Self::coverage_len(resolution)],
        }
    }

    /// Bytes of a packed coverage mask for `resolution`: `ceil(resolution² / 8)`.
    pub fn coverage_len(resolution: u32) -> usize {
        (u64::from(resolution) * u64::from(resolution)).div_ceil(8) as usize
    }

    /// Tiles per side (`resolution / tile_size`).
    pub fn tiles_per_side(&self) -> u32 {
        self.resolution.checked_div(self.tile_size).unwrap_or(0)
    }

    /// Texels per pane (`resolution²`).
    pub fn texels_per_pane(&self) -> usize {
        self.resolution as usize * self.resolution as usize
    }

    fn bit(&self, x: u32, y: u32) -> Option<(usize, u8)> {
        if x >= self.resolution || y >= self.resolution {
            return None;
        }
        let i = y as usize * self.resolution as usize + x as usize;
        Some((i / 8, 1u8 << (i % 8)))
    }

    /// Whether texel `(x, y)` is covered; `false` outside the atlas.
    pub fn is_covered(&self, x: u32, y: u32) -> bool {
        self.bit(x, y)
            .and_then(|(byte, mask)| self.coverage.get(byte).map(|b| b & mask != 0))
            .unwrap_or(false)
    }

    /// Sets or clears the coverage bit of texel `(x, y)`; ignored outside the atlas.
    pub fn set_covered(&mut self, x: u32, y: u32, covered: bool) {
        if let Some((byte, mask)) = self.bit(x, y) {
            if let Some(b) = self.coverage.get_mut(byte) {
                if covered {
                    *b |= mask;
                } else {
                    *b &= !mask;
                }
            }
        }
    }

    /// Number of covered texels.
    pub fn covered_texels(&self) -> u64 {
        self.coverage.iter().map(|b| u64::from(b.count_ones())).sum()
    }

    /// Raw size of the encoded section, `None` on overflow.
    pub(crate) fn raw_size_for(resolution: u32, triangles: u64) -> Option<u64> {
        let mask = (u64::from(resolution) * u64::from(resolution)).div_ceil(8);
        triangles
            .checked_mul(24)?
            .checked_add(ATLAS_HEADER_SIZE as u64)?
            .checked_add(mask)
    }

    pub(crate) fn validate(&self) -> Result<(), String> {
        let r = self.resolution;
        if r == 0 || r > limits::MAX_RESOLUTION {
            return Err(format!("atlas resolution {r} outside 1..={}", limits::MAX_RESOLUTION));
        }
        let t = self.tile_size;
        if t == 0 || t > limits::MAX_TILE_SIZE || t > r || !r.is_multiple_of(t) {
            return Err(format!(
                "tile size {t} must be in 1..={} and divide the resolution {r}",
                limits::MAX_TILE_SIZE
            ));
        }
        if self.triangle_uvs.len() as u64 > limits::MAX_TRIANGLES {
            return Err(format!("{} triangles exceed the limit", self.triangle_uvs.len()));
        }
        for (i, tri) in self.triangle_uvs.iter().enumerate() {
            if tri.iter().flatten().any(|c| !(0.0..=1.0).contains(c)) {
                return Err(format!("triangle {i} has UVs outside [0, 1]: {tri:?}"));
            }
        }
        if self.coverage.len() != Self::coverage_len(r) {
            return Err(format!(
                "coverage mask has {} bytes, resolution {r} needs {}",
                self.coverage.len(),
                Self::coverage_len(r)
            ));
        }
        let used_bits = (u64::from(r) * u64::from(r) % 8) as u32;
        if used_bits != 0 {
            let last = self.coverage.last().copied().unwrap_or(0);
            if last >> used_bits != 0 {
                return Err("coverage mask padding bits are not zero".into());
            }
        }
        Ok(())
    }

    pub(crate) fn encode(&self) -> Vec<u8> {
        let mut b = Vec::with_capacity(ATLAS_HEADER_SIZE + self.triangle_uvs.len() * 24 + self.coverage.len());
        b.put_u32(self.resolution);
        b.put_u32(self.tile_size);
        b.put_u32(self.triangle_uvs.len() as u32);
        b.put_u32(0);
        for tri in &self.triangle_uvs {
            for uv in tri {
                b.put_f32(uv[0]);
                b.put_f32(uv[1]);
            }
        }
        b.extend_from_slice(&self.coverage);
        b
    }

    /// Parses the fixed 16-byte header: `(resolution, tile_size, triangles)`.
    /// Checks the reserved field (if `strict`), the resolution and the
    /// triangle limit, which fix the section's raw size; the tile size is
    /// checked by [`validate`](Self::validate).
    pub(crate) fn decode_header(head: &[u8], strict: bool) -> Result<(u32, u32, u32), String> {
        let [resolution, tile_size, triangles, reserved] =
            Cursor::new(head, "atlas").u32s().map_err(|e| e.to_string())?;
        check_reserved("atlas", strict, reserved)?;
        if resolution == 0 || resolution > limits::MAX_RESOLUTION {
            return Err(format!(
                "atlas resolution {resolution} outside 1..={}",
                limits::MAX_RESOLUTION
            ));
        }
        if u64::from(triangles) > limits::MAX_TRIANGLES {
            return Err(format!(
                "{triangles} atlas triangles exceed the limit {}",
                limits::MAX_TRIANGLES
            ));
        }
        Ok((resolution, tile_size, triangles))
    }

    /// Decodes whole 24-byte triangle UV records.
    pub(crate) fn decode_uvs(raw: &[u8]) -> Result<Vec<[[f32; 2]; 3]>, String> {
        let mut c = Cursor::new(raw, "atlas");
        let mut out = Vec::with_capacity(raw.len() / 24);
        while out.len() < raw.len() / 24 {
            let mut tri = [[0.0f32; 2]; 3];
            for uv in &mut tri {
                *uv = [c.f32().map_err(|e| e.to_string())?, c.f32().map_err(|e| e.to_string())?];
            }
            out.push(tri);
        }
        Ok(out)
    }

    /// Decodes raw section bytes; `strict` demands zero reserved fields.
    #[cfg(test)]
    pub(crate) fn decode(raw: &[u8], strict: bool) -> Result<Self, String> {
        let head = raw.get(..ATLAS_HEADER_SIZE).ok_or("atlas record runs past its end")?;
        let (resolution, tile_size, triangles) = Self::decode_header(head, strict)?;
        let expected = Self::raw_size_for(resolution, u64::from(triangles));
        if expected != Some(raw.len() as u64) {
            return Err(format!(
                "atlas section has {} raw bytes, resolution {resolution} and {triangles} triangles need {expected:?}",
                raw.len()
            ));
        }
        let uv_end = ATLAS_HEADER_SIZE + triangles as usize * 24;
        let atlas = AtlasSection {
            resolution,
            tile_size,
            triangle_uvs: Self::decode_uvs(&raw[ATLAS_HEADER_SIZE..uv_end])?,
            coverage: raw[uv_end..].to_vec(),
        };
        atlas.validate()?;
        Ok(atlas)
    }
}

/// An entry point: a surface sample whose radiance transfer a pane stores.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Entry {
    /// World-space position.
    pub position: [f32; 3],
    /// World-space unit normal.
    pub normal: [f32; 3],
    /// Index of the cluster the entry belongs to.
    pub cluster: u32,
}

/// A cluster of entry points, owning one pane.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Cluster {
    /// Index of the first member in the entry list (entries are sorted by cluster).
    pub first: u32,
    /// Number of members.
    pub count: u32,
    /// Mean position of the members.
    pub centroid: [f32; 3],
    /// Mean normal of the members.
    pub mean_normal: [f32; 3],
    /// Sum of the cluster's pane texels (RGB); computed by the writer.
    pub energy: [f32; 3],
    /// Per-channel maximum of the pane texels; computed by the writer.
    pub peak: [f32; 3],
}

impl Cluster {
    /// A cluster with zero energy and peak (the writer fills both in).
    pub fn new(first: u32, count: u32, centroid: [f32; 3], mean_normal: [f32; 3]) -> Self {
        Cluster {
            first,
            count,
            centroid,
            mean_normal,
            energy: [0.0; 3],
            peak: [0.0; 3],
        }
    }

    /// Indices of the members in the entry list.
    pub fn members(&self) -> Range<usize> {
        self.first as usize..self.first as usize + self.count as usize
    }
}

fn finite3(v: &[f32; 3]) -> bool {
    v.iter().all(|c| c.is_finite())
}

record_codec!(Entry {
    position,
    normal,
    cluster
});
record_codec!(Cluster {
    first,
    count,
    centroid,
    mean_normal,
    energy,
    peak
});

/// Records of `size` bytes each, one after the other.
fn encode_records<T>(items: &[T], size: usize, encode_into: impl Fn(&T, &mut Vec<u8>)) -> Vec<u8> {
    let mut b = Vec::with_capacity(items.len() * size);
    for item in items {
        encode_into(item, &mut b);
    }
    b
}

/// Decodes a section of whole `size`-byte records; `what` names the section in errors.
fn decode_records<T>(
    raw: &[u8],
    size: usize,
    what: &'static str,
    decode: impl Fn(&mut Cursor<'_>) -> Result<T>,
) -> Result<Vec<T>, String> {
    if !raw.len().is_multiple_of(size) {
        return Err(format!("{what} section size {} is not a multiple of {size}", raw.len()));
    }
    let n = raw.len() / size;
    let mut c = Cursor::new(raw, what);
    let mut out = Vec::with_capacity(n);
    for _ in 0..n {
        out.push(decode(&mut c).map_err(|e| e.to_string())?);
    }
    Ok(out)
}

pub(crate) fn encode_entries(entries: &[Entry]) -> Vec<u8> {
    encode_records(entries, ENTRY_RECORD_SIZE, Entry::encode_into)
}

pub(crate) fn decode_entries(raw: &[u8]) -> Result<Vec<Entry>, String> {
    decode_records(raw, ENTRY_RECORD_SIZE, "entries", Entry::decode)
}

pub(crate) fn encode_entry_energy(energy: &[[f32; 3]]) -> Vec<u8> {
    encode_records(energy, ENTRY_ENERGY_RECORD_SIZE, |e, b| b.put_vec3(*e))
}

pub(crate) fn decode_entry_energy(raw: &[u8]) -> Result<Vec<[f32; 3]>, String> {
    let energy = decode_records(raw, ENTRY_ENERGY_RECORD_SIZE, "entry_energy", |c| c.vec3())?;
    for (i, e) in energy.iter().enumerate() {
        if !e.iter().all(|v| v.is_finite() && *v >= 0.0) {
            return Err(format!("entry {i}'s energy {e:?} is not finite and non-negative"));
        }
    }
    Ok(energy)
}

pub(crate) fn encode_clusters(clusters: &[Cluster]) -> Vec<u8> {
    encode_records(clusters, CLUSTER_RECORD_SIZE, Cluster::encode_into)
}

pub(crate) fn decode_clusters(raw: &[u8]) -> Result<Vec<Cluster>, String> {
    decode_records(raw, CLUSTER_RECORD_SIZE, "clusters", Cluster::decode)
}

/// Number of entries the cluster ranges cover, checking that they tile
/// `[0, n)` in order (cluster 0 starts at 0, each starts where the previous
/// ended). Read before the entries section, whose raw size it fixes.
pub(crate) fn entries_covered(clusters: &[Cluster]) -> Result<u64, String> {
    let mut next = 0u64;
    for (ci, c) in clusters.iter().enumerate() {
        if u64::from(c.first) != next {
            return Err(format!(
                "cluster {ci} starts at entry {}, expected {next} (ranges must tile the entries in order)",
                c.first
            ));
        }
        next += u64::from(c.count);
    }
    Ok(next)
}

/// Checks entries and clusters against each other: finite values, entries
/// sorted by cluster, cluster ranges tiling the entry list in order.
pub(crate) fn validate_entries_clusters(entries: &[Entry], clusters: &[Cluster]) -> Result<(), String> {
    if entries.len() as u64 > limits::MAX_ENTRIES {
        return Err(format!(
            "{} entries exceed the limit {}",
            entries.len(),
            limits::MAX_ENTRIES
        ));
    }
    if clusters.len() as u64 > limits::MAX_CLUSTERS {
        return Err(format!(
            "{} clusters exceed the limit {}",
            clusters.len(),
            limits::MAX_CLUSTERS
        ));
    }
    for (i, e) in entries.iter().enumerate() {
        if !finite3(&e.position) || !finite3(&e.normal) {
            return Err(format!("entry {i} has a non-finite position or normal"));
        }
    }
    let covered = entries_covered(clusters)?;
    if covered != entries.len() as u64 {
        return Err(format!(
            "clusters cover {covered} entries but there are {}",
            entries.len()
        ));
    }
    for (ci, c) in clusters.iter().enumerate() {
        for (k, e) in entries[c.members()].iter().enumerate() {
            if e.cluster as usize != ci {
                return Err(format!(
                    "entry {} lies in cluster {ci}'s range but names cluster {}",
                    c.first as usize + k,
                    e.cluster
                ));
            }
        }
        if !finite3(&c.centroid) || !finite3(&c.mean_normal) {
            return Err(format!("cluster {ci} has a non-finite centroid or normal"));
        }
        for v in c.energy.iter().chain(&c.peak) {
            if !(v.is_finite() && *v >= 0.0) {
                return Err(format!("cluster {ci} has a negative or non-finite energy/peak"));
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn atlas() -> AtlasSection {
        let mut a = AtlasSection::new(6, 3);
        a.triangle_uvs.push([[0.0, 0.0], [1.0, 0.0], [0.5, 1.0]]);
        a.set_covered(5, 5, true);
        a.set_covered(0, 1, true);
        a
    }

    #[test]
    fn atlas_round_trip() {
        let a = atlas();
        assert_eq!(a.coverage.len(), 5); // 36 bits
        assert!(a.is_covered(5, 5) && a.is_covered(0, 1) && !a.is_covered(1, 1));
        assert!(!a.is_covered(6, 0));
        assert_eq!(a.covered_texels(), 2);
        let raw = a.encode();
        assert_eq!(raw.len() as u64, AtlasSection::raw_size_for(6, 1).unwrap());
        assert_eq!(AtlasSection::decode(&raw, true).unwrap(), a);
    }

    #[test]
    fn atlas_rejects_bad_layouts() {
        let mut a = atlas();
        a.tile_size = 4;
        assert!(a.validate().is_err());
        let mut a = atlas();
        a.triangle_uvs[0][1][0] = f32::NAN;
        assert!(a.validate().is_err());
        let mut a = atlas();
        *a.coverage.last_mut().unwrap() |= 0x80; // padding bit
        assert!(a.validate().is_err());
        let raw = atlas().encode();
        assert!(AtlasSection::decode(&raw[..raw.len() - 1], true).is_err());
        let mut r = raw.clone();
        r[12] = 1;
        assert!(AtlasSection::decode(&r, true).is_err());
        assert!(AtlasSection::decode(&r, false).is_ok());
    }

    #[test]
    fn entries_and_clusters_round_trip_and_validate() {
        let entry = |p: f32, normal: [f32; 3], cluster: u32| Entry {
            position: [p; 3],
            normal,
            cluster,
        };
        let entries = vec![
            entry(0.0, [0.0, 1.0, 0.0], 0),
            entry(1.0, [0.0, 1.0, 0.0], 0),
            entry(2.0, [1.0, 0.0, 0.0], 2),
        ];
        let clusters = vec![
            Cluster::new(0, 2, [0.5; 3], [0.0, 1.0, 0.0]),
            Cluster::new(2, 0, [0.0; 3], [0.0, 1.0, 0.0]),
            Cluster::new(2, 1, [2.0; 3], [1.0, 0.0, 0.0]),
        ];
        validate_entries_clusters(&entries, &clusters).unwrap();
        assert_eq!(decode_entries(&encode_entries(&entries)).unwrap(), entries);
        assert_eq!(decode_clusters(&encode_clusters(&clusters)).unwrap(), clusters);

        let mut bad = clusters.clone();
        bad[2].count = 2;
        assert!(validate_entries_clusters(&entries, &bad).is_err());
        let mut bad = entries.clone();
        bad[2].cluster = 1;
        assert!(validate_entries_clusters(&bad, &clusters).is_err());
        assert!(validate_entries_clusters(&entries[..2], &clusters).is_err());
        assert!(decode_entries(&[0; 27]).is_err());
    }
}
