//! The sky section (kind 8): at every atlas texel, how much irradiance each of the nine
//! spherical-harmonic basis functions of [`crate::sh_basis`] gives when the sky's radiance is
//! that function, directly (visibility times cosine, one scalar) and after one or more bounces
//! (RGB, the albedos colour it). A sky with coefficients `L_i` (RGB) then gives the texel the
//! direct irradiance `Σ_i direct_i · L_i` and the indirect `Σ_i indirect_i ⊙ L_i`.
//!
//! Layout (formats/prm.md §5.3), little-endian: a 16-byte header (atlas resolution, coefficient
//! count, which must be [`SH_COEFFS`], flags, reserved; flags and reserved zero), then
//! `resolution²` texels of 9 direct coefficients, then `resolution²` texels of 9 RGB triples,
//! every value an IEEE binary16 (`f16`). The size is fixed by the header, so a reader checks it
//! before decompressing. Coefficients may be negative; every value must be finite.
//!
//! Why `f16`: the transfer is a few times 0.1–3 per coefficient, known to a few percent per
//! texel (its paths' noise), so `f16`'s relative step of 2⁻¹¹ is far below what it carries; and
//! its noise does not compress, so `f32` made the section larger than the panes (5.8 MiB
//! against 5.5 on our courtyard's 256² atlas, 8.3 MiB on Sponza's 512²).

use crate::layout::{check_flags, Cursor, PutLe};
use crate::sh::SH_COEFFS;

/// Size of the sky section's fixed header.
pub const SKY_HEADER_SIZE: usize = 16;
/// Bytes of one texel's direct transfer.
pub(crate) const DIRECT_TEXEL_BYTES: usize = SH_COEFFS * 2;
/// Bytes of one texel's indirect transfer.
pub(crate) const INDIRECT_TEXEL_BYTES: usize = SH_COEFFS * 6;
/// Largest finite `f16`: transfer values beyond it cannot be stored.
pub const SKY_MAX_VALUE: f32 = 65504.0;

/// The sky's transfer at the atlas texels, row-major, `resolution²` each.
#[derive(Clone, Debug, PartialEq)]
pub struct SkyTransfer {
    /// Direct irradiance per unit of each basis coefficient (visibility × cosine).
    pub direct: Vec<[f32; SH_COEFFS]>,
    /// Indirect irradiance per unit of each basis coefficient (RGB).
    pub indirect: Vec<[[f32; 3]; SH_COEFFS]>,
}

impl SkyTransfer {
    /// A transfer of `texels` zeros.
    pub fn zeros(texels: usize) -> SkyTransfer {
        SkyTransfer {
            direct: vec![[0.0; SH_COEFFS]; texels],
            indirect: vec![[[0.0; 3]; SH_COEFFS]; texels],
        }
    }

    /// The direct and indirect irradiance (RGB) at texel `t` under the sky `coeffs`.
    pub fn irradiance(&self, t: usize, coeffs: &[[f32; 3]; SH_COEFFS]) -> ([f32; 3], [f32; 3]) {
        let (mut d, mut i) = ([0.0f32; 3], [0.0f32; 3]);
        for (c, l) in coeffs.iter().enumerate() {
            for k in 0..3 {
                d[k] += self.direct[t][c] * l[k];
                i[k] += self.indirect[t][c][k] * l[k];
            }
        }
        (d, i)
    }
}

/// Raw size of a sky section at `resolution`, `None` on overflow.
pub(crate) fn raw_size_for(resolution: u32) -> Option<u64> {
    let texels = u64::from(resolution) * u64::from(resolution);
    texels
        .checked_mul((DIRECT_TEXEL_BYTES + INDIRECT_TEXEL_BYTES) as u64)?
        .checked_add(SKY_HEADER_SIZE as u64)
}

/// Checks `sky` against the atlas resolution.
pub(crate) fn validate(sky: &SkyTransfer, resolution: u32) -> Result<(), String> {
    let texels = resolution as usize * resolution as usize;
    if sky.direct.len() != texels || sky.indirect.len() != texels {
        return Err(format!(
            "sky transfer has {} direct and {} indirect texels, resolution {resolution} needs {texels}",
            sky.direct.len(),
            sky.indirect.len()
        ));
    }
    let storable = |v: &f32| v.abs() <= SKY_MAX_VALUE;
    if let Some(t) = sky.direct.iter().position(|c| !c.iter().all(storable)) {
        return Err(format!(
            "sky transfer: texel {t}'s direct coefficients are not finite within ±{SKY_MAX_VALUE}"
        ));
    }
    if let Some(t) = sky.indirect.iter().position(|c| !c.iter().flatten().all(storable)) {
        return Err(format!(
            "sky transfer: texel {t}'s indirect coefficients are not finite within ±{SKY_MAX_VALUE}"
        ));
    }
    Ok(())
}

/// Encodes a validated transfer.
pub(crate) fn encode(sky: &SkyTransfer, resolution: u32) -> Vec<u8> {
    let mut b = Vec::with_capacity(raw_size_for(resolution).unwrap_or(0) as usize);
    b.put_u32(resolution);
    b.put_u32(SH_COEFFS as u32);
    b.put_u32(0);
    b.put_u32(0);
    let mut put = |v: f32| b.extend_from_slice(&half::f16::from_f32(v).to_le_bytes());
    sky.direct.iter().flatten().for_each(|v| put(*v));
    sky.indirect.iter().flatten().flatten().for_each(|v| put(*v));
    b
}

/// Parses the header: the resolution; checks the coefficient count and flags, and if `strict`
/// the reserved field. The caller checks the resolution against the archive.
pub(crate) fn decode_header(head: &[u8], strict: bool) -> Result<u32, String> {
    let [resolution, coeffs, flags, reserved] = Cursor::new(head, "sky").u32s().map_err(|e| e.to_string())?;
    if coeffs != SH_COEFFS as u32 {
        return Err(format!(
            "sky section has {coeffs} coefficients per texel, this reader knows {SH_COEFFS}"
        ));
    }
    check_flags("sky", flags, 0, strict && reserved != 0)?;
    Ok(resolution)
}

/// The `f16` values of `raw`, whole, as `f32`; an infinity or NaN is refused.
fn decode_halves(raw: &[u8]) -> Result<Vec<f32>, String> {
    raw.chunks_exact(2)
        .map(|h| {
            let v = half::f16::from_le_bytes([h[0], h[1]]).to_f32();
            if v.is_finite() {
                Ok(v)
            } else {
                Err("a sky transfer value is not finite".to_string())
            }
        })
        .collect()
}

/// Decodes whole direct texels.
pub(crate) fn decode_direct(raw: &[u8]) -> Result<Vec<[f32; SH_COEFFS]>, String> {
    let v = decode_halves(raw)?;
    Ok(v.chunks_exact(SH_COEFFS)
        .map(|t| std::array::from_fn(|c| t[c]))
        .collect())
}

/// Decodes whole indirect texels.
pub(crate) fn decode_indirect(raw: &[u8]) -> Result<Vec<[[f32; 3]; SH_COEFFS]>, String> {
    let v = decode_halves(raw)?;
    Ok(v.chunks_exact(3 * SH_COEFFS)
        .map(|t| std::array::from_fn(|c| [t[3 * c], t[3 * c + 1], t[3 * c + 2]]))
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn transfer(res: u32) -> SkyTransfer {
        let n = (res * res) as usize;
        SkyTransfer {
            direct: (0..n)
                .map(|t| std::array::from_fn(|c| t as f32 - c as f32 * 0.5))
                .collect(),
            indirect: (0..n)
                .map(|t| std::array::from_fn(|c| [t as f32, -(c as f32), 0.25]))
                .collect(),
        }
    }

    #[test]
    fn round_trip_through_the_encoding() {
        let sky = transfer(4);
        validate(&sky, 4).unwrap();
        let raw = encode(&sky, 4);
        assert_eq!(raw.len() as u64, raw_size_for(4).unwrap());
        assert_eq!(decode_header(&raw[..SKY_HEADER_SIZE], true).unwrap(), 4);
        let split = SKY_HEADER_SIZE + 16 * DIRECT_TEXEL_BYTES;
        let back = SkyTransfer {
            direct: decode_direct(&raw[SKY_HEADER_SIZE..split]).unwrap(),
            indirect: decode_indirect(&raw[split..]).unwrap(),
        };
        assert_eq!(back, sky);
    }

    #[test]
    fn rejects_what_the_layout_cannot_hold() {
        assert!(validate(&transfer(4), 5).is_err(), "resolution");
        let mut nan = transfer(2);
        nan.indirect[3][8][2] = f32::INFINITY;
        assert!(validate(&nan, 2).is_err());
        let mut raw = encode(&transfer(2), 2);
        raw[4] = 16; // sixteen coefficients: order 3, unknown here
        assert!(decode_header(&raw[..16], true).is_err());
        let mut raw = encode(&transfer(2), 2);
        raw[8] = 1;
        assert!(decode_header(&raw[..16], false).is_err(), "unknown flag");
        let mut raw = encode(&transfer(2), 2);
        raw[SKY_HEADER_SIZE..SKY_HEADER_SIZE + 2].copy_from_slice(&half::f16::NAN.to_le_bytes());
        assert!(decode_direct(&raw[SKY_HEADER_SIZE..SKY_HEADER_SIZE + 18]).is_err());
        let mut big = transfer(2);
        big.direct[1][0] = 1e5;
        assert!(validate(&big, 2).is_err(), "beyond f16");
    }

    #[test]
    fn irradiance_is_the_dot_product() {
        let sky = transfer(1);
        let mut coeffs = [[0.0f32; 3]; SH_COEFFS];
        coeffs[0] = [2.0, 1.0, 0.0];
        coeffs[4] = [0.0, 0.0, 4.0];
        let (d, i) = sky.irradiance(0, &coeffs);
        assert_eq!(d, [0.0, 0.0, -8.0]);
        assert_eq!(i, [0.0, 0.0, 1.0]);
    }
}
