//! Lightmaps as KTX2 (Khronos Texture 2.0): one 2D level in `VK_FORMAT_E5B9G9R9_UFLOAT_PACK32`
//! (RGB9E5: three 9-bit mantissas sharing a 5-bit exponent, the format the run time keeps its
//! panes in), with Zstandard supercompression. Engines load it without conversion: Bevy's KTX2
//! loader (features `ktx2` and `zstd`) maps the format to `Rgb9e5Ufloat`.
//!
//! The layout follows the KTX 2.0 specification: the 80-byte header and index, one level index
//! entry, the data format descriptor (a Khronos basic block with one mantissa and one exponent
//! sample per channel, as the Khronos Data Format specification describes shared-exponent
//! formats), a `KTXwriter` key/value entry, then the compressed level.

use std::io::Write;
use std::path::Path;

use super::{bad_image, check_image, check_target, write_atomic, ExportError};

/// The KTX 2.0 file identifier.
const IDENTIFIER: [u8; 12] = [
    0xAB, b'K', b'T', b'X', b' ', b'2', b'0', 0xBB, b'\r', b'\n', 0x1A, b'\n',
];
/// `VK_FORMAT_E5B9G9R9_UFLOAT_PACK32`.
pub const VK_FORMAT_E5B9G9R9_UFLOAT_PACK32: u32 = 123;
/// `supercompressionScheme` for Zstandard.
const SUPERCOMPRESSION_ZSTD: u32 = 2;
/// Zstandard level of the level data: the lightmaps are small, so a high level costs little.
const ZSTD_LEVEL: i32 = 19;
/// Header (48 bytes) and index (32 bytes).
const HEADER_BYTES: usize = 80;
/// One level index entry: byte offset, byte length, uncompressed byte length.
const LEVEL_INDEX_BYTES: usize = 24;

/// Data format descriptor: total size, then one basic descriptor block of six samples.
fn data_format_descriptor() -> Vec<u8> {
    const SAMPLES: u32 = 6;
    const BLOCK_BYTES: u32 = 24 + 16 * SAMPLES;
    /// Sample qualifier: the sample holds the exponent of its channel.
    const EXPONENT: u32 = 0x20;
    /// `sampleUpper` of a mantissa, as the Khronos Data Format specification gives it for
    /// this format.
    const MANTISSA_UPPER: u32 = 8448;
    /// Exponent bias and largest exponent.
    const EXPONENT_BIAS: u32 = 15;
    const EXPONENT_MAX: u32 = 31;
    let mut words: Vec<u32> = vec![
        4 + BLOCK_BYTES,
        0,                        // vendor Khronos, descriptor type basic
        2 | (BLOCK_BYTES << 16),  // version 1.3, block size
        1 | (1 << 8) | (1 << 16), // model RGBSDA, primaries BT.709, transfer linear, flags 0
        0,                        // 1×1×1×1 texel blocks
        4,                        // 4 bytes in plane 0
        0,
    ];
    for channel in 0..3u32 {
        let sample = |offset: u32, bits: u32, id: u32, lower: u32, upper: u32| {
            [offset | ((bits - 1) << 16) | (id << 24), 0, lower, upper]
        };
        words.extend(sample(9 * channel, 9, channel, 0, MANTISSA_UPPER));
        words.extend(sample(27, 5, channel | EXPONENT, EXPONENT_BIAS, EXPONENT_MAX));
    }
    words.iter().flat_map(|w| w.to_le_bytes()).collect()
}

/// Key/value data: `KTXwriter` naming this library, padded to four bytes.
fn key_value_data() -> Vec<u8> {
    let entry = format!("KTXwriter\0prm-scene {}\0", env!("CARGO_PKG_VERSION"));
    let mut out = (entry.len() as u32).to_le_bytes().to_vec();
    out.extend_from_slice(entry.as_bytes());
    out.resize(out.len().next_multiple_of(4), 0);
    out
}

/// The whole KTX2 file for `width × height` texels already packed as RGB9E5.
fn ktx2_bytes(width: u32, height: u32, texels: &[u32]) -> std::io::Result<Vec<u8>> {
    let raw: Vec<u8> = texels.iter().flat_map(|t| t.to_le_bytes()).collect();
    let level = zstd::bulk::compress(&raw, ZSTD_LEVEL)?;
    let dfd = data_format_descriptor();
    let kvd = key_value_data();
    let dfd_offset = HEADER_BYTES + LEVEL_INDEX_BYTES;
    let kvd_offset = dfd_offset + dfd.len();
    let level_offset = (kvd_offset + kvd.len()).next_multiple_of(8);

    let mut out = Vec::with_capacity(level_offset + level.len());
    out.extend_from_slice(&IDENTIFIER);
    let header = [
        VK_FORMAT_E5B9G9R9_UFLOAT_PACK32,
        4, // typeSize: the packed word
        width,
        height,
        0, // pixelDepth: a 2D texture
        0, // layerCount: not an array
        1, // faceCount
        1, // levelCount
        SUPERCOMPRESSION_ZSTD,
        dfd_offset as u32,
        dfd.len() as u32,
        kvd_offset as u32,
        kvd.len() as u32,
    ];
    out.extend(header.iter().flat_map(|w| w.to_le_bytes()));
    out.extend_from_slice(&[0; 16]); // no supercompression global data
    for v in [level_offset, level.len(), raw.len()] {
        out.extend_from_slice(&(v as u64).to_le_bytes());
    }
    out.extend_from_slice(&dfd);
    out.extend_from_slice(&kvd);
    out.resize(level_offset, 0);
    out.extend_from_slice(&level);
    Ok(out)
}

/// Writes a linear RGB image (row 0 first: texel row 0 of a lightmap, `v = 0`) as a KTX2 file in
/// RGB9E5 with Zstandard supercompression. Negative and non-finite values are clamped as
/// [`prm_format::encode_rgb9e5`] clamps them. The same refusals as [`super::write_exr_rgb`]:
/// an empty image, a pixel count that is not `width × height`, a target that is not a regular
/// file; the file is written atomically.
pub fn write_ktx2_rgb9e5(path: &Path, width: usize, height: usize, rgb: &[[f32; 3]]) -> Result<(), ExportError> {
    check_image(path, width, height, rgb.len())?;
    let (Ok(w), Ok(h)) = (u32::try_from(width), u32::try_from(height)) else {
        return Err(bad_image(path, format!("{width}×{height} is too large for KTX2")));
    };
    check_target(path)?;
    let texels: Vec<u32> = rgb.iter().map(|&c| prm_format::encode_rgb9e5(c)).collect();
    let bytes = ktx2_bytes(w, h, &texels).map_err(|source| ExportError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    write_atomic(path, |f| f.write_all(&bytes))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_descriptor_and_offsets_are_consistent() {
        let texels = vec![prm_format::encode_rgb9e5([0.5, 1.0, 2.0]); 12];
        let bytes = ktx2_bytes(4, 3, &texels).unwrap();
        let u32_at = |o: usize| u32::from_le_bytes(bytes[o..o + 4].try_into().unwrap());
        let u64_at = |o: usize| u64::from_le_bytes(bytes[o..o + 8].try_into().unwrap()) as usize;
        assert_eq!(&bytes[..12], &IDENTIFIER);
        assert_eq!(u32_at(12), VK_FORMAT_E5B9G9R9_UFLOAT_PACK32);
        let (dfd_offset, dfd_len) = (u32_at(48) as usize, u32_at(52) as usize);
        assert_eq!(u32_at(dfd_offset) as usize, dfd_len, "the descriptor's own total size");
        assert_eq!(dfd_len, 4 + 24 + 6 * 16);
        let (offset, len, raw) = (u64_at(80), u64_at(88), u64_at(96));
        assert_eq!(offset + len, bytes.len());
        assert_eq!(raw, 12 * 4);
        let level = zstd::bulk::decompress(&bytes[offset..], raw).unwrap();
        assert_eq!(level, texels.iter().flat_map(|t| t.to_le_bytes()).collect::<Vec<u8>>());
    }
}
