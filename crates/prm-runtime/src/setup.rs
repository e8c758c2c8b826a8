//! The phases of [`Runtime::new`](crate::Runtime::new): checking the archive against the scene,
//! uploading the scene's geometry, the entries, clusters and panes, and building the lightmap and
//! the passes that need more than their constructor (the near field, the probes).

use std::io::{Read, Seek};

use prm_format::{Archive, NearField};
use prm_gpu_kit::pipeline;
use prm_scene::Scene;

use crate::shadow::ShadowMaps;
use crate::{
    baked, blend, irradiance, near_field, probes, Buffers, GpuCluster, GpuEntry, GpuFrame, GpuGatherPoint, GpuLight,
    GpuNearExit, GpuNearHit, GpuView, NearLight, ProbeLight, RuntimeError, RuntimeOptions, LIGHTMAP_FORMAT, MAX_LIGHTS,
};

/// Refuses one shard of a split bake, and an archive whose atlas has not one UV triangle per
/// scene triangle.
pub(crate) fn check_archive<R: Read + Seek>(archive: &Archive<R>, scene: &Scene) -> Result<(), RuntimeError> {
    if let Some(shard) = archive.metadata().params.get("shard") {
        let field = |k: &str| shard.get(k).map_or("?".to_string(), |v| v.to_string());
        return Err(RuntimeError::PartialArchive(format!(
            "{}/{}",
            field("index"),
            field("count")
        )));
    }
    let uvs = archive.atlas().triangle_uvs.len();
    if uvs != scene.triangles.len() {
        return Err(RuntimeError::Mismatch(format!(
            "the archive's atlas has {} triangles, the scene {}",
            uvs,
            scene.triangles.len()
        )));
    }
    Ok(())
}

/// Every cluster's residual group ([`prm_format::residual_groups`]; all 0 without groups).
pub(crate) fn residual_group_of<R: Read + Seek>(archive: &Archive<R>, group_count: u32) -> Vec<u32> {
    if group_count > 0 {
        prm_format::residual_groups(archive.clusters(), group_count)
    } else {
        vec![0; archive.clusters().len()]
    }
}

/// The scene's corners on the GPU: positions for the shadow maps, and position, normal and
/// lightmap UV for the irradiance pass.
pub(crate) struct SceneGeometry {
    pub positions: wgpu::Buffer,
    pub atlas_vertices: wgpu::Buffer,
    pub vertex_count: u32,
}

impl SceneGeometry {
    /// Uploads the corners of `scene`'s triangles with their lightmap UVs `triangle_uvs`.
    pub fn upload(device: &wgpu::Device, scene: &Scene, triangle_uvs: &[[[f32; 2]; 3]]) -> SceneGeometry {
        let positions: Vec<[f32; 3]> = scene
            .triangles
            .iter()
            .flat_map(|t| t.positions.map(|p| p.to_array()))
            .collect();
        let vertex_count = positions.len() as u32;
        let atlas_vertices: Vec<irradiance::AtlasVertex> = scene
            .triangles
            .iter()
            .zip(triangle_uvs)
            .flat_map(|(t, uv)| {
                (0..3).map(move |i| irradiance::AtlasVertex {
                    position: t.positions[i].to_array(),
                    normal: t.normals[i].to_array(),
                    uv: uv[i],
                })
            })
            .collect();
        let atlas_vertices = pipeline::vertex_buffer(device, "prm atlas vertices", &atlas_vertices);
        let positions = pipeline::vertex_buffer(device, "prm positions", &positions);
        SceneGeometry {
            positions,
            atlas_vertices,
            vertex_count,
        }
    }
}

/// The archive's entry points as the weights pass reads them, each weighed by the points of its
/// cell for the lights within `prm_scene::cell_reach2` of it or, in an archive without cells,
/// standing for a disk of area A/N (its irradiance bound, see `weights.wgsl`), before the
/// emitters' irradiance is added.
pub(crate) fn gpu_entries<R: Read + Seek>(archive: &Archive<R>, scene: &Scene) -> Vec<GpuEntry> {
    let disk = scene.entry_disk(archive.entries().len());
    let energy = archive.entry_energy();
    let cells = archive.entry_cells();
    let cell_weight = cells.map_or(0.0, |c| c.point_weight());
    let reach2 = prm_scene::cell_reach2((scene.area() / archive.entries().len().max(1) as f64) as f32);
    archive
        .entries()
        .iter()
        .enumerate()
        .map(|(i, e)| {
            let (first, end) = cells.map_or((0, 0), |c| (if i == 0 { 0 } else { c.ends[i - 1] }, c.ends[i]));
            GpuEntry {
                position: e.position,
                disk: if cells.is_some() { reach2 } else { disk },
                normal: e.normal,
                energy: energy.map_or([1.0; 3], |en| en[i]),
                cell_first: first,
                cell_count: end - first,
                cell_weight,
                ..Default::default()
            }
        })
        .collect()
}

/// The cell points of `archive`'s entry points as the weights pass reads them (prm-format's
/// `CellPoint::packed`); one zero point where it has none, for the binding.
pub(crate) fn gpu_cell_points<R: Read + Seek>(archive: &Archive<R>) -> Vec<[u32; 2]> {
    match archive.entry_cells() {
        Some(c) if !c.points.is_empty() => c.points.iter().map(|p| p.packed()).collect(),
        _ => vec![[0; 2]],
    }
}

/// The archive's clusters with their residual groups `group_of`.
pub(crate) fn gpu_clusters<R: Read + Seek>(archive: &Archive<R>, group_of: &[u32]) -> Vec<GpuCluster> {
    archive
        .clusters()
        .iter()
        .zip(group_of)
        .map(|(c, &group)| GpuCluster {
            first: c.first,
            count: c.count,
            group,
            energy: c.energy,
            ..Default::default()
        })
        .collect()
}

impl Buffers {
    /// The frame's buffers (empty until [`Runtime::update`](crate::Runtime::update)), `clusters`
    /// and `entries` uploaded, and room for the weights, ranks and selection of
    /// `cluster_count` clusters and `group_count` residual groups.
    pub(crate) fn new(
        device: &wgpu::Device,
        clusters: &[GpuCluster],
        entries: &[GpuEntry],
        cell_points: &[[u32; 2]],
        group_count: u32,
    ) -> Buffers {
        let cluster_count = clusters.len() as u32;
        let st = wgpu::BufferUsages::STORAGE;
        let src = wgpu::BufferUsages::COPY_SRC;
        let per_cluster = cluster_count.max(1) as u64 * 16;
        Buffers {
            frame: pipeline::uniform(device, "prm frame", std::mem::size_of::<GpuFrame>() as u64),
            lights: pipeline::storage(
                device,
                "prm lights",
                (MAX_LIGHTS * std::mem::size_of::<GpuLight>()) as u64,
                wgpu::BufferUsages::empty(),
            ),
            views: pipeline::storage(
                device,
                "prm views",
                // At most six views a light (update refuses more, whatever the sun tiles).
                (MAX_LIGHTS * 6 * std::mem::size_of::<GpuView>()) as u64,
                wgpu::BufferUsages::empty(),
            ),
            clusters: pipeline::buffer_init(device, "prm clusters", bytemuck::cast_slice(clusters), st),
            entries: pipeline::buffer_init(
                device,
                "prm entries",
                bytemuck::cast_slice(entries),
                st | wgpu::BufferUsages::COPY_DST,
            ),
            cell_points: pipeline::buffer_init(device, "prm cell points", bytemuck::cast_slice(cell_points), st),
            weights: pipeline::storage(device, "prm weights", per_cluster, src),
            ranks: pipeline::storage(device, "prm ranks", cluster_count.max(1) as u64 * 4, src),
            threshold: pipeline::storage(device, "prm threshold", 16, src),
            selected: pipeline::storage(
                device,
                "prm selected",
                (cluster_count + group_count).max(1) as u64 * 16,
                src,
            ),
            effective: pipeline::storage(device, "prm effective", per_cluster, src),
            group_energy: pipeline::storage(
                device,
                "prm group energy",
                group_count.max(1) as u64 * 16,
                wgpu::BufferUsages::COPY_DST,
            ),
        }
    }
}

/// The panes the mix and blend read: the archive's basis, with the residual groups'
/// coefficients after the clusters' and their energies (the sum of their members' recorded
/// energies) written to `b.group_energy`. Also returns the texels any pane may light.
pub(crate) fn upload_panes<R: Read + Seek>(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    archive: &Archive<R>,
    b: &Buffers,
    group_of: &[u32],
    group_count: u32,
    options: &RuntimeOptions,
) -> Result<(blend::Panes, Vec<bool>), RuntimeError> {
    let basis = archive.pane_basis();
    let panes = blend::Panes::upload(device, basis, group_of, group_count, options.pane_chunk_bytes)?;
    if group_count > 0 {
        let mut group_energy = vec![[0f32; 4]; group_count as usize];
        for (c, &g) in archive.clusters().iter().zip(group_of) {
            let e = &mut group_energy[g as usize];
            (0..3).for_each(|k| e[k] += c.energy[k]);
        }
        queue.write_buffer(&b.group_energy, 0, bytemuck::cast_slice(&group_energy));
    }
    // The texels the blend writes: any pane, the traced indirect light or the near field
    // lights them (the rest of the lightmap stays zero).
    let res = archive.atlas().resolution as usize;
    let mut lit = vec![false; res * res];
    panes.mark_lit(&mut lit);
    Ok((panes, lit))
}

/// The run time's lightmap, `res`² texels of [`LIGHTMAP_FORMAT`], and its view.
pub(crate) fn create_lightmap(device: &wgpu::Device, res: u32) -> (wgpu::Texture, wgpu::TextureView) {
    let lightmap = pipeline::texture(
        device,
        "prm lightmap",
        [res, res, 1],
        LIGHTMAP_FORMAT,
        // COPY_DST: an engine may seed or clear it (and the tests of GiUpdate do).
        wgpu::TextureUsages::STORAGE_BINDING
            | wgpu::TextureUsages::TEXTURE_BINDING
            | wgpu::TextureUsages::COPY_SRC
            | wgpu::TextureUsages::COPY_DST,
    );
    let view = lightmap.create_view(&Default::default());
    (lightmap, view)
}

/// What the near field's and the probes' passes read besides the shared buffers.
pub(crate) struct PassInputs<'a> {
    pub maps: &'a ShadowMaps,
    pub lightmap: &'a wgpu::TextureView,
    pub emitters: &'a baked::BakedLights,
    pub resolution: u32,
}

/// The near lightmap the blend adds (1×1 and unused without a near field) and, when `near` is
/// given, the near field's passes; refused when its hits, exit records or gather points exceed
/// the device's storage binding size.
pub(crate) fn build_near_field(
    device: &wgpu::Device,
    b: &Buffers,
    near: Option<&NearField>,
    inputs: &PassInputs,
    options: &RuntimeOptions,
) -> Result<(wgpu::TextureView, Option<near_field::NearFieldPass>), RuntimeError> {
    let res = inputs.resolution;
    let near_map = pipeline::texture(
        device,
        "prm near lightmap",
        if near.is_some() { [res, res, 1] } else { [1, 1, 1] },
        LIGHTMAP_FORMAT,
        wgpu::TextureUsages::STORAGE_BINDING | wgpu::TextureUsages::TEXTURE_BINDING,
    );
    let near_view = near_map.create_view(&Default::default());
    let Some(n) = near else {
        return Ok((near_view, None));
    };
    let merged = near_field::Merged::new(n);
    check_near_field_size(device, n, &merged)?;
    let pass = near_field::NearFieldPass::new(
        device,
        b,
        n,
        &merged,
        &inputs.maps.array,
        near_field::NearTargets {
            near_map: &near_view,
            lightmap: inputs.lightmap,
            emitted: &inputs.emitters.indirect_view,
            resolution: res,
        },
        near_field::NearSeries {
            gathers: options.near_bounces,
            tail: options.near_tail,
        },
    );
    Ok((near_view, Some(pass)))
}

/// Refuses a near field whose merged hits, exit records or gather points need a storage
/// binding larger than the device's.
fn check_near_field_size(
    device: &wgpu::Device,
    n: &NearField,
    merged: &near_field::Merged,
) -> Result<(), RuntimeError> {
    let limits = device.limits();
    let mib = |b: u64| b as f64 / (1 << 20) as f64;
    for (what, count, size) in [
        ("merged near hits", merged.hits.len(), std::mem::size_of::<GpuNearHit>()),
        (
            "near exit records",
            merged.ends.len(),
            std::mem::size_of::<GpuNearExit>(),
        ),
        (
            "near gather points",
            n.points.len(),
            std::mem::size_of::<GpuGatherPoint>(),
        ),
    ] {
        let bytes = count as u64 * size as u64;
        if bytes > limits.max_storage_buffer_binding_size {
            return Err(RuntimeError::NearField(format!(
                "{count} {what} take {:.1} MiB, over the device's {:.1} MiB storage binding (play with `NearLight::Off`)",
                mib(bytes),
                mib(limits.max_storage_buffer_binding_size)
            )));
        }
    }
    Ok(())
}

/// The near field the options gather, if the archive holds one.
pub(crate) fn gathered_near_field<'a, R: Read + Seek>(
    archive: &'a Archive<R>,
    options: &RuntimeOptions,
) -> Option<&'a NearField> {
    archive.near_field().filter(|_| options.near_light == NearLight::Gather)
}

/// Marks the texels of `near`'s exit records in `lit`: the near field lights them.
pub(crate) fn mark_near_exits(near: Option<&NearField>, lit: &mut [bool]) {
    for x in near.iter().flat_map(|n| &n.exits) {
        if let Some(l) = lit.get_mut(x.texel as usize) {
            *l = true;
        }
    }
}

/// The probes' passes when the archive holds probes (along their rays when it holds them and
/// the options gather them).
pub(crate) fn build_probes<R: Read + Seek>(
    device: &wgpu::Device,
    b: &Buffers,
    archive: &Archive<R>,
    inputs: &PassInputs,
    options: &RuntimeOptions,
) -> Result<Option<probes::ProbesPass>, RuntimeError> {
    let Some(p) = archive.probes() else {
        return Ok(None);
    };
    probes::ProbesPass::new(
        device,
        b,
        p,
        archive.probe_rays().filter(|_| options.probe_light == ProbeLight::Rays),
        probes::RayInputs {
            shadow_maps: &inputs.maps.array,
            lightmap: inputs.lightmap,
            baked_direct: &inputs.emitters.view,
            groups: inputs.emitters.scales.len(),
        },
    )
    .map(Some)
}
