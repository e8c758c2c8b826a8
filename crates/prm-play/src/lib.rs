//! `prm-play`: real-time weighting and blending of a baked PRM archive on the GPU (wgpu).
//!
//! Per frame, without a CPU–GPU round trip: shadow maps for every light ([`shadow`]), the
//! irradiance of every entry point and each cluster's weight (`play_weights.wgsl`), the rank of
//! every cluster by weight × pane energy (`play_rank.wgsl`), the top K with weights faded near the
//! threshold (`play_select.wgsl`), the blend of the kept panes into an indirect-irradiance
//! lightmap (`play_blend.wgsl`) and the shading of every pixel as albedo/π × (direct + indirect)
//! irradiance (`play_shade.wgsl`), in linear HDR. See [`Renderer`].
//!
//! [`open`] loads an archive and its scene (refusing an archive baked for other geometry),
//! [`window`] presents frames in a window (winit, orbit camera),
//! [`animation`] reads keyframed light and camera paths, [`output`] writes EXR and PNG images.

mod error;
mod gpu;
mod renderer;

pub mod animation;
pub mod output;
pub mod shadow;
pub mod synthetic;
pub mod window;

pub use error::PlayError;
pub use gpu::{open_vulkan, open_vulkan_for, vulkan_instance};
pub use renderer::{ClusterWeight, FrameInput, FrameTimings, Image, Mode, PlayOptions, Renderer, PASS_NAMES};

use std::path::{Path, PathBuf};

use prm_format::Archive;
use prm_scene::{Camera, Scene};

/// The archive type [`open`] returns.
pub type FileArchive = Archive<std::io::BufReader<std::fs::File>>;

/// Top K when neither `--top-k` nor the archive's `params.top_k` says otherwise.
pub const DEFAULT_TOP_K: u32 = 32;

/// Opens `archive` and loads its scene: `scene` if given, else the archive's `source_scene`
/// (relative to the archive's directory). Fails if the scene's fingerprint differs from the one
/// the archive was baked for.
pub fn open(archive: &Path, scene: Option<&Path>) -> Result<(FileArchive, Scene), PlayError> {
    let a = Archive::open(archive).map_err(|source| PlayError::Archive {
        path: archive.to_path_buf(),
        source,
    })?;
    let scene_path: PathBuf = match scene {
        Some(p) => p.to_path_buf(),
        None => {
            let rel = &a.metadata().source_scene;
            if rel.is_empty() {
                return Err(PlayError::NoSourceScene(archive.to_path_buf()));
            }
            archive.parent().unwrap_or(Path::new(".")).join(rel)
        }
    };
    let s = prm_scene::load(&scene_path).map_err(|source| PlayError::Scene {
        path: scene_path.clone(),
        source,
    })?;
    let expected = a.metadata().scene_fingerprint;
    let found = s.fingerprint();
    if expected != found || a.atlas().triangle_uvs.len() != s.triangles.len() {
        return Err(PlayError::FingerprintMismatch {
            archive: archive.to_path_buf(),
            scene: scene_path,
            expected,
            found,
        });
    }
    Ok((a, s))
}

/// The top K an archive asks for (`params.top_k`), else [`DEFAULT_TOP_K`].
pub fn archive_top_k<R: std::io::Read + std::io::Seek>(archive: &Archive<R>) -> u32 {
    archive
        .metadata()
        .params
        .get("top_k")
        .and_then(|v| v.as_u64())
        .map(|k| k.clamp(1, u32::MAX as u64) as u32)
        .unwrap_or(DEFAULT_TOP_K)
}

/// The scene's first camera, or a view of its bounds from +Z.
pub fn default_camera(scene: &Scene) -> Camera {
    if let Some(c) = scene.cameras.first() {
        return *c;
    }
    let b = scene.bounds();
    let centre = (b.min + b.max) * 0.5;
    let fov: f32 = 45.0;
    let radius = b.diagonal() * 0.5;
    let dist = radius / (fov.to_radians() * 0.5).tan() * 1.1;
    Camera {
        eye: centre + glam::Vec3::new(0.0, 0.0, dist + b.extent().z * 0.5),
        target: centre,
        fov_y_deg: fov,
    }
}
