//! PRM's global illumination in Bevy: a `.prm` archive is an asset, Bevy's lights are the
//! archive's lights, and the run time's indirect lightmap is Bevy's [`Lightmap`].
//!
//! Add [`PrmPlugin`] after Bevy's default plugins, then spawn [`PrmGi`] on an entity above the
//! meshes of the baked scene. The meshes need the archive's lightmap UVs in
//! [`Mesh::ATTRIBUTE_UV_1`]: those of the glTF that `prm-play --export` writes (its
//! `TEXCOORD_1`), or those [`PrmArchive::meshes`] builds. Once the archive has loaded, every mesh
//! below the [`PrmGi`] entity gets a [`Lightmap`] on one shared image, and the run time blends it
//! again on Bevy's render device whenever a light, an emitter scale or the sky changes.
//!
//! - Every [`PointLight`], [`SpotLight`] and [`DirectionalLight`] that is visible lights the
//!   scene, at most [`prm_runtime::MAX_LIGHTS`]. Bevy's photometric units map one to one onto
//!   the archive's radiometric ones: a point or spot light of `Φ` lumens and linear colour `c` is
//!   `c·Φ/4π` W/sr (a spot's cone is its `outer_angle`, hard-edged, and `range` is not
//!   applied to the indirect light), and a directional light of `L` lux is
//!   `c·L` W/m².
//! - The image holds `E/π`, the radiance of a white diffuse surface under the indirect
//!   irradiance `E`; Bevy multiplies it by the material's diffuse colour, and its own lights keep
//!   giving the direct light.
//! - [`PrmEmitterScales`] and [`PrmSky`] set the archive's baked emitters and sky.
//! - Bevy's ambient light no longer reaches lightmapped meshes
//!   (`GlobalAmbientLight::affects_lightmapped_meshes` is set to `false`): the lightmap is their
//!   indirect light.
//! - The scene file the archive was baked from is read from the file system, beside the
//!   archive under the asset folder (or where [`PrmArchiveSettings::scene`] says).

mod radiance;

use std::io::Cursor;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

use bevy_app::{App, Plugin, PostUpdate};
use bevy_asset::io::file::FileAssetReader;
use bevy_asset::io::Reader;
use bevy_asset::{Asset, AssetApp, AssetId, AssetLoader, AssetPlugin, Assets, Handle, LoadContext, RenderAssetUsages};
use bevy_camera::visibility::InheritedVisibility;
use bevy_color::LinearRgba;
use bevy_ecs::prelude::*;
use bevy_image::Image;
use bevy_light::{DirectionalLight, GlobalAmbientLight, PointLight, SpotLight};
use bevy_math::Rect;
use bevy_mesh::{Indices, Mesh, Mesh3d, PrimitiveTopology};
use bevy_pbr::Lightmap;
use bevy_reflect::TypePath;
use bevy_render::render_asset::RenderAssets;
use bevy_render::renderer::{RenderDevice, RenderQueue};
use bevy_render::texture::GpuImage;
use bevy_render::{Extract, ExtractSchedule, Render, RenderApp, RenderSystems};
use bevy_transform::components::GlobalTransform;
use bevy_transform::TransformSystems;
use glam::Vec3;
use prm_runtime::{Runtime, RuntimeOptions, Shadows, MAX_LIGHTS};
use prm_scene::{Light, Scene};
use serde::{Deserialize, Serialize};

pub use radiance::RADIANCE_FORMAT;

/// Registers the `.prm` asset, the systems that follow Bevy's lights, and the run time on
/// Bevy's render device. Add it after `AssetPlugin` and `RenderPlugin` (Bevy's default plugins).
pub struct PrmPlugin;

impl Plugin for PrmPlugin {
    fn build(&self, app: &mut App) {
        let folder = app
            .get_added_plugins::<AssetPlugin>()
            .first()
            .map_or_else(|| "assets".to_owned(), |p| p.file_path.clone());
        let root = FileAssetReader::get_base_path().join(folder);
        // The lightmap carries the indirect light: Bevy's ambient term would count it twice.
        if let Some(mut ambient) = app.world_mut().get_resource_mut::<GlobalAmbientLight>() {
            ambient.affects_lightmapped_meshes = false;
        }
        app.init_asset::<PrmArchive>()
            .register_asset_loader(PrmArchiveLoader { root })
            .init_resource::<PrmEmitterScales>()
            .init_resource::<PrmSky>()
            .init_resource::<PrmFrame>()
            .add_systems(
                PostUpdate,
                (create_lightmaps, attach_lightmaps, gather_frame, gather_lights)
                    .chain()
                    .after(TransformSystems::Propagate),
            );
        if let Some(render_app) = app.get_sub_app_mut(RenderApp) {
            render_app
                .init_resource::<PrmFrame>()
                .init_resource::<PrmRenderState>()
                .add_systems(ExtractSchedule, extract_frame)
                .add_systems(Render, update_gi.in_set(RenderSystems::PrepareResources));
        }
    }
}

/// The archive's global illumination for the meshes below this entity. One archive plays at a
/// time: the first `PrmGi` whose archive has loaded.
#[derive(Component, Clone)]
pub struct PrmGi {
    /// The archive (`asset_server.load("scene.prm")`).
    pub archive: Handle<PrmArchive>,
}

/// The image the meshes below a [`PrmGi`] entity receive as their [`Lightmap`]; added by the
/// plugin once the archive has loaded.
#[derive(Component, Clone)]
pub struct PrmLightmap(pub Handle<Image>);

/// Scales of the archive's baked emitter groups, one RGB triple per group; empty: the archive's
/// own (all one).
#[derive(Resource, Clone, Default, PartialEq)]
pub struct PrmEmitterScales(pub Vec<[f32; 3]>);

/// The sky as nine spherical-harmonic coefficients per channel; `None`: no sky. Needs an archive
/// baked with a sky transfer.
#[derive(Resource, Clone, Default, PartialEq)]
pub struct PrmSky(pub Option<[[f32; 3]; prm_format::SH_COEFFS]>);

/// A loaded `.prm` archive with the scene it was baked from.
#[derive(Asset, TypePath, Clone)]
pub struct PrmArchive {
    data: Arc<ArchiveData>,
}

/// The archive as read and checked once by the loader (the run time starts from it), and its
/// scene.
struct ArchiveData {
    archive: Mutex<prm_format::Archive<Cursor<Vec<u8>>>>,
    scene: Scene,
}

impl PrmArchive {
    /// Side of the archive's lightmap atlas, in texels.
    pub fn resolution(&self) -> u32 {
        self.data
            .archive
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .atlas()
            .resolution
    }

    /// The scene the archive was baked from.
    pub fn scene(&self) -> &Scene {
        &self.data.scene
    }

    /// The scene's triangles as one mesh per material, with normals and the archive's lightmap
    /// UVs in [`Mesh::ATTRIBUTE_UV_1`] (the same geometry and UVs as `prm-play --export`'s
    /// glTF), each with its material's linear albedo. Textures are not carried.
    pub fn meshes(&self) -> Vec<(Mesh, LinearRgba)> {
        let scene = &self.data.scene;
        let archive = self.data.archive.lock().unwrap_or_else(|e| e.into_inner());
        // Corners per material: positions, normals, lightmap UVs.
        let mut corners = vec![(Vec::new(), Vec::new(), Vec::new()); scene.materials.len()];
        for (t, uv) in scene.triangles.iter().zip(&archive.atlas().triangle_uvs) {
            let (p, n, u) = &mut corners[t.material as usize];
            p.extend(t.positions.map(|v| v.to_array()));
            n.extend(t.normals.map(|v| v.to_array()));
            u.extend(*uv);
        }
        corners
            .into_iter()
            .zip(&scene.materials)
            .filter(|((p, _, _), _)| !p.is_empty())
            .map(|((positions, normals, uvs), material)| {
                let count = positions.len() as u32;
                let mesh = Mesh::new(PrimitiveTopology::TriangleList, RenderAssetUsages::default())
                    .with_inserted_attribute(Mesh::ATTRIBUTE_POSITION, positions)
                    .with_inserted_attribute(Mesh::ATTRIBUTE_NORMAL, normals)
                    .with_inserted_attribute(Mesh::ATTRIBUTE_UV_0, uvs.clone())
                    .with_inserted_attribute(Mesh::ATTRIBUTE_UV_1, uvs)
                    .with_inserted_indices(Indices::U32((0..count).collect()));
                let a = material.albedo;
                (mesh, LinearRgba::rgb(a.x, a.y, a.z))
            })
            .collect()
    }
}

/// How a `.prm` asset finds its scene.
#[derive(Clone, Default, Serialize, Deserialize)]
pub struct PrmArchiveSettings {
    /// The scene file on the file system; `None`: the archive's `source_scene`, beside the
    /// archive.
    pub scene: Option<PathBuf>,
}

/// Why a `.prm` asset did not load.
#[derive(Debug, thiserror::Error)]
pub enum PrmLoadError {
    /// The archive's bytes could not be read.
    #[error("cannot read the archive: {0}")]
    Io(#[from] std::io::Error),
    /// The archive is not a valid `.prm` of a format this reader reads.
    #[error("{0}")]
    Archive(#[from] prm_format::Error),
    /// The archive's scene could not be loaded.
    #[error("cannot load the archive's scene {path}: {source}")]
    Scene {
        /// The scene file.
        path: PathBuf,
        /// Why.
        source: prm_scene::SceneError,
    },
}

/// Loads `.prm` archives and the scenes they were baked from.
#[derive(TypePath)]
struct PrmArchiveLoader {
    /// The asset folder on the file system.
    root: PathBuf,
}

impl AssetLoader for PrmArchiveLoader {
    type Asset = PrmArchive;
    type Settings = PrmArchiveSettings;
    type Error = PrmLoadError;

    async fn load(
        &self,
        reader: &mut dyn Reader,
        settings: &PrmArchiveSettings,
        load_context: &mut LoadContext<'_>,
    ) -> Result<PrmArchive, PrmLoadError> {
        let mut bytes = Vec::new();
        reader.read_to_end(&mut bytes).await?;
        let archive = prm_format::Archive::from_reader(Cursor::new(bytes))?;
        let path = settings.scene.clone().unwrap_or_else(|| {
            let dir = load_context.path().path().parent().unwrap_or(Path::new(""));
            self.root.join(dir).join(&archive.metadata().source_scene)
        });
        let scene = prm_scene::load(&path).map_err(|source| PrmLoadError::Scene { path, source })?;
        let data = ArchiveData {
            archive: Mutex::new(archive),
            scene,
        };
        Ok(PrmArchive { data: Arc::new(data) })
    }

    fn extensions(&self) -> &[&str] {
        &["prm"]
    }
}

/// Gives each [`PrmGi`] whose archive has loaded its lightmap image.
fn create_lightmaps(
    mut commands: Commands,
    gis: Query<(Entity, &PrmGi), Without<PrmLightmap>>,
    archives: Res<Assets<PrmArchive>>,
    mut images: ResMut<Assets<Image>>,
) {
    for (entity, gi) in &gis {
        let Some(archive) = archives.get(&gi.archive) else {
            continue;
        };
        let res = archive.resolution();
        let mut image = Image::new_target_texture(res, res, RADIANCE_FORMAT, None);
        // Written by the radiance pass; readable for tests and exports.
        image.texture_descriptor.usage |= wgpu::TextureUsages::STORAGE_BINDING | wgpu::TextureUsages::COPY_SRC;
        commands.entity(entity).insert(PrmLightmap(images.add(image)));
    }
}

/// Hands the lightmap to every mesh below a [`PrmGi`] entity that has none.
fn attach_lightmaps(
    mut commands: Commands,
    gis: Query<(Entity, &PrmLightmap)>,
    children: Query<&Children>,
    meshes: Query<(), (With<Mesh3d>, Without<Lightmap>)>,
) {
    for (root, lightmap) in &gis {
        for entity in std::iter::once(root).chain(children.iter_descendants(root)) {
            if meshes.contains(entity) {
                commands.entity(entity).insert(Lightmap {
                    image: lightmap.0.clone(),
                    uv_rect: Rect::new(0.0, 0.0, 1.0, 1.0),
                    bicubic_sampling: false,
                });
            }
        }
    }
}

/// What the render world needs for a frame of the run time.
#[derive(Resource, Clone, Default)]
struct PrmFrame {
    archive: Option<(AssetId<PrmArchive>, Arc<ArchiveData>)>,
    target: Option<AssetId<Image>>,
    inputs: GiInputs,
}

/// Everything the lightmap depends on besides the archive.
#[derive(Clone, Default, PartialEq)]
struct GiInputs {
    lights: Vec<Light>,
    emitter_scales: PrmEmitterScales,
    sky: PrmSky,
}

type LightQuery<'w, 's, L> = Query<
    'w,
    's,
    (
        &'static L,
        &'static GlobalTransform,
        Option<&'static InheritedVisibility>,
    ),
>;

/// Collects the first [`PrmGi`]'s archive and image, the emitter scales and the sky, for
/// extraction.
fn gather_frame(
    mut frame: ResMut<PrmFrame>,
    gis: Query<(&PrmGi, &PrmLightmap)>,
    archives: Res<Assets<PrmArchive>>,
    scales: Res<PrmEmitterScales>,
    sky: Res<PrmSky>,
) {
    if gis.iter().len() > 1 {
        bevy_log::warn_once!("prm: {} PrmGi entities; only the first one is lit", gis.iter().len());
    }
    let gi = gis.iter().next();
    frame.archive = gi.and_then(|(gi, _)| Some((gi.archive.id(), archives.get(&gi.archive)?.data.clone())));
    frame.target = gi.map(|(_, lightmap)| lightmap.0.id());
    frame.inputs.emitter_scales = scales.clone();
    frame.inputs.sky = sky.clone();
}

/// Collects the visible lights as the run time's, for extraction.
fn gather_lights(
    mut frame: ResMut<PrmFrame>,
    points: LightQuery<PointLight>,
    spots: LightQuery<SpotLight>,
    suns: LightQuery<DirectionalLight>,
) {
    let visible = |v: Option<&InheritedVisibility>| v.is_none_or(|v| v.get());
    let lights = &mut frame.inputs.lights;
    lights.clear();
    lights.extend(points.iter().filter(|l| visible(l.2)).map(|(l, t, _)| Light::Point {
        position: vec3(t.translation()),
        intensity: photometric_intensity(l.color.into(), l.intensity),
    }));
    lights.extend(spots.iter().filter(|l| visible(l.2)).map(|(l, t, _)| Light::Spot {
        position: vec3(t.translation()),
        direction: vec3(*t.forward()),
        angle: l.outer_angle,
        intensity: photometric_intensity(l.color.into(), l.intensity),
    }));
    lights.extend(suns.iter().filter(|l| visible(l.2)).map(|(l, t, _)| {
        let c: LinearRgba = l.color.into();
        Light::Directional {
            direction: vec3(*t.forward()),
            irradiance: Vec3::new(c.red, c.green, c.blue) * l.illuminance,
        }
    }));
    if lights.len() > MAX_LIGHTS {
        bevy_log::warn_once!(
            "prm: {} lights; the run time takes the first {MAX_LIGHTS}",
            lights.len()
        );
        lights.truncate(MAX_LIGHTS);
    }
}

/// A Bevy vector as the run time's (Bevy and PRM use different versions of `glam`).
fn vec3(v: bevy_math::Vec3) -> Vec3 {
    Vec3::from_array(v.to_array())
}

/// Radiant intensity (W/sr) of a point or spot light of `lumens` and colour `color`.
fn photometric_intensity(color: LinearRgba, lumens: f32) -> Vec3 {
    Vec3::new(color.red, color.green, color.blue) * lumens / (4.0 * std::f32::consts::PI)
}

fn extract_frame(mut commands: Commands, frame: Extract<Res<PrmFrame>>) {
    commands.insert_resource(frame.clone());
}

/// The run time on Bevy's render device, and what it last blended.
#[derive(Resource, Default)]
pub struct PrmRenderState {
    gi: Option<LoadedGi>,
    /// The archive whose run time failed to start (reported once).
    failed: Option<AssetId<PrmArchive>>,
    /// Lightmap updates so far.
    updates: u64,
}

impl PrmRenderState {
    /// How many times the lightmap has been blended again.
    pub fn updates(&self) -> u64 {
        self.updates
    }

    /// The running run time, once an archive has loaded.
    pub fn runtime(&self) -> Option<&Runtime> {
        self.gi.as_ref().map(|gi| &gi.runtime)
    }
}

struct LoadedGi {
    archive: AssetId<PrmArchive>,
    runtime: Runtime,
    radiance: radiance::RadiancePass,
    /// The inputs and target of the last blend.
    last: Option<(GiInputs, wgpu::Texture)>,
}

/// Starts the run time for a new archive and blends the lightmap again when its inputs change.
fn update_gi(
    frame: Res<PrmFrame>,
    mut state: ResMut<PrmRenderState>,
    device: Res<RenderDevice>,
    queue: Res<RenderQueue>,
    images: Res<RenderAssets<GpuImage>>,
) {
    let (Some((id, data)), Some(target)) = (&frame.archive, frame.target) else {
        return;
    };
    let Some(target) = images.get(target) else { return };
    if state.gi.as_ref().is_none_or(|gi| gi.archive != *id) && state.failed != Some(*id) {
        match start_runtime(device.wgpu_device(), &queue, data) {
            Ok(runtime) => {
                let radiance = radiance::RadiancePass::new(device.wgpu_device());
                state.gi = Some(LoadedGi {
                    archive: *id,
                    runtime,
                    radiance,
                    last: None,
                });
            }
            Err(e) => {
                bevy_log::error!("prm: cannot start the run time: {e}");
                state.failed = Some(*id);
                state.gi = None;
            }
        }
    }
    let Some(gi) = state.gi.as_mut() else { return };
    let texture: &wgpu::Texture = &target.texture;
    if gi
        .last
        .as_ref()
        .is_some_and(|(inputs, t)| *inputs == frame.inputs && t == texture)
    {
        return;
    }
    if let Err(e) = blend(gi, &frame.inputs, device.wgpu_device(), &queue, texture) {
        bevy_log::error!("prm: cannot update the lightmap: {e}");
    }
    gi.last = Some((frame.inputs.clone(), texture.clone()));
    state.updates += 1;
}

fn start_runtime(device: &wgpu::Device, queue: &wgpu::Queue, data: &ArchiveData) -> Result<Runtime, String> {
    let mut archive = data.archive.lock().unwrap_or_else(|e| e.into_inner());
    let options = RuntimeOptions::for_archive(&archive);
    Runtime::new(device, queue, &mut archive, &data.scene, options).map_err(|e| e.to_string())
}

/// Sets the inputs and records and submits one blend into `target`.
fn blend(
    gi: &mut LoadedGi,
    inputs: &GiInputs,
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    target: &wgpu::Texture,
) -> Result<(), prm_runtime::RuntimeError> {
    let runtime = &mut gi.runtime;
    let last = gi.last.as_ref().map(|(i, _)| i);
    if last.is_none_or(|l| l.emitter_scales != inputs.emitter_scales) && !inputs.emitter_scales.0.is_empty() {
        runtime.set_emitter_scales(&inputs.emitter_scales.0)?;
    }
    if last.is_none_or(|l| l.sky != inputs.sky) && runtime.has_sky() {
        runtime.set_sky(&inputs.sky.0.unwrap_or([[0.0; 3]; prm_format::SH_COEFFS]))?;
    }
    runtime.update(&inputs.lights)?;
    let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("prm gi") });
    runtime.encode(&mut encoder, Shadows::Own, None);
    gi.radiance.encode(device, &mut encoder, runtime.lightmap(), target);
    queue.submit([encoder.finish()]);
    Ok(())
}
