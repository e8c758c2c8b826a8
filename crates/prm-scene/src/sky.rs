//! The sky: radiance arriving from infinitely far away in every direction the scene leaves
//! open, a constant colour or an equirectangular environment map (Radiance `.hdr` or OpenEXR),
//! with an intensity and a rotation about +Y that change at run time. The sun is a
//! [`crate::Light::Directional`] beside it.
//!
//! Map convention: row 0 is the zenith (+Y) and the last row the nadir, the polar angle `θ`
//! grows linearly down the rows; column `u ∈ [0, 1)` is the azimuth `φ = 2πu` from +Z towards
//! +X, so a texel's direction is `(sin θ sin φ, cos θ, sin θ cos φ)`, the frame of
//! [`prm_format::sh_basis`]. Lookups take the nearest texel; [`Sky::sh`] projects the same
//! texels (midpoint rule, solid angle `(2π/W)(π/H) sin θ` each), so the two agree.

use std::path::Path;
use std::sync::Arc;

use glam::Vec3;
use prm_format::{sh_basis, sh_rotate_y, SH_COEFFS};

use crate::SceneError;

/// Largest accepted map side, in texels.
pub const MAX_SKY_MAP_SIDE: usize = 16384;

/// Smallest accepted map, width × height. The projection's midpoint rule samples each texel at
/// its centre: with fewer columns than the basis has azimuthal frequencies, or rows too few for
/// its polar ones, a constant map does not project to a constant (1×1 lights 7×
/// too bright, 2×1 10× too dark, 1×2 3× too bright; 8×4 and larger within 1%).
pub const MIN_SKY_MAP: (usize, usize) = (8, 4);

/// An equirectangular environment map, linear RGB radiance (W/(m²·sr)).
#[derive(Clone, Debug, PartialEq)]
pub struct SkyMap {
    /// Width in texels (the azimuth).
    pub width: usize,
    /// Height in texels (the polar angle).
    pub height: usize,
    /// Row-major from the zenith row.
    pub texels: Vec<Vec3>,
}

impl SkyMap {
    /// Loads a `.hdr` (Radiance RGBE) or `.exr` map; every texel must be finite and ≥ 0.
    pub fn load(path: &Path) -> Result<SkyMap, SceneError> {
        let malformed = |message: String| SceneError::Malformed {
            path: path.to_path_buf(),
            line: None,
            message,
        };
        if path.is_dir() {
            return Err(malformed("a directory, not a sky map (.hdr or .exr)".into()));
        }
        if !path.is_file() {
            return Err(SceneError::NotFound(path.to_path_buf()));
        }
        let ext = path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase);
        let (width, height, rgb) = match ext.as_deref() {
            Some("exr") => crate::read_exr_rgb(path).map_err(|e| malformed(e.to_string()))?,
            Some("hdr") => {
                let img = image::ImageReader::open(path)
                    .map_err(|source| SceneError::Io {
                        path: path.to_path_buf(),
                        source,
                    })?
                    .with_guessed_format()
                    .map_err(|source| SceneError::Io {
                        path: path.to_path_buf(),
                        source,
                    })?
                    .decode()
                    .map_err(|e| malformed(format!("not a readable Radiance HDR image: {e}")))?
                    .to_rgb32f();
                let (w, h) = (img.width() as usize, img.height() as usize);
                (w, h, img.pixels().map(|p| p.0).collect())
            }
            _ => return Err(malformed("a sky map must be .hdr or .exr".into())),
        };
        let map = SkyMap {
            width,
            height,
            texels: rgb.into_iter().map(Vec3::from).collect(),
        };
        map.validate().map_err(malformed)?;
        Ok(map)
    }

    fn validate(&self) -> Result<(), String> {
        let (w, h) = MIN_SKY_MAP;
        if self.width < w || self.height < h || self.width > MAX_SKY_MAP_SIDE || self.height > MAX_SKY_MAP_SIDE {
            return Err(format!(
                "sky map is {}×{}: it must be {w}×{h} to {MAX_SKY_MAP_SIDE}×{MAX_SKY_MAP_SIDE} texels",
                self.width, self.height
            ));
        }
        if self.texels.len() != self.width * self.height {
            return Err(format!(
                "{} texels for {}×{}",
                self.texels.len(),
                self.width,
                self.height
            ));
        }
        if let Some(i) = self.texels.iter().position(|t| !t.is_finite() || t.min_element() < 0.0) {
            return Err(format!(
                "texel {i} is {:?}: radiance must be finite and ≥ 0",
                self.texels[i]
            ));
        }
        Ok(())
    }

    /// A `width × height` map (each side at least 1) whose texel is `radiance` of its centre's
    /// direction.
    pub fn from_fn(width: usize, height: usize, radiance: impl Fn(Vec3) -> Vec3) -> SkyMap {
        let mut map = SkyMap {
            width: width.max(1),
            height: height.max(1),
            texels: Vec::new(),
        };
        map.texels = (0..map.width * map.height)
            .map(|i| radiance(map.direction(i % map.width, i / map.width)))
            .collect();
        map
    }

    /// The unit direction of texel `(col, row)`'s centre.
    pub fn direction(&self, col: usize, row: usize) -> Vec3 {
        let theta = (row as f32 + 0.5) / self.height as f32 * std::f32::consts::PI;
        let phi = (col as f32 + 0.5) / self.width as f32 * std::f32::consts::TAU;
        Vec3::new(theta.sin() * phi.sin(), theta.cos(), theta.sin() * phi.cos())
    }

    /// The texel nearest the unit direction `d`.
    pub fn lookup(&self, d: Vec3) -> Vec3 {
        let theta = d.y.clamp(-1.0, 1.0).acos();
        let phi = d.x.atan2(d.z).rem_euclid(std::f32::consts::TAU);
        let row = ((theta / std::f32::consts::PI * self.height as f32) as usize).min(self.height - 1);
        let col = ((phi / std::f32::consts::TAU * self.width as f32) as usize).min(self.width - 1);
        self.texels[row * self.width + col]
    }
}

/// Where the sky's radiance comes from.
#[derive(Clone, Debug, PartialEq)]
pub enum SkySource {
    /// The same radiance from every direction.
    Uniform(Vec3),
    /// An environment map (shared, not copied, between clones).
    Map(Arc<SkyMap>),
}

/// A sky light: its source at unit intensity, that source's projection onto the basis, and the
/// current intensity and rotation.
#[derive(Clone, Debug, PartialEq)]
pub struct Sky {
    source: SkySource,
    /// The source's coefficients at intensity 1 and rotation 0.
    sh: [[f32; 3]; SH_COEFFS],
    /// Multiplies the source's radiance.
    pub intensity: f32,
    /// Rotation about +Y in radians (right-handed: +Z turns towards +X).
    pub rotation: f32,
}

impl Sky {
    /// A sky of constant radiance `radiance`.
    pub fn uniform(radiance: Vec3) -> Sky {
        let mut sh = [[0.0; 3]; SH_COEFFS];
        // ∫ L·Y₀₀ dω over the sphere: 4π·½√(1/π) = 2√π.
        sh[0] = (radiance * 2.0 * std::f32::consts::PI.sqrt()).to_array();
        Sky {
            source: SkySource::Uniform(radiance),
            sh,
            intensity: 1.0,
            rotation: 0.0,
        }
    }

    /// A sky from an environment map (module docs for its orientation).
    pub fn from_map(map: SkyMap) -> Sky {
        // Summed in f64: an 8192×4096 map's 33 M terms summed in f32 loses 15%.
        let mut sum = [[0.0f64; 3]; SH_COEFFS];
        let cell = std::f64::consts::TAU / map.width as f64 * std::f64::consts::PI / map.height as f64;
        for row in 0..map.height {
            let theta = (row as f64 + 0.5) / map.height as f64 * std::f64::consts::PI;
            let w = cell * theta.sin();
            for col in 0..map.width {
                let l = map.texels[row * map.width + col].as_dvec3() * w;
                let y = sh_basis(map.direction(col, row).to_array());
                for (c, b) in sum.iter_mut().zip(y) {
                    for k in 0..3 {
                        c[k] += b as f64 * l[k];
                    }
                }
            }
        }
        let sh = sum.map(|c| c.map(|v| v as f32));
        Sky {
            source: SkySource::Map(Arc::new(map)),
            sh,
            intensity: 1.0,
            rotation: 0.0,
        }
    }

    /// Parses a sky spec: `R,G,B` (a constant radiance, finite, ≥ 0) or the path of a `.hdr` or
    /// `.exr` map.
    pub fn parse(spec: &str) -> Result<Sky, SceneError> {
        let parts: Vec<&str> = spec.split(',').collect();
        if parts.len() == 3 {
            if let Ok(v) = parts
                .iter()
                .map(|p| p.trim().parse::<f32>())
                .collect::<Result<Vec<_>, _>>()
            {
                let c = Vec3::new(v[0], v[1], v[2]);
                if !c.is_finite() || c.min_element() < 0.0 {
                    return Err(SceneError::Malformed {
                        path: spec.into(),
                        line: None,
                        message: "a sky colour must be finite and ≥ 0".into(),
                    });
                }
                return Ok(Sky::uniform(c));
            }
        }
        // Numbers and commas only, but not three numbers: a mistyped colour, not a file.
        let numeric = spec.contains(',')
            && spec
                .chars()
                .all(|c| c.is_ascii_digit() || matches!(c, ',' | '.' | '-' | '+' | 'e' | 'E' | ' '));
        if numeric && !Path::new(spec).exists() {
            return Err(SceneError::Malformed {
                path: spec.into(),
                line: None,
                message: format!(
                    "a sky colour is three numbers R,G,B (this has {}); a sky map is a .hdr or .exr file",
                    parts.len()
                ),
            });
        }
        SkyMap::load(Path::new(spec)).map(Sky::from_map)
    }

    /// The source at unit intensity.
    pub fn source(&self) -> &SkySource {
        &self.source
    }

    /// Radiance arriving from the unit direction `d` (travelling along `-d`).
    pub fn radiance(&self, d: Vec3) -> Vec3 {
        let l = match &self.source {
            SkySource::Uniform(c) => *c,
            SkySource::Map(m) => {
                let (s, c) = self.rotation.sin_cos();
                m.lookup(Vec3::new(d.x * c - d.z * s, d.y, d.x * s + d.z * c))
            }
        };
        l * self.intensity
    }

    /// The coefficients of the sky at its intensity and rotation ([`prm_format::sh_basis`]).
    pub fn sh(&self) -> [[f32; 3]; SH_COEFFS] {
        sh_rotate_y(&self.sh, self.rotation).map(|c| c.map(|v| v * self.intensity))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A map with a smooth gradient and a hot band, to tell orientations apart.
    fn map(w: usize, h: usize) -> SkyMap {
        SkyMap::from_fn(w, h, |d| {
            Vec3::new(1.0 + d.y, 0.5 + 0.5 * d.x.max(0.0), 0.2 + d.z.max(0.0))
        })
    }

    /// The basis order, measured: the irradiance of open surfaces of every orientation under a
    /// smooth sky (a blue gradient and a broad warm glow towards +X, no sun), exactly (by
    /// quadrature over the map) and from the sky's coefficients up to order 1 or 2, each with the
    /// transfer of an open surface computed the same way. Order 2 keeps the relative RMS error
    /// near 1%, order 1 does not.
    #[test]
    fn order_two_represents_a_smooth_sky_s_irradiance() {
        let map = SkyMap::from_fn(128, 64, |d| {
            Vec3::new(0.3, 0.5, 0.9) * d.y.max(0.0) * 1.5
                + Vec3::new(1.2, 0.8, 0.4) * (0.5 + 0.5 * d.x).powi(2) * d.y.max(0.0).sqrt()
        });
        let texels: Vec<(Vec3, Vec3, f32)> = (0..map.height)
            .flat_map(|row| (0..map.width).map(move |col| (col, row)))
            .map(|(col, row)| {
                let theta = (row as f32 + 0.5) / map.height as f32 * std::f32::consts::PI;
                let w =
                    std::f32::consts::TAU / map.width as f32 * std::f32::consts::PI / map.height as f32 * theta.sin();
                (map.direction(col, row), map.texels[row * map.width + col], w)
            })
            .collect();
        let sky = Sky::from_map(map);
        let coeffs = sky.sh();
        let (mut err1, mut err2, mut norm) = (0.0f64, 0.0f64, 0.0f64);
        for i in 0..200 {
            // Normals spread over the sphere (a Fibonacci spiral).
            let y = 1.0 - 2.0 * (i as f32 + 0.5) / 200.0;
            let phi = i as f32 * 2.399_963;
            let n = Vec3::new((1.0 - y * y).sqrt() * phi.sin(), y, (1.0 - y * y).sqrt() * phi.cos());
            let (mut exact, mut transfer) = (Vec3::ZERO, [0.0f32; SH_COEFFS]);
            for (d, l, w) in &texels {
                let c = n.dot(*d).max(0.0) * w;
                exact += *l * c;
                for (t, b) in transfer.iter_mut().zip(sh_basis(d.to_array())) {
                    *t += b * c;
                }
            }
            let upto = |order: usize| {
                (0..(order + 1) * (order + 1)).fold(Vec3::ZERO, |e, c| e + Vec3::from(coeffs[c]) * transfer[c])
            };
            err1 += (upto(1) - exact).length_squared() as f64;
            err2 += (upto(2) - exact).length_squared() as f64;
            norm += exact.length_squared() as f64;
        }
        let (e1, e2) = ((err1 / norm).sqrt(), (err2 / norm).sqrt());
        println!("open-surface irradiance error: order 1 {e1:.4}, order 2 {e2:.4}");
        assert!(e2 < 0.02 && e1 > 2.0 * e2, "order 1 {e1:.4}, order 2 {e2:.4}");
    }

    #[test]
    fn lookup_inverts_direction() {
        let m = map(64, 32);
        for (col, row) in [(0, 0), (17, 5), (63, 31), (32, 16)] {
            let d = m.direction(col, row);
            assert_eq!(m.lookup(d), m.texels[row * 64 + col], "texel ({col}, {row})");
        }
    }

    #[test]
    fn uniform_sky_projects_to_its_constant() {
        let u = Sky::uniform(Vec3::new(1.0, 2.0, 0.5));
        let mut m = map(128, 64);
        m.texels.iter_mut().for_each(|t| *t = Vec3::new(1.0, 2.0, 0.5));
        let s = Sky::from_map(m);
        for (a, b) in u.sh().iter().zip(s.sh()) {
            for k in 0..3 {
                assert!((a[k] - b[k]).abs() < 2e-3, "{a:?} vs {b:?}");
            }
        }
        // Irradiance on an open upward plane: π·L, from the band-0 and band-2 cosine lobes.
        assert!((u.radiance(Vec3::Y) - Vec3::new(1.0, 2.0, 0.5)).length() < 1e-6);
    }

    #[test]
    fn rotation_turns_radiance_and_coefficients_alike() {
        let mut s = Sky::from_map(map(256, 128));
        let angle = 1.1f32;
        s.rotation = angle;
        s.intensity = 2.0;
        // The rotated sky, resampled as a map, projects to the rotated coefficients.
        let probe = map(256, 128);
        let mut turned = probe.clone();
        for row in 0..128 {
            for col in 0..256 {
                turned.texels[row * 256 + col] = s.radiance(probe.direction(col, row));
            }
        }
        let direct = Sky::from_map(turned).sh();
        for (i, (a, b)) in s.sh().iter().zip(direct).enumerate() {
            for k in 0..3 {
                assert!((a[k] - b[k]).abs() < 0.05, "coefficient {i}: {a:?} vs {b:?}");
            }
        }
    }

    #[test]
    fn parse_takes_a_colour_or_refuses_a_bad_path() {
        assert_eq!(
            Sky::parse("0.5, 1, 2").unwrap().radiance(Vec3::X),
            Vec3::new(0.5, 1.0, 2.0)
        );
        assert!(Sky::parse("1,-1,2").is_err());
        assert!(matches!(Sky::parse("/no/such/sky.hdr"), Err(SceneError::NotFound(_))));
        let err = Sky::parse("1,1").unwrap_err();
        assert!(err.to_string().contains("three numbers R,G,B (this has 2)"), "{err}");
    }

    /// Maps smaller than [`MIN_SKY_MAP`] are refused (a constant one did not project to a
    /// constant), a directory is named as one, and a large map's projection keeps its constant
    /// (summed in f64; f32 lost 15% at 8192×4096).
    #[test]
    fn tiny_maps_and_directories_are_refused_and_large_maps_sum_exactly() {
        let dir = std::env::temp_dir().join(format!("prm-sky-small-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let tiny = dir.join("tiny.exr");
        crate::write_exr_rgb(&tiny, 2, 1, &[[1.0; 3]; 2]).unwrap();
        let err = SkyMap::load(&tiny).unwrap_err().to_string();
        assert!(err.contains("2×1") && err.contains("8×4"), "{err}");
        let err = SkyMap::load(&dir).unwrap_err().to_string();
        assert!(err.contains("a directory"), "{err}");
        std::fs::remove_dir_all(&dir).unwrap();
        // 4096×2048 = 8.4 M texels of radiance 1: the constant term is 2√π.
        let big = Sky::from_map(SkyMap::from_fn(4096, 2048, |_| Vec3::ONE));
        let dc = big.sh()[0][0] / (2.0 * std::f32::consts::PI.sqrt());
        assert!((dc - 1.0).abs() < 1e-4, "{dc}");
    }

    #[test]
    fn hdr_and_exr_maps_load_alike() {
        let dir = std::env::temp_dir().join(format!("prm-sky-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let m = map(32, 16);
        let exr = dir.join("sky.exr");
        let rgb: Vec<[f32; 3]> = m.texels.iter().map(|t| t.to_array()).collect();
        crate::write_exr_rgb(&exr, 32, 16, &rgb).unwrap();
        assert_eq!(SkyMap::load(&exr).unwrap(), m);
        let hdr = dir.join("sky.hdr");
        let img = image::Rgb32FImage::from_fn(32, 16, |x, y| image::Rgb(rgb[(y * 32 + x) as usize]));
        image::DynamicImage::ImageRgb32F(img).save(&hdr).unwrap();
        let back = SkyMap::load(&hdr).unwrap();
        // RGBE keeps about 8 bits of mantissa.
        for (a, b) in back.texels.iter().zip(&m.texels) {
            assert!((*a - *b).abs().max_element() <= 0.01 * b.max_element(), "{a} vs {b}");
        }
        let bad = dir.join("sky.png");
        std::fs::write(&bad, b"x").unwrap();
        assert!(SkyMap::load(&bad).is_err());
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
