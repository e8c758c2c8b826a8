//! Residual groups: the clusters split into a few spatial groups, whose summed panes carry the
//! light of the clusters a run time drops from its top K.
//!
//! A player that blends only the K clusters of highest score loses the others' light. Scaling
//! the kept ones up to the lost energy keeps the total but puts it where the strong clusters
//! shine. A residual group's pane, the sum of its members' panes, puts it roughly where the
//! dropped clusters would have: each group's dropped (and faded) energy `Σ w_c ⊙ e_c` is given
//! to its summed pane, scaled to that energy. Measured on default bakes against the reference
//! (`cargo xtask eval experiment residual_panes`, 2048 exit points, the bake
//! check's three lights): chairs (240 clusters, K = 32) 23.7% scaled, 12.3% with 4 residual
//! groups, 22.3% with K = 36 scaled (the same 36 panes), 10.4% with every cluster; the bundled
//! Cornell box (64 clusters) 13.6% (14.3% scaled), CornellBox-Sphere 11.9% (12.8%). One group (the sum
//! of every pane) gave 15.2% on chairs, 16 groups 12.1%.
//!
//! The groups are a function of the archive's cluster table alone (k-means of the clusters'
//! centroids, deterministic), so a run time and the bake's accuracy check derive the same ones
//! without storing them.

use crate::Cluster;

/// Residual groups a run time forms by default, at most one per [`CLUSTERS_PER_GROUP`]
/// clusters ([`residual_group_count`]). Measured in image space against the reference
/// (`cargo xtask eval --targets`'s cases, 4×4 error, K = 32, 8 entry points per cluster): 4
/// groups gave McGuire's box 8.2% (light under the ceiling) and 9.7% (low near the red wall),
/// CornellBox-Sphere 7.0%, chairs 8.6%; 16 groups 7.5%, 9.1%, 6.0%, 7.5%; 64 groups 6.4%,
/// 9.2%, 4.9%, 6.3%, against 5.2%, 9.2%, 4.5%, 5.5% with every cluster blended. With 4096
/// entry points (512 clusters) and K = 128, 64 groups give 4.3% and 4.6% against 3.4% and
/// 4.7% with every cluster. A group costs the run time what a kept cluster does (a pane
/// blended per texel; the bake's automatic top K leaves room for them), so the default is 64
/// (16 before the bakes grew to 4096 entry points and K to 128).
pub const RESIDUAL_GROUPS: u32 = 64;

/// Clusters per residual group at least: a group of one cluster is that cluster's pane again,
/// which blending every cluster gives with fewer panes.
pub const CLUSTERS_PER_GROUP: u32 = 4;

/// How many residual groups `clusters` clusters get when `asked` are asked for: at most one per
/// [`CLUSTERS_PER_GROUP`] clusters, and at least one while any are asked for.
pub fn residual_group_count(clusters: usize, asked: u32) -> u32 {
    let most = (clusters as u64 / u64::from(CLUSTERS_PER_GROUP)).max(1);
    u64::from(asked).min(most).min(clusters as u64) as u32
}

/// Rounds of k-means.
const ROUNDS: usize = 16;

/// The group of every cluster: `groups` groups (at most one per cluster, at least one; callers
/// ask for [`residual_group_count`] of them) by
/// k-means of the centroids, started from farthest points (the first cluster's centroid, then
/// each time the centroid farthest from the chosen ones, ties to the lower index). Every group
/// keeps at least its starting cluster.
pub fn residual_groups(clusters: &[Cluster], groups: u32) -> Vec<u32> {
    let n = clusters.len();
    let g = (groups as usize).min(n);
    if g <= 1 {
        return vec![0; n];
    }
    let p: Vec<[f64; 3]> = clusters.iter().map(|c| c.centroid.map(f64::from)).collect();
    // Plain products, not `powi`: the groups must be the same bits on every platform.
    let d2 = |a: &[f64; 3], b: &[f64; 3]| (0..3).map(|k| (a[k] - b[k]) * (a[k] - b[k])).sum::<f64>();
    let mut starts = vec![0usize];
    let mut chosen = vec![false; n];
    chosen[0] = true;
    let mut nearest: Vec<f64> = p.iter().map(|q| d2(q, &p[0])).collect();
    while starts.len() < g {
        let far = (0..n)
            .filter(|&i| !chosen[i])
            .reduce(|best, i| if nearest[i] > nearest[best] { i } else { best })
            .expect("fewer groups than clusters");
        chosen[far] = true;
        starts.push(far);
        for (i, q) in p.iter().enumerate() {
            nearest[i] = nearest[i].min(d2(q, &p[far]));
        }
    }
    let mut centres: Vec<[f64; 3]> = starts.iter().map(|&i| p[i]).collect();
    let mut of = vec![0u32; n];
    for _ in 0..ROUNDS {
        for (i, q) in p.iter().enumerate() {
            of[i] = (0..g).fold(0, |best, k| {
                if d2(q, &centres[k]) < d2(q, &centres[best]) {
                    k
                } else {
                    best
                }
            }) as u32;
        }
        // A start keeps its group, so no group empties.
        for (k, &s) in starts.iter().enumerate() {
            of[s] = k as u32;
        }
        let mut sum = vec![([0f64; 3], 0usize); g];
        for (i, q) in p.iter().enumerate() {
            let s = &mut sum[of[i] as usize];
            (0..3).for_each(|k| s.0[k] += q[k]);
            s.1 += 1;
        }
        for (c, (s, m)) in centres.iter_mut().zip(sum) {
            *c = s.map(|v| v / m as f64);
        }
    }
    of
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at(x: f32) -> Cluster {
        Cluster::new(0, 1, [x, 0.0, 0.0], [0.0, 1.0, 0.0])
    }

    #[test]
    fn group_count_keeps_four_clusters_a_group() {
        assert_eq!(residual_group_count(256, 64), 64);
        assert_eq!(residual_group_count(960, RESIDUAL_GROUPS), 64);
        assert_eq!(residual_group_count(205, RESIDUAL_GROUPS), 51);
        assert_eq!(residual_group_count(40, RESIDUAL_GROUPS), 10);
        assert_eq!(residual_group_count(64, 4), 4);
        assert_eq!(residual_group_count(3, 4), 1);
        assert_eq!(residual_group_count(0, 4), 0);
        assert_eq!(residual_group_count(100, 0), 0);
    }

    #[test]
    fn groups_follow_the_centroids() {
        let clusters: Vec<Cluster> = [0.0, 0.1, 0.2, 5.0, 5.1, 9.9, 10.0].into_iter().map(at).collect();
        let of = residual_groups(&clusters, 3);
        assert_eq!(of[0], of[1]);
        assert_eq!(of[1], of[2]);
        assert_eq!(of[3], of[4]);
        assert_eq!(of[5], of[6]);
        assert!(of[0] != of[3] && of[3] != of[5] && of[0] != of[5], "{of:?}");
        assert_eq!(of, residual_groups(&clusters, 3), "deterministic");
    }

    #[test]
    fn group_counts_are_clamped_and_never_empty() {
        let clusters: Vec<Cluster> = (0..5).map(|i| at(i as f32)).collect();
        assert_eq!(residual_groups(&clusters, 0), vec![0; 5]);
        assert_eq!(residual_groups(&clusters, 1), vec![0; 5]);
        let mut all = residual_groups(&clusters, 9);
        all.sort();
        assert_eq!(all, vec![0, 1, 2, 3, 4]);
        // Identical centroids: still one start per group.
        let same: Vec<Cluster> = (0..6).map(|_| at(1.0)).collect();
        let of = residual_groups(&same, 3);
        for k in 0..3 {
            assert!(of.contains(&k), "{of:?}");
        }
        assert!(residual_groups(&[], 4).is_empty());
    }
}
