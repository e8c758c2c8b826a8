//! `prm-runtime`: PRM's run-time passes on the caller's wgpu device: an opened archive and each
//! frame's lights in, the indirect-irradiance lightmap out.
//!
//! Per frame, all on the GPU: shadow maps of every light ([`shadow_views`]; or the caller's own,
//! [`Shadows::External`]), the shadow-mapped irradiance of every entry point and each cluster's
//! weight (`weights.wgsl`), when the archive holds the near field the light the
//! panes' VPL bound removes next to other surfaces, gathered from the direct light of the
//! texels there (`near_radiance.wgsl`, `near_field.wgsl`; also the deeper VPLs' share,
//! gathered after the blend from its lightmap, `near_indirect_radiance.wgsl`,
//! `near_indirect.wgsl`), the rank of every cluster by score (`rank.wgsl`), the top K with
//! weights faded near the threshold and the residual groups that carry the dropped clusters'
//! light (`select.wgsl`, [`prm_format::residual_groups`]) and the blend of the kept panes and
//! the groups' summed panes into an `rgba32float` lightmap of indirect irradiance in W/m² (`blend.wgsl`). The caller samples it
//! with the lightmap UVs [`Runtime::lightmap_uvs`] gives per triangle and shades as it likes:
//! radiance = albedo/π × (direct + indirect irradiance). Its direct light can use the same
//! shadow maps through [`LIGHTS_WGSL`] and [`Runtime::direct_light_bindings`]. Emissive surfaces
//! baked into the archive are scaled with [`Runtime::set_emitter_scales`], and the sky, when the
//! archive holds its transfer, is set with [`Runtime::set_sky`]; their direct light is
//! [`Runtime::emitter_lightmap`], their indirect light is in the lightmap. When the archive
//! holds probes, every frame also gathers their irradiance coefficients along their rays from
//! the surfaces' radiance of the frame (`probe_radiance.wgsl`, `probe_rays.wgsl`; archives
//! without rays: summed under the same cluster weights, `probes.wgsl`), and [`Runtime::probes`]
//! gives shaders the volume to light moving objects from with [`PROBES_WGSL`].
//!
//! Every resource lives on the device given to [`Runtime::new`]; nothing is global.
//!
//! ```no_run
//! # fn demo(device: &wgpu::Device, queue: &wgpu::Queue) -> Result<(), Box<dyn std::error::Error>> {
//! use prm_runtime::{Runtime, RuntimeOptions, Shadows};
//! let scene = prm_scene::load(std::path::Path::new("scenes/cornell/cornell.obj"))?;
//! let mut archive = prm_format::Archive::open(std::path::Path::new("cornell.prm"))?;
//! let options = RuntimeOptions::for_archive(&archive);
//! let mut runtime = Runtime::new(device, queue, &mut archive, &scene, options)?;
//! let light = prm_scene::Light::Point {
//!     position: glam::Vec3::new(0.0, 1.5, 0.0),
//!     intensity: glam::Vec3::splat(2.0),
//! };
//! runtime.update(&[light])?;
//! let mut encoder = device.create_command_encoder(&Default::default());
//! runtime.encode(&mut encoder, Shadows::Own, None);
//! queue.submit([encoder.finish()]);
//! // Sample `runtime.lightmap()` at the triangles' `runtime.lightmap_uvs()`.
//! # Ok(()) }
//! ```
//!
//! `examples/embed.rs` is a whole program: it opens a device, plays an archive and shades one
//! frame with its own few lines of WGSL.

#![warn(missing_docs)]

mod baked;
mod blend;
mod gather;
mod irradiance;
mod lights;
mod lit;
mod memory;
mod mix;
mod near_field;
mod options;
mod probe_rays;
mod probes;
mod setup;
mod shadow;
mod shared;
pub mod synthetic;
mod topk;
mod weights;

use prm_format::Archive;
use prm_gpu_kit::{readback, ErrorScopes, PassTimer};
use prm_scene::{Aabb, Light, Scene};

pub use baked::EmitterInfo;
pub use irradiance::DILATE_STEPS;
pub use lights::{look_to, orthographic, perspective, shadow_views, SPOT_SINGLE_VIEW_MAX_DEG};
pub use memory::{MemoryPart, MEMORY_PARTS};
pub use options::{
    archive_top_k, GiUpdate, NearLight, NearTail, ProbeLight, RuntimeError, RuntimeOptions, MAX_NEAR_BOUNCES,
    MAX_SHADOW_RESOLUTION, MAX_SUN_TILES,
};
pub use probes::ProbeVolume;
pub use shadow::SHADOW_FORMAT;
pub use shared::{
    GpuBlendChunk, GpuCluster, GpuEffective, GpuEntry, GpuFrame, GpuGatherPoint, GpuLight, GpuNearExit, GpuNearField,
    GpuNearHit, GpuNearPoint, GpuPaneTile, GpuProbeGrid, GpuProbeRays, GpuSelected, GpuView, GpuWeight, LightKind,
    LIGHTS_WGSL, LIGHT_BINDINGS_WGSL, PROBES_WGSL, SHARED_WGSL,
};

use shadow::{ShadowMaps, ShadowPass};
use topk::TopKPasses;
use weights::WeightsPass;

/// Most lights a frame may have.
pub const MAX_LIGHTS: usize = 256;
/// Names of the timed passes in frame order, for a [`PassTimer`] handed to [`Runtime::encode`].
pub const PASS_NAMES: [&str; 12] = [
    "shadow",
    "weights",
    "near radiance",
    "near field",
    "rank",
    "select",
    "mix",
    "blend",
    "near indirect radiance",
    "near indirect",
    "probe radiance",
    "probes",
];
/// Format of the lightmap [`Runtime::lightmap`] (not filterable everywhere: sample it with
/// `textureLoad` and filter by hand, as `prm-play`'s shading does).
pub const LIGHTMAP_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba32Float;

/// Which shadow maps a frame's weights read.
#[derive(Clone, Copy, Debug)]
pub enum Shadows<'a> {
    /// The run time renders its own ([`Runtime::encode`] records the shadow pass first).
    Own,
    /// The caller's: a `Depth32Float` 2D-array view with one layer per view of
    /// [`shadow_views`] for this frame's lights, in that order, rendered with those matrices
    /// at [`RuntimeOptions::shadow_resolution`]².
    External(&'a wgpu::TextureView),
}

/// A cluster's weights as the GPU computed them (read back by [`Runtime::read_weights`]).
#[derive(Clone, Copy, Debug)]
pub struct ClusterWeight {
    /// The members' entry irradiance weighed by their pane energy (their mean in archives
    /// without entry energies).
    pub weight: [f32; 3],
    /// Σ_rgb weight × pane energy.
    pub score: f32,
    /// Weight used in the blend (0 if dropped, faded near the threshold).
    pub effective: [f32; 3],
    /// Rank by score (0 = largest).
    pub rank: u32,
}

/// What a shader needs to compute direct light with [`LIGHTS_WGSL`] on the run time's shadow
/// maps: bind `frame` as `var<uniform> frame: Frame`, `lights` and `views` as read-only storage
/// arrays of `Light` and `ShadowView`, `shadow_maps` as `texture_depth_2d_array`
/// ([`LIGHT_BINDINGS_WGSL`] declares them as bindings 0 to 3 of group 0).
pub struct DirectLight<'a> {
    /// This frame's [`GpuFrame`] (uniform).
    pub frame: &'a wgpu::Buffer,
    /// This frame's [`GpuLight`]s (storage).
    pub lights: &'a wgpu::Buffer,
    /// This frame's [`GpuView`]s (storage).
    pub views: &'a wgpu::Buffer,
    /// The run time's shadow maps.
    pub shadow_maps: &'a wgpu::TextureView,
}

impl<'a> DirectLight<'a> {
    /// `frame`, `lights`, `views` and `shadow_maps` as bindings 0 to 3, in that order.
    pub fn resources(&self) -> [wgpu::BindingResource<'a>; 4] {
        [
            self.frame.as_entire_binding(),
            self.lights.as_entire_binding(),
            self.views.as_entire_binding(),
            wgpu::BindingResource::TextureView(self.shadow_maps),
        ]
    }
}

/// The buffers the passes share.
pub(crate) struct Buffers {
    frame: wgpu::Buffer,
    lights: wgpu::Buffer,
    views: wgpu::Buffer,
    clusters: wgpu::Buffer,
    entries: wgpu::Buffer,
    /// Every entry point's cell points (`setup::gpu_cell_points`).
    cell_points: wgpu::Buffer,
    weights: wgpu::Buffer,
    ranks: wgpu::Buffer,
    threshold: wgpu::Buffer,
    selected: wgpu::Buffer,
    effective: wgpu::Buffer,
    /// The energy of every residual group's pane, its members' summed (`vec4`, w unused).
    group_energy: wgpu::Buffer,
}

/// The run time's GPU state for one archive and scene.
pub struct Runtime {
    device: wgpu::Device,
    queue: wgpu::Queue,
    options: RuntimeOptions,
    bounds: Aabb,
    cluster_count: u32,
    /// Residual groups built at load (their coefficients follow the clusters').
    group_count: u32,
    /// The top K of the frame constants last uploaded (`update`), which the passes ran with.
    frame_top_k: u32,
    /// Most shadow views a frame's lights may need: the views buffer's and the device's layers.
    max_views: usize,
    entry_count: u32,
    resolution: u32,
    vertex_count: u32,
    lightmap_uvs: Vec<[[f32; 2]; 3]>,
    positions: wgpu::Buffer,
    /// Position, normal and lightmap UV of every corner, for [`Runtime::read_irradiance_lightmap`].
    atlas_vertices: wgpu::Buffer,
    buffers: Buffers,
    lightmap: wgpu::Texture,
    lightmap_view: wgpu::TextureView,
    maps: ShadowMaps,
    shadow: ShadowPass,
    weights: WeightsPass,
    topk: TopKPasses,
    blend: blend::BlendPass,
    /// The panes the blend reads (kept alive here).
    _panes: blend::Panes,
    /// Built by the first [`Runtime::read_irradiance_lightmap`].
    irradiance: std::sync::OnceLock<irradiance::IrradiancePass>,
    /// This frame's shadow views (set by [`Runtime::update`]).
    view_count: u32,
    /// The entries as uploaded (rewritten when the emitter scales change).
    entries: Vec<GpuEntry>,
    emitters: baked::BakedLights,
    probes: Option<probes::ProbesPass>,
    /// The near field's passes, when the archive holds it and the options gather it.
    near: Option<near_field::NearFieldPass>,
    /// The lights of the last [`Runtime::update`].
    last_lights: Vec<Light>,
    /// Whether the lightmap (and the probes) no longer follow the lights, K, the emitter
    /// scales and the sky as last set ([`GiUpdate::OnChange`]); an atomic so that `encode`
    /// takes `&self` and the runtime stays `Sync`.
    gi_stale: std::sync::atomic::AtomicBool,
}

impl Runtime {
    /// Uploads the scene's positions (for the shadow maps), the archive's entries, clusters and
    /// panes, and builds the passes on `device`. The archive must belong to the scene (its
    /// atlas has one UV triangle per scene triangle).
    pub fn new<R: std::io::Read + std::io::Seek>(
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        archive: &mut Archive<R>,
        scene: &Scene,
        options: RuntimeOptions,
    ) -> Result<Runtime, RuntimeError> {
        options.validate(&device.limits())?;
        setup::check_archive(archive, scene)?;
        let atlas = archive.atlas().clone();
        let cluster_count = archive.clusters().len() as u32;
        let max_layers = device.limits().max_texture_array_layers;
        let group_count = prm_format::residual_group_count(cluster_count as usize, options.residual_groups);
        let group_of = setup::residual_group_of(archive, group_count);
        let scope = ErrorScopes::push(device);
        let geometry = setup::SceneGeometry::upload(device, scene, &atlas.triangle_uvs);
        let mut entries = setup::gpu_entries(archive, scene);
        let clusters = setup::gpu_clusters(archive, &group_of);
        let mut emitters = baked::BakedLights::new(device, archive.emitters(), archive.sky(), atlas.resolution);
        emitters.apply(queue, &mut entries);
        let buffers = Buffers::new(
            device,
            &clusters,
            &entries,
            &setup::gpu_cell_points(archive),
            group_count,
        );
        let (mut panes, mut lit) =
            setup::upload_panes(device, queue, archive, &buffers, &group_of, group_count, &options)?;
        let res = atlas.resolution;
        let (lightmap, lightmap_view) = setup::create_lightmap(device, res);

        let maps = ShadowMaps::new(device, options.shadow_resolution, 1);
        let shadow = ShadowPass::new(device, &maps);
        let weights = WeightsPass::new(device, &buffers, &maps.array);
        let inputs = setup::PassInputs {
            maps: &maps,
            lightmap: &lightmap_view,
            emitters: &emitters,
            resolution: res,
        };
        let near_field = setup::gathered_near_field(archive, &options);
        let (near_view, near) = setup::build_near_field(device, &buffers, near_field, &inputs, &options)?;
        emitters.mark_indirect(&mut lit);
        setup::mark_near_exits(near_field, &mut lit);
        let topk = TopKPasses::new(device, &buffers);
        let blend = blend::BlendPass::new(
            device,
            &buffers,
            &mut panes,
            &blend::BlendTargets {
                lightmap: &lightmap_view,
                emitted: &emitters.indirect_view,
                near: &near_view,
            },
            &lit,
        );
        let probes = setup::build_probes(device, &buffers, archive, &inputs, &options)?;
        scope.pop("runtime setup")?;
        let frame_top_k = options.top_k.max(1);
        Ok(Runtime {
            device: device.clone(),
            queue: queue.clone(),
            options,
            bounds: scene.bounds(),
            cluster_count,
            group_count,
            frame_top_k,
            max_views: (MAX_LIGHTS * 6).min(max_layers as usize),
            entry_count: entries.len() as u32,
            resolution: res,
            vertex_count: geometry.vertex_count,
            lightmap_uvs: atlas.triangle_uvs,
            positions: geometry.positions,
            atlas_vertices: geometry.atlas_vertices,
            buffers,
            lightmap,
            lightmap_view,
            maps,
            shadow,
            weights,
            topk,
            blend,
            _panes: panes,
            irradiance: std::sync::OnceLock::new(),
            view_count: 0,
            entries,
            emitters,
            probes,
            near,
            last_lights: Vec::new(),
            gi_stale: std::sync::atomic::AtomicBool::new(true),
        })
    }

    /// Sets this frame's lights: uploads them, their shadow views and the frame constants.
    /// Returns `true` when the shadow-map array had to grow, which replaces the view
    /// [`Runtime::direct_light_bindings`] gives: rebuild bind groups that hold it.
    pub fn update(&mut self, lights: &[Light]) -> Result<bool, RuntimeError> {
        if lights.len() > MAX_LIGHTS {
            return Err(RuntimeError::TooManyLights { count: lights.len() });
        }
        let (gpu_lights, views) = shadow_views(
            lights,
            &self.bounds,
            self.options.shadow_resolution,
            self.options.sun_tiles,
        );
        let max_views = self.max_views;
        if views.len() > max_views {
            return Err(RuntimeError::TooManyShadowViews {
                views: views.len(),
                max: max_views,
                per_sun: self.options.sun_tiles * self.options.sun_tiles,
            });
        }
        let grew = views.len() as u32 > self.maps.capacity;
        if grew {
            let capacity = (views.len() as u32).next_power_of_two().min(max_views as u32);
            self.maps = ShadowMaps::new(&self.device, self.options.shadow_resolution, capacity);
            self.shadow.rebind(&self.device, &self.maps);
            self.weights.rebind(&self.device, &self.buffers, &self.maps.array);
            if let Some(p) = &mut self.probes {
                p.rebind(&self.device, &self.buffers, &self.maps.array);
            }
            if let Some(n) = &mut self.near {
                n.gathered.rebind(&self.device, &self.buffers, &self.maps.array);
            }
        }
        self.view_count = views.len() as u32;
        let o = &self.options;
        let frame = GpuFrame {
            light_count: gpu_lights.len() as u32,
            cluster_count: self.cluster_count,
            top_k: o.top_k.max(1),
            entry_count: self.entry_count,
            fade_band: o.fade_band,
            shadow_resolution: o.shadow_resolution as f32,
            normal_offset: o.normal_offset,
            depth_bias: o.depth_bias,
            group_count: self.group_count,
            ..Default::default()
        };
        if lights != self.last_lights.as_slice() || frame.top_k != self.frame_top_k {
            self.mark_stale();
            self.last_lights = lights.to_vec();
        }
        self.frame_top_k = frame.top_k;
        self.queue
            .write_buffer(&self.buffers.frame, 0, bytemuck::bytes_of(&frame));
        if !gpu_lights.is_empty() {
            self.queue
                .write_buffer(&self.buffers.lights, 0, bytemuck::cast_slice(&gpu_lights));
            self.queue
                .write_buffer(&self.buffers.views, 0, bytemuck::cast_slice(&views));
            self.maps.write_matrices(&self.queue, &views);
        }
        Ok(grew)
    }

    /// Records the shadow pass alone (for a frame that shows direct light only).
    pub fn encode_shadow_maps(&self, encoder: &mut wgpu::CommandEncoder, timer: Option<&PassTimer>) {
        self.shadow.encode(
            encoder,
            &self.maps,
            self.view_count,
            &self.positions,
            self.vertex_count,
            timer,
        );
    }

    /// Records the frame set by [`Runtime::update`]: with [`Shadows::Own`] the shadow pass, then
    /// weights, the near field, rank, select, mix and blend into
    /// [`Runtime::lightmap`], the near field's deeper share, then the probes. Timed passes
    /// are named as in [`PASS_NAMES`]. With [`GiUpdate::OnChange`] (the default) and the run
    /// time's own shadow maps, the passes after the shadow pass are recorded only when
    /// [`Runtime::gi_pending`] says so: the lightmap and the probes keep the last update's
    /// light, which is this frame's. Submit the encoder: the run time counts what it recorded
    /// as done.
    pub fn encode(&self, encoder: &mut wgpu::CommandEncoder, shadows: Shadows, timer: Option<&PassTimer>) {
        let external = match shadows {
            Shadows::Own => {
                self.encode_shadow_maps(encoder, timer);
                None
            }
            Shadows::External(view) => Some(view),
        };
        if self.cluster_count == 0 || (external.is_none() && !self.gi_pending()) {
            return;
        }
        self.gi_stale.store(false, std::sync::atomic::Ordering::Relaxed);
        let frame = lit::LitFrame {
            device: &self.device,
            buffers: &self.buffers,
            external,
            timer,
        };
        self.weights.encode(encoder, &frame, self.cluster_count);
        if let Some(n) = &self.near {
            n.gathered.encode(encoder, &frame);
        }
        self.topk.encode(encoder, self.cluster_count, timer);
        self.blend.encode(encoder, timer);
        if let Some(n) = &self.near {
            n.encode_after_blend(encoder, &self.lightmap, timer);
        }
        if let Some(p) = &self.probes {
            p.encode(encoder, &frame);
        }
    }

    /// Whether the next [`Runtime::encode`] with the run time's own shadow maps records the
    /// indirect light's passes: always with [`GiUpdate::EveryFrame`]; with
    /// [`GiUpdate::OnChange`] when the lights, K, the emitter scales or the sky changed since
    /// the last update it recorded (or none was). External shadow maps always record them.
    pub fn gi_pending(&self) -> bool {
        self.options.gi_update == GiUpdate::EveryFrame || self.gi_stale.load(std::sync::atomic::Ordering::Relaxed)
    }

    fn mark_stale(&self) {
        self.gi_stale.store(true, std::sync::atomic::Ordering::Relaxed);
    }

    /// The probe volume, when the archive holds probes: bindings for [`PROBES_WGSL`], whose
    /// coefficients every [`Runtime::encode`] fills. When the archive holds the probes' rays
    /// ([`Runtime::probes_gather_rays`]) they are gathered along them from the
    /// radiance of the surfaces the rays reach: the lights' direct light through the shadow
    /// maps, the lightmap's indirect light and the emitters' and sky's baked direct light, plus
    /// emissive surfaces (times their group's scale) and the sky seen directly. Without rays
    /// they are summed under the frame's weights of all clusters (the lights' indirect light
    /// through the panes), plus the sky's light, direct and bounced, when the archive holds its
    /// transfer to the probes (the emitters' light does not reach them then).
    pub fn probes(&self) -> Option<ProbeVolume<'_>> {
        self.probes.as_ref().map(|p| ProbeVolume {
            grid: &p.grid,
            cells: &p.cells,
            coefficients: &p.coefficients,
            positions: &p.positions,
        })
    }

    /// Whether the probes are gathered along their rays (archives baked with them) rather than
    /// summed through the panes.
    pub fn probes_gather_rays(&self) -> bool {
        self.probes.as_ref().is_some_and(|p| p.has_rays())
    }

    /// Reads back the radiance (RGB, W/m²/sr) the last frame gave every gather point of the
    /// probe rays ([`prm_format::ProbeRays::points`]; empty without rays), waiting for the
    /// device.
    pub fn read_probe_radiance(&self) -> Result<Vec<[f32; 3]>, RuntimeError> {
        self.read_radiance(self.probes.as_ref().and_then(|p| p.ray_radiance()))
    }

    /// Reads back the radiance (RGB, W/m²/sr) the last frame's direct light gave every gather
    /// point of the near field ([`prm_format::NearField::points`]; empty without it), waiting
    /// for the device.
    pub fn read_near_radiance(&self) -> Result<Vec<[f32; 3]>, RuntimeError> {
        self.read_radiance(self.near.as_ref().map(|n| n.gathered.radiance()))
    }

    /// The first `points` RGB values of a `vec4` radiance buffer, waiting for the device.
    fn read_radiance(&self, buffer: Option<(&wgpu::Buffer, u32)>) -> Result<Vec<[f32; 3]>, RuntimeError> {
        let Some((buffer, points)) = buffer.filter(|(_, p)| *p > 0) else {
            return Ok(Vec::new());
        };
        let bytes = readback::read_buffer(&self.device, &self.queue, buffer, u64::from(points) * 16)?;
        let v: &[[f32; 4]] = bytemuck::cast_slice(&bytes);
        Ok(v.iter().map(|c| [c[0], c[1], c[2]]).collect())
    }

    /// Reads the last frame's probe coefficients back (nine RGB per probe; empty without
    /// probes), waiting for the device.
    pub fn read_probes(&self) -> Result<Vec<[[f32; 3]; prm_format::SH_COEFFS]>, RuntimeError> {
        let Some(p) = &self.probes else {
            return Ok(Vec::new());
        };
        let n = p.positions.len();
        let bytes = readback::read_buffer(
            &self.device,
            &self.queue,
            &p.coefficients,
            (n * prm_format::SH_COEFFS * 16) as u64,
        )?;
        let v: &[[f32; 4]] = bytemuck::cast_slice(&bytes);
        Ok(v.chunks_exact(prm_format::SH_COEFFS)
            .map(|c| std::array::from_fn(|i| [c[i][0], c[i][1], c[i][2]]))
            .collect())
    }

    /// The indirect-irradiance lightmap (W/m², [`LIGHTMAP_FORMAT`]) of the last encoded frame.
    pub fn lightmap(&self) -> &wgpu::TextureView {
        &self.lightmap_view
    }

    /// The lightmap texture (for copies).
    pub fn lightmap_texture(&self) -> &wgpu::Texture {
        &self.lightmap
    }

    /// Lightmap side in texels.
    pub fn lightmap_resolution(&self) -> u32 {
        self.resolution
    }

    /// Lightmap UVs of every scene triangle's corners, in scene order ([0, 1]², v down).
    pub fn lightmap_uvs(&self) -> &[[[f32; 2]; 3]] {
        &self.lightmap_uvs
    }

    /// The buffers and shadow maps for direct light with [`LIGHTS_WGSL`].
    pub fn direct_light_bindings(&self) -> DirectLight<'_> {
        DirectLight {
            frame: &self.buffers.frame,
            lights: &self.buffers.lights,
            views: &self.buffers.views,
            shadow_maps: &self.maps.array,
        }
    }

    /// The archive's emitter groups (one per emissive material; empty without them), in the
    /// order [`Runtime::set_emitter_scales`] takes their scales.
    pub fn emitters(&self) -> &[EmitterInfo] {
        &self.emitters.info
    }

    /// The emitter groups' current scales (RGB multipliers of their baked radiance; 1 at
    /// first).
    pub fn emitter_scales(&self) -> &[[f32; 3]] {
        &self.emitters.scales
    }

    /// Scales each emitter group's radiance (one finite, non-negative RGB triple per group of
    /// [`Runtime::emitters`]) from the next [`Runtime::encode`] on: the emitter lightmap, the
    /// traced indirect lightmaps (added into [`Runtime::lightmap`] by the blend) and, for groups
    /// without one, the entries' irradiance (the cluster weights) are summed again on the CPU
    /// and uploaded; nothing is rendered.
    pub fn set_emitter_scales(&mut self, scales: &[[f32; 3]]) -> Result<(), RuntimeError> {
        self.emitters.check(scales)?;
        if scales == self.emitters.scales.as_slice() {
            // An animation holding its scales: nothing to sum, upload or compute again.
            return Ok(());
        }
        self.emitters.scales = scales.to_vec();
        self.emitters.apply(&self.queue, &mut self.entries);
        if let Some(p) = &self.probes {
            p.write_scales(&self.queue, scales);
        }
        self.queue
            .write_buffer(&self.buffers.entries, 0, bytemuck::cast_slice(&self.entries));
        self.mark_stale();
        Ok(())
    }

    /// Whether the archive holds the sky's transfer, so that [`Runtime::set_sky`] can light it.
    pub fn has_sky(&self) -> bool {
        self.emitters.sky.is_some()
    }

    /// Lights the scene with a sky of these coefficients in the basis of
    /// [`prm_format::sh_basis`] (RGB radiance, already turned and scaled:
    /// [`prm_scene::Sky::sh`] gives them; all zero: no sky), from the next [`Runtime::encode`]
    /// on. Its direct light joins [`Runtime::emitter_lightmap`] and its indirect light the
    /// lightmap: both are summed on the CPU from the archive's transfer and uploaded, nothing is
    /// rendered. Refused when the archive has no sky transfer ([`Runtime::has_sky`]).
    pub fn set_sky(&mut self, coeffs: &[[f32; 3]; prm_format::SH_COEFFS]) -> Result<(), RuntimeError> {
        self.emitters.check_sky(coeffs)?;
        if *coeffs == self.emitters.sky_coeffs {
            return Ok(());
        }
        self.emitters.sky_coeffs = *coeffs;
        self.emitters.apply(&self.queue, &mut self.entries);
        if let Some(p) = &self.probes {
            p.write_sky(&self.queue, coeffs);
        }
        self.mark_stale();
        Ok(())
    }

    /// The baked direct irradiance now: the emitters' at their current scales and the sky's
    /// (W/m², [`LIGHTMAP_FORMAT`], sampled with the same UVs as [`Runtime::lightmap`]; a black
    /// 1×1 texture without emitters or sky): add it to the lights' direct irradiance, and show
    /// each emissive material's radiance × its group's scale on its own surfaces.
    pub fn emitter_lightmap(&self) -> &wgpu::TextureView {
        &self.emitters.view
    }

    /// The scene's bounds (what [`shadow_views`] fits directional lights to).
    pub fn bounds(&self) -> Aabb {
        self.bounds
    }

    /// The options in use.
    pub fn options(&self) -> &RuntimeOptions {
        &self.options
    }

    /// Number of clusters (= panes).
    pub fn cluster_count(&self) -> u32 {
        self.cluster_count
    }

    /// Residual groups built at load ([`RuntimeOptions::residual_groups`], at most one per
    /// cluster).
    pub fn group_count(&self) -> u32 {
        self.group_count
    }

    /// The run time's GPU memory by part ([`MEMORY_PARTS`]), from the device's allocator
    /// report: what was allocated for the run time's labels, padding included. `None` where the
    /// backend gives no report (wgpu's Vulkan and DirectX 12 backends do).
    pub fn gpu_memory(&self) -> Option<Vec<MemoryPart>> {
        self.device.generate_allocator_report().map(|r| memory::by_part(&r))
    }

    /// Bytes the indirect light's passes read on every update, from the sizes of what they
    /// bind ([`Runtime::gi_bytes_read_by_part`], summed).
    pub fn gi_bytes_read(&self) -> u64 {
        self.gi_bytes_read_by_part().iter().map(|p| p.bytes).sum()
    }

    /// Bytes the indirect light's passes read on every update, by part, from the sizes of what
    /// they bind: `weights`, every entry, its cell points and every cluster; `panes`, the mix's coefficients of the
    /// kept clusters (and of the residual groups when K drops clusters) in every tile and the
    /// blend's basis rows of the lit texels; `near field`, its exit records and hits once per
    /// gather (one, plus [`RuntimeOptions::near_bounces`] for the deeper share). Texture reads
    /// (shadow maps, lightmaps) and the probes are not counted.
    pub fn gi_bytes_read_by_part(&self) -> [MemoryPart; 3] {
        let k = self.options.top_k.min(self.cluster_count);
        let groups = if self.cluster_count > self.options.top_k {
            self.group_count
        } else {
            0
        };
        let kept = u64::from(k + groups);
        let panes = kept * self.blend.coefficient_bytes_per_pane + self.blend.basis_bytes_read;
        let near = self
            .near
            .as_ref()
            .map_or(0, |n| (1 + self.options.near_bounces as u64) * n.bytes_per_gather);
        [
            MemoryPart {
                name: "weights",
                bytes: self.buffers.entries.size() + self.buffers.cell_points.size() + self.buffers.clusters.size(),
            },
            MemoryPart {
                name: "panes",
                bytes: panes,
            },
            MemoryPart {
                name: "near field",
                bytes: near,
            },
        ]
    }

    /// Changes the number of clusters kept, from the next [`Runtime::update`] on.
    pub fn set_top_k(&mut self, k: u32) {
        self.options.top_k = k.max(1);
    }

    /// Reads the last frame's lightmap back (texel (x, y) at `y·R + x`), waiting for the device.
    pub fn read_lightmap(&self) -> Result<Vec<[f32; 3]>, RuntimeError> {
        let texels = readback::read_rgba32f(&self.device, &self.queue, &self.lightmap, 0)?;
        Ok(texels.into_iter().map(|[r, g, b, _]| [r, g, b]).collect())
    }

    /// The full irradiance (direct through the run time's shadow maps, the emitters' direct
    /// light and the indirect, W/m²) at every
    /// lightmap texel (x, y) at `y·R + x`, for the frame last encoded with [`Shadows::Own`]:
    /// what an engine that takes only static lightmaps bakes in. Texels outside every chart are
    /// dilated from their neighbours [`DILATE_STEPS`] rings deep, 0 beyond. Waits for the device.
    pub fn read_irradiance_lightmap(&self) -> Result<Vec<[f32; 3]>, RuntimeError> {
        let d = self.direct_light_bindings();
        let pass = self
            .irradiance
            .get_or_init(|| irradiance::IrradiancePass::new(&self.device));
        let mut irradiance = pass.render(
            &self.device,
            &self.queue,
            &[
                &d.resources()[..],
                &[wgpu::BindingResource::TextureView(&self.lightmap_view)],
            ]
            .concat(),
            &self.atlas_vertices,
            self.vertex_count,
            self.resolution,
        )?;
        for (t, e) in irradiance.iter_mut().zip(&self.emitters.combined) {
            (0..3).for_each(|k| t[k] += e[k]);
        }
        Ok(irradiance)
    }

    /// Reads the last frame's residual group weights back, one per group: each group's summed
    /// pane was blended with it (all 0 when the top K dropped no cluster).
    pub fn read_group_weights(&self) -> Result<Vec<[f32; 3]>, RuntimeError> {
        let (c, k, g) = (self.cluster_count, self.frame_top_k, self.group_count);
        if g == 0 || c <= k {
            return Ok(vec![[0.0; 3]; g as usize]);
        }
        let bytes = readback::read_buffer(&self.device, &self.queue, &self.buffers.selected, u64::from(k + g) * 16)?;
        let selected: &[GpuSelected] = bytemuck::cast_slice(&bytes);
        Ok(selected[k as usize..].iter().map(|s| s.weight).collect())
    }

    /// Reads the last frame's cluster weights, scores, ranks and effective weights back.
    pub fn read_weights(&self) -> Result<Vec<ClusterWeight>, RuntimeError> {
        let n = self.cluster_count as u64;
        if n == 0 {
            return Ok(Vec::new());
        }
        let w = readback::read_buffer(&self.device, &self.queue, &self.buffers.weights, n * 16)?;
        let e = readback::read_buffer(&self.device, &self.queue, &self.buffers.effective, n * 16)?;
        let w: &[GpuWeight] = bytemuck::cast_slice(&w);
        let e: &[GpuEffective] = bytemuck::cast_slice(&e);
        Ok(w.iter()
            .zip(e)
            .map(|(w, e)| ClusterWeight {
                weight: w.weight,
                score: w.score,
                effective: e.weight,
                rank: e.rank,
            })
            .collect())
    }
}
