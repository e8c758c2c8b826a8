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

/// The CPU player's options for `archive` as the run time plays it by default
/// (`RuntimeOptions::for_archive`), with or without the near field and its deeper share's
/// `near_bounces` gathers.
pub fn cpu_options<R: std::io::Read + std::io::Seek>(
    archive: &prm_format::Archive<R>,
    near_field: bool,
    near_bounces: u32,
) -> prm_play::cpu::CpuOptions {
    let defaults = prm_play::RuntimeOptions::for_archive(archive);
    prm_play::cpu::CpuOptions {
        top_k: defaults.top_k,
        residual_groups: defaults.residual_groups,
        fade_band: defaults.fade_band,
        near_field,
        near_bounces,
    }
}

/// The default atlas of `scene` at `archive`'s resolution, refused unless its UVs are the
/// archive's (the exit points are then the archive's texels).
pub fn archive_atlas<R: std::io::Read + std::io::Seek>(
    scene: &prm_scene::Scene,
    archive: &prm_format::Archive<R>,
) -> anyhow::Result<prm_scene::Atlas> {
    let resolution = archive.atlas().resolution;
    let params = prm_scene::AtlasParams::with_sizing(prm_scene::Sizing::Resolution(resolution));
    let atlas = prm_scene::Atlas::build(scene, &params)?;
    let stored = &archive.atlas().triangle_uvs;
    anyhow::ensure!(
        stored.len() == atlas.uvs.len()
            && stored
                .iter()
                .zip(&atlas.uvs)
                .all(|(a, b)| a.iter().zip(b).all(|(p, q)| p == &q.to_array())),
        "the archive's atlas is not the default atlas of this scene at {resolution}²"
    );
    Ok(atlas)
}
