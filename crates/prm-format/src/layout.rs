//! On-disk constants, limits and little-endian byte helpers of the format 2 layout.

use crate::error::{Error, Result};

/// The eight magic bytes every archive starts with: `\x89PRM\r\n\x1a\n`.
///
/// Like PNG's signature, the high byte catches 7-bit transfers and the
/// CR LF / ^Z / LF sequence catches newline translation.
pub const MAGIC: [u8; 8] = *b"\x89PRM\r\n\x1a\n";

/// Major version written by this library; a reader refuses any other major (format 1 archives
/// with [`Error::Rebake`]).
pub const VERSION_MAJOR: u16 = 2;
/// Minor version this library writes, and the highest it knows; a reader accepts every minor of
/// its major (a later minor only adds what this reader may ignore, formats/prm.md §2.1).
pub const VERSION_MINOR: u16 = 1;

/// Size of the fixed file header.
pub const HEADER_SIZE: usize = 64;
/// Size of one section table record.
pub const SECTION_RECORD_SIZE: usize = 48;
/// Size of the atlas section's fixed header.
pub const ATLAS_HEADER_SIZE: usize = 16;
/// Size of one entry record.
pub const ENTRY_RECORD_SIZE: usize = 28;
/// Size of one entry energy record.
pub const ENTRY_ENERGY_RECORD_SIZE: usize = 12;
/// Size of one cluster record.
pub const CLUSTER_RECORD_SIZE: usize = 56;

/// Section kind codes.
pub mod kind {
    /// JSON metadata.
    pub const METADATA: u32 = 1;
    /// Atlas layout: resolution, tiles, per-triangle UVs, coverage.
    pub const ATLAS: u32 = 2;
    /// Entry points.
    pub const ENTRIES: u32 = 3;
    /// Clusters of entry points.
    pub const CLUSTERS: u32 = 4;
    /// The panes, as a low-rank basis per atlas tile.
    pub const PANES: u32 = 5;
    /// Per-entry pane energy (optional).
    pub const ENTRY_ENERGY: u32 = 6;
    /// Emitter groups: entry irradiance and direct lightmaps (optional).
    pub const EMITTERS: u32 = 7;
    /// The sky's spherical-harmonic transfer at the atlas texels (optional).
    pub const SKY: u32 = 8;
    /// Irradiance probes and every cluster's spherical-harmonic transfer to them (optional).
    pub const PROBES: u32 = 9;
    /// Where every probe's rays meet the scene, to gather its light from the surfaces
    /// (optional; only beside the probes section).
    pub const PROBE_RAYS: u32 = 10;
    /// Where every exit point's near rays end, to gather back what the VPL bound removes
    /// (optional).
    pub const NEAR_FIELD: u32 = 11;
    /// Points of the surface every entry point stands for, to weigh it by the light its whole
    /// cell receives (optional).
    pub const ENTRY_CELLS: u32 = 12;
    /// First kind reserved for private extensions (never assigned by the spec).
    pub const PRIVATE_FIRST: u32 = 0x8000_0000;

    /// Human-readable name of a kind defined by the format, `None` for others.
    pub fn name(kind: u32) -> Option<&'static str> {
        match kind {
            METADATA => Some("metadata"),
            ATLAS => Some("atlas"),
            ENTRIES => Some("entries"),
            CLUSTERS => Some("clusters"),
            PANES => Some("panes"),
            ENTRY_ENERGY => Some("entry_energy"),
            ENTRY_CELLS => Some("entry_cells"),
            EMITTERS => Some("emitters"),
            SKY => Some("sky"),
            PROBES => Some("probes"),
            PROBE_RAYS => Some("probe_rays"),
            NEAR_FIELD => Some("near_field"),
            _ => None,
        }
    }
}

/// Compression codes of the section table.
pub mod compression {
    /// Stored as is; `raw_size == stored_size`.
    pub const NONE: u32 = 0;
    /// One or more zstd frames.
    pub const ZSTD: u32 = 1;

    /// Human-readable name of a compression code.
    pub fn name(code: u32) -> &'static str {
        match code {
            NONE => "none",
            ZSTD => "zstd",
            _ => "unknown",
        }
    }
}

/// Hard limits of the format; archives beyond them are rejected, which bounds
/// what a hostile file can make a reader allocate.
pub mod limits {
    /// Largest atlas resolution (texels per side).
    pub const MAX_RESOLUTION: u32 = 8192;
    /// Largest tile size (texels per side).
    pub const MAX_TILE_SIZE: u32 = 1024;
    /// Most triangles in the atlas section.
    pub const MAX_TRIANGLES: u64 = 1 << 24;
    /// Most entry points.
    pub const MAX_ENTRIES: u64 = 1 << 24;
    /// Most clusters (and therefore panes).
    pub const MAX_CLUSTERS: u64 = 1 << 20;
    /// Largest raw metadata JSON, in bytes.
    pub const MAX_METADATA_BYTES: u64 = 16 << 20;
    /// Most records in the section table.
    pub const MAX_SECTIONS: u32 = 65_536;
    /// Most emitter groups.
    pub const MAX_EMITTER_GROUPS: u32 = 256;
}

/// xxh3-64 (seed 0, default secret) of `bytes`: the checksum used everywhere.
#[inline]
pub fn checksum(bytes: &[u8]) -> u64 {
    xxhash_rust::xxh3::xxh3_64(bytes)
}

/// Bounds-checked little-endian cursor over a byte slice.
pub(crate) struct Cursor<'a> {
    data: &'a [u8],
    pos: usize,
    what: &'static str,
}

impl<'a> Cursor<'a> {
    pub(crate) fn new(data: &'a [u8], what: &'static str) -> Self {
        Cursor { data, pos: 0, what }
    }

    pub(crate) fn bytes(&mut self, n: usize) -> Result<&'a [u8]> {
        let end = self
            .pos
            .checked_add(n)
            .filter(|&e| e <= self.data.len())
            .ok_or_else(|| Error::inconsistent(format!("{} record runs past its end", self.what)))?;
        let s = &self.data[self.pos..end];
        self.pos = end;
        Ok(s)
    }

    pub(crate) fn array<const N: usize>(&mut self) -> Result<[u8; N]> {
        let mut a = [0u8; N];
        a.copy_from_slice(self.bytes(N)?);
        Ok(a)
    }

    pub(crate) fn u16(&mut self) -> Result<u16> {
        Ok(u16::from_le_bytes(self.array()?))
    }
    pub(crate) fn u32(&mut self) -> Result<u32> {
        Ok(u32::from_le_bytes(self.array()?))
    }
    pub(crate) fn u64(&mut self) -> Result<u64> {
        Ok(u64::from_le_bytes(self.array()?))
    }
    pub(crate) fn f32(&mut self) -> Result<f32> {
        Ok(f32::from_le_bytes(self.array()?))
    }
    pub(crate) fn vec3(&mut self) -> Result<[f32; 3]> {
        Ok([self.f32()?, self.f32()?, self.f32()?])
    }
    /// The next `N` little-endian `u32` words, as a section header's counts are stored.
    pub(crate) fn u32s<const N: usize>(&mut self) -> Result<[u32; N]> {
        let mut words = [0u32; N];
        for w in &mut words {
            *w = self.u32()?;
        }
        Ok(words)
    }
}

/// Refuses, when `strict`, a section header's non-zero reserved word: "`what` reserved field is
/// not zero".
pub(crate) fn check_reserved(what: &str, strict: bool, reserved: u32) -> std::result::Result<(), String> {
    if strict && reserved != 0 {
        return Err(format!("{what} reserved field is not zero"));
    }
    Ok(())
}

/// Refuses a section header whose flags hold a bit outside `known`, or whose reserved fields
/// are set (`reserved_set`, which the caller computes only when strict).
pub(crate) fn check_flags(
    section: &str,
    flags: u32,
    known: u32,
    reserved_set: bool,
) -> std::result::Result<(), String> {
    if flags & !known != 0 || reserved_set {
        return Err(format!(
            "{section} section has unknown flags {flags:#x} or a non-zero reserved field"
        ));
    }
    Ok(())
}

/// Refuses a section header's count of rays per `per` (exit, probe) outside `1..=max`.
pub(crate) fn check_ray_count(section: &str, rays: u32, per: &str, max: u32) -> std::result::Result<(), String> {
    if rays == 0 || rays > max {
        return Err(format!(
            "{section} section has {rays} rays per {per}, not between 1 and {max}"
        ));
    }
    Ok(())
}

/// The little-endian `u32` at byte `offset` of a record.
pub(crate) fn u32_at(record: &[u8], offset: usize) -> u32 {
    u32::from_le_bytes(record[offset..offset + 4].try_into().expect("4 bytes"))
}

/// Little-endian appenders for building records.
pub(crate) trait PutLe {
    fn put_u16(&mut self, v: u16);
    fn put_u32(&mut self, v: u32);
    fn put_u64(&mut self, v: u64);
    fn put_f32(&mut self, v: f32);
    fn put_vec3(&mut self, v: [f32; 3]) {
        for c in v {
            self.put_f32(c);
        }
    }
}

impl PutLe for Vec<u8> {
    fn put_u16(&mut self, v: u16) {
        self.extend_from_slice(&v.to_le_bytes());
    }
    fn put_u32(&mut self, v: u32) {
        self.extend_from_slice(&v.to_le_bytes());
    }
    fn put_u64(&mut self, v: u64) {
        self.extend_from_slice(&v.to_le_bytes());
    }
    fn put_f32(&mut self, v: f32) {
        self.extend_from_slice(&v.to_le_bytes());
    }
}

/// A fixed-size little-endian field of a record.
pub(crate) trait Field: Sized {
    fn put(self, b: &mut Vec<u8>);
    fn take(c: &mut Cursor<'_>) -> Result<Self>;
}

impl Field for u32 {
    fn put(self, b: &mut Vec<u8>) {
        b.put_u32(self);
    }
    fn take(c: &mut Cursor<'_>) -> Result<Self> {
        c.u32()
    }
}

impl Field for u64 {
    fn put(self, b: &mut Vec<u8>) {
        b.put_u64(self);
    }
    fn take(c: &mut Cursor<'_>) -> Result<Self> {
        c.u64()
    }
}

impl Field for [f32; 3] {
    fn put(self, b: &mut Vec<u8>) {
        b.put_vec3(self);
    }
    fn take(c: &mut Cursor<'_>) -> Result<Self> {
        c.vec3()
    }
}

/// Gives a record struct `encode_into` and `decode`, its fields stored in the order listed, each
/// as its [`Field`] encoding.
macro_rules! record_codec {
    ($ty:ident { $($field:ident),* $(,)? }) => {
        impl $ty {
            pub(crate) fn encode_into(&self, b: &mut Vec<u8>) {
                $($crate::layout::Field::put(self.$field, b);)*
            }

            pub(crate) fn decode(c: &mut $crate::layout::Cursor<'_>) -> $crate::error::Result<$ty> {
                Ok($ty {
                    $($field: $crate::layout::Field::take(c)?,)*
                })
            }
        }
    };
}
pub(crate) use record_codec;

/// The fixed 64-byte file header.
#[derive(Clone, Debug, PartialEq, Eq)]
pub(crate) struct Header {
    pub major: u16,
    pub minor: u16,
    pub section_count: u32,
    pub table_offset: u64,
    pub file_length: u64,
    pub reserved: [u64; 2],
    pub table_checksum: u64,
}

impl Header {
    pub(crate) fn encode(&self) -> Vec<u8> {
        let mut b = Vec::with_capacity(HEADER_SIZE);
        b.extend_from_slice(&MAGIC);
        b.put_u16(self.major);
        b.put_u16(self.minor);
        b.put_u32(self.section_count);
        b.put_u64(self.table_offset);
        b.put_u64(self.file_length);
        b.put_u64(self.reserved[0]);
        b.put_u64(self.reserved[1]);
        b.put_u64(self.table_checksum);
        let sum = checksum(&b);
        b.put_u64(sum);
        b
    }

    /// Parses and checks a header: magic, then version, then checksum (the
    /// version is checked first because another major may lay the header out
    /// differently). A format 1 archive is [`Error::Rebake`], another major
    /// [`Error::UnsupportedVersion`].
    pub(crate) fn decode(b: &[u8]) -> Result<Header> {
        let prefix = b.len().min(MAGIC.len());
        if b[..prefix] != MAGIC[..prefix] {
            return Err(Error::BadMagic);
        }
        if b.len() < HEADER_SIZE {
            return Err(Error::truncated(format!(
                "the file has {} bytes, the header alone needs {HEADER_SIZE}",
                b.len()
            )));
        }
        let mut c = Cursor::new(b, "header");
        c.bytes(MAGIC.len())?;
        let major = c.u16()?;
        let minor = c.u16()?;
        if major == 1 {
            return Err(Error::Rebake { major, minor });
        }
        if major != VERSION_MAJOR {
            return Err(Error::UnsupportedVersion { major, minor });
        }
        let h = Header {
            major,
            minor,
            section_count: c.u32()?,
            table_offset: c.u64()?,
            file_length: c.u64()?,
            reserved: [c.u64()?, c.u64()?],
            table_checksum: c.u64()?,
        };
        let stored = c.u64()?;
        if checksum(&b[..HEADER_SIZE - 8]) != stored {
            return Err(Error::checksum("header"));
        }
        Ok(h)
    }

    /// Whether reserved fields must be zero: only for minors this library
    /// knows (a later minor may give them a meaning).
    #[allow(
        clippy::absurd_extreme_comparisons,
        reason = "the rule is for every minor this library knows, the first of which is 0"
    )]
    pub(crate) fn strict_reserved(&self) -> bool {
        self.minor <= VERSION_MINOR
    }
}

/// One record of the section table as stored.
#[derive(Clone, Debug, PartialEq, Eq)]
pub(crate) struct SectionRecord {
    pub kind: u32,
    pub compression: u32,
    pub offset: u64,
    pub stored_size: u64,
    pub raw_size: u64,
    pub checksum: u64,
    pub reserved: u64,
}

record_codec!(SectionRecord {
    kind,
    compression,
    offset,
    stored_size,
    raw_size,
    checksum,
    reserved
});

/// Byte planes (formats/prm.md §1): `values` little-endian values of `W` bytes each, stored as
/// `W` planes, plane `b` holding byte `b` of every value in order. Neighbouring values share their
/// high bytes, which zstd then finds in long runs.
pub(crate) fn to_planes<const W: usize>(values: impl ExactSizeIterator<Item = [u8; W]>) -> Vec<u8> {
    let n = values.len();
    let mut out = vec![0u8; n * W];
    for (i, v) in values.enumerate() {
        for (b, &byte) in v.iter().enumerate() {
            out[b * n + i] = byte;
        }
    }
    out
}

/// The values of `W` bytes that [`to_planes`] stored in `planes` (whose length is a multiple of
/// `W`).
pub(crate) fn from_planes<const W: usize>(planes: &[u8]) -> impl ExactSizeIterator<Item = [u8; W]> + '_ {
    let n = planes.len() / W;
    (0..n).map(move |i| std::array::from_fn(|b| planes[b * n + i]))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn header_round_trip_and_checks() {
        let h = Header {
            major: 2,
            minor: 0,
            section_count: 5,
            table_offset: 1000,
            file_length: 1240,
            reserved: [0, 0],
            table_checksum: 42,
        };
        let b = h.encode();
        assert_eq!(b.len(), HEADER_SIZE);
        assert_eq!(Header::decode(&b).unwrap(), h);
        let mut bad = b.clone();
        bad[20] ^= 1;
        assert!(matches!(Header::decode(&bad), Err(Error::ChecksumMismatch { .. })));
        let mut bad = b.clone();
        bad[0] = b'X';
        assert!(matches!(Header::decode(&bad), Err(Error::BadMagic)));
        assert!(matches!(Header::decode(&b[..30]), Err(Error::Truncated { .. })));
        assert!(matches!(Header::decode(&b[..3]), Err(Error::Truncated { .. })));
        let mut newer = b.clone();
        newer[8] = 3;
        assert!(matches!(
            Header::decode(&newer),
            Err(Error::UnsupportedVersion { major: 3, minor: 0 })
        ));
        let mut older = b.clone();
        older[8] = 1;
        older[10] = 9;
        let err = Header::decode(&older).unwrap_err();
        assert!(matches!(err, Error::Rebake { major: 1, minor: 9 }), "{err}");
        assert!(err.to_string().contains("re-bake"), "{err}");
    }

    #[test]
    fn cursor_is_bounds_checked() {
        let mut c = Cursor::new(&[1, 0, 0, 0, 5], "test");
        assert_eq!(c.u32().unwrap(), 1);
        assert!(c.u32().is_err());
        assert!(c.bytes(usize::MAX).is_err());
    }

    #[test]
    fn record_sizes_match_constants() {
        let mut b = Vec::new();
        SectionRecord {
            kind: 1,
            compression: 0,
            offset: 0,
            stored_size: 0,
            raw_size: 0,
            checksum: 0,
            reserved: 0,
        }
        .encode_into(&mut b);
        assert_eq!(b.len(), SECTION_RECORD_SIZE);
    }

    #[test]
    fn byte_planes_round_trip() {
        let values: Vec<[u8; 4]> = [1u32, 0x0102_0304, u32::MAX].iter().map(|v| v.to_le_bytes()).collect();
        let planes = to_planes(values.iter().copied());
        assert_eq!(planes, [1, 4, 0xff, 0, 3, 0xff, 0, 2, 0xff, 0, 1, 0xff]);
        assert_eq!(from_planes::<4>(&planes).collect::<Vec<_>>(), values);
    }
}
