//! Spectral-to-RGB reduction of the Cornell box measurements (reflectances and lamp emission).
//!
//! Method: integrate the spectrum against the CIE 1931 2° colour-matching functions (the
//! analytic multi-lobe fit of Wyman, Sloan & Shirley, JCGT 2013) over 400–700 nm in 1 nm steps,
//! the spectrum linearly interpolated between its samples; convert XYZ to linear sRGB
//! (IEC 61966-2-1 matrix); then divide each channel by the value a perfectly flat spectrum
//! of 1.0 gives (white balance to the equal-energy illuminant E), so that a grey reflectance of
//! 0.7 comes out exactly as (0.7, 0.7, 0.7). Negative channels (out of the sRGB gamut) clamp to 0.

/// Cornell box reflectance spectra, 400..=700 nm every 4 nm (76 samples), one surface a line:
/// its name (`white`, `green`, `red`) then its samples. Source: Cornell University Program of
/// Computer Graphics, "Cornell Box Data" page, section "Surface reflectances".
const CORNELL_SPECTRA: &str = include_str!("cornell_spectra.txt");

/// The measured reflectance spectrum of the Cornell box's surface `name` (`white`, `green` or
/// `red`) from [`CORNELL_SPECTRA`].
pub fn cornell_reflectance(name: &str) -> [f64; 76] {
    let line = CORNELL_SPECTRA
        .lines()
        .find(|l| l.split_whitespace().next() == Some(name))
        .unwrap_or_else(|| panic!("no spectrum `{name}` in cornell_spectra.txt"));
    let samples: Vec<f64> = line.split_whitespace().skip(1).map(|v| v.parse().unwrap()).collect();
    samples.try_into().expect("76 samples a spectrum")
}

/// Cornell lamp emission, (wavelength nm, value) pairs, piecewise linear. Same source
/// ("Light" section; radiance in the page's units).
pub const CORNELL_LAMP: [(f64, f64); 4] = [(400.0, 0.0), (500.0, 8.0), (600.0, 15.6), (700.0, 18.4)];

/// One lobe of the piecewise Gaussian used by the colour-matching-function fit.
fn lobe(x: f64, mu: f64, s1: f64, s2: f64) -> f64 {
    let s = if x < mu { s1 } else { s2 };
    let t = (x - mu) / s;
    (-0.5 * t * t).exp()
}

/// CIE 1931 2° colour-matching functions (x̄, ȳ, z̄) at `nm`, multi-lobe analytic fit.
fn cmf(nm: f64) -> [f64; 3] {
    let x =
        1.056 * lobe(nm, 599.8, 37.9, 31.0) + 0.362 * lobe(nm, 442.0, 16.0, 26.7) - 0.065 * lobe(nm, 501.1, 20.4, 26.2);
    let y = 0.821 * lobe(nm, 568.8, 46.9, 40.5) + 0.286 * lobe(nm, 530.9, 16.3, 31.1);
    let z = 1.217 * lobe(nm, 437.0, 11.8, 36.0) + 0.681 * lobe(nm, 459.0, 26.0, 13.8);
    [x, y, z]
}

/// XYZ → linear sRGB (D65 primaries), IEC 61966-2-1.
fn xyz_to_linear_srgb([x, y, z]: [f64; 3]) -> [f64; 3] {
    [
        3.240_454_2 * x - 1.537_138_5 * y - 0.498_531_4 * z,
        -0.969_266_0 * x + 1.876_010_8 * y + 0.041_556_0 * z,
        0.055_643_4 * x - 0.204_025_9 * y + 1.057_225_2 * z,
    ]
}

/// Unnormalised linear-sRGB of a spectrum given as a function of wavelength.
fn raw_rgb(spectrum: impl Fn(f64) -> f64) -> [f64; 3] {
    let mut xyz = [0.0; 3];
    for nm in 400..=700 {
        let nm = f64::from(nm);
        // Trapezoid weights: half weight at the two ends.
        let w = if nm == 400.0 || nm == 700.0 { 0.5 } else { 1.0 };
        let s = spectrum(nm) * w;
        let c = cmf(nm);
        for k in 0..3 {
            xyz[k] += s * c[k];
        }
    }
    xyz_to_linear_srgb(xyz)
}

/// Linear RGB of a spectrum, white-balanced so that a flat spectrum `v` gives `(v, v, v)`.
/// Negative channels are clamped to zero.
pub fn spectrum_to_rgb(spectrum: impl Fn(f64) -> f64) -> [f64; 3] {
    let white = raw_rgb(|_| 1.0);
    let rgb = raw_rgb(spectrum);
    [0, 1, 2].map(|k| (rgb[k] / white[k]).max(0.0))
}

/// Piecewise-linear interpolation of samples taken every 4 nm from 400 nm.
pub fn sampled_4nm(samples: &[f64; 76]) -> impl Fn(f64) -> f64 + '_ {
    move |nm| {
        let t = ((nm - 400.0) / 4.0).clamp(0.0, 75.0);
        let i = (t.floor() as usize).min(74);
        let f = t - i as f64;
        samples[i] * (1.0 - f) + samples[i + 1] * f
    }
}

/// Piecewise-linear interpolation of (wavelength, value) pairs sorted by wavelength.
pub fn piecewise(points: &[(f64, f64)]) -> impl Fn(f64) -> f64 + '_ {
    move |nm| {
        let (first, last) = (points[0], points[points.len() - 1]);
        if nm <= first.0 {
            return first.1;
        }
        if nm >= last.0 {
            return last.1;
        }
        let j = points.iter().position(|p| p.0 > nm).unwrap_or(points.len() - 1);
        let (a, b) = (points[j - 1], points[j]);
        a.1 + (b.1 - a.1) * (nm - a.0) / (b.0 - a.0)
    }
}

/// Rounds each channel to 4 decimals (the precision written to MTL and glTF).
pub fn round4(c: [f64; 3]) -> [f64; 3] {
    c.map(|v| (v * 1e4).round() / 1e4)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn flat_spectrum_is_neutral() {
        let c = spectrum_to_rgb(|_| 0.7);
        for v in c {
            assert!((v - 0.7).abs() < 1e-12, "{c:?}");
        }
    }

    #[test]
    fn cmf_fit_peaks_near_one() {
        let y555 = cmf(555.0)[1];
        assert!((y555 - 1.0).abs() < 0.01, "{y555}");
    }

    #[test]
    fn cornell_colours_have_the_expected_hues() {
        let red = spectrum_to_rgb(sampled_4nm(&cornell_reflectance("red")));
        let green = spectrum_to_rgb(sampled_4nm(&cornell_reflectance("green")));
        let white = spectrum_to_rgb(sampled_4nm(&cornell_reflectance("white")));
        assert!(red[0] > 0.4 && red[1] < 0.1 && red[2] < 0.1, "{red:?}");
        assert!(green[1] > 0.35 && green[0] < 0.2 && green[2] < 0.15, "{green:?}");
        assert!(white.iter().all(|v| (0.65..0.8).contains(v)), "{white:?}");
    }

    #[test]
    fn interpolation_hits_samples() {
        let white = cornell_reflectance("white");
        let f = sampled_4nm(&white);
        assert_eq!(f(400.0), 0.343);
        assert_eq!(f(700.0), 0.737);
        assert!((f(402.0) - 0.394).abs() < 1e-12);
        let g = piecewise(&CORNELL_LAMP);
        assert!((g(550.0) - 11.8).abs() < 1e-12);
    }
}
