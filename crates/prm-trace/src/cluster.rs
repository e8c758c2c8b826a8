//! Clustering entry points by position and normal (k-means++ seeding, then Lloyd iterations).
//!
//! Feature of an entry point: `((p − min)/D, w·n)` where `D` is the scene's bounding-box diagonal
//! (scale independence) and `w` = [`ClusterParams::normal_weight`]; squared Euclidean distance.
//! With `w = 0.3` two points with perpendicular normals are as far apart as two points 0.42·D
//! apart, so clusters do not straddle corners unless they are very coarse. Seeding and iteration
//! are deterministic for a seed (assignment runs in parallel but is per point; centroid sums are
//! sequential). Clusters left empty are dropped, so there can be fewer than asked.
//!
//! A cluster's pane is the sum of its members' panes and its run-time weight their direct
//! irradiances weighed by their pane energies ([`Clustering::weights_by_energy`]; the paper's
//! plain mean is [`Clustering::weights`]). Measured with exact visibility on McGuire's
//! CornellBox-Original, a light 0.26 under the ceiling (`cargo xtask eval experiment cluster_weights`, lightmap
//! space, 1024 entries in 64 clusters): unclustered 12.4% error, energy 0.97; the mean 21.8%,
//! 0.82; weighed by energy 11.8%, 0.97.

use glam::Vec3;
use prm_scene::Light;
use rayon::prelude::*;

use crate::rng::Rng;
use crate::Bvh;

/// Medoids an entry point that cannot see its own tries, nearest first.
pub const VISIBILITY_CANDIDATES: usize = 16;
use crate::sampling::SurfaceSample;
use crate::TraceError;

/// k-means parameters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ClusterParams {
    /// Number of clusters `C` (at most; `C ≥ N` gives one cluster per entry point).
    pub clusters: usize,
    /// Weight of the unit normal against diagonal-normalised positions.
    pub normal_weight: f32,
    /// Lloyd iterations after seeding.
    pub iterations: u32,
    /// Seed of the k-means++ draws.
    pub seed: u64,
}

impl ClusterParams {
    /// 256 clusters (the paper's figure for 4096 entry points), 20 iterations.
    pub const PAPER: ClusterParams = ClusterParams {
        clusters: 256,
        normal_weight: 0.3,
        iterations: 20,
        seed: 0,
    };

    /// The paper's settings with `clusters` clusters.
    pub fn with_clusters(clusters: usize) -> Self {
        ClusterParams {
            clusters,
            ..Self::PAPER
        }
    }
}

impl Default for ClusterParams {
    fn default() -> Self {
        Self::PAPER
    }
}

/// Entry points grouped into clusters.
#[derive(Clone, Debug, PartialEq)]
pub struct Clustering {
    /// Cluster of every entry point.
    pub of_entry: Vec<u32>,
    /// Mean position of every cluster's members.
    pub centroids: Vec<Vec3>,
    /// Normalised mean normal of every cluster's members (zero if they cancel).
    pub normals: Vec<Vec3>,
    /// Entry points of every cluster, ascending.
    pub members: Vec<Vec<u32>>,
}

impl Clustering {
    /// One cluster per entry point (no clustering).
    pub fn identity(entries: &[SurfaceSample]) -> Clustering {
        Clustering {
            of_entry: (0..entries.len() as u32).collect(),
            centroids: entries.iter().map(|e| e.position).collect(),
            normals: entries.iter().map(|e| e.normal).collect(),
            members: (0..entries.len() as u32).map(|k| vec![k]).collect(),
        }
    }

    /// The clustering of a bake: [`Clustering::kmeans`] with [`ClusterParams::with_clusters`]
    /// and `seed`, then [`Clustering::separate_by_visibility`].
    pub fn kmeans_separated(
        entries: &[SurfaceSample],
        bvh: &Bvh,
        diagonal: f32,
        clusters: usize,
        seed: u64,
    ) -> Result<Clustering, TraceError> {
        let params = ClusterParams {
            seed,
            ..ClusterParams::with_clusters(clusters)
        };
        Ok(Clustering::kmeans(entries, diagonal, &params)?.separate_by_visibility(entries, bvh))
    }

    /// k-means++ clustering of `entries`; `diagonal` is the scene's bounding-box diagonal.
    pub fn kmeans(entries: &[SurfaceSample], diagonal: f32, params: &ClusterParams) -> Result<Clustering, TraceError> {
        if params.clusters == 0 {
            return Err(TraceError::InvalidParameter("cluster count must be positive".into()));
        }
        if diagonal.is_nan() || diagonal <= 0.0 || params.normal_weight.is_nan() || params.normal_weight < 0.0 {
            return Err(TraceError::InvalidParameter(format!(
                "diagonal {diagonal} must be positive and normal weight {} non-negative",
                params.normal_weight
            )));
        }
        if params.clusters >= entries.len() {
            return Ok(Self::identity(entries));
        }
        let min = entries.iter().fold(Vec3::INFINITY, |m, e| m.min(e.position));
        let feats: Vec<[Vec3; 2]> = entries
            .iter()
            .map(|e| [(e.position - min) / diagonal, e.normal * params.normal_weight])
            .collect();
        let dist = |a: &[Vec3; 2], b: &[Vec3; 2]| (a[0] - b[0]).length_squared() + (a[1] - b[1]).length_squared();

        // k-means++ seeding.
        let mut rng = Rng::new(params.seed, 0xC1u64, entries.len() as u64);
        let n = entries.len();
        let mut centres = vec![feats[(rng.next_u32() as usize) % n]];
        let mut d2: Vec<f32> = feats.iter().map(|f| dist(f, &centres[0])).collect();
        while centres.len() < params.clusters {
            let total: f64 = d2.iter().map(|&d| d as f64).sum();
            let pick = if total > 0.0 {
                let target = rng.next_f32() as f64 * total;
                let mut acc = 0.0;
                let mut chosen = n - 1;
                for (i, &d) in d2.iter().enumerate() {
                    acc += d as f64;
                    if acc > target {
                        chosen = i;
                        break;
                    }
                }
                chosen
            } else {
                (rng.next_u32() as usize) % n
            };
            let c = feats[pick];
            for (d, f) in d2.iter_mut().zip(&feats) {
                *d = d.min(dist(f, &c));
            }
            centres.push(c);
        }

        // Lloyd iterations.
        let assign = |centres: &[[Vec3; 2]]| -> Vec<u32> {
            feats
                .par_iter()
                .map(|f| {
                    let mut best = (f32::INFINITY, 0u32);
                    for (j, c) in centres.iter().enumerate() {
                        let d = dist(f, c);
                        if d < best.0 {
                            best = (d, j as u32);
                        }
                    }
                    best.1
                })
                .collect()
        };
        let mut labels = assign(&centres);
        for _ in 0..params.iterations {
            let mut sums = vec![[Vec3::ZERO; 2]; centres.len()];
            let mut counts = vec![0u32; centres.len()];
            for (f, &l) in feats.iter().zip(&labels) {
                sums[l as usize][0] += f[0];
                sums[l as usize][1] += f[1];
                counts[l as usize] += 1;
            }
            for ((c, s), &k) in centres.iter_mut().zip(&sums).zip(&counts) {
                if k > 0 {
                    *c = [s[0] / k as f32, s[1] / k as f32];
                }
            }
            let next = assign(&centres);
            if next == labels {
                break;
            }
            labels = next;
        }

        Ok(Self::from_labels(entries, &labels))
    }

    /// Clusters from one label per entry point: empty ones dropped, renumbered in order of first
    /// member, centroids and mean normals recomputed.
    pub fn from_labels(entries: &[SurfaceSample], labels: &[u32]) -> Clustering {
        let mut remap = vec![u32::MAX; labels.iter().max().map_or(0, |&l| l as usize + 1)];
        let mut members: Vec<Vec<u32>> = Vec::new();
        for (k, &l) in labels.iter().enumerate() {
            if remap[l as usize] == u32::MAX {
                remap[l as usize] = members.len() as u32;
                members.push(Vec::new());
            }
            members[remap[l as usize] as usize].push(k as u32);
        }
        let of_entry = labels.iter().map(|&l| remap[l as usize]).collect();
        let centroids = members
            .iter()
            .map(|m| m.iter().map(|&k| entries[k as usize].position).sum::<Vec3>() / m.len() as f32)
            .collect();
        let normals = members
            .iter()
            .map(|m| {
                m.iter()
                    .map(|&k| entries[k as usize].normal)
                    .sum::<Vec3>()
                    .normalize_or_zero()
            })
            .collect();
        Clustering {
            of_entry,
            centroids,
            normals,
            members,
        }
    }

    /// Moves every entry point that cannot see its cluster's medoid (the member nearest the
    /// centroid) to the nearest cluster, by position, whose medoid it sees.
    ///
    /// k-means knows positions and normals, not walls: two floors on either side of a thin wall
    /// land in one cluster, whose weight then averages lit and unlit rooms and lights the dark
    /// room through the pane of the other side (on `two-rooms-closed`, 1.3% of the lit room's
    /// indirect light reached the shut room this way). An entry that sees none of the nearest
    /// [`VISIBILITY_CANDIDATES`] medoids stays where it is. Deterministic; one ray per entry
    /// point, a few more for those that move.
    pub fn separate_by_visibility(self, entries: &[SurfaceSample], bvh: &Bvh) -> Clustering {
        let medoids: Vec<usize> = self
            .members
            .iter()
            .zip(&self.centroids)
            .map(|(m, c)| {
                let nearest = m.iter().min_by(|&&a, &&b| {
                    let da = entries[a as usize].position.distance_squared(*c);
                    let db = entries[b as usize].position.distance_squared(*c);
                    da.total_cmp(&db).then(a.cmp(&b))
                });
                *nearest.expect("clusters are never empty") as usize
            })
            .collect();
        let sees = |k: usize, m: usize| {
            let (a, b) = (&entries[k], &entries[m]);
            k == m || bvh.visible(a.position, a.normal, a.triangle, b.position, b.normal, b.triangle)
        };
        let labels: Vec<u32> = (0..entries.len())
            .into_par_iter()
            .map(|k| {
                let own = self.of_entry[k];
                if sees(k, medoids[own as usize]) {
                    return own;
                }
                let p = entries[k].position;
                let n = entries[k].normal;
                let mut candidates: Vec<(f32, u32)> = medoids
                    .iter()
                    .enumerate()
                    .filter(|&(c, &m)| c as u32 != own && entries[m].normal.dot(n) > 0.5)
                    .map(|(c, &m)| (entries[m].position.distance_squared(p), c as u32))
                    .collect();
                candidates.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
                candidates
                    .iter()
                    .take(VISIBILITY_CANDIDATES)
                    .find(|&&(_, c)| sees(k, medoids[c as usize]))
                    .map_or(own, |&(_, c)| c)
            })
            .collect();
        Self::from_labels(entries, &labels)
    }

    /// Number of clusters.
    pub fn len(&self) -> usize {
        self.members.len()
    }

    /// Whether there are no clusters.
    pub fn is_empty(&self) -> bool {
        self.members.is_empty()
    }

    /// Weight of every cluster as the paper takes it: the mean of its members' direct irradiance.
    pub fn weights(&self, entry_irradiance: &[Vec3]) -> Vec<Vec3> {
        self.members
            .iter()
            .map(|m| m.iter().map(|&k| entry_irradiance[k as usize]).sum::<Vec3>() / m.len().max(1) as f32)
            .collect()
    }

    /// Run-time weight of every cluster as the player takes it: its members' direct irradiance
    /// weighed by their pane energy `e_i` ([`crate::Panes::entry_energy`]), per channel
    /// `Σ E_i e_i / Σ e_i`. With the cluster's pane `Σ_i P_i`, of energy `Σ e_i`, the cluster
    /// then gives exactly the indirect energy `Σ E_i e_i` its members give unclustered; the mean
    /// loses energy when `E_i` and `e_i` vary together (a light near a surface lights the
    /// members in the open, whose walks carry more energy, more than those near a corner).
    pub fn weights_by_energy(&self, entry_irradiance: &[Vec3], entry_energy: &[Vec3]) -> Vec<Vec3> {
        self.members
            .iter()
            .map(|m| energy_weight(m.iter().map(|&k| k as usize), entry_irradiance, entry_energy))
            .collect()
    }
}

/// One cluster's weight as [`Clustering::weights_by_energy`] takes it, from its `members`'
/// indices into `entry_irradiance` and `entry_energy`: `Σ E_i e_i / Σ e_i` per channel (0 where
/// the members carry no energy). For clusters that come from elsewhere, such as an archive's
/// cluster table.
pub fn energy_weight(
    members: impl IntoIterator<Item = usize>,
    entry_irradiance: &[Vec3],
    entry_energy: &[Vec3],
) -> Vec3 {
    let (mut num, mut den) = (Vec3::ZERO, Vec3::ZERO);
    for k in members {
        num += entry_irradiance[k] * entry_energy[k];
        den += entry_energy[k];
    }
    Vec3::select(den.cmpgt(Vec3::ZERO), num / den, Vec3::ZERO)
}

/// Every cluster of an archive weighed as the player weighs it under `lights`: each entry
/// point's irradiance from its cell where the archive has `cells` ([`crate::cell_irradiance`]),
/// else its own bounded by the entry disk of radius² `disk` ([`crate::bounded_irradiance`]),
/// then [`energy_weight`] over each cluster's members with the entries' pane energies
/// `entry_energy`.
pub fn archive_weights(
    bvh: &Bvh,
    lights: &[Light],
    entries: &[prm_format::Entry],
    entry_energy: &[Vec3],
    clusters: &[prm_format::Cluster],
    disk: f32,
    cells: Option<&prm_format::EntryCells>,
) -> Vec<Vec3> {
    let irradiance: Vec<Vec3> = match cells {
        Some(cells) => {
            let positions: Vec<Vec3> = entries.iter().map(|e| Vec3::from(e.position)).collect();
            let normals: Vec<Vec3> = entries.iter().map(|e| Vec3::from(e.normal)).collect();
            // `disk` is ENTRY_DISK · A/(Nπ).
            let reach2 = crate::cell_reach2(disk / prm_scene::ENTRY_DISK * std::f32::consts::PI);
            crate::cell_irradiance(bvh, lights, &positions, &normals, cells, reach2)
        }
        None => entries
            .par_iter()
            .map(|en| {
                let (p, n) = (Vec3::from(en.position), Vec3::from(en.normal));
                crate::bounded_irradiance(bvh, lights, p, n, n, u32::MAX, disk)
            })
            .collect(),
    };
    clusters
        .iter()
        .map(|c| energy_weight(c.members(), &irradiance, entry_energy))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec2;

    fn entries() -> Vec<SurfaceSample> {
        // Two planes meeting at a right angle, 200 points each.
        (0..400)
            .map(|i| {
                let u = crate::sampling::sobol2(i as u32 % 200, 9);
                let (p, n) = if i < 200 {
                    (Vec3::new(u.x, 0.0, u.y), Vec3::Y)
                } else {
                    (Vec3::new(0.0, u.x, u.y), Vec3::X)
                };
                SurfaceSample {
                    position: p,
                    normal: n,
                    albedo: Vec3::ONE,
                    triangle: 0,
                    barycentric: Vec2::ZERO,
                    weight: 1.0,
                }
            })
            .collect()
    }

    #[test]
    fn clusters_respect_normals_and_are_deterministic() {
        let e = entries();
        let p = ClusterParams::with_clusters(16);
        let a = Clustering::kmeans(&e, 1.7, &p).unwrap();
        let b = Clustering::kmeans(&e, 1.7, &p).unwrap();
        assert_eq!(a, b);
        assert!(a.len() <= 16 && a.len() >= 12);
        for m in &a.members {
            let n0 = e[m[0] as usize].normal;
            assert!(
                m.iter().all(|&k| e[k as usize].normal == n0),
                "cluster straddles the corner"
            );
        }
        let total: usize = a.members.iter().map(|m| m.len()).sum();
        assert_eq!(total, e.len());
        // Scale independence: scaling the scene and the diagonal gives the same partition.
        let scaled: Vec<SurfaceSample> = e
            .iter()
            .map(|s| SurfaceSample {
                position: s.position * 100.0,
                ..*s
            })
            .collect();
        let c = Clustering::kmeans(&scaled, 170.0, &p).unwrap();
        assert_eq!(a.of_entry, c.of_entry);
    }

    #[test]
    fn identity_and_weights() {
        let e = entries();
        let id = Clustering::kmeans(&e, 1.0, &ClusterParams::with_clusters(1000)).unwrap();
        assert_eq!(id, Clustering::identity(&e));
        let c = Clustering {
            of_entry: vec![0, 0, 1],
            centroids: vec![Vec3::ZERO; 2],
            normals: vec![Vec3::Y; 2],
            members: vec![vec![0, 1], vec![2]],
        };
        assert_eq!(
            c.weights(&[Vec3::ONE, Vec3::splat(3.0), Vec3::ZERO]),
            vec![Vec3::splat(2.0), Vec3::ZERO]
        );
    }
}
