//! Sharded bakes: the slice of clusters one shard renders ([`Shard`]), and [`merge`], which joins
//! the partial archives into the archive a single bake writes.
//!
//! Every shard runs the whole bake up to the panes (atlas, entry points, walks and clustering are
//! deterministic and cost seconds), then renders only the VPLs of its own clusters: cluster `c`
//! belongs to shard `c mod N`, which spreads large and small clusters evenly. A partial archive
//! is a valid `.prm` file whose other panes and entry energies are zero and whose
//! `params.shard` says `{ "index": I, "count": N }`; the player refuses it.
//!
//! With the CPU renderers (`cpu`, `cpu-exact`) a cluster's pane and its members' energies do
//! not depend on which other VPLs are rendered (each exit point sums a cluster's VPLs in the same
//! order, and shared visibility is decided per VPL), so the merged archive is byte for byte the
//! single bake's. A GPU renders VPLs in batches whose composition changes with the shard, so
//! there the merged panes agree with a single bake's to float rounding, not bit for bit.

use prm_format::{Archive, ArchiveWriter, Cluster, Metadata};
use std::fs::File;
use std::io::{BufReader, Read, Seek};
use std::path::{Path, PathBuf};

use crate::archive::relative_path;
use crate::pipeline::archive_error;
use crate::BakeError;

/// One slice of a bake's clusters: `index` of `count`, as `--shard I/N` writes it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Shard {
    /// Which slice, `0..count`.
    pub index: u32,
    /// How many slices.
    pub count: u32,
}

/// Private section of a shard's partial archive: its own clusters' panes, exactly as the whole
/// bake would compress them (RGB9E5 words, `R²` per pane, in cluster order), so that `merge`
/// compresses the same panes and writes the single bake's bytes. The partial archive's panes
/// section holds zero panes.
pub(crate) const SHARD_PANES: u32 = 0x8000_5052;

impl Shard {
    /// Whether cluster `cluster` is rendered by this shard.
    pub fn owns(&self, cluster: usize) -> bool {
        cluster % self.count as usize == self.index as usize
    }

    /// What the archive's `params.shard` records.
    pub(crate) fn to_json(self) -> serde_json::Value {
        serde_json::json!({ "index": self.index, "count": self.count })
    }

    /// The shard an archive's metadata records (`params.shard`), if it is a partial archive; an
    /// error says what is wrong with a malformed record.
    pub fn of(metadata: &Metadata) -> Option<Result<Shard, String>> {
        let v = metadata.params.get("shard")?;
        let field = |k: &str| v.get(k).and_then(|x| x.as_u64()).and_then(|x| u32::try_from(x).ok());
        Some(match (field("index"), field("count")) {
            (Some(index), Some(count)) if index < count => Ok(Shard { index, count }),
            _ => Err(format!("params.shard is not {{ index < count }}: {v}")),
        })
    }
}

impl std::fmt::Display for Shard {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}/{}", self.index, self.count)
    }
}

impl std::str::FromStr for Shard {
    type Err = String;

    /// `I/N` with `0 ≤ I < N` and `N ≥ 2`.
    fn from_str(s: &str) -> Result<Shard, String> {
        let (i, n) = s
            .split_once('/')
            .ok_or_else(|| format!("`{s}`: a shard is I/N, e.g. 0/4 (the first of four)"))?;
        let parse = |x: &str| {
            x.trim()
                .parse::<u32>()
                .map_err(|_| format!("`{s}`: `{x}` is not a whole number"))
        };
        let (index, count) = (parse(i)?, parse(n)?);
        if count == 0 || index >= count {
            return Err(format!("`{s}`: the index must be 0 to N-1 (shards are counted from 0)"));
        }
        if count == 1 {
            return Err(format!("`{s}`: one shard is the whole bake; leave out --shard"));
        }
        Ok(Shard { index, count })
    }
}

/// What [`merge`] wrote.
#[derive(Clone, Debug)]
pub struct Merged {
    /// Shards joined.
    pub shards: u32,
    /// Panes written.
    pub panes: usize,
    /// Size of the archive, bytes.
    pub archive_bytes: u64,
}

/// The first difference between two parts' metadata (other than their shard), as "what: a in
/// X, b in Y".
fn metadata_difference(a: &Metadata, b: &Metadata) -> Option<String> {
    if a.generator.name != b.generator.name || a.generator.version != b.generator.version {
        return Some(format!(
            "the generator: {} {} against {} {}",
            a.generator.name, a.generator.version, b.generator.name, b.generator.version
        ));
    }
    if a.scene_fingerprint != b.scene_fingerprint {
        return Some(format!(
            "the scene (fingerprint {:016x} against {:016x})",
            a.scene_fingerprint, b.scene_fingerprint
        ));
    }
    if a.seed != b.seed {
        return Some(format!("the seed: {} against {}", a.seed, b.seed));
    }
    let keys: std::collections::BTreeSet<&String> = a.params.keys().chain(b.params.keys()).collect();
    for k in keys.into_iter().filter(|k| *k != "shard") {
        let (x, y) = (a.params.get(k), b.params.get(k));
        if x != y {
            let show = |v: Option<&serde_json::Value>| v.map_or("absent".to_string(), |v| v.to_string());
            return Some(format!("the parameter `{k}`: {} against {}", show(x), show(y)));
        }
    }
    None
}

/// Whether two parts' cluster tables are one clustering: the same members, centroids and normals
/// (each part's pane energies and peaks are of its own panes only).
fn same_clusters(a: &[Cluster], b: &[Cluster]) -> bool {
    a.len() == b.len()
        && a.iter().zip(b).all(|(x, y)| {
            (x.first, x.count, x.centroid, x.mean_normal) == (y.first, y.count, y.centroid, y.mean_normal)
        })
}

/// Joins the partial archives `parts` (one per shard of one bake, in any order) into `output`,
/// written atomically like a bake. Refuses parts that are not shards, a missing or repeated
/// shard, and parts of different scenes, seeds, parameters or renderers, saying which.
pub fn merge(parts: &[PathBuf], output: &Path) -> Result<Merged, BakeError> {
    merge_recording(parts, output, None)
}

/// [`merge`], then the bake's accuracy check of the merged archive against `scene` (the scene
/// the parts were baked from; [`crate::estimate_accuracy`] at the bake's own size), recorded in
/// it as a single bake records it: the archive is written twice, the second time with the
/// estimate. The result is the single bake's archive, estimate included, byte for byte (CPU
/// shards).
pub fn merge_checked(
    parts: &[PathBuf],
    output: &Path,
    scene: &prm_scene::Scene,
    progress: &mut dyn crate::ProgressSink,
) -> Result<(Merged, prm_format::Accuracy), BakeError> {
    // The scene first: a part of another scene is refused before anything is written.
    if let Some(first) = parts.first() {
        let part = Archive::open(first).map_err(archive_error(format!("opening {}", first.display())))?;
        if part.metadata().scene_fingerprint != scene.fingerprint() {
            return Err(BakeError::InvalidParams(format!(
                "{}: baked from other geometry than {}",
                first.display(),
                scene.source.display()
            )));
        }
    }
    // The unchecked merge is checked beside the output, under a temporary name, so that a
    // failed check leaves the output as it was.
    let scratch = Scratch(prm_format::scratch_path(output));
    merge_recording(parts, &scratch.0, None)?;
    let accuracy = crate::estimate_accuracy(scene, &scratch.0, crate::EstimateSize::DEFAULT, None, progress)?;
    accuracy
        .validate()
        .map_err(|e| BakeError::InvalidParams(format!("no estimate of {}: {e}", output.display())))?;
    drop(scratch);
    let merged = merge_recording(parts, output, Some(accuracy.clone()))?;
    Ok((merged, accuracy))
}

/// A file removed when dropped.
struct Scratch(PathBuf);

impl Drop for Scratch {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.0);
    }
}

/// [`merge`] with `accuracy` as the merged archive's estimate.
fn merge_recording(
    parts: &[PathBuf],
    output: &Path,
    accuracy: Option<prm_format::Accuracy>,
) -> Result<Merged, BakeError> {
    let destination = prm_scene::check_destination(output).map_err(BakeError::Destination)?;
    let mut opened = open_parts(parts, output, &destination)?;
    let owners = shard_owners(&opened)?;
    let owner = |c: usize| owners[c % owners.len()];

    let out_dir = destination
        .parent()
        .filter(|d| !d.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    let first = &opened[0];
    let metadata = merged_metadata(first, accuracy, out_dir);
    let atlas = first.archive.atlas().clone();
    let entries = first.archive.entries().to_vec();
    // The writer computes every cluster's pane energy and peak again.
    let clusters: Vec<Cluster> = first
        .archive
        .clusters()
        .iter()
        .map(|c| Cluster::new(c.first, c.count, c.centroid, c.mean_normal))
        .collect();
    let made = crate::archive::MadeDirs::create(out_dir)?;
    let mut writer = ArchiveWriter::create(output, metadata, &atlas, &entries, &clusters)
        .map_err(archive_error(format!("starting {}", output.display())))?;
    // Entry energies: each entry's from the shard of its cluster.
    let energies: Option<Vec<[f32; 3]>> = entries
        .iter()
        .enumerate()
        .map(|(i, e)| opened[owner(e.cluster as usize)].archive.entry_energy().map(|en| en[i]))
        .collect();
    if let Some(energy) = energies {
        writer
            .set_entry_energy(energy)
            .map_err(archive_error("recording the entry energies"))?;
    }
    copy_shared_sections(&first.archive, &mut writer)?;
    merge_probes(&opened, owner, clusters.len(), &mut writer)?;
    let texels = (atlas.resolution as usize).pow(2);
    let mut shard_panes: Vec<Vec<u32>> = Vec::with_capacity(opened.len());
    for part in &mut opened {
        shard_panes.push(read_shard_panes(part, texels)?);
    }
    for c in 0..clusters.len() {
        let words = &shard_panes[owner(c)][(c / owners.len()) * texels..][..texels];
        writer
            .add_pane(&prm_format::decode_rgb9e5_slice(words))
            .map_err(archive_error("writing a pane"))?;
    }
    let archive_bytes = writer
        .finish()
        .map_err(archive_error(format!("finishing {}", output.display())))?;
    made.keep();
    Ok(Merged {
        shards: owners.len() as u32,
        panes: clusters.len(),
        archive_bytes,
    })
}

/// The panes a part rendered ([`SHARD_PANES`]): `texels` words per pane it owns.
fn read_shard_panes(part: &mut Part<'_>, texels: usize) -> Result<Vec<u32>, BakeError> {
    let bytes = part
        .archive
        .read_custom_section(SHARD_PANES)
        .map_err(archive_error(format!("reading the panes of {}", part.path.display())))?
        .unwrap_or_default();
    let clusters = part.archive.pane_count();
    let owned = (0..clusters).filter(|&c| part.shard.owns(c)).count();
    if bytes.len() != owned * texels * 4 {
        return Err(invalid(format!(
            "{} holds {} bytes of its shard's panes, not the {} of {owned} panes: not a part of this version of prm-bake",
            part.path.display(),
            bytes.len(),
            owned * texels * 4
        )));
    }
    Ok(bytes
        .chunks_exact(4)
        .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .collect())
}

/// A partial archive of a sharded bake.
struct Part<'p> {
    path: &'p Path,
    shard: Shard,
    archive: Archive<BufReader<File>>,
}

/// Opens the parts and reads their shards; refuses no parts, an output that is one of them
/// (`destination` is the output's checked path), and a whole archive.
fn open_parts<'p>(parts: &'p [PathBuf], output: &Path, destination: &Path) -> Result<Vec<Part<'p>>, BakeError> {
    if parts.is_empty() {
        return Err(invalid("no parts to merge".to_string()));
    }
    if let Some(p) = parts.iter().find(|p| prm_scene::same_destination(p, destination)) {
        return Err(invalid(format!(
            "the output {} is the part {}: name another file",
            output.display(),
            p.display()
        )));
    }
    let mut opened = Vec::with_capacity(parts.len());
    for p in parts {
        let archive = Archive::open(p).map_err(archive_error(format!("opening {}", p.display())))?;
        let shard = match Shard::of(archive.metadata()) {
            None => {
                return Err(invalid(format!(
                    "{} is a whole archive, not a shard of a bake (bake the parts with --shard I/N)",
                    p.display()
                )))
            }
            Some(Err(e)) => return Err(invalid(format!("{}: {e}", p.display()))),
            Some(Ok(s)) => s,
        };
        opened.push(Part {
            path: p,
            shard,
            archive,
        });
    }
    Ok(opened)
}

/// The part of each shard index, once the parts are found to be every shard of one bake once:
/// the same shard count, metadata (but the shard), entry points, clusters and atlas.
fn shard_owners(opened: &[Part<'_>]) -> Result<Vec<usize>, BakeError> {
    let first = &opened[0];
    let (p0, a0) = (first.path, &first.archive);
    let count = first.shard.count;
    let mut by_index: Vec<Option<usize>> = vec![None; count as usize];
    for (
        k,
        Part {
            path: p,
            shard,
            archive: a,
        },
    ) in opened.iter().enumerate()
    {
        if shard.count != count {
            return Err(invalid(format!(
                "{} is shard {shard} but {} is of {count} shards",
                p.display(),
                p0.display()
            )));
        }
        if let Some(diff) = metadata_difference(a0.metadata(), a.metadata()) {
            return Err(invalid(format!(
                "{} and {} are parts of different bakes: they differ in {diff}",
                p0.display(),
                p.display()
            )));
        }
        if a.entries() != a0.entries() || !same_clusters(a.clusters(), a0.clusters()) || a.atlas() != a0.atlas() {
            return Err(invalid(format!(
                "{} and {} have the same parameters but different entry points, clusters or atlas",
                p0.display(),
                p.display()
            )));
        }
        if let Some(other) = by_index[shard.index as usize].replace(k) {
            return Err(invalid(format!(
                "shard {shard} is given twice: {} and {}",
                opened[other].path.display(),
                p.display()
            )));
        }
    }
    if let Some(missing) = by_index.iter().position(Option::is_none) {
        return Err(invalid(format!(
            "shard {missing}/{count} is missing: pass all {count} parts"
        )));
    }
    Ok(by_index.into_iter().flatten().collect())
}

/// The single bake's metadata, from the `first` part's: no shard, `accuracy` as its estimate (a
/// shard never checks its accuracy; the merged archive is checked as one, or not at all), and
/// the scene's path relative to `out_dir`.
fn merged_metadata(first: &Part<'_>, accuracy: Option<prm_format::Accuracy>, out_dir: &Path) -> Metadata {
    let mut metadata = first.archive.metadata().clone();
    metadata.params.remove("shard");
    metadata.accuracy = accuracy;
    let part_dir = std::fs::canonicalize(first.path)
        .ok()
        .and_then(|p| p.parent().map(Path::to_path_buf))
        .unwrap_or_default();
    let scene = part_dir.join(&metadata.source_scene);
    if scene.exists() {
        metadata.source_scene = relative_path(out_dir, &scene);
    }
    metadata
}

/// Copies the sections every shard computes the same from the `first` part: the emitters, the
/// sky and the near field.
fn copy_shared_sections<R: Read + Seek>(first: &Archive<R>, writer: &mut ArchiveWriter) -> Result<(), BakeError> {
    if !first.emitters().is_empty() {
        writer
            .set_emitters(first.emitters().to_vec())
            .map_err(archive_error("recording the emitters"))?;
    }
    if let Some(sky) = first.sky() {
        writer
            .set_sky(sky.clone())
            .map_err(archive_error("recording the sky"))?;
    }
    if let Some(cells) = first.entry_cells() {
        writer
            .set_entry_cells(cells.clone())
            .map_err(archive_error("merging the entry cells"))?;
    }
    if let Some(near) = first.near_field() {
        writer
            .set_near_field(near.clone())
            .map_err(archive_error("recording the near field"))?;
    }
    Ok(())
}

/// The probes: every shard places the same ones and traces the same rays from them; each of the
/// `clusters` clusters' transfer comes from its `owner`'s part.
fn merge_probes(
    opened: &[Part<'_>],
    owner: impl Fn(usize) -> usize,
    clusters: usize,
    writer: &mut ArchiveWriter,
) -> Result<(), BakeError> {
    let first = &opened[0];
    let Some(probes) = first.archive.probes() else {
        return Ok(());
    };
    let n = probes.len();
    let mut merged = probes.clone();
    for c in 0..clusters {
        let part = &opened[owner(c)];
        let Some(own) = part
            .archive
            .probes()
            .filter(|q| q.len() == n && q.cells == probes.cells)
        else {
            return Err(invalid(format!(
                "{} has no probes or other ones than {}",
                part.path.display(),
                first.path.display()
            )));
        };
        merged.transfer[c * n..(c + 1) * n].copy_from_slice(&own.transfer[c * n..(c + 1) * n]);
    }
    writer
        .set_probes(merged)
        .map_err(archive_error("recording the probes"))?;
    if let Some(rays) = first.archive.probe_rays() {
        writer
            .set_probe_rays(rays.clone())
            .map_err(archive_error("recording the probe rays"))?;
    }
    Ok(())
}

/// A merge refused: [`BakeError::InvalidParams`] with `message`.
fn invalid(message: String) -> BakeError {
    BakeError::InvalidParams(message)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The merge re-serialises a part's parameters; without serde_json's `float_roundtrip` this
    /// value (a plan's estimate that broke the byte-identity test) parsed one ulp off.
    #[test]
    fn metadata_floats_survive_a_round_trip() {
        let x = 0.015381595018662361f64;
        let text = serde_json::to_string(&x).unwrap();
        assert_eq!(
            serde_json::from_str::<f64>(&text).unwrap().to_bits(),
            x.to_bits(),
            "{text}"
        );
    }

    #[test]
    fn shards_parse_and_own_every_cluster_once() {
        let s: Shard = "1/3".parse().unwrap();
        assert_eq!(s, Shard { index: 1, count: 3 });
        assert_eq!(s.to_string(), "1/3");
        for bad in ["3/3", "1", "a/2", "0/0", "-1/2", "1/2/3"] {
            assert!(bad.parse::<Shard>().is_err(), "{bad} accepted");
        }
        for c in 0..10 {
            let owners = (0..3).filter(|&i| Shard { index: i, count: 3 }.owns(c)).count();
            assert_eq!(owners, 1, "cluster {c}");
        }
    }
}
