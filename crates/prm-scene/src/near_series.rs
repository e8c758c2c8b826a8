//! The near field's deeper share as an operator on the exit records, and the tail of its series:
//! the CPU model that prm-runtime's load and the bake's accuracy check share, so that the check
//! plays what the player plays (formats/prm.md §5.6).
//!
//! A player adds the deeper VPLs' share after its blend: every exit record gains `π/M × Σ
//! R₁²/(r² + R₁²) × albedo/π × L` over its hits, `L` the lightmap at the hit's gather point, and
//! gathers again from the lightmap that sum completed. With `S` the blended lightmap (the panes
//! and the direct share) and `N` that operator, `K` gathers give `Σ_{k ≤ K} Nᵏ S`; the rest of
//! the series is extrapolated at every record from its last term, `f ⊙ Nᴷ S` with the factor `f`
//! of [`DeeperOperator::series_tail`].

use prm_format::NearField;

/// Below this share of the sum so far a term of the uniform light's series ends it
/// ([`DeeperOperator::series_tail`]): at the fireplace room's 0.87 a term, after about 85 terms
/// (0.5 s on two cores; 10⁻⁶ took 1.0 s on one).
pub const TAIL_TOLERANCE: f32 = 1e-5;
/// Most terms [`DeeperOperator::series_tail`] sums, which bounds the work where surfaces of
/// albedo near 1 enclose a space and the terms hardly fall.
pub const TAIL_TERMS: u32 = 512;

/// An exit record's hits on one gather point, merged into one.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct MergedHit {
    /// Gather point index.
    pub point: u32,
    /// Σ [`NearField::weight`] over the record's hits on the point.
    pub weight: f32,
    /// Σ [`NearField::indirect_weight`] over them.
    pub indirect_weight: f32,
}

/// The near field's hits merged per exit record and gather point, the input of
/// [`DeeperOperator::new`].
pub trait MergeNearHits {
    /// Every exit record's hits with the ones on one gather point merged, their weights summed
    /// in f32, and each record's end in them (as [`prm_format::NearExit::end`]). Several of an
    /// exit point's rays often end on one texel: 5.0 M hits make 2.25 M on the fireplace room,
    /// 225 k make 133 k on McGuire's box.
    fn merged_hits(&self) -> (Vec<u32>, Vec<MergedHit>);
}

impl MergeNearHits for NearField {
    fn merged_hits(&self) -> (Vec<u32>, Vec<MergedHit>) {
        let mut ends = Vec::with_capacity(self.exits.len());
        let mut merged: Vec<MergedHit> = Vec::with_capacity(self.hits.len() / 2);
        for i in 0..self.exits.len() {
            let start = merged.len();
            for h in self.hits_of(i) {
                let (w0, w1) = (self.weight(h.distance2), self.indirect_weight(h.distance2));
                match merged[start..].iter_mut().find(|m| m.point == h.point) {
                    Some(m) => {
                        m.weight += w0;
                        m.indirect_weight += w1;
                    }
                    None => merged.push(MergedHit {
                        point: h.point,
                        weight: w0,
                        indirect_weight: w1,
                    }),
                }
            }
            ends.push(merged.len() as u32);
        }
        (ends, merged)
    }
}

/// The deeper share's operator `N` on values of the exit records (module docs).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct DeeperOperator {
    /// Every exit record's end in [`DeeperOperator::terms`]; its first is the previous one's end.
    pub ends: Vec<u32>,
    /// Per merged hit, the exit record at its gather point's texel (`u32::MAX`: none, whose
    /// value is 0 to the series) and its factor `albedo × R₁²/(r² + R₁²) / M` (the `π` of `π/M`
    /// against the `1/π` of `albedo/π`).
    pub terms: Vec<(u32, [f32; 3])>,
}

impl DeeperOperator {
    /// The operator of `near` with its `merged` hits ([`MergeNearHits::merged_hits`]).
    pub fn new(near: &NearField, ends: &[u32], merged: &[MergedHit]) -> DeeperOperator {
        let scale = 1.0 / near.rays_per_exit.max(1) as f32;
        let terms = merged
            .iter()
            .map(|h| {
                let g = &near.points[h.point as usize];
                let at = near
                    .exits
                    .binary_search_by_key(&g.texel, |x| x.texel)
                    .map_or(u32::MAX, |i| i as u32);
                (at, g.albedo.map(|a| a * h.indirect_weight * scale))
            })
            .collect();
        DeeperOperator {
            ends: ends.to_vec(),
            terms,
        }
    }

    /// Exit records.
    pub fn len(&self) -> usize {
        self.ends.len()
    }

    /// Whether there are no exit records.
    pub fn is_empty(&self) -> bool {
        self.ends.is_empty()
    }

    /// Record `i`'s value of `N v`, with `v` a value per record (`None`: 1 everywhere).
    pub fn row(&self, i: usize, v: Option<&[[f32; 3]]>) -> [f32; 3] {
        let start = if i == 0 { 0 } else { self.ends[i - 1] as usize };
        let mut out = [0f32; 3];
        for &(at, f) in &self.terms[start..self.ends[i] as usize] {
            let x = match v {
                None => [1.0; 3],
                Some(v) => match v.get(at as usize) {
                    Some(x) => *x,
                    None => continue,
                },
            };
            (0..3).for_each(|k| out[k] += f[k] * x[k]);
        }
        out
    }

    /// `N v` at every record, one after another (`apply` of [`DeeperOperator::series_tail`]
    /// for a caller without threads).
    pub fn apply(&self, v: Option<&[[f32; 3]]>) -> Vec<[f32; 3]> {
        (0..self.len()).map(|i| self.row(i, v)).collect()
    }

    /// Every record's factor from the `gathers`-th term of the series to the sum of the terms
    /// after it, for uniform light: with `g_k = Nᵏ 1`, `Σ_{k > K} g_k / g_K` at `K = gathers`
    /// (per channel; 0 where `g_K` is). `apply(v)` returns `N v` at every record (`None`: of 1
    /// everywhere), [`DeeperOperator::apply`] or the caller's parallel map of
    /// [`DeeperOperator::row`]; the terms stop at [`TAIL_TOLERANCE`] or [`TAIL_TERMS`].
    ///
    /// After K gathers of the frame's light the record's last increment `Nᴷ S` times the factor
    /// stands for the rest: exact for uniform light, and close where the terms fall at one
    /// rate, which the enclosed spaces where the series converges slowly reach after a term or
    /// two. The fireplace room's default archive, its lightmap over every covered texel against
    /// the reference at 1024 paths a texel (a numpy model of these sums that matches the
    /// player's export to 3·10⁻⁵): one and two gathers 61.6% and 54.0% off, with this tail
    /// 15.5% and 15.8% (5.3% and 3.1% from the series' limit), the limit itself 15.1%. Where the
    /// frame's light reaches an enclosed space unlike uniform light does, single texels miss
    /// the limit by more (in a 6 mm gap between two parallel faces of albedo 0.89, 2.9 against
    /// the limit's 5.9 and the reference's 3.0: the panes leak light into the gap, and the limit
    /// multiplies it). In image space two gathers and the tail (7.08%) come closer to the
    /// reference than the limit (7.16%). Capping the factor per texel by the frame's own
    /// geometric rate (`r/(1 − r)`, `r` the last term over the one before) only costs energy
    /// (`cargo xtask eval --targets`: 0.5% on the fireplace room, 0.1% on McGuire's box, shape
    /// errors no better), and the rate alone, uncapped, is too noisy (it doubles the fireplace
    /// room's error), so the factor is not capped.
    pub fn series_tail(&self, gathers: u32, apply: impl Fn(Option<&[[f32; 3]]>) -> Vec<[f32; 3]>) -> Vec<[f32; 3]> {
        let n = self.len();
        if gathers == 0 {
            return vec![[0.0; 3]; n];
        }
        let mut g = apply(None);
        let (mut total, mut last, mut rest) = (0.0f32, Vec::new(), vec![[0f32; 3]; n]);
        for k in 1..=TAIL_TERMS {
            let size: f32 = g.iter().flatten().sum();
            total += size;
            if k == gathers {
                last = g.clone();
            } else if k > gathers {
                rest.iter_mut()
                    .zip(&g)
                    .for_each(|(r, v)| (0..3).for_each(|c| r[c] += v[c]));
            }
            if k >= gathers && size <= TAIL_TOLERANCE * total {
                break;
            }
            g = apply(Some(&g));
        }
        if last.is_empty() {
            return vec![[0.0; 3]; n];
        }
        rest.iter()
            .zip(&last)
            .map(|(r, l)| [0, 1, 2].map(|c| if l[c] > 0.0 { r[c] / l[c] } else { 0.0 }))
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use prm_format::{GatherPoint, NearExit, NearHit};

    /// Two exit records that see each other's texels (and one hit twice), albedo ½.
    fn pair() -> NearField {
        let point = |texel| GatherPoint {
            texel,
            albedo: [0.5; 3],
            ..Default::default()
        };
        let hit = |point| NearHit { point, distance2: 0.0 };
        NearField {
            rays_per_exit: 4,
            disk: 0.01,
            indirect_disk: 0.01,
            complement: false,
            points: vec![point(2), point(7), point(9)],
            exits: vec![NearExit { texel: 2, end: 3 }, NearExit { texel: 7, end: 5 }],
            // Record 0 sees record 1's texel twice and a texel without a record once; record 1
            // sees record 0's texel twice.
            hits: vec![hit(1), hit(2), hit(1), hit(0), hit(0)],
        }
    }

    #[test]
    fn merging_sums_the_weights_of_one_point() {
        let n = pair();
        let (ends, merged) = n.merged_hits();
        assert_eq!(ends, vec![2, 3]);
        assert_eq!(merged.iter().map(|m| m.point).collect::<Vec<_>>(), vec![1, 2, 0]);
        assert_eq!(merged[0].weight, 2.0);
        assert_eq!(merged[0].indirect_weight, 2.0);
        assert_eq!(merged[1].weight, 1.0);
    }

    #[test]
    fn the_tail_completes_the_series_of_uniform_light() {
        // Factors ½ · 2/4 = ¼ for the twice-hit points and ⅛ for the point without a record,
        // which uniform light lights too (N 1), but whose value is 0 from the second term on.
        let n = pair();
        let (ends, merged) = n.merged_hits();
        let op = DeeperOperator::new(&n, &ends, &merged);
        assert_eq!(op.terms.iter().map(|t| t.0).collect::<Vec<_>>(), vec![1, u32::MAX, 0]);
        assert_eq!(op.apply(None), vec![[0.375; 3], [0.25; 3]]);
        let v = [[1.0, 2.0, 0.0], [4.0, 0.0, 8.0]];
        assert_eq!(op.row(0, Some(&v)), [1.0, 0.0, 2.0]);
        assert_eq!(op.row(1, Some(&v)), [0.25, 0.5, 0.0]);
        // The factor against the series summed far.
        let tail = op.series_tail(2, |v| op.apply(v));
        let mut g = op.apply(None);
        let mut terms = vec![g.clone()];
        for _ in 0..200 {
            g = op.apply(Some(&g));
            terms.push(g.clone());
        }
        for (i, t) in tail.iter().enumerate() {
            let rest: f32 = terms[2..].iter().map(|g| g[i][0]).sum();
            let want = rest / terms[1][i][0];
            // The terms stop at TAIL_TOLERANCE of the sum so far.
            assert!(
                (t[0] - want).abs() < 10.0 * TAIL_TOLERANCE * want,
                "record {i}: {t:?} against {want}"
            );
        }
        assert_eq!(op.series_tail(0, |v| op.apply(v)), vec![[0.0; 3]; 2]);
    }
}
