//! Helpers the experiments share: knobs from the environment, an archive's entry energies and
//! the relative error.

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

/// Relative RMSE of `test` against a reference of per-point `mean` and `variance` with the
/// reference's noise removed from both sums, over the points `only` keeps; and the energy ratio
/// `Σ test / Σ mean` over them.
pub fn denoised_error(test: &[Vec3], mean: &[Vec3], variance: &[Vec3], only: impl Fn(usize) -> bool) -> (f64, f64) {
    let (mut e2, mut n2, mut v, mut st, mut sr) = (0f64, 0f64, 0f64, 0f64, 0f64);
    for (i, ((t, r), var)) in test.iter().zip(mean).zip(variance).enumerate() {
        if !only(i) {
            continue;
        }
        e2 += f64::from((*t - *r).length_squared());
        n2 += f64::from(r.length_squared());
        v += f64::from(var.element_sum());
        st += f64::from(t.element_sum());
        sr += f64::from(r.element_sum());
    }
    (((e2 - v).max(0.0) / (n2 - v)).sqrt(), st / sr)
}

/// Every entry point's pane energy in `archive`; panics on an archive without them.
pub fn entry_energy<R: std::io::Read + std::io::Seek>(archive: &prm_format::Archive<R>) -> Vec<Vec3> {
    let energy = archive.entry_energy().expect("the archive has no entry energies");
    energy.iter().map(|e| Vec3::from_array(*e)).collect()
}
