//! `cargo xtask eval compare TEST.exr REFERENCE.exr`: the image metrics every accuracy target
//! uses (`../shared/notes/metrics.md`), on two linear EXRs of the same size.
//!
//! - error: ‖t − r‖₂ / ‖r‖₂ over pixels × RGB after a 4×4 box downsample of both, and at full
//!   resolution;
//! - energy: Σ t / Σ r;
//! - shape error: the downsampled error left after t is scaled by (t·r)/(t·t);
//! - local error: the largest error over 8×8-pixel windows (full resolution), divided by the
//!   whole image's (blotches and spikes), with where that window is and how bright its
//!   reference is against the image's: a window at a few percent of the image's brightness
//!   is relative noise, one on a line of single pixels is geometry (McGuire's right
//!   wall meets the floor on the image diagonal, through pixel centres, which the rasterizer
//!   gives to the wall and the tracer to the floor).
//!
//! `--diff OUT.png` also writes where the error is: the reference, the test and their
//! difference side by side, all three scaled by the reference's mean luminance, the difference
//! red where the test is brighter and blue where it is darker.

use anyhow::{bail, Context, Result};
use std::path::Path;

/// A linear RGB image, row-major.
struct Rgb {
    width: usize,
    height: usize,
    px: Vec<[f64; 3]>,
}

fn load(path: &Path) -> Result<Rgb> {
    let img = prm_play::output::read_exr(path).with_context(|| format!("reading {}", path.display()))?;
    Ok(Rgb {
        width: img.width as usize,
        height: img.height as usize,
        px: img.rgb.iter().map(|p| p.map(f64::from)).collect(),
    })
}

/// Box-downsampled by `k` (partial blocks at the right and bottom edges are dropped).
fn downsample(img: &Rgb, k: usize) -> Rgb {
    let (w, h) = (img.width / k, img.height / k);
    let mut px = vec![[0.0; 3]; w * h];
    for y in 0..h {
        for x in 0..w {
            let mut s = [0.0; 3];
            for dy in 0..k {
                for dx in 0..k {
                    let p = img.px[(y * k + dy) * img.width + x * k + dx];
                    for c in 0..3 {
                        s[c] += p[c];
                    }
                }
            }
            px[y * w + x] = s.map(|v| v / (k * k) as f64);
        }
    }
    Rgb {
        width: w,
        height: h,
        px,
    }
}

/// ‖s·t − r‖ / ‖r‖ over `pixels` (indices).
fn error(t: &Rgb, r: &Rgb, scale: f64, pixels: impl Iterator<Item = usize>) -> f64 {
    let (mut d2, mut r2) = (0.0, 0.0);
    for i in pixels {
        for c in 0..3 {
            d2 += (scale * t.px[i][c] - r.px[i][c]).powi(2);
            r2 += r.px[i][c].powi(2);
        }
    }
    (d2 / r2.max(1e-300)).sqrt()
}

/// The metrics of `t` against `r`.
#[derive(Debug)]
pub struct Metrics {
    pub error: f64,
    pub error_full: f64,
    pub energy: f64,
    pub shape: f64,
    pub local: f64,
    /// The worst window's top-left pixel (x, y).
    pub local_at: (usize, usize),
    /// The worst window's reference RMS over the whole reference's.
    pub local_brightness: f64,
}

fn metrics(t: &Rgb, r: &Rgb) -> Metrics {
    let (t4, r4) = (downsample(t, 4), downsample(r, 4));
    let n4 = t4.px.len();
    let error = error(&t4, &r4, 1.0, 0..n4);
    let error_full = self::error(t, r, 1.0, 0..t.px.len());
    let sum = |img: &Rgb| img.px.iter().map(|p| p[0] + p[1] + p[2]).sum::<f64>();
    let energy = sum(t) / sum(r).max(1e-300);
    let dot = |a: &Rgb, b: &Rgb| {
        a.px.iter()
            .zip(&b.px)
            .map(|(p, q)| p[0] * q[0] + p[1] * q[1] + p[2] * q[2])
            .sum::<f64>()
    };
    let best = dot(&t4, &r4) / dot(&t4, &t4).max(1e-300);
    let shape = self::error(&t4, &r4, best, 0..n4);
    let (mut worst, mut local_at, mut worst_r2) = (0.0f64, (0, 0), 0.0);
    for by in 0..t.height / 8 {
        for bx in 0..t.width / 8 {
            let window = (0..64).map(|k| (by * 8 + k / 8) * t.width + bx * 8 + k % 8);
            // Windows where the reference is black say nothing relative.
            let r2: f64 = window.clone().map(|i| r.px[i].iter().map(|v| v * v).sum::<f64>()).sum();
            if r2 > 0.0 {
                let e = self::error(t, r, 1.0, window);
                if e > worst {
                    (worst, local_at, worst_r2) = (e, (bx * 8, by * 8), r2);
                }
            }
        }
    }
    let image_r2: f64 = r.px.iter().map(|p| p.iter().map(|v| v * v).sum::<f64>()).sum();
    let local_brightness = (worst_r2 / 64.0 / (image_r2 / r.px.len() as f64).max(1e-300)).sqrt();
    Metrics {
        error,
        error_full,
        energy,
        shape,
        local: worst / error_full.max(1e-300),
        local_at,
        local_brightness,
    }
}

/// The metrics of the EXR `test` against the EXR `reference` (same size).
pub fn compare_files(test: &Path, reference: &Path) -> Result<Metrics> {
    let (t, r) = load_pair(test, reference)?;
    Ok(metrics(&t, &r))
}

/// The EXRs `test` and `reference`, refused unless of one size.
fn load_pair(test: &Path, reference: &Path) -> Result<(Rgb, Rgb)> {
    let (t, r) = (load(test)?, load(reference)?);
    if (t.width, t.height) != (r.width, r.height) {
        bail!(
            "{} is {}x{}, {} {}x{}: compare images of one size",
            test.display(),
            t.width,
            t.height,
            reference.display(),
            r.width,
            r.height
        );
    }
    Ok((t, r))
}

/// Writes `reference`, `test` and their difference side by side to the PNG `out` (see the
/// module doc).
fn write_diff(test: &Rgb, reference: &Rgb, out: &Path) -> Result<()> {
    let luminance = |p: &[f64; 3]| 0.2126 * p[0] + 0.7152 * p[1] + 0.0722 * p[2];
    let mean = reference.px.iter().map(luminance).sum::<f64>() / reference.px.len().max(1) as f64;
    // Mean luminance at a quarter of full scale; the difference at twice the gain.
    let gain = 0.25 / mean.max(1e-300);
    let byte = |v: f64| (255.0 * v.clamp(0.0, 1.0).powf(1.0 / 2.2)).round() as u8;
    let (w, h) = (reference.width as u32, reference.height as u32);
    let mut img = image::RgbImage::new(3 * w, h);
    for (i, (t, r)) in test.px.iter().zip(&reference.px).enumerate() {
        let (x, y) = ((i % reference.width) as u32, (i / reference.width) as u32);
        img.put_pixel(x, y, image::Rgb(r.map(|v| byte(gain * v))));
        img.put_pixel(w + x, y, image::Rgb(t.map(|v| byte(gain * v))));
        let d = 2.0 * gain * (luminance(t) - luminance(r));
        img.put_pixel(2 * w + x, y, image::Rgb([byte(d), 0, byte(-d)]));
    }
    img.save(out).with_context(|| format!("writing {}", out.display()))
}

/// Runs `compare TEST REF [--diff OUT.png]`.
pub fn run(args: &[String]) -> Result<()> {
    let (test, reference, diff) = match args {
        [test, reference] => (test, reference, None),
        [test, reference, flag, out] if flag == "--diff" => (test, reference, Some(Path::new(out))),
        _ => bail!("usage: cargo xtask eval compare TEST.exr REFERENCE.exr [--diff OUT.png]"),
    };
    let (t, r) = load_pair(Path::new(test), Path::new(reference))?;
    let m = metrics(&t, &r);
    if let Some(out) = diff {
        write_diff(&t, &r, out)?;
    }
    println!(
        "error {:.2}% (4x4 downsample), {:.2}% full resolution; energy {:.3}; shape error {:.2}%; local error {:.2}x (8x8 window at {}, {}; its reference at {:.0}% of the image's RMS)",
        100.0 * m.error,
        100.0 * m.error_full,
        m.energy,
        100.0 * m.shape,
        m.local,
        m.local_at.0,
        m.local_at.1,
        100.0 * m.local_brightness
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn image(w: usize, h: usize, f: impl Fn(usize, usize) -> f64) -> Rgb {
        Rgb {
            width: w,
            height: h,
            px: (0..w * h).map(|i| [f(i % w, i / w); 3]).collect(),
        }
    }

    #[test]
    fn a_global_scale_is_energy_bias_not_shape_error() {
        let r = image(32, 32, |x, y| 1.0 + (x + y) as f64 * 0.1);
        let t = image(32, 32, |x, y| 0.8 * (1.0 + (x + y) as f64 * 0.1));
        let m = metrics(&t, &r);
        assert!((m.energy - 0.8).abs() < 1e-12);
        assert!((m.error - 0.2).abs() < 1e-12 && (m.error_full - 0.2).abs() < 1e-12);
        assert!(m.shape < 1e-12, "{m:?}");
        assert!((m.local - 1.0).abs() < 1e-9, "a uniform error has no blotch: {m:?}");
    }

    #[test]
    fn pixel_noise_averages_out_in_the_downsample_and_a_blotch_shows_locally() {
        let r = image(32, 32, |_, _| 1.0);
        // ±0.2 in a checkerboard: cancels in every 4×4 block.
        let noisy = image(32, 32, |x, y| if (x + y) % 2 == 0 { 1.2 } else { 0.8 });
        let m = metrics(&noisy, &r);
        assert!(m.error < 1e-12 && (m.error_full - 0.2).abs() < 1e-12, "{m:?}");
        let blotch = image(32, 32, |x, y| if x < 8 && y < 8 { 2.0 } else { 1.0 });
        let m = metrics(&blotch, &r);
        assert!(m.local > 3.0, "{m:?}");
        assert_eq!(m.local_at, (0, 0), "{m:?}");
        assert!((m.local_brightness - 1.0).abs() < 1e-12, "{m:?}");
    }

    #[test]
    fn the_diff_shows_reference_test_and_their_difference() {
        let r = image(16, 8, |_, _| 1.0);
        let t = image(16, 8, |x, _| if x < 8 { 2.0 } else { 0.5 });
        let out = std::env::temp_dir().join(format!("prm-compare-diff-{}.png", std::process::id()));
        write_diff(&t, &r, &out).unwrap();
        let png = image::open(&out).unwrap().to_rgb8();
        std::fs::remove_file(&out).ok();
        assert_eq!(png.dimensions(), (48, 8));
        // Brighter on the left: red; darker on the right: blue; the panels as bright as they are.
        let (left, right) = (png.get_pixel(32 + 2, 4), png.get_pixel(32 + 12, 4));
        assert!(left[0] > 0 && left[2] == 0, "{left:?}");
        assert!(right[2] > 0 && right[0] == 0, "{right:?}");
        assert!(png.get_pixel(16 + 2, 4)[1] > png.get_pixel(2, 4)[1]);
    }
}
