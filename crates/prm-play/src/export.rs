//! Static lightmap export, for engines that take only baked lightmaps (Bevy's `Lightmap`,
//! Godot, three.js): for one lighting, the indirect and the full (direct + indirect) irradiance
//! lightmaps as EXR and as KTX2 (RGB9E5, Zstandard-supercompressed; Bevy loads it directly) and
//! the scene as glTF with the lightmap UVs as `TEXCOORD_1`.

use std::path::{Path, PathBuf};

use glam::Vec2;
use prm_scene::{Camera, Light, Scene};

use crate::{FrameInput, Mode, PlayError, Renderer};

/// The files [`export`] writes into its directory.
pub const FILES: [&str; 6] = [
    "indirect.exr",
    "irradiance.exr",
    "indirect.ktx2",
    "irradiance.ktx2",
    "scene.gltf",
    "scene.bin",
];

/// What [`export`] wrote.
#[derive(Clone, Debug)]
pub struct Exported {
    /// `DIR/indirect.exr`: indirect irradiance (W/m²) per lightmap texel, row 0 at v = 0.
    pub indirect: PathBuf,
    /// `DIR/irradiance.exr`: direct (shadow-mapped) + indirect irradiance per texel.
    pub irradiance: PathBuf,
    /// `DIR/indirect.ktx2`: the indirect lightmap as KTX2 (RGB9E5, Zstandard).
    pub indirect_ktx2: PathBuf,
    /// `DIR/irradiance.ktx2`: the full lightmap as KTX2 (RGB9E5, Zstandard).
    pub irradiance_ktx2: PathBuf,
    /// `DIR/scene.gltf` (and `scene.bin`): the scene with the lightmap UVs as `TEXCOORD_1`.
    pub gltf: PathBuf,
}

/// Renders one frame lit by `lights` and writes its lightmaps and the scene into `dir` (created
/// if missing). Radiance in an engine is albedo/π × the irradiance map (or × the indirect map
/// plus its own direct light).
pub fn export(renderer: &mut Renderer, scene: &Scene, lights: &[Light], dir: &Path) -> Result<Exported, PlayError> {
    let fail = |path: &Path, message: String| PlayError::Output {
        path: path.to_path_buf(),
        message,
    };
    std::fs::create_dir_all(dir).map_err(|e| fail(dir, e.to_string()))?;
    renderer.render(&FrameInput {
        camera: Camera {
            eye: glam::Vec3::Z,
            target: glam::Vec3::ZERO,
            fov_y_deg: 45.0,
        },
        lights,
        mode: Mode::Gi,
    })?;
    let runtime = renderer.runtime();
    let res = runtime.lightmap_resolution() as usize;
    let out = Exported {
        indirect: dir.join(FILES[0]),
        irradiance: dir.join(FILES[1]),
        indirect_ktx2: dir.join(FILES[2]),
        irradiance_ktx2: dir.join(FILES[3]),
        gltf: dir.join(FILES[4]),
    };
    let export_err = |e: prm_scene::ExportError| PlayError::Export(e);
    let indirect = runtime.read_lightmap()?;
    let irradiance = runtime.read_irradiance_lightmap()?;
    prm_scene::write_exr_rgb(&out.indirect, res, res, &indirect).map_err(export_err)?;
    prm_scene::write_exr_rgb(&out.irradiance, res, res, &irradiance).map_err(export_err)?;
    prm_scene::write_ktx2_rgb9e5(&out.indirect_ktx2, res, res, &indirect).map_err(export_err)?;
    prm_scene::write_ktx2_rgb9e5(&out.irradiance_ktx2, res, res, &irradiance).map_err(export_err)?;
    let uvs: Vec<[Vec2; 3]> = runtime.lightmap_uvs().iter().map(|t| t.map(Vec2::from_array)).collect();
    prm_scene::write_gltf(scene, &uvs, &out.gltf).map_err(export_err)?;
    Ok(out)
}
