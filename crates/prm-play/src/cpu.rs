//! Frames without a GPU (`prm-play --headless --backend cpu`, and the fallback when no Vulkan
//! adapter exists): the same picture as the GPU player, ray-traced on the CPU.
//!
//! - **Visibility**: one primary ray a pixel through prm-trace's BVH, the camera as the GPU
//!   player projects it.
//! - **Direct light**: shadow rays to the punctual lights (exact, where the GPU player filters
//!   shadow maps).
//! - **Indirect light**: the run time's model on the CPU, the one the bake's accuracy check
//!   plays: the entry points' irradiance (shadow rays, from their cells or bounded by the entry disk), each
//!   cluster's weight by its members' pane energy, the top K clusters with the faded rest
//!   through the residual groups, blended from the panes' basis as the run time blends them
//!   ([`prm_format::PaneBasis::blend`]), then the near field's direct share and the
//!   series of its deeper share ([`prm_trace::NearPlay`]). The lightmap is sampled bilinearly
//!   at the triangles' lightmap UVs.
//!
//! It plays punctual lights only: an archive's emitter groups, sky and probes need the GPU
//! player. [`CpuPlayer::render_with`] shades with another lightmap of the scene through the
//! same lookup (`cargo xtask eval experiment lightmap_floor` shows a converged one with it).

use glam::{Vec2, Vec3};
use prm_format::Archive;
use prm_scene::{Camera, Light, Scene};
use prm_trace::{Bvh, BvhParams, NearPlay};
use rayon::prelude::*;

use crate::{FrameInput, Image, Mode, PlayError};

/// What the CPU player reads of an archive, loaded once.
pub struct CpuArchive {
    /// Entry points, sorted by cluster.
    entries: Vec<prm_format::Entry>,
    /// Radius² of the disk an entry point stands for (the run time's entry bound).
    entry_disk: f32,
    /// Every entry's pane energy (ones where the archive has none).
    entry_energy: Vec<Vec3>,
    /// Every entry's cell, if the archive has them.
    cells: Option<prm_format::EntryCells>,
    /// Every cluster, its entries a range into `entries`.
    clusters: Vec<prm_format::Cluster>,
    /// Every pane's energy.
    cluster_energy: Vec<Vec3>,
    /// Every pane, as the archive's low-rank basis per tile.
    panes: prm_format::PaneBasis,
    /// Every cluster's residual group; empty without groups.
    groups: Vec<u32>,
    /// Every group's energy: its members' summed.
    group_energy: Vec<Vec3>,
    /// The near field, if the archive has one and it is played.
    near: Option<prm_format::NearField>,
    /// Lightmap side, texels.
    resolution: usize,
    /// Lightmap UVs of every triangle.
    triangle_uvs: Vec<[Vec2; 3]>,
}

/// How the CPU player plays an archive.
#[derive(Clone, Copy, Debug)]
pub struct CpuOptions {
    /// Clusters blended a frame.
    pub top_k: u32,
    /// Residual groups (0: none).
    pub residual_groups: u32,
    /// Score band over which the clusters beyond K fade.
    pub fade_band: f32,
    /// Play the near field (when the archive has one).
    pub near_field: bool,
    /// Gathers of the near field's deeper share before its series is extrapolated.
    pub near_bounces: u32,
}

impl CpuArchive {
    /// Reads what the CPU player needs of `archive`, baked from `scene`.
    pub fn load<R: std::io::Read + std::io::Seek>(
        archive: &mut Archive<R>,
        scene: &Scene,
        options: &CpuOptions,
    ) -> Result<CpuArchive, PlayError> {
        let entries = archive.entries().to_vec();
        let entry_energy = match archive.entry_energy() {
            Some(e) => e.iter().map(|v| Vec3::from(*v)).collect(),
            None => vec![Vec3::ONE; entries.len()],
        };
        let clusters = archive.clusters().to_vec();
        let cluster_energy: Vec<Vec3> = archive.clusters().iter().map(|c| Vec3::from(c.energy)).collect();
        let groups = if options.residual_groups == 0 {
            Vec::new()
        } else {
            let count = prm_format::residual_group_count(archive.clusters().len(), options.residual_groups);
            prm_format::residual_groups(archive.clusters(), count)
        };
        let mut group_energy = vec![Vec3::ZERO; groups.iter().max().map_or(0, |g| *g as usize + 1)];
        for (e, &g) in cluster_energy.iter().zip(&groups) {
            group_energy[g as usize] += *e;
        }
        let atlas = archive.atlas();
        Ok(CpuArchive {
            entry_disk: scene.entry_disk(entries.len()),
            entries,
            entry_energy,
            cells: archive.entry_cells().cloned(),
            clusters,
            cluster_energy,
            panes: archive.pane_basis().clone(),
            groups,
            group_energy,
            near: archive.near_field().filter(|_| options.near_field).cloned(),
            resolution: atlas.resolution as usize,
            triangle_uvs: atlas.triangle_uvs.iter().map(|t| t.map(Vec2::from_array)).collect(),
        })
    }

    /// Lightmap side, texels.
    pub fn resolution(&self) -> usize {
        self.resolution
    }
}

/// The CPU player: an archive's model, the scene's BVH and the near field's series.
pub struct CpuPlayer<'a> {
    scene: &'a Scene,
    archive: &'a CpuArchive,
    bvh: Bvh,
    near: Option<NearPlay<'a>>,
    options: CpuOptions,
}

impl<'a> CpuPlayer<'a> {
    /// Builds the BVH of `scene` and the near field's series over the whole lightmap.
    pub fn new(scene: &'a Scene, archive: &'a CpuArchive, options: CpuOptions) -> Result<CpuPlayer<'a>, PlayError> {
        let bvh = Bvh::build(scene, &BvhParams::DEFAULT).map_err(|e| PlayError::Cpu(e.to_string()))?;
        // Every texel is its own exit point and every one is read.
        let texels: Vec<u32> = (0..(archive.resolution * archive.resolution) as u32).collect();
        let near = archive
            .near
            .as_ref()
            .map(|n| NearPlay::new(n, &texels, &texels, options.near_bounces));
        Ok(CpuPlayer {
            scene,
            archive,
            bvh,
            near,
            options,
        })
    }

    /// The indirect irradiance lightmap under `lights`, row 0 at `v = 0`.
    pub fn indirect_lightmap(&self, lights: &[Light]) -> Vec<Vec3> {
        let a = self.archive;
        let weights = prm_trace::archive_weights(
            &self.bvh,
            lights,
            &a.entries,
            &a.entry_energy,
            &a.clusters,
            a.entry_disk,
            a.cells.as_ref(),
        );
        let top_k = self.options.top_k as usize;
        let fade = self.options.fade_band;
        // Blending is linear: a residual group's weight goes to each of its members.
        let weights: Vec<[f32; 3]> = if a.groups.is_empty() {
            prm_trace::check::select_top_k(&weights, &a.cluster_energy, top_k, fade)
                .iter()
                .map(|w| w.to_array())
                .collect()
        } else {
            let (kept, residual) = prm_trace::check::select_with_residuals(
                &weights,
                &a.cluster_energy,
                top_k,
                fade,
                &a.groups,
                &a.group_energy,
            );
            kept.iter()
                .zip(&a.groups)
                .map(|(w, &g)| (*w + residual[g as usize]).to_array())
                .collect()
        };
        let lightmap: Vec<Vec3> = a.panes.blend(&weights).into_iter().map(Vec3::from).collect();
        match &self.near {
            Some(near) => {
                let mut played = near.series(&lightmap);
                for (p, d) in played.iter_mut().zip(near.direct(&self.bvh, lights)) {
                    *p += d;
                }
                played
            }
            None => lightmap,
        }
    }

    /// Renders one frame of `width × height` pixels: linear radiance, top row first.
    pub fn render(&self, input: &FrameInput, width: u32, height: u32) -> Image {
        let texels = match input.mode {
            Mode::Direct => Vec::new(),
            _ => self.indirect_lightmap(input.lights),
        };
        let lightmap = Lightmap {
            texels: &texels,
            resolution: self.archive.resolution,
            uvs: &self.archive.triangle_uvs,
        };
        self.render_with(input, width, height, &lightmap)
    }

    /// Renders as [`CpuPlayer::render`] does, with `lightmap` for the indirect light: another
    /// lightmap of the scene (a converged reference at the exit points, say) seen through the
    /// player's reconstruction.
    pub fn render_with(&self, input: &FrameInput, width: u32, height: u32, lightmap: &Lightmap) -> Image {
        let rays = CameraRays::new(&input.camera, width, height);
        let rgb = (0..width * height)
            .into_par_iter()
            .map(|i| {
                let (x, y) = (i % width, i / width);
                let mode = match input.mode {
                    Mode::Split if x < width / 2 => Mode::Direct,
                    Mode::Split => Mode::Gi,
                    m => m,
                };
                let lightmap = Some(lightmap).filter(|_| mode != Mode::Direct);
                self.shade(&rays, x, y, input.lights, mode, lightmap).to_array()
            })
            .collect();
        Image { width, height, rgb }
    }

    /// Radiance of pixel `(x, y)`: albedo/π × (direct + indirect irradiance).
    fn shade(
        &self,
        rays: &CameraRays,
        x: u32,
        y: u32,
        lights: &[Light],
        mode: Mode,
        lightmap: Option<&Lightmap>,
    ) -> Vec3 {
        let dir = rays.direction(x, y);
        let Some(hit) = self.bvh.closest_hit(rays.eye, dir, f32::INFINITY, u32::MAX) else {
            return Vec3::ZERO;
        };
        let t = &self.scene.triangles[hit.triangle as usize];
        let (b1, b2) = (hit.b1, hit.b2);
        let b0 = 1.0 - b1 - b2;
        let p = rays.eye + dir * hit.t;
        let mut ng = (t.positions[1] - t.positions[0])
            .cross(t.positions[2] - t.positions[0])
            .normalize_or_zero();
        if ng.dot(-dir) < 0.0 {
            ng = -ng;
        }
        let mut n = (t.normals[0] * b0 + t.normals[1] * b1 + t.normals[2] * b2).normalize_or(ng);
        if n.dot(ng) < 0.0 {
            n = -n;
        }
        let mut e = Vec3::ZERO;
        if mode != Mode::Indirect {
            e += prm_trace::direct_irradiance(&self.bvh, lights, p, ng, n, hit.triangle);
        }
        if let Some(map) = lightmap {
            let uv = map.uvs[hit.triangle as usize];
            let uv = uv[0] * b0 + uv[1] * b1 + uv[2] * b2;
            e += bilinear(map.texels, map.resolution, uv);
        }
        self.scene.albedo(hit.triangle as usize, b1, b2) / std::f32::consts::PI * e
    }
}

/// Indirect irradiance over a square atlas, as [`CpuPlayer::render_with`] shades it.
#[derive(Clone, Copy, Debug)]
pub struct Lightmap<'a> {
    /// Irradiance of every texel, row by row (`resolution²`).
    pub texels: &'a [Vec3],
    /// Texels on a side.
    pub resolution: usize,
    /// Every scene triangle's UVs in the atlas.
    pub uvs: &'a [[Vec2; 3]],
}

/// Bilinear lookup of a square `side × side` map at `uv`, clamped at its edges (as the GPU
/// player's shade pass filters the lightmap).
fn bilinear(map: &[Vec3], side: usize, uv: Vec2) -> Vec3 {
    let t = uv * side as f32 - 0.5;
    let base = t.floor();
    let f = t - base;
    let hi = side as i32 - 1;
    let at = |dx: i32, dy: i32| {
        let x = (base.x as i32 + dx).clamp(0, hi) as usize;
        let y = (base.y as i32 + dy).clamp(0, hi) as usize;
        map[y * side + x]
    };
    let top = at(0, 0).lerp(at(1, 0), f.x);
    let bottom = at(0, 1).lerp(at(1, 1), f.x);
    top.lerp(bottom, f.y)
}

/// Primary rays of a pinhole camera projected as the GPU player projects it: vertical field of
/// view, square pixels, +Y up (+Z when looking straight up or down).
struct CameraRays {
    eye: Vec3,
    forward: Vec3,
    right: Vec3,
    up: Vec3,
    width: f32,
    height: f32,
}

impl CameraRays {
    fn new(camera: &Camera, width: u32, height: u32) -> CameraRays {
        let forward = (camera.target - camera.eye).normalize_or(Vec3::NEG_Z);
        let world_up = if forward.y.abs() > 0.999 { Vec3::Z } else { Vec3::Y };
        let tan = (camera.fov_y_deg.to_radians() * 0.5).tan();
        let right = forward.cross(world_up).normalize() * tan * width as f32 / height as f32;
        let up = right.cross(forward).normalize() * tan;
        CameraRays {
            eye: camera.eye,
            forward,
            right,
            up,
            width: width as f32,
            height: height as f32,
        }
    }

    /// The unit direction through the centre of pixel `(x, y)` (row 0 at the top).
    fn direction(&self, x: u32, y: u32) -> Vec3 {
        let sx = 2.0 * (x as f32 + 0.5) / self.width - 1.0;
        let sy = 1.0 - 2.0 * (y as f32 + 0.5) / self.height;
        (self.forward + self.right * sx + self.up * sy).normalize()
    }
}
