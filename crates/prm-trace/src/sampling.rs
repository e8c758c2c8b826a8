//! Deterministic low-discrepancy sampling: entry points over the surface area, cosine hemisphere.
//!
//! Entry points are area-uniform (density `p = 1/A`) and stratified: point `i` of `N` takes the
//! jittered stratum `u_i = (i + ξ_i)/N` of the cumulative area, which picks its triangle through the
//! area CDF and, rescaled to that triangle's interval, gives its first coordinate; the second
//! coordinate is the Owen-scrambled (Laine–Karras hash) base-2 radical inverse of `i`. Consecutive
//! indices land on the same triangle, so each triangle receives a well stratified 2D point set, and
//! every triangle receives its share `N·a_t/A` of points to within one. Each sample carries the
//! area weight `A/N` = `1/(N·p)`.
//!
//! The entry points, not the walks, set a bake's seed-to-seed spread. The fireplace room's 120 s
//! sizes (3072 entry points, 14 walks each), entry points and walks from separate seeds, played
//! against the reference: entry seed 0 with walk seed 0 or 2 gives 10.96% or 11.39% (energy
//! 0.976, 0.968), entry seed 2 gives 14.69% or 14.81% (0.907, 0.906), with the same shape error
//! (10.4–10.9%). On that room's small triangles this sampler spaces points only somewhat better
//! than independent ones (mean distance to the nearest point of like normal, over `√(A/N)`: 0.655
//! against 0.545); ordering the triangles along a 3D Hilbert curve before the strata are laid, or
//! one shift for all strata, leaves it where it is (0.652, 0.672), so neither was kept. Weighted
//! sample elimination (four times the candidates thinned to `N`, the most crowded first) spreads
//! them to 0.80, but moved neither Sponza's sun (six seeds: mean 17.3% against 18.3%) nor the
//! fireplace room (three: 10.3% against 10.6%) beyond the seeds' spread (README, *Sky*), so it
//! was not kept either.
//!
//! Normals: samples carry the **geometric** normal of their triangle. The walks, the VPLs and the
//! reference tracer's intermediate vertices all use geometric normals; only exit points (which
//! come from the atlas) use its shading normal as receiver. For flat-shaded scenes they agree.

use glam::{Vec2, Vec3};
use prm_scene::Scene;

use crate::rng::{hash64, Rng};
use crate::TraceError;

/// How many entry points to draw and from which seed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct EntryParams {
    /// Number of entry points `N`.
    pub count: usize,
    /// Seed of the scrambling and jitter.
    pub seed: u64,
}

impl EntryParams {
    /// 1024 entry points, for previews and tests.
    pub const PREVIEW: EntryParams = EntryParams { count: 1024, seed: 0 };
    /// 4096 entry points, the paper's figure for a medium scene.
    pub const PAPER: EntryParams = EntryParams { count: 4096, seed: 0 };
}

impl Default for EntryParams {
    fn default() -> Self {
        Self::PAPER
    }
}

/// A point on the surface drawn area-uniformly.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SurfaceSample {
    /// World position.
    pub position: Vec3,
    /// Unit geometric normal of its triangle.
    pub normal: Vec3,
    /// Diffuse albedo there (texture included).
    pub albedo: Vec3,
    /// Triangle index in the scene.
    pub triangle: u32,
    /// Barycentric coordinates `(b1, b2)` (weights of corners 1 and 2).
    pub barycentric: Vec2,
    /// Area weight `A/N` (square scene units): the area this sample stands for.
    pub weight: f32,
}

/// Laine–Karras style hash permutation of the bits of `x`, low bits first (nested uniform
/// scrambling when applied to bit-reversed values).
fn laine_karras(mut x: u32, seed: u32) -> u32 {
    x = x.wrapping_add(seed);
    x ^= x.wrapping_mul(0x6c50_b47c);
    x ^= x.wrapping_mul(0xb82f_1e52);
    x ^= x.wrapping_mul(0xc7af_e638);
    x ^= x.wrapping_mul(0x8d22_f6e6);
    x
}

fn to_unit(bits: u32) -> f32 {
    (bits >> 8) as f32 * (1.0 / 16_777_216.0)
}

fn owen(bits_msb_first: u32, seed: u32) -> u32 {
    laine_karras(bits_msb_first.reverse_bits(), seed).reverse_bits()
}

/// Owen-scrambled base-2 radical inverse (van der Corput) of `i`, in `[0, 1)`.
pub fn radical_inverse_owen(i: u32, seed: u32) -> f32 {
    to_unit(owen(i.reverse_bits(), seed))
}

/// Point `i` of the Owen-scrambled 2D Sobol sequence (a (0,2)-sequence), in `[0, 1)²`.
pub fn sobol2(i: u32, seed: u32) -> Vec2 {
    let x = i.reverse_bits();
    let mut y = 0u32;
    let mut v = 1u32 << 31;
    let mut j = i;
    while j != 0 {
        if j & 1 != 0 {
            y ^= v;
        }
        j >>= 1;
        v ^= v >> 1;
    }
    let s2 = hash64(seed as u64 ^ 0x1234_5678_9ABC) as u32;
    Vec2::new(to_unit(owen(x, seed)), to_unit(owen(y, s2)))
}

/// Cosine-distributed direction about the unit normal `n` from `u ∈ [0,1)²` (pdf `cos θ / π`).
pub fn cosine_hemisphere(u: Vec2, n: Vec3) -> Vec3 {
    let r = u.x.sqrt();
    let phi = std::f32::consts::TAU * u.y;
    let (t, b) = n.any_orthonormal_pair();
    let z = (1.0 - u.x).max(0.0).sqrt();
    (t * (r * phi.cos()) + b * (r * phi.sin()) + n * z).normalize()
}

/// Area-uniform barycentric coordinates `(b1, b2)` from `u ∈ [0,1)²`.
pub fn triangle_barycentric(u: Vec2) -> Vec2 {
    let s = u.x.sqrt();
    Vec2::new(s * (1.0 - u.y), s * u.y)
}

/// `N` stratified, area-uniform entry points over all triangles (see the module docs).
pub fn sample_surface(scene: &Scene, params: &EntryParams) -> Result<Vec<SurfaceSample>, TraceError> {
    let n = params.count;
    if n == 0 {
        return Err(TraceError::InvalidParameter(
            "entry point count must be positive".into(),
        ));
    }
    let mut cdf = Vec::with_capacity(scene.triangles.len() + 1);
    let mut acc = 0.0f64;
    cdf.push(0.0);
    for t in &scene.triangles {
        acc += t.area() as f64;
        cdf.push(acc);
    }
    if acc.is_nan() || acc <= 0.0 {
        return Err(TraceError::EmptyScene);
    }
    let weight = (acc / n as f64) as f32;
    let seed32 = hash64(params.seed) as u32;
    let samples = (0..n)
        .map(|i| {
            let mut rng = Rng::new(params.seed, i as u64, 0x5A);
            let u = ((i as f64 + rng.next_f32() as f64) / n as f64).min(1.0 - 1e-12) * acc;
            // First triangle whose interval [cdf[t], cdf[t+1]) contains u, skipping zero-area ones.
            let t = (cdf.partition_point(|&c| c <= u) - 1).min(scene.triangles.len() - 1);
            let a = cdf[t + 1] - cdf[t];
            let u1 = if a > 0.0 {
                ((u - cdf[t]) / a).clamp(0.0, 1.0 - 1e-7)
            } else {
                0.5
            } as f32;
            let u2 = radical_inverse_owen(i as u32, seed32);
            let b = triangle_barycentric(Vec2::new(u1, u2));
            let tri = &scene.triangles[t];
            SurfaceSample {
                position: tri.point(b.x, b.y),
                normal: tri.normal(),
                albedo: scene.albedo(t, b.x, b.y),
                triangle: t as u32,
                barycentric: b,
                weight,
            }
        })
        .collect();
    Ok(samples)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sobol_is_stratified() {
        // The first 16 points of a (0,2)-sequence fill every 4x4 cell once.
        let mut cells = [0u32; 16];
        for i in 0..16 {
            let p = sobol2(i, 1234);
            assert!(p.x >= 0.0 && p.x < 1.0 && p.y >= 0.0 && p.y < 1.0);
            cells[(p.x * 4.0) as usize * 4 + (p.y * 4.0) as usize] += 1;
        }
        assert!(cells.iter().all(|&c| c == 1), "{cells:?}");
        let mut elementary = [0u32; 16];
        for i in 0..16 {
            let p = sobol2(i, 99);
            elementary[(p.x * 16.0) as usize] += 1;
        }
        assert!(elementary.iter().all(|&c| c == 1));
    }

    #[test]
    fn cosine_sampling_mean_cosine_is_two_thirds() {
        let n = Vec3::new(0.0, 0.6, 0.8);
        let k = 4096;
        let mean: f32 = (0..k).map(|i| cosine_hemisphere(sobol2(i, 5), n).dot(n)).sum::<f32>() / k as f32;
        assert!((mean - 2.0 / 3.0).abs() < 2e-3, "{mean}");
        assert!((0..k).all(|i| cosine_hemisphere(sobol2(i, 5), n).dot(n) >= 0.0));
    }

    #[test]
    fn triangle_mapping_stays_inside() {
        for i in 0..256 {
            let b = triangle_barycentric(sobol2(i, 3));
            assert!(b.x >= 0.0 && b.y >= 0.0 && b.x + b.y <= 1.0 + 1e-6);
        }
    }
}
