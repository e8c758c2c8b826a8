//! Image output: EXR of linear radiance (`exr::write_rgb_file`) and tone-mapped sRGB PNG.
//!
//! Tone mapping (display and PNG only): multiply by `exposure`, clamp to [0, 1], encode sRGB.

use std::path::Path;

use prm_scene::ExportError;

use crate::{Image, PlayError};

/// Linear → sRGB-encoded byte, with exposure and clamping.
pub fn tone_map(v: f32, exposure: f32) -> u8 {
    let x = (v * exposure).clamp(0.0, 1.0);
    let s = if x <= 0.003_130_8 {
        12.92 * x
    } else {
        1.055 * x.powf(1.0 / 2.4) - 0.055
    };
    (s * 255.0 + 0.5) as u8
}

/// Writes linear radiance as an RGB EXR (f32 samples).
pub fn write_exr(path: &Path, image: &Image) -> Result<(), PlayError> {
    let w = image.width as usize;
    exr::prelude::write_rgb_file(path, w, image.height as usize, |x, y| {
        let p = image.rgb[y * w + x];
        (p[0], p[1], p[2])
    })
    .map_err(|e| PlayError::Output {
        path: path.to_path_buf(),
        message: e.to_string(),
    })
}

/// Writes linear radiance as a small RGB EXR: half-float samples, ZIP compression (golden images).
pub fn write_exr_compact(path: &Path, image: &Image) -> Result<(), PlayError> {
    use exr::prelude::*;
    let w = image.width as usize;
    let channels = SpecificChannels::rgb(|pos: Vec2<usize>| {
        let p = image.rgb[pos.1 * w + pos.0];
        (f16::from_f32(p[0]), f16::from_f32(p[1]), f16::from_f32(p[2]))
    });
    Image::from_encoded_channels((w, image.height as usize), Encoding::SMALL_LOSSLESS, channels)
        .write()
        .to_file(path)
        .map_err(|e| PlayError::Output {
            path: path.to_path_buf(),
            message: e.to_string(),
        })
}

/// Writes the tone-mapped image as an 8-bit sRGB PNG.
pub fn write_png(path: &Path, image: &Image, exposure: f32) -> Result<(), PlayError> {
    let bytes: Vec<u8> = image
        .rgb
        .iter()
        .flat_map(|p| p.map(|c| tone_map(c, exposure)))
        .collect();
    image::save_buffer(path, &bytes, image.width, image.height, image::ExtendedColorType::Rgb8).map_err(|e| {
        PlayError::Output {
            path: path.to_path_buf(),
            message: e.to_string(),
        }
    })
}

/// Reads an RGB(A) EXR as linear RGB (for golden-image comparisons).
pub fn read_exr(path: &Path) -> Result<Image, PlayError> {
    let (w, h, rgb) = prm_scene::read_exr_rgb(path).map_err(|e| match e {
        ExportError::ExrRead { path, message } => PlayError::Output { path, message },
        e => PlayError::Export(e),
    })?;
    Ok(Image {
        width: w as u32,
        height: h as u32,
        rgb,
    })
}
