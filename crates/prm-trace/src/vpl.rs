//! Bounding the `1/r²` singularity of virtual point lights.
//!
//! A VPL's irradiance `Φ/π · cos θ_x cos θ_v / r²` is unbounded as the receiver approaches it,
//! which shows as bright splotches near VPLs and infinite variance. [`VplBound`] replaces `1/r²`:
//!
//! * [`VplBound::Clamp`]: `1/max(r², d_min²)`, a fixed distance in scene units;
//! * [`VplBound::Disk`]: the VPL is a disk of the area it stands for,
//!   `R² = scale² · area / π`, and `1/r²` becomes `1/(r² + R²)`, the exact on-axis irradiance
//!   factor of a Lambertian disk of radius `R` (it tends to `1/r²` far away).
//!
//! Both remove energy near the VPL and so bias the result low, most at receivers close to other
//! surfaces (inner corners, contact regions). The default is `Disk { scale: 1.0 }`; bakes that
//! trace the near field, which gives that energy back, use [`VplBound::Near`] (scale 3 in
//! `prm-bake`). Measured in
//! `tests/transport.rs` (4096 entry points, 4 walks each):
//!
//! * closed-box furnace (ρ = 0.5, expected 1): mean bias −0.45 % over the exit points that are
//!   not on a box edge (mean |error| 0.8 %, worst texel 5.5 %). Exit points lying exactly on a
//!   concave edge get about half the expected value: there the adjacent face's contribution
//!   concentrates within `R` of the receiver and the bound removes it (with no bound the
//!   contribution is still zero at distance 0, since `cos θ_v = 0`);
//! * Cornell box, README point light: the default bound keeps 99.2 % of the unbounded estimate's
//!   energy over the exit points of a 48² atlas (98.0 % on a 32² atlas, which has relatively more
//!   border texels); the remaining PRM-vs-reference bias (+1 %) is within the estimator's noise.
//!
use glam::Vec3;

use crate::walk::Vpl;

/// `1 − w₀` of [`VplBound::Near`], `w₀` the near field's cut (`prm_format::NEAR_MIN_WEIGHT`).
pub const NEAR_KEEP: f32 = 1.0 - prm_format::NEAR_MIN_WEIGHT;

/// How the `1/r²` term of a VPL is bounded.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum VplBound {
    /// Plain `1/r²` (unbiased, unbounded variance).
    None,
    /// `1/max(r², min_distance²)`.
    Clamp {
        /// Distance below which the falloff stops growing, scene units.
        min_distance: f32,
    },
    /// `1/(r² + R²)` with `R² = scale² · vpl.area / π`.
    Disk {
        /// Radius multiplier (1 = a disk of exactly the VPL's area).
        scale: f32,
    },
    /// The complement of a near field's cut weights:
    /// `1/max(r², (1 − w₀)(r² + R²))`, `R²` as for [`VplBound::Disk`] and `w₀` =
    /// `prm_format::NEAR_MIN_WEIGHT`. It is the disk's kernel times `1/(1 − w₀)` out to where
    /// `R²/(r² + R²)` falls to `w₀`, and `1/r²` beyond, so that with the near field's weight
    /// `(R²/(r² + R²) − w₀)/(1 − w₀)` it sums to `1/r²` at every distance: the disk's kernel
    /// loses what it removes beyond the cut, where the near field stores no rays.
    Near {
        /// Radius multiplier, as for [`VplBound::Disk`].
        scale: f32,
    },
}

impl VplBound {
    /// `Disk { scale: 1.0 }`.
    pub const DEFAULT: VplBound = VplBound::Disk { scale: 1.0 };

    /// The bounded replacement for `1/r²` given `r²` and the VPL.
    #[inline]
    pub fn inverse_square(&self, r2: f32, vpl: &Vpl) -> f32 {
        match *self {
            VplBound::None => 1.0 / r2,
            VplBound::Clamp { min_distance } => 1.0 / r2.max(min_distance * min_distance),
            VplBound::Disk { scale } => 1.0 / (r2 + scale * scale * vpl.area * std::f32::consts::FRAC_1_PI),
            VplBound::Near { scale } => {
                1.0 / r2.max(NEAR_KEEP * (r2 + scale * scale * vpl.area * std::f32::consts::FRAC_1_PI))
            }
        }
    }

    /// Unoccluded irradiance of `vpl` at `x` with unit receiver normal `nx`, W/m² per unit entry
    /// irradiance; zero when either side faces away.
    #[inline]
    pub fn irradiance(&self, vpl: &Vpl, x: Vec3, nx: Vec3) -> Vec3 {
        let d = vpl.position - x;
        let r2 = d.length_squared();
        if r2.is_nan() || r2 <= 0.0 {
            return Vec3::ZERO;
        }
        let r = r2.sqrt();
        let cx = nx.dot(d) / r;
        let cv = -vpl.normal.dot(d) / r;
        if cx <= 0.0 || cv <= 0.0 {
            return Vec3::ZERO;
        }
        vpl.power * (std::f32::consts::FRAC_1_PI * cx * cv * self.inverse_square(r2, vpl))
    }
}

impl Default for VplBound {
    fn default() -> Self {
        Self::DEFAULT
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn vpl() -> Vpl {
        Vpl {
            position: Vec3::ZERO,
            normal: Vec3::Y,
            power: Vec3::ONE,
            area: 0.01,
            triangle: 0,
            entry: 0,
            depth: 0,
        }
    }

    #[test]
    fn bounds_match_point_light_far_away_and_stay_finite_close() {
        let v = vpl();
        let far = Vec3::new(0.0, 10.0, 0.0);
        let exact = VplBound::None.irradiance(&v, far, -Vec3::Y).x;
        assert!((exact - 1.0 / (std::f32::consts::PI * 100.0)).abs() < 1e-7);
        for b in [VplBound::DEFAULT, VplBound::Clamp { min_distance: 0.05 }] {
            let e = b.irradiance(&v, far, -Vec3::Y).x;
            assert!((e / exact - 1.0).abs() < 1e-3);
            let near = b.irradiance(&v, Vec3::new(0.0, 1e-6, 0.0), -Vec3::Y).x;
            assert!(near.is_finite() && near < 200.0, "{near}");
        }
        assert_eq!(VplBound::DEFAULT.irradiance(&v, far, Vec3::Y), Vec3::ZERO);
        assert_eq!(VplBound::DEFAULT.irradiance(&v, -far, -Vec3::Y), Vec3::ZERO);
    }
}
