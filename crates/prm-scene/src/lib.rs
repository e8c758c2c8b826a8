//! Scene input for PRM: OBJ and glTF loaded into one flat triangle scene, plus its lightmap atlas.
//!
//! The flow is [`load`] (by file extension) → [`Scene`] → [`Atlas::build`]; [`write_gltf`] writes
//! a scene back as glTF with its lightmap UVs, for engines that play static lightmaps. A scene is a flat
//! list of triangles with per-corner attributes (no index buffer), a material table, textures,
//! lights and cameras, all in world space (right-handed, +Y up, metres by convention).
//!
//! Light comes from punctual [`Light`]s, from emissive materials (`Ke` in MTL, `emissiveFactor`
//! in glTF, see [`Material`]) and from a [`Sky`].
//!
//! Shared by the bake and the players beside the scene: [`DeeperOperator`], the CPU model of
//! the near field's deeper share and its series, and the binaries' checks of their output
//! paths ([`check_destination`], [`check_output_path`], [`same_destination`]).

#![warn(missing_docs)]

pub mod analytic;
mod atlas;
mod error;
pub mod export;
mod gltf_load;
mod near_series;
mod obj;
mod output;
mod scene;
mod sky;
mod spec;
mod texture;

pub use atlas::{barycentric, Atlas, AtlasParams, AtlasStats, ExitPoint, Sizing, EMPTY_TEXEL};
pub use error::SceneError;
pub use export::{read_exr_rgb, write_exr_rgb, write_gltf, write_ktx2_rgb9e5, ExportError};
pub use near_series::{
    DeeperOperator, MergeNearHits, MergedHit, TAIL_TERMS as NEAR_TAIL_TERMS, TAIL_TOLERANCE as NEAR_TAIL_TOLERANCE,
};
pub use output::{check_destination, check_output_path, same_destination};
pub use scene::{Aabb, Camera, Light, LoadReport, Material, Scene, Triangle, MAX_COORDINATE, RECT_MAX_HALF_ANGLE_DEG};
pub use sky::{Sky, SkyMap, SkySource, MAX_SKY_MAP_SIDE, MIN_SKY_MAP};
pub use spec::{parse_camera, parse_emitter_scale, parse_light, parse_size, resolve_emitter_scales, SpecError};
pub use texture::Texture;

/// Radius² of an entry point's disk bound, as a fraction of `A/(Nπ)` (the disk of its whole
/// area): an entry point stands for a small disk, so a point or spot light at distance `r` gives
/// it `I cos θ / (r² + ENTRY_DISK · A/(Nπ))`. Shared by the CPU estimator
/// (`prm_trace::entry_irradiance`, which records the measurement behind the value) and the
/// run-time weights pass (`prm-runtime`) for archives without entry cells, whose entry points
/// take the light of their whole cell instead (`prm_trace::cells`).
pub const ENTRY_DISK: f32 = 0.25;

/// How close, in entry-point radii `√(A/(Nπ))`, a point or spot light must be to an entry
/// point for the run time to sum it over the cell's points (`prm_trace::cell_irradiance`, prm-runtime's
/// `weights.wgsl`); a farther light, or a directional
/// one, varies too little over a cell to need them and is taken at the entry point times the
/// cell's area, `|cell| · N/M · E(entry)`. At 6 radii the irradiance of a light facing the cell
/// varies by less than 2% between the cell's centre and its mean, and few entry points are
/// that close to a light: summing every light over every point made the weights pass 5 times
/// as long on lavapipe (29 against 5.6 ms, the bundled Cornell box at 1024×768).
pub const CELL_NEAR_RADII: f32 = 6.0;

/// The squared distance within which a light is summed over a cell's points, for entry points
/// that each stand for the area `area_per_entry` ([`CELL_NEAR_RADII`]).
pub fn cell_reach2(area_per_entry: f32) -> f32 {
    CELL_NEAR_RADII * CELL_NEAR_RADII * area_per_entry / std::f32::consts::PI
}

use std::path::Path;

/// Loads a scene file, choosing the loader by extension (`.obj`, `.gltf`, `.glb`).
///
/// Recoverable problems (a missing MTL or texture, degenerate or duplicate triangles) do not
/// fail the load: they are listed in [`Scene::report`].
pub fn load(path: &Path) -> Result<Scene, SceneError> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(|e| e.to_ascii_lowercase())
        .unwrap_or_default();
    if path.as_os_str() == "-" {
        return Err(SceneError::Stdin);
    }
    if !path.exists() {
        return Err(SceneError::NotFound(path.to_path_buf()));
    }
    if path.is_dir() {
        return Err(SceneError::IsDirectory(path.to_path_buf()));
    }
    match ext.as_str() {
        "obj" => obj::load(path),
        "gltf" | "glb" => gltf_load::load(path),
        _ => Err(SceneError::UnsupportedFormat(path.to_path_buf())),
    }
}
