//! The bake's estimate of its own accuracy (`prm_trace::check`), for the bake's last step and
//! for an archive already written ([`estimate_accuracy`]: a merged sharded bake, which carries
//! none, or any archive checked at another size).
//!
//! An archive does not hold everything the check reads: the entry points' triangles and the
//! exit points come from the scene. [`estimate_accuracy`] makes them again as the bake did,
//! from the parameters and seed the archive records (the atlas, the buried exit points, the
//! sampled entry points and their clustering are deterministic), and refuses an archive whose
//! tables they do not reproduce. With the same check parameters it gives the estimate the bake
//! recorded, to the bit (`tests/bake.rs`).

use glam::Vec3;
use prm_format::{Accuracy, Archive, Metadata};
use prm_scene::{Atlas, Scene, Sizing};
use prm_trace::{Bvh, CheckParams, CheckPoints, Clustering, NearPlay, SurfaceSample};
use rayon::prelude::*;
use std::io::{Read, Seek};
use std::path::Path;

use crate::archive::archive_tables;
use crate::params::AtlasSize;
use crate::pipeline::{archive_error, cluster_entries, lightmap_atlas, sample_entries, scene_bvh};
use crate::sink::{Phase, ProgressSink};
use crate::BakeError;

/// What the check reads of a bake besides its panes.
pub(crate) struct CheckInputs<'a> {
    pub scene: &'a Scene,
    pub bvh: &'a Bvh,
    pub atlas: &'a Atlas,
    pub entries: &'a [SurfaceSample],
    /// Every entry point's cell in sampling order (`None`: the archive has none).
    pub cells: Option<&'a prm_format::EntryCells>,
    pub clustering: &'a Clustering,
    /// Every entry's pane energy in sampling order (`None`: the archive has none).
    pub entry_energy: Option<&'a [Vec3]>,
    /// Every pane's energy (the cluster table's).
    pub pane_energy: &'a [Vec3],
    /// The player's residual groups.
    pub groups: &'a [u32],
    pub top_k: usize,
    pub near: Option<&'a NearPlay<'a>>,
}

/// The checked exit points' values of one pane, given at every exit point, as the player
/// shows them: with the near field's series from it (`near`), else as they are.
pub(crate) fn checked_pane(near: Option<&NearPlay>, checked: &[usize], pane: &[Vec3]) -> Vec<Vec3> {
    match near {
        // The near field's series reads the pane far from the checked exit points.
        Some(near) => near.series(pane),
        None => checked.iter().map(|&i| pane[i]).collect(),
    }
}

/// Runs the check on `panes` (every pane at the `checked` exit points, [`checked_pane`]) as the
/// phase [`Phase::AccuracyCheck`] of `progress`, under point lights at `lights` (`None`: the
/// check's own, [`prm_trace::check_lights`]).
pub(crate) fn check(
    inputs: &CheckInputs,
    checked: &CheckPoints,
    panes: &[Vec<Vec3>],
    params: &CheckParams,
    lights: Option<&[Vec3]>,
    progress: &mut dyn ProgressSink,
) -> Result<Accuracy, BakeError> {
    let archive = prm_trace::CheckedArchive {
        points: checked,
        entries: inputs.entries,
        cells: inputs.cells,
        members: &inputs.clustering.members,
        entry_energy: inputs.entry_energy,
        cluster_energy: inputs.pane_energy,
        panes,
        top_k: inputs.top_k,
        groups: inputs.groups,
        fade_band: prm_trace::check::FADE_BAND,
        near: inputs.near,
    };
    let exits: Vec<_> = checked.exits.iter().map(|&i| inputs.atlas.exits[i]).collect();
    let lights = match lights {
        Some(given) => given.to_vec(),
        None => prm_trace::check_lights(inputs.scene, inputs.bvh),
    };
    let passes = prm_trace::check::reference_params(checked, params).passes;
    progress.phase_start(Phase::AccuracyCheck, lights.len() as u64 * u64::from(passes));
    prm_trace::check_accuracy(
        inputs.scene,
        inputs.bvh,
        &exits,
        &archive,
        &lights,
        params,
        &mut |done| progress.phase_advance(done),
    )
    .map_err(|source| BakeError::Trace {
        what: "checking the bake's accuracy",
        source,
    })
}

/// How much [`estimate_accuracy`] measures; its random streams are keyed by the bake's seed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct EstimateSize {
    /// Exit points compared.
    pub exit_points: u32,
    /// Reference paths per exit point and light.
    pub paths: u32,
}

impl EstimateSize {
    /// The bake's own check ([`CheckParams::DEFAULT`]).
    pub const DEFAULT: EstimateSize = EstimateSize {
        exit_points: CheckParams::DEFAULT.exit_points,
        paths: CheckParams::DEFAULT.paths,
    };
}

/// Estimates the accuracy of the archive at `archive_path`, baked from `scene`, at `size`, as
/// the bake's last step does: the estimate of an archive that has none (a merged sharded
/// bake), or of any archive at another size. Under white point lights at `lights`, one at a
/// time, or the check's own (`None`, as the bake). Refuses a partial archive of a sharded bake,
/// another scene's, and one whose tables its recorded parameters do not reproduce.
pub fn estimate_accuracy(
    scene: &Scene,
    archive_path: &Path,
    size: EstimateSize,
    lights: Option<&[Vec3]>,
    progress: &mut dyn ProgressSink,
) -> Result<Accuracy, BakeError> {
    let mut archive =
        Archive::open(archive_path).map_err(archive_error(format!("opening {}", archive_path.display())))?;
    let recorded = Recorded::read(scene, archive_path, archive.metadata(), progress)?;
    let params = CheckParams {
        exit_points: size.exit_points,
        paths: size.paths,
        seed: recorded.seed,
    };
    let remade = Remade::make(scene, &recorded)?;
    if !remade.matches(&archive) {
        return Err(refused(
            archive_path,
            "its atlas, entry points or clusters differ from what its parameters make of this scene (another version of prm-bake?)",
        ));
    }
    let atlas = &remade.atlas;

    let pane_energy: Vec<Vec3> = archive.clusters().iter().map(|c| Vec3::from(c.energy)).collect();
    let order: Vec<u32> = remade.clustering.members.iter().flatten().copied().collect();
    let entry_energy = archive
        .entry_energy()
        .map(|e| in_sampling_order(&order, e, remade.entries.len()));
    let groups = prm_format::residual_groups(
        archive.clusters(),
        prm_format::residual_group_count(archive.clusters().len(), prm_format::RESIDUAL_GROUPS),
    );
    let cells = archive.entry_cells().map(|c| {
        // Archive order back to sampling order: archive entry k is sampled entry order[k].
        let mut inverse = vec![0u32; order.len()];
        for (k, &i) in order.iter().enumerate() {
            inverse[i as usize] = k as u32;
        }
        prm_trace::reorder_cells(c, &inverse)
    });
    let checked = CheckPoints::draw(scene, atlas, params.exit_points, params.seed);
    let near_field = archive.near_field().cloned();
    let near = near_field.as_ref().map(|n| {
        let texels: Vec<u32> = checked.exits.iter().map(|&i| atlas.exits[i].texel).collect();
        NearPlay::new(n, &atlas.texel_exit, &texels, prm_trace::NEAR_GATHERS)
    });
    let panes = read_checked_panes(&mut archive, archive_path, atlas, near.as_ref(), &checked.exits)?;
    let inputs = CheckInputs {
        scene,
        bvh: &remade.bvh,
        atlas,
        entries: &remade.entries,
        cells: cells.as_ref(),
        clustering: &remade.clustering,
        entry_energy: entry_energy.as_deref(),
        pane_energy: &pane_energy,
        groups: &groups,
        top_k: recorded.top_k,
        near: near.as_ref(),
    };
    check(&inputs, &checked, &panes, &params, lights, progress)
}

/// The refusal of the archive at `archive_path`, saying `why`.
fn refused(archive_path: &Path, why: &str) -> BakeError {
    BakeError::InvalidParams(format!("{}: {why}", archive_path.display()))
}

/// What an archive's metadata records of the bake that made it, for making its tables again.
struct Recorded {
    entries: usize,
    clusters: usize,
    top_k: usize,
    sizing: Sizing,
    seed: u64,
}

impl Recorded {
    /// Reads the metadata of the archive at `archive_path`; refuses a shard's partial archive,
    /// another scene's, and metadata without the counts or the atlas size. Warns when the
    /// scene's materials are not those baked.
    fn read(
        scene: &Scene,
        archive_path: &Path,
        meta: &Metadata,
        progress: &mut dyn ProgressSink,
    ) -> Result<Recorded, BakeError> {
        if meta.params.contains_key("shard") {
            return Err(refused(
                archive_path,
                "a shard's partial archive; merge the shards first (prm-bake merge)",
            ));
        }
        if meta.scene_fingerprint != scene.fingerprint() {
            return Err(refused(archive_path, "baked from other geometry than this scene"));
        }
        let found = format!("{:016x}", scene.materials_fingerprint());
        if let Some(baked) = meta.params.get("materials_fingerprint").and_then(|v| v.as_str()) {
            if baked != found {
                progress.warn(&format!(
                    "{}: the scene's materials differ from those the archive was baked with (materials \
                     fingerprint {found}, baked {baked}): the estimate measures the old albedos' indirect \
                     light against the new ones",
                    archive_path.display()
                ));
            }
        }
        let number = |key: &str| meta.params.get(key).and_then(serde_json::Value::as_u64);
        let (Some(entries), Some(clusters), Some(top_k)) = (number("entries"), number("clusters"), number("top_k"))
        else {
            return Err(refused(
                archive_path,
                "its metadata records no entry, cluster or top K count",
            ));
        };
        let sizing = match meta
            .params
            .get("atlas")
            .map(|v| serde_json::from_value::<AtlasSize>(v.clone()))
        {
            Some(Ok(size)) => Sizing::from(size),
            _ => return Err(refused(archive_path, "its metadata records no atlas size")),
        };
        Ok(Recorded {
            entries: entries as usize,
            clusters: clusters as usize,
            top_k: top_k as usize,
            sizing,
            seed: meta.seed,
        })
    }
}

/// What the bake made before its panes, made again from what the archive records.
struct Remade {
    atlas: Atlas,
    bvh: Bvh,
    entries: Vec<SurfaceSample>,
    clustering: Clustering,
}

impl Remade {
    /// The atlas (its buried exit points moved), the BVH, the entry points and their clusters.
    fn make(scene: &Scene, recorded: &Recorded) -> Result<Remade, BakeError> {
        let mut atlas = lightmap_atlas(scene, recorded.sizing)?;
        let bvh = scene_bvh(scene)?;
        prm_trace::unbury_exits(scene, &bvh, &mut atlas);
        let entries = sample_entries(scene, recorded.entries, recorded.seed)?;
        let clustering = cluster_entries(scene, &bvh, &entries, recorded.clusters, recorded.seed)?;
        Ok(Remade {
            atlas,
            bvh,
            entries,
            clustering,
        })
    }

    /// Whether `archive`'s atlas, entry and cluster tables are those made again.
    fn matches<R: Read + Seek>(&self, archive: &Archive<R>) -> bool {
        let (table_entries, table_clusters, atlas_section) =
            archive_tables(&self.atlas, &self.entries, &self.clustering);
        let same_clusters = table_clusters.len() == archive.clusters().len()
            && table_clusters
                .iter()
                .zip(archive.clusters())
                .all(|(a, b)| (a.first, a.count) == (b.first, b.count));
        atlas_section.triangle_uvs == archive.atlas().triangle_uvs
            && atlas_section.coverage == archive.atlas().coverage
            && table_entries == archive.entries()
            && same_clusters
    }
}

/// Every pane of `archive` at the `checked` exit points of `atlas`, as the player shows them
/// ([`checked_pane`]).
fn read_checked_panes<R: Read + Seek>(
    archive: &mut Archive<R>,
    archive_path: &Path,
    atlas: &Atlas,
    near: Option<&NearPlay>,
    checked: &[usize],
) -> Result<Vec<Vec<Vec3>>, BakeError> {
    let mut panes = Vec::with_capacity(archive.pane_count());
    for c in 0..archive.pane_count() {
        let pane = archive
            .read_pane(c)
            .map_err(archive_error(format!("reading a pane of {}", archive_path.display())))?;
        let at_exits: Vec<Vec3> = atlas
            .exits
            .par_iter()
            .map(|e| Vec3::from(pane[e.texel as usize]))
            .collect();
        panes.push(checked_pane(near, checked, &at_exits));
    }
    Ok(panes)
}

/// `energies` in the archive's entry `order` (cluster by cluster), put back in the sampling
/// order of the `count` entry points.
pub(crate) fn in_sampling_order(order: &[u32], energies: &[[f32; 3]], count: usize) -> Vec<Vec3> {
    let mut sampled = vec![Vec3::ZERO; count];
    for (&k, v) in order.iter().zip(energies) {
        sampled[k as usize] = Vec3::from(*v);
    }
    sampled
}
