//! GPU pane rendering: every cluster's pane (indirect irradiance at every exit point per unit
//! irradiance on the cluster) from its VPLs, by the [`crate::vpl_depth`] and [`crate::pane_gather`]
//! passes.
//!
//! Same estimator and VPL bound as the CPU evaluator [`prm_trace::evaluate_panes`]; only the
//! visibility differs: a five-face hemicube depth map per VPL (each face `face_resolution²`,
//! sampled with 2×2 percentage-closer filtering) instead of a shadow ray.
//!
//! Work is cut twice: panes into *groups* that fit one storage binding (≤ 128 MiB on lavapipe),
//! and each group's VPLs (sorted by pane) into *batches* whose depth faces fit one texture array.
//! A group's panes are read back and handed to the caller before the next group starts, so at
//! most one group of panes is in memory.
//!
//! The panes rendered are those of the entry points (members in cluster order), summed into their
//! cluster's pane on the CPU, so that every member's pane energy is known (the player weighs a
//! cluster's members by it, formats/prm.md §5.1). The VPL work is the same as for a pane per
//! cluster; what grows is the read-back (entries × exits × 16 bytes instead of clusters × exits)
//! and the number of groups, hence of part-filled batches. Measured on the default Cornell bake
//! (1024 entries, 64 clusters, 256²): 46 batches and 58.4 s, against 42 and 56.6 s with a pane
//! per cluster. Above
//! [`PaneRenderParams::member_energy_bytes`] of read-back the clusters are rendered directly and
//! no member energies are produced.

use glam::Vec3;
use prm_gpu_kit::{pipeline, readback};
use prm_scene::{ExitPoint, Scene};
use prm_trace::{Clustering, Panes, VplBound, VplSet};

use crate::pane_gather::{GatherParams, GpuExit, PaneGatherPass, VplBoundKind};
use crate::vpl_depth::{ChunkedScene, DepthFrame, GpuVpl, VplDepthPass, FACES};
use crate::{ErrorScopes, GpuContext, GpuError};

/// Parameters of GPU pane rendering.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PaneRenderParams {
    /// The VPL singularity bound (must match the CPU evaluator's for comparisons).
    pub bound: VplBound,
    /// Texels on a side of each hemicube face.
    pub face_resolution: u32,
    /// VPLs whose depth faces are rendered per batch (clamped to the device's array-layer limit).
    pub vpls_per_batch: u32,
    /// Largest pane buffer of one group, bytes (clamped to the device's storage-binding limit).
    pub max_group_bytes: u64,
    /// Shadow-test biases.
    pub bias: ShadowBias,
    /// How the depth maps are read.
    pub filter: DepthFilter,
    /// Largest read-back of per-entry panes (entries × exits × 16 bytes) for which members'
    /// pane energies are produced; above it, panes are rendered per cluster and
    /// [`PaneOutput::Pane`]'s `member_energy` is empty.
    pub member_energy_bytes: u64,
}

/// How the gather pass reads a VPL's depth map, as [`GatherParams::depth_filter`] holds it (the
/// `DEPTH_*` constants of `pane_gather.wgsl`).
#[repr(u32)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DepthFilter {
    /// `DEPTH_NEAREST`: the depth texel under the receiver: hard shadows, fastest.
    Nearest = 0,
    /// `DEPTH_PCF2X2`: 2×2 percentage-closer filtering through a comparison sampler: softer
    /// shadow edges.
    Pcf2x2 = 1,
}

/// Biases of the depth-map visibility test against self-shadowing ("acne").
///
/// A receiver at distance `d` from the VPL counts as lit when the stored distance exceeds
/// `d − (constant + slope · d · texel_angle · tan θ)`, where `θ` is the angle between the receiver's
/// normal and the direction to the VPL (tan θ capped at 8). Larger values leak light through thin
/// walls; smaller ones darken surfaces seen at grazing angles.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ShadowBias {
    /// Constant part, as a fraction of the scene diagonal.
    pub constant: f32,
    /// Slope part, in depth texels.
    pub slope: f32,
    /// Receiver offset along its normal, as a fraction of the scene diagonal.
    pub receiver_offset: f32,
}

impl ShadowBias {
    /// 1e-4 diagonal constant, 1.5 texels of slope, no receiver offset.
    pub const DEFAULT: ShadowBias = ShadowBias {
        constant: 1e-4,
        slope: 1.5,
        receiver_offset: 0.0,
    };
}

impl PaneRenderParams {
    /// 128² faces, 256 VPLs a batch, 64 MiB groups, member energies up to 4 GiB of read-back
    /// (the chairs' `paper` preset, 4096 entries × 33k exits, needs 2.2 GiB; Sibenik's default,
    /// 5120 × 190k, 15.6 GiB, and keeps a pane per cluster).
    pub const DEFAULT: PaneRenderParams = PaneRenderParams {
        bound: VplBound::DEFAULT,
        face_resolution: 128,
        vpls_per_batch: 256,
        max_group_bytes: 64 << 20,
        bias: ShadowBias::DEFAULT,
        filter: DepthFilter::Pcf2x2,
        member_energy_bytes: 4 << 30,
    };
}

impl Default for PaneRenderParams {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// Counters of a pane rendering run.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PaneRenderStats {
    /// VPLs rendered.
    pub vpls: u64,
    /// Depth faces rendered.
    pub faces: u64,
    /// Triangles drawn into them (whole culling chunks, padding included).
    pub triangles: u64,
    /// Draws issued for them (runs of chunks).
    pub draws: u64,
    /// Batches submitted.
    pub batches: u64,
    /// Cluster groups read back.
    pub groups: u64,
    /// VPL × exit point evaluations.
    pub evaluations: u64,
    /// Wall time of the depth pass (write, record, run), seconds.
    pub depth_seconds: f64,
    /// Wall time of the gather pass, seconds.
    pub gather_seconds: f64,
}

/// What the panes are rendered from.
#[derive(Clone, Copy)]
pub struct PaneInputs<'a> {
    /// The scene whose triangles occlude the VPLs.
    pub scene: &'a Scene,
    /// The points every pane is evaluated at.
    pub exits: &'a [ExitPoint],
    /// The VPLs, by entry point.
    pub vpls: &'a VplSet,
    /// The clusters of entry points, one pane each.
    pub clustering: &'a Clustering,
}

/// What [`render_panes_with`] hands its sink.
#[derive(Debug)]
pub enum PaneOutput<'a> {
    /// A finished pane: irradiance at every exit point per unit irradiance on the cluster.
    Pane {
        /// Its cluster.
        cluster: usize,
        /// One value per exit point.
        irradiance: &'a [Vec3],
        /// The pane energy of each of the cluster's members, in `clustering.members` order: the
        /// sum over the exit points of what the member's own VPLs give (formats/prm.md §5.1).
        member_energy: &'a [Vec3],
    },
    /// The counters after another batch of VPLs (for progress bars on long bakes).
    Progress(&'a PaneRenderStats),
}

/// Renders every cluster's pane of `inputs` over its exit points with `params` on `ctx`, and
/// hands each to `sink` in cluster order, with its members' pane energies, and a
/// [`PaneOutput::Progress`] after every batch; `sink`'s errors stop the work and are returned as
/// they are.
///
/// The GPU renders one pane per *entry point* (members in cluster order) and the cluster's pane
/// is their sum, so each member's energy is known; see the module docs for the cost, and
/// [`PaneRenderParams::member_energy_bytes`] for when it renders per cluster instead.
pub fn render_panes_with<E: From<GpuError>>(
    ctx: &GpuContext,
    inputs: &PaneInputs,
    params: &PaneRenderParams,
    mut sink: impl FnMut(PaneOutput) -> Result<(), E>,
) -> Result<PaneRenderStats, E> {
    let (exits, clustering) = (inputs.exits, inputs.clustering);
    if member_readback_bytes(clustering.of_entry.len(), exits.len()) > params.member_energy_bytes {
        return render_cluster_panes(ctx, inputs, params, sink);
    }
    let order: Vec<u32> = clustering.members.iter().flatten().copied().collect();
    let mut of_entry = vec![0u32; clustering.of_entry.len()];
    for (j, &k) in order.iter().enumerate() {
        of_entry[k as usize] = j as u32;
    }
    let singletons = Clustering {
        of_entry,
        centroids: order
            .iter()
            .map(|&k| clustering.centroids[clustering.of_entry[k as usize] as usize])
            .collect(),
        normals: order
            .iter()
            .map(|&k| clustering.normals[clustering.of_entry[k as usize] as usize])
            .collect(),
        members: order.iter().map(|&k| vec![k]).collect(),
    };
    // The cluster being summed, its pane and its members' energies.
    let mut current = 0usize;
    let mut pane = vec![Vec3::ZERO; exits.len()];
    let mut energy: Vec<Vec3> = Vec::new();
    let per_entry = PaneInputs {
        clustering: &singletons,
        ..*inputs
    };
    let stats = render_cluster_panes(ctx, &per_entry, params, |out| match out {
        PaneOutput::Pane {
            cluster: j, irradiance, ..
        } => {
            let c = clustering.of_entry[order[j] as usize] as usize;
            debug_assert!(c >= current, "members and of_entry disagree");
            emit_clusters_before(c, &mut current, &mut pane, &mut energy, &mut sink)?;
            for (a, v) in pane.iter_mut().zip(irradiance) {
                *a += *v;
            }
            energy.push(irradiance.iter().sum());
            Ok(())
        }
        progress => sink(progress),
    })?;
    emit_clusters_before(clustering.len(), &mut current, &mut pane, &mut energy, &mut sink)?;
    Ok(stats)
}

/// Hands `sink` the summed pane of cluster `current` and of every (empty) cluster after it up to
/// `until`, resetting the sums after each.
fn emit_clusters_before<E>(
    until: usize,
    current: &mut usize,
    pane: &mut [Vec3],
    energy: &mut Vec<Vec3>,
    sink: &mut impl FnMut(PaneOutput) -> Result<(), E>,
) -> Result<(), E> {
    while *current < until {
        sink(PaneOutput::Pane {
            cluster: *current,
            irradiance: pane,
            member_energy: energy,
        })?;
        pane.fill(Vec3::ZERO);
        energy.clear();
        *current += 1;
    }
    Ok(())
}

/// Bytes of per-entry panes read back for `entries` entry points over `exits` exit points
/// (RGBA f32 texels), compared with [`PaneRenderParams::member_energy_bytes`].
pub fn member_readback_bytes(entries: usize, exits: usize) -> u64 {
    entries as u64 * exits as u64 * 16
}

/// The pane of every cluster of `inputs.clustering` in order (for [`render_panes_with`]: of
/// every entry point), with no member energies.
fn render_cluster_panes<E: From<GpuError>>(
    ctx: &GpuContext,
    inputs: &PaneInputs,
    params: &PaneRenderParams,
    mut sink: impl FnMut(PaneOutput) -> Result<(), E>,
) -> Result<PaneRenderStats, E> {
    let PaneInputs {
        scene,
        exits,
        vpls,
        clustering,
    } = *inputs;
    let device = &ctx.device;
    let clusters = clustering.len();
    let mut stats = PaneRenderStats::default();
    if clusters == 0 {
        return Ok(stats);
    }
    let scope = ErrorScopes::push(device);

    // Scene geometry in culling chunks, and the frame of the hemicubes.
    let triangles: Vec<[Vec3; 3]> = scene.triangles.iter().map(|t| t.positions).collect();
    let chunked = ChunkedScene::new(&triangles);
    let diagonal = scene.bounds().diagonal().max(1e-12);
    let frame = DepthFrame {
        near: 5e-4 * diagonal,
        far: 1.01 * diagonal,
        lift: 1e-5 * diagonal,
        _pad: 0.0,
    };
    let (sorted, cluster_start) = sort_vpls_by_cluster(vpls, clustering);
    let sizes = WorkSizes::new(&device.limits(), params, chunked.chunks(), exits.len());
    let mut gpu = PaneResources::new(device, &chunked, exits, &frame, &sizes, clusters);
    scope.pop("pane setup")?;
    ctx.take_uncaptured()?;

    let base = gather_params(
        params,
        &frame,
        diagonal,
        sizes.face_res,
        exits.len(),
        gpu.depth.faces_per_row,
    );
    let mut first = 0;
    while first < clusters {
        let last = (first + sizes.group_cap).min(clusters);
        gpu.clear_panes(ctx);
        for batch in sorted[cluster_start[first]..cluster_start[last]].chunks(sizes.batch_cap as usize) {
            let gp = GatherParams {
                vpl_count: batch.len() as u32,
                first_cluster: first as u32,
                ..base
            };
            gpu.render_batch(ctx, &chunked, batch, &gp, &mut stats)?;
            sink(PaneOutput::Progress(&stats))?;
        }
        gpu.read_group(ctx, first..last, exits.len(), &mut sink)?;
        stats.groups += 1;
        first = last;
    }
    Ok(stats)
}

/// The VPLs of `vpls` sorted by cluster (members ascending, VPLs of an entry in walk order),
/// and where each cluster's start in them (one more: the end).
fn sort_vpls_by_cluster(vpls: &VplSet, clustering: &Clustering) -> (Vec<GpuVpl>, Vec<usize>) {
    let mut sorted = Vec::with_capacity(vpls.vpls.len());
    let mut cluster_start = Vec::with_capacity(clustering.len() + 1);
    for (c, members) in clustering.members.iter().enumerate() {
        cluster_start.push(sorted.len());
        for &k in members {
            for v in &vpls.vpls[vpls.range(k as usize)] {
                sorted.push(GpuVpl::new(v.position, v.normal, v.power, v.area, c as u32));
            }
        }
    }
    cluster_start.push(sorted.len());
    (sorted, cluster_start)
}

/// How the work is cut on this device: VPLs per batch, clusters per group, face resolution.
struct WorkSizes {
    batch_cap: u32,
    group_cap: usize,
    face_res: u32,
}

impl WorkSizes {
    /// The sizes `params` ask for within `limits`, for a scene of `chunks` culling chunks and
    /// `exits` exit points.
    fn new(limits: &wgpu::Limits, params: &PaneRenderParams, chunks: usize, exits: usize) -> WorkSizes {
        let n_exit = exits.max(1) as u64;
        // Each face of a batch may need a draw for every other chunk; keep them in one buffer.
        let list_cap = limits.max_buffer_size / (16 * FACES as u64 * chunks.div_ceil(2).max(1) as u64);
        let batch_cap = params
            .vpls_per_batch
            .min(list_cap.min(u32::MAX as u64) as u32)
            .clamp(1, (limits.max_texture_array_layers / FACES).max(1));
        let group_bytes = params
            .max_group_bytes
            .min(limits.max_storage_buffer_binding_size)
            .max(16 * n_exit);
        WorkSizes {
            batch_cap,
            group_cap: (group_bytes / (16 * n_exit)).max(1) as usize,
            face_res: params.face_resolution.clamp(8, limits.max_texture_dimension_2d),
        }
    }
}

/// The gather parameters every batch shares (`vpl_count` and `first_cluster` 0).
fn gather_params(
    params: &PaneRenderParams,
    frame: &DepthFrame,
    diagonal: f32,
    face_res: u32,
    exit_count: usize,
    faces_per_row: u32,
) -> GatherParams {
    let (bound_kind, bound_value) = VplBoundKind::of(params.bound);
    GatherParams {
        exit_count: exit_count as u32,
        vpl_count: 0,
        first_cluster: 0,
        bound_kind: bound_kind as u32,
        bound_value,
        near: frame.near,
        far: frame.far,
        lift: frame.lift,
        receiver_offset: params.bias.receiver_offset * diagonal,
        bias_constant: params.bias.constant * diagonal,
        bias_slope: params.bias.slope,
        // A face spans 90°: one texel subtends about π/2 / resolution at its centre.
        texel_angle: std::f32::consts::FRAC_PI_2 / face_res as f32,
        depth_filter: params.filter as u32,
        face_resolution: face_res,
        faces_per_row,
        _pad: 0,
    }
}

/// The buffers and passes of a pane rendering run.
struct PaneResources {
    scene: wgpu::Buffer,
    /// The exit points and the hemicube frame, which only the passes' bind groups read.
    _bound: [wgpu::Buffer; 2],
    vpls: wgpu::Buffer,
    params: wgpu::Buffer,
    panes: wgpu::Buffer,
    readback: wgpu::Buffer,
    depth: VplDepthPass,
    gather: PaneGatherPass,
    lift: f32,
}

impl PaneResources {
    /// Uploads the scene and the exit points, and makes room for a batch of VPLs and a group
    /// of at most `clusters` panes.
    fn new(
        device: &wgpu::Device,
        chunked: &ChunkedScene,
        exits: &[ExitPoint],
        frame: &DepthFrame,
        sizes: &WorkSizes,
        clusters: usize,
    ) -> PaneResources {
        let scene = pipeline::vertex_buffer(device, "pane scene", &chunked.vertices);
        let gpu_exits: Vec<GpuExit> = exits
            .iter()
            .map(|e| GpuExit {
                position: e.position.to_array(),
                _pad0: 0.0,
                normal: e.normal.to_array(),
                _pad1: 0.0,
            })
            .collect();
        let exit_contents: &[u8] = if gpu_exits.is_empty() {
            &[0u8; 32]
        } else {
            bytemuck::cast_slice(&gpu_exits)
        };
        let exit_buffer = pipeline::buffer_init(device, "pane exits", exit_contents, wgpu::BufferUsages::STORAGE);
        // At least one VPL of at least 16 bytes: `storage`'s 16-byte floor changes nothing here.
        let vpl_bytes = sizes.batch_cap as u64 * std::mem::size_of::<GpuVpl>() as u64;
        let vpls = pipeline::storage(device, "pane vpl batch", vpl_bytes, wgpu::BufferUsages::empty());
        let frame_buffer = pipeline::buffer_init(
            device,
            "pane depth frame",
            bytemuck::bytes_of(frame),
            wgpu::BufferUsages::UNIFORM,
        );
        let params = pipeline::uniform(device, "pane gather params", std::mem::size_of::<GatherParams>() as u64);
        // At least one cluster and one exit point: at least 16 bytes.
        let pane_bytes = (sizes.group_cap.min(clusters) as u64) * 16 * exits.len().max(1) as u64;
        let panes = pipeline::storage(device, "pane group", pane_bytes, wgpu::BufferUsages::COPY_SRC);
        let readback = readback::staging(device, "pane readback", pane_bytes);
        let depth = VplDepthPass::new(device, sizes.batch_cap, sizes.face_res, &vpls, &frame_buffer, chunked);
        let gather = PaneGatherPass::new(device, &vpls, &exit_buffer, &panes, &params, &depth.array_view);
        PaneResources {
            scene,
            _bound: [exit_buffer, frame_buffer],
            vpls,
            params,
            panes,
            readback,
            depth,
            gather,
            lift: frame.lift,
        }
    }

    /// Zeroes the group's panes.
    fn clear_panes(&self, ctx: &GpuContext) {
        let mut encoder = ctx.device.create_command_encoder(&Default::default());
        encoder.clear_buffer(&self.panes, 0, None);
        ctx.queue.submit([encoder.finish()]);
    }

    /// Renders the depth faces of `batch` and adds its VPLs into the group's panes with `gp`,
    /// counting the work in `stats`.
    fn render_batch(
        &mut self,
        ctx: &GpuContext,
        chunked: &ChunkedScene,
        batch: &[GpuVpl],
        gp: &GatherParams,
        stats: &mut PaneRenderStats,
    ) -> Result<(), GpuError> {
        let scope = ErrorScopes::push(&ctx.device);
        ctx.queue.write_buffer(&self.vpls, 0, bytemuck::cast_slice(batch));
        ctx.queue.write_buffer(&self.params, 0, bytemuck::bytes_of(gp));
        // Two submissions so each pass can be timed (the device runs them in order anyway).
        let mut counts = (0, 0);
        stats.depth_seconds += submit_timed(ctx, |encoder| {
            counts = self
                .depth
                .encode(encoder, &ctx.queue, chunked, &self.scene, self.lift, batch);
        })?;
        stats.triangles += counts.0;
        stats.draws += counts.1;
        stats.gather_seconds += submit_timed(ctx, |encoder| self.gather.encode(encoder, gp.exit_count))?;
        scope.pop("pane batch")?;
        stats.vpls += batch.len() as u64;
        stats.faces += (batch.len() as u32 * FACES) as u64;
        stats.batches += 1;
        stats.evaluations += batch.len() as u64 * gp.exit_count as u64;
        Ok(())
    }

    /// Reads back the panes of `clusters` (the group) over `exit_count` exit points and hands
    /// each to `sink`.
    fn read_group<E: From<GpuError>>(
        &self,
        ctx: &GpuContext,
        clusters: std::ops::Range<usize>,
        exit_count: usize,
        sink: &mut impl FnMut(PaneOutput) -> Result<(), E>,
    ) -> Result<(), E> {
        let n_exit = exit_count.max(1);
        let bytes = clusters.len() as u64 * 16 * n_exit as u64;
        let mut encoder = ctx.device.create_command_encoder(&Default::default());
        encoder.copy_buffer_to_buffer(&self.panes, 0, &self.readback, 0, bytes);
        ctx.queue.submit([encoder.finish()]);
        let data = ctx.read_buffer(&self.readback)?;
        let texels: &[[f32; 4]] = bytemuck::cast_slice(&data);
        let mut pane = vec![Vec3::ZERO; exit_count];
        for c in clusters.clone() {
            let base = (c - clusters.start) * n_exit;
            for (i, p) in pane.iter_mut().enumerate() {
                let t = texels[base + i];
                *p = Vec3::new(t[0], t[1], t[2]);
            }
            sink(PaneOutput::Pane {
                cluster: c,
                irradiance: &pane,
                member_energy: &[],
            })?;
        }
        Ok(())
    }
}

/// Records into a fresh encoder with `record`, submits it and waits for the device: the seconds
/// that took.
fn submit_timed(ctx: &GpuContext, record: impl FnOnce(&mut wgpu::CommandEncoder)) -> Result<f64, GpuError> {
    let t = std::time::Instant::now();
    let mut encoder = ctx.device.create_command_encoder(&Default::default());
    record(&mut encoder);
    ctx.queue.submit([encoder.finish()]);
    ctx.wait()?;
    Ok(t.elapsed().as_secs_f64())
}

/// Checks that `ctx` can run the pane passes at all, in a few milliseconds: creates both passes
/// over a one-triangle scene. A backend whose shader translation lacks what the passes use
/// (GLSL has no `textureLoad` of depth textures, which the gather needs) fails here with the
/// backend's own reason, before a bake has done any work.
pub fn check_support(ctx: &GpuContext) -> Result<(), GpuError> {
    let device = &ctx.device;
    let scope = ErrorScopes::push(device);
    let chunked = ChunkedScene::new(&[[Vec3::ZERO, Vec3::X, Vec3::Y]]);
    let storage = |label: &str, size: usize| pipeline::storage(device, label, size as u64, wgpu::BufferUsages::empty());
    let vpls = storage("check vpls", std::mem::size_of::<GpuVpl>());
    let exits = storage("check exits", std::mem::size_of::<GpuExit>());
    let panes = storage("check panes", 16);
    let frame = pipeline::uniform(device, "check frame", std::mem::size_of::<DepthFrame>() as u64);
    let params = pipeline::uniform(device, "check params", std::mem::size_of::<GatherParams>() as u64);
    let depth = VplDepthPass::new(device, 1, 8, &vpls, &frame, &chunked);
    let _gather = PaneGatherPass::new(device, &vpls, &exits, &panes, &params, &depth.array_view);
    scope.pop("pane passes")?;
    ctx.wait()
}

/// Renders all panes into memory (cluster-major, like [`prm_trace::Panes`]).
pub fn render_panes(
    ctx: &GpuContext,
    inputs: &PaneInputs,
    params: &PaneRenderParams,
) -> Result<(Panes, PaneRenderStats), GpuError> {
    let (exits, clustering) = (inputs.exits, inputs.clustering);
    let mut data = vec![Vec3::ZERO; clustering.len() * exits.len()];
    let mut entry_energy = vec![Vec3::ZERO; clustering.of_entry.len()];
    let mut energies_complete = true;
    let n = exits.len();
    let stats = render_panes_with(ctx, inputs, params, |out| {
        if let PaneOutput::Pane {
            cluster,
            irradiance,
            member_energy,
        } = out
        {
            data[cluster * n..(cluster + 1) * n].copy_from_slice(irradiance);
            energies_complete &= member_energy.len() == clustering.members[cluster].len();
            for (&k, e) in clustering.members[cluster].iter().zip(member_energy) {
                entry_energy[k as usize] = *e;
            }
        }
        Ok::<(), GpuError>(())
    })?;
    Ok((
        Panes {
            clusters: clustering.len(),
            exits: n,
            data,
            rays: 0,
            entry_energy: if energies_complete { entry_energy } else { Vec::new() },
        },
        stats,
    ))
}
