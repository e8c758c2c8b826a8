//! RGB9E5 shared-exponent texel codec, bit-exact with WebGPU `rgb9e5ufloat`.
//!
//! A texel is one little-endian `u32`:
//!
//! | bits  | field                          |
//! |-------|--------------------------------|
//! | 0–8   | red mantissa (9 bits)          |
//! | 9–17  | green mantissa (9 bits)        |
//! | 18–26 | blue mantissa (9 bits)         |
//! | 27–31 | shared exponent (5 bits)       |
//!
//! Decoding is `channel = mantissa × 2^(exponent − 24)` (exponent bias 15,
//! 9 mantissa bits, no implicit leading one). This is the layout of WebGPU's
//! `rgb9e5ufloat`, Vulkan's `E5B9G9R9_UFLOAT_PACK32`, DXGI's
//! `R9G9B9E5_SHAREDEXP` and OpenGL's `GL_RGB9_E5`, so the bytes can be
//! uploaded and sampled by a GPU without conversion.
//!
//! Encoding follows the algorithm of `EXT_texture_shared_exponent` exactly
//! (round half up on the scaled mantissa, exponent bumped when the largest
//! channel's mantissa rounds up to 512).
//!
//! # Error bound
//!
//! For inputs in `[0, RGB9E5_MAX]` with `m = max(r, g, b)`:
//!
//! * every channel's absolute error is at most `max(m / 511.5, 2^-25)`;
//! * if `m ≥ 2^-16`, the largest channel's relative error is at most
//!   `1/513 < 2^-9` ([`RGB9E5_MAX_RELATIVE_ERROR`]);
//! * smaller channels share the largest channel's quantum, so their error
//!   is bounded relative to `m`, not to their own value (a channel below
//!   `m / 1023` may encode as zero).

/// Largest finite value representable in RGB9E5: `511/512 × 2^16 = 65408`.
pub const RGB9E5_MAX: f32 = 65408.0;

/// Bound on the relative error of the largest channel of an encoded texel
/// (`2^-9`), valid when that channel is at least [`RGB9E5_MIN_NORMAL`] and
/// at most [`RGB9E5_MAX`]. The true supremum is `1/513`.
pub const RGB9E5_MAX_RELATIVE_ERROR: f64 = 1.0 / 512.0;

/// Smallest largest-channel value for which [`RGB9E5_MAX_RELATIVE_ERROR`]
/// holds (`2^-16`); below it the absolute error is at most
/// [`RGB9E5_MIN_ABS_ERROR`].
pub const RGB9E5_MIN_NORMAL: f32 = 1.0 / 65536.0;

/// Absolute error bound for tiny values (`2^-25`, half the smallest quantum).
pub const RGB9E5_MIN_ABS_ERROR: f32 = 1.0 / 33_554_432.0;

/// Name of the encoding as used in archive metadata (the WebGPU format name).
pub const RGB9E5_NAME: &str = "rgb9e5ufloat";

const MANTISSA_BITS: i32 = 9;
const EXP_BIAS: i32 = 15;

/// Clamps one channel to `[0, RGB9E5_MAX]`; NaN and negatives become 0.
#[inline]
pub(crate) fn clamp_channel(c: f32) -> f32 {
    if c > 0.0 {
        c.min(RGB9E5_MAX)
    } else {
        0.0
    }
}

/// Encodes a linear RGB triple into an RGB9E5 texel.
///
/// NaN and negative channels encode as 0, values above [`RGB9E5_MAX`]
/// (including +∞) as [`RGB9E5_MAX`].
#[inline]
pub fn encode_rgb9e5(rgb: [f32; 3]) -> u32 {
    let r = clamp_channel(rgb[0]);
    let g = clamp_channel(rgb[1]);
    let b = clamp_channel(rgb[2]);
    let max_c = r.max(g).max(b);
    // floor(log2(max_c)), clamped below at -B-1 = -16. For max_c >= 2^-16 the
    // value is a normal f32 and its biased exponent field is exactly that.
    let floor_log2 = if max_c >= RGB9E5_MIN_NORMAL {
        ((max_c.to_bits() >> 23) & 0xff) as i32 - 127
    } else {
        -EXP_BIAS - 1
    };
    let mut exp_shared = floor_log2 + 1 + EXP_BIAS; // 0..=31
                                                    // Scaling by a power of two is exact in f64; +0.5 is exact as well
                                                    // because the scaled value has at most 24 significant bits.
    let scale = |e: i32| -> f64 { f64::powi(2.0, MANTISSA_BITS + EXP_BIAS - e) };
    let max_s = (f64::from(max_c) * scale(exp_shared) + 0.5).floor();
    if max_s >= 512.0 {
        exp_shared += 1;
    }
    let s = scale(exp_shared);
    let q = |c: f32| -> u32 { ((f64::from(c) * s + 0.5).floor() as u32).min(511) };
    q(r) | (q(g) << 9) | (q(b) << 18) | ((exp_shared as u32) << 27)
}

/// The three mantissas' bits of a texel: it decodes to zero exactly when they are all 0,
/// whatever its exponent.
pub const RGB9E5_MANTISSAS: u32 = (1 << 27) - 1;

/// Decodes an RGB9E5 texel into linear RGB (exact: every RGB9E5 value is
/// representable as an `f32`).
#[inline]
pub fn decode_rgb9e5(texel: u32) -> [f32; 3] {
    let e = (texel >> 27) as i32;
    // 2^(e - 24) with e in 0..=31 is a normal f32: build it from its bits.
    let scale = f32::from_bits(((e - MANTISSA_BITS - EXP_BIAS + 127) as u32) << 23);
    [
        (texel & 0x1ff) as f32 * scale,
        ((texel >> 9) & 0x1ff) as f32 * scale,
        ((texel >> 18) & 0x1ff) as f32 * scale,
    ]
}

/// Encodes a slice of RGB triples into `out` (which is cleared first).
pub fn encode_rgb9e5_slice(texels: &[[f32; 3]], out: &mut Vec<u32>) {
    out.clear();
    out.extend(texels.iter().map(|&t| encode_rgb9e5(t)));
}

/// Decodes a slice of RGB9E5 texels.
pub fn decode_rgb9e5_slice(texels: &[u32]) -> Vec<[f32; 3]> {
    texels.iter().map(|&t| decode_rgb9e5(t)).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    use crate::splitmix::Rng;

    impl Rng {
        fn unit(&mut self) -> f64 {
            (self.next() >> 11) as f64 / (1u64 << 53) as f64
        }
        /// Log-uniform value in [2^lo, 2^hi).
        fn log_uniform(&mut self, lo: f64, hi: f64) -> f32 {
            (2f64).powf(lo + (hi - lo) * self.unit()) as f32
        }
    }

    /// Straight transcription of the EXT_texture_shared_exponent pseudo code
    /// with f64 arithmetic and `log2`, used as an independent reference.
    fn reference_encode(rgb: [f32; 3]) -> u32 {
        let max = 65408.0f64;
        let c: Vec<f64> = rgb
            .iter()
            .map(|&v| {
                let v = f64::from(v);
                if v.is_nan() {
                    0.0
                } else {
                    v.clamp(0.0, max)
                }
            })
            .collect();
        let max_c = c[0].max(c[1]).max(c[2]);
        let exp_p = (-16f64).max(max_c.log2().floor()) as i32 + 1 + 15;
        let max_s = (max_c / 2f64.powi(exp_p - 24) + 0.5).floor();
        let exp = if max_s < 512.0 { exp_p } else { exp_p + 1 };
        let q = |v: f64| (v / 2f64.powi(exp - 24) + 0.5).floor() as u32;
        q(c[0]) | (q(c[1]) << 9) | (q(c[2]) << 18) | ((exp as u32) << 27)
    }

    #[test]
    fn known_values() {
        assert_eq!(encode_rgb9e5([0.0; 3]), 0);
        // 1.0 = 256 × 2^(16-24)
        assert_eq!(encode_rgb9e5([1.0, 1.0, 1.0]), 0x8402_0100);
        assert_eq!(decode_rgb9e5(0x8402_0100), [1.0, 1.0, 1.0]);
        assert_eq!(encode_rgb9e5([1.0, 0.0, 0.0]), (16 << 27) | 256);
        assert_eq!(encode_rgb9e5([0.5, 0.25, 0.0]), (15 << 27) | 256 | (128 << 9));
        // maximum: mantissa 511, exponent 31
        assert_eq!(
            encode_rgb9e5([RGB9E5_MAX; 3]),
            511 | (511 << 9) | (511 << 18) | (31 << 27)
        );
        assert_eq!(decode_rgb9e5(0xffff_ffff), [RGB9E5_MAX; 3]);
        // smallest non-zero quantum: 2^-24
        assert_eq!(decode_rgb9e5(1), [1.0 / 16_777_216.0, 0.0, 0.0]);
    }

    #[test]
    fn clamping() {
        assert_eq!(encode_rgb9e5([f32::NAN, -1.0, -0.0]), 0);
        assert_eq!(encode_rgb9e5([f32::NEG_INFINITY, 0.0, 0.0]), 0);
        let max = encode_rgb9e5([RGB9E5_MAX; 3]);
        assert_eq!(encode_rgb9e5([f32::INFINITY, 1e30, 70000.0]), max);
        let t = decode_rgb9e5(encode_rgb9e5([f32::INFINITY, f32::NAN, 1.0]));
        assert_eq!(t[0], RGB9E5_MAX);
        assert_eq!(t[1], 0.0);
        assert!((t[2] - 1.0).abs() <= RGB9E5_MAX / 511.5);
    }

    #[test]
    fn mantissa_rounding_bumps_exponent() {
        // 511.75 × 2^-8 rounds to 512 × 2^-8 = 2.0 → exponent bumped.
        let v = 511.75 / 256.0;
        let t = encode_rgb9e5([v, 0.0, 0.0]);
        assert_eq!(t >> 27, 17);
        assert_eq!(decode_rgb9e5(t)[0], 2.0);
        // Halfway rounds up (floor(x + 0.5)).
        let t = encode_rgb9e5([256.5 / 256.0, 0.0, 0.0]);
        assert_eq!(t & 0x1ff, 257);
    }

    #[test]
    fn matches_reference_and_error_bounds() {
        let mut rng = Rng(0x1234_5678);
        let mut worst_rel = 0.0f64;
        for i in 0..200_000 {
            let rgb = match i % 4 {
                // wide dynamic range, including the tiny-value regime
                0 => [
                    rng.log_uniform(-30.0, 16.0),
                    rng.log_uniform(-30.0, 16.0),
                    rng.log_uniform(-30.0, 16.0),
                ],
                // typical lighting values
                1 => [
                    rng.log_uniform(-8.0, 6.0),
                    rng.log_uniform(-8.0, 6.0),
                    rng.log_uniform(-8.0, 6.0),
                ],
                // arbitrary bit patterns (NaN, inf, negatives, subnormals)
                2 => [
                    f32::from_bits(rng.next() as u32),
                    f32::from_bits(rng.next() as u32),
                    f32::from_bits(rng.next() as u32),
                ],
                // one dominant channel
                _ => {
                    let m = rng.log_uniform(-16.0, 15.99);
                    [m, m * rng.unit() as f32, m * rng.log_uniform(-12.0, 0.0)]
                }
            };
            let enc = encode_rgb9e5(rgb);
            assert_eq!(enc, reference_encode(rgb), "input {rgb:?}");
            let dec = decode_rgb9e5(enc);
            let clamped = rgb.map(clamp_channel);
            let m = f64::from(clamped[0].max(clamped[1]).max(clamped[2]));
            let abs_bound = (m / 511.5).max(f64::from(RGB9E5_MIN_ABS_ERROR));
            for c in 0..3 {
                let err = (f64::from(dec[c]) - f64::from(clamped[c])).abs();
                assert!(err <= abs_bound, "channel {c} of {rgb:?}: err {err} > {abs_bound}");
            }
            if m >= f64::from(RGB9E5_MIN_NORMAL) {
                let k = (0..3).max_by(|&a, &b| clamped[a].total_cmp(&clamped[b])).unwrap();
                let rel = (f64::from(dec[k]) - m).abs() / m;
                assert!(rel <= 1.0 / 513.0 + 1e-15, "{rgb:?}: rel {rel}");
                worst_rel = worst_rel.max(rel);
            }
            // decode → encode is the identity on canonical encodings
            assert_eq!(encode_rgb9e5(dec), enc);
        }
        assert!(worst_rel <= RGB9E5_MAX_RELATIVE_ERROR);
        assert!(worst_rel > 0.9 / 513.0, "bound should be nearly tight: {worst_rel}");
    }

    #[test]
    fn relative_bound_is_attained_near_1_over_513() {
        // 256.5 - ε quanta rounds down to 256: relative error → 0.5 / 256.5.
        let v = f32::from_bits((256.5f32 / 256.0).to_bits() - 1);
        let dec = decode_rgb9e5(encode_rgb9e5([v, 0.0, 0.0]))[0];
        let rel = f64::from((dec - v).abs()) / f64::from(v);
        assert!(rel < 1.0 / 513.0 && rel > 0.99 / 513.0, "{rel}");
    }

    #[test]
    fn slices_round_trip() {
        let texels = [[0.1, 0.2, 0.3], [4.0, 0.0, 1.0]];
        let mut enc = Vec::new();
        encode_rgb9e5_slice(&texels, &mut enc);
        assert_eq!(enc.len(), 2);
        let dec = decode_rgb9e5_slice(&enc);
        assert_eq!(dec[1], [4.0, 0.0, 1.0]);
    }
}
