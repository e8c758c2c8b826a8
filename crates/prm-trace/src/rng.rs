//! Small seedable random numbers: a PCG32 stream keyed by a hash of `(seed, a, b)`, no global state.
//!
//! Every consumer derives its own stream from the run seed and its own indices (entry point and
//! walk, texel and pass, ...), so results never depend on how work is split across threads.

use glam::Vec2;

/// The SplitMix64 finaliser: a good 64-bit integer hash.
pub fn hash64(mut x: u64) -> u64 {
    x = x.wrapping_add(0x9E37_79B9_7F4A_7C15);
    x = (x ^ (x >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    x = (x ^ (x >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    x ^ (x >> 31)
}

/// Hash of a seed and two indices (order matters).
pub fn hash3(seed: u64, a: u64, b: u64) -> u64 {
    hash64(seed ^ hash64(a ^ hash64(b ^ 0x5851_F42D_4C95_7F2D)))
}

/// A PCG32 (XSH RR) generator.
#[derive(Clone, Debug)]
pub struct Rng {
    state: u64,
    inc: u64,
}

impl Rng {
    const MUL: u64 = 6_364_136_223_846_793_005;

    /// The stream for `(seed, a, b)`, e.g. `(run seed, entry index, walk index)`.
    pub fn new(seed: u64, a: u64, b: u64) -> Rng {
        let h = hash3(seed, a, b);
        let mut r = Rng {
            state: 0,
            inc: (hash64(h ^ 0xDA94_2042_E4DD_58B5) << 1) | 1,
        };
        r.next_u32();
        r.state = r.state.wrapping_add(h);
        r.next_u32();
        r
    }

    /// Next 32 random bits.
    pub fn next_u32(&mut self) -> u32 {
        let old = self.state;
        self.state = old.wrapping_mul(Self::MUL).wrapping_add(self.inc);
        let xorshifted = (((old >> 18) ^ old) >> 27) as u32;
        let rot = (old >> 59) as u32;
        xorshifted.rotate_right(rot)
    }

    /// Uniform in `[0, 1)` (24 bits).
    pub fn next_f32(&mut self) -> f32 {
        (self.next_u32() >> 8) as f32 * (1.0 / 16_777_216.0)
    }

    /// Two uniforms in `[0, 1)`.
    pub fn next_vec2(&mut self) -> Vec2 {
        let x = self.next_f32();
        Vec2::new(x, self.next_f32())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn streams_are_reproducible_and_distinct() {
        let a: Vec<u32> = (0..8)
            .map({
                let mut r = Rng::new(1, 2, 3);
                move |_| r.next_u32()
            })
            .collect();
        let mut r = Rng::new(1, 2, 3);
        assert!(a.iter().all(|&v| v == r.next_u32()));
        let mut s = Rng::new(1, 3, 2);
        assert_ne!(a[0], s.next_u32());
    }

    #[test]
    fn uniforms_have_the_right_mean() {
        let mut r = Rng::new(7, 0, 0);
        let n = 100_000;
        let mean: f64 = (0..n).map(|_| r.next_f32() as f64).sum::<f64>() / n as f64;
        assert!((mean - 0.5).abs() < 0.005, "{mean}");
    }
}
