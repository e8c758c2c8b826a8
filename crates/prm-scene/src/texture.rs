//! Base-colour textures: 8-bit sRGB storage, bilinear sampling to linear RGB with wrap-around.

use glam::{Vec2, Vec3};
use std::sync::OnceLock;

/// An sRGB-encoded RGB texture.
#[derive(Clone, Debug, PartialEq)]
pub struct Texture {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Row-major sRGB texels, top row first.
    pub texels: Vec<[u8; 3]>,
}

fn srgb_table() -> &'static [f32; 256] {
    static TABLE: OnceLock<[f32; 256]> = OnceLock::new();
    TABLE.get_or_init(|| {
        let mut t = [0.0; 256];
        for (i, v) in t.iter_mut().enumerate() {
            let c = i as f32 / 255.0;
            *v = if c <= 0.04045 {
                c / 12.92
            } else {
                ((c + 0.055) / 1.055).powf(2.4)
            };
        }
        t
    })
}

impl Texture {
    /// Decodes an image file into a texture.
    pub fn from_image(img: image::DynamicImage) -> Texture {
        let rgb = img.to_rgb8();
        let (width, height) = rgb.dimensions();
        let texels = rgb.pixels().map(|p| p.0).collect();
        Texture { width, height, texels }
    }

    /// Linear texel value at integer coordinates (wrapped).
    fn texel(&self, x: i64, y: i64) -> Vec3 {
        let t = srgb_table();
        let x = x.rem_euclid(self.width as i64) as usize;
        let y = y.rem_euclid(self.height as i64) as usize;
        let [r, g, b] = self.texels[y * self.width as usize + x];
        Vec3::new(t[r as usize], t[g as usize], t[b as usize])
    }

    /// Bilinear sample at texture coordinate `uv` (v = 0 at the bottom row, OBJ convention;
    /// glTF coordinates are flipped by its loader), repeating outside [0, 1].
    pub fn sample(&self, uv: Vec2) -> Vec3 {
        if self.width == 0 || self.height == 0 || !uv.is_finite() {
            return Vec3::splat(0.5);
        }
        let x = uv.x.fract() * self.width as f32 - 0.5;
        let y = (1.0 - uv.y).fract() * self.height as f32 - 0.5;
        let (x0, y0) = (x.floor(), y.floor());
        let (fx, fy) = (x - x0, y - y0);
        let (x0, y0) = (x0 as i64, y0 as i64);
        let a = self.texel(x0, y0).lerp(self.texel(x0 + 1, y0), fx);
        let b = self.texel(x0, y0 + 1).lerp(self.texel(x0 + 1, y0 + 1), fx);
        a.lerp(b, fy)
    }

    /// Mean linear colour over all texels.
    pub fn mean(&self) -> Vec3 {
        let t = srgb_table();
        let mut s = glam::DVec3::ZERO;
        for [r, g, b] in &self.texels {
            s += glam::DVec3::new(t[*r as usize] as f64, t[*g as usize] as f64, t[*b as usize] as f64);
        }
        (s / self.texels.len().max(1) as f64).as_vec3()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn srgb_endpoints_and_midpoint() {
        let t = srgb_table();
        assert_eq!(t[0], 0.0);
        assert!((t[255] - 1.0).abs() < 1e-6);
        assert!(
            (t[188] - 0.5).abs() < 0.01,
            "sRGB 188 is about linear 0.5, got {}",
            t[188]
        );
    }

    #[test]
    fn sampling_wraps_and_interpolates() {
        let tex = Texture {
            width: 2,
            height: 1,
            texels: vec![[0, 0, 0], [255, 255, 255]],
        };
        // Texel centres at u = 0.25 (black) and 0.75 (white); halfway is grey 0.5 linear.
        assert!(tex.sample(Vec2::new(0.25, 0.5)).x < 1e-6);
        assert!((tex.sample(Vec2::new(0.75, 0.5)).x - 1.0).abs() < 1e-6);
        assert!((tex.sample(Vec2::new(0.5, 0.5)).x - 0.5).abs() < 1e-6);
        assert_eq!(tex.sample(Vec2::new(1.25, 0.5)), tex.sample(Vec2::new(0.25, 0.5)));
    }
}
