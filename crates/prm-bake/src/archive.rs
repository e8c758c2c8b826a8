//! What the bake writes besides the panes: the archive's tables and metadata, and the output
//! directories it creates (removed again when it fails).

use prm_format::{AtlasSection, Cluster, Entry, Metadata};
use prm_scene::{Atlas, Scene};
use prm_trace::{Clustering, SurfaceSample};
use std::path::{Path, PathBuf};

use crate::params::BakeParams;
use crate::BakeError;

/// Largest tile size (64 at most) that divides `resolution`.
pub(crate) fn tile_size(resolution: u32) -> u32 {
    [64, 32, 16, 8, 4, 2, 1]
        .into_iter()
        .find(|&t| resolution.is_multiple_of(t))
        .unwrap_or(1)
}

/// The archive's tables: entries in cluster order, cluster ranges over them, and the atlas.
pub(crate) fn archive_tables(
    atlas: &Atlas,
    entries: &[SurfaceSample],
    clustering: &Clustering,
) -> (Vec<Entry>, Vec<Cluster>, AtlasSection) {
    let mut table_entries = Vec::with_capacity(entries.len());
    let mut table_clusters = Vec::with_capacity(clustering.len());
    for (c, members) in clustering.members.iter().enumerate() {
        table_clusters.push(Cluster::new(
            table_entries.len() as u32,
            members.len() as u32,
            clustering.centroids[c].to_array(),
            clustering.normals[c].to_array(),
        ));
        for &k in members {
            let e = &entries[k as usize];
            table_entries.push(Entry {
                position: e.position.to_array(),
                normal: e.normal.to_array(),
                cluster: c as u32,
            });
        }
    }
    let mut atlas_section = AtlasSection::new(atlas.resolution, tile_size(atlas.resolution));
    atlas_section.triangle_uvs = atlas.uvs.iter().map(|t| t.map(|uv| uv.to_array())).collect();
    for e in &atlas.exits {
        atlas_section.set_covered(e.texel % atlas.resolution, e.texel / atlas.resolution, true);
    }
    (table_entries, table_clusters, atlas_section)
}

/// The archive's metadata: seed, fingerprints, the scene's path relative to `out_dir`, the
/// parameters, the atlas statistics and the backend. No timings: the bytes must not change
/// between runs.
pub(crate) fn metadata(
    scene: &Scene,
    scene_path: &Path,
    out_dir: &Path,
    params: &BakeParams,
    atlas: &Atlas,
    backend: &str,
) -> Result<Metadata, BakeError> {
    let mut metadata = Metadata::new("prm-bake", env!("CARGO_PKG_VERSION"));
    metadata.seed = params.seed;
    metadata.scene_fingerprint = scene.fingerprint();
    metadata.source_scene = relative_path(out_dir, scene_path);
    if let serde_json::Value::Object(map) = serde_json::to_value(params).map_err(BakeError::Metadata)? {
        metadata.params = map;
    }
    metadata.params.insert(
        "atlas_stats".into(),
        serde_json::to_value(&atlas.stats).map_err(BakeError::Metadata)?,
    );
    metadata.params.insert("backend".into(), backend.into());
    // The player refuses other geometry (scene_fingerprint) but only warns about other albedos.
    metadata.params.insert(
        "materials_fingerprint".into(),
        format!("{:016x}", scene.materials_fingerprint()).into(),
    );
    Ok(metadata)
}

/// Directories a bake created for its output; those still empty are removed again when the bake
/// fails (the guard drops without [`MadeDirs::keep`]), so a failed bake leaves nothing behind.
pub(crate) struct MadeDirs(Vec<PathBuf>);

impl MadeDirs {
    /// Creates `dir` and its missing ancestors, remembering which were missing.
    pub(crate) fn create(dir: &Path) -> Result<MadeDirs, BakeError> {
        let mut missing = Vec::new();
        let mut d = Some(dir);
        while let Some(p) = d.filter(|p| !p.as_os_str().is_empty() && !p.exists()) {
            missing.push(p.to_path_buf());
            d = p.parent();
        }
        std::fs::create_dir_all(dir).map_err(|source| BakeError::OutputDir {
            path: dir.to_path_buf(),
            source,
        })?;
        Ok(MadeDirs(missing))
    }

    /// The bake succeeded: keep the directories.
    pub(crate) fn keep(mut self) {
        self.0.clear();
    }
}

impl Drop for MadeDirs {
    fn drop(&mut self) {
        // Innermost first; remove_dir refuses non-empty directories.
        for d in &self.0 {
            let _ = std::fs::remove_dir(d);
        }
    }
}

/// `to` relative to directory `from`, with `/` separators (absolute when they share no root).
pub(crate) fn relative_path(from: &Path, to: &Path) -> String {
    let (Ok(from), Ok(to)) = (from.canonicalize(), to.canonicalize()) else {
        return to.to_string_lossy().replace('\\', "/");
    };
    let (f, t): (Vec<_>, Vec<_>) = (from.components().collect(), to.components().collect());
    let common = f.iter().zip(&t).take_while(|(a, b)| a == b).count();
    if common == 0 {
        return to.to_string_lossy().replace('\\', "/");
    }
    let mut parts: Vec<String> = std::iter::repeat_n("..".to_string(), f.len() - common).collect();
    parts.extend(t[common..].iter().map(|c| c.as_os_str().to_string_lossy().into_owned()));
    parts.join("/")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn relative_paths() {
        let dir = std::env::temp_dir().join("prm-relpath-test/a/b");
        std::fs::create_dir_all(&dir).unwrap();
        let target = std::env::temp_dir().join("prm-relpath-test/c.obj");
        std::fs::write(&target, "").unwrap();
        assert_eq!(relative_path(&dir, &target), "../../c.obj");
    }

    #[test]
    fn tile_sizes_divide() {
        assert_eq!(tile_size(256), 64);
        assert_eq!(tile_size(96), 32);
        assert_eq!(tile_size(200), 8);
        assert_eq!(tile_size(7), 1);
    }
}
