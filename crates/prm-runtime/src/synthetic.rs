//! Synthetic archives for tests, benchmarks and demos until `prm-bake bake` produces real ones:
//! the scene's real atlas, entry points sampled uniformly over its area and grouped into clusters
//! of consecutive triangles, and smooth panes (one unoccluded diffuse bounce from each cluster's
//! centroid, coloured by the cluster's albedo). The lighting is plausible, not physically exact.

use std::path::{Component, Path, PathBuf};

use glam::Vec3;
use prm_format::{ArchiveWriter, AtlasSection, Cluster, Entry, Metadata};
use prm_scene::{Atlas, AtlasParams, Scene, Sizing, EMPTY_TEXEL};

/// What to generate.
#[derive(Clone, Copy, Debug)]
pub struct SyntheticParams {
    /// Atlas resolution.
    pub resolution: u32,
    /// Number of clusters (= panes).
    pub clusters: u32,
    /// Entry points per cluster.
    pub entries_per_cluster: u32,
    /// Random seed.
    pub seed: u64,
}

impl Default for SyntheticParams {
    fn default() -> Self {
        SyntheticParams {
            resolution: 64,
            clusters: 48,
            entries_per_cluster: 16,
            seed: 1,
        }
    }
}

/// SplitMix64.
struct Rng(u64);
impl Rng {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    fn unit(&mut self) -> f32 {
        (self.next() >> 40) as f32 / (1u64 << 24) as f32
    }
}

/// `to` relative to directory `from`, `/`-separated (both made absolute first).
pub fn relative_path(from: &Path, to: &Path) -> String {
    let abs = |p: &Path| std::fs::canonicalize(p).unwrap_or_else(|_| p.to_path_buf());
    let (from, to) = (abs(from), abs(to));
    let f: Vec<Component> = from.components().collect();
    let t: Vec<Component> = to.components().collect();
    let common = f.iter().zip(&t).take_while(|(a, b)| a == b).count();
    let mut parts: Vec<String> = vec!["..".into(); f.len() - common];
    parts.extend(t[common..].iter().map(|c| c.as_os_str().to_string_lossy().into_owned()));
    parts.join("/")
}

/// Writes a synthetic archive for `scene` (loaded from `scene_path`) at `out`.
pub fn write_archive(scene: &Scene, scene_path: &Path, out: &Path, p: SyntheticParams) -> Result<(), String> {
    let atlas =
        Atlas::build(scene, &AtlasParams::with_sizing(Sizing::Resolution(p.resolution))).map_err(|e| e.to_string())?;
    let res = atlas.resolution;
    let tile = [64u32, 32, 16, 8, 4, 2, 1]
        .into_iter()
        .find(|t| res % t == 0 && *t <= res)
        .unwrap_or(1);
    let mut section = AtlasSection::new(res, tile);
    section.triangle_uvs = atlas.uvs.iter().map(|uv| uv.map(|c| c.to_array())).collect();
    for (i, e) in atlas.texel_exit.iter().enumerate() {
        if *e != EMPTY_TEXEL {
            section.set_covered(i as u32 % res, i as u32 / res, true);
        }
    }

    // Entries: area-uniform samples, ordered by triangle, cut into equal clusters.
    let mut rng = Rng(p.seed);
    let areas: Vec<f64> = scene.triangles.iter().map(|t| t.area() as f64).collect();
    let total: f64 = areas.iter().sum();
    let n = (p.clusters * p.entries_per_cluster) as usize;
    let mut samples: Vec<(usize, f32, f32)> = (0..n)
        .map(|_| {
            let mut x = rng.unit() as f64 * total;
            let mut tri = areas.len() - 1;
            for (i, a) in areas.iter().enumerate() {
                if x < *a {
                    tri = i;
                    break;
                }
                x -= a;
            }
            let (mut b1, mut b2) = (rng.unit(), rng.unit());
            if b1 + b2 > 1.0 {
                (b1, b2) = (1.0 - b1, 1.0 - b2);
            }
            (tri, b1, b2)
        })
        .collect();
    samples.sort_by(|a, b| a.0.cmp(&b.0).then(a.1.total_cmp(&b.1)));
    let per = p.entries_per_cluster as usize;
    let mut entries = Vec::with_capacity(n);
    let mut clusters = Vec::new();
    let mut panes_src = Vec::new();
    for (c, chunk) in samples.chunks(per).enumerate() {
        let mut centroid = Vec3::ZERO;
        let mut normal = Vec3::ZERO;
        let mut albedo = Vec3::ZERO;
        for &(tri, b1, b2) in chunk {
            let t = &scene.triangles[tri];
            let pos = t.point(b1, b2);
            let nrm = t.normal();
            centroid += pos;
            normal += nrm;
            albedo += scene.albedo(tri, b1, b2);
            entries.push(Entry {
                position: pos.to_array(),
                normal: nrm.to_array(),
                cluster: c as u32,
            });
        }
        let k = chunk.len() as f32;
        clusters.push(Cluster {
            first: (c * per) as u32,
            count: chunk.len() as u32,
            centroid: (centroid / k).to_array(),
            mean_normal: normal.normalize_or_zero().to_array(),
            energy: [0.0; 3],
            peak: [0.0; 3],
        });
        // Power of the cluster's patch per unit irradiance: albedo × area share.
        let area = (total / n as f64) as f32 * k;
        panes_src.push((centroid / k, normal.normalize_or_zero(), albedo / k * area));
    }

    let mut metadata = Metadata::new("prm-play-synthetic", env!("CARGO_PKG_VERSION"));
    metadata.seed = p.seed;
    metadata.params.insert("synthetic".into(), true.into());
    metadata.params.insert(
        "materials_fingerprint".into(),
        format!("{:016x}", scene.materials_fingerprint()).into(),
    );
    let dir = out.parent().unwrap_or(Path::new("."));
    metadata.source_scene = relative_path(dir, scene_path);
    metadata.scene_fingerprint = scene.fingerprint();
    let mut w = ArchiveWriter::create(out, metadata, &section, &entries, &clusters).map_err(|e| e.to_string())?;
    // Unequal member energies (1, 2, 3, 1, ...), so the player's weighing by them is exercised;
    // they need not match the analytic panes.
    let energy = (0..entries.len()).map(|i| [1.0 + (i % 3) as f32; 3]).collect();
    w.set_entry_energy(energy).map_err(|e| e.to_string())?;
    let soft = (scene.bounds().diagonal() * 0.05).powi(2);
    for (centre, nc, power) in panes_src {
        let mut texels = vec![[0f32; 3]; (res * res) as usize];
        for (i, e) in atlas.texel_exit.iter().enumerate() {
            if *e == EMPTY_TEXEL {
                continue;
            }
            let x = &atlas.exits[*e as usize];
            let d = x.position - centre;
            let r2 = d.length_squared();
            let dn = d / r2.sqrt().max(1e-6);
            let g = (nc.dot(dn).max(0.0) * x.normal.dot(-dn).max(0.0)) / (r2 + soft);
            texels[i] = (power * g / std::f32::consts::PI).to_array();
        }
        for &(dst, src) in &atlas.dilation {
            texels[dst as usize] = texels[src as usize];
        }
        w.add_pane(&texels).map_err(|e| e.to_string())?;
    }
    w.finish().map_err(|e| e.to_string())?;
    Ok(())
}

/// `scenes/cornell-box/cornell-box.gltf` of the workspace this crate lives in.
pub fn cornell_box_path() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes/cornell-box/cornell-box.gltf")
}
