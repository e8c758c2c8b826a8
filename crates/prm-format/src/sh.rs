//! The real spherical-harmonic basis of order 2 (nine functions) that the sky section stores
//! its transfer in, with +Y as the polar axis so that a rotation of the sky about the vertical
//! is a rotation of each `(m, −m)` coefficient pair by `m·α` (formats/prm.md §5.3).
//!
//! With `θ` the angle from +Y and `φ` the azimuth from +Z towards +X (a direction is
//! `(sin θ sin φ, cos θ, sin θ cos φ)`), the functions are, in storage order:
//! `Y₀₀ = ½√(1/π)`; `Y₁₋₁ = c₁·x`, `Y₁₀ = c₁·y`, `Y₁₁ = c₁·z` with `c₁ = ½√(3/π)`;
//! `Y₂₋₂ = c₂·xz`, `Y₂₋₁ = c₂·xy`, `Y₂₀ = c₂₀·(3y² − 1)`, `Y₂₁ = c₂·yz`, `Y₂₂ = ½c₂·(z² − x²)`
//! with `c₂ = ½√(15/π)` and `c₂₀ = ¼√(5/π)`. They are orthonormal over the sphere.

/// Number of coefficients: orders 0, 1 and 2.
pub const SH_COEFFS: usize = 9;

const C0: f32 = 0.282_094_8; // ½√(1/π)
const C1: f32 = 0.488_602_5; // ½√(3/π)
const C2: f32 = 1.092_548_4; // ½√(15/π)
const C20: f32 = 0.315_391_57; // ¼√(5/π)

/// The nine basis functions at the unit direction `d` (storage order, module docs).
pub fn sh_basis(d: [f32; 3]) -> [f32; SH_COEFFS] {
    let [x, y, z] = d;
    [
        C0,
        C1 * x,
        C1 * y,
        C1 * z,
        C2 * x * z,
        C2 * x * y,
        C20 * (3.0 * y * y - 1.0),
        C2 * y * z,
        0.5 * C2 * (z * z - x * x),
    ]
}

/// The coefficients of the function `f(R⁻¹ω)`, `f` given by `coeffs` and `R` the right-handed
/// rotation by `angle` radians about +Y (which turns +Z towards +X): the sky turned by `angle`.
pub fn sh_rotate_y(coeffs: &[[f32; 3]; SH_COEFFS], angle: f32) -> [[f32; 3]; SH_COEFFS] {
    let mut out = *coeffs;
    // (index of m, index of −m, m) for each band's pairs.
    for (pos, neg, m) in [(3, 1, 1.0f32), (7, 5, 1.0), (8, 4, 2.0)] {
        let (s, c) = (m * angle).sin_cos();
        for k in 0..3 {
            let (a, b) = (coeffs[pos][k], coeffs[neg][k]);
            out[pos][k] = a * c - b * s;
            out[neg][k] = a * s + b * c;
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Directions and weights of a midpoint quadrature over the sphere (`n` × `2n` cells).
    fn sphere(n: usize) -> Vec<([f32; 3], f32)> {
        let mut out = Vec::new();
        for i in 0..n {
            let theta = (i as f32 + 0.5) / n as f32 * std::f32::consts::PI;
            for j in 0..2 * n {
                let phi = (j as f32 + 0.5) / (2 * n) as f32 * std::f32::consts::TAU;
                let w = (std::f32::consts::PI / n as f32).powi(2) * theta.sin();
                out.push(([theta.sin() * phi.sin(), theta.cos(), theta.sin() * phi.cos()], w));
            }
        }
        out
    }

    #[test]
    fn basis_is_orthonormal() {
        let q = sphere(128);
        for i in 0..SH_COEFFS {
            for j in 0..SH_COEFFS {
                let dot: f32 = q.iter().map(|(d, w)| sh_basis(*d)[i] * sh_basis(*d)[j] * w).sum();
                let want = if i == j { 1.0 } else { 0.0 };
                assert!((dot - want).abs() < 2e-3, "<Y{i}, Y{j}> = {dot}");
            }
        }
    }

    #[test]
    fn rotating_coefficients_is_rotating_the_function() {
        // A function inside the basis: f = Σ a_i Y_i; project f(R⁻¹ω) and compare.
        let a: [f32; SH_COEFFS] = [1.0, 0.3, -0.2, 0.5, 0.7, -0.4, 0.25, 0.6, -0.8];
        let coeffs: [[f32; 3]; SH_COEFFS] = a.map(|v| [v, 2.0 * v, -v]);
        let angle = 0.7f32;
        let rotated = sh_rotate_y(&coeffs, angle);
        let (s, c) = angle.sin_cos();
        let q = sphere(128);
        for (i, want) in rotated.iter().enumerate() {
            let projected: f32 = q
                .iter()
                .map(|([x, y, z], w)| {
                    // R⁻¹ω: turn back by `angle` (R turns +Z towards +X).
                    let back = [x * c - z * s, *y, x * s + z * c];
                    let f: f32 = sh_basis(back).iter().zip(&a).map(|(b, a)| b * a).sum();
                    f * sh_basis([*x, *y, *z])[i] * w
                })
                .sum();
            assert!(
                (projected - want[0]).abs() < 3e-3,
                "coefficient {i}: {projected} vs {}",
                want[0]
            );
            assert!((2.0 * projected - want[1]).abs() < 6e-3);
        }
        // A quarter turn takes +Z to +X: Y₁₁ (∝ z) becomes Y₁₋₁ (∝ x).
        let mut z = [[0.0; 3]; SH_COEFFS];
        z[3] = [1.0; 3];
        let turned = sh_rotate_y(&z, std::f32::consts::FRAC_PI_2);
        assert!((turned[1][0] - 1.0).abs() < 1e-6 && turned[3][0].abs() < 1e-6);
    }
}
