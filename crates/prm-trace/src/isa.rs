//! Run-time choice of the instruction set for the hot loops: AVX2 and FMA where the CPU has them.
//!
//! Ray traversal of the default wide BVH (obvhs's `traverse!`, expanded in [`crate::Bvh`]'s
//! queries; the BVH2 layout calls obvhs's own functions, built for the baseline) and the pane kernel's unoccluded
//! term are compiled twice: for the portable x86-64 baseline (SSE2) and, behind
//! `#[target_feature]`, for x86-64-v3 (AVX2, FMA, BMI1/2, LZCNT). Every call picks the second
//! where [`avx2`] says the CPU runs it, so one binary runs everywhere and is fast where it can
//! be. The two give the same bits: Rust never fuses a multiply and an add on its own, and the
//! vectorised loops have no reductions to reorder (tests in `bvh.rs` and `pane.rs` compare the
//! two on the same inputs).
//!
//! Measured with a whole build for x86-64-v3 (`RUSTFLAGS="-C target-cpu=x86-64-v3"`, release,
//! chairs `--preset paper --backend cpu`, two runs each, `perf`): shadow rays (`occluded_cached`)
//! 16 % fewer cycles, the kernel (`sum_exit`) 29 % fewer, pane rendering 5.9 s against 6.7 s.
//! The per-call choice below keeps most of that without building the binary for one CPU: chairs'
//! pane rendering 6.2 s against 7.0 s for the baseline alone (mean of three alternating runs),
//! Sibenik at 5120 entries, 135 clusters, 704², one walk: 56.8 s a bake against 62.8 s, archives
//! identical byte for byte. obvhs's traversal methods are functions of their own, built for the
//! baseline: called from an AVX2 variant they gained nothing (measured: the same 7.0 s), so the
//! variants expand obvhs's `traverse!` macro themselves (`bvh.rs`).

/// Whether the AVX2 variants may run on this CPU (always false off x86-64).
#[inline]
pub(crate) fn avx2() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::arch::is_x86_feature_detected!("avx2")
            && std::arch::is_x86_feature_detected!("fma")
            && std::arch::is_x86_feature_detected!("bmi1")
            && std::arch::is_x86_feature_detected!("bmi2")
            && std::arch::is_x86_feature_detected!("lzcnt")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// For the tests that compare the variants: the bundled Cornell box, or `None` on a CPU without
/// AVX2 (only the portable variant runs there), which fails under CI, whose machines have it.
#[cfg(test)]
pub(crate) fn variant_test_scene() -> Option<prm_scene::Scene> {
    if !avx2() {
        assert!(
            std::env::var_os("CI").is_none(),
            "CI machines have AVX2: the variants went untested"
        );
        eprintln!("this CPU has no AVX2: only the portable variant runs");
        return None;
    }
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes/cornell-box/cornell-box.obj");
    Some(prm_scene::load(&path).unwrap())
}
