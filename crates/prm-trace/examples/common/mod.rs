//! Helpers the experiments share: knobs from the environment and the relative error.

use glam::Vec3;

/// The environment variable `name` as a number, or `default` when unset.
pub fn env_or(name: &str, default: u32) -> u32 {
    std::env::var(name).ok().map_or(default, |s| s.parse().unwrap())
}

/// Relative RMSE of `a` against the reference `r`, and the energy ratio `Σ a / Σ r`.
pub fn rel_rmse(a: &[Vec3], r: &[Vec3]) -> (f64, f64) {
    let (mut e, mut n, mut sa, mut sr) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
    for (a, r) in a.iter().zip(r) {
        e += (*a - *r).length_squared() as f64;
        n += r.length_squared() as f64;
        sa += a.element_sum() as f64;
        sr += r.element_sum() as f64;
    }
    ((e / n.max(1e-30)).sqrt(), sa / sr.max(1e-30))
}
